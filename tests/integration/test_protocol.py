"""test_protocol.py — fxstreamd end to end with an independent client (python3-websockets):
HTTP endpoints, hello, frames and their headers, live parameter changes seen in frames,
broadcasts, one check per error code, limits, persistence across restarts, shutdown."""
import asyncio
import json
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request

import websockets

from fxtest import DAEMON, ROOT, Client, Daemon, Suite, refusal
from rawws import Conn

SMALL = {"width": 64, "height": 48, "fps": 30}  # cheap frames keep the suite fast
D = None


def http_get_status(path):
    try:
        return http_get(path)
    except urllib.error.HTTPError as e:
        return e.code, None, None


def http_get(path):
    with urllib.request.urlopen(D.http + path, timeout=10) as r:
        return r.status, r.headers.get("Content-Type"), r.read().decode()


def http_raw(port, request):
    """Sends request bytes as they are; the response head's lines, lower-cased but the first."""
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(request)
        out = b""
        while b"\r\n\r\n" not in out:
            chunk = s.recv(4096)
            if not chunk:
                break
            out += chunk
    lines = out.split(b"\r\n\r\n")[0].split(b"\r\n")
    return lines[:1] + [x.lower() for x in lines[1:]] if out else []


async def test_http(t):
    status, ctype, body = http_get("/healthz")
    h = json.loads(body)
    t.check(status == 200 and ctype.startswith("application/json"), "healthz is JSON")
    t.check(h["status"] == "ok" and h["version"] and h["device"] and "uptime_s" in h, "healthz fields")
    t.check(any(s["stream"] == "energy" for s in h["streams"]), "healthz lists the default stream")
    status, ctype, body = http_get("/metrics")
    t.check(status == 200 and ctype.startswith("text/plain"), "metrics is text")
    for name in ("fxs_connections", "fxs_frames_sent_total", "fxs_stream_frames_produced_total", "fxs_stream_step_seconds_sum",
                 "fxs_stream_particles", "fxs_stream_delivered_fps", "fxs_send_queue_bytes",
                 "fxs_stream_bytes_sent_total", "fxs_stream_frames_skipped_total"):
        t.check(name in body, "metrics has " + name)


async def test_metrics_parse(t):
    """/metrics by Prometheus's own text parser: every family parses, counters end in
    _total, histograms have cumulative buckets ending at +Inf with _count = the +Inf bucket, and
    the per-stream figures are there for a flame that is being watched."""
    from prometheus_client.parser import text_string_to_metric_families
    c = await Client.connect(D)
    await c.request("subscribe", stream="flame")
    for _ in range(8):
        await c.frame(kind=1)
    http_get("/metrics")  # starts the delivered-fps window
    end = time.monotonic() + 1.5
    while time.monotonic() < end:  # keep reading, as a subscriber does
        await c.frame(kind=1)
    _, _, body = http_get("/metrics")
    fams = {f.name: f for f in text_string_to_metric_families(body)}
    t.check(len(fams) >= 25, "the text parser reads %d metric families" % len(fams))
    # Each # TYPE line is a family of its own: a counter fxs_connections_total beside a gauge
    # fxs_connections would be read into the gauge's family.
    types = re.findall(r"^# TYPE (\S+) (\S+)$", body, re.M)
    own = [(n, ty) for n, ty in types if fams.get(n[:-6] if ty == "counter" and n.endswith("_total") else n) is not None
           and fams[n[:-6] if ty == "counter" and n.endswith("_total") else n].type == ty]
    t.check(len(fams) == len(types) and len(own) == len(types),
            "%d families for %d # TYPE lines, each its own (%s)" % (len(fams), len(types), sorted(set(types) - set(own))))
    bad = [n for n, f in fams.items() if f.type == "counter" and not any(s.name.endswith("_total") for s in f.samples)]
    t.check(not bad, "every counter's samples end in _total (%s)" % bad)
    for name in ("fxs_stream_step_seconds", "fxs_stream_encode_seconds", "fxs_stream_frame_age_seconds"):
        f = fams.get(name)
        ok = f is not None and f.type == "histogram"
        flame = [s for s in (f.samples if f else []) if s.labels.get("stream") == "flame"]
        buckets = [s.value for s in flame if s.name.endswith("_bucket")]
        count = [s.value for s in flame if s.name.endswith("_count")]
        ok = ok and buckets == sorted(buckets) and flame and [s for s in flame if s.labels.get("le") == "+Inf"] and \
            count and count[0] == buckets[-1] and count[0] > 0
        t.check(bool(ok), "%s: a histogram with cumulative buckets for the flame (%s)" % (name, count))
    parts = [s.value for s in fams["fxs_stream_particles"].samples if s.labels["stream"] == "flame"]
    t.check(parts and parts[0] > 1000, "fxs_stream_particles of the flame (%s)" % parts)
    fps = [s.value for s in fams["fxs_stream_delivered_fps"].samples if s.labels["stream"] == "flame" and s.labels["kind"] == "1"]
    t.check(fps and 1 <= fps[0] <= 60, "fxs_stream_delivered_fps of the flame, kind 1 (%s per subscriber)" % fps)
    roles = {s.labels["role"] for s in fams["fxs_send_queue_bytes"].samples}
    t.check(roles == {"none", "view", "tune", "admin"}, "fxs_send_queue_bytes by role (%s)" % sorted(roles))
    await c.close()


async def test_static_root(t):
    """Only regular files that resolve inside the web root are served: a symlink to a file or a
    directory outside it is 404; other methods than GET get 405 with Allow: GET."""
    root, outside = tempfile.mkdtemp(prefix="fxs-web-"), tempfile.mkdtemp(prefix="fxs-out-")
    with open(os.path.join(root, "index.html"), "w") as f:
        f.write("<p>root</p>")
    with open(os.path.join(outside, "secret.txt"), "w") as f:
        f.write("secret")
    os.symlink(os.path.join(outside, "secret.txt"), os.path.join(root, "link.txt"))
    os.symlink(outside, os.path.join(root, "dir"))
    os.mkdir(os.path.join(root, "sub"))
    with Daemon("--web-root", root) as d:
        def get(path, method="GET"):
            req = urllib.request.Request(d.http + path, method=method)
            try:
                with urllib.request.urlopen(req, timeout=10) as r:
                    return r.status, r.read().decode(), r.headers
            except urllib.error.HTTPError as e:
                return e.code, e.read().decode(), e.headers
        t.check(get("/")[:2] == (200, "<p>root</p>"), "the root's index.html at /")
        st, body, _ = get("/link.txt")
        t.check(st == 404 and "secret" not in body, "a symlink to a file outside the root: 404 (%s)" % st)
        st, body, _ = get("/dir/secret.txt")
        t.check(st == 404 and "secret" not in body, "a file through a symlinked directory: 404 (%s)" % st)
        t.check(get("/sub")[0] == 404 and get("/../../etc/passwd")[0] == 404, "a directory or a path out: 404")
        for method in ("OPTIONS", "POST", "PUT", "DELETE"):
            st, _, hd = get("/healthz", method)
            t.check(st == 405 and hd.get("Allow") == "GET", "%s: 405 with Allow: GET (%s, %s)" % (method, st, hd.get("Allow")))
        # lws would answer these itself, before any callback, with 403: they get 405 too
        for line in (b"OPTIONS * HTTP/1.1", b"TRACE / HTTP/1.1", b"TRACE * HTTP/1.1", b"BREW /pot HTTP/1.1",
                     b"CONNECT 127.0.0.1:1 HTTP/1.1"):  # CONNECT: lws makes it a raw socket held open
            head = http_raw(d.port, line + b"\r\nHost: 127.0.0.1\r\n\r\n")
            t.check(head[:1] and b" 405 " in head[0] and b"allow: get" in head[1:],
                    "%s: 405 with Allow: GET (%s)" % (line.decode(), head[:1]))
        head = http_raw(d.port, b"GET * HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        t.check(head[:1] and b" 403 " in head[0], "GET * (not a path) stays 403 (%s)" % head[:1])
        t.check(get("/healthz")[0] == 200, "GET still served")


async def test_websocket_version(t):
    """Only Sec-WebSocket-Version 13 is accepted; others get 426 naming 13 (RFC 6455 4.4)."""
    for version, want in (("8", b" 426"), ("12", b" 426"), ("13", b" 101")):
        c = Conn.connect(D.port, version=version)
        c.close()
        t.check(want in c.status and (version == "13" or b"sec-websocket-version: 13" in c.head.lower()),
                "Sec-WebSocket-Version %s: %s" % (version, c.status.decode(errors="replace")))


async def test_hello(t):
    c = await Client.connect(D)
    t.check(c.ws.subprotocol == "fxstream.v1", "subprotocol negotiated")
    h = c.hello
    t.check(h["op"] == "hello" and h["protocol"] == "fxstream.v1", "hello first")
    t.check(h["server"].startswith("fxstreamd/") and "energy_wave" in h["effects"], "hello server, effects")
    t.check(h["limits"]["max_message_bytes"] > 0, "hello limits")
    await c.close()
    r = await refusal(D, url="ws://127.0.0.1:%d/elsewhere" % D.port, read=True)
    t.check(r is not None, "WebSocket on a wrong path refused (%s), the daemon still running" % r)
    r = await refusal(D, read=True, subprotocols=None)
    t.check(r is not None, "WebSocket without subprotocol fxstream.v1 refused (%s), the daemon still running" % r)
    t.check(await refusal(D, read=True) is None, "then a correct WebSocket gets its hello")
    status, _, _ = http_get_status("/" + "x" * 300)
    t.check(status == 404, "long unknown path is 404 (got %s)" % status)


async def test_spec_current(t):
    """PROTOCOL.md's parameter tables are generated from describe; they must match it."""
    c = await Client.connect(D)
    for effect in c.hello["effects"]:
        desc = await c.request("describe", effect=effect)
        p = subprocess.run([sys.executable, os.path.join(ROOT, "tools", "param_table.py"), effect, "--check",
                            os.path.join(ROOT, "protocol", "PROTOCOL.md")],
                           input=json.dumps(desc), capture_output=True, text=True, timeout=30)
        t.check(p.returncode == 0, "PROTOCOL.md table of %s matches describe (tools/param_table.py --write)%s"
                % (effect, "\n" + p.stdout + p.stderr if p.returncode else ""))
    await c.close()


async def test_frames(t):
    c = await Client.connect(D)
    r = await c.request("create", effect="energy_wave", stream="frames", params=SMALL)
    t.check(r["op"] == "created" and r["rev"] == 1, "create small stream")
    r = await c.request("subscribe", stream="frames")
    t.check(r["op"] == "subscribed" and r["channel"] > 0, "subscribed with a channel")
    mixed = [await c.frame() for _ in range(6)]
    rigs = [x for x in mixed if x["kind"] == 3]
    t.check(len(rigs) >= 2 and all(x["codec"] == 1 and x["payload"][:4] == b"FXR1" for x in rigs),
            "light-rig frames (kind 3, FXR1) come with the textures by default (%d of 6)" % len(rigs))
    t.check(any(x["sim_time"] == y["sim_time"] for x in rigs for y in mixed if y["kind"] == 2),
            "a rig frame has its texture's sim_time")
    frames = [x for x in mixed if x["kind"] == 2]
    frames += [await c.frame(kind=2) for _ in range(3 - len(frames))]
    f = frames[0]
    t.check(f["magic"] == b"FXS1" and f["header_bytes"] == 64, "header magic and size")
    t.check(f["kind"] == 2 and f["codec"] == 1, "texture frame, EXR codec")
    t.check(f["channel"] == r["channel"], "channel matches subscribed")
    t.check(f["width"] == 64 and f["height"] == 48, "texture size")
    t.check(all(len(x["payload"]) == x["payload_bytes"] for x in frames), "payload_bytes matches")
    t.check(all(x["payload"][:4] == b"\x76\x2f\x31\x01" for x in frames), "payload is an OpenEXR file")
    t.check(frames[0]["seq"] < frames[1]["seq"] < frames[2]["seq"], "seq increases")
    t.check(frames[0]["sim_time"] <= frames[2]["sim_time"], "sim_time advances")
    lat = time.time() * 1e6 - frames[2]["server_time_us"]
    t.check(-1e6 < lat < 5e6, "server_time_us is wall-clock microseconds")
    await c.close()


async def test_set_reaches_frames(t):
    a, b = await Client.connect(D), await Client.connect(D)
    await a.request("subscribe", stream="frames")
    await b.request("subscribe", stream="frames")
    before = (await a.request("get", stream="frames"))["rev"]
    r = await a.request("set", stream="frames", params={"alpha": 2.0, "width": 32})
    t.check(r["op"] == "params" and r["rev"] == before + 1, "set -> params with rev + 1")
    t.check(r["params"]["alpha"] == 2.0 and r["params"]["width"] == 32, "set reply has the new values")
    ev = await b.text()
    t.check(ev["op"] == "params" and ev["rev"] == r["rev"] and "id" not in ev, "broadcast to other subscriber")
    deadline, seen = time.monotonic() + 15, None
    while time.monotonic() < deadline:
        f = await a.frame(kind=2)
        if f["param_rev"] == r["rev"]:
            seen = f
            break
    t.check(seen is not None, "frames carry the new rev")
    t.check(seen is not None and seen["width"] == 32, "the change took effect in the frame")
    await a.close()
    await b.close()


async def expect_error(t, c, text, code, what):
    m = await c.raw(text)
    t.check(m["op"] == "error" and m["code"] == code and m["message"], "%s -> %s (%s)" % (what, code, m.get("code")))
    return m


async def test_error_codes(t):
    c = await Client.connect(D)
    await expect_error(t, c, "{nope", "bad_json", "malformed JSON")
    await expect_error(t, c, "[" * 100 + "]" * 100, "bad_json", "deep nesting")
    await expect_error(t, c, '{"op":"list","stream":1}', "bad_request", "unknown field")
    await expect_error(t, c, '{"op":"warp"}', "unknown_op", "unknown op")
    await expect_error(t, c, '{"op":"describe","effect":"smoke"}', "unknown_effect", "unknown effect")
    await expect_error(t, c, '{"op":"get","stream":"ghost"}', "unknown_stream", "unknown stream")
    await expect_error(t, c, '{"op":"create","effect":"energy_wave","stream":"energy"}', "exists", "existing name")
    m = await expect_error(t, c, '{"op":"set","id":9,"stream":"energy","params":{"divisions":7}}', "bad_param",
                           "odd divisions")
    t.check(m.get("id") == 9 and m.get("param") == "divisions", "error echoes id and names the param")
    await expect_error(t, c, '{"op":"set","stream":"energy","params":{"eye":[0,0,"x"]}}', "bad_param", "wrong type")
    await expect_error(t, c, '{"op":"set","stream":"energy","params":{"alpha":1e400}}', "bad_param", "infinity")
    await expect_error(t, c, '{"op":"set","stream":"energy","params":{"fps":1000}}', "bad_param", "out of range")
    await expect_error(t, c, '{"op":"set","stream":"energy","params":{"eye":[1,2]}}', "bad_param", "wrong length")
    await expect_error(t, c, '{"op":"set","stream":"energy","params":{"colour":1}}', "bad_param", "unknown name")
    # A misspelt name gets the nearest known one ("did you mean"), a far-off one none.
    for text, code, hint in (('{"op":"set","stream":"energy","params":{"alpa":2}}', "bad_param", '"alpha"'),
                             ('{"op":"lst"}', "unknown_op", '"list"'),
                             ('{"op":"describe","effect":"flam"}', "unknown_effect", '"flame"'),
                             ('{"op":"get","stream":"energi"}', "unknown_stream", '"energy"'),
                             ('{"op":"get","stream":"zzzzzzzz"}', "unknown_stream", None)):
        m = await expect_error(t, c, text, code, "misspelt name in %s" % text)
        got = m["message"]
        t.check(('did you mean %s?' % hint in got) if hint else ("did you mean" not in got),
                "%s: %s" % ("suggests " + hint if hint else "no suggestion for a far-off name", got))
    # Only exactly one JSON value is acted on: cJSON alone would run the first of two objects,
    # the first of duplicate members and a string cut at U+0000.
    await expect_error(t, c, '{"op":"list"}{"op":"destroy","stream":"energy"}', "bad_json", "trailing data")
    await expect_error(t, c, '{"op":"get","op":"destroy","stream":"energy"}', "bad_json", "duplicate member")
    await expect_error(t, c, '{"op":"list\\u0000x"}', "bad_json", "U+0000")
    await expect_error(t, c, '{"op":"create","effect":"energy_wave","stream":"ab\\u0000cd"}', "bad_json", "U+0000")
    await expect_error(t, c, '{"op":"auth","token":"t\\u0000junk"}', "bad_json", "U+0000")
    # preset ops check their fields in the order of §3 before any state
    for text, code, param in (('{"op":"preset_save","stream":"nope","name":"bad name"}', "bad_request", "name"),
                              ('{"op":"preset_save","stream":"nope","name":"ok","doc":"%s"}' % ("x" * 201), "bad_request", "doc"),
                              ('{"op":"preset_save","stream":"energy","name":"ember-arc","doc":"%s"}' % ("x" * 201),
                               "bad_request", "doc"),
                              ('{"op":"preset_save","stream":"nope","name":"ember-arc"}', "unknown_stream", "stream"),
                              ('{"op":"preset_save","name":"x","doc":7}', "bad_request", "stream"),
                              ('{"op":"preset_load","name":7}', "bad_request", "stream")):
        m = await expect_error(t, c, text, code, text[:60])
        t.check(m.get("param") == param, "%s: param %s (%s)" % (text[:60], param, m.get("param")))
    # RFC 8259 exactly: not 0200 as 200, nor \f as whitespace, nor raw control characters.
    rev = (await c.request("get", stream="energy"))["rev"]
    for text, why in (('{"op":"set","stream":"energy","params":{"divisions":0200}}', "leading zero"),
                      ('{"op":"set","stream":"energy","params":{"alpha":1.}}', "digit must follow '.'"),
                      ('{"op":"set","stream":"energy","params":{"alpha":-00}}', "leading zero"),
                      ('\f{"op":"list"}', "byte 0x0c"), ('{"op":"list"}\v', "trailing data"),
                      ('{"op":"li\x01st"}', "raw control character U+0001")):
        m = await expect_error(t, c, text, "bad_json", "%r" % text)
        t.check(why in m["message"], "%r: the message says %r (%s)" % (text, why, m["message"]))
    t.check((await c.request("get", stream="energy"))["rev"] == rev, "none of those sets changed the stream")
    # ids come back exactly, or are refused when a double cannot hold them
    for text in ("9007199254740991", "-9007199254740991", "0.1", "123456.789", "1e-300", '"x\\u00e9"'):
        await c.ws.send('{"op":"list","id":%s}' % text)
        got, want = json.loads(await c.ws.recv()).get("id"), json.loads(text)
        t.check(got == want and type(got) is type(want), "id %s echoed exactly (got %r)" % (text, got))
    for text in ("9007199254740992", "1e400", "-1e400"):
        m = await expect_error(t, c, '{"op":"list","id":%s}' % text, "bad_request", "id %s refused" % text)
        t.check(m.get("param") == "id" and "id" not in m, "id %s: refused naming id, no id echoed" % text)
    # Replies are valid UTF-8 even where a quoted client string is cut: the
    # client would otherwise drop the connection (websockets raises on invalid UTF-8).
    m = await expect_error(t, c, json.dumps({"op": "a" * 63 + "\u00e9"}, ensure_ascii=False), "unknown_op",
                           "an op cut inside a character")
    t.check(m["message"].endswith('a?"'), "the cut character is replaced, not split (%s)" % m["message"][-12:])
    m = await expect_error(t, c, json.dumps({"op": "set", "stream": "energy", "params": {"\u00e9" * 300: 1}},
                                            ensure_ascii=False), "bad_param", "a long unknown parameter name")
    names = [x["stream"] for x in (await c.request("list"))["streams"]]
    t.check("energy" in names and "ab" not in names and "abcd" not in names,
            "none of them destroyed or created anything (%s)" % names)
    big = json.dumps({"op": "list", "pad": "x" * (c.hello["limits"]["max_message_bytes"] + 10)})
    await expect_error(t, c, big, "limit", "oversized message")
    r = await c.request("list")
    t.check(r["op"] == "list", "connection usable after every error")
    await c.close()


async def test_invalid_utf8_closes_1007(t):
    """A text frame that is not UTF-8 closes the connection with 1007 (RFC 6455 8.1)."""
    c = await Client.connect(D)
    await c.ws.write_frame(True, websockets.frames.OP_TEXT, b'{"op":"list","x":"\xff\xfe"}')
    try:
        await c.text(timeout=5)
        t.check(False, "invalid UTF-8 in a text frame: closed with 1007")
    except websockets.exceptions.ConnectionClosed as e:
        t.check(e.rcvd is not None and e.rcvd.code == 1007, "invalid UTF-8 in a text frame: closed with 1007 (%s)" % e.rcvd)
    t.check(await refusal(D, read=True) is None, "the daemon serves the next connection")


async def test_noop_set(t):
    """A set that changes nothing keeps the revision and broadcasts nothing (no new rev, no
    params to every subscriber)."""
    a, b = await Client.connect(D), await Client.connect(D)
    await a.request("create", effect="energy_wave", stream="still", params=SMALL)
    await b.request("subscribe", stream="still")
    cur = await a.request("get", stream="still")
    for params in ({"alpha": cur["params"]["alpha"]}, {}, {"width": SMALL["width"], "fps": SMALL["fps"]}, cur["params"]):
        r = await a.request("set", stream="still", params=params)
        t.check(r["op"] == "params" and r["rev"] == cur["rev"] and r["params"] == cur["params"],
                "a set of the current values %s: rev stays %d (%s)" % (list(params)[:3], cur["rev"], r.get("rev")))
    r = await a.request("preset_save", stream="still", name="same")
    r = await a.request("preset_load", stream="still", name="same")
    t.check(r["op"] == "params" and r["rev"] == cur["rev"], "a preset_load of the current document too (%s)" % r.get("rev"))
    r = await a.request("set", stream="still", params={"alpha": 2.5})
    t.check(r["rev"] == cur["rev"] + 1, "a real change takes the next revision (%s)" % r["rev"])
    events = []
    try:
        while True:
            events.append(await b.text(timeout=1.0))
    except asyncio.TimeoutError:
        pass
    events = [e["rev"] for e in events if e["op"] == "params"]
    t.check(events == [cur["rev"] + 1], "the subscriber heard of the real change only (%s)" % events)
    await a.request("preset_delete", effect="energy_wave", name="same")
    await a.request("destroy", stream="still")
    await a.close()
    await b.close()


async def test_paused_first_frame(t):
    """The first frame after subscribing to a paused stream was computed before the pause: it is
    sent at once marked FXS_FLAG_BEFORE_PAUSE (flags bit 31), fresh frames unmarked after it,
    so a client can tell an old frame with its old sim_time from a fresh one."""
    c = await Client.connect(D)
    await c.request("create", effect="energy_wave", stream="napping", params=SMALL)
    await c.request("subscribe", stream="napping")
    last = [await c.frame(kind=2) for _ in range(3)][-1]
    t.check(all(f["flags"] == 0 for f in [last]), "frames of a running stream are unmarked")
    await c.request("unsubscribe", stream="napping")
    await asyncio.sleep(0.5)
    await c.request("subscribe", stream="napping")
    first, second = await c.frame(kind=2), await c.frame(kind=2)
    t.check(first["flags"] == 0x80000000 and first["seq"] >= last["seq"] and first["sim_time"] <= second["sim_time"],
            "the first frame after the pause is marked (flags %#x, seq %d after %d)" % (first["flags"], first["seq"], last["seq"]))
    t.check(second["flags"] == 0 and second["seq"] > first["seq"], "the next one is fresh and unmarked (%#x)" % second["flags"])
    d = await Client.connect(D)
    await d.request("subscribe", stream="napping")
    f = await d.frame(kind=2)
    t.check(f["flags"] == 0, "a subscriber joining the running stream gets no marked frame (%#x)" % f["flags"])
    await c.request("destroy", stream="napping")
    await c.close()
    await d.close()


async def test_nothing_half_applied(t):
    c = await Client.connect(D)
    before = await c.request("get", stream="energy")
    r = await c.request("set", stream="energy", params={"alpha": 3.0, "beta": -1})
    t.check(r["op"] == "error", "partly bad set rejected")
    after = await c.request("get", stream="energy")
    t.check(before["params"] == after["params"] and before["rev"] == after["rev"], "nothing half-applied")
    await c.close()


async def test_destroy_and_max_fps(t):
    c, sub = await Client.connect(D), await Client.connect(D)
    await c.request("create", effect="energy_wave", stream="slow", params=SMALL)
    r = await sub.request("subscribe", stream="slow", max_fps=2)
    t.check(r["op"] == "subscribed", "subscribe with max_fps")
    start, n = time.monotonic(), {2: 0, 3: 0}
    while time.monotonic() - start < 2.0:
        try:
            f = await sub.frame(timeout=max(0.05, 2.0 - (time.monotonic() - start)))
            n[f["kind"]] += 1
        except asyncio.TimeoutError:
            break
    t.check(1 <= n[2] <= 6, "max_fps=2 caps the rate (%d textures in 2 s)" % n[2])
    t.check(abs(n[3] - n[2]) <= 1, "max_fps counts steps: each texture's light rig comes with it (%d rigs)" % n[3])
    r = await c.request("destroy", stream="slow")
    t.check(r["op"] == "destroyed", "destroy")
    ev = await sub.text()
    t.check(ev["op"] == "unsubscribed" and ev.get("reason") == "destroyed", "subscriber told of destroy")
    await c.close()
    await sub.close()


async def test_max_fps_range(t):
    """max_fps is bounded to [0.01, 1000]: a rate like 1e-14 was once accepted and its interval
    overflowed the daemon's timer, which then spun and ignored healthz, new clients and SIGTERM."""
    c, slow, other = await Client.connect(D), await Client.connect(D), await Client.connect(D)
    await c.request("create", effect="energy_wave", stream="rare", params=SMALL)
    for mf in (1e-14, 1e-300, 5e-324, 0.0099):
        r = await slow.request("subscribe", stream="rare", max_fps=mf)
        t.check(r["op"] == "error" and r["code"] == "bad_request" and r.get("param") == "max_fps",
                "max_fps %g refused (%s)" % (mf, r.get("message")))
    r = await slow.request("subscribe", stream="rare", max_fps=0.01)
    t.check(r["op"] == "subscribed", "max_fps 0.01 (the minimum) accepted")
    await slow.frame(kind=2)
    status, _, _ = http_get("/healthz")
    t.check(status == 200, "healthz answers beside a 0.01 fps subscription")
    r = await other.request("subscribe", stream="rare")
    n = 0
    for _ in range(5):
        await other.frame(kind=2, timeout=5)
        n += 1
    t.check(n == 5, "another subscriber of the same stream keeps getting frames")
    try:
        f = await slow.frame(kind=2, timeout=1.0)
        t.check(False, "the 0.01 fps subscriber got a second step within 1 s (seq %d)" % f["seq"])
    except asyncio.TimeoutError:
        t.check(True, "the 0.01 fps subscriber waits for its next step")
    await c.request("destroy", stream="rare")
    for x in (c, slow, other):
        await x.close()


async def test_persistence(t):
    global D
    c = await Client.connect(D)
    await c.request("create", effect="energy_wave", stream="kept", params={"width": 40})
    r = await c.request("set", stream="kept", params={"alpha": 1.5})
    await c.close()
    status = D.stop()
    t.check(status == 0, "SIGTERM exits 0 (got %s)" % status)
    D = Daemon(state_dir=D.state_dir)
    c = await Client.connect(D)
    g = await c.request("get", stream="kept")
    t.check(g["op"] == "params" and g["params"]["width"] == 40 and g["params"]["alpha"] == 1.5,
            "streams and parameters survive a restart")
    t.check(g.get("rev") == r["rev"], "revision survives a restart")
    await c.close()


async def test_rev_64bit(t):
    """rev is 64-bit end to end: a stored 4294967295 goes on to 4294967296, not 0."""
    state = tempfile.mkdtemp(prefix="fxs-state-")
    with open(os.path.join(state, "streams.json"), "w") as f:
        json.dump([{"stream": "big", "effect": "energy_wave", "rev": 4294967295, "params": {"width": 32, "height": 32}}], f)
    with Daemon(state_dir=state) as d:
        c = await Client.connect(d)
        g = await c.request("get", stream="big")
        s = await c.request("set", stream="big", params={"alpha": 2})
        t.check(g.get("rev") == 4294967295 and s.get("rev") == 4294967296, "rev %s -> %s" % (g.get("rev"), s.get("rev")))
        await c.close()
    with Daemon(state_dir=state) as d:
        c = await Client.connect(d)
        g = await c.request("get", stream="big")
        t.check(g.get("rev") == 4294967296, "and it is stored as such (%s)" % g.get("rev"))
        await c.close()


async def test_state_write_failure(t):
    """A change the state directory refuses is not applied: set, create and
    destroy get `unavailable`, nothing changes, /healthz and /metrics show the condition until a
    write succeeds, and a restart finds exactly the acknowledged state."""
    state = tempfile.mkdtemp(prefix="fxs-state-")
    blocker = os.path.join(state, "streams.json.tmp")  # a directory there fails the write, even as root
    with Daemon(state_dir=state) as d:
        c = await Client.connect(d)
        r = await c.request("set", stream="energy", params={"alpha": 1.5})
        t.check(r.get("rev") == 2, "a set is stored and acknowledged (rev 2)")
        os.mkdir(blocker)
        r = await c.request("set", stream="energy", params={"alpha": 3})
        t.check(r.get("code") == "unavailable" and "streams.json" in r.get("message", ""),
                "a set the disk refuses: unavailable naming the file (%s)" % r)
        g = await c.request("get", stream="energy")
        t.check(g["rev"] == 2 and g["params"]["alpha"] == 1.5, "and it is not applied (rev %s, alpha %s)"
                % (g["rev"], g["params"]["alpha"]))
        r = await c.request("create", effect="energy_wave", stream="nope", params={"width": 32, "height": 32})
        names = [s["stream"] for s in (await c.request("list"))["streams"]]
        t.check(r.get("code") == "unavailable" and "nope" not in names, "a create: unavailable, no stream (%s)" % names)
        r = await c.request("destroy", stream="eye")
        names = [s["stream"] for s in (await c.request("list"))["streams"]]
        t.check(r.get("code") == "unavailable" and "eye" in names, "a destroy: unavailable, the stream stays")
        with urllib.request.urlopen(d.http + "/healthz", timeout=10) as h:
            h = json.loads(h.read())
        t.check(h["status"] == "degraded" and h["state"]["writable"] is False and "streams.json" in h["state"]["last_error"],
                "/healthz: degraded, state not writable, with the reason (%s)" % h.get("state"))
        with urllib.request.urlopen(d.http + "/metrics", timeout=10) as m:
            m = m.read().decode()
        t.check("fxs_state_writable 0" in m and "fxs_state_write_failures_total 3" in m,
                "/metrics: fxs_state_writable 0, 3 failures")
        os.rmdir(blocker)
        r = await c.request("set", stream="energy", params={"alpha": 2.5})
        with urllib.request.urlopen(d.http + "/healthz", timeout=10) as h:
            h = json.loads(h.read())
        t.check(r.get("rev") == 3 and h["status"] == "ok" and h["state"] == {"writable": True},
                "once a write succeeds: rev 3, /healthz ok again (%s)" % h.get("state"))
        await c.close()
    with Daemon(state_dir=state) as d:
        c = await Client.connect(d)
        g = await c.request("get", stream="energy")
        names = [s["stream"] for s in (await c.request("list"))["streams"]]
        t.check(g["rev"] == 3 and g["params"]["alpha"] == 2.5 and names == ["energy", "flame", "eye"],
                "a restart finds exactly the acknowledged state (rev %s, %s)" % (g["rev"], names))
        await c.close()


async def test_presets_persist(t):
    """User presets survive a restart; a save whose file write fails is `unavailable` and changes
    nothing; a stored preset that no longer validates loads as bad_param."""
    state = tempfile.mkdtemp(prefix="fxs-state-")
    with Daemon(state_dir=state) as d:
        c = await Client.connect(d)
        await c.request("set", stream="flame", params={"k_buo": 0.02, "fps": 24})
        r = await c.request("preset_save", stream="flame", name="tall", doc="strong buoyancy")
        t.check(r.get("op") == "preset_saved", "preset_save acknowledged (%s)" % r)
        t.check(os.path.exists(os.path.join(state, "presets.json")), "presets.json written before the reply")
        os.mkdir(os.path.join(state, "presets.json.tmp"))  # the next write fails, even as root
        r = await c.request("preset_save", stream="flame", name="lost")
        t.check(r.get("code") == "unavailable" and "presets.json" in r.get("message", ""),
                "a failed write: unavailable naming the file (%s)" % r)
        r = await c.request("preset_delete", effect="flame", name="tall")
        t.check(r.get("code") == "unavailable", "a failed delete: unavailable (%s)" % r.get("code"))
        names = [p["name"] for p in (await c.request("presets", effect="flame"))["presets"] if not p["builtin"]]
        t.check(names == ["tall"], "nothing changed in memory (%s)" % names)
        os.rmdir(os.path.join(state, "presets.json.tmp"))
        t.check((await c.request("get", stream="flame"))["params"]["k_buo"] == 0.02, "connection usable")
        await c.close()
    stored = json.load(open(os.path.join(state, "presets.json")))
    stored.append({"effect": "flame", "name": "old", "doc": "", "params": {"k_buo": 9}})
    with open(os.path.join(state, "presets.json"), "w") as f:
        json.dump(stored, f)
    with Daemon(state_dir=state) as d:
        c = await Client.connect(d)
        await c.request("preset_load", stream="flame", name="thesis-table3.1")
        r = await c.request("preset_load", stream="flame", name="tall")
        t.check(r.get("op") == "params" and r["params"]["k_buo"] == 0.02 and r["params"]["fps"] == 24 and
                r["params"]["h"] == 0.0035, "the saved preset survives a restart and loads whole (%s)" % r.get("op"))
        r = await c.request("preset_load", stream="flame", name="old")
        t.check(r.get("code") == "bad_param" and r.get("param") == "k_buo", "a preset that no longer validates: "
                "bad_param k_buo (%s)" % r)
        t.check((await c.request("get", stream="flame"))["params"]["k_buo"] == 0.02, "and changes nothing")
        await c.close()
    # Each entry is checked as preset_save checks one: unchecked, each of these would load and
    # then be listed (1e999 as null), sent raw (\xff) or be impossible to delete (../../x).
    good = json.load(open(os.path.join(state, "presets.json")))
    entry = lambda name, **kw: dict(dict(effect="flame", name=name, doc="", params={"fps": 20}), **kw)
    for extra, why in (([entry("candle")], 'entry 3 (flame/candle): "candle" is a built-in flame preset'),
                       ([entry("../../x")], "entry 3 (flame/../../x): preset names are"),
                       ([entry("twin"), entry("twin")], 'entry 4 (flame/twin): a second preset named "twin"'),
                       ([entry("inf", params={"fps": "INF"})], "entry 3 (flame/inf): params.fps is not a finite number"),
                       ([entry("p%d" % i) for i in range(63)], "entry 65 (flame/p62): flame already has 64 presets"),
                       ([entry("bad\xff")], "invalid UTF-8")):
        text = json.dumps(good + extra).replace('"INF"', "1e999").encode().replace(b"\\u00ff", b"\xff")
        with open(os.path.join(state, "presets.json"), "wb") as f:
            f.write(text)
        try:
            p = subprocess.run([DAEMON, "--port", "0", "--state-dir", state], capture_output=True, timeout=20)
        except subprocess.TimeoutExpired as e:  # it started and served
            p = subprocess.CompletedProcess(e.cmd, None, b"", e.stderr or b"")
        err = [x for x in p.stderr.decode(errors="replace").splitlines() if "presets.json" in x]
        t.check(p.returncode not in (0, None) and err and why in err[-1] and open(os.path.join(state, "presets.json"), "rb").read() == text,
                "presets.json with %s: the start is refused naming it, the file kept (%s)" % (why[:40], err))


async def test_quarantine(t):
    """Stored streams that no longer validate are kept aside, not erased."""
    state = tempfile.mkdtemp(prefix="fxs-state-")
    stored = [{"stream": "ok", "effect": "energy_wave", "rev": 3, "params": {"width": 32, "height": 32}},
              {"stream": "old", "effect": "smoke", "rev": 7, "params": {}},
              {"stream": "wide", "effect": "energy_wave", "rev": 2, "params": {"width": 99999}}]
    with open(os.path.join(state, "streams.json"), "w") as f:
        json.dump(stored, f)
    with Daemon(state_dir=state) as d:
        c = await Client.connect(d)
        names = [s["stream"] for s in (await c.request("list"))["streams"]]
        await c.request("set", stream="ok", params={"alpha": 2})  # rewrites streams.json
        await c.close()
        with urllib.request.urlopen(d.http + "/healthz", timeout=10) as r:
            h = json.loads(r.read())
    q = json.load(open(os.path.join(state, "streams.quarantine.json")))
    now = [s["stream"] for s in json.load(open(os.path.join(state, "streams.json")))]
    t.check(names == ["ok"] and h.get("quarantined") == 2, "the valid stream runs, 2 quarantined in /healthz (%s, %s)"
            % (names, h.get("quarantined")))
    t.check([s["stream"] for s in q] == ["old", "wide"] and all(s.get("reason") for s in q) and q[0]["rev"] == 7,
            "streams.quarantine.json keeps them whole with the reason (%s)" % [s.get("reason") for s in q])
    t.check(now == ["ok"], "streams.json then holds only the valid stream (%s)" % now)
    with Daemon(state_dir=state) as d:  # a second start adds nothing new and loses nothing
        pass
    t.check(len(json.load(open(os.path.join(state, "streams.quarantine.json")))) == 2, "a restart keeps the quarantine")


async def test_stream_events(t):
    """A stream created or destroyed by one connection is announced to the others as an event
    (no id); the requester gets only its reply."""
    a, b = await Client.connect(D), await Client.connect(D)
    r = await a.request("create", effect="energy_wave", stream="evt", params={"width": 32, "height": 32})
    ev = await b.text()
    t.check(r["op"] == "created" and ev == {"op": "created", "stream": "evt", "effect": "energy_wave", "rev": 1},
            "another connection gets the created event, without id (%s)" % ev)
    r = await a.request("destroy", stream="evt")
    ev = await b.text()
    t.check(r["op"] == "destroyed" and ev == {"op": "destroyed", "stream": "evt"},
            "and the destroyed event (%s)" % ev)
    nxt = await a.raw(json.dumps({"op": "list", "id": "after"}))
    t.check(nxt.get("op") == "list" and nxt.get("id") == "after",
            "the requester gets no event of its own change (next message: %s)" % nxt.get("op"))
    await a.close()
    await b.close()


async def test_shutdown_closes_1001(t):
    c = await Client.connect(D)
    D.proc.send_signal(signal.SIGINT)
    try:
        while True:
            await c.recv(timeout=10)
    except websockets.exceptions.ConnectionClosed as e:
        t.check(e.code == 1001, "clients closed with 1001 on shutdown (got %s)" % e.code)
    t.check(D.proc.wait(timeout=10) == 0, "SIGINT exits 0")


async def test_flags(t):
    def run(*args):
        p = subprocess.run([DAEMON, *args], capture_output=True, text=True, timeout=10)
        return p.returncode, p.stdout + p.stderr
    code, out = run("--help")
    t.check(code == 0 and "--state-dir" in out and "--device" in out, "--help documents the flags")
    code, out = run("--bogus")
    t.check(code == 2 and "bogus" in out, "unknown flag is an error")
    code, out = run("--port", "99999")
    t.check(code == 2 and "port" in out, "bad port is an error")
    code, out = run("--device", "banana")
    t.check(code == 2 and "device" in out, "bad device spec is an error")
    code, out = run("--log-level", "loud")
    t.check(code == 2, "bad log level is an error")
    for text, word, what in (('{"port": 1,', "JSON", "malformed config file"),
                             ('{"bogus": 1}', "bogus", "unknown config key (non-string value)"),
                             ('{"listen": 5}', "listen", "config value of the wrong type"),
                             ('{"limits": {"max_streams": 0}}', "max_streams", "config limit out of range"),
                             ('{"port": 7000} {"port": 1}', "trailing data", "config file with trailing data"),
                             ('{"port": 7000, "port": 1}', 'duplicate member "port"', "config file with a duplicate key"),
                             ('{"allowed_hosts": ["studio.local:80"]}', "allowed_hosts", "allowed_hosts with a port"),
                             ('{"allowed_hosts": "studio.local"}', "allowed_hosts: expected an array",
                              "allowed_hosts not an array"),
                             ('{"allowed_origins": [7]}', "allowed_origins: expected strings", "allowed_origins not strings")):
        with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
            f.write(text)
        code, out = run("--config", f.name)
        os.unlink(f.name)
        t.check(code == 2 and word in out, "%s is an error naming it (%s)" % (what, out.strip()))
    code, out = run("--config", "/nonexistent/fxs.json")
    t.check(code == 2 and "cannot open" in out, "missing config file is an error")
    # A state file that is not exactly one JSON value: the daemon refuses to start and leaves it as it is.
    state = tempfile.mkdtemp(prefix="fxs-state-")
    text = '[{"stream":"a","effect":"energy_wave","effect":"flame","rev":1,"params":{}}]'
    with open(os.path.join(state, "streams.json"), "w") as f:
        f.write(text)
    code, out = run("--port", "0", "--state-dir", state)
    t.check(code != 0 and 'duplicate member "effect"' in out and open(os.path.join(state, "streams.json")).read() == text,
            "a state file with a duplicate key stops the start, kept unchanged (%s)" % out.strip()[-120:])


if __name__ == "__main__":
    D = Daemon()
    s = Suite("test_protocol")
    try:
        s.run([test_http, test_metrics_parse, test_static_root, test_websocket_version, test_hello, test_spec_current, test_frames, test_set_reaches_frames, test_error_codes,
               test_invalid_utf8_closes_1007, test_noop_set, test_paused_first_frame, test_nothing_half_applied, test_destroy_and_max_fps, test_max_fps_range, test_persistence, test_rev_64bit, test_state_write_failure, test_presets_persist, test_quarantine, test_stream_events,
               test_shutdown_closes_1001, test_flags])
    finally:
        D.stop(signal.SIGKILL)
