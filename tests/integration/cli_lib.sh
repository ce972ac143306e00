# cli_lib.sh — what the shell suites of the C tools (test_fxctl.sh, test_fxload.sh) share:
# a scratch directory, pass/fail counting, judging one tool call (exit status, stdout and
# stderr patterns), bounded polling, and a daemon on a free loopback port. Sourced, with
# SUITE set to the suite's name; not a suite itself.
passed=0
failed=0
tmp=$(mktemp -d)
dpid=
trap 'test -n "$dpid" && kill "$dpid" 2>/dev/null; rm -rf "$tmp"' EXIT INT TERM

pass() { passed=$((passed + 1)); echo "ok   $1"; }
fail() { failed=$((failed + 1)); echo "FAIL $1"; sed 's/^/     | /' "$tmp/out" "$tmp/err" 2>/dev/null | tail -n 12; }

# check NAME WANT_RC [STDOUT_PATTERN [STDERR_PATTERN]]: judges the last tool call ($rc,
# $tmp/out, $tmp/err).
check() {
    name=$1 want=$2 outpat=${3:-} errpat=${4:-}
    if [ "$rc" -ne "$want" ]; then fail "$name (exit $rc, want $want)"; return; fi
    if [ -n "$outpat" ] && ! grep -q -- "$outpat" "$tmp/out"; then fail "$name (stdout lacks $outpat)"; return; fi
    if [ -n "$errpat" ] && ! grep -q -- "$errpat" "$tmp/err"; then fail "$name (stderr lacks $errpat)"; return; fi
    pass "$name"
}

# wait_for FILE PATTERN TENTHS: polls until FILE contains PATTERN; 0 when it does.
wait_for() {
    i=0
    while [ "$i" -lt "$3" ]; do
        grep -q -- "$2" "$1" 2>/dev/null && return 0
        sleep 0.1
        i=$((i + 1))
    done
    return 1
}

summary() {
    echo "$SUITE: $passed passed, $failed failed"
    [ "$failed" -eq 0 ]
    exit $?
}

# start_daemon PROGRAM...: checks the programs are built, starts build/fxstreamd --port 0
# (bounded wait for its "listening on" line) and sets $port.
start_daemon() {
    for p in build/fxstreamd "$@"; do
        if [ ! -x "$p" ]; then
            fail "$p exists (run make)"
            summary
        fi
    done
    build/fxstreamd --port 0 >"$tmp/daemon.out" 2>"$tmp/daemon.err" &
    dpid=$!
    if ! wait_for "$tmp/daemon.out" "listening on http://" 150; then
        fail "fxstreamd starts within 15 s"
        sed 's/^/     | /' "$tmp/daemon.err" | tail -n 5
        summary
    fi
    port=$(sed -n 's|.*listening on http://[^:]*:\([0-9][0-9]*\)/.*|\1|p' "$tmp/daemon.out" | head -n 1)
    pass "fxstreamd listening on port $port"
}
