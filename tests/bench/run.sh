#!/bin/sh
# run.sh — runs every benchmark in build/bench/, each printing one line per figure, then
# repeats the lines that name a target as one summary (the performance targets' table).
set -u
cd "$(dirname "$0")/../.."
status=0
out=$(mktemp)
rcf=$(mktemp)
trap 'rm -f "$out" "$rcf"' EXIT
for b in build/bench/bench_*; do
    [ -x "$b" ] || continue
    echo "== $(basename "$b")"
    { "$b"; echo $? >"$rcf"; } | tee -a "$out"
    [ "$(cat "$rcf")" = 0 ] || status=1
done
echo "== targets (every line above that names one)"
grep -i "target" "$out"
exit $status
