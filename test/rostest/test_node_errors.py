#!/usr/bin/env python3
"""Nodes refuse parameters they cannot use the same way: exit status 1 and one FATAL line
"<node>: <what is wrong>" naming the parameter (cnc_bridge::runNode, params::tcpPort/choice); a
required parameter left out (a serial port, a program folder, an address) is named with the
launch argument that sets it, and the launch files give it no stand-in value."""
import os
import re
import shutil
import subprocess
import sys
import tempfile
import unittest

import rosgraph
import rostest
import yaml


def start(node, *params):
    """Runs `node` in a namespace of its own with private `params` ("name:=value"); returns its exit
    status and its output. A node that accepts the parameters keeps running: it is stopped after
    20 s and the test fails on the status."""
    name = f"{node}_errors"
    # Private parameters stay on the master after the node: start each run without the last one's.
    master = rosgraph.Master("/test_node_errors")
    if master.hasParam(f"/node_errors/{name}"):
        master.deleteParam(f"/node_errors/{name}")
    args = ["rosrun", "cnc_bridge", node, "__ns:=/node_errors", f"__name:={name}"] + [f"_{p}" for p in params]
    try:
        done = subprocess.run(args, capture_output=True, text=True, timeout=20,
                              env=dict(os.environ, ROSCONSOLE_FORMAT="[${severity}] ${message}"))
    except subprocess.TimeoutExpired as running:
        return None, (running.stdout or b"").decode() + (running.stderr or b"").decode()
    return done.returncode, done.stdout + done.stderr


def dump_params(launch, *args):
    """The parameters `roslaunch cnc_bridge <launch> <args>` would set, without starting anything."""
    done = subprocess.run(["roslaunch", "--dump-params", "cnc_bridge", launch] + list(args),
                          capture_output=True, text=True, timeout=60, check=True)
    return yaml.safe_load(done.stdout)


class NodeErrors(unittest.TestCase):
    def setUp(self):
        self.scratch = tempfile.mkdtemp(prefix="cnc_node_errors_")

    def tearDown(self):
        shutil.rmtree(self.scratch, ignore_errors=True)

    def assertRefused(self, node, params, *expected):
        status, output = start(node, *params)
        self.assertEqual(status, 1, f"{node} {params}: exit status {status}, output:\n{output}")
        plain = re.sub(r"\x1b\[[0-9;]*m", "", output)  # rosconsole colours its lines
        fatal = [line for line in plain.splitlines() if line.startswith("[FATAL]")]
        self.assertEqual(len(fatal), 1, f"{node}: one FATAL line expected:\n{output}")
        self.assertIn(f"/node_errors/{node}_errors: ", fatal[0])
        for text in expected:
            self.assertIn(text, fatal[0])

    def test_a_tcp_port_out_of_range(self):
        self.assertRefused("dprnt_node", ["input:=tcp", "host:=127.0.0.1", "tcp_port:=70000"],
                           "/node_errors/dprnt_node_errors/tcp_port must be a TCP port (1..65535), not 70000")
        self.assertRefused("haas_mdc_node", ["host:=127.0.0.1", "tcp_port:=0"],
                           "/node_errors/haas_mdc_node_errors/tcp_port must be a TCP port (1..65535), not 0")

    def test_a_choice_not_offered(self):
        self.assertRefused("at_controller_node", ["host:=127.0.0.1", "report_mode:=sideways"],
                           "report_mode must be one of client, server, not 'sideways'")
        self.assertRefused("ethernut_node", ["host:=127.0.0.1", "g53_moves:=ignore"],
                           "g53_moves must be one of refuse, skip, not 'ignore'")

    def test_a_link_parameter_that_cannot_be_used(self):
        """A serial port that is neither a device nor a device server's address, or a line setting
        out of range, stops the node at start naming the parameter (params::serialLink), instead of
        a link that fails at every reconnection."""
        self.assertRefused("slave_bus_node", ["port:=telnet2://10.0.0.5:23"],
                           "/node_errors/slave_bus_node_errors/port: serial port 'telnet2://10.0.0.5:23': "
                           "unknown kind of link")
        self.assertRefused("dprnt_node", ["input:=serial", "port:=/dev/null", "stop_bits:=3"],
                           "/node_errors/dprnt_node_errors/stop_bits must be 1..2, not 3")
        self.assertRefused("haas_mdc_node", ["port:=/dev/null", "parity:=mark"],
                           "/node_errors/haas_mdc_node_errors/parity: parity must be none, even or odd, not 'mark'")

    def assertRequired(self, node, params, parameter):
        """`node` without `parameter` stops, naming its resolved name and the launch argument."""
        self.assertRefused(node, params,
                           f"Required parameter /node_errors/{node}_errors/{parameter} not given",
                           f"the launch argument {parameter}:=... of {node}.launch")

    def test_a_missing_required_parameter(self):
        # A serial device: no /dev/ttyUSB0 taken for granted.
        self.assertRequired("dnc_node", [], "port")
        self.assertRequired("slave_bus_node", [], "port")
        self.assertRequired("dprnt_node", ["input:=serial"], "port")
        # A program folder: no $HOME/nc_programs taken for granted.
        self.assertRequired("dnc_node", ["port:=/dev/null"], "program_dir")
        self.assertRequired("share_node", [f"url:={self.scratch}"], "program_dir")
        # An address: no 127.0.0.1 taken for granted.
        self.assertRequired("at_controller_node", [], "host")
        self.assertRequired("haas_mdc_node", [], "host")
        self.assertRequired("dprnt_node", ["input:=tcp"], "host")
        self.assertRequired("ethernut_node", [], "host")

    def test_launch_files_leave_required_parameters_unset(self):
        """The node launch files give no stand-in value for a required parameter: left out, it
        reaches the node unset (and stops it, above); given as the argument, it is set."""
        cases = [("dnc_node", "dnc_node", ["port", "program_dir"]),
                 ("share_node", "share_node", ["program_dir"]),
                 ("slave_bus_node", "slave_bus_node", ["port"]),
                 ("dprnt_node", "dprnt_node", ["port", "host", "tcp_port", "file"]),
                 ("at_controller_node", "at_controller_node", ["host"]),
                 ("haas_mdc_node", "haas_mdc_node", ["host", "port"])]
        for launch, node, required in cases:
            with self.subTest(launch=launch):
                unset = dump_params(f"{launch}.launch")
                self.assertTrue(any(name.startswith(f"/{node}/") for name in unset), unset)
                for parameter in required:
                    self.assertNotIn(f"/{node}/{parameter}", unset)
                given = dump_params(f"{launch}.launch", *[f"{p}:=given_{p}" for p in required])
                for parameter in required:
                    self.assertEqual(given.get(f"/{node}/{parameter}"), f"given_{parameter}")


if __name__ == "__main__":
    rostest.rosrun("cnc_bridge", "test_node_errors", NodeErrors, sys.argv)
