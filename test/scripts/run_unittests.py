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
        self.outcomes = []  # (test id, None or failure text)

    def addSuccess(self, test):
        super().addSuccess(test)
        self.outcomes.append((test.id(), None))

    def addFailure(self, test, err):
        super().addFailure(test, err)
        self.outcomes.append((test.id(), self._exc_info_to_string(err, test)))

    def addError(self, test, err):
        super().addError(test, err)
        self.outcomes.append((test.id(), self._exc_info_to_string(err, test)))


def main(out):
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(HERE)), "scripts"))
    suite = unittest.defaultTestLoader.discover(HERE, pattern="test_*.py")
    result = unittest.TextTestRunner(resultclass=RecordingResult, verbosity=1).run(suite)
    root = ET.Element("testsuite", name="scripts", tests=str(len(result.outcomes)))
    for test_id, problem in result.outcomes:
        module, _, name = test_id.rpartition(".")
        case = ET.SubElement(root, "testcase", classname=f"scripts.{module}", name=name)
        if problem:
            ET.SubElement(case, "failure", message=problem.strip().splitlines()[-1]).text = problem
    ET.ElementTree(root).write(out)
    return 0 if result.wasSuccessful() and result.testsRun else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
