#!/usr/bin/env python3
"""The module table of docs/DEVELOPING.md against the tree.

The table ("## Modules") has a row per folder of src/core/ and src/ros/ and per other src/ folder and names, in backquotes, the module's CMake
fragment, library, node, simulator, unit tests, rostests, fuzz targets, benchmark folder and doc
pages. This check fails when:
- such a folder has no row, or a row names a folder that does not exist;
- a named file or folder does not exist, or a named CMake target is declared nowhere in
  CMakeLists.txt or cmake/modules/*.cmake;
- a CMake fragment, a rostest launch file, a fuzz target (test/fuzz/fuzz_*.cpp), a benchmark
  folder (bench/*/) or a protocol page (docs/protocols/*.md) appears in no row;
- any repository path written elsewhere in the guide (e.g. a source file in the fragment example)
  does not exist.

Run alone (`scripts/check_module_table.py`, exit 1 on a problem) or as a case of scripts/lint.py
(problems()).
"""
import glob
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GUIDE = "docs/DEVELOPING.md"
HEADING = "## Modules"
COLUMNS = ("folder", "cmake fragment", "library", "node", "simulator", "unit tests", "rostests", "fuzz targets",
           "benchmark", "doc pages")
# src/ shows the layers: the ROS-free core (a folder per protocol), the ROS layer (the nodes and what
# they share), the simulators, the test doubles and the command-line tools.
LAYERS = ("src/core", "src/ros")
TARGET_COLUMNS = ("library", "node", "simulator", "unit tests", "fuzz targets")
# A CMake target is declared by one of these (the package's own helpers and CMake's/catkin's).
DECLARATION = re.compile(r"\b(?:cnc_core_module|cnc_sim_library|cnc_node|cnc_tool|cnc_core_gtest|cnc_fuzz_target|add_library|"
                         r"add_executable|catkin_add_gtest|add_rostest_gtest)\(\s*([A-Za-z0-9_]+)")
# Repository paths written in the guide's prose and examples (patterns with <, *, { or $ are skipped).
REPO_PATH = re.compile(r"(?<![\w./$-])((?:src|include|test|scripts|bench|docs|cmake|launch|config|msg|srv|action|urdf|"
                       r"rviz)/[A-Za-z0-9_./<>*{}$-]*[A-Za-z0-9_/])")


def read(path):
    with open(os.path.join(ROOT, path), encoding="utf-8") as f:
        return f.read()


def table_rows(text):
    """The rows of the table under HEADING as lists of cells; raises ValueError when it is missing."""
    lines = text.splitlines()
    try:
        start = lines.index(HEADING)
    except ValueError:
        raise ValueError(f"{GUIDE} has no '{HEADING}' section") from None
    rows = []
    for line in lines[start + 1:]:
        if line.startswith("## "):
            break
        if line.startswith("|"):
            rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
        elif rows:
            break
    if len(rows) < 3:
        raise ValueError(f"{GUIDE}: no table under '{HEADING}'")
    header = tuple(cell.lower() for cell in rows[0])
    if header != COLUMNS:
        raise ValueError(f"{GUIDE}: the module table's columns are {list(header)}, expected {list(COLUMNS)}")
    return rows[2:]


def names(cell):
    return re.findall(r"`([^`]+)`", cell)


def declared_targets():
    files = ["CMakeLists.txt"] + sorted(os.path.relpath(p, ROOT) for p in glob.glob(os.path.join(ROOT, "cmake/modules/*.cmake")))
    targets = set()
    for path in files:
        code = "\n".join(line.split("#", 1)[0] for line in read(path).splitlines())
        targets.update(DECLARATION.findall(code))
    return targets


def exists(path):
    return os.path.exists(os.path.join(ROOT, path))


def row_problems(rows, targets):
    problems, named = [], {column: set() for column in COLUMNS}
    for row in rows:
        if len(row) != len(COLUMNS):
            problems.append(f"row '{row[0]}' has {len(row)} cells, not {len(COLUMNS)}")
            continue
        for column, cell in zip(COLUMNS, row):
            for name in names(cell):
                named[column].add(name)
                if column in TARGET_COLUMNS and "/" not in name and "." not in name:
                    if name not in targets:
                        problems.append(f"{column} '{name}' (row {row[0]}) is no CMake target")
                    continue
                path = os.path.join("test/rostest", name) if column == "rostests" and "/" not in name else name
                if not exists(path):
                    problems.append(f"{column} '{name}' (row {row[0]}) does not exist")
    return problems, named


def coverage_problems(named):
    problems = []
    folders = {name.rstrip("/") for name in named["folder"]}
    for folder in sorted(d for d in glob.glob(os.path.join(ROOT, "src/*")) + glob.glob(os.path.join(ROOT, "src/*/*"))
                         if os.path.isdir(d)):
        rel = os.path.relpath(folder, ROOT)
        if rel in LAYERS or rel.startswith("src/sim/"):
            continue  # a layer has a row per folder in it; the simulators' folders share one row
        if rel not in folders:
            problems.append(f"{rel}/ has no row")
    expected = {
        "cmake fragment": {os.path.relpath(p, ROOT) for p in glob.glob(os.path.join(ROOT, "cmake/modules/*.cmake"))},
        "rostests": {os.path.basename(p) for p in glob.glob(os.path.join(ROOT, "test/rostest/*.test"))},
        "fuzz targets": {os.path.splitext(os.path.basename(p))[0] for p in glob.glob(os.path.join(ROOT, "test/fuzz/fuzz_*.cpp"))},
        "benchmark": {os.path.relpath(p, ROOT) + "/" for p in glob.glob(os.path.join(ROOT, "bench/*")) if os.path.isdir(p)},
        "doc pages": {os.path.relpath(p, ROOT) for p in glob.glob(os.path.join(ROOT, "docs/protocols/*.md"))
                      if not p.endswith("README.md")},
    }
    for column, wanted in expected.items():
        given = {os.path.basename(n) if column == "rostests" else n for n in named[column]}
        for missing in sorted(wanted - given):
            problems.append(f"{missing} appears in no row (column '{column}')")
    return problems


def path_problems(text):
    problems = []
    for path in sorted(set(REPO_PATH.findall(text))):
        if any(c in path for c in "<>*{}$"):
            continue
        if not exists(path.rstrip(".")):
            problems.append(f"{GUIDE} names {path}, which does not exist")
    return problems


def problems():
    """Every disagreement between the guide and the tree, as sentences; [] when they agree."""
    text = read(GUIDE)
    try:
        rows = table_rows(text)
    except ValueError as error:
        return [str(error)]
    found, named = row_problems(rows, declared_targets())
    return found + coverage_problems(named) + path_problems(text)


def main():
    found = problems()
    for problem in found:
        print(f"module table: {problem}")
    print(f"module table: {'ok' if not found else f'{len(found)} problem(s)'}")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
