#!/usr/bin/env python3
"""JUnit results for what a test step itself did, so nothing that failed leaves the count.

  junit_step.py failed OUT NAME MESSAGE
      OUT gets one failed case NAME: a step that could not run (a configure or build that
      failed, a checker that crashed before writing its results) still counts as a failure.
  junit_step.py exit-status XML STATUS LOG
      A test program that exited with STATUS != 0 although its XML says every case passed (a
      LeakSanitizer report is printed after GoogleTest wrote its results, then the exit status
      becomes non-zero) gets one failed case added to XML, quoting the end of LOG.
"""
import sys
import xml.etree.ElementTree as ET


def failed(out, name, message):
    suite = ET.Element("testsuite", name=name, tests="1", failures="1")
    case = ET.SubElement(suite, "testcase", classname="step", name=name)
    ET.SubElement(case, "failure", message=message)
    ET.ElementTree(suite).write(out)


def has_failure(root):
    return any(case.find("failure") is not None or case.find("error") is not None for case in root.iter("testcase"))


def log_tail(path, lines=15):
    try:
        with open(path, errors="replace") as f:
            return "".join(f.readlines()[-lines:])
    except OSError:
        return f"(no log at {path})"


def exit_status(path, status, log):
    if int(status) == 0:
        return
    tree = ET.parse(path)
    root = tree.getroot()
    if has_failure(root):
        return  # the failure is already counted
    # GoogleTest writes <testsuites><testsuite>...; the added case goes into the first suite.
    suite = root.find("testsuite") if root.tag == "testsuites" else None
    suite = root if suite is None else suite
    case = ET.SubElement(suite, "testcase", classname="exit_status", name="process exit status")
    failure = ET.SubElement(case, "failure",
                            message=f"exited with status {status} after every case passed "
                                    f"(a sanitizer report after the tests, e.g. a leak): see {log}")
    failure.text = log_tail(log)
    tree.write(path)


def main(argv):
    if len(argv) == 5 and argv[1] == "failed":
        failed(argv[2], argv[3], argv[4])
    elif len(argv) == 5 and argv[1] == "exit-status":
        exit_status(argv[2], argv[3], argv[4])
    else:
        print(__doc__, file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
