# Sourced by every bench/<module>/run.sh right after its `set` line: the first line of its output
# says what the figures below it come from (the commit, with "+changes" for a tree that differs
# from it, the date and the load average), and bench_done prints the load again at the end, so a
# figure is never read apart from the machine state it was measured in. A benchmark that finds a
# failed transfer or step calls bench_failed: it still prints the rest, but no figure of the failed
# run, and exits non-zero.
bench_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bench_name=$(basename "$(dirname "$(readlink -f "$0")")")
bench_status=0
bench_commit() {
  local commit
  commit=$(git -C "$bench_root" rev-parse --short HEAD 2>/dev/null) || { echo "no commit"; return; }
  git -C "$bench_root" diff --quiet HEAD -- 2>/dev/null || commit+="+changes"
  echo "$commit"
}
bench_load() { cut -d' ' -f1-3 /proc/loadavg; }
echo "bench/$bench_name: commit $(bench_commit), $(date -u '+%Y-%m-%d %H:%M:%S UTC'), load $(bench_load) (1/5/15 min), $(nproc) cores"
bench_failed() {  # bench_failed WHAT: a transfer or step that failed; no figure of it is reported
  echo "bench/$bench_name: FAILED: $*" >&2
  bench_status=1
}
bench_done() {  # the last line of a run.sh: the load after, and the exit status
  echo "bench/$bench_name: done $(date -u '+%H:%M:%S UTC'), load $(bench_load)$([[ $bench_status -eq 0 ]] || echo ", FAILED")"
  exit "$bench_status"
}
