#!/usr/bin/env python3
"""Runs the unit tests of the project's own scripts (test/scripts/test_*.py) and writes their
cases as JUnit XML, so the closing line counts them.  usage: run_unittests.py OUT.xml"""
import os
import sys
import unittest
import xml.etree.ElementTree as ET

HERE = os.path.dirname(os.path.abspath(__file__))


class RecordingResult(unittest.TextTestResult):
    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.outcomes = []  # (test id, state, text): state "passed", "failed" or "skipped"

    def addSuccess(self, test):
        super().addSuccess(test)
        self.outcomes.append((test.id(), "passed", ""))

    def addFailure(self, test, err):
        super().addFailure(test, err)
        self.outcomes.append((test.id(), "failed", self._exc_info_to_string(err, test)))

    def addError(self, test, err):
        super().addError(test, err)
        self.outcomes.append((test.id(), "failed", self._exc_info_to_string(err, test)))

    def addSkip(self, test, reason):
        super().addSkip(test, reason)
        self.outcomes.append((test.id(), "skipped", reason))

    def addExpectedFailure(self, test, err):
        super().addExpectedFailure(test, err)
        self.outcomes.append((test.id(), "passed", ""))

    def addUnexpectedSuccess(self, test):
        super().addUnexpectedSuccess(test)
        self.outcomes.append((test.id(), "failed", "unexpected success: the test is marked as an expected failure"))


def main(out):
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(HERE)), "scripts"))
    suite = unittest.defaultTestLoader.discover(HERE, pattern="test_*.py")
    result = unittest.TextTestRunner(resultclass=RecordingResult, verbosity=1).run(suite)
    root = ET.Element("testsuite", name="scripts", tests=str(len(result.outcomes)))
    for test_id, state, text in result.outcomes:
        module, _, name = test_id.rpartition(".")
        case = ET.SubElement(root, "testcase", classname=f"scripts.{module}", name=name)
        if state == "failed":
            ET.SubElement(case, "failure", message=text.strip().splitlines()[-1]).text = text
        elif state == "skipped":
            ET.SubElement(case, "skipped", message=text)
    ET.ElementTree(root).write(out)
    # Skips are written as skips; whether one was expected is decided by scripts/count_results.py.
    failed = any(state == "failed" for _, state, _ in result.outcomes)
    return 0 if not failed and result.testsRun else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
