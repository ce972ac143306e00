#!/bin/sh
# test_includes.sh — no #include cycles among the modules of server/, protocol/ and clients/c/,
# and protocol/ includes nothing outside itself (tools/check_includes.py says how).
cd "$(dirname "$0")/../.." || exit 2
exec /usr/bin/python3 tools/check_includes.py
