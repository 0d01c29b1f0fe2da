#!/usr/bin/env python3
"""An SHDR adapter that changes one data item at a steady rate, for bench/mtconnect.

The agent (cppagent) connects to PORT; the adapter sends the mill's initial state
(test/data/mtconnect/recording/Devices.xml), waits WARMUP seconds, then sets `Xact` to 1, 2, 3 ...
(its nativeUnits are INCH: the agent reports 25.4, 50.8 ... mm), RATE times a second for SECONDS seconds, and writes "<n> <epoch seconds when sent>" per change
to LOG. `* PING` is answered `* PONG 10000`.

usage: source.py PORT RATE SECONDS WARMUP LOG
"""
import socket
import sys
import threading
import time

port, rate, seconds, warmup, log = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), \
    sys.argv[5]
INITIAL = ["avail|AVAILABLE|estop|ARMED|mode|AUTOMATIC|exec|ACTIVE|program|O1234|partcount|1",
           "Xact|0|Yact|0|Zact|0|Xcom|0|Ycom|0|Zcom|0|Sspeed|0|Frate|0"]


def stamp():
    now = time.time()
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(now)) + ".%06dZ" % int(now % 1 * 1e6)


server = socket.create_server(("127.0.0.1", port))
peer, _ = server.accept()
peer.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
lock = threading.Lock()


def answer_pings():
    data = b""
    while True:
        chunk = peer.recv(1024)
        if not chunk:
            return
        data += chunk
        while b"\n" in data:
            line, data = data.split(b"\n", 1)
            if line.strip() == b"* PING":
                with lock:
                    peer.sendall(b"* PONG 10000\n")


threading.Thread(target=answer_pings, daemon=True).start()
with lock:
    for line in INITIAL:
        peer.sendall(("%s|%s\n" % (stamp(), line)).encode())
time.sleep(warmup)  # stands for: the agent's clients connecting and reading /current first
period = 1.0 / rate
start = time.time()
with open(log, "w") as out:
    n = 0
    while time.time() - start < seconds:
        n += 1
        with lock:
            sent = time.time()
            peer.sendall(("%s|Xact|%d\n" % (stamp(), n)).encode())
        out.write("%d %.6f\n" % (n, sent))
        next_at = start + n * period
        time.sleep(max(0.0, next_at - time.time()))  # the machine's pace: RATE changes a second
time.sleep(1.0)  # stands for: the last changes reaching the clients before the agent goes
