#!/usr/bin/env python3
"""No sleep stands in for synchronisation in the tests. A test waits on an event (a message, a
condition variable, a read with a timeout, a line in a simulator's log); a sleep in test/ is allowed
only where it says, in a comment on its line or in the comment lines just above it, which of these
it is:
- "poll": a loop that polls a condition with a deadline, where the condition has no event to wait
  on (a file another process writes, a counter of another thread, a port that starts answering);
- "window": a measurement window, a span of time in which nothing may happen, which the test then
  closes with an event proving the system was running (a later message on the same link);
- "under test": the passing of time is itself what the test is about (a timeout, a deadman, a stall);
- "pace": the pace of a client or a stream the test plays (10 Hz jog calls);
- "stands for": a duration of work the test plays (a query's round trip).
usage: check_test_sleeps.py [FILE ...]  (default: every test file of the repository)"""
import os
import re
import sys

from repo_files import repo_files

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TEST_FILES = ("test/*.cpp", "test/*.h", "test/*.py", "test/*.sh")
SLEEP = re.compile(r"sleep_for\s*\(|\busleep\s*\(|\bnanosleep\s*\(|\.sleep\s*\(|\btime\.sleep\s*\(|\brospy\.sleep\s*\("
                   r"|^\s*sleep\s+[0-9.]|[;&|]\s*sleep\s+[0-9.]")
REASON = re.compile(r"\b(?:poll(?:s|ed|ing)?|window|under test|pace|stands? for)\b", re.IGNORECASE)
COMMENT = re.compile(r"^\s*(?://|#)")
LOOK_ABOVE = 3
OWN_TEST = "test/scripts/test_check_test_sleeps.py"  # its examples of sleeps are strings


def problems_in(path, text):
    """[(path:line, problem)] for each sleep without a reason."""
    lines = text.splitlines()
    found = []
    for index, line in enumerate(lines):
        if not SLEEP.search(line) or COMMENT.match(line):
            continue
        context = [line]
        above = index - 1
        while above >= 0 and index - above <= LOOK_ABOVE and COMMENT.match(lines[above]):
            context.append(lines[above])
            above -= 1
        if not any(REASON.search(each) for each in context):
            found.append((f"{path}:{index + 1}", "a sleep without its reason (poll, window, under test, pace, "
                                                 "stands for): wait on an event instead, or say which it is"))
    return found


def problems(paths=None):
    if paths is None:
        paths = [path for path in repo_files(ROOT, *TEST_FILES) if path != OWN_TEST]
    found = []
    for path in paths:
        with open(os.path.join(ROOT, path), errors="replace") as f:
            found += problems_in(path, f.read())
    return found, len(paths)


def main(argv):
    found, checked = problems(argv[1:] or None)
    for where, problem in found:
        print(f"{where}: {problem}")
    print(f"{checked} test files checked, {len(found)} sleeps without a reason")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
