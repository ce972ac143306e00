#!/bin/sh
# screenshot_godot.sh FILE — README's picture of the Godot demo (clients/godot/demo): starts
# build/fxstreamd on a free loopback port with its default streams, runs the demo in the
# Godot 3 editor build under a virtual X server (Xvfb, Mesa's software OpenGL) at 1280x720
# with `--screenshot FILE` (demo.gd saves the picture once every stream has drawn, then
# quits), and stops the daemon. Run from the repository root after make (make screenshots
# does both); needs godot3, xvfb and libgl1-mesa-dri (deploy/install-deps.sh --screenshots).
# Exits 1, saying why, when the picture was not made.
set -u
out=${1:?usage: tools/screenshot_godot.sh FILE.png}
for p in build/fxstreamd godot3 xvfb-run; do
    command -v "$p" >/dev/null 2>&1 || { echo "screenshot_godot: $p not found" >&2; exit 1; }
done
tmp=$(mktemp -d)
dpid=
trap 'test -n "$dpid" && kill "$dpid" 2>/dev/null; rm -rf "$tmp"' EXIT INT TERM

build/fxstreamd --port 0 >"$tmp/daemon.out" 2>"$tmp/daemon.err" &
dpid=$!
i=0
until grep -q "listening on http://" "$tmp/daemon.out" 2>/dev/null; do
    i=$((i + 1))
    if [ "$i" -gt 150 ]; then
        echo "screenshot_godot: fxstreamd did not start within 15 s" >&2
        tail -n 5 "$tmp/daemon.err" >&2
        exit 1
    fi
    sleep 0.1
done
port=$(sed -n 's|.*listening on http://[^:]*:\([0-9][0-9]*\)/.*|\1|p' "$tmp/daemon.out" | head -n 1)

rm -f "$out"
# Godot writes its user data under HOME; the demo reads the daemon's URL from FXSTREAM_URL.
HOME=$tmp FXSTREAM_URL="ws://127.0.0.1:$port/v1/ws" timeout 180 \
    xvfb-run -a -s "-screen 0 1280x720x24" godot3 --resolution 1280x720 --path clients/godot/demo -- \
    --screenshot "$(realpath -m "$out")" >"$tmp/godot.log" 2>&1
rc=$?
if [ "$rc" -ne 0 ] || [ ! -s "$out" ]; then
    echo "screenshot_godot: no picture (godot3 exit $rc)" >&2
    tail -n 12 "$tmp/godot.log" >&2
    exit 1
fi
echo "screenshot_godot: $out"
