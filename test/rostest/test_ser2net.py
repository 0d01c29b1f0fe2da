#!/usr/bin/env python3
"""Every serial node through ser2net (test/rostest/ser2net.test says who is where).

The tests run in the order of their names: the last one kills the server. Every wait is on a
message, a service, an action result or a file, with a timeout.
"""
import glob
import os
import re
import signal
import sys
import termios
import threading
import time
import unittest

import actionlib
import rospy
import rostest

from cnc_bridge.msg import BusFrame, BusPayload, DprntLine, MachineState, TransferAction, TransferGoal
from cnc_bridge.srv import ReceiveProgram, SendProgram

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from topic_collector import Collector  # noqa: E402

WAIT = 30.0  # s: generous for a loaded machine; healthy transfers here take a few seconds
CLOSED = "closed the connection or stopped answering"


def read(path):
    with open(path, "rb") as f:
        return f.read()


def write(path, data):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as f:
        f.write(data)


def wait_for_file(path, timeout=WAIT):
    """The simulators write their files atomically (renamed into place): wait until one is there."""
    deadline = time.monotonic() + timeout
    while not os.path.exists(path) and time.monotonic() < deadline:
        time.sleep(0.05)  # polling a file another process renames into place: no event to wait on
    return os.path.exists(path)


def big_program():
    """A text program of about 6 KB: 7 s at 9600 baud, long enough to pull the server from under it."""
    lines = [b"%", b"O01000 (SER2NET RESTART)"]
    lines += [b"N%d G01 X%.4f Y%.4f F250." % (n, n * 0.01, n * 0.02) for n in range(1, 230)]
    lines += [b"M30", b"%"]
    return b"\n".join(lines) + b"\n"


def iac_program():
    """A program whose comment holds every byte value but CR, LF and SUB: 0xFF is Telnet's IAC."""
    body = bytes(b for b in range(256) if b not in (0x0A, 0x0D, 0x1A))
    return b"%\nO01234 (" + body + b")\nM30\n%\n"


class TestSer2net(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = rospy.get_param("~tmp")
        cls.states = {
            name: Collector("/cell/%s/state" % name, MachineState) for name in ("dprnt", "mdc", "bus", "xm_tcp", "shared")
        }
        cls.dprnt_lines = Collector("/cell/dprnt/dprnt/raw", DprntLine)

    def service(self, name, kind):
        rospy.wait_for_service(name, WAIT)
        return rospy.ServiceProxy(name, kind)

    def transfer_client(self, ns):
        client = actionlib.SimpleActionClient(ns + "/dnc_node/transfer", TransferAction)
        self.assertTrue(client.wait_for_server(rospy.Duration(WAIT)), ns)
        return client

    def down_index(self, name, mark):
        """The index after the first state from mark on whose link is not up."""
        collector = self.states[name]
        down = collector.wait(lambda s: s.link != MachineState.LINK_UP, WAIT, start=mark)
        self.assertIsNotNone(down, name + ": the link never went down")
        with collector.cv:
            return collector.messages.index(down, mark) + 1

    # -----------------------------------------------------------------------------------------
    def test_1_xmodem_both_ways_over_raw_tcp(self):
        program = big_program()
        write(rospy.get_param("~big_program"), program)
        receive = self.service("/cell/xm_tcp/dnc_node/receive_program", ReceiveProgram)
        answer = receive(file="from_control.nc", protocol="")
        self.assertTrue(answer.success, answer.message)
        self.assertEqual(read(self.tmp + ".programs_tcp/from_control.nc"), program)

        haas = read(rospy.get_param("~haas_program"))
        write(self.tmp + ".programs_tcp/O05555.nc", haas)
        send = self.service("/cell/xm_tcp/dnc_node/send_program", SendProgram)
        answer = send(file="O05555.nc", protocol="")
        self.assertTrue(answer.success, answer.message)
        self.assertTrue(wait_for_file(self.tmp + ".control_tcp/O05555.nc"))
        self.assertEqual(read(self.tmp + ".control_tcp/O05555.nc"), haas)

    def test_2_binary_program_with_iac_both_ways_over_rfc2217(self):
        program = iac_program()
        write(self.tmp + ".rfc_program.nc", program)  # what the control sends when asked
        write(self.tmp + ".programs_rfc/O01234.nc", program)
        send = self.service("/cell/xm_rfc/dnc_node/send_program", SendProgram)
        answer = send(file="O01234.nc", protocol="")
        self.assertTrue(answer.success, answer.message)
        self.assertTrue(wait_for_file(self.tmp + ".control_rfc/O01234.nc"))
        self.assertEqual(read(self.tmp + ".control_rfc/O01234.nc"), program)

        receive = self.service("/cell/xm_rfc/dnc_node/receive_program", ReceiveProgram)
        answer = receive(file="from_control.bin", protocol="")
        self.assertTrue(answer.success, answer.message)
        got = read(self.tmp + ".programs_rfc/from_control.bin")
        # ~binary keeps the bytes exactly, XModem's padding (SUB to the end of the block) too.
        self.assertEqual(got[: len(program)], program)
        self.assertEqual(len(got) % 128, 0)
        self.assertEqual(set(got[len(program):]), {0x1A} if len(got) > len(program) else set())

    def test_3_line_settings_on_the_pty_are_the_nodes(self):
        # xm_rfc's node (115200 baud, 2 stop bits, no flow control) keeps its connection open after
        # the transfers above; the server's own setting for that port is 9600 8N1. The pty keeps the
        # speed, the stop bits and the flow control; a Linux pty forces 8 data bits and no parity
        # whatever is set, so those two are checked on the server's answers (test_network_serial_line).
        fd = os.open(os.path.realpath(rospy.get_param("~xm_rfc")), os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        try:
            iflag, _, cflag, _, ispeed, ospeed, _ = termios.tcgetattr(fd)
        finally:
            os.close(fd)
        self.assertEqual(ospeed, termios.B115200)
        self.assertEqual(ispeed, termios.B115200)
        self.assertTrue(cflag & termios.CSTOPB, "2 stop bits")
        self.assertFalse(cflag & termios.CRTSCTS, "no RTS/CTS")
        self.assertFalse(iflag & termios.IXON, "no XON/XOFF")

    def test_4_drip_feeds_with_xoff_over_both(self):
        program = read(rospy.get_param("~drip_program_path"))
        clients = {name: self.transfer_client("/cell/" + name) for name in ("drip_rfc", "drip_tcp")}
        for client in clients.values():
            client.send_goal(TransferGoal(direction="send", protocol="drip", file=rospy.get_param("~drip_program")))
        for name, client in clients.items():
            self.assertTrue(client.wait_for_result(rospy.Duration(60)), name)
            result = client.get_result()
            self.assertTrue(result.success, "%s: %s" % (name, result.message))
            stats_path = "%s.%s.stats" % (self.tmp, name)
            self.assertTrue(wait_for_file(stats_path), name)
            stats = read(stats_path).decode()
            print("%s: sim_haas_serial drip: %s" % (name, stats))
            self.assertIn("program complete", stats, name)
            # The control's buffer filled: it sent XOFF (DC3) and the feed held until its XON.
            xoff = int(re.search(r"xoff (\d+)", stats).group(1))
            self.assertGreater(xoff, 0, "%s: no XOFF event: %s" % (name, stats))
            self.assertEqual(read("%s.%s.received" % (self.tmp, name)), program, name)

    def test_5_dprnt_lines_arrive(self):
        line = self.dprnt_lines.wait(lambda m: "X" in m.text or "Z" in m.text, WAIT)
        self.assertIsNotNone(line, "no DPRNT line through the device server")
        self.assertEqual(line.machine, "dprnt")

    def test_6_mdc_queries_answered(self):
        state = self.states["mdc"].wait(
            lambda s: s.link == MachineState.LINK_UP and s.mode != MachineState.MODE_UNKNOWN, WAIT
        )
        self.assertIsNotNone(state, "no MDC status through the device server")

    def test_7_slave_bus_step_delivered(self):
        publisher = rospy.Publisher("/cell/bus/bus/frame", BusFrame, queue_size=1)
        deadline = time.monotonic() + WAIT
        while publisher.get_num_connections() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)  # polling the connection count: rospy offers no wait for it
        self.assertTrue(self.states["bus"].wait(lambda s: s.link == MachineState.LINK_UP, WAIT))
        publisher.publish(BusFrame(payloads=[BusPayload(address=1, data=[0x01, 0x2C])]))
        deliveries = rospy.get_param("~deliveries")
        while time.monotonic() < deadline:
            if os.path.exists(deliveries) and "1 012c" in read(deliveries).decode().split("\n"):
                return
            time.sleep(0.05)  # polling the simulator's log file: no event to wait on
        self.fail("the step did not reach the slave: %r" % (read(deliveries) if os.path.exists(deliveries) else None))

    def test_8_a_second_client_is_refused_and_says_so(self):
        # haas_mdc_node holds the MDC port; ser2net serves a port to one client at a time.
        self.assertTrue(self.states["mdc"].wait(lambda s: s.link == MachineState.LINK_UP, WAIT))
        write(self.tmp + ".programs_second/O02000.nc", b"%\nO02000 (SECOND CLIENT)\nM30\n%\n")
        send = self.service("/cell/mdc/second/dnc_node/send_program", SendProgram)
        answer = send(file="O02000.nc", protocol="")
        self.assertFalse(answer.success)
        self.assertIn("another client holds it", answer.message)
        # The holder keeps its line: the MDC node is still up and answered after the refusal.
        mark = self.states["mdc"].count()
        self.assertIsNotNone(
            self.states["mdc"].wait(lambda s: s.link == MachineState.LINK_UP, WAIT, start=mark),
            "the MDC node lost its line to the refused client",
        )
        queries = self.tmp + ".mdc_queries"
        if os.path.exists(queries):
            self.assertNotIn("O02000", read(queries).decode(errors="replace"))

    def test_8b_nodes_sharing_a_port_for_two_clients_take_turns(self):
        # dnc_node connects for its transfer while haas_mdc_node holds its own connection: the server
        # takes both, the port lock keeps their bytes apart. The control here is an MDC-only one, so the
        # send ends waiting for its NAK, not refused by the server.
        self.assertTrue(self.states["shared"].wait(lambda s: s.link == MachineState.LINK_UP, WAIT))
        write(self.tmp + ".programs_shared/O02001.nc", b"%\nO02001 (SHARED)\nM30\n%\n")
        send = self.service("/cell/shared/dnc/dnc_node/send_program", SendProgram)
        answer = send(file="O02001.nc", protocol="")
        self.assertFalse(answer.success)
        self.assertNotIn("another client", answer.message)
        self.assertIn("NAK", answer.message)
        mark = self.states["shared"].count()
        self.assertIsNotNone(
            self.states["shared"].wait(
                lambda s: s.link == MachineState.LINK_UP and s.mode != MachineState.MODE_UNKNOWN, WAIT, start=mark
            ),
            "the MDC node did not go on polling after the transfer",
        )

    def test_9_server_restart_mid_transfer(self):
        programs = self.tmp + ".programs_tcp"
        marks = {name: collector.count() for name, collector in self.states.items()}
        client = self.transfer_client("/cell/xm_tcp")
        started = threading.Event()

        def feedback(f):
            if f.bytes >= 1024:
                started.set()

        client.send_goal(TransferGoal(direction="receive", protocol="xmodem", file="restart.nc"), feedback_cb=feedback)
        self.assertTrue(started.wait(WAIT), "the receive did not start")
        with open(rospy.get_param("~pid_file")) as f:
            pid = int(f.read().split()[0])
        os.kill(pid, signal.SIGKILL)  # the device server switched off mid-transfer

        self.assertTrue(client.wait_for_result(rospy.Duration(WAIT)))
        result = client.get_result()
        self.assertFalse(result.success)
        self.assertIn(CLOSED, result.message)
        self.assertEqual(glob.glob(programs + "/restart*") + glob.glob(programs + "/.restart*"), [])

        # The reconnecting nodes say the link went down and why, then come back with the server
        # (roslaunch starts it again after respawn_delay).
        for name in ("dprnt", "mdc", "bus"):
            collector = self.states[name]
            after_down = self.down_index(name, marks[name])
            up = collector.wait(lambda s: s.link == MachineState.LINK_UP, WAIT, start=after_down)
            self.assertIsNotNone(up, name + ": the link did not come back")
            with collector.cv:
                outage = collector.messages[marks[name] : collector.messages.index(up, after_down)]
            reasons = {s.message for s in outage if s.link != MachineState.LINK_UP}
            self.assertTrue(any(CLOSED in r for r in reasons), "%s: the state did not say why: %s" % (name, reasons))
        # A transfer after the restart works again. The control still sends the broken one until
        # its own timeouts run out and it cancels (CAN CAN): a receive that meets that cancel is
        # run again, as an operator would.
        receive = self.service("/cell/xm_tcp/dnc_node/receive_program", ReceiveProgram)
        for attempt in range(3):
            answer = receive(file="after_restart.nc", protocol="")
            if answer.success or "cancelled" not in answer.message:
                break
        self.assertTrue(answer.success, answer.message)
        self.assertEqual(read(programs + "/after_restart.nc"), read(rospy.get_param("~big_program")))


if __name__ == "__main__":
    rospy.init_node("test_ser2net")
    rostest.rosrun("cnc_bridge", "ser2net", TestSer2net)
