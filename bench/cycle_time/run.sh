#!/usr/bin/env bash
# Time to cycle end: cell_monitor's prediction (src/core/cell/cycle_time.cpp, a cycle profile of
# scalar limits) against the cycle the simulated '@' controller runs, over the demo's programs and
# the CAM corpus of test/data/gcode/cam: median and p90 of |error| / cycle time, the machine with
# a trapezoid and with an S-curve profile. The counterpart is the project's own simulator: the
# setpoints at_controller_node streams to sim_at_controller (one per 1 ms period) plus the dwells,
# counted without waiting them out in real time; sim_haas_mdc's cycles are scripted, not run from a
# program, so it is no counterpart here. Builds nothing: uses bench_cycle_time from BUILD_DIR.
#   BUILD_DIR=.build bench/cycle_time/run.sh
set -euo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
build=${BUILD_DIR:-$(cd "$(dirname "$0")/../.." && pwd)/.build}
bench=$(find "$build" -name bench_cycle_time -type f -perm -u+x | head -n 1)
[[ -n "$bench" ]] || { echo "bench_cycle_time not built in $build (build target bench_cycle_time)" >&2; exit 1; }
programs=("$bench_root"/config/demo/*.nc "$bench_root"/test/data/gcode/cam/*.nc
          "$bench_root"/test/data/gcode/cam/*.ngc "$bench_root"/test/data/gcode/cam/*.gcode)
# The machine: at_controller_node's default limits (X, Y 50 mm/s and 500 mm/s^2, Z half of that);
# the prediction's profile: one rapid rate and one acceleration for every axis, those of X and Y.
for profile in trapezoid scurve; do
  echo "machine profile $profile:"
  "$bench" --machine-speed 50,50,25 --machine-accel 500,500,250 --machine-profile "$profile" \
    --rapid-rate 50 --max-feed 50 --acceleration 500 "${programs[@]}" || bench_failed "bench_cycle_time ($profile)"
done
bench_done
