#!/usr/bin/env python3
"""The serial control profiles reach the driver, and a port that cannot be opened is explained: dnc_node, started through launch/dnc_node.launch
with params_file:=config/controls/<profile>.yaml and a pty as its port (keep_open, so the port is
opened at start-up), must leave the pty's termios as the profile says: baud rate in and out, stop
bits and the flow control the kernel does. A pty keeps 8 data bits and no parity whatever it is
told (the driver asks again without them, see src/core/transport/serial_port.cpp), so those two are
checked as what a pty shows, and against the profile in test/scripts/test_launch_files.py."""
import os
import pty
import signal
import subprocess
import sys
import tempfile
import termios
import unittest

import rospy
import yaml

from cnc_bridge.msg import MachineState

SPEEDS = {4800: termios.B4800, 9600: termios.B9600, 19200: termios.B19200, 38400: termios.B38400,
          57600: termios.B57600, 115200: termios.B115200}
# Profiles of controls on RS-232 that dnc_node serves.
DNC_PROFILES = ["haas_classic_rs232", "haas_classic_rs232_7e1", "fanuc_0i_rs232", "fanuc_0i_rs232_7n2"]


class ControlProfilesOnAPty(unittest.TestCase):
    def setUp(self):
        self.package = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        self.scratch = tempfile.mkdtemp(prefix="cnc_profiles_")

    def start_node(self, namespace, profile, link):
        command = ["roslaunch", "cnc_bridge", "dnc_node.launch", "params_file:=" + profile, "port:=" + link,
                   "keep_open:=true", "program_dir:=" + self.scratch, "machine:=" + namespace]
        env = dict(os.environ, ROS_NAMESPACE="/profiles/" + namespace)
        log = open(os.path.join(self.scratch, namespace + ".log"), "w")
        return subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True), log

    def wait_link_up(self, namespace):
        deadline = rospy.Time.now() + rospy.Duration(30)
        while not rospy.is_shutdown() and rospy.Time.now() < deadline:
            state = rospy.wait_for_message("/profiles/%s/state" % namespace, MachineState, timeout=30)
            if state.link == MachineState.LINK_UP:
                return
        self.fail("dnc_node with profile %s did not open its port" % namespace)

    def test_serial_profiles_reach_the_pty(self):
        for name in DNC_PROFILES:
            with self.subTest(profile=name):
                path = os.path.join(self.package, "config", "controls", name + ".yaml")
                with open(path) as f:
                    profile = yaml.safe_load(f)
                master, slave = pty.openpty()
                link = os.path.join(self.scratch, name + ".pty")
                os.symlink(os.ttyname(slave), link)
                # What the pty shows before: 38400 baud, not the profile's rate.
                before = termios.tcgetattr(slave)
                self.assertNotEqual(before[4], SPEEDS[profile["baud"]])
                process, log = self.start_node(name, path, link)
                try:
                    self.wait_link_up(name)
                    iflag, _, cflag, _, ispeed, ospeed, _ = termios.tcgetattr(slave)
                    self.assertEqual((ispeed, ospeed), (SPEEDS[profile["baud"]],) * 2, "baud rate")
                    self.assertEqual(bool(cflag & termios.CSTOPB), profile["stop_bits"] == 2, "stop bits")
                    kernel_xonxoff = profile.get("flow_control", "none") == "xonxoff"
                    self.assertEqual(bool(iflag & termios.IXON), kernel_xonxoff, "XON/XOFF in the kernel")
                    self.assertEqual(bool(cflag & termios.CRTSCTS), profile.get("flow_control") == "rtscts")
                    # What a pty keeps of character size and parity, whatever was asked.
                    self.assertEqual(cflag & termios.CSIZE, termios.CS8)
                    self.assertFalse(cflag & termios.PARENB)
                finally:
                    os.killpg(process.pid, signal.SIGINT)
                    process.wait(timeout=20)
                    log.close()
                    os.close(master)
                    os.close(slave)

    def test_start_up_error_explains_a_missing_port(self):
        """The node's start-up error says why, in words: the same explanation as cnc_dnc doctor."""
        missing = os.path.join(self.scratch, "ttyUSB9")
        path = os.path.join(self.package, "config", "controls", "haas_classic_rs232.yaml")
        process, log = self.start_node("missing", path, missing)
        try:
            deadline = rospy.Time.now() + rospy.Duration(30)
            message = ""
            while not rospy.is_shutdown() and rospy.Time.now() < deadline and "does not exist" not in message:
                state = rospy.wait_for_message("/profiles/missing/state", MachineState, timeout=30)
                message = state.message
            self.assertEqual(state.link, MachineState.LINK_DOWN)
            self.assertIn(missing + " does not exist", message)
            self.assertIn("/dev/serial/by-id", message)
        finally:
            os.killpg(process.pid, signal.SIGINT)
            process.wait(timeout=20)
            log.close()


if __name__ == "__main__":
    import rostest
    rospy.init_node("test_control_profiles")
    rostest.rosrun("cnc_bridge", "control_profiles", ControlProfilesOnAPty, sys.argv)
