#!/usr/bin/env bash
# G-code parse rate: cnc_bridge's gcode::Reader vs the npm package gcode-parser (the parser behind
# cncjs), same generated 1,000,000-line program, same machine, same run. Builds nothing: uses
# bench_gcode from BUILD_DIR (default .build/). Installs gcode-parser with npm into
# bench/gcode/node_modules on first use (git-ignored). Then the parser's peak memory (ru_maxrss)
# on a program of lines/10 and of lines: streaming, it must not grow with the file.
#   BUILD_DIR=.build bench/gcode/run.sh [lines]
set -euo pipefail
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
printf "peak memory (ru_maxrss), one pass: %d lines (%d KiB file) %d KiB; %d lines (%d KiB file) %d KiB; growth %+d KiB\n" \
  "$small_lines" "$(( $(stat -c %s "$small") / 1024 ))" "$small_rss" \
  "$big_lines" "$(( $(stat -c %s "$program") / 1024 ))" "$big_rss" "$((big_rss - small_rss))"
