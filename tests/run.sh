#!/bin/sh
# run.sh — runs every test suite and prints the grand total as "N passed, N failed".
#
# Usage: tests/run.sh [SUITE...]. Suites (all by default): each unit binary in build/tests/,
# then each integration suite in tests/integration/ (test_*.py with Debian's python3,
# test_*.sh with sh). Every suite
# ends with a line "<name>: N passed, M failed". A suite fails the run when it reports a
# failure, prints no summary line, or exits non-zero (a crash or a signal) even after a
# summary of no failures: that counts as one failure more. Failed suites are named before
# the total.
# Exit status is non-zero when anything failed.
set -u
cd "$(dirname "$0")/.." || exit 2
passed=0
failed=0
bad=""
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

describe_status() { # exit status -> words
    if [ "$1" -gt 128 ]; then echo "killed by signal $(($1 - 128))"; else echo "exited with status $1"; fi
}

run_suite() { # name, command...
    name=$1; shift
    echo "== $name"
    # The suite's exit status does not survive the pipe into tee: it goes through a file.
    { "$@" 2>&1; echo $? >"$tmp/rc"; } | tee "$tmp/log"
    rc=$(cat "$tmp/rc")
    line=$(grep -E '^[A-Za-z0-9_.-]+: [0-9]+ passed, [0-9]+ failed' "$tmp/log" | tail -n 1)
    p=0 f=0 why=""
    if [ -n "$line" ]; then
        p=$(echo "$line" | sed -E 's/.*: ([0-9]+) passed.*/\1/')
        f=$(echo "$line" | sed -E 's/.* ([0-9]+) failed.*/\1/')
        [ "$f" -gt 0 ] && why="$f failed"
    else
        why="no summary line"
    fi
    if [ "$rc" -ne 0 ]; then
        why="${why:+$why, }$(describe_status "$rc")"
    fi
    if [ -n "$why" ] && [ "$f" -eq 0 ]; then # dead or silent without a counted failure
        echo "$name: $why, counted as 1 failed"
        f=1
    fi
    passed=$((passed + p))
    failed=$((failed + f))
    [ -n "$why" ] && bad="$bad
  $name: $why"
}

# A suite: a unit binary, or a .py/.sh integration suite, by its path.
run_path() {
    case $1 in
        *.py) run_suite "$(basename "$1")" /usr/bin/python3 "$1" ;;
        *.sh) run_suite "$(basename "$1")" sh "$1" ;;
        *) run_suite "$(basename "$1")" "$1" ;;
    esac
}

if [ $# -gt 0 ]; then
    for t in "$@"; do run_path "$t"; done
else
    for t in build/tests/test_* tests/integration/test_*.py tests/integration/test_*.sh; do
        [ -f "$t" ] || continue
        case $t in build/tests/*) [ -x "$t" ] || continue ;; esac
        run_path "$t"
    done
fi

[ -n "$bad" ] && echo "failed suites:$bad"
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ] && [ "$passed" -gt 0 ]
