#!/usr/bin/env bash
# Configures and builds the catkin package out of tree in .build/ (devel space .build/devel).
# BUILD_DIR and CMAKE_ARGS may be set to make other builds (sanitizers, fuzzing) beside it.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
source "$root/scripts/env.sh"
build=${BUILD_DIR:-$root/.build}
mkdir -p "$build"
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
if [[ ! -f "$build/CMakeCache.txt" ]]; then
  cmake -S "$root" -B "$build" -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCATKIN_DEVEL_PREFIX="$build/devel" \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo "${launcher[@]}" ${CMAKE_ARGS:-} >"$build/configure.log" \
    || { cat "$build/configure.log"; exit 1; }
fi
jobs=${JOBS:-$(nproc)}
cmake --build "$build" -- -j"$jobs" ${TARGETS:-all}
# catkin snapshots the environment for `make run_tests` when it configures; on a fresh build the
# devel space (its Python messages, its libraries) did not exist yet, so configure once more.
if ! grep -q "PYTHONPATH='$build/devel" "$build/catkin_generated/setup_cached.sh" 2>/dev/null; then
  cmake "$build" >>"$build/configure.log"
fi
