#!/bin/sh
# test_fuzz.sh — the libFuzzer targets (tests/fuzz/) for a bounded 10 s each in make test;
# `make fuzz` runs them longer and grows the committed corpus.
exec "$(dirname "$0")/../fuzz/run.sh" "${FUZZ_TEST_SECONDS:-10}"
