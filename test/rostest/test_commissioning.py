#!/usr/bin/env python3
"""docs/COMMISSIONING.md as a new user follows it, with simulators standing in for the machines:
every command block of the page (```sh after a `<!-- block: NAME -->` line) is run as written,
in order, after replacing the machine's addresses with the simulators' (the serial devices with
their ptys, 192.168.1.50 with the loopback address, the control's TCP ports with free ones), and
must end with exit status 0 and print what the page promises. A block of the page that this test
does not know, or a known block missing from the page, fails the test."""
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
import unittest

import rospy

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
PAGE = os.path.join(ROOT, "docs", "COMMISSIONING.md")
BLOCK = re.compile(r"<!-- block: (\w+) -->\n```sh\n(.*?)```", re.S)
# The simulator repeats config/dprnt/grid_probe.nc, so `rostopic echo -n1` may catch any of its
# lines: a PROBE line most of the time, but also the lines before and after the grid.
DPRNT_LINE = re.compile(r'text: "(X *1\.5436 Z|CYCLE START|PROBE X|Z OFFSET IS|MACHINE X|CYCLE END)')


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def page_blocks():
    with open(PAGE) as f:
        return BLOCK.findall(f.read())


class Commissioning(unittest.TestCase):
    def setUp(self):
        self.scratch = tempfile.mkdtemp(prefix="cnc_commissioning_")
        self.background = []
        self.sim_dir = os.path.join(ROOT, ".build", "devel", "lib", "cnc_bridge")
        for path in os.environ.get("CMAKE_PREFIX_PATH", "").split(":"):
            if os.path.exists(os.path.join(path, "lib", "cnc_bridge", "sim_haas_serial")):
                self.sim_dir = os.path.join(path, "lib", "cnc_bridge")
                break

    def tearDown(self):
        """Stops every process group started: a block's shell has ended, but the roslaunch it put
        in the background lives on in its group until stopped, and would answer the next block."""
        for process, log in reversed(self.background):
            for sig, grace in ((signal.SIGINT, 20), (signal.SIGKILL, 5)):
                try:
                    os.killpg(process.pid, sig)
                except ProcessLookupError:
                    break
                deadline = time.monotonic() + grace
                while time.monotonic() < deadline and self.group_alive(process):
                    time.sleep(0.1)  # polling for the group's last process to end
                if not self.group_alive(process):
                    break
            process.wait()
            log.close()

    @staticmethod
    def group_alive(process):
        process.poll()
        try:
            os.killpg(process.pid, 0)
            return True
        except ProcessLookupError:
            return False

    # -- the simulated machines ------------------------------------------------------------
    def start(self, name, argv):
        log = open(os.path.join(self.scratch, name + ".log"), "w")
        process = subprocess.Popen([os.path.join(self.sim_dir, argv[0])] + argv[1:], stdout=log,
                                   stderr=subprocess.STDOUT, cwd=self.scratch, start_new_session=True)
        self.background.append((process, log))
        return process

    def wait_for(self, path):
        deadline = time.monotonic() + 15
        while not os.path.exists(path):
            self.assertLess(time.monotonic(), deadline, "no " + path)
            time.sleep(0.05)  # polling for the simulator's link to appear

    def pty_link(self, name, argv):
        link = os.path.join(self.scratch, name + ".pty")
        self.start(name, argv + ["--link", link])
        self.wait_for(link)
        return link

    def program(self, name):
        text = "%\n" + name[:-3] + " (COMMISSIONING)\n" + "".join(
            "N%d G01 X%d.5 Y1. F100.\n" % (i, i) for i in range(1, 40)) + "M30\n%\n"
        with open(os.path.join(self.scratch, name), "w") as f:
            f.write(text)
        return text

    def setup_block(self, name):
        """Starts the block's simulated machine: (replacements, what the output must contain)."""
        dprnt_program = os.path.join(ROOT, "config", "dprnt", "grid_probe.nc")
        if name == "check_port":
            return {"/dev/ttyUSB0": self.pty_link("xmodem", ["sim_haas_serial", "xmodem", "--dir", self.scratch])}, \
                [": opens", "settings applied: 115200 baud"]
        if name == "listen":
            self.program("O01001.nc")
            link = self.pty_link("punch", ["sim_haas_serial", "punch", "--file", "O01001.nc", "--baud", "9600",
                                           "--7e1", "--at-once"])
            return {"/dev/ttyUSB0": link}, ["line: 7 data bits, even parity", "fanuc_0i_rs232"]
        if name == "haas_send":
            self.program("O01234.nc")
            memory = os.path.join(self.scratch, "haas_memory")
            self.expect_file = (os.path.join(memory, "O01234.nc"), os.path.join(self.scratch, "O01234.nc"))
            return {"/dev/ttyUSB0": self.pty_link("xmodem", ["sim_haas_serial", "xmodem", "--dir", memory])}, \
                ["sent "]
        if name == "haas_dnc_node":
            link = self.pty_link("xmodem", ["sim_haas_serial", "xmodem", "--dir", self.scratch])
            return {"/dev/ttyUSB0": link}, ["port open"]
        if name == "haas_dprnt":
            link = self.pty_link("dprnt", ["sim_haas_serial", "dprnt", "--program", dprnt_program, "--repeat", "0",
                                           "--rate", "20", "--parity", "even"])
            return {"/dev/ttyUSB1": link}, [DPRNT_LINE]
        if name == "ngc_status":
            port = free_port()
            self.start("mdc", ["sim_haas_mdc", "--port", str(port), "--script",
                               os.path.join(ROOT, "config", "demo", "haas_vf2.mdcsim")])
            return {"192.168.1.50": "127.0.0.1", "tcp_port:=5051": "tcp_port:=%d" % port}, ["link: 2", 'machine: "haas"']
        if name == "ngc_dprnt":
            port = free_port()
            self.start("dprnt_tcp", ["sim_haas_serial", "dprnt", "--tcp", str(port), "--program", dprnt_program,
                                     "--repeat", "0", "--rate", "20"])
            return {"192.168.1.50": "127.0.0.1", "tcp_port:=5052": "tcp_port:=%d" % port}, [DPRNT_LINE]
        if name == "fanuc_backup":
            self.program("O01001.nc")
            os.rename(os.path.join(self.scratch, "O01001.nc"), os.path.join(self.scratch, "control.nc"))
            link = self.pty_link("punch", ["sim_haas_serial", "punch", "--file", "control.nc", "--baud", "9600",
                                           "--7e1", "--eob", "lf"])
            self.expect_file = (os.path.join(self.scratch, "O01001.nc"), None)
            return {"/dev/ttyUSB0": link}, []
        if name == "ethernut_status":
            port = free_port()
            self.start("ethernut", ["sim_ethernut", "--port", str(port)])
            return {"192.168.1.50": "127.0.0.1", "tcp_port:=6666": "tcp_port:=%d" % port}, []
        if name == "at_status":
            command, report = free_port(), free_port()
            self.start("at", ["sim_at_controller", "--command-port", str(command), "--report-mode", "server",
                              "--report-port", str(report)])
            return {"192.168.1.50": "127.0.0.1", "tcp_port:=5000": "tcp_port:=%d" % command,
                    "report_port:=5001": "report_port:=%d" % report}, []
        if name == "board_status":
            return {"/dev/ttyACM0": self.pty_link("board", ["sim_slave_bus", "--framing", "framed"])}, []
        return None

    # -- the page ----------------------------------------------------------------------------
    def run_block(self, name, text):
        self.expect_file = None
        setup = self.setup_block(name)
        self.assertIsNotNone(setup, "docs/COMMISSIONING.md has a block '%s' this test does not run" % name)
        replacements, expected = setup
        for old, new in replacements.items():
            self.assertIn(old, text, "block %s: the page no longer says %s" % (name, old))
            text = text.replace(old, new)
        # cnc_dnc as an installed package puts it on the PATH; the build tree has it beside the nodes.
        env = dict(os.environ, PATH=self.sim_dir + ":" + os.environ["PATH"])
        log_path = os.path.join(self.scratch, name + ".out")
        with open(log_path, "w") as log:
            shell = subprocess.Popen(["bash", "-e", "-o", "pipefail", "-c", text], stdout=log,
                                     stderr=subprocess.STDOUT, cwd=self.scratch, env=env, start_new_session=True)
            self.background.append((shell, open(os.devnull)))
            try:
                status = shell.wait(timeout=90)
            except subprocess.TimeoutExpired:
                status = "timeout"
        with open(log_path) as f:
            output = f.read()
        self.assertEqual(status, 0, "block %s:\n%s\nended with %s:\n%s" % (name, text, status, output[-3000:]))
        for promise in expected:
            if isinstance(promise, re.Pattern):
                self.assertRegex(output, promise, "block %s printed:\n%s" % (name, output[-3000:]))
            else:
                self.assertIn(promise, output, "block %s printed:\n%s" % (name, output[-3000:]))
        if self.expect_file:
            stored, sent = self.expect_file
            self.assertTrue(os.path.exists(stored), "block %s stored nothing at %s" % (name, stored))
            if sent:
                with open(stored) as a, open(sent) as b:
                    self.assertEqual(a.read(), b.read())
        self.tearDown()
        self.background = []

    def test_every_block_of_the_page(self):
        blocks = page_blocks()
        names = [name for name, _ in blocks]
        self.assertEqual(names, ["check_port", "listen", "haas_send", "haas_dnc_node", "haas_dprnt", "ngc_status",
                                 "ngc_dprnt", "fanuc_backup", "ethernut_status", "at_status", "board_status"])
        # One block after the other, each block's nodes stopped before the next (they share /state).
        for name, text in blocks:
            started = time.monotonic()
            self.run_block(name, text)
            sys.stderr.write("commissioning: block %s %.1f s\n" % (name, time.monotonic() - started))


if __name__ == "__main__":
    import rostest
    rospy.init_node("test_commissioning", anonymous=True)
    rostest.rosrun("cnc_bridge", "commissioning", Commissioning, sys.argv)
