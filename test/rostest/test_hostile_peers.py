#!/usr/bin/env python3
"""Hostile peers (test/rostest/hostile_peers.test): each TCP protocol's node (ethernut_node,
at_controller_node, haas_mdc_node, dprnt_node), and slave_bus_node, a Classic's haas_mdc_node and
dprnt_node over a pty, connects to a fake peer played by this test that
floods it with garbage, sends one oversize frame, sends malformed frames, closes in the middle of a
frame and accepts without ever answering. After each: the node is alive, its resident memory (read
from /proc) stays below RSS_BOUND_MB, and its state's link says the link is not up once the peer has
gone, with a message."""
import os
import random
import select
import socket
import sys
import threading
import time
import tty
import unittest
import xmlrpc.client

import rosgraph
import rosnode
import rospy
import rostest

from cnc_bridge.msg import MachineState

RSS_BOUND_MB = 400  # a node that buffered the flood would hold hundreds of MB more
FLOOD_SECONDS = 3.0
OVERSIZE_BYTES = 16 * 1024 * 1024


def rss_mb(pid):
    with open("/proc/%d/status" % pid) as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return 0.0


def node_pid(name):
    uri = rosgraph.Master("/test_hostile_peers").lookupNode(name)
    _, _, pid = xmlrpc.client.ServerProxy(uri).getPid("/test_hostile_peers")
    return pid


class Peer:
    """A listening socket on 127.0.0.1:port; accept() hands over the next connection the node makes."""

    def __init__(self, port):
        self.server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.server.bind(("127.0.0.1", port))
        self.server.listen(4)

    def accept(self, timeout=30.0):
        self.server.settimeout(timeout)
        conn, _ = self.server.accept()
        conn.settimeout(5.0)
        return conn


class PtyConnection:
    """The master side of a pty, used like a socket by the cases: what the node writes is read and
    dropped (so that its writes never block), what is sent goes to the node."""

    def __init__(self, master, slave):
        self.master, self.slave = master, slave
        os.set_blocking(master, False)

    def drain(self):
        try:
            while os.read(self.master, 65536):
                pass
        except (BlockingIOError, OSError):
            pass

    def send(self, data):
        self.drain()
        end = time.monotonic() + 5.0
        while True:
            try:
                return os.write(self.master, data)
            except BlockingIOError:  # the node is not reading: wait for it as a socket would
                if time.monotonic() > end:
                    raise socket.timeout()
                time.sleep(0.01)  # poll: a full pty buffer has no event to wait on here
                self.drain()

    def sendall(self, data):
        while data:
            data = data[self.send(data):]

    def close(self):
        os.close(self.master)
        os.close(self.slave)


class PtyPeer:
    """A serial peer: a new pty for each case, its device linked at the path the node opens."""

    def __init__(self, link, wait_up):
        self.link, self.wait_up = link, wait_up

    def accept(self):
        master, slave = os.openpty()
        tty.setraw(slave)
        tmp = self.link + ".new"
        os.symlink(os.ttyname(slave), tmp)
        os.replace(tmp, self.link)
        if self.wait_up:
            self.wait_up()  # the node reopens the link by itself (it retries after a backoff)
        else:
            # A polling node (a Classic's MDC) has the port open once its first query arrives.
            ready, _, _ = select.select([master], [], [], 30.0)
            if not ready:
                raise AssertionError("the node did not open %s and query within 30 s" % self.link)
        return PtyConnection(master, slave)


def send_for(conn, seconds, make_chunk):
    """Sends chunks for `seconds` (or until the node stops reading: a full send buffer times out)."""
    end = time.monotonic() + seconds
    sent = 0
    while time.monotonic() < end:
        try:
            sent += conn.send(make_chunk())
        except (socket.timeout, BrokenPipeError, ConnectionResetError):
            break
    return sent


class HostilePeers(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("test_hostile_peers")
        cls.ns = rospy.get_param("~namespace")
        cls.states = {}
        cls.lock = threading.RLock()
        cls.changed = threading.Condition(cls.lock)  # notified with every state recorded
        cls.subs = []

    def watch(self, node):
        def keep(msg):
            with self.changed:
                self.states[node] = msg
                self.changed.notify_all()

        self.subs.append(rospy.Subscriber("%s/state" % self.machine(node), MachineState, keep))

    # Each case's node: its machine's namespace (the state topic is <namespace>/state) and its name.
    MACHINES = {"ethernut_node": ("router", "ethernut_node"), "at_controller_node": ("at", "at_controller_node"),
                "haas_mdc_node": ("mdc", "haas_mdc_node"), "dprnt_node": ("dprnt", "dprnt_node"),
                "slave_bus_node": ("laser", "slave_bus_node"),
                "haas_mdc_node (serial)": ("classic", "haas_mdc_node"),
                "dprnt_node (serial)": ("dprnt_serial", "dprnt_node")}

    def machine(self, node):
        """The namespace of `node` (each has its own: the state topic is <namespace>/state)."""
        return "%s/%s" % (self.ns, self.MACHINES[node][0])

    def full_name(self, node):
        return "%s/%s" % (self.machine(node), self.MACHINES[node][1])

    def state(self, node):
        with self.lock:
            return self.states.get(node)

    def wait_for(self, what, predicate, timeout=20.0):
        # The predicates read the states the subscriber thread records: each one recorded wakes it.
        with self.changed:
            if not self.changed.wait_for(predicate, timeout):
                self.fail("timed out waiting for " + what)

    def assert_well(self, node, pid, after):
        self.assertTrue(rosnode.rosnode_ping(self.full_name(node), max_count=1, verbose=False),
                        "%s died after %s" % (node, after))
        self.assertTrue(os.path.exists("/proc/%d" % pid), "%s died after %s" % (node, after))
        rss = rss_mb(pid)
        self.assertLess(rss, RSS_BOUND_MB, "%s holds %.0f MB after %s" % (node, rss, after))
        print("%s after %s: alive, %.0f MB resident" % (node, after, rss))

    def assert_link_not_up(self, node, after):
        self.wait_for("%s's link to leave UP after %s" % (node, after),
                      lambda: self.state(node) is not None and self.state(node).link != MachineState.LINK_UP)

    def run_peer(self, node, port, frame, extra_ports=(), pty_link=None, oversize_bytes=OVERSIZE_BYTES, polling=False):
        """The five hostile peers in turn against `node`; `frame` is one well-formed-looking frame of
        its protocol (for the malformed and mid-frame cases). The port listens only while a case
        runs, so that between cases the node's reconnects are refused and its link shows it."""
        self.watch(node)
        extra = [Peer(p) for p in extra_ports]  # e.g. the '@' report port: accepted, silent
        held = []
        for p in extra:
            threading.Thread(target=lambda p=p: held.append(p.accept(60)), daemon=True).start()
        pid = node_pid(self.full_name(node))
        rng = random.Random(26)

        def link_up():
            self.wait_for(node + "'s link up",
                          lambda: self.state(node) is not None and self.state(node).link == MachineState.LINK_UP)

        def case(what, act, link_goes_down=True):
            if pty_link:
                conn = PtyPeer(pty_link, None if polling else link_up).accept()
            else:
                peer = Peer(port)
                conn = peer.accept()
                peer.server.close()
            detail = act(conn)
            conn.close()
            self.assert_well(node, pid, what + detail)
            if link_goes_down:
                self.assert_link_not_up(node, what)
                self.assertTrue(self.state(node).message, "%s: the link state says nothing after %s" % (node, what))
                print("  link %d: %s" % (self.state(node).link, self.state(node).message))

        def flood(conn):
            return " (%d bytes)" % send_for(conn, FLOOD_SECONDS, lambda: rng.randbytes(4096))

        def oversize(conn):
            total = 0
            while total < oversize_bytes:
                try:
                    total += conn.send(b"A" * 65536)
                except (socket.timeout, BrokenPipeError, ConnectionResetError):
                    break
            return " (%d bytes)" % total

        def malformed(conn):
            bad = [frame[: len(frame) // 2] + b"\xff\x00\xfe" + frame[len(frame) // 2:], frame[::-1], b"\x00" * 64,
                   frame.replace(b",", b",,,,")]
            for _ in range(200):
                try:
                    conn.sendall(rng.choice(bad))
                except (socket.timeout, BrokenPipeError, ConnectionResetError):
                    break
            return ""

        def mid_frame(conn):
            try:
                conn.sendall(frame[: max(1, len(frame) // 2)])
            except OSError:
                pass
            return ""

        def silent(conn):
            rospy.sleep(3.0)  # under test: a peer that never answers, for a span of time
            return ""

        case("a flooding peer", flood)
        case("a frame without an end", oversize)
        case("malformed frames", malformed)
        case("a peer that closed mid-frame", mid_frame)
        case("a peer that never answers", silent)
        for p in extra:
            p.server.close()
        for c in held:
            c.close()

    def test_ethernut_node(self):
        self.run_peer("ethernut_node", 23691, b"\x0f\x0f\x00\x00\x00\x00\x00\x00")

    def test_at_controller_node(self):
        # The node reads the report link (the command link it only writes): the hostile peer plays
        # the report side, the command side is accepted and stays silent.
        self.run_peer("at_controller_node", 23341, b"45334 34623 54934\n", extra_ports=(23340,))

    def test_haas_mdc_node(self):
        self.run_peer("haas_mdc_node", 15173, b"\x02PROGRAM, O00110, IDLE, PARTS, 4523\x17\r\n")

    def test_dprnt_node(self):
        self.run_peer("dprnt_node", 23293, b"X0.1234 Y-0.5678 Z0.0012\r\n")

    def test_slave_bus_node(self):
        # Serial: the peer is the master side of a pty (the uplink of the slave-bus master).
        self.run_peer("slave_bus_node", None, b"\x7e\x01\x04\xd2\x00\x55\x7e",
                      pty_link=rospy.get_param("~slave_link"), oversize_bytes=1024 * 1024)  # a pty moves ~200 KB/s

    def test_haas_mdc_node_serial(self):
        # A Classic's MDC over RS-232: the node polls, so a case starts once its first query arrives
        # (its link is up only after an answer, which a hostile peer never gives).
        self.run_peer("haas_mdc_node (serial)", None, b"\x02PROGRAM, O00110, IDLE, PARTS, 4523\x17\r\n",
                      pty_link=rospy.get_param("~mdc_link"), oversize_bytes=1024 * 1024, polling=True)

    def test_dprnt_node_serial(self):
        self.run_peer("dprnt_node (serial)", None, b"X0.1234 Y-0.5678 Z0.0012\r\n",
                      pty_link=rospy.get_param("~dprnt_link"), oversize_bytes=1024 * 1024)


if __name__ == "__main__":
    rostest.rosrun("cnc_bridge", "test_hostile_peers", HostilePeers, sys.argv)