#!/usr/bin/env python3
"""Checks that package.xml and scripts/debian-packages.txt name the same dependencies.

package.xml speaks in ROS dependency keys (roscpp, tf2_ros, python3-numpy, ...); setup installs
Debian 12 packages. Every key must map to Debian packages that the list installs, and every
package the list installs must come from a key or be one of the tools that only the build and
the test scripts use. Writes JUnit XML (one case per key and one per listed package).

usage: check_packages.py [--junit FILE]
"""
import argparse
import os
import re
import sys
import xml.etree.ElementTree as ET

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# ROS dependency key -> the Debian 12 packages that provide it (what rosdep would install).
DEBIAN_OF_KEY = {
    "catkin": ["catkin", "python3-catkin-pkg", "python3-empy"],
    "roscpp": ["ros-core-dev", "libroscpp-dev"],
    "rospy": ["python3-rospy"],
    "rostest": ["librostest-dev", "python3-rostest"],
    "roslaunch": ["python3-roslaunch"],
    "rosbag": ["librosbag-dev", "python3-rosbag"],
    "rosnode": ["python3-rosnode"],
    "rostopic": ["python3-rostopic"],
    "rosservice": ["python3-rosservice"],
    "rosbash": ["rosbash"],
    "message_generation": ["ros-message-generation"],
    "message_runtime": ["ros-message-runtime"],
    "actionlib": ["libactionlib-dev", "python3-actionlib"],
    "actionlib_msgs": ["libactionlib-msgs-dev"],
    "tf2": ["libtf2-dev"],
    "tf2_ros": ["libtf2-ros-dev", "python3-tf2-ros"],
    "tf2_geometry_msgs": ["libtf2-geometry-msgs-dev"],
    "diagnostic_updater": ["libdiagnostic-updater-dev"],
    "diagnostic_msgs": ["libdiagnostic-msgs-dev", "python3-diagnostic-msgs"],
    "geometry_msgs": ["libgeometry-msgs-dev", "python3-geometry-msgs"],
    "sensor_msgs": ["libsensor-msgs-dev", "python3-sensor-msgs"],
    "nav_msgs": ["libnav-msgs-dev", "python3-nav-msgs"],
    "visualization_msgs": ["libvisualization-msgs-dev"],
    "std_msgs": ["libstd-msgs-dev", "python3-std-msgs"],
    "std_srvs": ["libstd-srvs-dev", "python3-std-srvs"],
    "robot_state_publisher": ["ros-robot-state-publisher"],
    "rviz": ["rviz"],
    "boost": ["libboost-dev", "libboost-system-dev", "libboost-thread-dev", "libboost-program-options-dev"],
    "yaml-cpp": ["libyaml-cpp-dev"],
    "gtest": ["libgtest-dev", "googletest"],
    "python3-numpy": ["python3-numpy"],
    "python3-matplotlib": ["python3-matplotlib"],
    "python3-yaml": ["python3-yaml"],
    "lrzsz": ["lrzsz"],
    "socat": ["socat"],
    "python3-xmodem": ["python3-xmodem"],
    "rt-tests": ["rt-tests"],
    "xvfb": ["xvfb", "x11-apps", "imagemagick", "libgl1-mesa-dri"],
    "clang": ["clang", "libclang-rt-14-dev"],
    "clang-format": ["clang-format"],
    "iproute2": ["iproute2"],
    "procps": ["procps"],
}

# Installed for building and running the scripts themselves, not a dependency of the package.
TOOLS = {"build-essential", "cmake", "ccache"}

DEPEND_TAGS = ("buildtool_depend", "depend", "build_depend", "build_export_depend", "exec_depend", "test_depend")


def package_keys(path):
    root = ET.parse(path).getroot()
    return sorted({element.text.strip() for tag in DEPEND_TAGS for element in root.findall(tag)})


def listed_packages(path):
    with open(path) as f:
        return [line.strip() for line in f if line.strip() and not re.match(r"\s*#", line)]


def problems(keys, listed):
    """(name, problem or None) for every key of package.xml and every package of the list."""
    listed_set = set(listed)
    provided = set()
    results = []
    for key in keys:
        debian = DEBIAN_OF_KEY.get(key)
        if debian is None:
            results.append((f"key {key}", f"package.xml depends on '{key}', which has no Debian package "
                                          "in scripts/check_packages.py"))
            continue
        provided.update(debian)
        missing = [name for name in debian if name not in listed_set]
        results.append((f"key {key}", f"'{key}' needs {', '.join(missing)}, missing from scripts/debian-packages.txt"
                        if missing else None))
    for name in listed:
        orphan = name not in provided and name not in TOOLS
        results.append((f"debian {name}", f"scripts/debian-packages.txt installs '{name}', which no package.xml "
                                          "dependency asks for" if orphan else None))
    return results


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--junit")
    args = parser.parse_args()
    results = problems(package_keys(os.path.join(ROOT, "package.xml")),
                       listed_packages(os.path.join(ROOT, "scripts/debian-packages.txt")))
    failed = [(name, problem) for name, problem in results if problem]
    for name, problem in failed:
        print(f"packages: {problem}")
    if args.junit:
        suite = ET.Element("testsuite", name="packages", tests=str(len(results)), failures=str(len(failed)))
        for name, problem in results:
            case = ET.SubElement(suite, "testcase", classname="packages.consistent", name=name)
            if problem:
                ET.SubElement(case, "failure", message=problem)
        os.makedirs(os.path.dirname(os.path.abspath(args.junit)), exist_ok=True)
        ET.ElementTree(suite).write(args.junit)
    print(f"packages: {len(results) - len(failed)} of {len(results)} checks passed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
