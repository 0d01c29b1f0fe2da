#!/usr/bin/env bash
# DNC drip-feed benchmark (issue 4), with dnc_drip_bench (bench/dnc/drip_bench.cpp): the sender
# and the simulated control of sim_haas_serial drip on a pty in one process. Three measurements,
# each printed beside its target as a ratio:
#  1. resident memory while drip-feeding a generated 1 GB program vs a 1 MB one (growth < 5 MB);
#     unpaced (drain after each write); the 1 GB feed is cancelled after RSS_SECONDS (default 30)
#     once its whole-file pre-send check (a full read of the 1 GB) is done;
#  2. characters the host sent after an XOFF, worst case over >= 1000 XOFF events at 115200
#     (<= 10, the Fanuc limit), against a control with a 40-character high mark;
#  3. throughput at 115200 pacing into a control that executes instantly (>= 97% of line rate).
# Programs are generated in /tmp and deleted. Builds nothing: runs BUILD_DIR's binaries.
# usage: BUILD_DIR=/work/main/.build bench/dnc/run.sh
set -euo pipefail
build=${BUILD_DIR:-/work/main/.build}
rss_seconds=${RSS_SECONDS:-30}
bin() { for d in "$build/devel/lib/cnc_bridge" "$build/bin"; do [[ -x "$d/$1" ]] && { echo "$d/$1"; return; }; done; echo "missing $1 in $build" >&2; exit 1; }
bench=$(bin dnc_drip_bench)
field() { grep -oE "(^| )$1=[^ ]+" <<<"$2" | head -1 | cut -d= -f2; }
echo "load average: $(cut -d' ' -f1-3 /proc/loadavg)"

echo "--- 1. resident memory, 1 MB vs 1 GB program"
small=$("$bench" --bytes 1000000 --baud 0)
echo "1 MB: $small"
large=$("$bench" --bytes 1000000000 --baud 0 --seconds "$rss_seconds")
echo "1 GB: $large"
hwm_small=$(field hwm_kb "$small")
hwm_large=$(field hwm_kb "$large")
awk -v s="$hwm_small" -v l="$hwm_large" 'BEGIN { g = (l - s) / 1024.0;
  printf "peak RSS 1 MB: %.1f MB, 1 GB: %.1f MB, growth %.2f MB vs target < 5 MB: ratio %.3f\n", s / 1024.0, l / 1024.0, g, g / 5.0 }'

echo "--- 2. characters after XOFF at 115200, worst case"
xoff=$("$bench" --bytes 90000 --baud 115200 --buffer 64 --high 40 --low 20 --exec-rate 6000)
echo "$xoff"
events=$(field xoff "$xoff")
after=$(field max_after_xoff "$xoff")
awk -v e="$events" -v a="$after" -v f="$(field max_in_flight "$xoff")" 'BEGIN {
  printf "%d XOFF events: max %d characters sent after an XOFF vs limit 10: ratio %.2f (max %d already queued in the pty when the XOFF went out)\n", e, a, a / 10.0, f }'

echo "--- 3. throughput at 115200 pacing, control executing instantly"
rate=$("$bench" --bytes 250000 --baud 115200)
echo "$rate"
awk -v f="$(field line_fraction "$rate")" -v c="$(field chars_per_s "$rate")" 'BEGIN {
  printf "%.0f characters/s = %.2f%% of the line rate (11520/s) vs target >= 97%%: ratio %.3f\n", c, 100 * f, f / 0.97 }'
