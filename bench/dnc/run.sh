#!/usr/bin/env bash
# DNC drip-feed benchmark, with dnc_drip_bench (bench/dnc/drip_bench.cpp: the sender and the
# project's simulated control in one process) and, on a pty, `cnc_dnc drip` against an independent
# control model (bench/dnc/control_model.py). Each row prints the load average and its figure
# beside its target:
#  1. resident memory against bytes delivered: a 200 MB program fed unthrottled (a line in memory
#     as fast as memory), RSS sampled every 10 MB; the slope (least squares) in KB per 100 MB;
#  2. characters the control took after its XOFF (the host's queue and later writes), worst case
#     and the overflow of the control's buffer in every row: the project's simulated control (a
#     wire model and a pty, 115200 and 9600), then the independent model on a pty (256-character
#     buffer, XOFF at 3/4, UART at the line rate, executing at half of it) idle and under load
#     (one busy loop per core started and stopped here, beside whatever else the machine runs),
#     with the normal scheduler and with the sender at SCHED_FIFO 5;
#  3. throughput at 115200 pacing into a control that executes instantly (>= 97% of line rate).
# Programs are generated in /tmp and deleted. Builds nothing: runs BUILD_DIR's binaries.
# usage: BUILD_DIR=.build [MEMORY_MB=200] bench/dnc/run.sh
set -euo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
build=${BUILD_DIR:-$(cd "$(dirname "$0")/../.." && pwd)/.build}
# SCHED_FIFO priority of the sender in measurements 2 and 3 (DripOptions::realtime_priority; the
# simulated control's UART runs at 10); 0 = the normal scheduler.
rt=${REALTIME:-5}
bin() { for d in "$build/devel/lib/cnc_bridge" "$build/bin"; do [[ -x "$d/$1" ]] && { echo "$d/$1"; return; }; done; echo "missing $1 in $build" >&2; exit 1; }
bench=$(bin dnc_drip_bench)
field() { grep -oE "(^| )$1=[^ ]+" <<<"$2" | head -1 | cut -d= -f2; }
echo "load average: $(cut -d' ' -f1-3 /proc/loadavg); sender real-time priority $rt"

echo "--- 1. resident memory against bytes delivered (${MEMORY_MB:-200} MB, RSS every 10 MB; load $(cut -d' ' -f1-3 /proc/loadavg))"
memory=$("$bench" --bytes $((${MEMORY_MB:-200} * 1000000)) --baud 0 --line memory --rss-every 10000000)
echo "$memory"
grep -o 'rss_samples=[^ ]*' <<<"$memory" | cut -d= -f2 | tr ',' '\n' | awk -F: '{ x = $1 / 1e8; y = $2; n++; sx += x; sy += y; sxx += x * x; sxy += x * y;
    if (n == 1) first = y; last = y; lastx = $1 }
  END { slope = (n * sxy - sx * sy) / (n * sxx - sx * sx);
    printf "RSS %d KB at 0 MB, %d KB at %.0f MB (%d samples); slope %.1f KB per 100 MB delivered (least squares) vs target: no growth with bytes sent\n", first, last, lastx / 1e6, n, slope }'

# The control's UART takes characters at the line rate and counts every character it takes after
# its XOFF, what the host had queued included. Two lines: a pty (the sender's real SerialPort; the
# kernel delivers each direction through a worker thread, which under load can hold a DC3 for
# milliseconds) and a SimulatedLine in memory (a wire, one character per character time each way).
after_xoff() { # baud bytes exec-rate line
  local out
  out=$("$bench" --bytes "$2" --baud "$1" --buffer 64 --high 40 --low 20 --exec-rate "$3" --line "$4" --realtime "$rt")
  echo "$out"
  awk -v b="$1" -v l="$4" -v e="$(field xoff "$out")" -v a="$(field max_after_xoff "$out")" \
      -v o="$(field xoff_over_allowance "$out")" -v r="$(field overruns "$out")" -v q="$(field sender_max_queued_at_xoff "$out")" \
      -v f="$(field overflow "$out")" -v load="$(cut -d' ' -f1 /proc/loadavg)" 'BEGIN {
    printf "%s line at %d (load %s): %d XOFF events, max %d characters after an XOFF (limit 10), overflow %d; %d events over 10, %d overruns; sender queue at XOFF max %d\n", l, b, load, e, a, f, o, r, q }'
}
echo "--- 2. characters after XOFF at 115200 and 9600, worst case"
after_xoff 115200 90000 5760 memory
after_xoff 115200 90000 5760 pty
after_xoff 9600 12000 480 memory
after_xoff 9600 12000 480 pty

# The independent control model on a pty, `cnc_dnc drip` feeding it as a user runs it.
dnc=$(bin cnc_dnc)
here=$(cd "$(dirname "$0")" && pwd)
program=$(mktemp /tmp/drip_model.XXXXXX.nc)
python3 -c "
out = '%\nO0001 (DRIP)\n'; n = 1
while len(out) < 150000:
    out += 'N%d G1 X%d.%d Y%d.5 F900.\n' % (n, n % 500, n % 10, n % 300); n += 1
open('$program', 'w').write(out + 'M30\n%\n')"
model_row() {  # label realtime
  local link=/tmp/drip_model_link.$$ out
  python3 "$here/control_model.py" "$link" 115200 5760 256 120 >"$program.model" &
  local model=$!
  for _ in $(seq 100); do [[ -e $link ]] && break; sleep 0.05; done
  if ! "$dnc" drip --port "$link" --realtime "$2" "$program" >"$program.drip" 2>&1; then
    wait "$model" || true
    bench_failed "the drip-feed to the independent model ($1) failed: $(tail -1 "$program.drip")"
    return
  fi
  wait "$model" || { bench_failed "the independent model ($1) failed"; return; }
  out=$(cat "$program.model")
  echo "independent model, pty 115200, $1, sender SCHED_FIFO $2 (load $(cut -d' ' -f1 /proc/loadavg)): $out"
}
model_row "no extra load" 0
busy=()
for _ in $(seq "$(nproc)"); do (while :; do :; done) & busy+=($!); done
model_row "$(nproc) busy loops" 0
model_row "$(nproc) busy loops" 5
kill "${busy[@]}"
rm -f "$program" "$program.model"

echo "--- 3. throughput at 115200 pacing, control executing instantly"
for line in memory pty; do
  rate=$("$bench" --bytes 250000 --baud 115200 --line "$line" --realtime "$rt")
  echo "$rate"
  awk -v l="$line" -v f="$(field line_fraction "$rate")" -v c="$(field chars_per_s "$rate")" 'BEGIN {
    printf "%s line: %.0f characters/s = %.2f%% of the line rate (11520/s) vs target >= 97%%: ratio %.3f\n", l, c, 100 * f, f / 0.97 }'
done
bench_done
