#!/usr/bin/env python3
"""Checks that the core of cnc_bridge is free of ROS, in its sources and in what it links.

- Sources: no core file (anything outside src/ros/, *_node.{h,cpp}, test/rostest and
  bench/) includes a ROS header: roscpp, tf/tf2, actionlib, diagnostics, rosbag, any *_msgs or
  *_srvs package, or one of cnc_bridge's generated message headers (cnc_bridge/MachineState.h).
- Binaries (after a build): the core's executables (simulators, cnc_dnc, core unit tests) load no
  ROS library (ldd).
- Itself: the patterns catch a sample of ROS includes and pass core includes, so a loosened
  pattern fails here rather than letting ROS in unseen; and it finds core sources at all (from
  git, or by walking the tree outside a git checkout: scripts/repo_files.py).

Writes JUnit XML. usage: check_ros_free.py --junit FILE [--build BUILD_DIR]
"""
import argparse
import glob
import os
import re
import subprocess
import sys

from repo_files import repo_files
from tool_cases import ToolCases

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

ROS_PACKAGES = ("ros|rospy|roscpp|rosconsole|rostime|rosbag|rosbag_storage|tf|tf2|tf2_ros|tf2_geometry_msgs|"
                "tf2_eigen|actionlib|diagnostic_updater|message_filters|xmlrpcpp|robot_state_publisher|urdf|"
                "image_transport|pluginlib|nodelet|dynamic_reconfigure|[a-z0-9_]+_msgs|[a-z0-9_]+_srvs")
# Generated message, service and action headers of this package are CamelCase (MachineState.h);
# the core's own headers are lower case.
ROS_INCLUDE = re.compile(r'#\s*include\s*[<"]((' + ROS_PACKAGES + r')/|cnc_bridge/[A-Z]\w*\.h)')
NOT_CORE = re.compile(r"(^|/)(ros|nodes)/|_node\.(h|cpp)$|^test/rostest/|^test/net/")
ROS_LIBRARY = re.compile(r"\blib(roscpp|rosconsole|rostime|rosbag|tf2|actionlib|diagnostic_updater|xmlrpcpp|"
                         r"cpp_common|message_filters)\S*\.so")

SHOULD_CATCH = ["#include <ros/ros.h>", "#include <tf2_ros/buffer.h>", "#include <geometry_msgs/Point.h>",
                "#include <std_srvs/Trigger.h>", '#include "cnc_bridge/MachineState.h"',
                "#include <diagnostic_updater/publisher.h>", "#  include <rosbag/bag.h>", "#include <tf2/LinearMath/Vector3.h>"]
SHOULD_PASS = ['#include "cnc_bridge/xmodem/session.h"', "#include <boost/asio.hpp>", "#include <termios.h>",
               '#include "cnc_bridge/transport/tcp.h"', "#include <gtest/gtest.h>"]


def is_core(path):
    return path.endswith((".h", ".hpp", ".cpp")) and not NOT_CORE.search(path)


def ros_include_in(path):
    with open(os.path.join(ROOT, path), errors="replace") as f:
        for number, line in enumerate(f, 1):
            if ROS_INCLUDE.search(line):
                return f"line {number}: core code includes ROS: {line.strip()}"
    return None


def tracked_sources():
    return repo_files(ROOT, "*.h", "*.hpp", "*.cpp")


def core_targets():
    """Executables the CMake fragments declare as ROS-free: cnc_tool() and cnc_core_gtest()."""
    names = set()
    for fragment in [os.path.join(ROOT, "CMakeLists.txt")] + glob.glob(os.path.join(ROOT, "cmake/modules/*.cmake")):
        with open(fragment) as f:
            names.update(re.findall(r"^\s*cnc_(?:tool|core_gtest)\((\w+)", f.read(), re.M))
    return sorted(names)


def ros_libraries_of(binary):
    out = subprocess.run(["ldd", binary], capture_output=True, text=True, check=False).stdout
    return sorted({m.group(0) for m in ROS_LIBRARY.finditer(out)})


def find_binary(build, name):
    for folder in ("devel/lib/cnc_bridge", "bin", "."):
        path = os.path.join(build, folder, name)
        if os.path.isfile(path) and os.access(path, os.X_OK):
            return path
    return None


def cases(build):
    results = []
    for text in SHOULD_CATCH:
        results.append(("self_test", f"catches {text}", None if ROS_INCLUDE.search(text) else "not caught"))
    for text in SHOULD_PASS:
        results.append(("self_test", f"passes {text}", "caught as ROS" if ROS_INCLUDE.search(text) else None))
    core = [path for path in tracked_sources() if is_core(path)]
    results.append(("self_test", "finds core sources", None if core else f"no core source found under {ROOT}"))
    for path in core:
        results.append(("sources", path, ros_include_in(path)))
    if build:
        for name in core_targets():
            binary = find_binary(build, name)
            if binary is None:
                results.append(("binaries", name, f"{name} was not built in {build}"))
                continue
            libraries = ros_libraries_of(binary)
            results.append(("binaries", name, "links ROS: " + ", ".join(libraries) if libraries else None))
    return results


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--junit", required=True)
    parser.add_argument("--build", help="build directory whose core executables are checked with ldd")
    args = parser.parse_args()
    results = cases(args.build)
    tools = ToolCases("ros_free_core")
    # One case per check: the sources' includes, the binaries' libraries, the patterns themselves.
    for group in dict.fromkeys(group for group, _, _ in results):
        checked = [(name, problem) for each, name, problem in results if each == group]
        tools.add(group, checked, checked=len(checked))
    tools.write(args.junit)
    return tools.report()


if __name__ == "__main__":
    sys.exit(main())
