#!/bin/sh
# run.sh — runs every test suite and prints the grand total as "N passed, N failed".
#
# Suites: each unit binary in build/tests/, then each integration suite in
# tests/integration/ (test_*.py with Debian's python3, test_*.sh with sh). Every suite
# ends with a line "<name>: N passed, M failed"; a suite that dies without that line
# counts as one failure. Exit status is non-zero when anything failed.
set -u
cd "$(dirname "$0")/.."
passed=0
failed=0
log=$(mktemp)
trap 'rm -f "$log"' EXIT

run_suite() { # name, command...
    name=$1; shift
    echo "== $name"
    "$@" 2>&1 | tee "$log"
    line=$(grep -E '^[A-Za-z0-9_.-]+: [0-9]+ passed, [0-9]+ failed' "$log" | tail -n 1)
    if [ -z "$line" ]; then
        echo "$name: no summary line (crashed?), counted as 1 failed"
        failed=$((failed + 1))
        return
    fi
    p=$(echo "$line" | sed -E 's/.*: ([0-9]+) passed.*/\1/')
    f=$(echo "$line" | sed -E 's/.* ([0-9]+) failed.*/\1/')
    passed=$((passed + p))
    failed=$((failed + f))
}

for t in build/tests/test_*; do
    [ -x "$t" ] || continue
    run_suite "$(basename "$t")" "$t"
done
for t in tests/integration/test_*.py; do
    [ -f "$t" ] || continue
    run_suite "$(basename "$t")" /usr/bin/python3 "$t"
done
for t in tests/integration/test_*.sh; do
    [ -f "$t" ] || continue
    run_suite "$(basename "$t")" sh "$t"
done

echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ] && [ "$passed" -gt 0 ]
