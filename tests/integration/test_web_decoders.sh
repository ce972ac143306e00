#!/bin/sh
# test_web_decoders.sh — the browser client's decoders under node against what the C side
# produced: light-rig frames written by the real encoder (build/tests/test_light_rig --dump,
# with the values they must decode to), kind 3 payloads captured by fxctl from a real
# daemon on a random loopback port, and kind 4 look-up tables of compound_eye streams
# (square and hex) with the PNGs fxctl wrote from them through the C decoder
# (protocol/fxs_lut.c), and flame particle payloads with velocities with the PLY the C
# decoder made of them. Runs web_decoders_check.mjs; its last line is
# "test_web_decoders: N passed, M failed". Run from the repo root.
cd "$(dirname "$0")/../.." || exit 1
summary_fail() { echo "test_web_decoders: $1"; echo "test_web_decoders: 0 passed, 1 failed"; exit 1; }
command -v node >/dev/null 2>&1 || summary_fail "node not found"
[ -x build/tests/test_light_rig ] || summary_fail "build/tests/test_light_rig missing (make unit)"
tmp=$(mktemp -d)
pid=""
cleanup() { [ -n "$pid" ] && kill "$pid" 2>/dev/null; rm -rf "$tmp"; }
trap cleanup EXIT
mkdir -p "$tmp/vec" "$tmp/real" "$tmp/eye" "$tmp/flame"
build/tests/test_light_rig --dump "$tmp/vec" >/dev/null || summary_fail "dump failed"

# A real daemon: energy (the thesis's joined curves, preset thesis-fig5.6) with the light rig
# on, 3 steps (a texture and its rig each) captured by fxctl.
build/fxstreamd --port 0 --state-dir "$tmp/state" --log-level warn >"$tmp/d.out" 2>"$tmp/d.err" &
pid=$!
i=0
while [ $i -lt 100 ] && ! grep -q "listening on" "$tmp/d.out"; do sleep 0.1; i=$((i + 1)); done
port=$(sed -n 's/.*127\.0\.0\.1:\([0-9]*\)\/.*/\1/p' "$tmp/d.out" | head -n 1)
[ -n "$port" ] || summary_fail "daemon did not start"
url="ws://127.0.0.1:$port"
timeout 20 build/fxctl --url "$url" preset load energy thesis-fig5.6 >/dev/null || summary_fail "preset load failed"
timeout 20 build/fxctl --url "$url" set energy light_rig=true 'ramp=[{"m_min":-1,"color":[0.1,0.2,0.3]},{"m_min":0.25,"color":[1,0.5,0]}]' >/dev/null \
    || summary_fail "set light_rig failed"
timeout 30 build/fxctl --url "$url" subscribe energy --frames 3 --out "$tmp/real" >"$tmp/real/lines.txt" 2>"$tmp/real/err.txt"
# Two compound eyes in mode lut (small tables): one kind 4 frame each, payload + C-decoded PNGs;
# black dots on a pale base, ringless (the check tells dots from base by brightness).
plain='base_color=[0.8,0.78,0.72] dot_color=[0.02,0.02,0.02] ring_inner=0 ring_outer=0'
for spec in "eyesq lattice=square lut_cells=12 lut_dirs=10" "eyehex lattice=hex lut_cells=8 lut_dirs=12 lens_radius=1.2"; do
    set -- $spec $plain
    timeout 20 build/fxctl --url "$url" create compound_eye "$@" >/dev/null || summary_fail "create $1 failed"
    timeout 30 build/fxctl --url "$url" subscribe "$1" --frames 1 --out "$tmp/eye" >>"$tmp/eye/lines.txt" 2>>"$tmp/eye/err.txt" \
        || summary_fail "subscribe $1 failed: $(cat "$tmp/eye/err.txt")"
done
# The flame with velocities on (10 bits): payloads (.bin) and the C decoder's PLY of each.
timeout 20 build/fxctl --url "$url" set flame velocities=true vel_bits=10 >/dev/null || summary_fail "set velocities failed"
timeout 30 build/fxctl --url "$url" subscribe flame --frames 3 --out "$tmp/flame" >"$tmp/flame/lines.txt" 2>"$tmp/flame/err.txt" \
    || summary_fail "subscribe flame failed: $(cat "$tmp/flame/err.txt")"
node tests/integration/web_decoders_check.mjs "$tmp/vec" "$tmp/real" "$tmp/eye" "$tmp/flame"
