#!/usr/bin/env python3
"""Records a real MTConnect agent's HTTP responses, byte for byte, as test fixtures.

Runs the agent (mtconnect/cppagent v1.8.0.3, built outside this repository) with agent.cfg and
Devices.xml from this folder, feeds it from a small SHDR adapter (a thread of this script: a
three-axis mill going through a cycle), and saves what the agent sends on the socket for each
request (status line, headers, chunked framing, multipart boundaries: nothing re-encoded) into
test/data/mtconnect/<name>.http. recording.json lists each file with its request.

usage: record.py AGENT_BINARY [OUT_DIR]
"""
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
AGENT_PORT = 15000
ADAPTER_PORT = 17878


class Adapter:
    """An SHDR adapter: full state to a newly connected agent, then the lines it is given."""

    INITIAL = [
        "avail|AVAILABLE|estop|ARMED|mode|AUTOMATIC|exec|READY|program|O1234|line|0|partcount|41"
        "|tool|3|door_state|CLOSED|Smode|SPINDLE",
        "Xact|1.0|Yact|2.0|Zact|3.0|Xcom|1.0|Ycom|2.0|Zcom|3.0|Sspeed|0|Frate|0",
        "system|NORMAL||||",
        "motion|NORMAL||||",
    ]

    def __init__(self):
        self.server = socket.create_server(("127.0.0.1", ADAPTER_PORT))
        self.lock = threading.Lock()
        self.peer = None
        self.connected = threading.Event()
        threading.Thread(target=self.accept_loop, daemon=True).start()

    def accept_loop(self):
        while True:
            peer, _ = self.server.accept()
            with self.lock:
                self.peer = peer
            for line in self.INITIAL:
                self.send_raw(line)
            self.connected.set()
            threading.Thread(target=self.read_loop, args=(peer,), daemon=True).start()

    def read_loop(self, peer):
        data = b""
        while True:
            try:
                chunk = peer.recv(1024)
            except OSError:
                return
            if not chunk:
                return
            data += chunk
            while b"\n" in data:
                line, data = data.split(b"\n", 1)
                if line.strip() == b"* PING":
                    with self.lock:
                        peer.sendall(b"* PONG 10000\n")

    def send_raw(self, body):
        stamp = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime()) + ".%06dZ" % (time.time() % 1 * 1e6)
        with self.lock:
            if self.peer is not None:
                self.peer.sendall(("%s|%s\n" % (stamp, body)).encode())

    def send(self, *lines, pause=0.05):
        for line in lines:
            self.send_raw(line)
            time.sleep(pause)  # stands for: a machine's pace between updates


def http_get(target, timeout=5.0, read_for=None, kill_after=None):
    """Sends GET target; returns every byte the agent sent until it closed (or read_for s passed)."""
    sock = socket.create_connection(("127.0.0.1", AGENT_PORT), timeout=timeout)
    sock.sendall(("GET %s HTTP/1.1\r\nHost: 127.0.0.1:%d\r\nAccept: */*\r\nConnection: close\r\n\r\n"
                  % (target, AGENT_PORT)).encode())
    data = b""
    deadline = time.time() + read_for if read_for else None
    sock.settimeout(0.2)
    while True:
        if deadline and time.time() > deadline:
            break
        if kill_after and time.time() > kill_after[0]:
            kill_after[1]()
            kill_after = None
        try:
            chunk = sock.recv(65536)
        except socket.timeout:
            continue
        except ConnectionResetError:
            break
        if not chunk:
            break
        data += chunk
    sock.close()
    return data


def header_of(response, name):
    match = re.search(rb'%s="([^"]*)"' % name.encode(), response)
    return int(match.group(1)) if match else None


class Recorder:
    def __init__(self, agent_binary, out_dir):
        self.agent_binary = agent_binary
        self.out_dir = out_dir
        self.work = tempfile.mkdtemp(prefix="mtconnect_recording_")
        for name in ("agent.cfg", "Devices.xml"):
            shutil.copy(os.path.join(HERE, name), self.work)
        self.agent = None
        self.index = []

    def start_agent(self, adapter):
        adapter.connected.clear()
        self.agent = subprocess.Popen([self.agent_binary, "run", "agent.cfg"], cwd=self.work,
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.time() + 30
        while time.time() < deadline:
            try:
                socket.create_connection(("127.0.0.1", AGENT_PORT), timeout=0.5).close()
                break
            except OSError:
                time.sleep(0.1)  # poll: the agent's port opens when it is up
        if not adapter.connected.wait(30):
            raise RuntimeError("the agent did not connect to the adapter")
        while b"AVAILABLE" not in http_get("/current"):
            time.sleep(0.1)  # poll: the adapter's first lines reach the agent's buffer

    def stop_agent(self):
        self.agent.terminate()
        self.agent.wait(10)

    def save(self, name, target, data, note=""):
        with open(os.path.join(self.out_dir, name + ".http"), "wb") as f:
            f.write(data)
        self.index.append({"file": name + ".http", "request": "GET " + target, "bytes": len(data), "note": note})
        print("%-28s %6d bytes  GET %s" % (name, len(data), target))

    def get(self, name, target, note=""):
        data = http_get(target)
        self.save(name, target, data, note)
        return data


def cycle_lines(start_x):
    """A cycle: start, a few moves with line numbers, end with the part counter up."""
    lines = ["exec|ACTIVE|Sspeed|1200|Frate|50|line|10"]
    for i in range(1, 6):
        x = start_x + i * 0.5
        lines.append("Xact|%.4f|Xcom|%.4f|Zact|%.4f|Zcom|%.4f|line|%d" % (x, x + 0.1, 3.0 - i * 0.1, 2.9 - i * 0.1,
                                                                          10 + i * 10))
    return lines


STREAM = "&interval=100&heartbeat=500"  # the client's request order: from, count, interval, heartbeat


def main():
    agent_binary = os.path.abspath(sys.argv[1])
    out_dir = os.path.abspath(sys.argv[2] if len(sys.argv) > 2 else os.path.dirname(HERE))
    adapter = Adapter()
    rec = Recorder(agent_binary, out_dir)
    rec.start_agent(adapter)

    # Each stream or poll asks from the nextSequence of the /current recorded before it, so that
    # replaying the files in order is the conversation a client has.
    rec.get("probe", "/probe")
    first = header_of(rec.get("current", "/current", "the adapter's initial state"), "nextSequence")
    adapter.send(*cycle_lines(1.0))
    time.sleep(0.3)  # stands for: the agent taking the adapter's lines into its buffer
    second = header_of(rec.get("sample", "/sample?from=%d&count=8" % first, "a poll: the cycle's first 8"),
                       "nextSequence")
    rec.get("sample_next", "/sample?from=%d&count=8" % second, "the next poll")

    # A streaming session from the same point: the buffered cycle start, then live the cycle's
    # end (part count), conditions (warning, fault, normal), a feed hold with the door open and an
    # emergency stop, and heartbeats in between.
    def feed():
        time.sleep(0.6)  # stands for: the machine's pace
        adapter.send("exec|READY|Sspeed|0|Frate|0|partcount|42|line|0", pause=0.3)
        adapter.send("motion|WARNING|1010|2|HIGH|Feed rate override at 10%", pause=0.3)
        adapter.send("system|FAULT|2001|1||Spindle drive overload", pause=0.3)
        adapter.send("exec|ACTIVE|Sspeed|900", pause=0.3)
        adapter.send("system|NORMAL||||", "motion|NORMAL||||", pause=0.3)
        adapter.send("exec|INTERRUPTED|door_state|OPEN", "estop|TRIGGERED", pause=1.2)
    threading.Thread(target=feed, daemon=True).start()
    target = "/sample?from=%d&count=8%s" % (first, STREAM)
    rec.save("stream", target, http_get(target, read_for=4.5), "multipart stream, 4.5 s: cycle, conditions, e-stop")
    adapter.send("estop|ARMED|door_state|CLOSED|exec|READY", "mode|MANUAL")

    # Buffer overrun: more observations than the 64-slot buffer holds since a /current.
    old = header_of(rec.get("current_before_overrun", "/current"), "nextSequence")
    for i in range(40):
        adapter.send("Xact|%.4f|Yact|%.4f" % (2.0 + i * 0.01, 2.0 - i * 0.01), pause=0.02)
    time.sleep(0.3)  # stands for: the agent taking the adapter's lines into its buffer
    rec.get("sample_out_of_range", "/sample?from=%d&count=8" % old,
            "a poll from older than firstSequence: the agent answers OUT_OF_RANGE")
    target = "/sample?from=%d&count=8%s" % (old, STREAM)
    rec.save("stream_overrun", target, http_get(target, read_for=1.2),
             "streaming from older than firstSequence: the agent starts at firstSequence")

    # Restart: the agent is stopped during a stream (cut without its last chunk); the new agent
    # has a new instanceId and starts its sequence again.
    resume = header_of(rec.get("current_after_overrun", "/current"), "nextSequence")
    target = "/sample?from=%d&count=8%s" % (resume, STREAM)
    # stands for: the machine's pace (the sleep below)
    threading.Thread(target=lambda: (time.sleep(0.5), adapter.send("Zact|4.0|Zcom|4.0")), daemon=True).start()
    data = http_get(target, read_for=10, kill_after=(time.time() + 1.2, rec.stop_agent))
    rec.save("stream_agent_stopped", target, data, "the agent is stopped 1.2 s into the stream")
    time.sleep(1.5)  # stands for: an agent down a while; instanceId (its start time in s) must differ
    rec.start_agent(adapter)
    rec.get("probe_after_restart", "/probe")
    again = header_of(rec.get("current_after_restart", "/current", "new instanceId, sequences from 1"),
                      "nextSequence")
    # stands for: the machine's pace (the sleep below)
    threading.Thread(target=lambda: (time.sleep(0.4), adapter.send("exec|ACTIVE|Xact|5.0|Xcom|5.0")),
                     daemon=True).start()
    target = "/sample?from=%d&count=8%s" % (again, STREAM)
    rec.save("stream_after_restart", target, http_get(target, read_for=1.5), "the new instance streams")
    rec.get("sample_not_found", "/sample?path=//Nothing", "an error document of another kind")
    rec.stop_agent()

    with open(os.path.join(out_dir, "recording.json"), "w") as f:
        json.dump(rec.index, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
