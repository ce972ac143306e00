"""test_schemas.py — protocol/schemas/*.json against a real fxstreamd.

Every control message the daemon sends in a session that performs every op (and makes
each error code happen) is validated against its schema and against server.json (one
named check each); every request this suite sends is first validated against its
request schema and request.json; deliberately invalid requests (unknown field, wrong
types, bad values) must be rejected by the request schemas, and by the daemon too.
Run from the repository root: /usr/bin/python3 tests/integration/test_schemas.py"""
import asyncio
import glob
import json
import os
import signal
import tempfile
import time

import jsonschema
import websockets

from fxtest import ROOT, Client, Daemon, Suite

SCHEMA_DIR = os.path.join(ROOT, "protocol", "schemas")
SMALL = {"width": 32, "height": 16, "fps": 30}
D = None
SCHEMAS = {}   # file name -> schema
STORE = {}     # $id -> schema


def load_schemas():
    for path in sorted(glob.glob(os.path.join(SCHEMA_DIR, "*.json"))):
        with open(path) as f:
            s = json.load(f)
        SCHEMAS[os.path.basename(path)] = s
        STORE[s["$id"]] = s


def validator(name):
    s = SCHEMAS[name]
    cls = jsonschema.validators.validator_for(s)
    return cls(s, resolver=jsonschema.RefResolver.from_schema(s, store=STORE))


def errors(name, msg):
    """The validation error messages of msg against schema file name ([] when valid)."""
    return [e.message for e in validator(name).iter_errors(msg)]


def param_schema(d):
    """A JSON Schema for one parameter value, built from its describe descriptor (PROTOCOL.md §9)."""
    t = d["type"]
    num = {"type": "integer" if t == "int" else "number"}
    if "min" in d:
        num.update(minimum=d["min"], maximum=d["max"])
    if d.get("even"):
        num["multipleOf"] = 2
    if t in ("float", "int"):
        return num
    if t == "bool":
        return {"type": "boolean"}
    if t == "enum":
        return {"enum": d["choices"]}
    if t in ("vec3", "color"):
        return {"type": "array", "items": num, "minItems": 3, "maxItems": 3}
    if t == "float_list":
        return {"type": "array", "items": num, "minItems": d["min_len"], "maxItems": d["max_len"]}
    item = params_doc_schema(d["fields"])
    return {"type": "array", "items": item, "minItems": d["min_len"], "maxItems": d["max_len"]}


def params_doc_schema(descriptors):
    """A complete parameter document: every described parameter, nothing else."""
    return {"type": "object", "required": [d["name"] for d in descriptors],
            "properties": {d["name"]: param_schema(d) for d in descriptors}, "additionalProperties": False}


def server_schema(m):
    """The schema file for a message received from the server."""
    op = m.get("op")
    if op == "hello":
        return "event.hello.json"
    if op == "error":
        return "event.error.json" if "stream" in m else "reply.error.json"
    if op == "unsubscribed":
        return "event.unsubscribed.json" if "reason" in m else "reply.unsubscribed.json"
    if op in ("params", "created", "destroyed", "preset_saved", "preset_deleted"):  # this suite always sends ids: without one it is an event
        return ("reply.%s.json" if "id" in m else "event.%s.json") % op
    return "reply.%s.json" % op


def check_server_msg(t, m, what):
    """Two named checks: m is valid per its own schema and per server.json."""
    name = server_schema(m)
    if name not in SCHEMAS:
        return t.check(False, "%s: no schema for server message op %r" % (what, m.get("op")))
    e = errors(name, m)
    ok = t.check(not e, "%s valid per %s%s" % (what, name, "" if not e else ": %s in %s" % (e[:2], json.dumps(m)[:300])))
    e2 = errors("server.json", m)
    t.check(not e2, "%s valid per server.json" % what)
    return ok


def check_request(t, req, what):
    """Two named checks: req is valid per request.<op>.json and request.json."""
    name = "request.%s.json" % req.get("op")
    e = errors(name, req) if name in SCHEMAS else ["no schema " + name]
    t.check(not e, "request %s valid per %s%s" % (what, name, "" if not e else ": %s" % e[:2]))
    e2 = errors("request.json", req)
    t.check(not e2, "request %s valid per request.json" % what)


class Rec(Client):
    """A Client whose every text message received is validated; requests are validated before sending."""

    def __init__(self, ws):
        super().__init__(ws)
        self.t = None
        self.label = "client"
        self.frames = []

    @classmethod
    async def open(cls, t, daemon, label):
        c = await cls.connect(daemon)
        c.t, c.label = t, label
        check_server_msg(t, c.hello, "%s: hello" % label)
        return c

    async def text(self, timeout=10):
        deadline = time.monotonic() + timeout
        while True:
            m = await self.recv(max(0.01, deadline - time.monotonic()))
            if isinstance(m, bytes):
                self.frames.append(m)
                continue
            m = json.loads(m)
            if self.t:
                check_server_msg(self.t, m, "%s: %s%s" % (self.label, m.get("op"), " (id %s)" % m["id"] if "id" in m else ""))
            return m

    async def req(self, op, what=None, **fields):
        """A valid request (checked against the schemas) with a fresh id; returns its reply."""
        msg = dict(op=op, id=self.next_id, **fields)
        check_request(self.t, msg, what or op)
        return await self.request(op, **fields)

    async def send_raw(self, text):
        """Sends text as is and returns the next text message (validated by text())."""
        return await self.raw(text)


async def test_schema_files(t):
    t.check(len(SCHEMAS) >= 25, "schema files found (%d)" % len(SCHEMAS))
    for name, s in sorted(SCHEMAS.items()):
        try:
            jsonschema.validators.validator_for(s).check_schema(s)
            ok = s["$id"].endswith("/" + name)
        except jsonschema.exceptions.SchemaError as e:
            ok = False
            print("  ", e.message)
        t.check(ok, "%s is a valid JSON Schema with a matching $id" % name)
    for name, s in SCHEMAS.items():
        if name.startswith("request.") and name != "request.json":
            t.check(s.get("additionalProperties") is False, "%s is strict (additionalProperties false)" % name)


async def test_session(t):
    a = await Rec.open(t, D, "A")
    b = await Rec.open(t, D, "B")
    r = await a.req("list")
    t.check(r["op"] == "list" and any(s["stream"] == "energy" for s in r["streams"]), "list has the default stream")
    r = await a.req("describe", effect="energy_wave")
    t.check(r["op"] == "describe" and r["params"], "describe energy_wave")
    names = [p["name"] for p in r["params"]]
    g = await a.req("get", stream="energy")
    t.check(g["op"] == "params" and sorted(g["params"]) == sorted(names), "get returns every described parameter")
    doc_schema = params_doc_schema(r["params"])
    e = list(jsonschema.Draft202012Validator(doc_schema).iter_errors(g["params"]))
    t.check(not e, "the complete document matches its describe descriptors%s" % ("" if not e else ": " + e[0].message))
    for d in r["params"]:
        e = list(jsonschema.Draft202012Validator(param_schema(d)).iter_errors(d["default"]))
        t.check(not e, "describe default of %s is valid per its own descriptor" % d["name"])
    r = await a.req("create", effect="energy_wave", stream="sch.a", params=SMALL)
    t.check(r["op"] == "created" and r["rev"] == 1, "create")
    r = await a.req("create", "create without params", effect="energy_wave", stream="sch-b")
    t.check(r["op"] == "created", "create without params")
    r = await b.req("subscribe", stream="sch.a", max_fps=60)
    t.check(r["op"] == "subscribed", "B subscribes with max_fps")
    r = await a.req("subscribe", stream="sch.a")
    t.check(r["op"] == "subscribed" and r["channel"] >= 1, "A subscribes")
    r = await a.req("subscribe", "subscribe again", stream="sch.a", max_fps=1000)
    t.check(r["op"] == "subscribed", "subscribing again only changes max_fps")
    r = await a.req("subscribe", "subscribe with a particle budget", stream="sch.a", max_particles=25000)
    t.check(r["op"] == "subscribed" and r.get("max_particles") == 20000, "a budget: the step served in the reply")
    r = await a.req("subscribe", "subscribe again without the budget", stream="sch.a")
    t.check(r["op"] == "subscribed" and "max_particles" not in r, "without it: no max_particles in the reply")
    r = await a.req("set", stream="sch.a", params={"alpha": 2.0, "curves": []})
    t.check(r["op"] == "params" and r["rev"] == 2 and r["params"]["curves"] == [], "set replies params rev 2")
    ev = await b.text()
    t.check(ev["op"] == "params" and "id" not in ev and ev["rev"] == 2, "B gets the params broadcast")
    r = await a.req("set", "set with empty params", stream="sch.a", params={})
    t.check(r["op"] == "params" and r["rev"] == 2, "an empty set is accepted and, changing nothing, keeps rev 2")
    r = await a.req("set", "set of a new value", stream="sch.a", params={"alpha": 3.0})
    t.check(r["op"] == "params" and r["rev"] == 3, "a set that changes a value takes rev 3")
    ev = await b.text()
    t.check(ev["op"] == "params" and ev["rev"] == 3, "B gets the second broadcast, of that set only")
    r2 = await a.raw(json.dumps({"op": "get", "id": "str-1", "stream": "sch.a"}))
    t.check(r2.get("id") == "str-1", "a string id is echoed")
    r = await a.req("reset", stream="sch.a")
    t.check(r["op"] == "reset", "reset")
    r = await a.req("unsubscribe", stream="sch.a")
    t.check(r["op"] == "unsubscribed" and "reason" not in r, "unsubscribe reply")
    r = await a.req("destroy", stream="sch.a")
    t.check(r["op"] == "destroyed", "destroy")
    ev = await b.text()
    t.check(ev["op"] == "unsubscribed" and ev.get("reason") == "destroyed", "B told of destroy")
    r = await a.req("destroy", "destroy second stream", stream="sch-b")
    t.check(r["op"] == "destroyed", "destroy second stream")
    # no id at all: the reply carries none
    m = await a.raw('{"op":"list"}')
    t.check(m["op"] == "list" and "id" not in m, "a reply to a request without id has no id")
    t.check(not errors("request.list.json", {"op": "list"}), "request without id valid per request.list.json")
    await a.close()
    await b.close()


# (request or raw text, expected code, what); requests that are valid per the schemas
# but fail on the server's state.
VALID_BUT_FAILING = [
    ({"op": "describe", "effect": "smoke"}, "unknown_effect", "unknown effect"),
    ({"op": "create", "effect": "smoke", "stream": "x1"}, "unknown_effect", "create with unknown effect"),
    ({"op": "create", "effect": "energy_wave", "stream": "energy"}, "exists", "create an existing stream"),
    ({"op": "get", "stream": "ghost"}, "unknown_stream", "get unknown stream"),
    ({"op": "set", "stream": "ghost", "params": {}}, "unknown_stream", "set unknown stream"),
    ({"op": "subscribe", "stream": "ghost"}, "unknown_stream", "subscribe unknown stream"),
    ({"op": "unsubscribe", "stream": "ghost"}, "unknown_stream", "unsubscribe unknown stream"),
    ({"op": "destroy", "stream": "ghost"}, "unknown_stream", "destroy unknown stream"),
    ({"op": "reset", "stream": "ghost"}, "unknown_stream", "reset unknown stream"),
    ({"op": "unsubscribe", "stream": "energy"}, "bad_request", "unsubscribe while not subscribed"),
    ({"op": "set", "stream": "energy", "params": {"divisions": 7}}, "bad_param", "odd divisions"),
    ({"op": "set", "stream": "energy", "params": {"fps": 1000}}, "bad_param", "out of range"),
    ({"op": "set", "stream": "energy", "params": {"colour": 1}}, "bad_param", "unknown parameter"),
    ({"op": "set", "stream": "energy", "params": {"eye": [1, 2, 3], "center": [1, 2, 3]}}, "bad_param",
     "cross-field rule (eye = center)"),
    ({"op": "set", "stream": "energy", "params": {"curves": [{"W": [1, 1, 2]}]}}, "bad_param", "list item element"),
    ({"op": "create", "effect": "energy_wave", "stream": "x2", "params": {"mode": "euler"}}, "bad_param",
     "create with a bad enum"),
    ({"op": "presets", "effect": "smoke"}, "unknown_effect", "presets of an unknown effect"),
    ({"op": "preset_load", "stream": "energy", "name": "nope"}, "unknown_preset", "load an unknown preset"),
    ({"op": "preset_load", "stream": "ghost", "name": "thesis-fig5.1"}, "unknown_stream", "load into an unknown stream"),
    ({"op": "preset_save", "stream": "energy", "name": "thesis-fig5.1"}, "read_only", "save over a built-in"),
    ({"op": "preset_delete", "effect": "energy_wave", "name": "thesis-fig5.1"}, "read_only", "delete a built-in"),
    ({"op": "preset_delete", "effect": "energy_wave", "name": "nope"}, "unknown_preset", "delete an unknown preset"),
]

# Requests the schemas must reject, and the server too (bad_request unless said otherwise).
INVALID = [
    ({"op": "list", "stream": 1}, "bad_request", "unknown field"),
    ({"op": "get", "stream": "energy", "extra": True}, "bad_request", "unknown field on get"),
    ({"op": "list", "id": None}, "bad_request", "null id"),
    ({"op": "list", "id": {"a": 1}}, "bad_request", "object id"),
    ({"op": "list", "id": [1]}, "bad_request", "array id"),
    ({"id": 5}, "bad_request", "missing op"),
    ({"op": 5}, "bad_request", "op not a string"),
    ({"op": "warp"}, "unknown_op", "unknown op"),
    ({"op": "describe"}, "bad_request", "describe without effect"),
    ({"op": "describe", "effect": 3}, "bad_request", "effect not a string"),
    ({"op": "create", "stream": "x3"}, "bad_request", "create without effect"),
    ({"op": "create", "effect": "energy_wave"}, "bad_request", "create without stream"),
    ({"op": "create", "effect": "energy_wave", "stream": "bad name"}, "bad_request", "stream name with a space"),
    ({"op": "create", "effect": "energy_wave", "stream": ""}, "bad_request", "empty stream name"),
    ({"op": "create", "effect": "energy_wave", "stream": "x" * 64}, "bad_request", "64-character stream name"),
    ({"op": "create", "effect": "energy_wave", "stream": "x4", "params": [1]}, "bad_request", "create params not an object"),
    ({"op": "get", "stream": 7}, "bad_request", "stream not a string"),
    ({"op": "set", "stream": "energy"}, "bad_request", "set without params"),
    ({"op": "set", "stream": "energy", "params": "alpha=2"}, "bad_request", "set params not an object"),
    ({"op": "subscribe", "stream": "energy", "max_fps": 0}, "bad_request", "max_fps 0"),
    ({"op": "subscribe", "stream": "energy", "max_fps": 1001}, "bad_request", "max_fps above 1000"),
    ({"op": "subscribe", "stream": "energy", "max_fps": 1e-14}, "bad_request", "max_fps below 0.01"),
    ({"op": "subscribe", "stream": "energy", "max_fps": 5e-324}, "bad_request", "max_fps denormal"),
    ({"op": "subscribe", "stream": "energy", "max_fps": "30"}, "bad_request", "max_fps a string"),
    ({"op": "subscribe"}, "bad_request", "subscribe without stream"),
    ({"op": "reset", "stream": ["energy"]}, "bad_request", "stream an array"),
    ({"op": "destroy", "stream": "energy", "force": True}, "bad_request", "unknown field on destroy"),
    ({"op": "presets", "effect": 1}, "bad_request", "presets effect not a string"),
    ({"op": "preset_save", "stream": "energy"}, "bad_request", "preset_save without name"),
    ({"op": "preset_save", "stream": "energy", "name": "a b"}, "bad_request", "preset name with a space"),
    ({"op": "preset_save", "stream": "energy", "name": "ok", "doc": 5}, "bad_request", "preset doc not a string"),
    ({"op": "preset_save", "stream": "energy", "name": "ok", "doc": "d" * 201}, "bad_request", "preset doc too long"),
    ({"op": "preset_load", "stream": "energy"}, "bad_request", "preset_load without name"),
    ({"op": "preset_load", "stream": "energy", "name": "x", "params": {}}, "bad_request", "unknown field on preset_load"),
    ({"op": "preset_delete", "name": "x"}, "bad_request", "preset_delete without effect"),
]


async def test_presets(t):
    """Every preset reply and event, valid per its schema: list, load (params to the requester and
    the broadcast to a subscriber), save (and the event to another connection), delete."""
    a = await Rec.open(t, D, "P")
    b = await Rec.open(t, D, "Q")
    r = await a.req("presets", "presets of all effects")
    effects = {p["effect"] for p in r["presets"]}
    t.check(effects == {"energy_wave", "flame", "compound_eye"} and all(p["builtin"] for p in r["presets"]),
            "built-in presets of every effect (%s)" % sorted(effects))
    r = await a.req("presets", effect="energy_wave")
    t.check({p["effect"] for p in r["presets"]} == {"energy_wave"}, "presets of one effect")
    await a.req("create", effect="energy_wave", stream="sch.p", params=SMALL)
    await b.req("subscribe", stream="sch.p")
    r = await a.req("preset_load", stream="sch.p", name="thesis-fig5.2")
    t.check(r["op"] == "params" and r["rev"] == 2 and r["params"]["tori"][0]["R"] == 3.0,
            "preset_load replies params with the preset's values")
    ev = await b.text()
    t.check(ev["op"] == "params" and "id" not in ev and ev["rev"] == 2, "the subscriber gets the params broadcast")
    r = await a.req("preset_save", stream="sch.p", name="sch-look", doc="a test look")
    t.check(r["op"] == "preset_saved" and r["replaced"] is False, "preset_save")
    ev = await b.text()
    t.check(ev["op"] == "preset_saved" and "id" not in ev and ev["name"] == "sch-look", "others get preset_saved")
    r = await a.req("preset_delete", effect="energy_wave", name="sch-look")
    t.check(r["op"] == "preset_deleted", "preset_delete")
    ev = await b.text()
    t.check(ev["op"] == "preset_deleted" and "id" not in ev, "others get preset_deleted")
    await a.req("destroy", stream="sch.p")
    await a.close()
    await b.close()


async def test_errors(t):
    c = await Rec.open(t, D, "E")
    n = 100
    for req, code, what in VALID_BUT_FAILING:
        req = dict(req, id=n)
        n += 1
        check_request(t, req, what)
        m = await c.send_raw(json.dumps(req))
        t.check(m["op"] == "error" and m["code"] == code and m.get("id") == req["id"],
                "%s -> %s with id echoed (got %s)" % (what, code, m.get("code")))
    for req, code, what in INVALID:
        e = errors("request.json", req)
        e2 = errors("request.%s.json" % req["op"], req) if isinstance(req.get("op"), str) and \
            "request.%s.json" % req["op"] in SCHEMAS else ["no such op"]
        t.check(bool(e) and bool(e2), "schemas reject %s" % what)
        m = await c.send_raw(json.dumps(req))
        t.check(m["op"] == "error" and m["code"] == code, "server rejects %s -> %s (got %s)" % (what, code, m.get("code")))
    # error codes that arise before a request is parsed: no id in the reply
    m = await c.send_raw('{"op":"list","id":1')
    t.check(m["code"] == "bad_json" and "id" not in m, "malformed JSON -> bad_json without id")
    m = await c.send_raw("[" * 40 + "]" * 40)
    t.check(m["code"] == "bad_json", "nesting deeper than max_json_depth -> bad_json")
    m = await c.send_raw('["list"]')
    t.check(m["code"] == "bad_request" and "param" not in m, "non-object message -> bad_request")
    big = json.dumps({"op": "list", "id": 1, "pad": "x" * (c.hello["limits"]["max_message_bytes"] + 10)})
    m = await c.send_raw(big)
    t.check(m["code"] == "limit" and "id" not in m, "oversized message -> limit without id")
    await c.ws.send(b"\x00\x01\x02")
    m = await c.text()
    t.check(m["op"] == "error" and m["code"] == "bad_request", "binary message -> bad_request")
    m = await c.raw('{"op":"list","id":"after"}')
    t.check(m.get("id") == "after" and m["op"] == "list", "connection usable after every error")
    await c.close()


async def test_frames(t):
    """The `subscribed` channel is the channel of every frame of that stream."""
    c = await Rec.open(t, D, "F")
    await c.req("create", effect="energy_wave", stream="sch.frames", params=SMALL)
    r = await c.req("subscribe", stream="sch.frames")
    deadline = time.monotonic() + 20
    while not c.frames and time.monotonic() < deadline:
        m = await c.recv(max(0.01, deadline - time.monotonic()))
        if isinstance(m, bytes):
            c.frames.append(m)
        else:
            check_server_msg(t, json.loads(m), "F: message while waiting for a frame")
    f = c.frames[0] if c.frames else b""
    t.check(len(f) >= 64 and f[:4] == b"FXS1", "a frame arrives")
    t.check(len(f) >= 64 and int.from_bytes(f[8:12], "little") == r["channel"], "frame channel = subscribed channel")
    await c.req("destroy", stream="sch.frames")
    await c.close()


async def test_limits(t):
    """A daemon with small limits: limit errors, the rate limit and the connection limit (1013)."""
    cfg = tempfile.NamedTemporaryFile("w", suffix=".json", delete=False)
    json.dump({"limits": {"max_connections": 3, "max_streams": 2, "max_subscriptions": 1,
                          "max_control_per_sec": 10},
               "streams": [{"stream": "energy", "effect": "energy_wave", "params": SMALL}]}, cfg)
    cfg.close()
    d = Daemon("--config", cfg.name)
    try:
        a = await Rec.open(t, d, "L")
        t.check(a.hello["limits"]["max_streams"] == 2 and a.hello["limits"]["max_control_per_sec"] == 10,
                "hello reports the configured limits")
        r = await a.req("create", effect="energy_wave", stream="two", params=SMALL)
        t.check(r["op"] == "created", "create up to max_streams")
        r = await a.req("create", "create beyond max_streams", effect="energy_wave", stream="three")
        t.check(r["op"] == "error" and r["code"] == "limit" and r.get("param") == "stream", "max_streams -> limit")
        r = await a.req("subscribe", stream="two")
        r = await a.req("subscribe", "subscribe beyond max_subscriptions", stream="energy")
        t.check(r["op"] == "error" and r["code"] == "limit", "max_subscriptions -> limit")
        b = await Rec.open(t, d, "L2")
        await asyncio.sleep(1.1)  # a full token bucket
        for i in range(15):
            await b.ws.send(json.dumps({"op": "list", "id": 1000 + i}))
        got = [await b.text() for _ in range(15)]
        limited = [m for m in got if m["op"] == "error"]
        t.check(limited and all(m["code"] == "limit" and "id" not in m for m in limited),
                "more than max_control_per_sec -> limit without id (%d of 15)" % len(limited))
        c3 = await Rec.open(t, d, "L3")
        try:
            ws = await asyncio.wait_for(websockets.connect(d.url, subprotocols=["fxstream.v1"]), 10)
            m = await asyncio.wait_for(ws.recv(), 10)
            t.check(False, "connection beyond max_connections refused (got %r)" % m[:80])
        except websockets.exceptions.ConnectionClosed as e:
            t.check(e.code == 1013, "connection beyond max_connections closed with 1013 (got %s)" % e.code)
        await c3.close()
        await b.close()
        await a.close()
    finally:
        d.stop(signal.SIGKILL)
        os.unlink(cfg.name)


async def test_stream_error_event(t):
    """A stream failure event cannot be provoked through the protocol with valid parameters,
    so the schema is checked against the exact shape session_poll_errors builds."""
    ev = {"op": "error", "code": "internal", "stream": "energy", "message": "energy_wave rendered a non-finite value"}
    t.check(not errors("event.error.json", ev) and not errors("server.json", ev), "stream error event shape valid")
    t.check(errors("event.error.json", dict(ev, id=1)) != [], "stream error event with an id rejected")
    t.check(errors("reply.error.json", dict(ev, code="nope")) != [], "unknown error code rejected")


if __name__ == "__main__":
    load_schemas()
    D = Daemon()
    s = Suite("test_schemas")
    try:
        s.run([test_schema_files, test_session, test_presets, test_errors, test_frames, test_limits, test_stream_error_event],
              timeout=40)
    finally:
        D.stop(signal.SIGKILL)
