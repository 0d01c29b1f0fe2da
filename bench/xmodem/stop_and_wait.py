#!/usr/bin/python3
"""The stop-and-wait bound of a link: one side writes 132 bytes and waits for a 1-byte reply, the
other reads 132 bytes and replies, N times. Prints payload bytes/s (128 per round), i.e. the
fastest any XModem-128 pair could go over this link.

usage: stop_and_wait.py DEV_A DEV_B ROUNDS [PACKET_BYTES] [PAYLOAD_BYTES]
"""
import os
import sys
import threading
import time
import tty


def open_raw(path):
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    return fd


def read_exactly(fd, n):
    data = b""
    while len(data) < n:
        chunk = os.read(fd, n - len(data))
        if not chunk:
            raise EOFError
        data += chunk
    return data


def main():
    a, b, rounds = sys.argv[1], sys.argv[2], int(sys.argv[3])
    packet = int(sys.argv[4]) if len(sys.argv) > 4 else 132
    payload = int(sys.argv[5]) if len(sys.argv) > 5 else 128
    fa, fb = open_raw(a), open_raw(b)

    def echo():
        for _ in range(rounds):
            read_exactly(fb, packet)
            os.write(fb, b"\x06")

    t = threading.Thread(target=echo)
    t.start()
    block = bytes(packet)
    start = time.monotonic()
    for _ in range(rounds):
        os.write(fa, block)
        read_exactly(fa, 1)
    elapsed = time.monotonic() - start
    t.join()
    print("%.0f" % (rounds * payload / elapsed))


if __name__ == "__main__":
    main()
