#!/bin/sh
# browser_suite.sh NAME SCRIPT SECONDS — runs a browser suite's node script (headless Debian
# chromium through playwright-core) for at most SECONDS, once what it needs is there: node,
# /usr/bin/chromium (deploy/install-deps.sh), the test bundle (make web) and node_modules (npm ci).
# Arguments after SECONDS go to the script.
# Without one it prints the suite's summary line with one failure. Run from the repo root.
name=$1 script=$2 limit=$3
summary_fail() { echo "$name: $1"; echo "$name: 0 passed, 1 failed"; exit 1; }
command -v node >/dev/null 2>&1 || summary_fail "node not found"
[ -x /usr/bin/chromium ] || summary_fail "/usr/bin/chromium missing (deploy/install-deps.sh)"
[ -f clients/web/dist/app-test.js ] || summary_fail "clients/web/dist/app-test.js missing (make web)"
[ -d node_modules/playwright-core ] || summary_fail "node_modules missing (npm ci)"
shift 3
timeout "$limit" node "$script" "$@"
