#!/usr/bin/env python3
"""clang-tidy (the checks of .clang-tidy) on the core sources, with the build's compile commands.

The core is every source under src/core/<module>/ (not the ROS layer, src/ros/, nor the
executables' folders, src/sim/ and src/cli/); its headers under include/cnc_bridge/ are checked through
them (.clang-tidy's HeaderFilterRegex). The compile commands come from the build directory
(CMakeLists.txt sets CMAKE_EXPORT_COMPILE_COMMANDS). Files are checked in parallel, JOBS at a time
(default: the number of processors). A finding is a failure; each is reported once with its file,
line and check.

Run alone (`scripts/check_clang_tidy.py [--build DIR] [FILE...]`, exit 1 on a finding) or as a case
of scripts/lint.py (findings()).
"""
import argparse
import concurrent.futures
import json
import os
import re
import shutil
import subprocess
import sys

from repo_files import repo_files

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FINDING = re.compile(r"^(/[^:\n]+):(\d+):\d+: (?:warning|error): (.*) \[([\w.,-]+)\]$", re.M)


def core_sources():
    return [path for path in repo_files(ROOT, "src/core/*.cpp") if path.count("/") == 3]


def unexplained_exclusions():
    """Checks that .clang-tidy turns off ("-name" in Checks) without a line "#   name: reason" above."""
    text = read_config()
    block = re.search(r"^Checks: >\n((?:  .*\n)+)", text, re.M)
    if block is None:
        return [(".clang-tidy", "no 'Checks: >' block")]
    excluded = re.findall(r"^\s+-([\w.-]+),?$", block.group(1), re.M)
    return [(".clang-tidy", f"{check} is turned off without a reason ('#   {check}: why')") for check in excluded
            if check != "*" and not re.search(rf"^#\s+{re.escape(check)}: \S", text, re.M)]


def read_config():
    with open(os.path.join(ROOT, ".clang-tidy"), encoding="utf-8") as f:
        return f.read()


def tidy(path, build):
    result = subprocess.run(["clang-tidy", "--quiet", "-p", build, os.path.join(ROOT, path)], cwd=ROOT,
                            capture_output=True, text=True)
    findings = [(os.path.relpath(file, ROOT), int(line), check, message)
                for file, line, message, check in FINDING.findall(result.stdout)]
    if result.returncode != 0 and not findings:
        findings.append((path, 0, "clang-tidy", (result.stderr.strip().splitlines() or ["failed"])[-1]))
    return findings


def findings(build, files=None, jobs=None):
    """(where, what) for every finding ('file:line', 'check: message'), and the number of files checked."""
    if shutil.which("clang-tidy") is None:
        return [("clang-tidy", "not installed (Debian package clang-tidy, in scripts/debian-packages.txt)")], 0
    database = os.path.join(build, "compile_commands.json")
    if not os.path.exists(database):
        return [(database, "missing: build first (scripts/build.sh; CMakeLists.txt exports the compile commands)")], 0
    with open(database) as f:
        compiled = {os.path.relpath(os.path.realpath(entry["file"]), os.path.realpath(ROOT)) for entry in json.load(f)}
    files = files or core_sources()
    if not files:
        return [(f"{ROOT}/src", "no core source found")], 0
    found = unexplained_exclusions()
    found += [(path, f"not in {database} (is it built?)") for path in files if path not in compiled]
    files = [path for path in files if path in compiled]
    results = set()
    with concurrent.futures.ThreadPoolExecutor(max_workers=jobs or os.cpu_count() or 1) as pool:
        for result in pool.map(lambda path: tidy(path, build), files):
            results.update(result)
    found += [(f"{file}:{line}", f"{check}: {message}") for file, line, check, message in sorted(results)]
    return found, len(files)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--build", default=os.environ.get("BUILD_DIR", os.path.join(ROOT, ".build")))
    parser.add_argument("files", nargs="*", help="sources relative to the repository (default: the core)")
    args = parser.parse_args()
    found, checked = findings(os.path.abspath(args.build), args.files, int(os.environ.get("JOBS", 0)) or None)
    for where, what in found:
        print(f"clang-tidy: {where}: {what}")
    print(f"clang-tidy ({checked} files checked): {'no finding' if not found else f'{len(found)} finding(s)'}")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
