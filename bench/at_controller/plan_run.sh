#!/usr/bin/env bash
# '@' path planning: cnc_plan on a generated 100,000-line CAM-like program (bench/gcode's generator:
# G01 moves, rapids, a G03 arc every 7 lines cut into 0.01 mm chords), trapezoid vs S-curve.
# Timed from outside (the whole cnc_plan process: parse, plan, every 1 ms setpoint generated, no
# CSV), and cnc_plan's own split (segments/s planned, setpoints/s generated), the machining time of
# each profile and its worst limit ratio. Builds nothing: uses cnc_plan from BUILD_DIR.
#   BUILD_DIR=$PWD/.build bench/at_controller/plan_run.sh [lines]
set -euo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
here=$(cd "$(dirname "$0")" && pwd)
build=${BUILD_DIR:-$(cd "$(dirname "$0")/../.." && pwd)/.build}
lines=${1:-100000}
plan=$(find "$build" -name cnc_plan -type f -perm -u+x | head -n 1)
[[ -n "$plan" ]] || { echo "cnc_plan not built in $build (build target cnc_plan)" >&2; exit 1; }
program=$(mktemp /tmp/bench_plan_XXXXXX.nc)
trap 'rm -f "$program"' EXIT
/usr/bin/python3 "$here/../gcode/gen_program.py" "$program" "$lines"
echo "program: $lines lines; load average: $(cut -d' ' -f1-3 /proc/loadavg)"
for profile in trapezoid scurve; do
  start=$(date +%s.%N)
  out=$("$plan" --gcode "$program" --profile "$profile") || { bench_failed "cnc_plan --profile $profile"; continue; }
  end=$(date +%s.%N)
  echo "$out"
  awk -v s="$start" -v e="$end" -v p="$profile" 'BEGIN { printf "%s: wall time of cnc_plan %.2f s\n", p, e - s }'
done
bench_done
