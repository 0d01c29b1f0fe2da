#!/usr/bin/env bash
# Builds and installs the reference MTConnect agent the round-trip test runs
# (test_mtconnect_agent: adapter -> agent -> client): mtconnect/cppagent, tag v1.8.0.3
# (Apache-2.0, https://github.com/mtconnect/cppagent), the agent the fixtures in
# test/data/mtconnect/ were recorded from. Built with CMake from Debian 12's packages (dlib, date,
# nlohmann-json, libxml2: scripts/debian-packages.txt) through a small wrapper that stands in for
# the dependencies its own build would download. Nothing of it goes into this repository.
#
#   scripts/build_cppagent.sh [--work DIR] [--prefix DIR] [--check]
#     --work DIR    where the source (DIR/cppagent-src, cloned at the tag if absent), the wrapper
#                   and the build (DIR/cppagent-build, kept: a second run only re-links) go;
#                   default a temporary folder, removed afterwards
#     --prefix DIR  where the agent binary is installed (default
#                   /usr/local/lib/cnc_bridge/cppagent-1.8.0.3, what the test looks for;
#                   CNC_MTCONNECT_AGENT=<binary> points the test elsewhere)
#     --check       only say whether the agent is installed; exit status 1 if not
# An agent already installed at the prefix is left alone. Needs the network for the clone.
set -euo pipefail
tag=v1.8.0.3
version=${tag#v}
prefix=/usr/local/lib/cnc_bridge/cppagent-$version
work=""
check_only=0
while [[ $# -gt 0 ]]; do
  case "$1" in
    --work) work=$2; shift 2 ;;
    --prefix) prefix=$2; shift 2 ;;
    --check) check_only=1; shift ;;
    *) echo "usage: build_cppagent.sh [--work DIR] [--prefix DIR] [--check]" >&2; exit 2 ;;
  esac
done

installed() {
  # The agent prints its version first, whatever its argument (here taken as a missing file).
  # (Its output read whole first: grep -q leaving early would fail the pipe under pipefail.)
  [[ -x "$prefix/agent" ]] || return 1
  local said
  local scratch
  scratch=$(mktemp -d)  # the agent starts a log in the folder it runs in
  said=$(cd "$scratch" && "$prefix/agent" version 2>&1 || true)
  rm -rf "$scratch"
  [[ $said == *"Version $version"* ]]
}
if installed; then
  echo "build_cppagent: MTConnect agent $version installed at $prefix/agent"
  exit 0
fi
if [[ $check_only -eq 1 ]]; then
  echo "build_cppagent: the MTConnect agent $version is not installed at $prefix/agent (scripts/build_cppagent.sh builds it)"
  exit 1
fi

if [[ -z "$work" ]]; then
  work=$(mktemp -d /tmp/cppagent.XXXXXX)
  trap 'rm -rf "$work"' EXIT
fi
mkdir -p "$work"
work=$(cd "$work" && pwd)
if [[ ! -f "$work/cppagent-src/CMakeLists.txt" ]]; then
  git clone --quiet --depth 1 --branch "$tag" https://github.com/mtconnect/cppagent.git "$work/cppagent-src"
fi
mkdir -p "$work/cppagent-wrapper"
cat >"$work/cppagent-wrapper/CMakeLists.txt" <<EOF
# Builds mtconnect/cppagent $tag from Debian's packages instead of its downloaded dependencies.
cmake_minimum_required(VERSION 3.16)
project(cppagent_wrapper LANGUAGES C CXX)
find_package(dlib REQUIRED)
find_package(LibXml2 REQUIRED)
add_library(date INTERFACE)
add_library(json INTERFACE)
set(AGENT_USE_NATIVE_LIBXML2 ON CACHE BOOL "" FORCE)
set(AGENT_ENABLE_UNITTESTS OFF CACHE BOOL "" FORCE)
add_subdirectory($work/cppagent-src cppagent)
EOF
cmake -S "$work/cppagent-wrapper" -B "$work/cppagent-build" -DCMAKE_BUILD_TYPE=Release >"$work/configure.log" \
  || { cat "$work/configure.log"; exit 1; }
cmake --build "$work/cppagent-build" -- -j"${JOBS:-$(nproc)}" agent
sudo=""
if [[ ! -w "$(dirname "$prefix")" && $(id -u) -ne 0 ]]; then
  sudo="sudo"
fi
$sudo install -D -m 755 "$work/cppagent-build/cppagent/agent/agent" "$prefix/agent"
installed || { echo "build_cppagent: $prefix/agent does not run as agent $version" >&2; exit 1; }
echo "build_cppagent: MTConnect agent $version installed at $prefix/agent"
