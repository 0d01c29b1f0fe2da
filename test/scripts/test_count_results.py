"""What the closing line counts: test cases by kind, never files, and every failure to run."""
import os
import subprocess
import sys
import tempfile
import unittest

import count_results
import junit_step

SCRIPTS = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "scripts")

GTEST_TWO_PASS = """<testsuites tests="2"><testsuite name="S" tests="2">
<testcase name="a" status="run" classname="S"/><testcase name="b" status="run" classname="S"/>
</testsuite></testsuites>"""
GTEST_FILTER_MATCHED_NOTHING = """<testsuites tests="0" failures="0" disabled="0" errors="0" name="AllTests"></testsuites>"""
ROSTEST_WRAPPER_PASSED = """<testsuite tests="1"><testcase classname="rostest.runner.RosTest" name="testx"/></testsuite>"""
ROSTEST_WRAPPER_FAILED = """<testsuite tests="1"><testcase classname="rostest.runner.RosTest" name="testy">
<failure>test [y] did not generate test results</failure></testcase></testsuite>"""
PYTHON_ROSTEST = """<testsuite name="unittest.suite.TestSuite" tests="2">
<testcase classname="__main__.T" name="test_a"/><testcase classname="__main__.T" name="test_b"><skipped/></testcase>
</testsuite>"""
LINT_TWO_TOOLS = """<testsuite name="lint" tests="2"><testcase classname="lint.lint" name="clang-format"/>
<testcase classname="lint.lint" name="launch arg docs"><failure message="1 of 13 failed">x.launch: no doc</failure>
</testcase></testsuite>"""


class CountResults(unittest.TestCase):
    def setUp(self):
        self.directory = tempfile.TemporaryDirectory()
        self.addCleanup(self.directory.cleanup)

    def write(self, name, text):
        with open(os.path.join(self.directory.name, name), "w") as f:
            f.write(text)

    def tally(self):
        return count_results.count(self.directory.name)

    def test_cases_are_counted_by_kind(self):
        self.write("gtest-test_a.xml", GTEST_TWO_PASS)
        self.write("rosunit-x.xml", GTEST_TWO_PASS)
        self.write("rosunit-py.xml", PYTHON_ROSTEST)
        self.write("lint.xml", LINT_TWO_TOOLS)
        self.write("install_space.xml", ROSTEST_WRAPPER_PASSED.replace("rostest.runner.RosTest", "install"))
        tally, failures = self.tally()
        self.assertEqual(tally["unit tests"], [2, 0, 0])
        self.assertEqual(tally["install space"], [1, 0, 0])
        self.assertEqual(tally["rostests (C++)"], [2, 0, 0])
        self.assertEqual(tally["rostests (Python)"], [1, 0, 1])
        self.assertEqual(tally["lint tools"], [1, 1, 0])
        self.assertEqual(len(failures), 1)
        self.assertIn("launch arg docs", failures[0])

    def test_a_passed_rostest_wrapper_is_not_a_second_count_but_a_failed_one_is_a_failure(self):
        self.write("rostest-x.xml", ROSTEST_WRAPPER_PASSED)
        self.write("rosunit-x.xml", GTEST_TWO_PASS)
        self.write("rostest-y.xml", ROSTEST_WRAPPER_FAILED)
        tally, failures = self.tally()
        self.assertEqual(tally["rostests (C++)"], [2, 0, 0])
        self.assertEqual(tally["rostest runs"], [0, 1, 0])
        self.assertIn("did not generate test results", failures[0])

    def test_a_result_with_no_case_fails(self):
        self.write("rosunit-ethernut_link.xml", GTEST_FILTER_MATCHED_NOTHING)
        tally, failures = self.tally()
        self.assertEqual(tally["rostests (C++)"], [0, 1, 0])
        self.assertIn("no test case ran", failures[0])

    def test_an_unreadable_file_fails(self):
        self.write("gtest-broken.xml", "<testsuites><testsu")
        tally, failures = self.tally()
        self.assertEqual(sum(each[1] for each in tally.values()), 1)

    def test_closing_line_and_exit_status(self):
        self.write("gtest-test_a.xml", GTEST_TWO_PASS)
        self.write("lint.xml", LINT_TWO_TOOLS)
        run = subprocess.run([sys.executable, os.path.join(SCRIPTS, "count_results.py"), self.directory.name],
                             capture_output=True, text=True)
        lines = run.stdout.strip().splitlines()
        self.assertEqual(lines[-1], "3 passed, 1 failed")
        self.assertIn("test cases by kind:", lines)
        self.assertEqual(run.returncode, 1)

    def test_nothing_run_is_a_failure(self):
        run = subprocess.run([sys.executable, os.path.join(SCRIPTS, "count_results.py"), self.directory.name],
                             capture_output=True, text=True)
        self.assertEqual(run.stdout.strip().splitlines()[-1], "0 passed, 0 failed")
        self.assertEqual(run.returncode, 1)


class JunitStep(unittest.TestCase):
    def setUp(self):
        self.directory = tempfile.TemporaryDirectory()
        self.addCleanup(self.directory.cleanup)
        self.xml = os.path.join(self.directory.name, "asan_test_x.xml")
        self.log = os.path.join(self.directory.name, "test_x.log")
        with open(self.log, "w") as f:
            f.write("==1==ERROR: LeakSanitizer: detected memory leaks\n")

    def failures(self):
        _, failures = count_results.count(self.directory.name)
        return failures

    def test_a_leak_report_after_an_all_pass_xml_is_a_failure(self):
        with open(self.xml, "w") as f:
            f.write(GTEST_TWO_PASS)
        junit_step.exit_status(self.xml, "1", self.log)
        failures = self.failures()
        self.assertEqual(len(failures), 1)
        self.assertIn("exited with status 1 after every case passed", failures[0])
        self.assertIn("LeakSanitizer", failures[0])

    def test_exit_status_zero_adds_nothing_and_a_counted_failure_is_not_counted_twice(self):
        with open(self.xml, "w") as f:
            f.write(GTEST_TWO_PASS)
        junit_step.exit_status(self.xml, "0", self.log)
        self.assertEqual(self.failures(), [])
        with open(self.xml, "w") as f:
            f.write(ROSTEST_WRAPPER_FAILED)
        junit_step.exit_status(self.xml, "1", self.log)
        self.assertEqual(len(self.failures()), 1)

    def test_a_step_that_could_not_run_is_one_failed_case(self):
        junit_step.failed(os.path.join(self.directory.name, "step_lint.xml"), "lint", "lint.py crashed")
        tally, failures = count_results.count(self.directory.name)
        self.assertEqual(tally["steps that could not run"], [0, 1, 0])
        self.assertIn("lint.py crashed", failures[0])


if __name__ == "__main__":
    unittest.main()
