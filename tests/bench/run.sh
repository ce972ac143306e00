#!/bin/sh
# run.sh — runs every benchmark in build/bench/, each printing one line per figure.
set -u
cd "$(dirname "$0")/../.."
status=0
for b in build/bench/bench_*; do
    [ -x "$b" ] || continue
    echo "== $(basename "$b")"
    "$b" || status=1
done
exit $status
