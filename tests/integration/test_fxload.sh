#!/bin/sh
# test_fxload.sh — end-to-end checks of fxload (and so libfxclient's fxpool) against a real fxstreamd.
#
# Owns: starting build/fxstreamd --port 0 on a free loopback port (bounded wait for its
# "listening on" line), running fxload against it in subscribe and set mode, judging
# the JSON report (python3: per-kind counts, delivered rate, thresholds, restored values),
# the per-second table and summary, the SVG plot (python3's XML parser: connections, a line
# per stream, skipped/s), thresholds' exit status 4, misspelled streams and parameters
# (exit 2 at once), set mode's restore and --keep (checked with fxctl get), a
# 1000-connection run, option errors, a refused connection, and a daemon killed under a
# run (subscribe and set mode). Each check counts one pass or fail; the last line is
# "test_fxload: N passed, M failed". Every fxload call runs under `timeout`; the suite
# takes about 40 s.
set -u
cd "$(dirname "$0")/../.."

FXLOAD=build/fxload
FXCTL=build/fxctl
T=30 # seconds any one fxload call may take
SUITE=test_fxload
. tests/integration/cli_lib.sh

# ld ARGS...: runs fxload, stdout in $tmp/out, stderr in $tmp/err, exit status in $rc.
ld() {
    timeout "$T" "$FXLOAD" "$@" >"$tmp/out" 2>"$tmp/err"
    rc=$?
}

# jcheck NAME FILE EXPR: EXPR is a python3 expression over d, the JSON document in FILE.
jcheck() {
    if /usr/bin/python3 - "$2" "$3" >"$tmp/jc" 2>&1 <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
s = {x["stream"]: x for x in d.get("streams", [])}
K = lambda x: x.get("kinds", {})
ok = eval(sys.argv[2].replace("\n", " "))
if not ok:
    print("false:", sys.argv[2])
    print(json.dumps({k: d[k] for k in ("connections", "totals", "errors") if k in d})[:800])
sys.exit(0 if ok else 1)
EOF
    then pass "$1"
    else fail "$1"; sed 's/^/     | /' "$tmp/jc" | head -n 6; fi
}

start_fxload_daemon() {
    start_daemon "$FXCTL" "$FXLOAD"
    URL="ws://127.0.0.1:$port"
}

check_usage() {
    ld --help; check "--help documents the options" 0 "--connections N"
    ld --connections 0; check "--connections 0: usage error" 2 "" "connections needs an integer"
    ld --connections 10001; check "--connections 10001: usage error" 2 "" "1 to 10000"
    ld --connections; check "option without value: usage error" 2 "" "needs a value"
    ld --frobnicate 3; check "unknown option: usage error" 2 "" "unknown option"
    ld extra; check "positional argument: usage error" 2 "" "unexpected argument"
    ld --url http://127.0.0.1:1/; check "bad URL: usage error" 2 "" "bad URL"
    ld --url ws://127.0.0.1:1 --url http://x; check "a bad second --url: usage error" 2 "" "bad URL \"http://x\""
    ld $(for i in $(seq 17); do printf -- '--url ws://127.0.0.1:%d ' "$i"; done)
    check "17 --url: usage error" 2 "" "at most 16 times"
    ld --mode fire; check "bad --mode: usage error" 2 "" "subscribe or set"
    ld --duration 2 --ramp 2; check "--ramp >= --duration: usage error" 2 "" "ramp must be shorter"
    ld --duration -1; check "negative --duration: usage error" 2 "" "duration needs seconds"
    ld --streams 'energy,,flame'; check "empty stream item: usage error" 2 "" "streams"
    ld --streams 'bad name'; check "invalid stream name: usage error" 2 "" "invalid stream name"
    ld --streams 'flame:0'; check "zero weight: usage error" 2 "" "WEIGHT"
    ld --set energy.alpha=1..2; check "--set without --mode set: usage error" 2 "" "goes with --mode set"
    ld --mode set --set energy.alpha=3..1; check "--set LO > HI: usage error" 2 "" "LO <= HI"
    ld --mode set --set alpha=1; check "--set without STREAM.: usage error" 2 "" "STREAM.PARAM"
    ld --mode set --set 'energy.alpha=not json'; check "--set bad JSON: usage error" 2 "" "JSON value"
    ld --mode set --max-fps 5; check "--max-fps in set mode: usage error" 2 "" "goes with --mode subscribe"
    ld --rate 5; check "--rate in subscribe mode: usage error" 2 "" "goes with --mode set"
    ld --max-fps 0; check "--max-fps 0: usage error" 2 "" "max-fps needs"
    ld --plot "$tmp/p.pdf"; check "--plot .pdf: usage error" 2 "" ".svg or .png"
    ld --max-p99 0; check "--max-p99 0: usage error" 2 "" "max-p99 needs milliseconds"
    ld --min-delivered 150; check "--min-delivered 150: usage error" 2 "" "percentage in (0, 100]"
    ld --max-skipped -1; check "--max-skipped -1: usage error" 2 "" "percentage in \[0, 100)"
    ld --mode set --min-delivered 50; check "--min-delivered in set mode: usage error" 2 "" "goes with --mode subscribe"
    ld --mode set --max-skipped 5; check "--max-skipped in set mode: usage error" 2 "" "goes with --mode subscribe"
    ld --url ws://127.0.0.1:1 --connections 3 --duration 3 --json "$tmp/nowhere/r.json"
    check "unwritable --json fails before the run" 1 "" "cannot write"
    ld --url ws://127.0.0.1:1 --connections 3 --duration 3 --ramp 0
    check "refused connection: exit 1 with a clear message" 1 "" "connection refused by 127.0.0.1:1"
    if grep -q "no connection could be established" "$tmp/err"; then pass "refused: says nothing connected"
    else fail "refused: says nothing connected"; fi
}

check_subscribe() {
    j=$tmp/run.json
    ld --url "$URL" --connections 50 --duration 4 --ramp 1 --json "$j" --plot "$tmp/run.svg"
    check "50 connections on energy,flame for 4 s" 0 "frames/s" ""
    run_rc=$rc # the plot checks below judge this run's SVG
    jcheck "report: 50 requested, 50 connected, none failed" "$j" \
        'd["connections"]["requested"] == 50 and d["connections"]["connected"] == 50 and d["connections"]["failed"] == 0'
    jcheck "report: no disconnects, no errors" "$j" \
        'd["connections"]["disconnects"] == 0 and d["totals"]["errors"] == 0 and d["errors"] == []'
    jcheck "report: frames and bytes > 0 on energy and flame" "$j" \
        'all(s[n]["frames"] > 0 and s[n]["bytes"] > 0 for n in ("energy", "flame"))'
    jcheck "report: 25 subscribers per stream" "$j" 's["energy"]["subscribers"] == 25 and s["flame"]["subscribers"] == 25'
    jcheck "report: energy sends textures (kind 2), flame particles (kind 1)" "$j" \
        '"2" in s["energy"]["kinds"] and "1" in s["flame"]["kinds"]'
    jcheck "report: energy's textures and light rigs counted apart, adding up to the stream" "$j" \
        'K(s["energy"])["2"]["name"] == "texture" and K(s["energy"])["3"]["name"] == "light_rig" and
         K(s["energy"])["2"]["frames"] > 0 and K(s["energy"])["3"]["frames"] > 0 and
         sum(k["frames"] for k in K(s["energy"]).values()) == s["energy"]["frames"] and
         sum(k["bytes"] for k in K(s["energy"]).values()) == s["energy"]["bytes"] and
         K(s["flame"])["1"]["name"] == "particles" and K(s["flame"])["1"]["frames"] == s["flame"]["frames"]'
    jcheck "report: latency per kind" "$j" \
        'len([k for x in d["streams"] for k in K(x).values()]) == 3 and
         all(0 < k["latency_ms"]["p50"] <= k["latency_ms"]["max"] for x in d["streams"] for k in K(x).values())'
    jcheck "report: delivered fps per subscriber against the stream fps (30), 0 < % <= 110" "$j" \
        'all(x["fps"] == 30 and x["target_fps"] == 30 and x["subscriber_seconds"] > 0 and 0 < x["delivered_pct"] <= 110
             and abs(x["delivered_fps"] - x["target_fps"] * x["delivered_pct"] / 100) < 0.1
             and all(0 < k["delivered_pct"] <= 110 for k in K(x).values()) for x in d["streams"])'
    if grep -q -E '^energy +25 .* [0-9.]+ of 30 fps \([0-9]+%\)$' "$tmp/out" &&
        grep -q -E '^  2 texture +[1-9][0-9]* .* of 30 fps' "$tmp/out" &&
        grep -q -E '^  3 light_rig +[1-9][0-9]* ' "$tmp/out" && grep -q -E '^  1 particles +[1-9]' "$tmp/out"; then
        pass "summary: a line per kind, delivered \"N of 30 fps (P%)\""
    else fail "summary: a line per kind, delivered \"N of 30 fps (P%)\""; fi
    jcheck "report: totals add up over streams" "$j" \
        'd["totals"]["frames"] > 0 and d["totals"]["frames"] == sum(x["frames"] for x in d["streams"]) and d["totals"]["bytes"] == sum(x["bytes"] for x in d["streams"])'
    jcheck "report: 0 < p50 <= p95 <= p99 <= max (total and per stream)" "$j" \
        'all(0 < L["p50"] <= L["p95"] <= L["p99"] <= L["max"] for L in [d["totals"]["latency_ms"]] + [x["latency_ms"] for x in d["streams"]])'
    jcheck "report: timed frames counted" "$j" 'd["totals"]["latency_ms"]["count"] > 0 and d["totals"]["latency_ms"]["count"] <= d["totals"]["frames"]'
    jcheck "report: one row per second, frames summing to the total" "$j" \
        '4 <= len(d["seconds"]) <= 5 and sum(r["frames"] for r in d["seconds"]) == d["totals"]["frames"]'
    jcheck "report: 50 connections open in the last full second" "$j" 'd["seconds"][3]["connections"] == 50'
    jcheck "report: each second's frames and skipped per stream add up" "$j" \
        'all(sum(x["frames"] for x in r["streams"].values()) == r["frames"] and
             sum(x["skipped"] for x in r["streams"].values()) == r["skipped"] for r in d["seconds"]) and
         0 < sum(r["streams"]["energy"]["frames"] for r in d["seconds"]) == s["energy"]["frames"]'
    rows=$(grep -c -E '^ +[0-9]+\.[0-9] +[0-9]+ +[0-9]+ +[0-9.]+ ' "$tmp/out")
    if [ "$rows" -ge 4 ]; then pass "table: $rows per-second lines"; else fail "table: per-second lines ($rows)"; fi
    if grep -q -E '^ +4\.0 +50 +[1-9][0-9]* ' "$tmp/out"; then pass "table: second 4 shows 50 connections and frames"
    else fail "table: second 4 shows 50 connections and frames"; fi
    if grep -q -E '^total +50 +[1-9]' "$tmp/out"; then pass "summary: total line"; else fail "summary: total line"; fi
    if [ "$run_rc" -eq 0 ] && [ -s "$tmp/run.svg" ] && /usr/bin/python3 -c '
import sys, xml.etree.ElementTree as E
r = E.parse(sys.argv[1]).getroot()
sys.exit(0 if r.tag.endswith("svg") and len(list(r.iter())) > 20 else 1)' "$tmp/run.svg" 2>"$tmp/err"
    then pass "plot: SVG exists and is well-formed XML"
    else fail "plot: SVG exists and is well-formed XML"; fi
    if [ "$run_rc" -eq 0 ] && grep -q "p99" "$tmp/run.svg" && grep -q "MB/s" "$tmp/run.svg"; then pass "plot: latency and throughput series"
    else fail "plot: latency and throughput series"; fi
    if [ "$run_rc" -eq 0 ] && /usr/bin/python3 - "$tmp/run.svg" >"$tmp/err" 2>&1 <<'EOF'
import sys, xml.etree.ElementTree as E
texts = {"".join(t.itertext()).strip() for t in E.parse(sys.argv[1]).getroot().iter() if t.tag.endswith("text")}
need = {"frame latency (ms)", "connections", "frames/s", "MB/s (all)", "skipped/s", "energy", "flame"}
title = [t for t in texts if t.startswith("fxload subscribe: 50 connections to ")]
missing = sorted(need - texts)
print("missing:", missing, "title:", title)
sys.exit(0 if not missing and title else 1)
EOF
    then pass "plot: connections, a line per stream (energy, flame), a skipped/s axis"
    else fail "plot: connections, a line per stream (energy, flame), a skipped/s axis"; fi

    check_misspelled_stream
    check_thresholds

    ld --url "$URL" --connections 6 --duration 2 --ramp 0 --streams 'energy+flame:2,flame' --max-fps 10 --quiet --json -
    check "groups, weights, --max-fps, --json - to stdout" 0 '"tool"'
    sed -n '/^{/,$p' "$tmp/out" >"$tmp/g.json"
    jcheck "groups: 4 energy+flame and 2 flame connections" "$tmp/g.json" \
        's["energy"]["subscribers"] == 4 and s["flame"]["subscribers"] == 6'
    jcheck "max-fps 10 caps the frame rate" "$tmp/g.json" \
        '0 < s["flame"]["frames"] <= 6 * 10 * 2.5 + 12'
    jcheck "max-fps 10: delivered against 10 fps, the stream's fps still 30" "$tmp/g.json" \
        'all(x["fps"] == 30 and x["target_fps"] == 10 and 0 < x["delivered_pct"] <= 110 for x in d["streams"])'
    if ! grep -q "frames/s" "$tmp/out" && grep -q "^total  *10  *[1-9]" "$tmp/err"; then pass "--json -: table to stderr, quiet"
    else fail "--json -: table to stderr, quiet"; fi
}

# A misspelled stream is a usage error: fxload stops at the server's first unknown_stream
# answer (not after --duration) with exit 2, the server's message, and no report file.
check_misspelled_stream() {
    start=$(date +%s)
    ld --url "$URL" --connections 4 --duration 25 --ramp 0 --streams enrgy,energy --payloads --json "$tmp/u.json"
    took=$(($(date +%s) - start))
    check "misspelled stream: exit 2 with the server's message" 2 "" \
        'fxload: subscribe enrgy: unknown_stream: no stream named "enrgy" (did you mean "energy"?)'
    if [ "$rc" -eq 2 ] && [ "$took" -le 5 ]; then pass "misspelled stream: fails at once (${took} s of 25)"
    else fail "misspelled stream: fails at once (${took} s of 25)"; fi
    if [ ! -e "$tmp/u.json" ]; then pass "misspelled stream: no empty report left"
    else fail "misspelled stream: no empty report left"; fi
}

# Thresholds: loose ones pass (exit 0), an impossible p99 fails with exit 4, named in the
# summary and on stderr; the JSON report lists every check with its measured value.
check_thresholds() {
    ld --url "$URL" --connections 6 --duration 3 --ramp 0.5 --quiet --json "$tmp/th.json" \
        --max-p99 60000 --min-delivered 1 --max-skipped 99
    check "loose thresholds: exit 0" 0 "thresholds: 0 of 4 failed"
    if grep -q -E '^  pass  --max-p99 60000 +frame latency p99 [0-9.]+ ms <= 60000 ms$' "$tmp/out" &&
        grep -q -E '^  pass  --min-delivered 1 +energy delivered [0-9.]+% >= 1%$' "$tmp/out" &&
        grep -q -E '^  pass  --min-delivered 1 +flame delivered ' "$tmp/out" &&
        grep -q -E '^  pass  --max-skipped 99 +skipped frames [0-9.]+% <= 99%$' "$tmp/out"; then
        pass "loose thresholds: each listed with its measured value and pass"
    else fail "loose thresholds: each listed with its measured value and pass"; fi
    jcheck "loose thresholds: JSON checks, all passed, measured values" "$tmp/th.json" \
        'd["thresholds"]["passed"] is True and [c["option"] for c in d["thresholds"]["checks"]] ==
         ["--max-p99", "--min-delivered", "--min-delivered", "--max-skipped"] and
         all(c["passed"] and c["measured"] is not None for c in d["thresholds"]["checks"]) and
         abs(d["thresholds"]["checks"][0]["measured"] - d["totals"]["latency_ms"]["p99"]) < 0.002 and
         [c["stream"] for c in d["thresholds"]["checks"][1:3]] == ["energy", "flame"] and
         abs(d["thresholds"]["checks"][1]["measured"] - s["energy"]["delivered_pct"]) < 0.06 and
         abs(d["thresholds"]["checks"][3]["measured"] - d["totals"]["skipped_pct"]) < 0.002'
    ld --url "$URL" --connections 6 --duration 3 --ramp 0.5 --quiet --json "$tmp/th.json" --max-p99 0.001 --max-skipped 99
    check "impossible --max-p99 0.001: exit 4, named on stderr" 4 "thresholds: 1 of 2 failed" \
        "fxload: threshold failed: --max-p99 0.001 (frame latency p99 [0-9.]* ms > 0.001 ms)"
    if grep -q -E '^  FAIL  --max-p99 0.001 +frame latency p99 [0-9.]+ ms > 0.001 ms$' "$tmp/out" &&
        grep -q -E '^  pass  --max-skipped 99 ' "$tmp/out"; then pass "impossible --max-p99: the summary names it FAIL"
    else fail "impossible --max-p99: the summary names it FAIL"; fi
    jcheck "impossible --max-p99: JSON says failed, measured above the limit" "$tmp/th.json" \
        'd["thresholds"]["passed"] is False and d["thresholds"]["checks"][0]["passed"] is False and
         d["thresholds"]["checks"][0]["measured"] > 0.001 and d["thresholds"]["checks"][1]["passed"] is True'
}

# getp STREAM: the stream's `params` reply (fxctl get) in $tmp/get.json; rev, alpha and beta
# of energy as $grev, $galpha, $gbeta (empty when the get failed).
getp() {
    timeout "$T" "$FXCTL" --url "$URL" get "$1" >"$tmp/get.json" 2>&1
    set -- $(/usr/bin/python3 -c 'import json, sys
d = json.load(open(sys.argv[1])); p = d["params"]
print(d["rev"], p.get("alpha", "-"), p.get("beta", "-"))' "$tmp/get.json" 2>/dev/null)
    grev=${1:-} galpha=${2:-} gbeta=${3:-}
}

check_set() {
    timeout "$T" "$FXCTL" --url "$URL" set energy alpha=1.25 beta=0.75 >"$tmp/out" 2>"$tmp/err"
    rc=$?; check "set mode: known values before the run (fxctl set alpha=1.25 beta=0.75)" 0
    getp energy; rev0=$grev
    # both drawn from ranges: every set changes a value, so each takes a revision (a set of the
    # values a stream already has keeps its rev: PROTOCOL.md §3.8)
    ld --url "$URL" --mode set --rate 40 --connections 5 --duration 2 --ramp 0.5 --set 'energy.alpha=0.5..2' \
        --set 'energy.beta=0.5..1' --json "$tmp/set.json" --plot "$tmp/set.png"
    check "set mode: 40 sets/s from 5 connections" 0 "sets/s"
    set_rc=$rc
    jcheck "set mode: sets ok, none failed, round trips ordered" "$tmp/set.json" \
        'd["sets"]["ok"] >= 40 and d["sets"]["failed"] == 0 and 0 < d["sets"]["latency_ms"]["p50"] <= d["sets"]["latency_ms"]["p99"] <= d["sets"]["latency_ms"]["max"]'
    jcheck "set mode: values before the run in the report, restored at the rev after the last set" "$tmp/set.json" \
        's["energy"]["before"] == {"alpha": 1.25, "beta": 0.75} and s["energy"]["restore"] == "done" and
         s["energy"]["restored_rev"] == s["energy"]["max_rev"] + 1 and d["options"]["keep"] is False'
    ok=$(/usr/bin/python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["sets"]["ok"])' "$tmp/set.json" 2>/dev/null)
    getp energy
    # the sets in flight at the end are answered before the restoring set: +1 exactly
    if [ -n "$rev0" ] && [ -n "$ok" ] && [ -n "$grev" ] && [ "$grev" -eq $((rev0 + ok + 1)) ]; then
        pass "set mode: server revision $rev0 -> $grev ($ok sets acknowledged, then the restore)"
    else
        fail "set mode: server revision advanced by the sets and the restore ($rev0 -> $grev, ok $ok)"
    fi
    if [ "$galpha" = 1.25 ] && [ "$gbeta" = 0.75 ]; then pass "set mode: fxctl get shows alpha and beta restored"
    else fail "set mode: fxctl get shows alpha and beta restored (alpha $galpha, beta $gbeta)"; fi
    if grep -q -E '^  energy: [0-9]+ ok, 0 failed, rev now [0-9]+; restored alpha=1.25, beta=0.75 \(rev [0-9]+\)$' "$tmp/out"
    then pass "set mode: the summary says what was restored"
    else fail "set mode: the summary says what was restored"; fi
    if [ "$set_rc" -eq 0 ] && [ -s "$tmp/set.png" ] && head -c 8 "$tmp/set.png" | grep -q PNG; then pass "set mode: PNG plot written"
    else fail "set mode: PNG plot written"; fi

    ld --url "$URL" --mode set --rate 20 --connections 2 --duration 1.5 --ramp 0 --set 'energy.alpha=1.75' --keep \
        --json "$tmp/keep.json"
    check "set mode --keep: run completes" 0 "kept (--keep): before the run alpha=1.25"
    getp energy
    if [ "$galpha" = 1.75 ]; then pass "set mode --keep: fxctl get shows the value set (1.75)"
    else fail "set mode --keep: fxctl get shows the value set (alpha $galpha)"; fi
    jcheck "set mode --keep: the report says kept" "$tmp/keep.json" \
        's["energy"]["restore"] == "kept" and "restored_rev" not in s["energy"] and d["options"]["keep"] is True'
    ld --keep; check "--keep in subscribe mode: usage error" 2 "" "keep goes with --mode set"

    getp energy; rev0=$grev
    ld --url "$URL" --mode set --rate 20 --connections 2 --duration 1.5 --ramp 0 --set 'energy.alpha=500..600'
    check "set mode: rejected values reported (bad_param), exit 3" 3 "" "set energy.alpha: bad_param"
    getp energy
    if [ "$galpha" = 1.75 ]; then pass "set mode: rejected values leave alpha as it was"
    else fail "set mode: rejected values leave alpha as it was ($galpha)"; fi

    rev0=$grev start=$(date +%s)
    ld --url "$URL" --mode set --duration 25 --set 'energy.alhpa=1'
    check "set mode: misspelled parameter, exit 2" 2 "" 'fxload: --set energy.alhpa: stream energy has no parameter "alhpa"'
    ld --url "$URL" --mode set --duration 25 --set 'energy.alpha=1' --set 'enrgy.alpha=1'
    check "set mode: misspelled stream, exit 2" 2 "" 'fxload: get enrgy: unknown_stream: no stream named "enrgy"'
    took=$(($(date +%s) - start))
    getp energy
    if [ "$rc" -eq 2 ] && [ "$took" -le 6 ] && [ -n "$grev" ] && [ "$grev" = "$rev0" ]; then
        pass "set mode: misspellings fail at once, nothing set"
    else fail "set mode: misspellings fail at once, nothing set (${took} s, rev $rev0 -> $grev)"; fi
}

check_scale() {
    timeout "$T" "$FXCTL" --url "$URL" create energy_wave fxload_small width=32 height=32 >"$tmp/out" 2>"$tmp/err"
    rc=$?; check "create a small stream for the scale run" 0
    ld --url "$URL" --connections 1000 --duration 5 --ramp 1.5 --streams fxload_small --max-fps 4 --quiet --json "$tmp/k.json"
    check "1000 connections: run completes" 0
    jcheck "1000 connections: all connected at once (peak 1000), none failed" "$tmp/k.json" \
        'd["connections"]["connected"] == 1000 and d["connections"]["peak"] == 1000 and d["connections"]["failed"] == 0 and d["connections"]["disconnects"] == 0'
    jcheck "1000 connections: all subscribed and frames flowing" "$tmp/k.json" \
        's["fxload_small"]["subscribers"] == 1000 and s["fxload_small"]["frames"] >= 1000'
}

check_daemon_killed() {
    timeout "$T" "$FXLOAD" --url "$URL" --connections 10 --duration 25 --ramp 0 --json "$tmp/kill.json" \
        >"$tmp/kill.out" 2>"$tmp/kill.err" &
    lpid=$!
    timeout "$T" "$FXLOAD" --url "$URL" --mode set --rate 20 --connections 2 --duration 25 --ramp 0 \
        --set energy.alpha=1.5 --json "$tmp/kills.json" >"$tmp/kills.out" 2>"$tmp/kills.err" &
    spid=$!
    wait_for "$tmp/kill.out" '^ *2\.0 ' 100
    wait_for "$tmp/kills.out" '^ *2\.0 ' 100
    kill "$dpid"; wait "$dpid" 2>/dev/null; dpid=
    start=$(date +%s)
    wait "$lpid"; rc=$?
    took=$(($(date +%s) - start))
    cp "$tmp/kill.out" "$tmp/out"; cp "$tmp/kill.err" "$tmp/err"
    check "daemon killed mid-run: fxload ends, exit 3" 3 "" "server closed the connection\|lost"
    wait "$spid"; rc=$?
    cp "$tmp/kills.out" "$tmp/out"; cp "$tmp/kills.err" "$tmp/err"
    check "daemon killed in set mode: the values cannot be restored, exit 1" 1 \
        "NOT restored (no connection open): before the run alpha=" "fxload: cannot restore energy: NOT restored"
    jcheck "daemon killed in set mode: the report says the restore failed" "$tmp/kills.json" \
        's["energy"]["restore"] == "failed" and s["energy"]["restore_error"] == "no connection open"'
    if [ "$took" -le 10 ]; then pass "daemon killed: fxload ended by itself within ${took} s"
    else fail "daemon killed: fxload ended by itself (${took} s)"; fi
    jcheck "daemon killed: 10 disconnects reported, run ended early" "$tmp/kill.json" \
        'd["connections"]["disconnects"] == 10 and d["end"] == "every connection closed" and d["elapsed_s"] < 20'
}

start_fxload_daemon
check_usage
check_subscribe
check_set
check_scale
check_daemon_killed
summary
