#!/usr/bin/env python3
"""cnc_bridge as a machine computer gets it: installed, not built. Installs the build directory
into a temporary folder (`make install` with DESTDIR, so the build's configuration is reused),
then, in an environment where only that install space is sourced (no build tree, no devel space,
no source checkout on any path):

  - the package, its nodes, libraries and Python messages resolve to the install space;
  - every installed launch file loads and every node it starts exists (roslaunch's own check);
  - dnc_node started through its installed launch file reaches LINK_UP on its simulator
    (sim_haas_serial xmodem, also from the install space);
  - `cnc_dnc send` (from the PATH of the install space) stores a program on the XModem simulator;
  - no installed node or library carries the test doubles of cnc_bridge_testing, whose headers are
    not installed either (the simulators do carry them).

Writes JUnit XML (one case per check).

usage: test_install_space.py --build BUILD_DIR --junit FILE [--keep]
"""
import argparse
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PACKAGE = "cnc_bridge"


class Failure(Exception):
    pass


class InstallSpace:
    """A DESTDIR install of the build directory, and commands run with only it sourced."""

    def __init__(self, build, scratch):
        self.build = build
        self.scratch = scratch
        self.destdir = os.path.join(scratch, "root")
        self.prefix = None
        self.home = os.path.join(scratch, "home")
        os.makedirs(self.home)
        # What the launch files and programs put in TMPDIR (pid files, pty links, a sandbox a test
        # launch file makes as it is loaded) stays in the scratch folder.
        self.tmp = os.path.join(scratch, "tmp")
        os.makedirs(self.tmp)
        self.processes = []

    def install(self):
        result = subprocess.run(["cmake", "--build", self.build, "--target", "install"],
                                env=dict(os.environ, DESTDIR=self.destdir), capture_output=True, text=True)
        if result.returncode != 0:
            raise Failure("make install failed: " + (result.stdout + result.stderr)[-2000:])
        setups = [os.path.join(parent, "setup.bash") for parent, _, files in os.walk(self.destdir)
                  if "setup.bash" in files and ".catkin" in files]
        if len(setups) != 1:
            raise Failure("expected one install space (setup.bash beside .catkin) under %s, found %s"
                          % (self.destdir, setups))
        self.prefix = os.path.dirname(setups[0])

    def environment(self, extra=None):
        """A login-like environment: nothing of the calling shell, so no ROS path leaks in."""
        env = {"HOME": self.home, "PATH": "/usr/bin:/bin", "LANG": "C.UTF-8",
               "ROS_HOME": os.path.join(self.home, ".ros"), "TMPDIR": self.tmp}
        env.update(extra or {})
        return env

    def command(self, text):
        return ["bash", "-c", 'source "%s/setup.bash" && %s' % (self.prefix, text)]

    def run(self, text, timeout=60, extra=None):
        return subprocess.run(self.command(text), env=self.environment(extra), capture_output=True, text=True,
                              timeout=timeout, cwd=self.home)

    def start(self, text, log_name, extra=None):
        log = open(os.path.join(self.scratch, log_name), "w")
        process = subprocess.Popen(self.command("exec " + text), env=self.environment(extra), stdout=log,
                                   stderr=subprocess.STDOUT, cwd=self.home, start_new_session=True)
        self.processes.append((process, log))
        return process

    def stop_all(self):
        for process, log in reversed(self.processes):
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGINT)
                try:
                    process.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    os.killpg(process.pid, signal.SIGKILL)
                    process.wait()
            log.close()
        self.processes = []

    def log(self, name):
        try:
            with open(os.path.join(self.scratch, name)) as f:
                return f.read()[-1500:]
        except OSError:
            return ""


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(condition, timeout, what):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.1)  # poll: the condition has no event to wait on
    raise Failure("timed out after %.0f s waiting for %s" % (timeout, what))


def outside_checkout(path):
    real = os.path.realpath(path)
    return not (real == ROOT or real.startswith(ROOT + os.sep))


# ---------------------------------------------------------------------------------------------
def check_resolves_to_install(space):
    """The package, a node, its libraries and the Python messages come from the install space."""
    script = ("rospack find %s; echo ROS_PACKAGE_PATH=$ROS_PACKAGE_PATH; echo LD_LIBRARY_PATH=$LD_LIBRARY_PATH; "
              "command -v cnc_dnc; ldd $(dirname $(rospack find %s))/../lib/%s/dnc_node; "
              "/usr/bin/python3 -c 'import cnc_bridge.msg; print(cnc_bridge.msg.__file__)'" % ((PACKAGE,) * 3))
    result = space.run(script)
    if result.returncode != 0:
        raise Failure("looking the package up failed: " + result.stderr[-1500:])
    lines = result.stdout.splitlines()
    share = os.path.join(space.prefix, "share", PACKAGE)
    if os.path.realpath(lines[0]) != os.path.realpath(share):
        raise Failure("rospack finds %s at %s, not in the install space %s" % (PACKAGE, lines[0], share))
    for line in lines[1:3]:
        for path in line.split("=", 1)[1].split(":"):
            if path and not outside_checkout(path):
                raise Failure("%s names the checkout or its build tree: %s" % (line.split("=")[0], path))
    if not lines[3].startswith(space.prefix + "/"):
        raise Failure("cnc_dnc on the PATH is %s, not the installed one" % lines[3])
    own_libraries = [line for line in lines if "libcnc_bridge" in line]
    if not own_libraries:
        raise Failure("dnc_node links none of the package's libraries? ldd: " + result.stdout)
    for line in own_libraries:
        if "not found" in line or space.prefix not in line:
            raise Failure("dnc_node's library is not the installed one: " + line.strip())
    if not lines[-1].startswith(space.prefix + "/"):
        raise Failure("the Python messages come from %s, not the install space" % lines[-1])


def check_launch_files(space):
    """roslaunch's own check on every installed launch file: it loads (including the commands its
    parameters run, e.g. prefix_urdf.py) and every node it would start exists."""
    launch_dir = os.path.join(space.prefix, "share", PACKAGE, "launch")
    names = sorted(name for name in os.listdir(launch_dir) if name.endswith(".launch"))
    sources = sorted(name for name in os.listdir(os.path.join(ROOT, "launch")) if name.endswith(".launch"))
    if names != sources:
        raise Failure("installed launch files %s differ from launch/ %s" % (names, sources))
    script = ("/usr/bin/python3 -c 'import sys, roslaunch.rlutil as r\n"
              "bad = [(f, r.check_roslaunch(f)) for f in sys.argv[1:]]\n"
              "bad = [b for b in bad if b[1]]\n"
              "print(bad)\nsys.exit(1 if bad else 0)' " + " ".join(os.path.join(launch_dir, n) for n in names))
    result = space.run(script, timeout=120)
    if result.returncode != 0:
        raise Failure("launch files that do not work from the install space: " + (result.stdout + result.stderr)[-2000:])


def check_simulators_of_cell(space):
    """The simulators the cell launch file starts through run_sim.sh are installed."""
    import xml.etree.ElementTree as LaunchXml
    tree = LaunchXml.parse(os.path.join(space.prefix, "share", PACKAGE, "launch", "cell.launch"))
    simulators = {node.get("args").split()[0] for node in tree.iter("node") if node.get("type") == "run_sim.sh"}
    if not simulators:
        raise Failure("cell.launch starts no simulator through run_sim.sh?")
    missing = [s for s in sorted(simulators)
               if not os.access(os.path.join(space.prefix, "lib", PACKAGE, s), os.X_OK)]
    if missing:
        raise Failure("simulators not installed: %s" % missing)


def owning_packages(paths):
    """{library path: the Debian package that installed it} in one dpkg query (ldd may name a file
    by /lib or /usr/lib)."""
    candidates = {}
    for path in paths:
        real = os.path.realpath(path)
        for candidate in (path, real, path.replace("/usr/lib/", "/lib/", 1), real.replace("/usr/lib/", "/lib/", 1),
                          "/usr" + path):
            candidates.setdefault(candidate, path)
    result = subprocess.run(["dpkg-query", "-S"] + sorted(candidates), capture_output=True, text=True)
    owners = {}
    for line in result.stdout.splitlines():
        packages, _, owned = line.partition(": ")
        if owned in candidates:
            owners.setdefault(candidates[owned], packages.split(",")[0].split(":")[0].strip())
    return {path: owners.get(path) for path in paths}


def installed_dependency_closure(packages):
    """The installed packages that `packages` depend on (Depends, Pre-Depends), recursively;
    a dependency on a virtual package counts for the installed packages that provide it."""
    table = subprocess.run(["dpkg-query", "-W", "-f", "${db:Status-Abbrev}\t${Package}\t${Depends}, ${Pre-Depends}"
                            "\t${Provides}\n"], capture_output=True, text=True, check=True).stdout
    depends, providers = {}, {}

    def names(field):
        # "a (>= 1) | b, c:any" -> [a, b, c]: every alternative, without versions and architectures
        return [word.split(":")[0] for word in re.sub(r"\([^)]*\)", "", field).replace("|", ",").split(",")
                for word in [word.strip()] if word]

    for line in table.splitlines():
        status, package, depend_field, provide_field = (line.split("\t") + ["", "", "", ""])[:4]
        if not status.startswith("ii"):
            continue
        depends[package] = names(depend_field)
        for virtual in names(provide_field):
            providers.setdefault(virtual, []).append(package)
    closure, stack = set(), list(packages)
    while stack:
        name = stack.pop()
        for package in [name] if name in depends else providers.get(name, []):
            if package not in closure:
                closure.add(package)
                stack.extend(depends[package])
    return closure


def check_runtime_packages_cover_programs(space):
    """Every system library an installed program or library loads comes from a package that
    `scripts/setup.sh --runtime` installs, or from one of their dependencies."""
    with open(os.path.join(ROOT, "scripts", "debian-runtime-packages.txt")) as f:
        runtime = [line.strip() for line in f if line.strip() and not line.lstrip().startswith("#")]
    available = installed_dependency_closure(runtime)
    available.update(["libc6", "libgcc-s1", "libstdc++6"])  # the C and C++ run-time of every Debian system
    files = [os.path.join(space.prefix, "lib", PACKAGE, name) for name in os.listdir(os.path.join(space.prefix, "lib",
                                                                                                  PACKAGE))]
    files += [os.path.join(space.prefix, "lib", name) for name in os.listdir(os.path.join(space.prefix, "lib"))
              if name.endswith(".so")]
    libraries = set()
    for path in files:
        with open(path, "rb") as f:
            if f.read(4) != b"\x7fELF":
                continue
        result = subprocess.run(["ldd", path], capture_output=True, text=True,
                                env={"LD_LIBRARY_PATH": os.path.join(space.prefix, "lib"), "PATH": "/usr/bin:/bin"})
        for line in result.stdout.splitlines():
            if "not found" in line:
                raise Failure("%s: %s" % (path, line.strip()))
            parts = line.split("=>")
            if len(parts) == 2 and parts[1].split() and parts[1].split()[0].startswith("/"):
                library = parts[1].split()[0]
                if not library.startswith(space.prefix):
                    libraries.add(library)
    owners = owning_packages(sorted(libraries))
    uncovered = sorted("%s (%s)" % (library, owner) for library, owner in owners.items() if owner not in available)
    if uncovered:
        raise Failure("libraries loaded by installed programs whose packages scripts/debian-runtime-packages.txt "
                      "does not bring: " + ", ".join(uncovered))


# Classes and functions of cnc_bridge_testing (include/cnc_bridge/testing/), as nm -C prints them.
TEST_DOUBLE = re.compile(r"\bcnc_bridge::(?:FakeTransport|FaultyTransport|PacedTransport|PtyMaster|sim::SimulatedLine|"
                         r"sim::announce)\b")


def test_doubles_in(path):
    result = subprocess.run(["nm", "-C", "--defined-only", path], capture_output=True, text=True)
    if result.returncode != 0:
        raise Failure("nm %s: %s" % (path, result.stderr[-500:]))
    return sorted(set(TEST_DOUBLE.findall(result.stdout)))


def check_no_test_doubles_shipped(space):
    """The nodes and the package's libraries define none of the test doubles; a simulator, which
    links them, does (so the symbol names looked for are the right ones)."""
    programs = os.path.join(space.prefix, "lib", PACKAGE)
    files = [os.path.join(programs, name) for name in os.listdir(programs) if name.endswith("_node")]
    files += [os.path.join(space.prefix, "lib", name) for name in os.listdir(os.path.join(space.prefix, "lib"))
              if name.startswith("libcnc_bridge") and name.endswith(".so")]
    if not any(path.endswith("_node") for path in files) or not any(path.endswith(".so") for path in files):
        raise Failure("no node or no library installed? " + str(files))
    shipped = ["%s (%s)" % (os.path.basename(path), ", ".join(found))
               for path in sorted(files) for found in [test_doubles_in(path)] if found]
    if shipped:
        raise Failure("installed nodes and libraries that carry test doubles: " + "; ".join(shipped))
    if not test_doubles_in(os.path.join(programs, "sim_haas_serial")):
        raise Failure("sim_haas_serial defines no test double: the symbol names looked for are out of date")
    headers = os.path.join(space.prefix, "include", PACKAGE, "testing")
    if os.path.exists(headers):
        raise Failure("the headers of cnc_bridge_testing are installed: " + headers)


def check_node_reaches_link_up(space):
    """dnc_node through its installed launch file, on the installed XModem simulator's pty."""
    port = free_port()
    master = {"ROS_MASTER_URI": "http://127.0.0.1:%d" % port}
    link = os.path.join(space.scratch, "haas_rs232.pty")
    programs = os.path.join(space.scratch, "programs")
    os.makedirs(programs)
    space.start("roscore -p %d" % port, "roscore.log", master)
    space.start("rosrun %s sim_haas_serial xmodem --link %s --dir %s" % (PACKAGE, link, space.scratch + "/memory"),
                "sim_node.log")
    wait_until(lambda: os.path.exists(link), 20, "the simulator's pty link")
    space.start("roslaunch --wait %s dnc_node.launch machine:=installed_haas port:=%s program_dir:=%s keep_open:=true"
                % (PACKAGE, link, programs), "roslaunch.log", dict(master, ROS_NAMESPACE="/cell/installed_haas"))
    checker = ("/usr/bin/python3 -c 'import rospy\n"
               "from cnc_bridge.msg import MachineState\n"
               "rospy.init_node(\"install_check\")\n"
               "deadline = rospy.Time.now() + rospy.Duration(40)\n"
               "while not rospy.is_shutdown() and rospy.Time.now() < deadline:\n"
               "    m = rospy.wait_for_message(\"/cell/installed_haas/state\", MachineState, timeout=40)\n"
               "    print(m.machine, m.link, flush=True)\n"
               "    if m.link == MachineState.LINK_UP: raise SystemExit(0)\n"
               "raise SystemExit(1)'")
    result = space.run(checker, timeout=90, extra=master)
    if result.returncode != 0:
        raise Failure("dnc_node's state did not reach LINK_UP: %s %s\nroslaunch: %s" %
                      (result.stdout[-500:], result.stderr[-800:], space.log("roslaunch.log")))
    if "installed_haas 2" not in result.stdout:
        raise Failure("no LINK_UP state from machine installed_haas: " + result.stdout[-500:])


def check_cnc_dnc_send(space):
    """`cnc_dnc send` from the install space's PATH to the installed XModem simulator."""
    link = os.path.join(space.scratch, "haas_cli.pty")
    memory = os.path.join(space.scratch, "cli_memory")
    space.start("%s/lib/%s/sim_haas_serial xmodem --link %s --dir %s" % (space.prefix, PACKAGE, link, memory),
                "sim_cli.log")
    wait_until(lambda: os.path.exists(link), 20, "the simulator's pty link")
    program = os.path.join(space.scratch, "O04321.nc")
    text = "%\nO04321 (INSTALLED)\n" + "".join("G01 X%d.0 Y1.0 F100.\n" % i for i in range(200)) + "M30\n%\n"
    with open(program, "w") as f:
        f.write(text)
    result = space.run("cnc_dnc send --port %s --timeout 20 %s" % (link, program), timeout=60)
    if result.returncode != 0:
        raise Failure("cnc_dnc send failed (%d): %s %s" % (result.returncode, result.stdout, result.stderr[-800:]))
    stored = os.path.join(memory, "O04321.nc")
    wait_until(lambda: os.path.exists(stored), 10, "the program in the simulator's memory")
    with open(stored) as f:
        if f.read() != text:
            raise Failure("the simulator stored a different program than was sent")


# ---------------------------------------------------------------------------------------------
def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--build", default=os.path.join(ROOT, ".build"))
    parser.add_argument("--junit", required=True)
    parser.add_argument("--keep", action="store_true", help="keep the install space and logs")
    args = parser.parse_args()
    scratch = tempfile.mkdtemp(prefix="cnc_install_")
    space = InstallSpace(os.path.abspath(args.build), scratch)
    checks = [("install", space.install), ("resolves_to_install_space", lambda: check_resolves_to_install(space)),
              ("launch_files_load_and_their_nodes_exist", lambda: check_launch_files(space)),
              ("cell_simulators_installed", lambda: check_simulators_of_cell(space)),
              ("runtime_packages_cover_installed_programs", lambda: check_runtime_packages_cover_programs(space)),
              ("no_test_doubles_in_nodes_and_libraries", lambda: check_no_test_doubles_shipped(space)),
              ("dnc_node_launch_reaches_link_up", lambda: check_node_reaches_link_up(space)),
              ("cnc_dnc_send_to_xmodem_simulator", lambda: check_cnc_dnc_send(space))]
    results = []
    try:
        for name, check in checks:
            if results and results[0][1] is not None:
                results.append((name, "not run: the install failed"))
                continue
            started = time.monotonic()
            try:
                check()
                problem = None
            except (Failure, subprocess.TimeoutExpired) as error:
                problem = str(error)
            results.append((name, problem))
            print("install_space: %s %s (%.1f s)%s" % (name, "ok" if problem is None else "FAILED",
                                                        time.monotonic() - started,
                                                        "" if problem is None else ": " + problem), flush=True)
    finally:
        space.stop_all()
        if args.keep or any(problem for _, problem in results):
            print("install_space: install space and logs kept in " + scratch)
        else:
            shutil.rmtree(scratch, ignore_errors=True)
    suite = ET.Element("testsuite", name="install_space", tests=str(len(results)),
                       failures=str(sum(1 for _, p in results if p)))
    for name, problem in results:
        case = ET.SubElement(suite, "testcase", classname="install_space", name=name)
        if problem:
            ET.SubElement(case, "failure", message=problem[:2000])
    os.makedirs(os.path.dirname(os.path.abspath(args.junit)), exist_ok=True)
    ET.ElementTree(suite).write(args.junit)
    return 1 if any(problem for _, problem in results) else 0


if __name__ == "__main__":
    sys.exit(main())
