#!/usr/bin/env bash
# XModem throughput over one socat pty link (a fresh link per run, same options), in checksum-128
# and 1K modes: cnc_dnc->cnc_dnc, sx->rx (lrzsz), cnc_dnc->rx, sx->cnc_dnc, and the link's
# stop-and-wait bound (a 132- or 1029-byte write answered by a 1-byte reply, repeated). Then the
# payload efficiency of cnc_dnc -> sim_haas_serial paced at 115200 baud 8N1 against the line-rate
# bound (128 payload bytes per 133 on the wire). Builds nothing: runs binaries from $BUILD_DIR.
# usage: BUILD_DIR=/work/main/.build bench/xmodem/run.sh [KILOBYTES]   (default 1024)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
build=${BUILD_DIR:-/work/main/.build}
bin="$build/devel/lib/cnc_bridge"
[[ -x "$bin/cnc_dnc" ]] || bin="$build/bin"
cnc_dnc="$bin/cnc_dnc"
sim="$bin/sim_haas_serial"
kb=${1:-1024}
work=$(mktemp -d /tmp/bench_xmodem.XXXXXX)
trap 'kill $(jobs -p) 2>/dev/null; rm -rf "$work"' EXIT
head -c $((kb * 1024)) /dev/urandom >"$work/payload.bin"
size=$(stat -c %s "$work/payload.bin")

link_up() {  # a fresh pty pair $work/a <-> $work/b
  rm -f "$work/a" "$work/b"
  socat pty,raw,echo=0,link="$work/a" pty,raw,echo=0,link="$work/b" 2>/dev/null &
  socat_pid=$!
  for _ in $(seq 100); do [[ -e "$work/a" && -e "$work/b" ]] && return; sleep 0.02; done
  echo "socat did not come up" >&2; exit 1
}
link_down() { kill "$socat_pid" 2>/dev/null || true; wait "$socat_pid" 2>/dev/null || true; }

# run SENDER_CMD RECEIVER_CMD: the sender starts first and waits for the receiver's NAK/'C'; the
# time is from the receiver's start to its exit with the whole file (rx's ACK of EOT may be lost,
# see docs/dnc_node.md, so the sender's exit is not waited for).
run() {
  link_up
  rm -f "$work/out.bin"
  bash -c "$1" >/dev/null 2>&1 &
  local sender=$!
  sleep 0.3
  local t0 t1
  t0=$(date +%s.%N)
  timeout 120 bash -c "$2" >/dev/null 2>&1 || true
  t1=$(date +%s.%N)
  kill "$sender" 2>/dev/null || true; wait "$sender" 2>/dev/null || true
  link_down
  if ! cmp -s -n "$size" "$work/payload.bin" "$work/out.bin"; then echo "FAILED"; return; fi
  echo "$size $t0 $t1" | awk '{printf "%.0f", $1 / ($3 - $2)}'
}

A="$work/a"; B="$work/b"; P="$work/payload.bin"; O="$work/out.bin"
declare -A rate
for mode in checksum 1k; do
  if [[ $mode == checksum ]]; then sxo=""; rxo=""; sendm=checksum; recvm=checksum; pkt=132; pay=128
  else sxo="-k"; rxo="-c"; sendm=1k; recvm=crc; pkt=1029; pay=1024; fi
  rate[$mode,dnc_dnc]=$(run "$cnc_dnc send --port $A --mode $sendm --binary $P" \
                            "$cnc_dnc receive --port $B --mode $recvm --binary $O")
  rate[$mode,sx_rx]=$(run "sx $sxo $P <$A >$A" "cd $work && rx $rxo out.bin <$B >$B")
  rate[$mode,dnc_rx]=$(run "$cnc_dnc send --port $A --mode $sendm --binary $P" "cd $work && rx $rxo out.bin <$B >$B")
  rate[$mode,sx_dnc]=$(run "sx $sxo $P <$A >$A" "$cnc_dnc receive --port $B --mode $recvm --binary $O")
  link_up
  echo "$mode: cnc_dnc->cnc_dnc ${rate[$mode,dnc_dnc]} sx->rx ${rate[$mode,sx_rx]} cnc_dnc->rx ${rate[$mode,dnc_rx]} sx->cnc_dnc ${rate[$mode,sx_dnc]}" >&2
  rate[$mode,bound]=$(/usr/bin/python3 "$here/stop_and_wait.py" "$A" "$B" $((size / pay)) $pkt $pay)
  link_down
done

printf "%-28s %14s %14s\n" "payload bytes/s ($kb KB)" "checksum-128" "1K"
for pair in dnc_dnc sx_rx dnc_rx sx_dnc bound; do
  case $pair in dnc_dnc) name="cnc_dnc -> cnc_dnc";; sx_rx) name="sx -> rx";; dnc_rx) name="cnc_dnc -> rx";;
    sx_dnc) name="sx -> cnc_dnc";; bound) name="stop-and-wait bound";; esac
  printf "%-28s %14s %14s\n" "$name" "${rate[checksum,$pair]}" "${rate[1k,$pair]}"
done
for mode in checksum 1k; do
  awk -v a="${rate[$mode,dnc_dnc]}" -v s="${rate[$mode,sx_rx]}" -v b="${rate[$mode,bound]}" \
      -v d="${rate[$mode,dnc_rx]}" -v x="${rate[$mode,sx_dnc]}" -v m="$mode" 'BEGIN {
    printf "%-9s cnc_dnc pair / sx->rx = %.2fx, / bound = %.0f%%; cnc_dnc->rx / sx->rx = %.2f; sx->cnc_dnc / sx->rx = %.2f\n",
      m, a / s, 100 * a / b, d / s, x / s }'
done

# Paced: the simulated Haas, its output paced at 115200 8N1, sends 100 KB (checksum-128) to
# cnc_dnc receive. The sender's side is the paced one, so this is the line-rate case.
head -c 102400 /dev/urandom | tr '\032\r' 'xy' >"$work/paced.bin"
rm -rf "$work/mem"; mkdir -p "$work/mem"
"$sim" xmodem --link "$work/haas" --dir "$work/mem" --program "$work/paced.bin" --pace-baud 115200 \
  --nak-interval 10 >"$work/sim.out" 2>&1 &
sim_pid=$!
for _ in $(seq 100); do [[ -e "$work/haas" ]] && break; sleep 0.02; done
t0=$(date +%s.%N)
"$cnc_dnc" receive --port "$work/haas" --mode checksum --binary "$work/paced_out.bin" >/dev/null 2>&1
t1=$(date +%s.%N)
kill "$sim_pid"; wait "$sim_pid" 2>/dev/null || true
cmp -s -n 102400 "$work/paced.bin" "$work/paced_out.bin" || echo "paced transfer FAILED"
awk -v n=102400 -v a="$t0" -v b="$t1" 'BEGIN { r = n / (b - a); bound = 11520 * 128 / 133;
  printf "paced 115200 8N1, 100 KB checksum-128 (sim -> cnc_dnc): %.0f B/s payload, bound %.0f B/s (128/133 of 11520 char/s): %.1f%%\n",
    r, bound, 100 * r / bound }'
