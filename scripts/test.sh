#!/usr/bin/env bash
# Runs every test of cnc_bridge and ends with one line "N passed, N failed":
#   1. catkin build, then scripts/run_tests.py (GoogleTest unit tests, rostests, launch-file checks,
#      each under a time limit, as declared by CMake in .build/test_manifest.txt);
#   2. two hosts (network namespaces): a machine's state and tf cross to the cell's master;
#      the package installed into a temporary prefix and run from there (test/install);
#   3. lint: clang-format on every C++ file, launch-file docs, the module table, clang-tidy on the
#      core (with the build's compile commands); the core free of ROS in its includes
#      and in the libraries its executables load; package.xml and the Debian package list agree;
#      the unit tests of these scripts themselves (test/scripts);
#   4. the core and its unit tests again under AddressSanitizer + UndefinedBehaviorSanitizer,
#      with the libFuzzer targets, each fuzzed for FUZZ_SECONDS (default 10).
# Every step writes JUnit XML under .build/test_results; a step that fails without writing any
# counts as one failed case. scripts/count_results.py counts test cases (a lint tool is one case)
# and prints a breakdown by kind above the closing line.
# Exit status is non-zero if anything failed.
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
source "$root/scripts/env.sh"
build=${BUILD_DIR:-$root/.build}
results=$build/test_results/cnc_bridge
fuzz_seconds=${FUZZ_SECONDS:-10}
status=0
step() { echo; echo "=== $*"; }

# A step that cannot run at all is still counted: a JUnit file with one failed case.
failed_step() {  # failed_step NAME MESSAGE
  mkdir -p "$results"
  "$root/scripts/junit_step.py" failed "$results/step_$1.xml" "$1" "$2"
}

# run_step NAME RESULT COMMAND...: a step that writes its own JUnit RESULT file(s). If it fails
# without writing any (it crashed, or could not start), a failed case stands in for it.
run_step() {
  local name=$1 written=$2
  shift 2
  "$@"
  local code=$?
  if [[ $code -ne 0 ]]; then
    status=1
    compgen -G "$written" >/dev/null ||
      failed_step "$name" "$name exited with status $code without writing its results (output above)"
  fi
}

step "build"
rm -rf "$build/test_results"
if ! "$root/scripts/build.sh" || ! cmake --build "$build" -- -j"${JOBS:-$(nproc)}" tests; then
  failed_step build "the build failed (output above); no test ran"
  python3 "$root/scripts/count_results.py" "$build/test_results"
  exit 1
fi
mkdir -p "$results"

step "unit tests, rostests, launch checks"
# One test at a time: rostests start their own roscore and simulators. The X server and the cell's
# scratch folder are for the rviz screenshot test, which runs the demo cell.
export CNC_DEMO_DIR=$build/cell_test
rm -rf "$CNC_DEMO_DIR" && mkdir -p "$CNC_DEMO_DIR/programs" "$CNC_DEMO_DIR/haas_vf2_memory"
export CNC_BRIDGE_SCREENSHOT=$results/rviz_cell.png
# scripts/run_tests.py runs exactly the tests CMake declared (.build/test_manifest.txt), each under
# its time limit, and fails a missing binary, a hang, and a crash after an all-pass result.
(cd "$build" && set +u && source devel/setup.bash &&
  xvfb-run -a -s "-screen 0 1280x900x24" python3 "$root/scripts/run_tests.py" --build "$build" --results "$results") ||
  status=1

step "distributed: a machine node on another host"
run_step two_hosts "$results/two_hosts.xml" "$root/test/net/test_two_hosts.sh" "$results/two_hosts.xml"

step "install space: the package installed, run with only the install space sourced"
run_step install_space "$results/install_space.xml" \
  "$root/test/install/test_install_space.py" --build "$build" --junit "$results/install_space.xml"

step "lint"
run_step lint "$results/lint.xml" python3 "$root/scripts/lint.py" --build "$build" --junit "$results/lint.xml"
run_step ros_free_core "$results/ros_free_core.xml" \
  python3 "$root/scripts/check_ros_free.py" --build "$build" --junit "$results/ros_free_core.xml"
run_step packages "$results/packages.xml" python3 "$root/scripts/check_packages.py" --junit "$results/packages.xml"
run_step scripts "$results/scripts.xml" python3 "$root/test/scripts/run_unittests.py" "$results/scripts.xml"

step "sanitizers (ASan + UBSan) and fuzzing"
run_step sanitizers "$results/asan_*.xml" "$root/scripts/sanitize_and_fuzz.sh" "$results" "$fuzz_seconds"

step "results"
python3 "$root/scripts/count_results.py" "$build/test_results" || status=1
exit $status
