#!/usr/bin/env python3
"""Runs every test the build declares (<build>/test_manifest.txt, written by CMake) one at a time,
each under its time limit, and makes sure that each leaves a JUnit result that tells the truth:

- a declared unit test whose binary is missing fails (a test that was not built is not a pass);
- a test still running at its time limit is killed with its process group and fails, naming the
  test and the limit (catkin ignores GoogleTest timeouts, so nothing else would stop it);
- a test program that exits non-zero although its XML says every case passed (a crash or a
  sanitizer report after GoogleTest wrote its results) fails;
- a test that writes no result at all fails;
- each test has a scratch folder of its own as TMPDIR (the rostests' pid files, pty links and logs go
  there), removed when the test passed and kept, its path printed, when it failed.

usage: run_tests.py --build BUILD --results DIR [--only NAME ...] [--manifest FILE]
Unit tests run from BUILD (as catkin runs them); rostests with the package's source as --pkgdir.
Each test's output goes to BUILD/test_logs/NAME.log; one line per test is printed, with the end of
the log of a test that failed. Exit status 1 if any test failed.
"""
import argparse
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import junit_step  # noqa: E402  (scripts/junit_step.py)

# A rostest's limit: the sum of its test nodes' own time limits (rostest's default is 60 s) plus
# this margin for the master, the nodes and the simulators to start and stop.
ROSTEST_MARGIN_S = 120
ROSTEST_DEFAULT_NODE_LIMIT_S = 60
KILL_GRACE_S = 10
# rostest runs on the Python ROS is installed for (as catkin runs it), whatever python3 is first on PATH.
SYSTEM_PYTHON = "/usr/bin/python3"


class Test:
    def __init__(self, kind, name, limit, what):
        self.kind, self.name, self.limit, self.what = kind, name, limit, what

    def __repr__(self):
        return f"{self.kind} {self.name}"


def read_manifest(path):
    """The tests of the manifest, in its order. Fuzz targets are run by the sanitizer step."""
    tests = []
    with open(path) as f:
        for number, line in enumerate(f, 1):
            line = line.strip()
            if not line:
                continue
            parts = line.split(" ", 3)
            if len(parts) != 4:
                raise ValueError(f"{path}:{number}: expected 'KIND NAME TIME_LIMIT WHAT', got {line!r}")
            kind, name, limit, what = parts
            if kind != "fuzz":
                tests.append(Test(kind, name, int(limit), what))
    return tests


def rostest_time_limit(launch_file):
    """Seconds a rostest may take: its <test> nodes' time limits plus the margin."""
    root = ET.parse(launch_file).getroot()
    limits = [float(node.get("time-limit", ROSTEST_DEFAULT_NODE_LIMIT_S)) for node in root.iter("test")]
    return int(sum(limits)) + ROSTEST_MARGIN_S


def run_limited(command, limit, log_path, cwd, scratch):
    """(exit status, seconds, timed out): `command` in a process group of its own, killed whole
    (the master and nodes a rostest started too) when it is still running after `limit` seconds.
    Its scratch files (TMPDIR: the rostests' pid files, pty links and logs, Python's tempfile) go
    to `scratch`."""
    start = time.monotonic()
    with open(log_path, "wb") as log:
        process = subprocess.Popen(command, cwd=cwd, stdout=log, stderr=subprocess.STDOUT,
                                   stdin=subprocess.DEVNULL, start_new_session=True,
                                   env=dict(os.environ, TMPDIR=scratch))
        try:
            status = process.wait(timeout=limit)
            timed_out = False
        except subprocess.TimeoutExpired:
            timed_out = True
            os.killpg(process.pid, signal.SIGTERM)
            try:
                process.wait(timeout=KILL_GRACE_S)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
            status = process.returncode
    return status, time.monotonic() - start, timed_out


def has_failure(path):
    try:
        return junit_step.has_failure(ET.parse(path).getroot())
    except (OSError, ET.ParseError):
        return False


def add_failed_case(path, name, message, log):
    """One failed case `name` in the result file `path` (created if it does not exist)."""
    if not os.path.exists(path):
        junit_step.failed(path, name, message)
        return
    try:
        tree = ET.parse(path)
    except ET.ParseError:
        junit_step.failed(path, name, message)
        return
    root = tree.getroot()
    suite = root.find("testsuite") if root.tag == "testsuites" else root
    suite = root if suite is None else suite
    case = ET.SubElement(suite, "testcase", classname="run", name=name)
    ET.SubElement(case, "failure", message=message).text = junit_step.log_tail(log)
    tree.write(path)


def result_files(test, results):
    """The JUnit files `test` writes: the first one is where a failure of the run itself goes."""
    if test.kind == "gtest":
        return [os.path.join(results, f"gtest-{test.name}.xml")]
    if test.kind == "rostest":
        # rostest's own file is named after the launch file, each test node's after its test-name.
        stem = os.path.splitext(test.name)[0]
        nodes = [node.get("test-name") for node in ET.parse(test.what).getroot().iter("test")]
        return [os.path.join(results, f"rostest-{stem}.xml")] + [os.path.join(results, f"rosunit-{n}.xml") for n in nodes]
    return [os.path.join(results, f"roslaunch-check_{test.name}.xml")]


def command_of(test, build, results, source):
    if test.kind == "gtest":
        return [test.what, f"--gtest_output=xml:{result_files(test, results)[0]}"], test.limit
    if test.kind == "rostest":
        stem = os.path.splitext(test.name)[0]
        return ([SYSTEM_PYTHON, "/usr/bin/rostest", f"--pkgdir={source}", "--package=cnc_bridge",
                 "--results-filename", f"{stem}.xml", "--results-base-dir", os.path.dirname(results), test.what],
                rostest_time_limit(test.what))
    return ["cmake", "--build", build, "--target", test.what], test.limit


def run_one(test, build, results, source, logs):
    """Runs `test` with a scratch folder of its own as TMPDIR, removed if it passed and kept for a
    look if it failed (and left something there); returns None if it passed, else why it failed."""
    scratch = tempfile.mkdtemp(prefix="cnc_test.")
    problem = run_in(test, build, results, source, logs, scratch)
    if problem is None or not os.listdir(scratch):
        shutil.rmtree(scratch, ignore_errors=True)
        return problem
    return f"{problem}; its scratch folder is kept: {scratch}"


def run_in(test, build, results, source, logs, scratch):
    files = result_files(test, results)
    for path in files:
        if os.path.exists(path):
            os.remove(path)
    log = os.path.join(logs, f"{test.name}.log")
    if test.kind == "gtest" and not os.access(test.what, os.X_OK):
        message = f"{test.name} is declared (test_manifest.txt) but its binary {test.what} was not built"
        junit_step.failed(files[0], test.name, message)
        return message
    command, limit = command_of(test, build, results, source)
    status, seconds, timed_out = run_limited(command, limit, log, build, scratch)
    if timed_out:
        message = f"{test.name} hung: still running after its time limit of {limit} s, killed (log: {log})"
        add_failed_case(files[0], "time limit", message, log)
        return message
    written = [path for path in files if os.path.exists(path)]
    if not written:
        message = f"{test.name} exited with status {status} without writing results (log: {log})"
        junit_step.failed(files[0], test.name, message)
        return message
    if any(has_failure(path) for path in written):
        return f"{test.name}: a case failed (log: {log})"
    if status != 0:
        message = (f"{test.name} exited with status {status} after every case passed "
                   f"(a crash or a sanitizer report after the results were written; log: {log})")
        add_failed_case(files[0], "process exit status", message, log)
        return message
    return None


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--build", required=True)
    parser.add_argument("--results", required=True, help="the JUnit directory (<build>/test_results/cnc_bridge)")
    parser.add_argument("--manifest", help="default: BUILD/test_manifest.txt")
    parser.add_argument("--source", default=os.path.dirname(HERE), help="the package's source folder")
    parser.add_argument("--only", nargs="*", help="run only these tests (names as in the manifest)")
    args = parser.parse_args(argv)
    build = os.path.abspath(args.build)
    results = os.path.abspath(args.results)
    logs = os.path.join(build, "test_logs")
    os.makedirs(results, exist_ok=True)
    os.makedirs(logs, exist_ok=True)
    manifest = args.manifest or os.path.join(build, "test_manifest.txt")
    try:
        tests = read_manifest(manifest)
    except (OSError, ValueError) as error:
        junit_step.failed(os.path.join(results, "step_manifest.xml"), "test manifest",
                          f"no list of the declared tests ({error}): configure the build again")
        print(f"run_tests: {error}")
        return 1
    if args.only:
        tests = [test for test in tests if test.name in args.only]
    failures = 0
    for test in tests:
        start = time.monotonic()
        problem = run_one(test, build, results, args.source, logs)
        seconds = time.monotonic() - start
        print(f"{'ok  ' if problem is None else 'FAIL'} {test.kind:<12} {test.name:<40} {seconds:7.1f} s", flush=True)
        if problem:
            failures += 1
            print(f"     {problem}")
            print(re.sub(r"(?m)^", "     | ", junit_step.log_tail(os.path.join(logs, f"{test.name}.log"), 25)))
    print(f"run_tests: {len(tests)} tests run, {failures} failed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
