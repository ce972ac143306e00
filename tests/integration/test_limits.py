"""test_limits.py — every configurable limit of PROTOCOL.md §6, hit on a real fxstreamd with
small limits: the `limit` error (with the param the spec names) or the close code that
says why, and the connection or daemon still usable afterwards.
Run from the repository root: /usr/bin/python3 tests/integration/test_limits.py"""
import asyncio
import json
import os
import resource
import socket
import tempfile
import time
import urllib.request

import websockets

from fxtest import Client, Daemon, Suite, config_file
from rawws import Conn, frame

N_BURST = 100
N_READERS, ASKS = 100, 120
FLOOD = 1150
LIMITS = {"max_connections": 3, "max_streams": 4, "max_subscriptions": 2, "max_control_per_sec": 20,
          "max_message_bytes": 2048}


def small_daemon():
    return Daemon("--config", config_file({"limits": LIMITS}))


async def test_connections(t):
    with small_daemon() as d:
        cs = [await Client.connect(d) for _ in range(3)]
        t.check(all(c.hello["limits"]["max_connections"] == 3 for c in cs), "hello reports max_connections 3")
        ws = await asyncio.wait_for(websockets.connect(d.url, subprotocols=["fxstream.v1"]), 10)
        try:
            await asyncio.wait_for(ws.recv(), 10)
            t.check(False, "a 4th connection is refused")
        except websockets.ConnectionClosed as e:
            t.check(e.code == 1013 and e.reason == "connection limit reached", "a 4th connection: 1013 (%s)" % e.reason)
        await cs[0].close()
        await asyncio.sleep(0.2)
        c = await Client.connect(d)
        t.check(c.hello["op"] == "hello", "a slot freed by a close is usable again")
        for x in cs[1:] + [c]:
            await x.close()


async def test_streams_and_subscriptions(t):
    with small_daemon() as d:
        c = await Client.connect(d)
        t.check((await c.request("create", effect="energy_wave", stream="third"))["op"] == "created",
                "the 4th stream (3 defaults) is created")
        r = await c.request("create", effect="energy_wave", stream="fourth")
        t.check(r["op"] == "error" and r["code"] == "limit" and r.get("param") == "stream", "a 5th stream: limit")
        t.check(len((await c.request("list"))["streams"]) == 4, "nothing half-created")
        for s in ("energy", "flame"):
            await c.request("subscribe", stream=s)
        r = await c.request("subscribe", stream="third")
        t.check(r["code"] == "limit" and r.get("param") == "stream", "a 3rd subscription: limit")
        t.check((await c.request("unsubscribe", stream="flame"))["op"] == "unsubscribed", "unsubscribe frees one")
        t.check((await c.request("subscribe", stream="third"))["op"] == "subscribed", "then the subscription works")
        await c.close()


async def test_rate_and_size(t):
    with small_daemon() as d:
        c = await Client.connect(d)
        # A full bucket of 20 passes, then 20/s: over the window from the first send to the
        # last reply (t) at most 20 + 20 t + 1 pass, however busy the machine is.
        t0 = time.monotonic()
        for i in range(N_BURST):
            await c.ws.send(json.dumps({"op": "list", "id": i}))
        replies = [await c.text() for _ in range(N_BURST)]
        window = time.monotonic() - t0
        limited = [m for m in replies if m["op"] == "error" and m["code"] == "limit"]
        passed = N_BURST - len(limited)
        t.check(20 <= passed <= 20 + 20 * window + 1 and all("id" not in m for m in limited),
                "%d messages at once with 20/s: %d passed in %.2f s (bucket of 20 + 20/s), the %d dropped have "
                "limit and no id" % (N_BURST, passed, window, len(limited)))
        await asyncio.sleep(1.1)
        t.check((await c.request("list"))["op"] == "list", "the bucket refills")
        r = await c.raw(json.dumps({"op": "list", "pad": "x" * 2100}))
        t.check(r["code"] == "limit" and "2048" in r["message"], "a 2100-byte message: limit (%s)" % r["message"])
        t.check((await c.request("list"))["op"] == "list", "the connection stays usable")
        await c.close()


def raw_ws(port, rcvbuf=4096):
    """A WebSocket on a socket with a small receive buffer that this test does not read from."""
    return Conn.connect(port, rcvbuf=rcvbuf)


def rss_kib(d):
    with open("/proc/%d/status" % d.proc.pid) as f:
        return int(f.read().split("VmRSS:")[1].split()[0])


# A rich energy document's sources: 16 curves of 32 weights at full precision (~15 kB of JSON).
RICH_CURVES = [{"p0": [-1.123456789012345 - i, 0.3333333333333333, 0.1428571428571428],
                "p1": [0.7071067811865476, 1.4142135623730951 + i, -0.5772156649015329],
                "p2": [1.618033988749895, -0.6931471805599453, 2.718281828459045 + i],
                "coef": 8.123456789012345, "W": [(k + 1) / 33 for k in range(32)]} for i in range(16)]


def drain_close(c, timeout=20):
    """Reads c to its end; the close frame's code and the last bytes read."""
    s = c.s
    s.settimeout(10)
    tail, deadline = b"", time.monotonic() + timeout
    while time.monotonic() < deadline:  # drain what was sent; the close frame comes last
        try:
            chunk = s.recv(65536)
        except OSError:
            break
        if not chunk:
            break
        tail = (tail + chunk)[-64:]
    i = tail.rfind(b"\x88")
    return (int.from_bytes(tail[i + 2:i + 4], "big") if i >= 0 and len(tail) >= i + 4 else None), tail


async def test_queued_bytes(t):
    """Replies a client does not read are bounded in bytes: describe replies (~11 kB) asked for
    at the allowed rate by readers that never read. Its requests are not read while its replies
    wait, and each one is answered once it reads."""
    # stall_timeout_s 60: sending 12,000 requests can take longer than the default 10 s on a
    # loaded host, and a reader whose socket is full that long is closed for not reading (no
    # close frame fits), which is another limit than the one checked here.
    limits = {"max_queued_bytes": 65536, "max_control_per_sec": 1000, "stall_timeout_s": 60}
    with Daemon("--config", config_file({"limits": limits})) as d:
        rss0 = rss_kib(d)
        conns = [raw_ws(d.port) for _ in range(N_READERS)]
        for _ in range(ASKS):
            for c in conns:
                c.send(frame('{"op":"describe","effect":"energy_wave"}'))
        await asyncio.sleep(1.0)
        grown = rss_kib(d) - rss0
        bound = N_READERS * (65536 + 512 * 1024) // 1024  # the queue limit plus socket buffers, per reader
        t.check(grown < bound, "%d readers that never read asked for %d x 11 kB each: RSS +%d KiB (bound %d KiB)"
                % (N_READERS, ASKS, grown, bound))
        c = conns[0]
        c.read_text()  # hello
        got = [json.loads(c.read_text())["op"] for _ in range(ASKS)]
        t.check(got == ["describe"] * ASKS, "once it reads, it gets every one of its %d replies (%d)" % (ASKS, len(got)))
        c.send(frame('{"op":"list","id":1}'))
        t.check(json.loads(c.read_text())["op"] == "list", "and the connection is served on")
        for x in conns:
            x.close()
        t.check(d.proc.poll() is None, "the daemon runs on")


async def test_events_not_read(t):
    """Events a client does not read (another client's sets of a stream it watches, ~15 kB each,
    more than the socket's buffers take) are bounded: more than max_queued_bytes of them close it
    with 1008."""
    limits = {"max_queued_bytes": 65536, "max_control_per_sec": 1000, "stall_timeout_s": 60}
    with Daemon("--config", config_file({"limits": limits})) as d:
        a = await Client.connect(d)
        r = await a.request("create", effect="energy_wave", stream="tiny", params={"width": 32, "height": 32, "curves": RICH_CURVES})
        reader = raw_ws(d.port)
        reader.send(frame('{"op":"subscribe","stream":"tiny"}'))
        t.check(r["op"] == "created" and json.loads(reader.read_text())["op"] == "hello" and
                json.loads(reader.read_text())["op"] == "subscribed", "the reader subscribes, then reads no more")
        for i in range(600):
            await a.request("set", stream="tiny", params={"alpha": 1 + i / 1000})
        code, tail = drain_close(reader)
        t.check(code == 1008 and b"messages not read" in tail, "the reader was closed with 1008 (%s, %r)" % (code, tail[-24:]))
        t.check((await a.request("list"))["op"] == "list", "the other client is served on")
        await a.close()
        reader.close()


async def test_large_reply(t):
    """A reply larger than max_queued_bytes is delivered to a client that reads it: 64 presets of
    a rich energy document (presets.json ~600 kB) must not close the page's connection with
    1008. Two such replies asked for at once both come."""
    state = tempfile.mkdtemp(prefix="fxs-state-")
    with Daemon(state_dir=state) as d:
        c = await Client.connect(d)
        builtins = len((await c.request("presets")).get("presets", []))
        r = await c.request("set", stream="energy", params={"curves": RICH_CURVES})
        t.check(r["op"] == "params", "a rich energy document is set (%s)" % r.get("message"))
        for i in range(64):
            r = await c.request("preset_save", stream="energy", name="rich-%02d" % i, doc="sixteen curves, 32 weights")
        t.check(r["op"] == "preset_saved", "64 presets saved (%s)" % r.get("message"))
        r = await c.request("preset_save", stream="energy", name="one-more")
        t.check(r.get("code") == "limit", "a 65th is refused: limit (%s)" % r.get("code"))
        size = os.path.getsize(os.path.join(state, "presets.json"))
        ids = []
        for i in (1, 2):  # both requests in one go
            await c.ws.send(json.dumps({"op": "presets", "id": 100 + i}))
        for _ in (1, 2):
            m = await c.recv(timeout=20)
            ids.append((json.loads(m).get("id"), len(m), len(json.loads(m).get("presets", []))))
        t.check([x[0] for x in ids] == [101, 102] and all(x[1] > 262144 and x[2] == 64 + builtins for x in ids),
                "presets.json of %d kB: both presets replies arrive whole (%s)" % (size // 1024, ids))
        await c.close()


async def test_half_open_flood(t):
    """A bounded flood of half-open handshakes (1150 sockets that send a partial GET and are
    reopened when dropped, for 12 s) does not lock out new sessions or /healthz: pending
    connections are capped at 128, the oldest dropped, each given 3 s at most."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    resource.setrlimit(resource.RLIMIT_NOFILE, (min(hard, 4096), hard))
    with Daemon() as d:
        def opener():
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.setblocking(False)
            try:
                s.connect(("127.0.0.1", d.port))
            except BlockingIOError:
                pass
            return s
        socks, sent = [opener() for _ in range(FLOOD)], set()
        ok = hz = probes = 0
        end, next_probe = time.monotonic() + 12, time.monotonic() + 1
        while time.monotonic() < end:
            for i, s in enumerate(socks):
                try:
                    if i not in sent:
                        s.send(b"GET /v1/ws HTTP/1.1\r\nHost: 127.0.0.1\r\n")  # and never the rest
                        sent.add(i)
                    elif s.recv(1, socket.MSG_PEEK) == b"":
                        raise ConnectionResetError
                except BlockingIOError:
                    pass
                except OSError:  # dropped by the daemon: the attacker reopens it
                    s.close()
                    socks[i] = opener()
                    sent.discard(i)
            if time.monotonic() >= next_probe:
                next_probe += 1
                probes += 1
                try:
                    c = await Client.connect(d, timeout=2)
                    ok += (await c.request("list", timeout=2))["op"] == "list"
                    await c.close()
                except Exception:
                    pass
                try:
                    with urllib.request.urlopen(d.http + "/healthz", timeout=2) as r:
                        hz += r.status == 200
                except Exception:
                    pass
            await asyncio.sleep(0.05)
        for s in socks:
            s.close()
        evicted = metric(d, "fxs_handshakes_evicted_total")
        t.check(probes >= 8 and ok >= 0.75 * probes and hz >= 0.75 * probes,
                "under %d half-open handshakes: %d of %d new sessions and %d of %d /healthz served (%s evicted)"
                % (FLOOD, ok, probes, hz, probes, evicted))
        t.check(d.proc.poll() is None, "the daemon runs on")
    resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


def metric(d, name):
    with urllib.request.urlopen(d.http + "/metrics", timeout=10) as r:
        for line in r.read().decode().splitlines():
            if line.startswith(name + " "):
                return float(line.split()[1])
    return None


if __name__ == "__main__":
    Suite("test_limits").run([test_connections, test_streams_and_subscriptions, test_rate_and_size, test_queued_bytes,
                              test_events_not_read, test_large_reply, test_half_open_flood])
