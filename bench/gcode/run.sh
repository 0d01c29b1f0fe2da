#!/usr/bin/env bash
# G-code parse rate: cnc_bridge's gcode::Reader vs the npm package gcode-parser (the parser behind
# cncjs), same generated 1,000,000-line program, same machine, same run; and vs LinuxCNC's rs274,
# the reference RS274/NGC interpreter, on a 100,000-line program. Builds nothing: uses
# bench_gcode from BUILD_DIR (default .build/). Installs gcode-parser with npm into
# bench/gcode/node_modules on first use (git-ignored). Then the parser's peak memory (ru_maxrss)
# on a program of lines/10 and of lines: streaming, it must not grow with the file.
#   BUILD_DIR=.build bench/gcode/run.sh [lines]
set -euo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
here=$(cd "$(dirname "$0")" && pwd)
build=${BUILD_DIR:-$(cd "$(dirname "$0")/../.." && pwd)/.build}
lines=${1:-1000000}
ours=$(find "$build" -name bench_gcode -type f -perm -u+x | head -n 1)
[[ -n "$ours" ]] || { echo "bench_gcode not built in $build (build target bench_gcode)" >&2; exit 1; }
if [[ ! -d "$here/node_modules/gcode-parser" ]]; then
  npm install --silent --no-audit --no-fund --prefix "$here" gcode-parser@2.2.0 >/dev/null
fi
program=$(mktemp /tmp/bench_gcode_XXXXXX.nc)
small=$(mktemp /tmp/bench_gcode_small_XXXXXX.nc)
trap 'rm -f "$program" "$small"' EXIT
/usr/bin/python3 "$here/gen_program.py" "$program" "$lines"
/usr/bin/python3 "$here/gen_program.py" "$small" "$((lines / 10))"

read -r their_lines their_s _ < <(node "$here/parse_with_gcode_parser.js" "$program" 3)
read -r our_lines our_s our_moves _ < <("$ours" "$program" 3)
# Memory: one pass each, in its own process (ru_maxrss is the process's peak).
read -r small_lines _ _ small_rss < <("$ours" "$small" 1)
read -r big_lines _ _ big_rss < <("$ours" "$program" 1)
awk -v tl="$their_lines" -v ts="$their_s" -v ol="$our_lines" -v os="$our_s" -v om="$our_moves" 'BEGIN {
  tr = tl / ts; or = ol / os;
  printf "%-34s %12s %10s %14s\n", "parser", "lines", "best s", "lines/s";
  printf "%-34s %12d %10.3f %14.0f\n", "npm gcode-parser 2.2.0 (parseLine)", tl, ts, tr;
  printf "%-34s %12d %10.3f %14.0f\n", "cnc_bridge gcode::Reader", ol, os, or;
  printf "ratio cnc_bridge / gcode-parser: %.1fx (goal >= 5x); cnc_bridge also cut arcs into %d moves\n", or / tr, om;
}'
# The reference interpreter: LinuxCNC's rs274 (C++, the canonical calls of every block printed)
# against bench_gcode on one 100,000-line program, best of 3 each, wall and CPU time (user + sys,
# which the load of other processes changes less).
reference=$(mktemp /tmp/bench_gcode_rs274_XXXXXX.nc)
trap 'rm -f "$program" "$small" "$reference"' EXIT
/usr/bin/python3 "$here/gen_program.py" "$reference" 100000
best_of_3() {  # best_of_3 COMMAND...: "wall cpu" seconds, the best of three runs each
  local wall=1e9 cpu=1e9 w c
  for _ in 1 2 3; do
    # Wall and CPU (user + sys) of the child, to the microsecond (GNU time rounds to 10 ms, the
    # size of our whole run on this program).
    read -r w c < <(/usr/bin/python3 -c '
import resource, subprocess, sys, time
t0 = time.perf_counter()
status = subprocess.call(sys.argv[1:], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
wall = time.perf_counter() - t0
r = resource.getrusage(resource.RUSAGE_CHILDREN)
print("%.6f %.6f" % (wall, r.ru_utime + r.ru_stime) if status == 0 else "failed")' "$@")
    [[ $w != failed ]] || { bench_failed "$* failed"; echo "nan nan"; return; }
    wall=$(awk -v a="$wall" -v b="$w" 'BEGIN { print (b < a) ? b : a }')
    cpu=$(awk -v a="$cpu" -v b="$c" 'BEGIN { print (b < a) ? b : a }')
  done
  echo "$wall $cpu"
}
if command -v rs274 >/dev/null; then
  rs274 -g "$reference" </dev/null >"$reference.out" 2>&1 || bench_failed "rs274 refused the benchmark program"
  grep -q "PROGRAM_END" "$reference.out" || bench_failed "rs274 did not reach the program's end"
  rm -f "$reference.out"
  read -r rs_wall rs_cpu < <(best_of_3 rs274 -g "$reference")
  read -r our_wall our_cpu < <(best_of_3 "$ours" "$reference" 1)
  awk -v rw="$rs_wall" -v rc="$rs_cpu" -v ow="$our_wall" -v oc="$our_cpu" 'BEGIN {
    printf "%-34s %12s %10s %10s\n", "100,000 lines, best of 3", "wall s", "CPU s", "lines/s (CPU)";
    printf "%-34s %12.3f %10.3f %10.0f\n", "LinuxCNC rs274 -g", rw, rc, 100000 / rc;
    printf "%-34s %12.3f %10.3f %10.0f\n", "cnc_bridge gcode::Reader", ow, oc, 100000 / oc;
    printf "ratio cnc_bridge / rs274: %.1fx by CPU time, %.1fx by wall time\n", rc / oc, rw / ow;
  }'
else
  bench_failed "rs274 (Debian linuxcnc-uspace) is not installed: no comparison with the reference interpreter"
fi
printf "peak memory (ru_maxrss), one pass: %d lines (%d KiB file) %d KiB; %d lines (%d KiB file) %d KiB; growth %+d KiB\n" \
  "$small_lines" "$(( $(stat -c %s "$small") / 1024 ))" "$small_rss" \
  "$big_lines" "$(( $(stat -c %s "$program") / 1024 ))" "$big_rss" "$((big_rss - small_rss))"
bench_done
