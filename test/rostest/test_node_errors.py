#!/usr/bin/env python3
"""Nodes refuse parameters they cannot use the same way: exit status 1 and one FATAL line
"<node>: <what is wrong>" naming the parameter (cnc_bridge::runNode, params::tcpPort/choice)."""
import os
import re
import subprocess
import sys
import unittest

import rostest


def start(node, *params):
    """Runs `node` in a namespace of its own with private `params` ("name:=value"); returns its exit
    status and its output. A node that accepts the parameters keeps running: it is stopped after
    20 s and the test fails on the status."""
    name = f"{node}_errors"
    args = ["rosrun", "cnc_bridge", node, "__ns:=/node_errors", f"__name:={name}"] + [f"_{p}" for p in params]
    try:
        done = subprocess.run(args, capture_output=True, text=True, timeout=20,
                              env=dict(os.environ, ROSCONSOLE_FORMAT="[${severity}] ${message}"))
    except subprocess.TimeoutExpired as running:
        return None, (running.stdout or b"").decode() + (running.stderr or b"").decode()
    return done.returncode, done.stdout + done.stderr


class NodeErrors(unittest.TestCase):
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
        self.assertRefused("at_controller_node", ["report_mode:=sideways"],
                           "report_mode must be one of client, server, not 'sideways'")
        self.assertRefused("ethernut_node", ["host:=127.0.0.1", "g53_moves:=ignore"],
                           "g53_moves must be one of refuse, skip, not 'ignore'")

    def test_a_missing_required_parameter(self):
        self.assertRefused("dnc_node", [], "/node_errors/dnc_node_errors/port")


if __name__ == "__main__":
    rostest.rosrun("cnc_bridge", "test_node_errors", NodeErrors, sys.argv)
