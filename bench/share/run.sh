#!/usr/bin/env bash
# Programs to and from an SMB share: cnc_dnc send/receive --share against Samba's own smbclient
# put/get, to the same smbd in the same run, round by round, as a user times them (from starting
# the program to its exit). smbd runs on 127.0.0.1 on a free port with everything in a scratch
# folder (as the tests' samba_server.h does); both clients log in with the same user and
# credentials file.
#   bench/share/run.sh [ROUNDS]      (as root: smbd must be able to become the user it serves)
# Prints one line per size and direction: medians of ROUNDS, MB/s, and the throughput ratio
# cnc_dnc / smbclient (>= 0.9 is the goal), the median of the rounds' ratios (and, beside it, the
# ratio of the two medians); and the fixed per-transfer cost (a 1-byte program:
# process start, connect, authenticate, and for cnc_dnc the temporary name and renames); then the
# same for one 1 MB transfer phase by phase (bench/share/phases.py, when strace is installed).
set -euo pipefail
source "$(dirname "$(readlink -f "$0")")/../provenance.sh"
root=$(cd "$(dirname "$0")/../.." && pwd)
source "$root/scripts/env.sh"
build=${BUILD_DIR:-$root/.build}
cnc_dnc=$build/devel/lib/cnc_bridge/cnc_dnc
rounds=${1:-5}
[[ $(id -u) == 0 ]] || { echo "bench/share: run as root (smbd becomes the user it serves)"; exit 1; }
[[ -x $cnc_dnc ]] || { echo "bench/share: build cnc_dnc first ($cnc_dnc)"; exit 1; }

dir=$(mktemp -d /tmp/cnc_bench_share.XXXXXX)
smbd_pid=
cleanup() {
  # smbd ends by the signal, so its status is non-zero: not a failure of the benchmark.
  [[ -n $smbd_pid ]] && kill -TERM -- -"$smbd_pid" 2>/dev/null && { wait "$smbd_pid" 2>/dev/null || true; }
  rm -rf "$dir"
}
trap cleanup EXIT
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
user=$(id -un)
mkdir -p "$dir"/{private,lock,state,cache,pid,ncalrpc,share}
cat >"$dir/smb.conf" <<CONF
[global]
  server role = standalone server
  smb ports = $port
  interfaces = 127.0.0.1
  bind interfaces only = yes
  disable netbios = yes
  passdb backend = tdbsam:$dir/private/passdb.tdb
  private dir = $dir/private
  lock directory = $dir/lock
  state directory = $dir/state
  cache directory = $dir/cache
  pid directory = $dir/pid
  ncalrpc dir = $dir/ncalrpc
  log file = $dir/smbd.log
  load printers = no
  printing = bsd
  printcap name = /dev/null
  disable spoolss = yes
[bench]
  path = $dir/share
  valid users = $user
  read only = no
CONF
printf 'bench-Pass-1\nbench-Pass-1\n' | smbpasswd -c "$dir/smb.conf" -s -a "$user" >/dev/null
printf 'username = %s\npassword = bench-Pass-1\n' "$user" >"$dir/auth"
chmod 600 "$dir/auth"
setsid smbd --foreground --no-process-group -s "$dir/smb.conf" >"$dir/smbd.out" 2>&1 &
smbd_pid=$!
for _ in $(seq 300); do
  (exec 3<>/dev/tcp/127.0.0.1/"$port") 2>/dev/null && break
  sleep 0.05  # polling the port until smbd answers
done
url=smb://127.0.0.1:$port/bench

# seconds a command takes, from its start to its exit
timed() {
  local start end
  start=$(date +%s.%N)
  "$@" >/dev/null 2>&1 || { echo "bench/share: failed: $*" >&2; exit 1; }
  end=$(date +%s.%N)
  echo "$end - $start" | python3 -c 'import sys; print("%.4f" % eval(sys.stdin.read()))'
}

echo "bench/share: $(date -u '+%Y-%m-%d %H:%M UTC'), load $(cut -d' ' -f1-3 /proc/loadavg), smbd $(smbd --version | cut -d' ' -f2), $rounds rounds, medians"
for size in 1 1048576 20971520; do
  head -c "$size" /dev/urandom >"$dir/local.nc"
  for direction in up down; do
    declare -A runs=([cnc_dnc]="" [smbclient]="")
    # Round by round, the two tools one after the other (which goes first alternates), so that a
    # change of the machine's load falls on both alike.
    for round in $(seq "$rounds"); do
      order=(cnc_dnc smbclient)
      (( round % 2 == 0 )) && order=(smbclient cnc_dnc)
      for tool in "${order[@]}"; do
        if [[ $direction == up && $tool == cnc_dnc ]]; then
          runs[$tool]+=" $(timed "$cnc_dnc" send --share "$url" --credentials "$dir/auth" --name "by_cnc_dnc.nc" "$dir/local.nc")"
          cmp -s "$dir/local.nc" "$dir/share/by_cnc_dnc.nc" || { echo "bench/share: cnc_dnc upload differs"; exit 1; }
        elif [[ $direction == up ]]; then
          runs[$tool]+=" $(timed smbclient //127.0.0.1/bench -p "$port" -A "$dir/auth" -c "put $dir/local.nc by_smbclient.nc")"
          cmp -s "$dir/local.nc" "$dir/share/by_smbclient.nc" || { echo "bench/share: smbclient upload differs"; exit 1; }
        elif [[ $tool == cnc_dnc ]]; then
          rm -f "$dir/back.nc"
          runs[$tool]+=" $(timed "$cnc_dnc" receive --share "$url" --credentials "$dir/auth" by_smbclient.nc "$dir/back.nc")"
          cmp -s "$dir/local.nc" "$dir/back.nc" || { echo "bench/share: cnc_dnc download differs"; exit 1; }
        else
          rm -f "$dir/back.nc"
          runs[$tool]+=" $(timed smbclient //127.0.0.1/bench -p "$port" -A "$dir/auth" -c "get by_cnc_dnc.nc $dir/back.nc")"
          cmp -s "$dir/local.nc" "$dir/back.nc" || { echo "bench/share: smbclient download differs"; exit 1; }
        fi
      done
    done
    # The ratio of each round (the two tools one after the other, under the same load), and its
    # median: a burst of load on the machine falls on both tools of a round alike.
    python3 - "$size" "$direction" "${runs[cnc_dnc]}" "${runs[smbclient]}" <<'PY'
import statistics
import sys
size, direction = int(sys.argv[1]), sys.argv[2]
ours_runs, theirs_runs = ([float(x) for x in runs.split()] for runs in sys.argv[3:5])
ours, theirs = statistics.median(ours_runs), statistics.median(theirs_runs)
ratio = statistics.median(t / o for o, t in zip(ours_runs, theirs_runs))
label = "1 byte (fixed cost)" if size == 1 else "%d MB" % (size // 1048576)
if size == 1:
    print("%-20s %-4s cnc_dnc %.3f s, smbclient %.3f s (difference %+.3f s)" % (label, direction, ours, theirs, ours - theirs))
else:
    print("%-20s %-4s cnc_dnc %.3f s %6.1f MB/s, smbclient %.3f s %6.1f MB/s, throughput ratio %.2f (of the medians %.2f)"
          % (label, direction, ours, size / ours / 1e6, theirs, size / theirs / 1e6, ratio, theirs / ours))
PY
  done
done

# Where the time of one 1 MB transfer goes, phase by phase, from each client's SMB2 requests.
if command -v strace >/dev/null; then
  head -c 1048576 /dev/urandom >"$dir/local.nc"
  python3 "$root/bench/share/phases.py" "$cnc_dnc" "$url" "$dir/auth" "$dir/local.nc" "$rounds"
else
  echo "bench/share: phases not measured: strace is not installed (apt-get install strace)"
fi
bench_done
