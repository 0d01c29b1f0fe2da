#!/usr/bin/env bash
# 1 kHz setpoint streaming to sim_at_controller: SECONDS (default 60) of a planned path, once with
# the machine otherwise idle and once under competing CPU load (one busy loop per core, started
# here). Prints the sender's setpoint interval p50/p99/max, underruns and lateness, the simulator's
# arrival intervals, and each as a ratio to the 1 ms period the controller expects.
# REALTIME_PRIORITY=N gives the sender thread SCHED_FIFO priority N (needs CAP_SYS_NICE / root).
# usage: BUILD_DIR=.build [REALTIME_PRIORITY=50] bench/at_controller/run.sh [SECONDS]
set -euo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
build=${BUILD_DIR:-$(cd "$(dirname "$0")/../.." && pwd)/.build}
seconds=${1:-60}
bin=$(dirname "$(find "$build" -type f -name at_stream_bench -perm -u+x | head -1)")
[[ -x "$bin/at_stream_bench" && -x "$bin/sim_at_controller" ]] || { echo "build at_stream_bench and sim_at_controller in $build first" >&2; exit 1; }
work=$(mktemp -d)
pids=()
cleanup() { for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done; rm -rf "$work"; }
trap cleanup EXIT

run_once() {  # $1: label
  "$bin/sim_at_controller" --command-port 0 >"$work/sim.out" 2>"$work/sim.err" &
  local sim=$!
  for _ in $(seq 100); do grep -q '^sim_at_controller tcp' "$work/sim.out" 2>/dev/null && break; sleep 0.05; done
  local port
  port=$(head -1 "$work/sim.out" | sed 's/.*://')
  local result
  result=$("$bin/at_stream_bench" --command-port "$port" --seconds "$seconds" --realtime-priority "${REALTIME_PRIORITY:-0}")
  kill -INT "$sim"
  wait "$sim" || true
  local arrival
  arrival=$(grep -o 'arrival interval.*' "$work/sim.err" | sed 's/arrival interval //')
  echo "$1 | load $(cut -d' ' -f1-3 /proc/loadavg) | $result | sim arrival: $arrival"
}

# The platform's own wake-up latency in the same conditions: cyclictest (rt-tests), one thread at
# the sender's priority waking every 1 ms for as long, with its memory locked and CPU idle latency
# held at 0 as the sender does. Prints its max latency and how many wake-ups were over 1 ms late
# (comparable with the sender's stalls, not its underruns: one stall delays several setpoints).
platform_once() {  # $1: label
  if ! command -v cyclictest >/dev/null; then
    echo "$1 | cyclictest not installed (apt install rt-tests)"
    return
  fi
  local policy=(-p "${REALTIME_PRIORITY:-0}")
  [[ "${REALTIME_PRIORITY:-0}" == 0 ]] && policy=(--policy=other)
  cyclictest -m "${policy[@]}" -i 1000 -l $((seconds * 1000)) -q -h 100000 >"$work/cyclictest.out" 2>&1 || true
  awk -v label="$1" '/^[0-9]/ { if ($1 > 1000) late += $2 } /Max Latencies/ { max = $4 + 0 }
    END { printf "%s | cyclictest: wake-ups over 1 ms late=%d max_ms=%.3f\n", label, late, max / 1000 }' "$work/cyclictest.out"
}

echo "at_controller streaming benchmark: $seconds s at 1 kHz, $(nproc) cores, sender SCHED_FIFO priority ${REALTIME_PRIORITY:-0} (0: normal scheduler)"
idle=$(run_once idle)
echo "$idle"
platform_idle=$(platform_once idle)
echo "$platform_idle"
for _ in $(seq "$(nproc)"); do (while :; do :; done) & pids+=($!); done
loaded=$(run_once "busy loops x$(nproc)")
echo "$loaded"
platform_loaded=$(platform_once "busy loops x$(nproc)")
echo "$platform_loaded"
for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
pids=()

ratio() {  # value / 1 ms
  awk -v v="$1" 'BEGIN { printf "%.3f", v / 1.0 }'
}
field() { echo "$1" | grep -o "$2=[^ ]*" | cut -d= -f2; }
printf '\n%-22s %12s %12s %14s %14s\n' "" "idle" "loaded" "idle/1ms" "loaded/1ms"
# The headline: setpoint arrival intervals at the controller (the simulator's clock), then the
# sender's own statistics for comparison.
arrival() {  # line, which of p50|p99|max
  sed -n "s/.*sim arrival:.*$2 \([0-9.e+-]*\) ms.*/\1/p" <<<"$1" | awk '{printf "%.4f", $1}'
}
for which in p50 p99 max; do
  a=$(arrival "$idle" "$which"); b=$(arrival "$loaded" "$which")
  printf '%-22s %12s %12s %14s %14s\n' "arrival $which (ms)" "$a" "$b" "$(ratio "$a")" "$(ratio "$b")"
done
printf '%-22s %12s %12s\n' "load average" "$(sed -n 's/.*| load \([0-9.]*\) .*/\1/p' <<<"$idle")" \
  "$(sed -n 's/.*| load \([0-9.]*\) .*/\1/p' <<<"$loaded")"
echo "sender's own statistics:"
for key in interval_p50_ms interval_p99_ms interval_max_ms late_max_ms; do
  a=$(field "$idle" $key); b=$(field "$loaded" $key)
  printf '%-22s %12s %12s %14s %14s\n' "$key" "$a" "$b" "$(ratio "$a")" "$(ratio "$b")"
done
printf '%-22s %12s %12s\n' "underruns" "$(field "$idle" underruns)" "$(field "$loaded" underruns)"
printf '%-22s %12s %12s\n' "stalls" "$(field "$idle" stalls)" "$(field "$loaded" stalls)"
printf '%-22s %12s %12s\n' "cyclictest late" "$(field "$platform_idle" late)" "$(field "$platform_loaded" late)"
printf '%-22s %12s %12s\n' "cyclictest max_ms" "$(field "$platform_idle" max_ms)" "$(field "$platform_loaded" max_ms)"
printf '%-22s %12s %12s\n' "setpoints" "$(field "$idle" setpoints)" "$(field "$loaded" setpoints)"
bench_done
