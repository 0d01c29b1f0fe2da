#!/usr/bin/env bash
# Runs every test of cnc_bridge and ends with one line "N passed, N failed":
#   1. catkin build, then `make run_tests` (GoogleTest unit tests, rostests, launch-file checks);
#   2. two hosts (network namespaces): a machine's state and tf cross to the cell's master;
#   3. lint: clang-format on every C++ file, launch-file docs; the core free of ROS in its includes
#      and in the libraries its executables load; package.xml and the Debian package list agree;
#   4. the core and its unit tests again under AddressSanitizer + UndefinedBehaviorSanitizer,
#      with the libFuzzer targets, each fuzzed for FUZZ_SECONDS (default 10).
# Every step writes JUnit XML under .build/test_results; scripts/count_results.py counts it.
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
  printf '<testsuite name="%s" tests="1" failures="1"><testcase classname="make_test" name="%s"><failure message="%s"/></testcase></testsuite>\n' \
    "$1" "$1" "$2" >"$results/$1.xml"
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
(cd "$build" && set +u && source devel/setup.bash &&
  xvfb-run -a -s "-screen 0 1280x900x24" make -j1 run_tests >"$build/run_tests.log" 2>&1) || status=1
grep -E '^\[ *(OK|FAILED|PASSED) *\]|^(SUMMARY|  \* RESULT|ERROR)' "$build/run_tests.log" | grep -vE 'OK \]' | tail -40

step "distributed: a machine node on another host"
"$root/test/net/test_two_hosts.sh" "$results/two_hosts.xml" || status=1

step "lint"
python3 "$root/scripts/lint.py" --junit "$results/lint.xml" || status=1
python3 "$root/scripts/check_ros_free.py" --build "$build" --junit "$results/ros_free_core.xml" || status=1
python3 "$root/scripts/check_packages.py" --junit "$results/packages.xml" || status=1

step "sanitizers (ASan + UBSan) and fuzzing"
"$root/scripts/sanitize_and_fuzz.sh" "$results" "$fuzz_seconds" || status=1

step "results"
python3 "$root/scripts/count_results.py" "$build/test_results" || status=1
exit $status
