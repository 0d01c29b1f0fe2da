#!/usr/bin/env python3
"""Counts the test cases of a run from its JUnit XML and prints "N passed, N failed" last.

Every runner of the test suite (GoogleTest, rostest, the lint, sanitizer and fuzz steps) writes
JUnit XML. What counts is a test case, never a file:
- A lint tool is one case (its failure message lists the files), a fuzz target is one case, a
  unit test case run again under the sanitizers counts again, as a sanitizer re-run.
- rostest writes two files per launch file: rosunit-<name>.xml with the cases the test node ran,
  and rostest-<name>.xml with one wrapper case saying whether the node produced results. The
  wrapper counts only when it failed (the test did not run), so a case is never counted twice.
- A result file with no case at all is a failure: a --gtest_filter that matches nothing, a test
  node that ran no test, must not pass. So is a file that cannot be read.
A breakdown by kind is printed above the closing line. Exit status 1 if anything failed or
nothing ran.
"""
import os
import sys
import xml.etree.ElementTree as ET
from collections import OrderedDict

# Kinds in the order the breakdown lists them.
KINDS = ["unit tests", "script tests", "rostests (C++)", "rostests (Python)", "rostest runs", "launch file checks",
         "sanitizer re-runs", "fuzz targets", "lint tools", "two hosts", "install space", "steps that could not run", "other"]


def summary(problem, limit=400):
    """The failure's message and text on one line, cut to `limit` characters: enough to tell from
    the last lines of a run's output why a test failed."""
    text = " ".join(filter(None, [problem.get("message", ""), problem.text or ""]))
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


# Result files by the start of their name: what each step of scripts/test.sh writes.
KIND_OF_PREFIX = [("gtest-", "unit tests"), ("rostest-", "rostest runs"), ("roslaunch-check", "launch file checks"),
                  ("asan_", "sanitizer re-runs"), ("fuzz_", "fuzz targets"), ("step_", "steps that could not run"),
                  ("MISSING-", "steps that could not run"),
                  ("scripts", "script tests"), ("two_hosts", "two hosts"), ("install_space", "install space")]


def kind_of(name, root):
    """The kind of the result file `name` (its root element `root`)."""
    if name.startswith("rosunit-"):
        # GoogleTest writes <testsuites>; Python's unittest (through rosunit) a <testsuite>.
        return "rostests (C++)" if root.tag == "testsuites" else "rostests (Python)"
    for prefix, kind in KIND_OF_PREFIX:
        if name.startswith(prefix):
            return kind
    if any((case.get("classname") or "").startswith("lint.") for case in root.iter("testcase")):
        return "lint tools"
    return "other"


def count(directory):
    """{kind: [passed, failed, skipped]} and the failures' labels."""
    tally = OrderedDict((kind, [0, 0, 0]) for kind in KINDS)
    failures = []
    for dirpath, _, files in os.walk(directory):
        for name in sorted(files):
            if not name.endswith(".xml"):
                continue
            path = os.path.join(dirpath, name)
            try:
                root = ET.parse(path).getroot()
            except ET.ParseError as error:
                tally["other"][1] += 1
                failures.append(f"{path}: unreadable result ({error})")
                continue
            kind = kind_of(name, root)
            cases = list(root.iter("testcase"))
            if not cases:
                tally[kind][1] += 1
                failures.append(f"{path}: no test case ran (a filter that matches nothing? a test that did not start?)")
                continue
            for case in cases:
                label = f"{case.get('classname', '')}.{case.get('name', '')}"
                problem = case.find("failure")
                if problem is None:
                    problem = case.find("error")
                if problem is not None:
                    tally[kind][1] += 1
                    failures.append(f"{label}: {summary(problem)}")
                elif kind == "rostest runs":
                    continue  # the cases it ran are counted from its rosunit file
                elif case.find("skipped") is not None or case.get("status") == "notrun":
                    tally[kind][2] += 1
                else:
                    tally[kind][0] += 1
    return tally, failures


def main():
    directory = sys.argv[1] if len(sys.argv) > 1 else ".build/test_results"
    tally, failures = count(directory)
    for label in failures:
        print(f"FAILED: {label}")
    passed = sum(each[0] for each in tally.values())
    failed = sum(each[1] for each in tally.values())
    skipped = sum(each[2] for each in tally.values())
    print("test cases by kind:")
    for kind, (kind_passed, kind_failed, kind_skipped) in tally.items():
        if kind_passed or kind_failed or kind_skipped:
            extra = f", {kind_skipped} skipped" if kind_skipped else ""
            print(f"  {kind:<26} {kind_passed:5d} passed, {kind_failed} failed{extra}")
    # A skipped test is neither passed nor hidden: it is named in the closing line.
    print(f"{passed} passed, {failed} failed" + (f", {skipped} skipped" if skipped else ""))
    return 0 if failed == 0 and passed > 0 else 1


if __name__ == "__main__":
    sys.exit(main())
