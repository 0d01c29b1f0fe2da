#!/usr/bin/env bash
# Serial device server benchmark: the same transfers over a local pty and through ser2net (raw TCP
# and RFC 2217, test/rostest/ser2net_server.py) in one run, as ratios.
#  1. XModem: `cnc_dnc send --binary` of a random program (256 KiB) to sim_haas_serial xmodem, the
#     median time of ROUNDS sends over each path, and the ratio to the pty;
#  2. drip-feed: `cnc_dnc drip` of a DRIP_BYTES program (1 MB) at 115200 into the independent
#     control model (bench/dnc/control_model.py: 256-character buffer, XOFF at 3/4, executing at
#     90 % of the line rate) over each path: the time (ratio to the pty) and the characters the
#     control took after each XOFF, worst case and distribution (p50/p90/p99);
#  3. the alternative where the server's buffering makes <= 10 after an XOFF impossible for a feed
#     that reads DC3 itself: RFC 2217 with the server's own XON/XOFF (`--flow none --line-flow
#     xonxoff`: the node asks the server for XON/XOFF, whose kernel stops the line at the DC3).
# Every path's transfer must succeed, or that row is not reported and the run exits non-zero.
# Builds nothing: runs BUILD_DIR's binaries. Needs ser2net (Debian package ser2net).
# usage: BUILD_DIR=.build [ROUNDS=5] [XMODEM_KIB=256] [DRIP_BYTES=1000000] bench/ser2net/run.sh
set -euo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
build=${BUILD_DIR:-$(cd "$(dirname "$0")/../.." && pwd)/.build}
rounds=${ROUNDS:-5}
kib=${XMODEM_KIB:-256}
drip_bytes=${DRIP_BYTES:-1000000}
bin() { for d in "$build/devel/lib/cnc_bridge" "$build/bin"; do [[ -x "$d/$1" ]] && { echo "$d/$1"; return; }; done; echo "missing $1 in $build" >&2; exit 1; }
dnc=$(bin cnc_dnc)
sim=$(bin sim_haas_serial)
root=$(cd "$(dirname "$0")/../.." && pwd)
command -v ser2net >/dev/null || { echo "bench/ser2net: ser2net is not installed (apt-get install ser2net)" >&2; exit 1; }
work=$(mktemp -d /tmp/bench_ser2net.XXXXXX)
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; rm -rf "$work"; }
trap cleanup EXIT
free_port() { python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
wait_for() { for _ in $(seq 200); do [[ -e $1 ]] && return 0; sleep 0.05; done; return 1; }  # a file another process makes
# Waits until TCP port $1 accepts (ser2net started): polling the port, there is no event to wait on.
wait_port() { for _ in $(seq 200); do python3 -c "import socket; socket.create_connection(('127.0.0.1', $1), 0.2).close()" 2>/dev/null && return 0; sleep 0.05; done; return 1; }
start_server() {  # start_server NAME LINK LINE: ser2net on a raw (port in $raw) and an RFC 2217 port ($rfc) for LINK
  raw=$(free_port); rfc=$(free_port)
  python3 "$root/test/rostest/ser2net_server.py" --config "$work/$1.yaml" "raw:$raw:$2:$3" "rfc2217:$rfc:$2:$3" \
    >"$work/$1.ser2net.log" 2>&1 &
  pids+=($!)  # the script replaces itself with ser2net: this is the server's pid
  wait_port "$raw" && wait_port "$rfc" || { echo "ser2net did not start: $(cat "$work/$1.ser2net.log")" >&2; exit 1; }
}
median() { sort -g | awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }
now() { date +%s.%N; }

# --- 1. XModem -------------------------------------------------------------------------------
python3 -c "import os; open('$work/program.bin', 'wb').write(os.urandom($kib * 1024 - 1) + b'x')"
xm_link=$work/xmodem.pty
"$sim" xmodem --link "$xm_link" --dir "$work/control" --nak-interval 0.05 >"$work/sim.log" 2>&1 &
pids+=($!)
wait_for "$xm_link" || { echo "sim_haas_serial did not start" >&2; exit 1; }
start_server xmodem "$xm_link" 115200n81  # not in a subshell: the cleanup needs its pid
xm_raw=$raw xm_rfc=$rfc
declare -A xm_median
echo "--- 1. XModem send of $kib KiB (binary, checksum-128, random bytes: 0xFF among them), median of $rounds (load $(bench_load))"
for path in pty "tcp://127.0.0.1:$xm_raw" "rfc2217://127.0.0.1:$xm_rfc"; do
  port=$path; [[ $path == pty ]] && port=$xm_link
  times=()
  for round in $(seq "$rounds"); do
    start=$(now)
    if ! "$dnc" send --port "$port" --baud 115200 --mode checksum --binary --timeout 30 "$work/program.bin" \
        >"$work/send.log" 2>&1; then
      bench_failed "XModem send over $path, round $round: $(tail -1 "$work/send.log")"
      continue 2
    fi
    times+=("$(echo "$(now) - $start" | bc -l)")
  done
  xm_median[$path]=$(printf '%s\n' "${times[@]}" | median)
  printf '%-28s median %.3f s (%s)\n' "$path" "${xm_median[$path]}" "$(printf '%.3f ' "${times[@]}")"
done
if [[ -n ${xm_median[pty]:-} ]]; then
  for path in "${!xm_median[@]}"; do
    [[ $path == pty ]] && continue
    printf 'XModem %d KiB through ser2net %s: %.2fx the time over the local pty\n' "$kib" "${path%%:*}" \
      "$(echo "${xm_median[$path]} / ${xm_median[pty]}" | bc -l)"
  done
fi

# --- 2./3. drip-feed -------------------------------------------------------------------------
python3 -c "
out = '%\nO0001 (DRIP)\n'; n = 1
while len(out) < $drip_bytes - 8:
    out += 'N%d G1 X%d.%d Y%d.5 F900.\n' % (n, n % 500, n % 10, n % 300); n += 1
open('$work/drip.nc', 'w').write(out + 'M30\n%\n')"
drip_link=$work/drip.pty
start_server drip "$drip_link" 115200n81
drip_raw=$raw drip_rfc=$rfc
declare -A drip_time
drip_row() {  # drip_row LABEL PORT [cnc_dnc drip options]
  local label=$1 port=$2 start out
  shift 2
  [[ $port == pty ]] && port=$drip_link
  rm -f "$drip_link"
  python3 "$root/bench/dnc/control_model.py" "$drip_link" 115200 10368 256 900 >"$work/model.out" &
  local model=$!
  wait_for "$drip_link" || { bench_failed "the control model did not start ($label)"; return; }
  start=$(now)
  if ! "$dnc" drip --port "$port" --baud 115200 "$@" "$work/drip.nc" >"$work/drip.log" 2>&1; then
    kill "$model" 2>/dev/null || true
    wait "$model" || true
    bench_failed "drip-feed over $label: $(tail -1 "$work/drip.log")"
    return
  fi
  local elapsed
  elapsed=$(echo "$(now) - $start" | bc -l)
  wait "$model" || { bench_failed "the control model ($label) failed"; return; }
  out=$(cat "$work/model.out")
  drip_time[$label]=$elapsed
  printf '%-34s %.1f s (load %s): %s\n' "$label" "$elapsed" "$(cut -d' ' -f1 /proc/loadavg)" "$out"
}
echo "--- 2. drip-feed of $(stat -c %s "$work/drip.nc") bytes at 115200 into the independent control model (executing at 90 % of the line)"
drip_row pty pty
drip_row "ser2net raw" "tcp://127.0.0.1:$drip_raw"
drip_row "ser2net rfc2217" "rfc2217://127.0.0.1:$drip_rfc"
echo "--- 3. RFC 2217 with the server's own XON/XOFF (the feed paces only)"
drip_row "ser2net rfc2217, server xonxoff" "rfc2217://127.0.0.1:$drip_rfc" --flow none --line-flow xonxoff
if [[ -n ${drip_time[pty]:-} ]]; then
  for label in "ser2net raw" "ser2net rfc2217" "ser2net rfc2217, server xonxoff"; do
    [[ -n ${drip_time[$label]:-} ]] || continue
    printf 'drip-feed through %s: %.3fx the time over the local pty\n' "$label" \
      "$(echo "${drip_time[$label]} / ${drip_time[pty]}" | bc -l)"
  done
fi
bench_done
