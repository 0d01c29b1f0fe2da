#!/usr/bin/env python3
"""Counts JUnit XML test results under a directory and prints "N passed, N failed" last.

Every runner of the test suite (GoogleTest, rostest, the lint and fuzz steps) writes JUnit XML;
a result file that cannot be parsed counts as one failure, so a crashed test is never silent.
Exit status 1 if anything failed or nothing ran.
"""
import os
import sys
import xml.etree.ElementTree as ET


def summary(problem, limit=400):
    """The failure's message and text on one line, cut to `limit` characters: enough to tell from
    the last lines of a run's output why a test failed."""
    text = " ".join(filter(None, [problem.get("message", ""), problem.text or ""]))
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def count(directory):
    passed, failed, skipped, failures = 0, 0, 0, []
    for dirpath, _, files in os.walk(directory):
        for name in sorted(files):
            if not name.endswith(".xml"):
                continue
            path = os.path.join(dirpath, name)
            try:
                root = ET.parse(path).getroot()
            except ET.ParseError as error:
                failed += 1
                failures.append(f"{path}: unreadable result ({error})")
                continue
            cases = list(root.iter("testcase"))
            if not cases and root.get("errors", "0") not in ("0", ""):
                failed += 1
                failures.append(f"{path}: the test did not run")
            for case in cases:
                label = f"{case.get('classname', '')}.{case.get('name', '')}"
                problem = case.find("failure")
                if problem is None:
                    problem = case.find("error")
                if problem is not None:
                    failed += 1
                    failures.append(f"{label}: {summary(problem)}")
                elif case.find("skipped") is not None or case.get("status") == "notrun":
                    skipped += 1
                else:
                    passed += 1
    return passed, failed, skipped, failures


def main():
    directory = sys.argv[1] if len(sys.argv) > 1 else ".build/test_results"
    passed, failed, skipped, failures = count(directory)
    for label in failures:
        print(f"FAILED: {label}")
    # A skipped test is neither passed nor hidden: it is named in the closing line.
    print(f"{passed} passed, {failed} failed" + (f", {skipped} skipped" if skipped else ""))
    return 0 if failed == 0 and passed > 0 else 1


if __name__ == "__main__":
    sys.exit(main())
