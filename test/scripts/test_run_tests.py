"""What scripts/run_tests.py makes of a test that hangs, crashes after passing, or was not built."""
import os
import stat
import subprocess
import sys
import tempfile
import textwrap
import unittest

import count_results

SCRIPTS = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "scripts")

ALL_PASS = '<testsuites tests="1"><testsuite name="S" tests="1"><testcase name="a" status="run" classname="S"/></testsuite></testsuites>'

# Stand-ins for GoogleTest binaries: each writes its --gtest_output=xml:PATH like GoogleTest does.
WRITE_RESULT = 'out="${1#--gtest_output=xml:}"; echo \'' + ALL_PASS + '\' >"$out"'
SCRATCH = '\ntouch "$TMPDIR/simulator.pid"; echo -n "$TMPDIR" >"$(dirname "$0")/scratch_of_{name}"'
PROGRAMS = {
    "test_passes": WRITE_RESULT + "\nexit 0",
    # Writes an all-pass result, then dies: a crash in a destructor, a leak report.
    "test_crashes_after_passing": WRITE_RESULT + "\nkill -SEGV $$",
    # Never ends: the hang itself is what is under test (the runner must kill it at its limit).
    "test_hangs": "exec sleep 600",
    # Each leaves a file in its TMPDIR (as a rostest's simulators leave pid files and pty links) and
    # tells where that was; one passes, one fails.
    "test_passes_leaving_scratch": WRITE_RESULT + SCRATCH.format(name="passing") + "\nexit 0",
    "test_fails_leaving_scratch": WRITE_RESULT + SCRATCH.format(name="failing") + "\nexit 3",
}


class RunTests(unittest.TestCase):
    def setUp(self):
        self.directory = tempfile.TemporaryDirectory()
        self.addCleanup(self.directory.cleanup)
        self.build = self.directory.name
        self.results = os.path.join(self.build, "test_results", "cnc_bridge")
        lines = []
        for name, body in PROGRAMS.items():
            path = os.path.join(self.build, name)
            with open(path, "w") as f:
                f.write("#!/bin/bash\n" + body + "\n")
            os.chmod(path, stat.S_IRWXU)
            lines.append(f"gtest {name} 2 {path}")
        lines.append(f"gtest test_never_built 300 {os.path.join(self.build, 'test_never_built')}")
        lines.append(f"fuzz fuzz_x 0 {os.path.join(self.build, 'fuzz_x')}")  # run by the sanitizer step
        with open(os.path.join(self.build, "test_manifest.txt"), "w") as f:
            f.write("\n".join(lines) + "\n")

    def run_tests(self, *only):
        command = [sys.executable, os.path.join(SCRIPTS, "run_tests.py"), "--build", self.build, "--results", self.results]
        if only:
            command += ["--only", *only]
        # The runner makes each test's scratch folder in its own TMPDIR: here, this test's folder.
        return subprocess.run(command, capture_output=True, text=True, timeout=120, env=dict(os.environ, TMPDIR=self.build))

    def failures(self):
        tally, failures, _ = count_results.count(os.path.join(self.build, "test_results"), set())
        return tally, failures

    def test_a_passing_test_passes(self):
        run = self.run_tests("test_passes")
        self.assertEqual(run.returncode, 0, run.stdout)
        tally, failures = self.failures()
        self.assertEqual(tally["unit tests"], [1, 0, 0])
        self.assertEqual(failures, [])

    def test_a_crash_after_an_all_pass_result_fails(self):
        run = self.run_tests("test_crashes_after_passing")
        self.assertEqual(run.returncode, 1)
        tally, failures = self.failures()
        self.assertEqual(tally["unit tests"], [1, 1, 0])
        self.assertIn("exited with status -11 after every case passed", failures[0])

    def test_a_hung_test_is_killed_at_its_limit_and_fails_naming_it(self):
        run = self.run_tests("test_hangs")
        self.assertEqual(run.returncode, 1)
        self.assertIn("test_hangs hung: still running after its time limit of 2 s", run.stdout)
        tally, failures = self.failures()
        self.assertEqual(tally["unit tests"][1], 1)
        self.assertIn("test_hangs hung", failures[0])

    def test_each_test_has_a_scratch_folder_removed_if_it_passed_and_kept_if_it_failed(self):
        run = self.run_tests("test_passes_leaving_scratch", "test_fails_leaving_scratch")
        self.assertEqual(run.returncode, 1)
        with open(os.path.join(self.build, "scratch_of_passing")) as f:
            passing = f.read()
        with open(os.path.join(self.build, "scratch_of_failing")) as f:
            failing = f.read()
        self.assertNotEqual(passing, failing)
        self.assertEqual(os.path.dirname(passing), self.build, "no folder of its own")
        self.assertFalse(os.path.exists(passing), "the passing test's scratch folder was left")
        self.assertTrue(os.path.exists(os.path.join(failing, "simulator.pid")))
        self.assertIn("its scratch folder is kept: " + failing, run.stdout)

    def test_a_declared_test_that_was_not_built_fails(self):
        run = self.run_tests("test_never_built")
        self.assertEqual(run.returncode, 1)
        tally, failures = self.failures()
        self.assertEqual(tally["unit tests"], [0, 1, 0])
        self.assertIn("test_never_built is declared", failures[0])
        self.assertIn("was not built", failures[0])

    def test_a_rostest_limit_is_its_nodes_limits_plus_a_margin(self):
        import run_tests
        path = os.path.join(self.build, "x.test")
        with open(path, "w") as f:
            f.write(textwrap.dedent("""\
                <launch><test test-name="a" pkg="p" type="t" time-limit="90"/>
                <test test-name="b" pkg="p" type="t"/></launch>"""))
        self.assertEqual(run_tests.rostest_time_limit(path), 90 + 60 + run_tests.ROSTEST_MARGIN_S)

    def test_a_manifest_line_of_another_shape_is_refused(self):
        import run_tests
        path = os.path.join(self.build, "bad_manifest.txt")
        with open(path, "w") as f:
            f.write("gtest only_a_name\n")
        with self.assertRaises(ValueError):
            run_tests.read_manifest(path)


if __name__ == "__main__":
    unittest.main()
