#!/usr/bin/env bash
# XModem benchmark (bench/xmodem/bench_xmodem.py): every pair (cnc_dnc->cnc_dnc, sx->rx,
# cnc_dnc->rx, sx->cnc_dnc) timed end to end as a user times it, from starting both programs to
# both having exited, over one pty link per run; the start, data-block and end phases of each run
# read off the link by the same tap (bench/xmodem/tap.c, in place of socat); ratios to sx->rx of
# the same run. Then a 16 KiB program through a noisy 115200 wire (seeded), in CRC and checksum
# mode. Between them, the same pairs at 115200 baud on the tap beside the stop-and-wait bound of
# that line (LINE_RATE_ROUNDS, default 3; 0 leaves it out, as ROUNDS=0 and SEEDS=0 leave theirs).
# Builds nothing but the tap: runs cnc_dnc from BUILD_DIR.
# usage: BUILD_DIR=.build [ROUNDS=5] [SEEDS=8] [LINE_RATE_ROUNDS=3] bench/xmodem/run.sh [KILOBYTES]   (default 256)
set -euo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
here=$(cd "$(dirname "$0")" && pwd)
build=${BUILD_DIR:-$(dirname "$(dirname "$here")")/.build}
bin="$build/devel/lib/cnc_bridge"
[[ -x "$bin/cnc_dnc" ]] || bin="$build/bin"
work=$(mktemp -d /tmp/bench_xmodem_tap.XXXXXX)
trap 'rm -rf "$work"' EXIT
cc -O2 -o "$work/tap" "$here/tap.c" -lutil
echo "command: BUILD_DIR=$build ROUNDS=${ROUNDS:-5} SEEDS=${SEEDS:-8} LINE_RATE_ROUNDS=${LINE_RATE_ROUNDS:-3} bench/xmodem/run.sh ${1:-256}; $(date -u '+%Y-%m-%d %H:%M UTC')"
python3 "$here/bench_xmodem.py" "$bin" "$work/tap" "${1:-256}" "${ROUNDS:-5}" "${SEEDS:-8}" ||
  bench_failed "a transfer with cnc_dnc on one side did not complete (above); its figures are left out"

# Paced: the simulated Haas (sim_haas_serial xmodem), its output paced at 115200 8N1, sends 100 KB
# (checksum-128) to cnc_dnc receive; the line-rate bound is 128 payload bytes per 133 on the wire.
# Timed from cnc_dnc's start to its exit, so the start request and the EOT exchange are included.
sim="$bin/sim_haas_serial"
head -c 102400 /dev/urandom | tr '\032\r' 'xy' >"$work/paced.bin"
mkdir -p "$work/mem"
"$sim" xmodem --link "$work/haas" --dir "$work/mem" --program "$work/paced.bin" --pace-baud 115200 \
  --nak-interval 10 >"$work/sim.out" 2>&1 &
sim_pid=$!
for _ in $(seq 100); do [[ -e "$work/haas" ]] && break; sleep 0.02; done
t0=$(date +%s.%N)
paced_ok=1
"$bin/cnc_dnc" receive --port "$work/haas" --mode checksum --binary "$work/paced_out.bin" >"$work/paced.log" 2>&1 ||
  { paced_ok=0; bench_failed "paced receive: $(tail -1 "$work/paced.log")"; }
t1=$(date +%s.%N)
kill "$sim_pid"; wait "$sim_pid" 2>/dev/null || true
cmp -s -n 102400 "$work/paced.bin" "$work/paced_out.bin" || { paced_ok=0; bench_failed "paced transfer: the file received differs"; }
[[ $paced_ok -eq 1 ]] && awk -v n=102400 -v a="$t0" -v b="$t1" -v load="$(cut -d' ' -f1-3 /proc/loadavg)" 'BEGIN { r = n / (b - a); bound = 11520 * 128 / 133;
  printf "paced 115200 8N1, 100 KB checksum-128 (sim -> cnc_dnc), end to end: %.0f B/s payload, line-rate bound %.0f B/s: %.1f%% (load %s)\n",
    r, bound, 100 * r / bound, load }'
bench_done
