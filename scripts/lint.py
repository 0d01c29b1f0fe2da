#!/usr/bin/env python3
"""Style checks, written as JUnit XML: every C++ file clang-formatted (.clang-format), every
launch file with a doc on each <arg>, no citation of a document a reader of the repository cannot
open, the module table of docs/DEVELOPING.md matching the tree
(scripts/check_module_table.py), no sleep standing in for synchronisation in test/
(scripts/check_test_sleeps.py), no function in src/ over 100 lines (scripts/check_function_length.py),
clang-tidy clean on the core (scripts/check_clang_tidy.py, with the
compile commands of the build given by --build). (The core's freedom from ROS: scripts/check_ros_free.py.)

The files come from git, or from a walk of the tree outside a git checkout (scripts/repo_files.py);
finding no C++ or no launch file at all is a failure, not a pass over nothing."""
import argparse
import os
import re
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

import check_clang_tidy
import check_module_table
import check_function_length
import check_test_sleeps
from repo_files import git_files, repo_files, walked_files
from tool_cases import ToolCases

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CPP = ("*.cpp", "*.h")
# Text that cites what a reader of the repository cannot open: the project's internal source
# documents, their design notes, issue numbers. Cite docs/ (docs/protocols/ for the wire
# protocols), manuals by name and public projects instead.
UNOPENABLE = re.compile(
    r"\bseeds/|shared/(?:seeds|fixtures)|\.\./shared/"
    r"|\b(?:opendnc_haas_xmodem_dprnt|pc_dnc_drip_feed_fanuc|qcnc_ethernut_opcode_client|esprit_at_protocol_controller"
    r"|universal_cnc_serial_i2c_protocol)\.md"
    r"|\b[Tt]he seed(?:'s|s'|s\b| document| section)|(?<![-~\w])[Ss]eed (?:section|figure|document|\d)|\(seed\b[ :]"
    r"|\bDESIGN(?: section| §| \d|\.md)|\b[Ii]ssue \d+")
# A citation of a section of a page under docs/, as docs/protocols/xmodem.md#packet.
SECTION = re.compile(r"((?:docs/)?(?:protocols/)?[A-Za-z_]+\.md)#([a-z0-9-]+)")
REFERENCED = ("src/*", "include/*", "test/*", "scripts/*", "bench/*", "docs/*", "cmake/*", "launch/*", "config/*",
              "CMakeLists.txt", "README.md", "package.xml", "Makefile")
LAUNCH = ("launch/*.launch",)


def found_cases():
    """A case per file kind that must exist; in a git checkout also: the walk finds what git lists."""
    cases = []
    for kind, patterns in (("C++", CPP), ("launch", LAUNCH)):
        count = len(repo_files(ROOT, *patterns))
        cases.append(("files_found", kind, None if count else f"no {kind} file found under {ROOT}"))
        listed = git_files(ROOT, patterns)
        if listed is not None:
            walked = walked_files(ROOT, patterns)
            differ = sorted(set(listed) ^ set(walked))
            cases.append(("walk_matches_git", kind, f"the tree walk and git differ on: {', '.join(differ[:5])}"
                          if differ else None))
    return cases


def check_format(path):
    result = subprocess.run(["clang-format", "--dry-run", "-Werror", path], cwd=ROOT, capture_output=True, text=True)
    return None if result.returncode == 0 else (result.stderr.strip().splitlines() or ["not formatted"])[0]


def check_launch_args(path):
    root = ET.parse(os.path.join(ROOT, path)).getroot()
    declared = [arg for element in root.iter() if element.tag != "include" for arg in element.findall("arg")]
    missing = [arg.get("name") for arg in declared if not arg.get("doc")]
    return f"<arg> without doc: {', '.join(missing)}" if missing else None


def heading_anchors(path):
    """The anchors a Markdown viewer gives the headings of a page ("## Haas end of transfer" -> haas-end-of-transfer)."""
    with open(os.path.join(ROOT, path), encoding="utf-8") as f:
        headings = [line.lstrip("#").strip().lower() for line in f if line.startswith("#")]
    return {re.sub(r"[^\w\- ]", "", heading).replace(" ", "-") for heading in headings}


def check_references(paths):
    """(file:line, problem) for every citation of something a reader of the repository cannot open, and for
    every citation of a page section (docs/protocols/xmodem.md#haas-end-of-transfer) that does not exist."""
    pages = {path: heading_anchors(path) for path in paths if path.startswith("docs/") and path.endswith(".md")}
    found = []
    for path in paths:
        try:
            with open(os.path.join(ROOT, path), encoding="utf-8") as f:
                lines = f.read().splitlines()
        except (UnicodeDecodeError, IsADirectoryError):
            continue  # binary files cite nothing
        for number, line in enumerate(lines, 1):
            match = UNOPENABLE.search(line)
            if match:
                found.append((f"{path}:{number}", f"cites {match.group(0)!r}: cite docs/ or a named public source"))
            for page, anchor in SECTION.findall(line):
                candidates = [page, "docs/" + page, "docs/protocols/" + page,
                              os.path.normpath(os.path.join(os.path.dirname(path), page))]
                target = next((candidate for candidate in candidates if candidate in pages), None)
                if target is None or anchor not in pages[target]:
                    found.append((f"{path}:{number}", f"cites {page}#{anchor}, a page section that does not exist"))
    return found


def check_cell_launch_generated(path, rviz_path="rviz/cell.rviz"):
    """launch/cell.launch and rviz/cell.rviz must be what scripts/cell_launch.py makes of
    config/cell.yaml."""
    with tempfile.TemporaryDirectory() as scratch:
        rviz = os.path.join(scratch, "cell.rviz")
        result = subprocess.run([sys.executable, "scripts/cell_launch.py", "config/cell.yaml", "--rviz", rviz],
                                cwd=ROOT, capture_output=True, text=True)
        if result.returncode != 0:
            return "scripts/cell_launch.py failed: " + result.stderr.strip()
        with open(rviz) as f:
            rviz_text = f.read()
    # The launch file names the configuration it was written with: here the package's own.
    launch_text = result.stdout.replace(rviz, "$(find cnc_bridge)/" + rviz_path)
    for name, text in ((path, launch_text), (rviz_path, rviz_text)):
        with open(os.path.join(ROOT, name)) as f:
            if f.read() != text:
                return (f"{name} out of date: run scripts/cell_launch.py config/cell.yaml -o launch/cell.launch "
                        f"--rviz rviz/cell.rviz")
    return None


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--junit", required=True)
    parser.add_argument("--build", default=os.path.join(ROOT, ".build"), help="build directory: compile commands")
    args = parser.parse_args()
    tools = ToolCases("lint")
    discovery = found_cases()
    tools.add("file discovery", [(f"{check} {kind}", problem) for check, kind, problem in discovery],
              checked=len(discovery))
    cpp = repo_files(ROOT, *CPP)
    tools.add("clang-format", [(path, check_format(path)) for path in cpp], checked=len(cpp))
    launch = repo_files(ROOT, *LAUNCH)
    tools.add("launch arg docs", [(path, check_launch_args(path)) for path in launch], checked=len(launch))
    text = repo_files(ROOT, *REFERENCED)
    tools.add("references resolvable", check_references(text), checked=len(text))
    table = check_module_table.problems()
    tools.add("module table", [(check_module_table.GUIDE, problem) for problem in table], checked=1)
    sleeps, sleep_files = check_test_sleeps.problems()
    tools.add("no sleep as synchronisation", sleeps, checked=sleep_files)
    long_functions, functions = check_function_length.problems()
    tools.add("functions at most 100 lines", long_functions, checked=functions)
    tidy, tidied = check_clang_tidy.findings(os.path.abspath(args.build))
    tools.add("clang-tidy", tidy, checked=tidied)
    if os.path.exists(os.path.join(ROOT, "config/cell.yaml")):
        tools.add("cell.launch generated", [("launch/cell.launch", check_cell_launch_generated("launch/cell.launch"))],
                  checked=1)
    tools.write(args.junit)
    return tools.report()


if __name__ == "__main__":
    sys.exit(main())
