#!/usr/bin/env bash
# Runs every benchmark of the suite (bench/<module>/run.sh) against the build in .build/ and
# prints their results; bench/README.md lists what each compares with and the latest numbers.
# Benchmarks take minutes and load the machine: run them on an otherwise idle machine.
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
source "$root/scripts/env.sh"
export BUILD_DIR=${BUILD_DIR:-$root/.build}
status=0
for script in "$root"/bench/*/run.sh; do
  [[ -x "$script" ]] || continue
  module=$(basename "$(dirname "$script")")
  if [[ $# -gt 0 && " $* " != *" $module "* ]]; then
    continue
  fi
  echo "=== bench/$module"
  "$script" || { status=1; echo "bench/$module failed"; }
done
exit $status
