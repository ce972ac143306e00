#!/bin/sh
# test_refs.sh — every "§N.N" reference to the protocol in the sources and docs names a section
# of protocol/PROTOCOL.md (tools/check_refs.py says how a reference's document is told).
cd "$(dirname "$0")/../.." || exit 2
exec /usr/bin/python3 tools/check_refs.py
