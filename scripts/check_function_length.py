#!/usr/bin/env python3
"""No function in src/ is longer than LIMIT lines (from its first line to its closing brace):
a longer one is split by what each part does (one function per canned cycle, one per receiver
state, ...), so that each part can be read, named and tested on its own. Every executable's code
counts: the core, the ROS layer, the simulators and the tools.

Functions are found by Universal Ctags (Debian universal-ctags), which gives each definition's first
and last line; lambdas count as part of the function that holds them.

Run alone (`scripts/check_function_length.py [FILE ...]`, exit 1 on a problem) or as a case of
scripts/lint.py (problems()).
"""
import os
import shutil
import subprocess
import sys

from repo_files import repo_files

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LIMIT = 100
SOURCES = ("src/*.cpp", "src/*.h")


def ctags():
    for name in ("ctags-universal", "universal-ctags", "ctags"):
        path = shutil.which(name)
        if path:
            return path
    return None


def functions(paths):
    """(path, name, first line, last line) of every function defined in \\p paths."""
    tool = ctags()
    if tool is None:
        raise RuntimeError("Universal Ctags is not installed (Debian package universal-ctags)")
    result = subprocess.run([tool, "-x", "--_xformat=%F\t%N\t%n\t%{end}", "--kinds-c++=f", "--fields=+ne",
                             "--language-force=C++"] + list(paths),
                            cwd=ROOT, capture_output=True, text=True, check=True)
    found = []
    for line in result.stdout.splitlines():
        path, name, first, last = line.split("\t")
        if name.startswith("__anon") or not last.isdigit():
            continue  # a lambda: part of the function around it
        found.append((path, name, int(first), int(last)))
    return found


def problems(paths=None):
    """[(where, problem)] for every function over LIMIT lines, and how many functions were checked."""
    paths = paths or repo_files(ROOT, *SOURCES)
    found = functions(paths)
    long = [(f"{path}:{first}", f"{name} is {last - first + 1} lines long (at most {LIMIT}): split it by what "
             f"each part does") for path, name, first, last in found if last - first + 1 > LIMIT]
    return long, len(found)


def main():
    long, checked = problems(sys.argv[1:])
    for where, problem in long:
        print(f"function length: {where}: {problem}")
    print(f"function length: {checked} functions checked, {len(long)} over {LIMIT} lines")
    return 1 if long else 0


if __name__ == "__main__":
    sys.exit(main())
