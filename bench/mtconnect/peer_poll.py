#!/usr/bin/env python3
"""The peer a user would otherwise write: a Python client polling the agent's /current (urllib +
ElementTree, as the MTConnect Institute's Python examples do), every PERIOD seconds (0: back to
back). For each change `Xact = n` (inches; the agent reports mm) the source sent, the time until a /current shows it; and the
client's own CPU time over the run.

usage: peer_poll.py AGENT_URL SECONDS PERIOD SOURCE_LOG
Prints: changes seen of sent, latency p50/p99/max in ms, polls, observations parsed, CPU ms."""
import resource
import sys
import time
import urllib.request
import xml.etree.ElementTree as ET

url, seconds, period, log = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
seen = {}
polls = 0
observations = 0
cpu_start = resource.getrusage(resource.RUSAGE_SELF)
end = time.time() + seconds
while time.time() < end:
    try:
        with urllib.request.urlopen(url + "/current", timeout=5) as answer:
            body = answer.read()
    except OSError:
        time.sleep(0.1)  # the agent not up yet: try again
        continue
    now = time.time()
    polls += 1
    root = ET.fromstring(body)
    for element in root.iter():
        if element.get("dataItemId") is None:
            continue
        observations += 1
        if element.get("dataItemId") == "Xact" and element.text not in (None, "UNAVAILABLE"):
            seen.setdefault(int(round(float(element.text) / 25.4)), now)  # the agent reports mm
    if period > 0:
        time.sleep(period)  # the client's poll period
cpu = resource.getrusage(resource.RUSAGE_SELF)
cpu_ms = (cpu.ru_utime - cpu_start.ru_utime + cpu.ru_stime - cpu_start.ru_stime) * 1000.0
sent = {}
with open(log) as f:
    for line in f:
        n, at = line.split()
        sent[int(n)] = float(at)
values = sorted((seen[n] - sent[n]) * 1000.0 for n in sent if n in seen)
if not values:
    print("no change seen of %d sent" % len(sent))
    sys.exit(1)
print("changes %d of %d latency p50 %.1f ms p99 %.1f ms max %.1f ms polls %d observations parsed %d cpu %.0f ms"
      % (len(values), len(sent), values[len(values) // 2], values[min(len(values) - 1, int(len(values) * 0.99))],
         values[-1], polls, observations, cpu_ms))
