#!/usr/bin/env bash
# DNC drip-feed benchmark (docs/dnc_drip_feed.md), with dnc_drip_bench (bench/dnc/drip_bench.cpp): the sender
# and the simulated control of sim_haas_serial drip on a pty in one process. Three measurements,
# each printed beside its target as a ratio:
#  1. resident memory while drip-feeding a generated 1 GB program vs a 1 MB one (growth < 5 MB);
#     unpaced (drain after each write); the 1 GB feed is cancelled after RSS_SECONDS (default 30)
#     once its whole-file pre-send check (a full read of the 1 GB) is done;
#  2. characters the control took after its XOFF (the host's queue and later writes), worst case
#     over >= 1000 XOFF events at 115200 and some hundreds at 9600 (<= 10, the Fanuc limit),
#     against a control with a 40-character high mark executing at half the line rate;
#  3. throughput at 115200 pacing into a control that executes instantly (>= 97% of line rate).
# Programs are generated in /tmp and deleted. Builds nothing: runs BUILD_DIR's binaries.
# usage: BUILD_DIR=/work/main/.build bench/dnc/run.sh
set -euo pipefail
build=${BUILD_DIR:-/work/main/.build}
rss_seconds=${RSS_SECONDS:-30}
# SCHED_FIFO priority of the sender in measurements 2 and 3 (DripOptions::realtime_priority; the
# simulated control's UART runs at 10); 0 = the normal scheduler.
rt=${REALTIME:-5}
bin() { for d in "$build/devel/lib/cnc_bridge" "$build/bin"; do [[ -x "$d/$1" ]] && { echo "$d/$1"; return; }; done; echo "missing $1 in $build" >&2; exit 1; }
bench=$(bin dnc_drip_bench)
field() { grep -oE "(^| )$1=[^ ]+" <<<"$2" | head -1 | cut -d= -f2; }
echo "load average: $(cut -d' ' -f1-3 /proc/loadavg); sender real-time priority $rt"

echo "--- 1. resident memory, 1 MB vs 1 GB program"
small=$("$bench" --bytes 1000000 --baud 0)
echo "1 MB: $small"
large=$("$bench" --bytes 1000000000 --baud 0 --seconds "$rss_seconds")
echo "1 GB: $large"
hwm_small=$(field hwm_kb "$small")
hwm_large=$(field hwm_kb "$large")
awk -v s="$hwm_small" -v l="$hwm_large" 'BEGIN { g = (l - s) / 1024.0;
  printf "peak RSS 1 MB: %.1f MB, 1 GB: %.1f MB, growth %.2f MB vs target < 5 MB: ratio %.3f\n", s / 1024.0, l / 1024.0, g, g / 5.0 }'

# The control's UART takes characters at the line rate and counts every character it takes after
# its XOFF, what the host had queued included. Two lines: a pty (the sender's real SerialPort; the
# kernel delivers each direction through a worker thread, which under load can hold a DC3 for
# milliseconds) and a SimulatedLine in memory (a wire, one character per character time each way).
after_xoff() { # baud bytes exec-rate line
  local out
  out=$("$bench" --bytes "$2" --baud "$1" --buffer 64 --high 40 --low 20 --exec-rate "$3" --line "$4" --realtime "$rt")
  echo "$out"
  awk -v b="$1" -v l="$4" -v e="$(field xoff "$out")" -v a="$(field max_after_xoff "$out")" \
      -v o="$(field xoff_over_allowance "$out")" -v r="$(field overruns "$out")" -v q="$(field sender_max_queued_at_xoff "$out")" 'BEGIN {
    printf "%s line at %d: %d XOFF events, max %d characters after an XOFF vs limit 10: ratio %.2f; %d events over, %d overruns; sender queue at XOFF max %d\n", l, b, e, a, a / 10.0, o, r, q }'
}
echo "--- 2. characters after XOFF at 115200 and 9600, worst case"
after_xoff 115200 90000 5760 memory
after_xoff 115200 90000 5760 pty
after_xoff 9600 12000 480 memory
after_xoff 9600 12000 480 pty

echo "--- 3. throughput at 115200 pacing, control executing instantly"
for line in memory pty; do
  rate=$("$bench" --bytes 250000 --baud 115200 --line "$line" --realtime "$rt")
  echo "$rate"
  awk -v l="$line" -v f="$(field line_fraction "$rate")" -v c="$(field chars_per_s "$rate")" 'BEGIN {
    printf "%s line: %.0f characters/s = %.2f%% of the line rate (11520/s) vs target >= 97%%: ratio %.3f\n", l, c, 100 * f, f / 0.97 }'
done
echo "load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)"
