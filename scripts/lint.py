#!/usr/bin/env python3
"""Style checks, written as JUnit XML: every C++ file clang-formatted (.clang-format), every
launch file with a doc on each <arg>. (The core's freedom from ROS: scripts/check_ros_free.py.)"""
import argparse
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def tracked(*patterns):
    out = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard", *patterns],
                         cwd=ROOT, capture_output=True, text=True, check=False).stdout
    return [line for line in out.splitlines() if line and os.path.exists(os.path.join(ROOT, line))]


def check_format(path):
    result = subprocess.run(["clang-format", "--dry-run", "-Werror", path], cwd=ROOT, capture_output=True, text=True)
    return None if result.returncode == 0 else (result.stderr.strip().splitlines() or ["not formatted"])[0]


def check_launch_args(path):
    root = ET.parse(os.path.join(ROOT, path)).getroot()
    declared = [arg for element in root.iter() if element.tag != "include" for arg in element.findall("arg")]
    missing = [arg.get("name") for arg in declared if not arg.get("doc")]
    return f"<arg> without doc: {', '.join(missing)}" if missing else None


def check_cell_launch_generated(path):
    """launch/cell.launch must be what scripts/cell_launch.py makes of config/cell.yaml."""
    result = subprocess.run([sys.executable, "scripts/cell_launch.py", "config/cell.yaml"], cwd=ROOT,
                            capture_output=True, text=True)
    if result.returncode != 0:
        return "scripts/cell_launch.py failed: " + result.stderr.strip()
    with open(os.path.join(ROOT, path)) as f:
        if f.read() != result.stdout:
            return "out of date: run scripts/cell_launch.py config/cell.yaml -o launch/cell.launch"
    return None


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--junit", required=True)
    args = parser.parse_args()
    cases = []
    cpp = tracked("*.cpp", "*.h")
    for path in cpp:
        cases.append(("format", path, check_format(path)))
    for path in tracked("launch/*.launch"):
        cases.append(("launch_args_documented", path, check_launch_args(path)))
    if os.path.exists(os.path.join(ROOT, "config/cell.yaml")):
        cases.append(("cell_launch_generated", "launch/cell.launch", check_cell_launch_generated("launch/cell.launch")))
    suite = ET.Element("testsuite", name="lint", tests=str(len(cases)))
    failed = 0
    for check, path, problem in cases:
        case = ET.SubElement(suite, "testcase", classname=f"lint.{check}", name=path)
        if problem:
            failed += 1
            ET.SubElement(case, "failure", message=problem)
            print(f"lint {check}: {path}: {problem}")
    suite.set("failures", str(failed))
    os.makedirs(os.path.dirname(args.junit), exist_ok=True)
    ET.ElementTree(suite).write(args.junit)
    print(f"lint: {len(cases) - failed} of {len(cases)} checks passed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
