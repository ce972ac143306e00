#!/bin/sh
# test_web_look.sh — the first look, measured in headless chromium (see web_look_check.mjs).
# Needs the bundle (make web), node_modules (npm ci) and /usr/bin/chromium (deploy/install-deps.sh).
cd "$(dirname "$0")/../.." || exit 1
summary_fail() { echo "test_web_look: $1"; echo "test_web_look: 0 passed, 1 failed"; exit 1; }
command -v node >/dev/null 2>&1 || summary_fail "node not found"
[ -x /usr/bin/chromium ] || summary_fail "/usr/bin/chromium missing (deploy/install-deps.sh)"
[ -f clients/web/dist/app-test.js ] || summary_fail "clients/web/dist/app-test.js missing (make web)"
[ -d node_modules/playwright-core ] || summary_fail "node_modules missing (npm ci)"
timeout 580 node tests/integration/web_look_check.mjs "$@"
