"""An MTConnect agent made of recorded answers (test/data/mtconnect/, from cppagent v1.8.0.3).

Each connection gets the next step of a script: the client's request is read, compared with the
request the recording answered (recording.json), and the recorded bytes are sent back unchanged
(status line, headers, chunked framing, multipart boundaries), then the connection is closed, as
the reference agent closes it. A stream recorded until it was cut is replayed cut. Past the last
step the server stops listening, so the client finds the agent gone.
"""
import json
import os
import socket
import threading


class ReplayAgent:
    def __init__(self, data_dir, steps, port, host="127.0.0.1"):
        with open(os.path.join(data_dir, "recording.json")) as f:
            self.requests = {e["file"]: e["request"][4:] for e in json.load(f)}
        self.answers = [(name, self.requests[name + ".http"], open(os.path.join(data_dir, name + ".http"), "rb").read())
                        for name in steps]
        self.lock = threading.Condition()
        self.served = []      # (step name, the client's request target)
        self.mismatches = []  # requests that are not the recorded ones
        self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.server.bind((host, port))
        self.server.listen(4)
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self):
        for name, recorded, answer in self.answers:
            peer, _ = self.server.accept()
            with peer:
                target = self.read_request(peer)
                with self.lock:
                    self.served.append((name, target))
                    if target != recorded:
                        self.mismatches.append("%s: asked %s, recorded %s" % (name, target, recorded))
                    self.lock.notify_all()
                try:
                    peer.settimeout(10.0)
                    peer.sendall(answer)
                    peer.shutdown(socket.SHUT_WR)
                    while peer.recv(65536):  # until the client closes: nothing of the answer is lost
                        pass
                except OSError:
                    pass  # the client left mid-answer (it stops reading a stream after a gap)
        self.server.close()
        with self.lock:
            self.lock.notify_all()

    @staticmethod
    def read_request(peer):
        data = b""
        while b"\r\n\r\n" not in data:
            chunk = peer.recv(4096)
            if not chunk:
                break
            data += chunk
        line = data.split(b"\r\n", 1)[0].decode("latin-1").split(" ")
        return line[1] if len(line) > 1 else ""

    def wait_done(self, timeout):
        with self.lock:
            return self.lock.wait_for(lambda: len(self.served) == len(self.answers), timeout)
