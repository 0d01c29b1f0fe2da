#!/usr/bin/env bash
# The ROS-free core built a second time with clang, AddressSanitizer and UndefinedBehaviorSanitizer
# (.build-asan/): its unit tests run under the sanitizers, then every libFuzzer target runs for a
# bounded time from its seed corpus (test/fuzz/corpus/<target>/). Results as JUnit XML.
# usage: sanitize_and_fuzz.sh RESULTS_DIR [SECONDS_PER_FUZZ_TARGET]
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
source "$root/scripts/env.sh"
results=${1:?results directory}
seconds=${2:-10}
build=${ASAN_BUILD_DIR:-$root/.build-asan}
mkdir -p "$results" "$build"
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
if [[ ! -f "$build/CMakeCache.txt" ]]; then
  CC=clang CXX=clang++ cmake -S "$root" -B "$build" -DCNC_BRIDGE_CORE_ONLY=ON -DCNC_BRIDGE_FUZZ=ON \
    -DCMAKE_BUILD_TYPE=Debug "${launcher[@]}" \
    -DCMAKE_CXX_FLAGS="-O1 -fsanitize=address,undefined,fuzzer-no-link -fno-sanitize-recover=undefined -fno-omit-frame-pointer" \
    -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" >"$build/configure.log" 2>&1 \
    || { cat "$build/configure.log"; rm -f "$build/CMakeCache.txt"
         "$root/scripts/junit_step.py" failed "$results/asan_build.xml" asan_configure \
           "the sanitizer build could not be configured (see $build/configure.log): no sanitizer or fuzz case ran"
         exit 1; }
fi
if ! cmake --build "$build" -- -j"${JOBS:-$(nproc)}"; then
  "$root/scripts/junit_step.py" failed "$results/asan_build.xml" asan_build \
    "the sanitizer build failed (output above): no sanitizer or fuzz case ran"
  exit 1
fi

status=0
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=0 UBSAN_OPTIONS=print_stacktrace=1
# The unit tests and fuzz targets this build declared (CMake's test_manifest.txt): each one must
# be there, so a target that was not built fails instead of leaving the count.
manifest="$build/test_manifest.txt"
declared() {  # declared KIND: "NAME TIME_LIMIT PATH" per declared test of that kind
  awk -v kind="$1" '$1 == kind { print $2, $3, $4 }' "$manifest"
}
if [[ ! -s "$manifest" ]] || [[ -z "$(declared gtest)" ]]; then
  "$root/scripts/junit_step.py" failed "$results/asan_manifest.xml" asan_manifest \
    "the sanitizer build declared no unit test ($manifest): no sanitizer case ran"
  exit 1
fi
while read -r name limit test; do
  rm -f "$results/asan_$name.xml"
  if [[ ! -x "$test" ]]; then
    status=1
    "$root/scripts/junit_step.py" failed "$results/asan_$name.xml" "$name" \
      "$name is declared but its sanitizer build $test is missing"
    continue
  fi
  # A hung test must not hold up the whole run: it fails after twice its own time limit (the
  # sanitizers slow it down), killed with everything it started.
  timeout -k 10 $((limit * 2)) "$test" --gtest_output="xml:$results/asan_$name.xml" >"$build/$name.log" 2>&1 </dev/null
  exit_status=$?
  if [[ $exit_status -eq 124 || $exit_status -eq 137 ]]; then
    echo "sanitizer run hung: $name still running after $((limit * 2)) s (log: $build/$name.log)"
    rm -f "$results/asan_$name.xml"
    "$root/scripts/junit_step.py" failed "$results/asan_$name.xml" "$name" \
      "hung under the sanitizers: still running after its time limit of $((limit * 2)) s, killed (log: $build/$name.log)"
    sed -i "s/classname=\"/classname=\"asan./g" "$results/asan_$name.xml"
    status=1
    continue
  fi
  if [[ $exit_status -ne 0 ]]; then
    status=1
    echo "sanitizer run failed: $name, exit status $exit_status (log: $build/$name.log)"
    tail -20 "$build/$name.log"
  fi
  if [[ -f "$results/asan_$name.xml" ]]; then
    # LeakSanitizer reports after GoogleTest wrote an all-pass XML: the exit status tells.
    "$root/scripts/junit_step.py" exit-status "$results/asan_$name.xml" "$exit_status" "$build/$name.log"
  else
    # A sanitizer abort leaves no XML: count it as a failure.
    "$root/scripts/junit_step.py" failed "$results/asan_$name.xml" "$name" \
      "died under the sanitizers with exit status $exit_status before writing results: see $build/$name.log"
  fi
  # Prefix suite names so these results are told apart from the plain build's.
  sed -i "s/classname=\"/classname=\"asan./g" "$results/asan_$name.xml"
done < <(declared gtest)

while read -r name _ fuzzer; do
  if [[ ! -x "$fuzzer" ]]; then
    status=1
    echo "<testsuite name=\"fuzz\"><testcase classname=\"fuzz\" name=\"$name\"><failure message=\"declared but not built: $fuzzer\"/></testcase></testsuite>" >"$results/fuzz_$name.xml"
    continue
  fi
  corpus="$build/corpus/$name"
  mkdir -p "$corpus"
  seeds="$root/test/fuzz/corpus/$name"
  [[ -d "$seeds" ]] || seeds=""
  # Crash inputs go to the build directory, never into the source tree.
  if timeout -k 10 $((seconds + 120)) "$fuzzer" -max_total_time="$seconds" -timeout=5 -rss_limit_mb=2048 -print_final_stats=1 \
      -artifact_prefix="$build/$name-" "$corpus" $seeds \
      >"$build/$name.log" 2>&1; then
    runs=$(grep -oE 'stat::number_of_executed_units: *[0-9]+' "$build/$name.log" | grep -oE '[0-9]+$')
    echo "fuzz $name: ${runs:-?} inputs in ${seconds}s, no crash"
    echo "<testsuite name=\"fuzz\"><testcase classname=\"fuzz\" name=\"$name\"/></testsuite>" >"$results/fuzz_$name.xml"
  else
    status=1
    echo "fuzz $name: FAILED (log: $build/$name.log)"
    # Sanitizer reports start with "ERROR:", UndefinedBehaviorSanitizer's with "runtime error:".
    grep -E -A15 'ERROR:|runtime error:' "$build/$name.log" | head -30
    echo "reproduce: $fuzzer $(ls -t "$build/$name"-crash-* "$build/$name"-timeout-* "$build/$name"-oom-* 2>/dev/null | head -1)"
    echo "<testsuite name=\"fuzz\"><testcase classname=\"fuzz\" name=\"$name\"><failure message=\"crash, see $build/$name.log\"/></testcase></testsuite>" >"$results/fuzz_$name.xml"
  fi
done < <(declared fuzz)
exit $status
