#!/bin/sh
# test_web_views.sh — the browser client's views against their contract with the page
# (clients/web/src/view.js), under node: runs web_views_check.mjs, whose last line is
# "test_web_views: N passed, M failed". Run from the repo root; needs node_modules (make deps).
cd "$(dirname "$0")/../.." || exit 1
summary_fail() { echo "test_web_views: $1"; echo "test_web_views: 0 passed, 1 failed"; exit 1; }
command -v node >/dev/null 2>&1 || summary_fail "node not found"
[ -d node_modules/three ] || summary_fail "node_modules missing (make deps)"
exec node tests/integration/web_views_check.mjs
