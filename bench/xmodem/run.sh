#!/usr/bin/env bash
# XModem throughput over one socat pty link (a fresh link per run, same options), in checksum-128
# and 1K modes: cnc_dnc->cnc_dnc, sx->rx (lrzsz), cnc_dnc->rx, sx->cnc_dnc, and the link's
# stop-and-wait bound (a 132- or 1029-byte write answered by a 1-byte reply, repeated). Then the
# payload efficiency of cnc_dnc -> sim_haas_serial paced at 115200 baud 8N1 against the line-rate
# bound (128 payload bytes per 133 on the wire). Builds nothing: runs binaries from $BUILD_DIR.
#
# Two rates per pair. "file": payload / (receiver start .. receiver exit with the whole file), what
# a user waits for, start handshake and EOT included (cnc_dnc waits 30 ms of silence after EOT,
# lrzsz rx 1 s). "blocks": payload / (first block .. last block's ACK), as `cnc_dnc receive`
# reports it; the bound is measured the same way (its rounds only), so blocks/bound compares like
# with like. rx reports no such time, so pairs ending in rx have the file rate only.
# Every pair runs ROUNDS times (default 5), the pairs taking turns, and the median is reported with
# the number of stalled runs (lrzsz rx flushes its input after each NAK/ACK; a block that crosses
# that flush is lost and rx waits 5 s for it, see RESULTS.md).
# usage: BUILD_DIR=/work/main/.build [ROUNDS=5] bench/xmodem/run.sh [KILOBYTES]   (default 1024)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
build=${BUILD_DIR:-/work/main/.build}
bin="$build/devel/lib/cnc_bridge"
[[ -x "$bin/cnc_dnc" ]] || bin="$build/bin"
cnc_dnc="$bin/cnc_dnc"
sim="$bin/sim_haas_serial"
kb=${1:-1024}
rounds=${ROUNDS:-5}
work=$(mktemp -d /tmp/bench_xmodem.XXXXXX)
trap 'kill $(jobs -p) 2>/dev/null; rm -rf "$work"' EXIT
# The bound's two loops in C: a Python loop costs more per round than cnc_dnc on 132-byte packets.
cc -O2 -o "$work/stop_and_wait" "$here/stop_and_wait.c"
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
# file time is from the receiver's start to its exit with the whole file (rx's ACK of EOT may be
# lost, see docs/dnc_node.md, so the sender's exit is not waited for). Prints "FILE_RATE BLOCK_RATE"
# (BLOCK_RATE "-" when the receiver does not report it), or "FAILED -" (wrong bytes, or no end
# within the 120 s bound: lrzsz rx can stall, see RESULTS.md).
run() {
  link_up
  rm -f "$work/out.bin"
  bash -c "$1" >/dev/null 2>&1 &
  local sender=$!
  sleep 0.3
  local t0 t1
  t0=$(date +%s.%N)
  timeout 120 bash -c "$2" >"$work/receiver.out" 2>/dev/null || true
  t1=$(date +%s.%N)
  kill "$sender" 2>/dev/null || true; wait "$sender" 2>/dev/null || true
  link_down
  if ! cmp -s -n "$size" "$work/payload.bin" "$work/out.bin"; then echo "FAILED -"; return; fi
  local blocks
  blocks=$(sed -n 's/.*data blocks [0-9.]* s, \([0-9]*\) B\/s.*/\1/p' "$work/receiver.out")
  echo "$size $t0 $t1 ${blocks:--}" | awk '{printf "%.0f %s", $1 / ($3 - $2), $4}'
}

A="$work/a"; B="$work/b"; P="$work/payload.bin"; O="$work/out.bin"
# cnc_dnc sends with its defaults: 10 ms of quiet after the start request or a NAK, none after an
# ACK (as sx). Each measurement appends to a list; the tables show medians.
declare -A file blocks
measure() {  # measure MODE PAIR SENDER_CMD RECEIVER_CMD
  local r; r=($(run "$3" "$4"))
  file[$1,$2]+="${r[0]} "; blocks[$1,$2]+="${r[1]} "
}
median() {  # median of numbers (FAILED counts as 0, "-" passes through)
  tr ' ' '\n' <<<"$1" | sed '/^$/d; s/FAILED/0/' | sort -g | awk '{v[NR] = $1} END {
    if (NR == 0 || v[1] == "-") { print "-"; exit }
    print (NR % 2) ? v[(NR + 1) / 2] : int((v[NR / 2] + v[NR / 2 + 1]) / 2) }'
}
stalls() {  # runs slower than half the median: a lost block and a receiver's timeout
  local m; m=$(median "$1")
  [[ $m == - ]] && { echo -; return; }
  tr ' ' '\n' <<<"$1" | sed '/^$/d; s/FAILED/0/' | awk -v m="$m" '$1 < m / 2 {n++} END {print n + 0}'
}
for round in $(seq "$rounds"); do
  for mode in checksum 1k; do
    if [[ $mode == checksum ]]; then sxo=""; rxo=""; sendm=checksum; recvm=checksum; pkt=132; pay=128
    else sxo="-k"; rxo="-c"; sendm=1k; recvm=crc; pkt=1029; pay=1024; fi
    measure $mode dnc_dnc "$cnc_dnc send --port $A --mode $sendm --binary $P" \
                          "$cnc_dnc receive --port $B --mode $recvm --binary $O"
    measure $mode sx_rx "sx $sxo $P <$A >$A" "cd $work && rx $rxo out.bin <$B >$B"
    measure $mode dnc_rx "$cnc_dnc send --port $A --mode $sendm --binary $P" "cd $work && rx $rxo out.bin <$B >$B"
    measure $mode sx_dnc "sx $sxo $P <$A >$A" "$cnc_dnc receive --port $B --mode $recvm --binary $O"
    link_up
    file[$mode,bound]+="- "
    blocks[$mode,bound]+="$("$work/stop_and_wait" "$A" "$B" $((size / pay)) $pkt $pay) "
    link_down
  done
  echo "round $round of $rounds done, load: $(cut -d' ' -f1-3 /proc/loadavg)" >&2
done
declare -A stalled
for key in "${!file[@]}"; do
  stalled[$key]=$(stalls "${file[$key]}")
  file[$key]=$(median "${file[$key]}"); blocks[$key]=$(median "${blocks[$key]}")
done

printf "payload bytes/s, %s KB, medians of %s runs: rate over the whole file / over the data blocks;\n" "$kb" "$rounds"
printf "stalled runs (under half the median) in brackets (load %s)\n" "$(cut -d' ' -f1-3 /proc/loadavg)"
printf "%-22s %16s %10s %16s %10s\n" "" "file chk-128" "blocks" "file 1K" "blocks"
for pair in dnc_dnc sx_rx dnc_rx sx_dnc bound; do
  case $pair in dnc_dnc) name="cnc_dnc -> cnc_dnc";; sx_rx) name="sx -> rx";; dnc_rx) name="cnc_dnc -> rx";;
    sx_dnc) name="sx -> cnc_dnc";; bound) name="stop-and-wait bound";; esac
  printf "%-22s %11s [%2s] %10s %11s [%2s] %10s\n" "$name" "${file[checksum,$pair]}" "${stalled[checksum,$pair]}" \
    "${blocks[checksum,$pair]}" "${file[1k,$pair]}" "${stalled[1k,$pair]}" "${blocks[1k,$pair]}"
done
# A median of 0 means most sx->rx runs FAILED (the 120 s bound): its rate is below size/120 s, so
# ratios to it are lower bounds.
for mode in checksum 1k; do
  awk -v a="${file[$mode,dnc_dnc]}" -v ab="${blocks[$mode,dnc_dnc]}" -v s="${file[$mode,sx_rx]}" \
      -v b="${blocks[$mode,bound]}" -v d="${file[$mode,dnc_rx]}" -v x="${file[$mode,sx_dnc]}" -v m="$mode" \
      -v n="$size" 'BEGIN {
    gt = "";
    if (s == 0) { s = n / 120; gt = ">" }
    printf "%-9s cnc_dnc pair: blocks / bound = %.0f%%, file / sx->rx = %s%.2fx; cnc_dnc->rx / sx->rx = %s%.2f; sx->cnc_dnc / sx->rx = %s%.2f\n",
      m, 100 * ab / b, gt, a / s, gt, d / s, gt, x / s }'
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
