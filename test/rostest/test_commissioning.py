#!/usr/bin/env python3
"""docs/COMMISSIONING.md as a new user follows it, with simulators standing in for the machines.

Every command block of the page (```sh after a `<!-- block: NAME -->` line) runs as written, in
order, in a fresh bash whose environment is a new terminal's (a login PATH, no ROS or catkin
variable, only the master's address): the page's setup block (`source .build/devel/setup.bash`,
run in the checkout) and then the block. Nothing else is put on PATH: the commands must be
where the page's setup line puts them. Before a block, its simulator (```sh after
`<!-- simulator: NAME -->`, the page's rehearsal command) is started the same way. The machine's
addresses are replaced by the simulators' (the serial devices by the ptys in the rehearsal
folder, 192.168.1.50 by the loopback address, the control's TCP ports by free ones), the
rehearsal folder /tmp/rehearsal by a folder of the test, which is also the terminal's HOME. Each block must end
with exit status 0 and print what the page promises. A block of the page that this test does not
know, or a known block missing from the page, fails the test."""
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
BLOCK = re.compile(r"<!-- (block|simulator): (\w+) -->\n```sh\n(.*?)```", re.S)
# The first line every simulator prints (sim::announce): it is ready.
ANNOUNCED = re.compile(r"^sim_\w+ (pty|tcp) ", re.M)
# The simulator repeats config/dprnt/grid_probe.nc, so `rostopic echo -n1` may catch any of its
# lines: a PROBE line most of the time, but also the lines before and after the grid.
DPRNT_LINE = re.compile(r'text: "(X *1\.5436 Z|CYCLE START|PROBE X|Z OFFSET IS|MACHINE X|CYCLE END)')
# What a new terminal has: the system's PATH, nothing of ROS or catkin.
LOGIN_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"
KEPT = ("ROS_MASTER_URI", "ROS_IP", "ROS_HOSTNAME", "LANG", "LC_ALL", "USER", "LOGNAME", "TERM", "TMPDIR")
SETUP_LINE = "source .build/devel/setup.bash"
# Per block: the TCP ports of the page that become free ones, and what the output must contain.
PORTS = {"ngc_status": ["5051"], "ngc_dprnt": ["5052"], "ethernut_status": ["6666"], "at_status": ["5000", "5001"]}
EXPECTED = {
    "check_port": [": opens", "settings applied: 115200 baud"],
    "listen": ["line: 7 data bits, even parity", "fanuc_0i_rs232"],
    "haas_send": ["sent "],
    "haas_dnc_node": ["success: True"],
    "haas_classic_shared": ['machine: "haas_classic"', 'program: "O01000"', "link: 2"],
    # One port for all three: the transfer through dnc_node, then MDC's state (only the state has
    # a `program:` field) and a DPRNT line through haas_mdc_node to dprnt_node.
    "haas_classic_dprnt": ["success: True", 'program: "O01000"', "link: 2", DPRNT_LINE],
    "haas_dprnt": [DPRNT_LINE],
    "ngc_status": ["link: 2", 'machine: "haas_vf2"'],
    "ngc_dprnt": [DPRNT_LINE],
}
BLOCKS = ["setup", "programs", "rehearsal", "check_port", "listen", "haas_send", "haas_dnc_node",
          "haas_classic_shared", "haas_classic_dprnt", "haas_dprnt", "ngc_status", "ngc_dprnt", "fanuc_backup", "ethernut_status",
          "at_status", "board_status"]


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def page_blocks():
    """(blocks in page order [(name, text)], simulators {name: text})."""
    with open(PAGE) as f:
        found = BLOCK.findall(f.read())
    return [(name, text) for kind, name, text in found if kind == "block"], \
        {name: text for kind, name, text in found if kind == "simulator"}


def devel_setup():
    """The setup.bash of the devel space this test runs from (the one with the simulators)."""
    for path in os.environ.get("CMAKE_PREFIX_PATH", "").split(":"):
        if os.path.exists(os.path.join(path, "lib", "cnc_bridge", "sim_haas_serial")):
            return os.path.join(path, "setup.bash")
    return os.path.join(ROOT, ".build", "devel", "setup.bash")


class Commissioning(unittest.TestCase):
    def setUp(self):
        self.scratch = tempfile.mkdtemp(prefix="cnc_commissioning_")
        self.home = os.path.join(self.scratch, "home")
        self.rehearsal = os.path.join(self.scratch, "rehearsal")
        os.makedirs(self.home)
        self.background = []
        self.blocks, self.simulators = page_blocks()
        self.setup_text = dict(self.blocks).get("setup", "")
        # The page's line as written when the test runs from the checkout's own build (a fresh
        # clone after `make build`); a build folder elsewhere stands in for .build/devel.
        setup = devel_setup()
        if os.path.realpath(setup) != os.path.realpath(os.path.join(ROOT, ".build", "devel", "setup.bash")):
            self.setup_text = self.setup_text.replace(SETUP_LINE, "source " + setup)

    def tearDown(self):
        self.stop_background()

    def stop_background(self):
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
                    time.sleep(0.1)  # poll: the group's last process ending has no event to wait on
                if not self.group_alive(process):
                    break
            process.wait()
            log.close()
        self.background = []

    @staticmethod
    def group_alive(process):
        process.poll()
        try:
            os.killpg(process.pid, 0)
            return True
        except ProcessLookupError:
            return False

    # -- a new terminal --------------------------------------------------------------------
    def terminal_env(self):
        env = {name: os.environ[name] for name in KEPT if name in os.environ}
        env.update(PATH=LOGIN_PATH, HOME=self.home)
        return env

    def shell(self, name, text):
        """Starts `text` after the page's setup line in a new terminal, in the checkout."""
        log = open(os.path.join(self.scratch, name + ".out"), "w")
        script = self.setup_text + text
        # -e: a command that fails ends the block. Not pipefail: as in a terminal, a pipeline's
        # status is its last command's (`rostopic echo ... | grep -m1 ...` ends with grep's).
        process = subprocess.Popen(["bash", "-e", "-c", script], stdout=log,
                                   stderr=subprocess.STDOUT, cwd=ROOT, env=self.terminal_env(),
                                   start_new_session=True)
        self.background.append((process, log))
        return process, log.name

    def replaced(self, name, text, replacements):
        for old, new in replacements:
            self.assertRegex(text, old, "block %s: the page no longer says %s" % (name, old.pattern))
            text = old.sub(new, text)
        return text

    def replacements(self, name):
        """The machine's addresses -> the simulators' (as regular expressions)."""
        pairs = [(re.compile(r"/tmp/rehearsal"), self.rehearsal)]
        for port in PORTS.get(name, []):
            pairs.append((re.compile(r"(?<![\d.])%s(?!\d)" % port), str(free_port())))
        return pairs

    def device_replacements(self, text):
        pairs = [(re.compile(re.escape(device)), os.path.join(self.rehearsal, os.path.basename(device)))
                 for device in ("/dev/ttyUSB0", "/dev/ttyACM0") if device in text]
        if "192.168.1.50" in text:
            pairs.append((re.compile(re.escape("192.168.1.50")), "127.0.0.1"))
        return pairs

    def start_simulator(self, name, replacements):
        self.assertIn(name, self.simulators, "docs/COMMISSIONING.md gives no simulator for block " + name)
        text = self.simulators[name]
        for old, new in replacements:
            text = old.sub(new, text)
        _, log_path = self.shell("sim_" + name, text)
        deadline = time.monotonic() + 20
        while True:
            with open(log_path) as f:
                output = f.read()
            if ANNOUNCED.search(output):
                return
            self.assertLess(time.monotonic(), deadline, "simulator of %s:\n%s\nsaid:\n%s" % (name, text, output))
            time.sleep(0.05)  # poll: the simulator's first line is written to a file

    # -- the page ----------------------------------------------------------------------------
    def run_block(self, name, text):
        self.assertIn(name, BLOCKS, "docs/COMMISSIONING.md has a block '%s' this test does not run" % name)
        replacements = self.replacements(name)
        if name not in ("setup", "programs", "rehearsal"):
            self.start_simulator(name, replacements)
        text = self.replaced(name, text, [(old, new) for old, new in replacements if old.search(text)]
                             + self.device_replacements(text))
        if name == "setup":
            # The commands the page uses, on PATH from the setup line alone.
            text = "command -v cnc_dnc cnc_plan roslaunch rostopic rosservice rosrun\n"
        shell, log_path = self.shell(name, text)
        try:
            status = shell.wait(timeout=90)
        except subprocess.TimeoutExpired:
            status = "timeout"
        with open(log_path) as f:
            output = f.read()
        self.assertEqual(status, 0, "block %s:\n%s\nended with %s:\n%s" % (name, text, status, output[-3000:]))
        for promise in EXPECTED.get(name, []):
            if isinstance(promise, re.Pattern):
                self.assertRegex(output, promise, "block %s printed:\n%s" % (name, output[-3000:]))
            else:
                self.assertIn(promise, output, "block %s printed:\n%s" % (name, output[-3000:]))
        self.check_effect(name, output)
        self.stop_background()

    def check_effect(self, name, output):
        """What a block leaves behind: files where the page says."""
        programs = os.path.join(self.home, "nc_programs")
        sample = os.path.join(programs, "O05555.nc")
        if name == "setup":
            devel = os.path.dirname(devel_setup())
            for command in ("cnc_dnc", "cnc_plan"):
                self.assertIn(os.path.join(devel, "bin", command), output)
        if name == "programs":
            with open(sample) as copy, open(os.path.join(ROOT, "config", "demo", "O05555.nc")) as original:
                self.assertEqual(copy.read(), original.read())
        if name == "rehearsal":
            self.assertTrue(os.path.isdir(self.rehearsal))
        if name in ("haas_send", "haas_dnc_node"):
            stored = os.path.join(self.rehearsal, "haas_memory", "O05555.nc")
            self.assertTrue(os.path.exists(stored), "block %s stored nothing at %s" % (name, stored))
            with open(stored) as a, open(sample) as b:
                self.assertEqual(a.read(), b.read())
            os.remove(stored)  # the next block must store it again
        if name == "haas_classic_dprnt":
            # sim_haas_serial classic numbers what it receives.
            stored = os.path.join(self.rehearsal, "haas_memory", "received_1.nc")
            self.assertTrue(os.path.exists(stored), "block %s stored nothing at %s" % (name, stored))
            with open(stored) as a, open(sample) as b:
                self.assertEqual(a.read(), b.read())
        if name == "fanuc_backup":
            with open(os.path.join(programs, "punched.nc")) as punched:
                self.assertIn("O05555", punched.read())

    def test_every_block_of_the_page(self):
        names = [name for name, _ in self.blocks]
        self.assertEqual(names, BLOCKS)
        self.assertIn(SETUP_LINE, dict(self.blocks)["setup"])
        self.assertEqual(sorted(self.simulators), sorted(BLOCKS[3:]))
        # One block after the other, each block's simulator and nodes stopped before the next.
        for name, text in self.blocks:
            started = time.monotonic()
            self.run_block(name, text)
            sys.stderr.write("commissioning: block %s %.1f s\n" % (name, time.monotonic() - started))


if __name__ == "__main__":
    import rostest
    rospy.init_node("test_commissioning", anonymous=True)
    rostest.rosrun("cnc_bridge", "commissioning", Commissioning, sys.argv)
