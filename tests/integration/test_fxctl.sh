#!/bin/sh
# test_fxctl.sh — end-to-end checks of fxctl (and so libfxclient) against a real fxstreamd.
#
# Owns: starting build/fxstreamd --port 0 on a free port (bounded wait for its
# "listening on" line), driving every fxctl command against it, and stopping it.
# Each check counts one pass or fail; the last line is "test_fxctl: N passed, M failed".
# Every fxctl call runs under `timeout` so the suite stays well under 60 s.
set -u
cd "$(dirname "$0")/../.."

FXCTL=build/fxctl
T=30 # seconds any one fxctl call may take
SUITE=test_fxctl
. tests/integration/cli_lib.sh

# fx ARGS...: runs fxctl, stdout in $tmp/out, stderr in $tmp/err, exit status in $rc.
fx() {
    timeout "$T" "$FXCTL" --timeout 15000 "$@" >"$tmp/out" 2>"$tmp/err"
    rc=$?
}

# fxtty ARGS...: fxctl on a pseudo-terminal 100 columns wide (script(1)); stdout and stderr
# both in $tmp/out, exit status in $rc.
fxtty() {
    timeout "$T" script -qec "stty cols 100; $FXCTL --timeout 15000 $*" /dev/null >"$tmp/out" 2>"$tmp/err"
    rc=$?
}

rev_of() { grep -o '"rev":[0-9]*' "$tmp/out" | head -n 1 | cut -d: -f2; }

start_fxctl_daemon() {
    start_daemon "$FXCTL"
    FXCTL_URL="ws://127.0.0.1:$port"
    export FXCTL_URL
}

check_usage() {
    fx; check "no command: usage error" 2 "" "no command"
    fx frobnicate; check "unknown command: usage error" 2 "" "unknown command"
    fx set energy; check "set without K=V: usage error" 2 "" "usage: fxctl set"
    fx subscribe energy; check "subscribe without --frames: usage error" 2 "" "frames"
    fx list --frames 3; check "--frames outside subscribe: usage error" 2
    fx --url http://127.0.0.1:1/ list; check "bad URL: usage error" 2 "" "bad URL"
    fx --help; check "--help documents subscribe" 0 "subscribe NAME --frames N"
    fx --url ws://127.0.0.1:1 list; check "connection refused" 1 "" "connection refused"
    fx --url "$FXCTL_URL/not/ws" list; check "wrong path: handshake failure" 1 "" "handshake failed"
}

check_params() {
    fx list; check "list shows energy" 0 '"stream":"energy"'
    fx describe energy_wave; check "describe energy_wave has params" 0 '"params":\[{"name"'
    fx describe nope; check "describe unknown effect" 1 "" "unknown_effect"
    fx get energy; check "get energy" 0 '"op":"params"'
    rev0=$(rev_of)
    fx set energy alpha=2 'mode="adaptive"'; check "set energy valid" 0 '"alpha":2'
    rev1=$(rev_of)
    if [ -n "$rev0" ] && [ "$rev1" = $((rev0 + 1)) ]; then pass "set bumps rev ($rev0 -> $rev1)"
    else fail "set bumps rev ($rev0 -> $rev1)"; fi
    fx set energy alpha=-999; check "set bad value fails with bad_param" 1 "" "bad_param"
    fx get energy; check "get after bad set" 0 '"alpha":2'
    if [ "$(rev_of)" = "$rev1" ]; then pass "bad set leaves rev at $rev1"; else fail "bad set leaves rev ($(rev_of))"; fi
    fx set energy mode=adaptive; check "bare word value is a string" 0 '"mode":"adaptive"'
    fx get nope; check "get unknown stream" 1 "" "unknown_stream"
    fx set nope alpha=2; check "set unknown stream" 1 "" "unknown_stream"
    fx reset energy; check "reset energy" 0 '"op":"reset"'
}

check_streams() {
    fx create energy_wave fxctl_t1 width=32 height=32; check "create stream" 0 '"op":"created"'
    fx create energy_wave fxctl_t1; check "create existing name: exists" 1 "" "exists"
    fx list; check "list shows created stream" 0 '"stream":"fxctl_t1"'
    fx destroy fxctl_t1; check "destroy stream" 0 '"op":"destroyed"'
    fx destroy fxctl_t1; check "destroy again: unknown_stream" 1 "" "unknown_stream"
}

check_subscribe() {
    out=$tmp/frames
    fx subscribe energy --frames 3 --kind 2 --out "$out"; check "subscribe energy --frames 3 --kind 2" 0 '"seq":'
    n=$(grep -c '"payload_bytes"' "$tmp/out")
    if [ "$n" -eq 3 ]; then pass "3 frame lines printed"; else fail "3 frame lines printed ($n)"; fi
    n=$(grep -c '"kind":2' "$tmp/out")
    if [ "$n" -eq 3 ]; then pass "--kind 2: only textures"; else fail "--kind 2: only textures ($n of 3)"; fi
    nexr=$(ls "$out"/energy-*.exr 2>/dev/null | wc -l)
    njson=$(ls "$out"/energy-*.json 2>/dev/null | wc -l)
    if [ "$nexr" -eq 3 ] && [ "$njson" -eq 3 ]; then pass "3 .exr + 3 .json written"
    else fail "3 .exr + 3 .json written ($nexr, $njson)"; fi
    first=$(ls "$out"/energy-*.exr 2>/dev/null | head -n 1)
    if ! command -v exrheader >/dev/null 2>&1; then
        echo "skip exrheader not installed"
    elif [ -n "$first" ] && exrheader "$first" >"$tmp/out" 2>"$tmp/err" && grep -q dataWindow "$tmp/out"; then
        pass "exrheader reads $(basename "$first")"
    else
        fail "exrheader reads the .exr"
    fi
}

# Without --kind, --frames counts steps: energy's 6 textures each with its light rig (kind 3,
# same seq and sim_time), saved beside the textures under their own names: one .json per
# frame, nothing overwritten.
check_subscribe_rig() {
    out=$tmp/mixed
    fx subscribe energy --frames 6 --out "$out"; check "subscribe energy --frames 6 (textures and rigs)" 0 '"kind":3'
    nrig=$(ls "$out"/energy-*-rig.bin 2>/dev/null | wc -l)
    njson=$(ls "$out"/energy-*.json 2>/dev/null | wc -l)
    nexr=$(ls "$out"/energy-*.exr 2>/dev/null | wc -l)
    if [ "$nexr" -eq 6 ] && [ "$nrig" -ge 2 ] && [ "$njson" -eq $((nrig + nexr)) ]; then
        pass "6 steps: 6 textures, rig frames to NAME-SEQ-rig.bin, a .json each"
    else fail "6 steps: 6 textures, rig frames to NAME-SEQ-rig.bin, a .json each ($nrig rig, $nexr exr, $njson json)"; fi
    fx subscribe energy --frames 1 --kind 5; check "--kind 5 is a usage error" 2 "" "--kind needs a frame kind"
}

# --frames counts steps, not frames: 5 steps of energy are 5 textures, and each light rig
# printed belongs to one of them (a rig shares its texture's seq).
check_subscribe_steps() {
    fx subscribe energy --frames 5; check "subscribe energy --frames 5" 0 '"kind":2'
    ntex=$(grep '"kind":2' "$tmp/out" | grep -o '"seq":[0-9]*' | sort -u | wc -l)
    nrig=$(grep -c '"kind":3' "$tmp/out")
    orphan=$(grep '"kind":3' "$tmp/out" | grep -o '"seq":[0-9]*,' | while read -r q; do
        grep '"kind":2' "$tmp/out" | grep -q -- "$q" || echo "$q"; done)
    if [ "$ntex" -eq 5 ] && [ "$nrig" -ge 1 ] && [ -z "$orphan" ]; then
        pass "--frames 5 on energy: 5 steps, 5 textures and $nrig light rigs of those steps"
    else fail "--frames 5 on energy: 5 steps ($ntex textures, $nrig rigs, rigs of other steps: $orphan)"; fi
}

# The timeout bounds the whole wait: frames of a kind filtered out do not restart it, and a
# kind the stream never sends is named with what it sent instead.
check_subscribe_timeout() {
    start=$(date +%s)
    timeout 20 "$FXCTL" --timeout 2000 subscribe flame --frames 1 --kind 2 >"$tmp/out" 2>"$tmp/err"; rc=$?
    took=$(($(date +%s) - start))
    check "--kind 2 of the flame: exit 1, the kinds named" 1 "" \
        'no frame of kind 2 (texture) came; the stream sent [0-9]* of kind 1 (particles)'
    if [ "$rc" -eq 1 ] && [ "$took" -le 6 ]; then pass "... after the 2 s timeout ($took s), not reset by particle frames"
    else fail "... after the 2 s timeout (exit $rc after $took s)"; fi
}

# Particle frames to PLY: x y z temperature fuel flags, and vx vy vz after them once the
# flame sends velocities (its `velocities` parameter); the header's count matches the file.
check_subscribe_ply() {
    for vel in true false; do
        out=$tmp/ply-$vel
        fx set flame velocities=$vel; check "set flame velocities=$vel" 0 '"velocities":'"$vel"
        fx subscribe flame --frames 3 --out "$out"; check "subscribe flame --frames 3 --out (velocities $vel)" 0 '"kind":1'
        last=$(ls "$out"/flame-*.ply 2>/dev/null | sort -t- -k2 -n | tail -n 1)
        n=$(sed -n 's/^element vertex \([0-9]*\)$/\1/p' "$last" 2>/dev/null | head -n 1)
        hdr=$(grep -a -c '^property float v[xyz]$' "$last" 2>/dev/null)
        size=$(wc -c <"$last" 2>/dev/null || echo 0)
        head_bytes=$(grep -a -b -m 1 '^end_header$' "$last" 2>/dev/null | cut -d: -f1)
        rec=21
        want=0
        if [ "$vel" = true ]; then rec=33; want=3; fi
        if [ -n "$n" ] && [ "$n" -gt 0 ] && [ "$hdr" -eq "$want" ] && [ "$size" -eq $((head_bytes + 11 + n * rec)) ]; then
            pass "PLY of $n particles, $rec-byte records (velocities $vel)"
        else
            fail "PLY records (velocities $vel): n=$n, $hdr velocity properties, $size bytes"
        fi
    done
}

# --encoding engine (PROTOCOL.md §7.8): particles decoded into PLY (x y z temperature, then
# vx vy vz with velocities), textures written as the EXR of their halves; bad names refused.
check_subscribe_engine() {
    for vel in true false; do
        out=$tmp/engine-$vel
        fx set flame velocities=$vel; check "set flame velocities=$vel" 0 '"velocities":'"$vel"
        fx subscribe flame --frames 3 --encoding engine --out "$out"
        check "subscribe flame --encoding engine (velocities $vel)" 0 '"codec":16'
        last=$(ls "$out"/flame-*.ply 2>/dev/null | sort -t- -k2 -n | tail -n 1)
        n=$(sed -n 's/^element vertex \([0-9]*\)$/\1/p' "$last" 2>/dev/null | head -n 1)
        size=$(wc -c <"$last" 2>/dev/null || echo 0)
        head_bytes=$(grep -a -b -m 1 '^end_header$' "$last" 2>/dev/null | cut -d: -f1)
        rec=16
        if [ "$vel" = true ]; then rec=28; fi
        if [ -n "$n" ] && [ "$n" -gt 0 ] && ! grep -a -q '^property float fuel$' "$last" &&
            [ "$size" -eq $((head_bytes + 11 + n * rec)) ]; then
            pass "engine PLY of $n particles, $rec-byte records (velocities $vel)"
        else
            fail "engine PLY records (velocities $vel): n=$n, $size bytes"
        fi
    done
    out=$tmp/engine-tex
    fx subscribe energy --frames 2 --kind 2 --encoding engine --out "$out"
    check "subscribe energy --encoding engine" 0 '"codec":16'
    first=$(ls "$out"/energy-*.exr 2>/dev/null | head -n 1)
    if [ -n "$first" ] && exrheader "$first" >"$tmp/out" 2>"$tmp/err" && grep -q '(0 0) - (255 255)' "$tmp/out"; then
        pass "the engine texture as a 256x256 EXR"
    else
        fail "the engine texture as a 256x256 EXR"
    fi
    fx subscribe flame --frames 1 --encoding engin; check "--encoding engin is a usage error" 2 "" "--encoding needs default or engine"
    fx list --encoding engine; check "--encoding outside subscribe: usage error" 2 "" "go with subscribe only"
}

# A subscriber prints its stream's params broadcasts and fails clearly when the
# stream is destroyed under it.
check_destroyed() {
    fx create energy_wave fxctl_t2 width=32 height=32; check "create stream to destroy" 0
    timeout "$T" "$FXCTL" subscribe fxctl_t2 --frames 100000 >"$tmp/sub.out" 2>"$tmp/sub.err" &
    spid=$!
    wait_for "$tmp/sub.out" '"subscribed"' 100
    fx set fxctl_t2 alpha=3; check "set while subscribed" 0
    fx destroy fxctl_t2
    wait "$spid"; rc=$?
    cp "$tmp/sub.out" "$tmp/out"; cp "$tmp/sub.err" "$tmp/err"
    check "subscriber of destroyed stream fails" 1 '"op":"params","stream":"fxctl_t2"' "destroyed"
}

# watch prints the list, then streams created and destroyed by other connections.
check_watch() {
    timeout "$T" "$FXCTL" watch --count 2 >"$tmp/watch.out" 2>"$tmp/watch.err" &
    wpid=$!
    wait_for "$tmp/watch.out" '"op":"list"' 100
    fx create energy_wave fxctl_w width=32 height=32; check "create while watching" 0
    fx destroy fxctl_w; check "destroy while watching" 0
    wait "$wpid"; rc=$?
    cp "$tmp/watch.out" "$tmp/out"; cp "$tmp/watch.err" "$tmp/err"
    check "watch: the created event" 0 '^{"op":"created","stream":"fxctl_w","effect":"energy_wave","rev":1}$'
    check "watch: the destroyed event, then stops at --count" 0 '^{"op":"destroyed","stream":"fxctl_w"}$'
    fx watch --count 1 --timeout 300; check "watch --count with no event: timeout, exit 1" 1 '"op":"list"' "timeout after 300 ms"
    fx get energy --count 1; check "--count goes with watch only" 2 "" "watch only"
}

# Presets: list, load (a params reply), save and delete a user preset, and the errors.
check_presets() {
    fx presets flame; check "presets EFFECT lists its built-ins" 0 '"name":"thesis-table3.1","builtin":true'
    fx presets; check "presets lists every effect's" 0 '"effect":"compound_eye"'
    fx preset load flame candle; check "preset load: the params reply" 0 '"op":"params","stream":"flame"'
    fx get flame; check "the preset's values are in place" 0 '"radius":0.004'
    fx preset save flame fxctl-look "from the CLI"; check "preset save" 0 '"op":"preset_saved","effect":"flame","name":"fxctl-look","replaced":false'
    fx presets flame; check "the saved preset is listed with its doc" 0 '"name":"fxctl-look","builtin":false,"doc":"from the CLI"'
    fx preset delete flame fxctl-look; check "preset delete" 0 '"op":"preset_deleted"'
    fx preset delete flame candle; check "a built-in cannot be deleted: exit 1" 1 "" "read_only"
    fx preset load flame candel; check "an unknown preset: exit 1 with a suggestion" 1 "" 'did you mean "candle"'
    fx preset frob flame x; check "an unknown preset verb: exit 2" 2 "" "load, save or delete"
    fx preset load flame; check "preset load without a preset name: exit 2" 2 "" "wrong number of arguments"
}

# On a terminal fxctl prints for people; --json and pipes keep the JSON lines.
check_human() {
    fxtty describe flame; check "tty describe: a table per group" 0 '^\[combustion\]'
    grep -q '^name  *type  *default  *range  *unit  *update  *doc' "$tmp/out" && ! grep -q '"op"' "$tmp/out"
    rc=$?; check "tty describe: aligned columns, no JSON" 0
    test "$(grep -c '^\[combustion\]' "$tmp/out")" -eq 1; rc=$?; check "tty describe: each group once" 0
    fxtty get flame; check "tty get: aligned name = value" 0 '^  k_buo  *= 0\.0'
    fxtty set flame k_buo=0.011 fps=29; check "tty set: the stream and its new rev" 0 '^flame · rev [0-9]'
    grep -q '^  fps  *= 29' "$tmp/out" && ! grep -q 'k_stiff' "$tmp/out"; rc=$?
    check "tty set: only the values it changed" 0
    fxtty set flame h=0.004; check "a set that restarts the simulation says so" 0 "changing h restarted the simulation of flame"
    fx set flame h=0.0035 k_buo=0.01 fps=30; check "piped set: JSON on stdout, the restart note on stderr" 0 '^{"op":"params"' "restarted the simulation"
    fxtty --json get flame; check "tty --json: one JSON line" 0 '^{"op":"params","stream":"flame"'
    fx set flame k_buo=0.02 fps=25; check "piped set before a preset load" 0
    fxtty preset load flame candle; check "tty preset load: each value it changed, with what it was" 0 \
        '^  k_buo  *= 0.005  *(was 0.02)'
    n=$(grep -c ' = \|^ *= ' "$tmp/out")
    if grep -q '^  fps  *= 30  *(was 25)' "$tmp/out" && [ "$n" -lt 10 ] && ! grep -q '"op"' "$tmp/out"; then
        pass "tty preset load: only those ($n of 37 parameters), no JSON"
    else fail "tty preset load: only those ($n of 37 parameters)"; fi
    fxtty preset load flame candle; check "tty preset load of the same values: nothing changed" 0 '(no value changed)'
    fxtty create energy_wave fxctl_h width=32 height=32; check "tty create: a sentence" 0 '^created stream fxctl_h (effect energy_wave, rev 1)'
    fxtty reset fxctl_h; check "tty reset: a sentence" 0 '^reset stream fxctl_h: its simulation starts over'
    fxtty destroy fxctl_h; check "tty destroy: a sentence" 0 '^destroyed stream fxctl_h'
    fxtty preset save flame fxctl-tty; ! grep -q replacing "$tmp/out" || rc=9
    check "tty preset save: a sentence" 0 '^saved preset fxctl-tty of flame'
    fxtty preset save flame fxctl-tty; check "tty preset save again: it says it replaced" 0 '^saved preset fxctl-tty of flame, replacing'
    fxtty preset delete flame fxctl-tty; check "tty preset delete: a sentence" 0 '^deleted preset fxctl-tty of flame'
    fxtty list; check "tty list: a table" 0 '^flame  *flame  *[0-9]'
    fx set flame k_buo=0.01 k_buo=0.02; check "the same parameter twice: usage error" 2 "" "parameter given twice: k_buo"
    fx sett flame; check "an unknown command: did you mean" 2 "" 'did you mean "set"'
    fx set flame alpa=1; check "an unknown parameter: the server's did you mean" 1 "" 'unknown parameter'
    fx set flame k_bou=0.01; check "swapped letters: did you mean k_buo" 1 "" 'did you mean "k_buo"'
    fx set energy alhpa=2; check "swapped letters: did you mean alpha" 1 "" 'did you mean "alpha"'
    fx lsit; check "a command with swapped letters: did you mean list" 2 "" 'did you mean "list"'
    fx subscribe eye --frames 1; sleep 1.5
    fx subscribe eye --frames 1; check "a stale first frame is noted" 0 '"kind":4' "the first frame is [0-9.]* s old"
}

# A subscriber must fail clearly when the server goes away.
check_server_close() {
    timeout "$T" "$FXCTL" subscribe energy --frames 100000 >"$tmp/close.out" 2>"$tmp/close.err" &
    spid=$!
    wait_for "$tmp/close.out" '"seq"' 100
    kill "$dpid"; wait "$dpid" 2>/dev/null; dpid=
    wait "$spid"; rc=$?
    cp "$tmp/close.out" "$tmp/out"; cp "$tmp/close.err" "$tmp/err"
    check "subscriber fails when the server stops" 1 "" "server closed\|connection .* lost"
}

start_fxctl_daemon
check_usage
check_params
check_streams
check_subscribe
check_subscribe_rig
check_subscribe_steps
check_subscribe_timeout
check_subscribe_ply
check_subscribe_engine
check_destroyed
check_watch
check_presets
check_human
check_server_close
summary
