#!/usr/bin/env python3
"""XModem pairs timed as a user times them, and their phases read off the link by one tap.

Every pair (cnc_dnc->cnc_dnc, sx->rx, cnc_dnc->rx, sx->cnc_dnc) runs ROUNDS times in turn, each
over a fresh link made by `tap` (bench/xmodem/tap.c: two ptys joined like `socat pty,raw,echo=0`
that time-stamps every byte each side sends). A run starts the receiver and at once the sender,
and ends when both have exited ("end to end", what a user waits for). From the tap's record:

  start  = launch .. the sender's first packet byte (process start, the start request, the
           sender's turnaround)
  blocks = the sender's first packet byte .. the receiver's reply to the last packet (the data)
  end    = that reply .. both programs exited (EOT, the receiver's silence check, its ACK, file
           close; and a sender left waiting for an ACK of EOT that never came)

The same tap measures every pair, so the block phases compare like with like. A sender still
running SENDER_CAP seconds after its receiver exited is killed and the run is marked (its end to
end time is then at least the figure shown): lrzsz rx flushes its tty as it exits, and the ACK of
EOT it has just written is sometimes thrown away with it, which leaves the sender waiting.

Then the same pairs at line rate: the tap carries 115200 baud (10 bits a character) both ways,
LINE_RATE_ROUNDS times each (default 3) with a 64 KiB program, beside the stop-and-wait bound of
that link: every packet's 132 characters (checksum-128) and its one-character ACK, one after the
other, at 115200 baud. No run can beat it; the ratio to it is the protocol's efficiency on a real
line, for cnc_dnc and lrzsz alike.

Then the noisy wire: cnc_dnc -> cnc_dnc over the tap carrying 115200 baud (10 bits a character)
and damaging each direction (a byte in 500 flipped, in 1000 lost, in 2000 doubled, seeded), a
16 KB program, once per seed, in CRC and in checksum mode.

usage: bench_xmodem.py BIN_DIR TAP KILOBYTES ROUNDS NOISY_SEEDS   (LINE_RATE_ROUNDS=N in the environment)
"""
import os
import random
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time

SENDER_CAP = 30.0
RECEIVER_CAP = 120.0
LINE_BAUD = 115200
LINE_KB = 64
CHECKSUM_PACKET = 132  # SOH, block number, its complement, 128 bytes, checksum


def load():
    with open("/proc/loadavg") as f:
        return " ".join(f.read().split()[:3])


class Link:
    """A tap link A (sender) <-> B (receiver); the record is read after stop()."""

    def __init__(self, tap, work, baud=0, faults=None):
        self.a, self.b, self.log = work + "/A", work + "/B", work + "/tap.log"
        for p in (self.a, self.b):
            if os.path.lexists(p):
                os.unlink(p)
        args = [tap, self.a, self.b, self.log, str(baud)]
        if faults:
            args += [str(x) for x in faults]
        self.proc = subprocess.Popen(args)
        for _ in range(250):
            if os.path.exists(self.a) and os.path.exists(self.b):
                return
            time.sleep(0.01)
        raise RuntimeError("tap did not come up")

    def stop(self):
        self.proc.send_signal(signal.SIGTERM)
        self.proc.wait()
        records, counts = [], {}
        with open(self.log) as f:
            for line in f:
                if line.startswith("#"):
                    side, rest = line[2], line[4:].split()
                    counts[side] = {k: int(v) for k, v in (x.split("=") for x in rest)}
                    continue
                t, side, data = line.split()
                records.append((float(t), side, bytes.fromhex(data)))
        return records, counts


def phases(records, packet_size):
    """(first packet byte, reply to the last packet) times from the tap's record of a clean run."""
    first, eot_time = None, None
    sender, pos = bytearray(), 0
    for t, side, data in records:
        if side != "a":
            continue
        if first is None:
            first = t
        sender += data
        # Walk the sender's stream packet by packet: an EOT at a packet boundary ends the data.
        while pos < len(sender):
            if sender[pos] == 0x04:
                eot_time = t
                break
            size = packet_size if sender[pos] == 0x01 else 1029 if sender[pos] == 0x02 else 1
            if pos + size > len(sender):
                break
            pos += size
        if eot_time is not None:
            break
    if first is None or eot_time is None:
        return None
    last_reply = max((t for t, side, _ in records if side == "b" and t <= eot_time), default=None)
    return first, last_reply


def run_pair(tap, work, sender, receiver, out, payload, packet_size, baud=0, faults=None):
    link = Link(tap, work, baud, faults)
    if os.path.exists(out):
        os.unlink(out)
    t0 = time.time()
    rx = subprocess.Popen(receiver(link.b), cwd=work, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    tx = subprocess.Popen(sender(link.a), cwd=work, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    capped = False
    try:
        rx_out = rx.communicate(timeout=RECEIVER_CAP)[0].decode(errors="replace")
    except subprocess.TimeoutExpired:
        rx.kill()
        rx_out = rx.communicate()[0].decode(errors="replace")
    t_rx = time.time()
    try:
        tx.wait(timeout=SENDER_CAP)
    except subprocess.TimeoutExpired:
        tx.kill()
        tx.wait()
        capped = True
    t_end = time.time()
    records, counts = link.stop()
    exact = os.path.exists(out) and open(out, "rb").read()[: len(payload)] == payload
    # Complete: the file arrived exactly, and both programs ended by themselves with status 0.
    complete = exact and not capped and rx.returncode == 0 and tx.returncode == 0
    result = {"total": t_end - t0, "receiver": t_rx - t0, "capped": capped, "exact": exact, "complete": complete,
              "out": rx_out, "counts": counts}
    p = phases(records, packet_size)
    if p:
        result["start"] = p[0] - t0
        result["blocks"] = p[1] - p[0]
        result["end"] = t_end - p[1]
    return result


def run_rounds(tap, work, pairs, payload, rounds, baud=0):
    """Every pair ROUNDS times, the pairs taking turns; a list of run results per pair."""
    with open(work + "/payload.bin", "wb") as f:
        f.write(payload)
    results = {name: [] for name in pairs}
    for r in range(rounds):
        for name, (sender, receiver) in pairs.items():
            results[name].append(run_pair(tap, work, sender, receiver, work + "/out.bin", payload, CHECKSUM_PACKET,
                                          baud))
        print("round %d of %d done, load %s" % (r + 1, rounds, load()), file=sys.stderr)
    return results


def median_of_complete(runs, key):
    # Medians over complete runs only: a run in which a peer stalled, was killed or left a wrong
    # file is counted and shown apart, never averaged in.
    values = [x[key] for x in runs if key in x and x["complete"]]
    return statistics.median(values) if values else float("nan")


def print_pairs(results, title, bound=None):
    """The table of medians, the ratios to sx -> rx (and to \p bound, seconds, when given), every run."""
    rounds = len(next(iter(results.values())))
    print("\n%s, medians of the complete runs of %d per pair (seconds); every pair over the same tap" % (title, rounds))
    print("%-20s %12s %8s %8s %8s %9s  %s" % ("pair", "end to end", "start", "blocks", "end", "complete",
                                               "apart: sender killed after its receiver exited / wrong file / exit status"))
    for name, runs in results.items():
        med = lambda key: median_of_complete(runs, key)
        print("%-20s %12.3f %8.3f %8.3f %8.3f %6d/%-2d  %d / %d / %d" % (
            name, med("total"), med("start"), med("blocks"), med("end"),
            sum(x["complete"] for x in runs), len(runs), sum(x["capped"] for x in runs),
            sum(not x["exact"] for x in runs),
            sum(x["exact"] and not x["capped"] and not x["complete"] for x in runs)))
    base_total = median_of_complete(results["sx -> rx"], "total")
    base_blocks = median_of_complete(results["sx -> rx"], "blocks")
    print("\nratios to sx -> rx (its time / the pair's time: above 1 = faster than sx -> rx)%s"
          % ("; blocks against the stop-and-wait bound %.3f s (at most 100 %%)" % bound if bound else ""))
    print("%-20s %12s %12s%s" % ("pair", "end to end", "blocks", " %14s" % "bound/blocks" if bound else ""))
    for name, runs in results.items():
        total, blocks = median_of_complete(runs, "total"), median_of_complete(runs, "blocks")
        print("%-20s %11.2fx %11.2fx%s" % (name, base_total / total, base_blocks / blocks,
                                           " %13.1f%%" % (100 * bound / blocks) if bound else ""))
    print("every run, end to end seconds (k = sender killed %.0f s after its receiver exited):" % SENDER_CAP)
    for name, runs in results.items():
        print("  %-20s %s" % (name, " ".join("%.2f%s" % (x["total"], "" if x["complete"] else "k" if x["capped"] else "x")
                                             for x in runs)))
    print("  (x = incomplete: a wrong file or a non-zero exit status)")
    return [name for name in results if "cnc_dnc" in name and not all(x["complete"] for x in results[name])]


def stop_and_wait_bound(kb, baud):
    """The blocks phase on a line of \p baud: each packet, then its ACK, nothing overlapping. The
    phase ends when the receiver writes its last ACK, so that one's character time is not in it."""
    packets = kb * 1024 // 128
    return (packets * (CHECKSUM_PACKET + 1) - 1) * 10.0 / baud


def main():
    bin_dir, tap, kb, rounds, seeds = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
    line_rounds = int(os.environ.get("LINE_RATE_ROUNDS", "3"))
    dnc = bin_dir + "/cnc_dnc"
    work = tempfile.mkdtemp(prefix="bench_xmodem.")
    try:
        pairs = {
            "cnc_dnc -> cnc_dnc": (lambda a: [dnc, "send", "--port", a, "--mode", "checksum", "--binary", "payload.bin"],
                                   lambda b: [dnc, "receive", "--port", b, "--mode", "checksum", "--binary", "out.bin"]),
            "sx -> rx": (lambda a: ["sh", "-c", 'exec sx payload.bin <"$0" >"$0"', a],
                         lambda b: ["sh", "-c", 'exec rx out.bin <"$0" >"$0"', b]),
            "cnc_dnc -> rx": (lambda a: [dnc, "send", "--port", a, "--mode", "checksum", "--binary", "payload.bin"],
                              lambda b: ["sh", "-c", 'exec rx out.bin <"$0" >"$0"', b]),
            "sx -> cnc_dnc": (lambda a: ["sh", "-c", 'exec sx payload.bin <"$0" >"$0"', a],
                              lambda b: [dnc, "receive", "--port", b, "--mode", "checksum", "--binary", "out.bin"]),
        }
        ours_failed = []
        print("load average at the start: %s" % load())
        if rounds > 0:
            results = run_rounds(tap, work, pairs, os.urandom(kb * 1024), rounds)
            print("load average at the end: %s" % load())
            ours_failed += print_pairs(results, "%d KiB, checksum-128, unpaced ptys" % kb)
        if line_rounds > 0:
            results = run_rounds(tap, work, pairs, os.urandom(LINE_KB * 1024), line_rounds, LINE_BAUD)
            print("load average at the end: %s" % load())
            ours_failed += print_pairs(results, "%d KiB, checksum-128, %d baud both ways on the tap" % (LINE_KB, LINE_BAUD),
                                       stop_and_wait_bound(LINE_KB, LINE_BAUD))

        # The noisy wire.
        if seeds > 0:
            rng = random.Random(5)
            text = "%\nO1234 (NOISY WIRE)\n"
            n = 10
            while len(text) < 16384 - 8:
                text += "N%d G01 X%d.%03d Y%d.%03d F300.\n" % (n, rng.randrange(500), rng.randrange(1000),
                                                               rng.randrange(500), rng.randrange(1000))
                n += 5
            text = text[: 16384 - 7] + "\nM30\n%\n"
            with open(work + "/noisy.nc", "w") as f:
                f.write(text)
            program = text.encode()
            print("\nnoisy wire: 16 KiB program, cnc_dnc -> cnc_dnc, 115200 baud on the tap, per byte and direction "
                  "flip 1/500, drop 1/1000, double 1/2000; load %s" % load())
            print("%-9s %5s %10s %8s %7s  %s" % ("mode", "seed", "seconds", "retries", "exact", "faults sender->receiver / receiver->sender (flipped dropped doubled)"))
            for mode in ("crc", "checksum"):
                times = []
                for seed in range(1, seeds + 1):
                    sender = lambda a, m=mode: [dnc, "send", "--port", a, "--mode", m, "noisy.nc"]
                    receiver = lambda b, m=mode: [dnc, "receive", "--port", b, "--mode", m, "noisy_out.nc"]
                    res = run_pair(tap, work, sender, receiver, work + "/noisy_out.nc", program, 132 if mode == "checksum" else 133,
                                   115200, (0.002, 0.001, 0.0005, seed))
                    exact = os.path.exists(work + "/noisy_out.nc") and open(work + "/noisy_out.nc", "rb").read() == program
                    retries = "-"
                    for word in res["out"].split(";")[0].split(","):
                        if "retries" in word:
                            retries = word.split()[0]
                    c = res["counts"]
                    fa = "%d %d %d" % (c["a"]["flipped"], c["a"]["dropped"], c["a"]["doubled"])
                    fb = "%d %d %d" % (c["b"]["flipped"], c["b"]["dropped"], c["b"]["doubled"])
                    times.append(res["total"])
                    print("%-9s %5d %10.2f %8s %7s  %s / %s" % (mode, seed, res["total"], retries, "yes" if exact else "NO",
                                                                fa, fb))
                print("%-9s median %.2f s, worst %.2f s over %d seeds" % (mode, statistics.median(times), max(times), len(times)))
            # The same program on a clean 115200 line: what the retries cost on top of it.
            clean = run_pair(tap, work, lambda a: [dnc, "send", "--port", a, "--mode", "crc", "noisy.nc"],
                             lambda b: [dnc, "receive", "--port", b, "--mode", "crc", "noisy_out.nc"],
                             work + "/noisy_out.nc", program, 133, 115200, None)
            print("clean 115200 line, same program, crc: %.2f s" % clean["total"])
            print("load average at the end: %s" % load())
        if ours_failed:
            # A pair with cnc_dnc on either side that did not complete every run is a failure of the
            # benchmark (the figures above are from the complete runs only).
            print("FAILED: incomplete runs of %s" % ", ".join(ours_failed), file=sys.stderr)
            return 1
        return 0
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
