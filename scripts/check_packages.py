#!/usr/bin/env python3
"""Checks that package.xml and scripts/debian-packages.txt name the same dependencies, and that
the list holds everything the scripts, tests and benchmarks use on a fresh Debian 12.

package.xml speaks in ROS dependency keys (roscpp, tf2_ros, python3-numpy, ...); setup installs
Debian 12 packages. Every key must map to Debian packages that the list installs, and every
package the list installs must come from a key or be one of the tools that only the build and
the test scripts use.

What is used: every Python module imported under scripts/, test/ and bench/ (Python files,
Python scripts without the .py suffix, Python embedded in shell scripts) must be the standard
library's, the repository's own, or come from a listed package (PYTHON_MODULE_PACKAGE); every
program the scripts and tests run that no Essential package provides must come from a listed
package (PROGRAM_PACKAGES). An import of a module the table does not know fails the check, so a
new dependency cannot slip in unlisted. Writes JUnit XML: one case per check (self test,
key agreement, use, setup), each failure listing every package, module or program at fault.

Also: every key is one rosdep resolves (a ROS package, or a system key of rosdep's base.yaml or
python.yaml) or a documented exception; scripts/debian-runtime-packages.txt (what `setup.sh
--runtime` installs on a machine computer) is exactly what package.xml's run-time keys need.

usage: check_packages.py [--junit FILE]
"""
import argparse
import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

from tool_cases import ToolCases

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
    "rosparam": ["python3-rosparam"],
    "message_generation": ["ros-message-generation"],
    "message_runtime": ["ros-message-runtime"],
    "actionlib": ["libactionlib-dev", "python3-actionlib"],
    "actionlib_msgs": ["libactionlib-msgs-dev", "python3-actionlib-msgs"],
    "rosgraph": ["python3-rosgraph"],
    "roslib": ["python3-roslib"],
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
    "tinyxml2": ["libtinyxml2-dev"],
    "libsmbclient-dev": ["libsmbclient-dev"],
    "samba": ["samba"],
    "smbclient": ["smbclient"],
    "gtest": ["libgtest-dev", "googletest"],
    "python3-numpy": ["python3-numpy"],
    "python3-matplotlib": ["python3-matplotlib"],
    "python3-yaml": ["python3-yaml"],
    "lrzsz": ["lrzsz"],
    "ser2net": ["ser2net"],
    "socat": ["socat"],
    "python3-xmodem": ["python3-xmodem"],
    "rt-tests": ["rt-tests"],
    "python3-pil": ["python3-pil"],
    # xvfb-run needs xauth but xvfb only recommends it (setup installs without recommends)
    "xvfb": ["xvfb", "xauth", "x11-apps", "imagemagick", "libgl1-mesa-dri"],
    "clang": ["clang", "libclang-rt-14-dev"],
    "clang-format": ["clang-format"],
    "iproute2": ["iproute2"],
    "procps": ["procps"],
    # LinuxCNC's rs274 (the reference G-code interpreter test_gcode_rs274 compares with)
    "linuxcnc-uspace": ["linuxcnc-uspace"],
}

# Run-time key -> the Debian 12 packages a machine computer needs for it to run an installed
# package (scripts/debian-runtime-packages.txt). Empty: nothing at run time (headers, or the
# generated code carries it), or not on a machine computer (rviz shows the cell elsewhere).
RUNTIME_DEBIAN_OF_KEY = {
    "roscpp": ["libroscpp4d"],
    "actionlib": ["libactionlib1d"],
    "actionlib_msgs": ["python3-actionlib-msgs"],
    "tf2": ["libtf2-2d"],
    "tf2_ros": ["libtf2-ros1d", "python3-tf2-ros"],  # python: surface_mapper's part frame
    "tf2_geometry_msgs": [],
    "diagnostic_updater": [],
    "diagnostic_msgs": ["python3-diagnostic-msgs"],
    "geometry_msgs": ["python3-geometry-msgs"],
    "sensor_msgs": ["python3-sensor-msgs"],
    "nav_msgs": ["python3-nav-msgs"],
    "visualization_msgs": [],
    "std_msgs": ["python3-std-msgs"],
    "std_srvs": ["python3-std-srvs"],
    "boost": ["libboost-thread1.74.0", "libboost-program-options1.74.0"],
    "yaml-cpp": ["libyaml-cpp0.7"],
    "tinyxml2": ["libtinyxml2-9"],
    "libsmbclient-dev": ["libsmbclient"],
    "message_runtime": [],
    "roslaunch": ["python3-roslaunch"],
    "rospy": ["python3-rospy"],
    "rosbash": ["rosbash"],
    "rosparam": ["python3-rosparam"],
    "rosnode": ["python3-rosnode"],
    "rostopic": ["python3-rostopic"],
    "rosservice": ["python3-rosservice"],
    "rosbag": ["python3-rosbag"],
    "robot_state_publisher": ["ros-robot-state-publisher"],
    "rviz": [],
    "python3-numpy": ["python3-numpy"],
    "python3-matplotlib": ["python3-matplotlib"],
    "python3-yaml": ["python3-yaml"],
}
RUNTIME_TAGS = ("depend", "exec_depend")

# System keys of rosdep (ros/rosdistro rosdep/base.yaml and rosdep/python.yaml) this package uses;
# all resolve on Debian and Ubuntu. A new system key goes here once looked up there.
ROSDEP_SYSTEM_KEYS = {
    "boost", "yaml-cpp", "tinyxml2", "gtest", "socat", "rt-tests", "xvfb", "python3-pil", "clang", "clang-format",
    "iproute2", "procps", "python3-numpy", "python3-matplotlib", "python3-yaml", "smbclient",
}
# Keys without a rosdep rule, with what a user does instead (docs/INSTALL.md says the same).
ROSDEP_EXCEPTIONS = {
    "lrzsz": "test peer (sx/rx); no rosdep key: apt-get install lrzsz",
    "ser2net": "test peer (a serial device server); no rosdep key: apt-get install ser2net",
    "python3-xmodem": "test peer; no rosdep key: apt-get install python3-xmodem",
    "libsmbclient-dev": "Samba's client library (the SMB program store); no rosdep key: apt-get install libsmbclient-dev",
    "samba": "test peer (smbd, smbpasswd); no rosdep key: apt-get install samba",
    "linuxcnc-uspace": "test peer (LinuxCNC's rs274 for the G-code comparison); no rosdep key: apt-get install "
                       "linuxcnc-uspace (Debian 12)",
}

# Installed for building and running the scripts and benchmarks, not a dependency of the package.
TOOLS = {"build-essential", "cmake", "ccache", "bc", "nodejs", "npm", "time", "clang-tidy", "universal-ctags",
         # scripts/build_cppagent.sh: the reference MTConnect agent, a test peer built from its tag
         "git", "libdlib-dev", "libhowardhinnant-date-dev", "nlohmann-json3-dev", "libxml2-dev"}

# Python module (top-level name) -> the Debian 12 package that provides it.
PYTHON_MODULE_PACKAGE = {
    "rospy": "python3-rospy",
    "rostest": "python3-rostest",
    "rosnode": "python3-rosnode",
    "roslaunch": "python3-roslaunch",
    "rosbag": "python3-rosbag",
    "actionlib": "python3-actionlib",
    "actionlib_msgs": "python3-actionlib-msgs",
    "rosgraph": "python3-rosgraph",
    "roslib": "python3-roslib",
    "rosservice": "python3-rosservice",
    "tf2_ros": "python3-tf2-ros",
    "sensor_msgs": "python3-sensor-msgs",
    "geometry_msgs": "python3-geometry-msgs",
    "nav_msgs": "python3-nav-msgs",
    "std_msgs": "python3-std-msgs",
    "std_srvs": "python3-std-srvs",
    "diagnostic_msgs": "python3-diagnostic-msgs",
    "numpy": "python3-numpy",
    "matplotlib": "python3-matplotlib",
    "yaml": "python3-yaml",
    "xmodem": "python3-xmodem",
    "PIL": "python3-pil",
}
# Modules this repository makes itself: its generated messages and services.
OWN_MODULES = {"cnc_bridge"}

# Programs the scripts, tests and benchmarks run, with the packages they need; programs of
# Essential packages (coreutils, util-linux, grep, sed, mawk, findutils, diffutils, libc-bin) are
# left out. Keep in step with what scripts/*.sh, test/ and bench/ call.
PROGRAM_PACKAGES = {
    "xvfb-run": ["xvfb", "xauth"],  # every test runs under it; xvfb only recommends xauth
    "xwd": ["x11-apps"],  # the rviz screenshot
    "convert": ["imagemagick"],
    "socat": ["socat"],
    "sx": ["lrzsz"], "rx": ["lrzsz"],
    "ser2net": ["ser2net"],
    "cyclictest": ["rt-tests"],
    "ip": ["iproute2"],  # the two-host test's network namespaces
    "pgrep": ["procps"],
    "smbd": ["samba"], "smbpasswd": ["samba"],  # the SMB tests' server
    "smbclient": ["smbclient"],  # the SMB tests' control and bench/share's reference
    "clang": ["clang", "libclang-rt-14-dev"],  # sanitizers and libFuzzer
    "clang-format": ["clang-format"],
    "clang-tidy": ["clang-tidy"],  # the lint step, on the core
    "ctags-universal": ["universal-ctags"],  # the lint step: function lengths
    "cmake": ["cmake"], "cc": ["build-essential"], "ccache": ["ccache"],
    "nm": ["build-essential"],  # binutils: the install-space test's look at what nodes ship
    "roscore": ["python3-roslaunch"], "roslaunch": ["python3-roslaunch"], "rostest": ["python3-rostest"],
    "rosrun": ["rosbash"], "rosparam": ["python3-rosparam"], "rosbag": ["python3-rosbag"],
    "rostopic": ["python3-rostopic"], "rosservice": ["python3-rosservice"], "rosnode": ["python3-rosnode"],
    "rviz": ["rviz"],
    "bc": ["bc"],  # bench/dprnt
    "/usr/bin/time": ["time"],  # bench/gcode: CPU time of rs274 and of the parser
    "node": ["nodejs"], "npm": ["npm"],  # bench/gcode's peer, npm gcode-parser
    "rs274": ["linuxcnc-uspace"],  # test_gcode_rs274's reference interpreter
    "git": ["git"],  # scripts/build_cppagent.sh clones the reference MTConnect agent's tag
}

SCANNED_FOLDERS = ("scripts", "test", "bench")
IMPORT = re.compile(r"^\s*(?:from\s+([A-Za-z_]\w*)[\w.]*\s+import\b|import\s+([A-Za-z_][\w., ]*?)\s*(?:#.*)?$)")

DEPEND_TAGS = ("buildtool_depend", "depend", "build_depend", "build_export_depend", "exec_depend", "test_depend")


def package_keys(path, tags=DEPEND_TAGS):
    root = ET.parse(path).getroot()
    return sorted({element.text.strip() for tag in tags for element in root.findall(tag)})


def rosdep_problems(keys):
    """(name, problem or None): every key is a ROS package (Debian installs its package.xml under
    /usr/share, and the ROS distribution's rosdep index has it), a rosdep system key, or a
    documented exception."""
    results = []
    for key in keys:
        ros_package = os.path.exists(os.path.join("/usr/share", key, "package.xml"))
        known = ros_package or key in ROSDEP_SYSTEM_KEYS or key in ROSDEP_EXCEPTIONS
        results.append((f"rosdep {key}", None if known else
                        f"'{key}' is neither a ROS package nor a rosdep system key known to scripts/check_packages.py "
                        "(ROSDEP_SYSTEM_KEYS, after looking it up in ros/rosdistro rosdep/*.yaml) nor a documented "
                        "exception (ROSDEP_EXCEPTIONS and docs/INSTALL.md)"))
    return results


def runtime_problems(runtime_keys, runtime_listed):
    """(name, problem or None): the runtime list is exactly what the run-time keys need."""
    results = []
    needed = set()
    for key in runtime_keys:
        debian = RUNTIME_DEBIAN_OF_KEY.get(key)
        if debian is None:
            results.append((f"runtime key {key}", f"package.xml needs '{key}' at run time, which has no entry in "
                                                  "RUNTIME_DEBIAN_OF_KEY of scripts/check_packages.py"))
            continue
        needed.update(debian)
        missing = [name for name in debian if name not in runtime_listed]
        results.append((f"runtime key {key}", f"'{key}' needs {', '.join(missing)} at run time, missing from "
                                              "scripts/debian-runtime-packages.txt" if missing else None))
    for name in runtime_listed:
        results.append((f"runtime debian {name}", None if name in needed else
                        f"scripts/debian-runtime-packages.txt installs '{name}', which no run-time key of package.xml "
                        "asks for"))
    return results


def listed_packages(path):
    with open(path) as f:
        return [line.strip() for line in f if line.strip() and not re.match(r"\s*#", line)]


def imported_modules(text):
    """Top-level module names a Python text (or shell text with embedded Python) imports."""
    names = set()
    for line in text.splitlines():
        match = IMPORT.match(line)
        if match and match.group(1):
            names.add(match.group(1))
        elif match:
            for part in match.group(2).split(","):
                words = part.split()
                if words:
                    names.add(words[0].split(".")[0])
    return names


def scanned_files():
    """Python and shell files under the scanned folders: by suffix, or by a python/sh #! line."""
    for folder in SCANNED_FOLDERS:
        for parent, dirs, files in os.walk(os.path.join(ROOT, folder)):
            dirs[:] = [d for d in dirs if d not in ("node_modules", "corpus", "__pycache__")]
            for name in files:
                path = os.path.join(parent, name)
                if name.endswith((".py", ".sh")):
                    yield path
                elif "." not in name:
                    with open(path, "rb") as f:
                        first = f.readline()
                    if first.startswith(b"#!") and (b"python" in first or b"sh" in first):
                        yield path


def used_modules():
    """{module: first file importing it} over the scanned files."""
    used = {}
    for path in sorted(scanned_files()):
        with open(path, errors="replace") as f:
            for module in imported_modules(f.read()):
                used.setdefault(module, os.path.relpath(path, ROOT))
    return used


def local_modules():
    return {os.path.splitext(name)[0] for folder in SCANNED_FOLDERS
            for _, _, files in os.walk(os.path.join(ROOT, folder)) for name in files if name.endswith(".py")}


def usage_problems(listed, used, local):
    """(name, problem or None) for every imported module and every program the scripts run."""
    listed_set = set(listed)
    results = []
    for module, where in sorted(used.items()):
        if module in sys.stdlib_module_names or module in OWN_MODULES or module in local:
            continue
        package = PYTHON_MODULE_PACKAGE.get(module)
        if package is None:
            problem = (f"{where} imports '{module}', which scripts/check_packages.py does not know: add it to "
                       "PYTHON_MODULE_PACKAGE and its Debian package to scripts/debian-packages.txt")
        elif package not in listed_set:
            problem = f"{where} imports '{module}' from {package}, missing from scripts/debian-packages.txt"
        else:
            problem = None
        results.append((f"python {module}", problem))
    for program, packages in sorted(PROGRAM_PACKAGES.items()):
        missing = [name for name in packages if name not in listed_set]
        results.append((f"program {program}", f"'{program}' needs {', '.join(missing)}, missing from "
                        "scripts/debian-packages.txt" if missing else None))
    return results


def self_test():
    """The import scanner on samples, so a broken pattern fails here instead of passing everything."""
    samples = {
        "import os": {"os"}, "from PIL import Image": {"PIL"}, "    import numpy as np": {"numpy"},
        "import sys, time, yaml, rospy": {"sys", "time", "yaml", "rospy"},
        "from sensor_msgs.msg import JointState": {"sensor_msgs"}, "import xml.etree.ElementTree as ET": {"xml"},
        "# import nothing": set(), "echo important": set(), "imports = 3": set(),
    }
    results = []
    for line, expected in samples.items():
        found = imported_modules(line)
        results.append((f"self_test {line.strip()}", None if found == expected else f"found {sorted(found)}"))
    return results


def setup_check():
    """After setup (make test runs it first), setup.sh --check must find nothing missing: else a
    second run would install again, or the tests ran without a package the list names."""
    setup = os.path.join(ROOT, "scripts/setup.sh")
    if not shutil.which("dpkg-query"):
        return []
    results = []
    for options in (["--check"], ["--runtime", "--check"]):
        result = subprocess.run([setup] + options, capture_output=True, text=True)
        problem = None if result.returncode == 0 else (result.stdout + result.stderr).strip()
        results.append(("setup " + " ".join(options), problem))
    return results


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
    listed = listed_packages(os.path.join(ROOT, "scripts/debian-packages.txt"))
    runtime_listed = listed_packages(os.path.join(ROOT, "scripts/debian-runtime-packages.txt"))
    manifest = os.path.join(ROOT, "package.xml")
    keys = package_keys(manifest)
    tools = ToolCases("packages")
    checks = [("self test", self_test()), ("package.xml keys and the Debian list agree", problems(keys, listed)),
              ("every key resolves by rosdep or is a documented exception", rosdep_problems(keys)),
              ("the runtime list is what the run-time keys need",
               runtime_problems(package_keys(manifest, RUNTIME_TAGS), runtime_listed)),
              ("every import and program comes from a listed package",
               usage_problems(listed, used_modules(), local_modules())),
              ("setup.sh --check finds nothing missing", setup_check())]
    for name, results in checks:
        tools.add(name, results, checked=len(results))
    if args.junit:
        tools.write(args.junit)
    return tools.report()


if __name__ == "__main__":
    sys.exit(main())
