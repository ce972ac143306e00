"""test_limits.py — every configurable limit of PROTOCOL.md §6, hit on a real fxstreamd with
small limits: the `limit` error (with the param the spec names) or the close code that
says why, and the connection or daemon still usable afterwards.
Run from the repository root: /usr/bin/python3 tests/integration/test_limits.py"""
import asyncio
import json
import time

import websockets

from fxtest import Client, Daemon, Suite, config_file

N_BURST = 100
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


if __name__ == "__main__":
    Suite("test_limits").run([test_connections, test_streams_and_subscriptions, test_rate_and_size])
