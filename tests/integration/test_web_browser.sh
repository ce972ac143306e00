#!/bin/sh
# test_web_browser.sh — the browser client in headless chromium (see web_browser_check.mjs).
cd "$(dirname "$0")/../.." || exit 1
exec sh tests/integration/browser_suite.sh test_web_browser tests/integration/web_browser_check.mjs 440
