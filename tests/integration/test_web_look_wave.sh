#!/bin/sh
# test_web_look_wave.sh — issue 25's look of the energy wave, its toon scene and the compound eye
# in headless chromium (see web_look_wave_check.mjs). Needs the bundle (make web), node_modules
# (npm ci) and /usr/bin/chromium (deploy/install-deps.sh).
cd "$(dirname "$0")/../.." || exit 1
summary_fail() { echo "test_web_look_wave: $1"; echo "test_web_look_wave: 0 passed, 1 failed"; exit 1; }
command -v node >/dev/null 2>&1 || summary_fail "node not found"
[ -x /usr/bin/chromium ] || summary_fail "/usr/bin/chromium missing (deploy/install-deps.sh)"
[ -f clients/web/dist/app.js ] || summary_fail "clients/web/dist/app.js missing (make web)"
[ -d node_modules/playwright-core ] || summary_fail "node_modules missing (npm ci)"
timeout 440 node tests/integration/web_look_wave_check.mjs
