#!/bin/sh
# test_particles_js.sh — the browser particle decoder (clients/web/fxs_particles.js)
# against the C encoder's test vectors (tests/data/particles/, written and checked by
# build/tests/test_particles). Runs tests/integration/particles_js_check.mjs with node;
# its last line is "test_particles_js: N passed, M failed". Run from the repo root.
cd "$(dirname "$0")/../.." || exit 1
if ! command -v node >/dev/null 2>&1; then
    echo "test_particles_js: node not found"
    echo "test_particles_js: 0 passed, 1 failed"
    exit 1
fi
node tests/integration/particles_js_check.mjs
