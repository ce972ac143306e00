#!/bin/sh
# test_readme.sh — runs every `build/fxctl` example of README.md (the block under "The two
# commands") against a real fxstreamd, in order, as a user would paste them (with /tmp/ moved
# into the suite's scratch directory), and checks that each does what its comment says.
# `watch` runs until interrupted: it gets 3 s. The last line is "test_readme: N passed, M failed".
set -u
cd "$(dirname "$0")/../.."

FXCTL=build/fxctl
SUITE=test_readme
. tests/integration/cli_lib.sh

start_daemon "$FXCTL"
FXCTL_URL="ws://127.0.0.1:$port"
export FXCTL_URL

# The examples of "The two commands", one per line, comments cut, /tmp/ redirected (other
# sections' examples need other set-ups: a cluster, tokens).
awk '/^## The two commands/ { on = 1; next } /^## / { on = 0 } on' README.md | grep '^build/fxctl ' |
    sed -e 's/  *#.*$//' -e "s|/tmp/|$tmp/|g" >"$tmp/examples"
n=$(wc -l <"$tmp/examples")
test "$n" -ge 12; rc=$?; check "README has its fxctl examples ($n)" 0

i=0
while IFS= read -r line; do
    i=$((i + 1))
    case $line in
    *" watch"*) timeout 3 sh -c "$line" >"$tmp/out" 2>"$tmp/err"; rc=$?; [ "$rc" -eq 124 ] && rc=0 ;;
    *) timeout 60 sh -c "$line" >"$tmp/out" 2>"$tmp/err"; rc=$? ;;
    esac
    check "example $i runs: $line" 0
    cp "$tmp/out" "$tmp/out.$i"
done <"$tmp/examples"

# What the comments promise, from each example's own output ($tmp/out.N) or the state after it.
out_of() { cp "$tmp/out.$(grep -n -- "$1" "$tmp/examples" | head -n 1 | cut -d: -f1)" "$tmp/out"; rc=0; }
get() { timeout 20 "$FXCTL" get "$1" >"$tmp/out" 2>"$tmp/err"; rc=$?; }
out_of "set energy alpha=2"; check "set energy: alpha 2 and the orange colour" 0 '"alpha":2,.*"color_energy":\[1,0.3,0.05\]'
test "$(ls "$tmp"/frames/energy-*.exr | wc -l)" -ge 10; rc=$?; check "subscribe --kind 2 --out: 10 textures and more" 0
ls "$tmp"/frames/energy-*-rig.bin >/dev/null 2>&1; rc=$?; check "subscribe --out without --kind: light rigs too" 0
out_of "frames 10 --out"; test "$(grep -c '"kind":2' "$tmp/out")" -eq 10 && grep -q '"kind":3' "$tmp/out"; rc=$?
check "subscribe --frames 10 without --kind: 10 steps, 10 textures with their rigs" 0
get arc; check "create arc: one curve, no torus" 0 '"tori":\[\],"curves":\[{"p0":\[-5,-2.5,0\],"p1":\[0,5,0\],"p2":\[5,-2.5,0\],"coef":8,'
get flame; check "set flame: the wind" 0 '"wind_velocity":\[2,0,0\]'
test "$(ls "$tmp"/flame/flame-*.ply | wc -l)" -eq 5; rc=$?; check "subscribe flame --out: 5 PLY files" 0
get flame; check "set flame velocities=true" 0 '"velocities":true'
grep -a -q '^property float vx$' "$(ls "$tmp"/flame/flame-*.ply | sort -t- -k2 -n | tail -n 1)"; rc=$?
check "subscribe flame --out after velocities=true: PLY with vx vy vz" 0
test "$(ls "$tmp"/flame/flame-*.bin | wc -l)" -eq 5; rc=$?; check "subscribe flame --out: the payloads in .bin too" 0
out_of "presets flame"; check "presets flame lists the thesis scene" 0 '"name":"thesis-table3.1"'
get energy; check "preset load energy thesis-fig5.2: its torus" 0 '"tori":\[{"center":\[0,0,0\],"axis":\[0,1,1\],"R":3,'
out_of "preset save flame"; check "preset save: saved" 0 '"op":"preset_saved"'
summary
