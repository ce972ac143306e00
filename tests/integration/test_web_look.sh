#!/bin/sh
# test_web_look.sh — the flame's first look, measured in headless chromium (web_look_check.mjs);
# with --shots DIR it also takes README's pictures there (make screenshots).
cd "$(dirname "$0")/../.." || exit 1
exec sh tests/integration/browser_suite.sh test_web_look tests/integration/web_look_check.mjs 580 "$@"
