#!/usr/bin/env python3
"""Counts the test cases of a run from its JUnit XML and prints "N passed, N failed" last.

Every runner of the test suite (GoogleTest, rostest, the lint, sanitizer and fuzz steps) writes
JUnit XML. What counts is a distinct test case, never a file, and each case once:
- A unit test case runs twice, in the plain build (gtest-<binary>.xml) and under ASan + UBSan
  (asan_<binary>.xml, classnames prefixed "asan."); it is one case, which fails if either run
  failed. A case only one of the two runs has (a run's own failure: a hang, an exit status) counts
  on its own.
- A lint or format tool is one case (its failure message lists the files); a fuzz target is one case.
- rostest writes two files per launch file: rosunit-<name>.xml with the cases the test node ran,
  and rostest-<name>.xml with one wrapper case saying whether the node produced results. The
  wrapper counts only when it failed (the test did not run), so a case is never counted twice.
- A result file with no case at all is a failure: a --gtest_filter that matches nothing, a test
  node that ran no test, must not pass. So is a file that cannot be read.
- A skipped case is a skip only if test/expected_skips.txt names it (classname.name, one a line);
  any other skip is an unexpected skip and counts as failed.
A breakdown by kind is printed above the closing line; the kinds add up to it. Exit status 1 if
anything failed or nothing ran.
"""
import os
import sys
import xml.etree.ElementTree as ET
from collections import OrderedDict

# Kinds in the order the breakdown lists them.
KINDS = ["unit tests", "script tests", "rostests (C++)", "rostests (Python)", "rostest runs", "launch file checks",
         "fuzz targets", "lint tools", "two hosts", "install space", "steps that could not run", "other"]
SANITIZER_PREFIX = "asan."
EXPECTED_SKIPS = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "test", "expected_skips.txt")


def summary(problem, limit=400):
    """The failure's message and text on one line, cut to `limit` characters: enough to tell from
    the last lines of a run's output why a test failed."""
    text = " ".join(filter(None, [problem.get("message", ""), problem.text or ""]))
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


# Result files by the start of their name: what each step of scripts/test.sh writes.
KIND_OF_PREFIX = [("gtest-", "unit tests"), ("rostest-", "rostest runs"), ("roslaunch-check", "launch file checks"),
                  ("asan_", "unit tests"), ("fuzz_", "fuzz targets"), ("step_", "steps that could not run"),
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


def expected_skips(path=EXPECTED_SKIPS):
    try:
        with open(path) as f:
            return {line.strip() for line in f if line.strip() and not line.startswith("#")}
    except OSError:
        return set()


def outcome(case):
    """("failed", why), ("skipped", why) or ("passed", "") of one <testcase>."""
    problem = case.find("failure")
    if problem is None:
        problem = case.find("error")
    if problem is not None:
        return "failed", summary(problem)
    skipped = case.find("skipped")
    if skipped is not None or case.get("status") == "notrun":
        return "skipped", summary(skipped) if skipped is not None else "not run"
    return "passed", ""


def unit_key(name, case):
    """The identity of a unit test case across its plain and its sanitizer run."""
    binary = name[len("asan_"):] if name.startswith("asan_") else name[len("gtest-"):]
    classname = case.get("classname", "")
    if classname.startswith(SANITIZER_PREFIX):
        classname = classname[len(SANITIZER_PREFIX):]
    return binary[: -len(".xml")], classname, case.get("name", "")


def read_cases(directory):
    """[(kind, label, outcome, unit key or None)] of every case, and the failures of files."""
    cases, file_failures = [], []
    for dirpath, _, files in os.walk(directory):
        for name in sorted(files):
            if not name.endswith(".xml"):
                continue
            path = os.path.join(dirpath, name)
            try:
                root = ET.parse(path).getroot()
            except ET.ParseError as error:
                file_failures.append(("other", f"{path}: unreadable result ({error})"))
                continue
            kind = kind_of(name, root)
            found = list(root.iter("testcase"))
            if not found:
                file_failures.append((kind, f"{path}: no test case ran (a filter that matches nothing? a test that did not start?)"))
                continue
            for case in found:
                label = f"{case.get('classname', '')}.{case.get('name', '')}"
                result = outcome(case)
                if kind == "rostest runs" and result[0] != "failed":
                    continue  # the cases it ran are counted from its rosunit file
                key = unit_key(name, case) if name.startswith(("gtest-", "asan_")) else None
                cases.append((kind, label, result, key))
    return cases, file_failures


def merge_sanitizer_runs(cases):
    """The cases with each unit case's two runs made one; the number of unit cases that ran both."""
    merged, by_key, both = [], {}, 0
    for kind, label, result, key in cases:
        if key is None:
            merged.append((kind, label, result))
            continue
        if key in by_key:
            # The second run of the case: it keeps the first run's place and takes a failure of
            # either run, labelled by the run that failed ("asan." for the sanitizer run).
            index = by_key[key]
            _, first_label, first = merged[index]
            if first[0] != "failed" and result[0] == "failed":
                merged[index] = (kind, label, result)
            elif first[0] != "failed" and first_label.startswith(SANITIZER_PREFIX):
                merged[index] = (kind, label, first)
            both += 1
            continue
        by_key[key] = len(merged)
        merged.append((kind, label, result))
    return merged, both


def count(directory, allowed_skips=None):
    """{kind: [passed, failed, skipped]}, the failures' labels, and how many unit cases also ran
    under the sanitizers."""
    allowed_skips = expected_skips() if allowed_skips is None else allowed_skips
    tally = OrderedDict((kind, [0, 0, 0]) for kind in KINDS)
    cases, file_failures = read_cases(directory)
    failures = []
    for kind, message in file_failures:
        tally[kind][1] += 1
        failures.append(message)
    merged, sanitized = merge_sanitizer_runs(cases)
    for kind, label, (state, why) in merged:
        if state == "skipped" and label not in allowed_skips:
            state, why = "failed", f"unexpected skip ({why}); test/expected_skips.txt lists the skips a run may have"
        if state == "failed":
            tally[kind][1] += 1
            failures.append(f"{label}: {why}")
        elif state == "skipped":
            tally[kind][2] += 1
        else:
            tally[kind][0] += 1
    return tally, failures, sanitized


def main():
    directory = sys.argv[1] if len(sys.argv) > 1 else ".build/test_results"
    tally, failures, sanitized = count(directory)
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
            if kind == "unit tests" and sanitized:
                print(f"  {'':<26} ({sanitized} of them ran twice: plain, and under ASan + UBSan; counted once)")
    # A skipped test is neither passed nor hidden: it is named in the closing line.
    print(f"{passed} passed, {failed} failed" + (f", {skipped} skipped" if skipped else ""))
    return 0 if failed == 0 and passed > 0 else 1


if __name__ == "__main__":
    sys.exit(main())
