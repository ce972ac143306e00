#!/bin/sh
# test_web_budget.sh — the page's particle budget and how the flame view draws a subset, under
# node (web_budget_check.mjs); its last line is "test_web_budget: N passed, M failed". Run from
# the repo root.
cd "$(dirname "$0")/../.." || exit 1
if ! command -v node >/dev/null 2>&1; then
    echo "test_web_budget: node not found"
    echo "test_web_budget: 0 passed, 1 failed"
    exit 1
fi
node tests/integration/web_budget_check.mjs
