#!/usr/bin/env python3
"""A Haas Classic's one RS-232 port carrying MDC, DPRNT and an XModem transfer (dprnt_shared_port.test).

The simulated control prints "LINE n OF 60" for n = 1..60 while haas_mdc_node polls it; after line
30 it goes into RECV and takes one program from dnc_node, then prints the rest. Every line must
reach dprnt/raw once, in order, whole, and no MDC reply may be taken for a DPRNT line. Every wait is
on a message, a service or a file the simulator writes, with a timeout.
"""
import os
import re
import threading
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray

from cnc_bridge.msg import DprntLine, MachineState
from cnc_bridge.srv import SendProgram

LINE = re.compile(r"^LINE +(\d+) +OF +60$")


class TestDprntSharedPort(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.ns = rospy.get_param("~namespace")
        cls.lock = threading.Condition()
        cls.lines = []
        cls.mdc = {}
        cls.state = None
        rospy.Subscriber(cls.ns + "/dprnt/raw", DprntLine, cls.on_line, queue_size=1000)
        rospy.Subscriber("/diagnostics", DiagnosticArray, cls.on_diagnostics, queue_size=100)
        rospy.Subscriber(cls.ns + "/state", MachineState, cls.on_state, queue_size=10)

    @classmethod
    def on_line(cls, msg):
        with cls.lock:
            cls.lines.append(msg.text)
            cls.lock.notify_all()

    @classmethod
    def on_diagnostics(cls, array):
        for status in array.status:
            if status.name.endswith(": mdc"):
                with cls.lock:
                    cls.mdc = {kv.key: kv.value for kv in status.values}
                    cls.lock.notify_all()

    @classmethod
    def on_state(cls, msg):
        with cls.lock:
            cls.state = msg
            cls.lock.notify_all()

    def wait_for(self, predicate, timeout, what):
        with self.lock:
            self.assertTrue(self.lock.wait_for(predicate, timeout), "timed out waiting for " + what)

    def test_all_three_on_one_port(self):
        # dprnt_node takes the forwarded lines before the program starts: none printed into the void.
        self.wait_for(lambda: int(self.mdc.get("DPRNT readers", "0")) >= 1, 30, "dprnt_node reading port_lines")
        self.wait_for(lambda: self.state is not None and self.state.program != "", 30, "MDC state")
        open(rospy.get_param("~start_file"), "w").close()  # CYCLE START

        self.wait_for(lambda: len(self.lines) >= 30, 30, "the first 30 DPRNT lines")
        # The control is in RECV now: the transfer takes the port, MDC and DPRNT pause.
        program = rospy.get_param("~program")
        program_dir = rospy.get_param("~program_dir")
        with open(program, "rb") as f:
            text = f.read()
        with open(os.path.join(program_dir, "O05555.nc"), "wb") as f:
            f.write(text)
        rospy.wait_for_service(self.ns + "/dnc_node/send_program", 30)
        send = rospy.ServiceProxy(self.ns + "/dnc_node/send_program", SendProgram)
        result = send(file="O05555.nc", protocol="xmodem")
        self.assertTrue(result.success, result.message)
        open(rospy.get_param("~resume_file"), "w").close()  # CYCLE START again: the program goes on

        self.wait_for(lambda: len(self.lines) >= 60, 30, "the last 30 DPRNT lines")
        # Every line once, in order, whole: no line lost, none cut, none holding a reply.
        numbers = []
        for line in self.lines:
            match = LINE.match(line)
            self.assertIsNotNone(match, "not a line of the program: %r" % line)
            numbers.append(int(match.group(1)))
        self.assertEqual(numbers, list(range(1, 61)))

        # The program arrived whole at the control.
        received = os.path.join(rospy.get_param("~haas_memory"), "received_1.nc")
        self.wait_for(lambda: os.path.exists(received), 10, "the received program")
        with open(received, "rb") as f:
            self.assertEqual(f.read(), text)

        # MDC went on around the transfer: replies answered, after the port came back too, and
        # no reply was taken for a DPRNT line (checked above).
        self.wait_for(lambda: int(self.mdc.get("port regained after a DNC transfer", "0")) >= 1, 30,
                      "MDC polling again after the transfer")
        self.wait_for(lambda: int(self.mdc["DPRNT lines forwarded"]) >= 60, 10, "the forwarded lines counted")
        answered = int(self.mdc["answered"])
        self.wait_for(lambda: int(self.mdc["answered"]) > answered, 10, "a reply after the transfer")


if __name__ == "__main__":
    rospy.init_node("test_dprnt_shared_port")
    rostest.rosrun("cnc_bridge", "dprnt_shared_port", TestDprntSharedPort)
