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

    def tally(self, allowed_skips=frozenset()):
        tally, failures, _ = count_results.count(self.directory.name, allowed_skips)
        return tally, failures

    def test_cases_are_counted_by_kind(self):
        self.write("gtest-test_a.xml", GTEST_TWO_PASS)
        self.write("rosunit-x.xml", GTEST_TWO_PASS)
        self.write("rosunit-py.xml", PYTHON_ROSTEST)
        self.write("lint.xml", LINT_TWO_TOOLS)
        self.write("install_space.xml", ROSTEST_WRAPPER_PASSED.replace("rostest.runner.RosTest", "install"))
        tally, failures = self.tally(allowed_skips={"__main__.T.test_b"})
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

    def test_a_unit_case_and_its_sanitizer_run_are_one_case(self):
        self.write("gtest-test_a.xml", GTEST_TWO_PASS)
        self.write("asan_test_a.xml", GTEST_TWO_PASS.replace('classname="S"', 'classname="asan.S"'))
        tally, failures, sanitized = count_results.count(self.directory.name, set())
        self.assertEqual(tally["unit tests"], [2, 0, 0])
        self.assertEqual(sanitized, 2)
        self.assertEqual(failures, [])

    def test_a_case_that_fails_only_under_the_sanitizers_fails_once(self):
        self.write("gtest-test_a.xml", GTEST_TWO_PASS)
        self.write("asan_test_a.xml", GTEST_TWO_PASS.replace('classname="S"', 'classname="asan.S"').replace(
            '<testcase name="b" status="run" classname="asan.S"/>',
            '<testcase name="b" status="run" classname="asan.S"><failure message="heap-use-after-free"/></testcase>'))
        tally, failures = self.tally()
        self.assertEqual(tally["unit tests"], [1, 1, 0])
        self.assertEqual(len(failures), 1)
        self.assertIn("asan.S.b", failures[0])
        self.assertIn("heap-use-after-free", failures[0])

    def test_the_same_case_name_in_two_binaries_is_two_cases(self):
        self.write("gtest-test_a.xml", GTEST_TWO_PASS)
        self.write("gtest-test_b.xml", GTEST_TWO_PASS)
        self.write("asan_test_a.xml", GTEST_TWO_PASS.replace('classname="S"', 'classname="asan.S"'))
        tally, _ = self.tally()
        self.assertEqual(tally["unit tests"], [4, 0, 0])

    def test_an_unexpected_skip_fails_and_an_expected_one_is_a_skip(self):
        self.write("rosunit-py.xml", PYTHON_ROSTEST)
        tally, failures = self.tally()
        self.assertEqual(tally["rostests (Python)"], [1, 1, 0])
        self.assertIn("unexpected skip", failures[0])
        tally, failures = self.tally(allowed_skips={"__main__.T.test_b"})
        self.assertEqual(tally["rostests (Python)"], [1, 0, 1])
        self.assertEqual(failures, [])

    def test_the_suite_expects_no_skip_it_does_not_list(self):
        # The list the real run reads: every line names a case (classname.name), no wildcard.
        for line in count_results.expected_skips():
            self.assertRegex(line, r"^[\w.]+\.\w+$")

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
        _, failures, _ = count_results.count(self.directory.name, set())
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
        tally, failures, _ = count_results.count(self.directory.name, set())
        self.assertEqual(tally["steps that could not run"], [0, 1, 0])
        self.assertIn("lint.py crashed", failures[0])


if __name__ == "__main__":
    unittest.main()
