#!/usr/bin/env bash
# XModem benchmark (bench/xmodem/bench_xmodem.py): every pair (cnc_dnc->cnc_dnc, sx->rx,
# cnc_dnc->rx, sx->cnc_dnc) timed end to end as a user times it, from starting both programs to
# both having exited, over one pty link per run; the start, data-block and end phases of each run
# read off the link by the same tap (bench/xmodem/tap.c, in place of socat); ratios to sx->rx of
# the same run. Then a 16 KiB program through a noisy 115200 wire (seeded), in CRC and checksum
# mode. Builds nothing but the tap: runs cnc_dnc from BUILD_DIR.
# usage: BUILD_DIR=/work/main/.build [ROUNDS=5] [SEEDS=8] bench/xmodem/run.sh [KILOBYTES]   (default 256)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
build=${BUILD_DIR:-/work/main/.build}
bin="$build/devel/lib/cnc_bridge"
[[ -x "$bin/cnc_dnc" ]] || bin="$build/bin"
work=$(mktemp -d /tmp/bench_xmodem_tap.XXXXXX)
trap 'rm -rf "$work"' EXIT
cc -O2 -o "$work/tap" "$here/tap.c" -lutil
echo "command: BUILD_DIR=$build ROUNDS=${ROUNDS:-5} SEEDS=${SEEDS:-8} bench/xmodem/run.sh ${1:-256}; $(date -u '+%Y-%m-%d %H:%M UTC')"
python3 "$here/bench_xmodem.py" "$bin" "$work/tap" "${1:-256}" "${ROUNDS:-5}" "${SEEDS:-8}"
