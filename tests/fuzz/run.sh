#!/bin/sh
# run.sh — runs every libFuzzer target (build/fuzz/fuzz_*) for SECONDS each on the committed
# corpus (tests/fuzz/corpus/TARGET, read-only here) plus a scratch corpus in build/fuzz.
# With "merge", inputs that add coverage are merged into the committed corpus afterwards
# (make fuzz). Prints one line per target and "test_fuzz: N passed, M failed"; a crash, leak
# or sanitizer report fails the target and leaves its input and log in build/fuzz/.
set -u
SECONDS_EACH=${1:-10}
MODE=${2:-}
cd "$(dirname "$0")/../.." || exit 2
pass=0 fail=0
for bin in build/fuzz/fuzz_*; do
    [ -x "$bin" ] || continue
    t=$(basename "$bin")
    seeds=tests/fuzz/corpus/$t scratch=build/fuzz/corpus/$t log=build/fuzz/$t.log
    mkdir -p "$seeds" "$scratch"
    if "$bin" -max_total_time="$SECONDS_EACH" -timeout=10 -rss_limit_mb=2048 -max_len=65536 \
        -artifact_prefix=build/fuzz/"$t"- -print_final_stats=1 "$scratch" "$seeds" >"$log" 2>&1; then
        runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log")
        echo "ok   $t: ${runs:-?} inputs in ${SECONDS_EACH} s, no crash"
        pass=$((pass + 1))
    else
        echo "FAIL $t: see $log"
        tail -n 30 "$log"
        fail=$((fail + 1))
    fi
    if [ "$MODE" = merge ]; then
        "$bin" -merge=1 "$seeds" "$scratch" >>"$log" 2>&1 && echo "     merged into $seeds ($(ls "$seeds" | wc -l) inputs)"
    fi
done
if [ $((pass + fail)) -eq 0 ]; then
    echo "FAIL no fuzz target in build/fuzz (make builds them with clang: make test, make fuzz)"
    fail=1
fi
echo "test_fuzz: $pass passed, $fail failed"
[ "$fail" -eq 0 ]
