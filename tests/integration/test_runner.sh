#!/bin/sh
# test_runner.sh — tests/run.sh itself: a suite that prints a clean summary and then exits
# non-zero, one killed by a signal after its summary, one that prints nothing, and a clean
# one; the run must fail, count each bad suite as a failure and name it.
SUITE=test_runner
cd "$(dirname "$0")/../.." || exit 2
. tests/integration/cli_lib.sh

suite() { # NAME BODY: a fake integration suite in $tmp
    printf '#!/bin/sh\n%s\n' "$2" >"$tmp/$1.sh"
}
suite ok_suite 'echo "ok_suite: 3 passed, 0 failed"'
suite exit_after 'echo "exit_after: 2 passed, 0 failed"; exit 3'
suite killed 'echo "killed: 1 passed, 0 failed"; kill -9 $$'
suite silent 'echo "no summary here"'
suite counted 'echo "counted: 1 passed, 2 failed"; exit 1'

tests/run.sh "$tmp/ok_suite.sh" >"$tmp/out" 2>"$tmp/err"; rc=$?
check "a clean suite passes the run" 0 '^3 passed, 0 failed$'

tests/run.sh "$tmp/ok_suite.sh" "$tmp/exit_after.sh" "$tmp/killed.sh" "$tmp/silent.sh" "$tmp/counted.sh" \
    >"$tmp/out" 2>"$tmp/err"; rc=$?
check "bad suites fail the run" 1 '^7 passed, 5 failed$'
check "exit status after a clean summary is named" 1 'exit_after.sh: exited with status 3'
check "a signal after a clean summary is named" 1 'killed.sh: killed by signal 9'
check "a suite without summary is named" 1 'silent.sh: no summary line'
check "reported failures are named, not counted twice" 1 'counted.sh: 2 failed, exited with status 1'
if grep -q 'ok_suite.sh:' "$tmp/out"; then fail "a clean suite is not named"; else pass "a clean suite is not named"; fi
summary
