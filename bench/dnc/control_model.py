#!/usr/bin/env python3
"""A Fanuc-style drip-feed receiver on a pty, written apart from the project's simulator.

It owns the pty master (the host opens the slave path it prints), takes characters from the line
no faster than BAUD/10 a second (its UART), keeps them in a BUFFER-character buffer, executes them
at EXEC characters a second, sends DC3 when the buffer reaches 3/4 and DC1 when it is down to 1/4.
For every DC3 it counts the characters it takes from the line until its DC1: what the host had
queued at that moment and what it wrote after. A control may take 10 (Fanuc); more overflow a
small buffer. It runs until the program's closing '%' arrived (after the first) or SECONDS pass.

Prints one line: xoff=N max_after_xoff=N over_10=N overflow=N characters=N seconds=S
after_xoff_p50=N after_xoff_p90=N after_xoff_p99=N
(overflow: characters beyond the buffer's size, which a control would lose; the percentiles are of
the characters taken after each XOFF).

usage: control_model.py LINK BAUD EXEC [BUFFER] [SECONDS]
"""
import os
import pty
import select
import sys
import termios
import time
import tty

DC1, DC3 = 0x11, 0x13


def main():
    link, baud, exec_cps = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    size = int(sys.argv[4]) if len(sys.argv) > 4 else 256
    limit = float(sys.argv[5]) if len(sys.argv) > 5 else 600.0
    line_cps = baud / 10.0
    high, low = size * 3 // 4, size // 4
    try:  # a control's UART is served at once: real-time, where allowed
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(20))
    except OSError:
        pass
    master, slave = pty.openpty()
    tty.setraw(slave)
    if os.path.lexists(link):
        os.unlink(link)
    os.symlink(os.ttyname(slave), link)
    os.set_blocking(master, False)
    pending = bytearray()  # on the line, not yet taken by the UART
    buffered = 0.0
    stopped = False
    credit = 0.0
    after, worst, over, overflow, xoffs, total, percents = 0, 0, 0, 0, 0, 0, 0
    afters = []  # characters taken after each XOFF, for the distribution
    start = last = time.monotonic()
    try:
        while time.monotonic() - start < limit and percents < 2:
            select.select([master], [], [], 0.0005)
            try:
                pending += os.read(master, 65536)
            except (BlockingIOError, OSError):
                pass
            now = time.monotonic()
            elapsed, last = now - last, now
            # The UART: at most the line's rate, character by character; execution drains the buffer.
            credit = credit + elapsed * line_cps if pending else 1.0
            take = min(len(pending), int(credit))
            credit -= take
            taken, pending = pending[:take], pending[take:]
            total += take
            percents += taken.count(b"%")
            buffered = max(0.0, buffered - elapsed * exec_cps)
            for _ in range(take):
                buffered += 1
                if stopped:
                    after += 1
                if buffered > size:
                    overflow += 1
                    buffered = size
                if not stopped and buffered >= high:
                    os.write(master, bytes([DC3]))
                    stopped, after = True, 0
                    xoffs += 1
            if not stopped:
                continue
            if buffered <= low:
                worst = max(worst, after)
                over += after > 10
                afters.append(after)
                os.write(master, bytes([DC1]))
                stopped = False
    finally:
        os.unlink(link)
    afters.sort()

    def percentile(p):
        return afters[min(len(afters) - 1, int(p / 100.0 * len(afters)))] if afters else 0

    print("xoff=%d max_after_xoff=%d over_10=%d overflow=%d characters=%d seconds=%.1f"
          " after_xoff_p50=%d after_xoff_p90=%d after_xoff_p99=%d"
          % (xoffs, worst, over, overflow, total, time.monotonic() - start, percentile(50), percentile(90),
             percentile(99)))


if __name__ == "__main__":
    main()
