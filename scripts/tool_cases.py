"""One JUnit test case per check tool: a lint tool run over 500 files is one test, not 500.

A check gives its problems as (where, what) pairs; the case fails when there is any, and its
failure message lists them all (the file, then what is wrong with it), so the closing line counts
tools while the output still names every file to fix.
"""
import os
import xml.etree.ElementTree as ET


class ToolCases:
    """Collects the cases of one suite (a lint script) and writes them as JUnit XML."""

    def __init__(self, suite):
        self.suite = suite
        self.cases = []  # (name, checked count, problems)

    def add(self, name, problems, checked=None):
        """A case `name` that checked `checked` items and found `problems` [(where, what), ...]."""
        self.cases.append((name, checked, [(where, what) for where, what in problems if what]))

    def failed(self):
        return [case for case in self.cases if case[2]]

    def report(self):
        """Prints every problem, then one summary line per case; returns the exit status."""
        for name, _, problems in self.cases:
            for where, what in problems:
                print(f"{self.suite} {name}: {where}: {what}")
        for name, checked, problems in self.cases:
            scope = f" ({checked} checked)" if checked is not None else ""
            verdict = f"FAILED, {len(problems)} problem(s)" if problems else "passed"
            print(f"{self.suite} {name}{scope}: {verdict}")
        return 1 if self.failed() else 0

    def write(self, path):
        root = ET.Element("testsuite", name=self.suite, tests=str(len(self.cases)),
                          failures=str(len(self.failed())))
        for name, checked, problems in self.cases:
            case = ET.SubElement(root, "testcase", classname=f"lint.{self.suite}", name=name)
            if problems:
                failure = ET.SubElement(case, "failure",
                                        message=f"{len(problems)} of {checked if checked is not None else '?'} failed")
                failure.text = "\n".join(f"{where}: {what}" for where, what in problems)
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        ET.ElementTree(root).write(path)
