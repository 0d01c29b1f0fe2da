#!/usr/bin/env python3
"""Reference peer for the poll-rate benchmark: the plain way MDC is polled from Python by small
MTConnect adapters and shop scripts (one blocking socket, send ?Qnnn, read lines until the
answering reply). Same query mix as bench_mdc_poll. usage: peer_poll.py HOST PORT SECONDS"""
import socket
import sys
import time

host, port, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
# An NGC answers Q600 with "MACRO, value" (no variable number: docs/protocols/haas_mdc.md).
queries = [("?Q500", ("PROGRAM", "STATUS")), ("?Q104", ("MODE",))] + \
    [("?Q600 %d" % n, ("MACRO,",)) for n in (5021, 5022, 5023, 5041, 5042, 5043)]
sock = socket.create_connection((host, port), timeout=1.0)
sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
reader = sock.makefile("rb")
answered = 0
latencies = []
end = time.monotonic() + seconds
i = 0
while time.monotonic() < end:
    text, keys = queries[i % len(queries)]
    i += 1
    started = time.monotonic()
    sock.sendall((text + "\r\n").encode())
    while True:
        line = reader.readline().decode(errors="replace").strip().lstrip(">").strip()
        if any(line.startswith(k) for k in keys):
            break
    latencies.append((time.monotonic() - started) * 1000.0)
    answered += 1
elapsed = seconds
print("queries %d in %.2f s: %.0f queries/s, latency mean %.3f ms max %.3f ms"
      % (answered, elapsed, answered / elapsed, sum(latencies) / len(latencies), max(latencies)))
