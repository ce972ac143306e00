#!/bin/sh
# test_web_look_wave.sh — the look of the energy wave, its toon scene and the compound eye
# measured in headless chromium (see web_look_wave_check.mjs).
cd "$(dirname "$0")/../.." || exit 1
exec sh tests/integration/browser_suite.sh test_web_look_wave tests/integration/web_look_wave_check.mjs 440
