#!/usr/bin/env bash
# Coordinates per second streamed by the ethernut client to sim_ethernut over loopback (NEXT after
# every set, tool moving instantly, no position reports), against the round-trip bound: a bare
# 20-byte request/response echo between two processes over the same socket type, same run.
# Builds nothing: uses sim_ethernut and bench_ethernut from BUILD_DIR (default .build/).
#   BUILD_DIR=.build bench/ethernut/run.sh [coordinates] [rounds]
set -euo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
build=${BUILD_DIR:-$(cd "$(dirname "$0")/../.." && pwd)/.build}
n=${1:-20000}
rounds=${2:-5}
find_bin() { find "$build" -name "$1" -type f -perm -u+x | head -n 1; }
sim=$(find_bin sim_ethernut)
bench=$(find_bin bench_ethernut)
[[ -n "$sim" && -n "$bench" ]] || { echo "build sim_ethernut and bench_ethernut in $build first" >&2; exit 1; }
out=$(mktemp -d)
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; rm -rf "$out"; }
trap cleanup EXIT

port_of() {  # waits for the announce line "<name> tcp host:port" in file $1
  for _ in $(seq 1 100); do
    if [[ -s "$1" ]]; then head -n 1 "$1" | sed 's/.*://'; return; fi
    sleep 0.05
  done
  echo "no announce line in $1" >&2; exit 1
}

# The box may be shared: alternate the two measurements for several rounds and compare the best
# of each (the least disturbed run), also printing the medians.
"$sim" --port 0 --speed 0 --report-period-ms 0 >"$out/sim" 2>/dev/null & pids+=($!)
sim_port=$(port_of "$out/sim")
for round in $(seq 1 "$rounds"); do
  "$bench" echo-server >"$out/echo$round" & pids+=($!)
  "$bench" echo-client "$(port_of "$out/echo$round")" "$n" >>"$out/echo_results"
  "$bench" stream "$sim_port" "$n" >>"$out/stream_results"
done

awk -v rounds="$rounds" '
  FNR == 1 { file++ }
  { rate = $1 / $2; cpu = 1e6 * $3 / $1; if (file == 1) { e[++ne] = rate; ec[ne] = cpu } else { s[++ns] = rate; sc[ns] = cpu }; n = $1 }
  function sort(a, k,   i, j, t) { for (i = 1; i <= k; i++) for (j = i + 1; j <= k; j++) if (a[j] < a[i]) { t = a[i]; a[i] = a[j]; a[j] = t } }
  END {
    sort(e, ne); sort(s, ns); sort(ec, ne); sort(sc, ns);
    printf "%-48s %8s %10s %10s %14s\n", "loopback TCP, 20-byte messages, " rounds " rounds", "count", "best /s", "median /s", "client CPU us";
    printf "%-48s %8d %10.0f %10.0f %14.1f\n", "bare request/response echo (the bound)", n, e[ne], e[int((ne + 1) / 2)], ec[int((ne + 1) / 2)];
    printf "%-48s %8d %10.0f %10.0f %14.1f\n", "ethernut client -> sim_ethernut (NEXT per set)", n, s[ns], s[int((ns + 1) / 2)], sc[int((ns + 1) / 2)];
    printf "ratio streaming / bound: best %.0f%%, median %.0f%% (goal >= 80%%); client CPU per message, bound / ours: %.0f%%\n", 100 * s[ns] / e[ne], 100 * s[int((ns + 1) / 2)] / e[int((ne + 1) / 2)], 100 * ec[int((ne + 1) / 2)] / sc[int((ns + 1) / 2)];
  }' "$out/echo_results" "$out/stream_results"
bench_done
