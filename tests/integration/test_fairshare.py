"""test_fairshare.py — streams share the engine (engine.c's scheduling): a default energy_wave
stream keeps at least 80% of its rate beside a stream whose every frame takes seconds (a
2048^2 texture), both rates measured the same way in alternating phases of one run; the heavy
stream still gets some of the engine, and /metrics shows each stream's configured and achieved
fps and engine time. A `set` reaches a stream in the middle of a long step (a 64x64x8 lens
table) within a second, and after a `destroy` the daemon stops computing within a second. A
subscriber of an encoding nobody took gets the latest frame at once while the next one is being
computed in slices, and that frame is the one the other encoding carried, texel for texel."""
import asyncio
import ctypes
import json
import os
import re
import struct
import time
import urllib.request

import numpy as np

from fxtest import ROOT, Client, Daemon, Suite, config_file, cpu_seconds

HEAVY_WAVE = {"width": 2048, "height": 2048}  # ~64 x the default's work per frame
HEAVY_TABLE = {"lut_cells": 64, "lut_dirs": 64, "lut_supersample": 8}  # ~1e9 rays: tens of seconds
SMALL_TABLE = {"lut_cells": 8, "lut_dirs": 8, "lut_supersample": 1}
# A pulse running along a curve: every frame a different picture; EXR uncompressed (exr_halves).
# Simpson's rule (~10x adaptive's work) keeps its steps seconds long on a fast kernel, so a
# subscription made during one lands between its slices, not at its end.
HEAVY_PULSE = dict(HEAVY_WAVE, tori=[], size=20.4, compression="none", mode="simpson", curves=[
    {"p0": [-13.2, -4.2, 1.8], "p1": [-6.6, 9.0, -1.8], "p2": [0, 0, 0], "coef": 8.0}])
# Alternating phases of a second, so that the machine's other load, which changes over seconds,
# hits both alike; at least MIN_ROUNDS, more (up to MAX_ROUNDS) until each has MIN_FRAMES.
PHASE_S, MIN_ROUNDS, MAX_ROUNDS, MIN_FRAMES = 1.0, 20, 40, 250


def metrics(d):
    return urllib.request.urlopen(d.http + "/metrics", timeout=10).read().decode()


def per_stream(text, name):
    """{stream: value} of a per-stream metric."""
    return {m.group(1): float(m.group(2))
            for m in re.finditer(r'^%s\{stream="([^"]+)"[^}]*\} (\S+)$' % name, text, re.M)}


class Counter:
    """Frames of the subscribed texture stream over phases of wall time: each frame that arrives
    during a phase adds how far its seq moved on (frames skipped in delivery count too)."""

    def __init__(self, c, seq):
        self.c, self.seq = c, seq

    async def phase(self, seconds, into):
        """Reads for `seconds`, adding [frames, seconds] into `into`."""
        t0 = time.monotonic()
        end = t0 + seconds
        while time.monotonic() < end:
            try:
                f = await self.c.frame(max(0.01, end - time.monotonic()), kind=2)
            except asyncio.TimeoutError:
                break
            into[0] += f["seq"] - self.seq
            self.seq = f["seq"]
        into[1] += time.monotonic() - t0


async def test_heavy_beside_default(t):
    with Daemon("--config", config_file({"streams": []})) as d:
        c, h = await Client.connect(d), await Client.connect(d)
        r = await c.request("create", effect="energy_wave", stream="light")
        t.check(r["op"] == "created", "create a default energy_wave stream")
        r = await h.request("create", effect="energy_wave", stream="heavy", params=HEAVY_WAVE)
        t.check(r["op"] == "created", "create a 2048^2 energy_wave stream")
        await c.request("subscribe", stream="light")
        light = Counter(c, (await c.frame(60, kind=2))["seq"])  # the kernel is built
        # The heavy stream computes while it has a subscriber (pause_idle) and, paused, keeps its
        # frame in progress: each phase beside it sees a stream in the middle of a long frame.
        # First it shows that its frames are long (more than a second of engine time so far).
        await h.request("subscribe", stream="heavy")
        t0, warm = time.monotonic(), 0
        while time.monotonic() - t0 < 15 and warm < 1.2:
            await asyncio.sleep(0.2)
            warm = per_stream(metrics(d), "fxs_stream_engine_seconds_total").get("heavy", 0)
        await light.phase(0.5, [0, 0.0])  # the frames of the warm-up count nowhere
        alone, beside = [0, 0.0], [0, 0.0]
        rounds = 0
        while rounds < MIN_ROUNDS or (rounds < MAX_ROUNDS and min(alone[0], beside[0]) < MIN_FRAMES):
            await h.request("unsubscribe", stream="heavy")
            await light.phase(PHASE_S, alone)
            await h.request("subscribe", stream="heavy")
            await light.phase(PHASE_S, beside)
            rounds += 1
        rate_alone, rate_beside = alone[0] / alone[1], beside[0] / beside[1]
        t.check(alone[0] >= 50, "enough frames alone (%d in %d rounds)" % (alone[0], rounds))
        t.check(rate_beside >= 0.8 * rate_alone,
                "the default stream keeps >= 80%% of its rate beside the heavy one: %.1f fps (%d frames) vs "
                "%.1f alone (%d frames), %.0f%%" % (rate_beside, beside[0], rate_alone, alone[0],
                                                     100 * rate_beside / rate_alone))
        m = metrics(d)
        fps, achieved = per_stream(m, "fxs_stream_fps"), per_stream(m, "fxs_stream_achieved_fps")
        engine, share = per_stream(m, "fxs_stream_engine_seconds_total"), per_stream(m, "fxs_stream_engine_share")
        heavy_s = engine.get("heavy", 0) - warm
        t.check(heavy_s >= 0.01 * beside[1],
                "the heavy stream is not starved: %.2f engine seconds in the %.0f s beside" % (heavy_s, beside[1]))
        t.check(fps.get("light") == 30 and fps.get("heavy") == 30, "/metrics: configured fps of each stream")
        t.check(0 < achieved.get("light", 0) <= 31 and achieved.get("heavy", 99) < 30,
                "/metrics: achieved fps, the heavy stream below its fps (light %s, heavy %s)"
                % (achieved.get("light"), achieved.get("heavy")))
        # Shares of one engine thread: how they split depends on the light stream's cost (the
        # heavy one takes what that leaves), each published at its own time.
        t.check(engine.get("light", 0) > 0 and share.get("light", 0) > 0 and share.get("heavy", 0) > 0
                and share["light"] + share["heavy"] <= 1.1,
                "/metrics: engine seconds and share per stream (shares light %s, heavy %s)"
                % (share.get("light"), share.get("heavy")))
        busy = re.search(r"^fxs_engine_busy_seconds_total (\S+)$", m, re.M)
        t.check(busy is not None and float(busy.group(1)) >= sum(engine.values()) - 0.01,
                "/metrics: the engine's busy seconds")
        await c.close()
        await h.close()


async def wait_table(c, rev, timeout):
    """Seconds until a kind 4 frame of revision rev arrives, or None."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        try:
            f = await c.frame(max(0.05, timeout - (time.monotonic() - t0)), kind=4)
        except asyncio.TimeoutError:
            return None
        if f["param_rev"] == rev:
            return time.monotonic() - t0
    return None


def cpu_rate(d, seconds):
    c0, t0 = cpu_seconds(d), time.monotonic()
    time.sleep(seconds)
    return (cpu_seconds(d) - c0) / (time.monotonic() - t0)


async def test_change_and_destroy_reach_a_long_step(t):
    cfg = config_file({"streams": []})
    with Daemon("--config", cfg) as d:
        c = await Client.connect(d)
        r = await c.request("create", effect="compound_eye", stream="eye", params=HEAVY_TABLE)
        t.check(r["op"] == "created", "create a compound_eye stream with a 64x64x8 table")
        await c.request("subscribe", stream="eye")
        await asyncio.sleep(1.5)  # in the middle of the table
        r = await c.request("set", stream="eye", params=SMALL_TABLE)
        took = await wait_table(c, r["rev"], 15)
        t.check(took is not None and took < 1.0, "a set reaches the long step: the small table comes %s s after it"
                % (None if took is None else "%.2f" % took))
        await c.request("set", stream="eye", params=HEAVY_TABLE)
        await asyncio.sleep(1.5)
        busy = cpu_rate(d, 1.0)
        r = await c.request("destroy", stream="eye")
        t.check(r["op"] == "destroyed", "destroy it in the middle of the long step")
        time.sleep(1.0)
        after = cpu_rate(d, 1.0)
        t.check(busy > 0.03 and after < 0.2 * busy,
                "the daemon stops computing within 1 s of the destroy: CPU %.2f s/s before, %.2f s/s from 1 s after"
                % (busy, after))
        await c.close()


def exr_halves(payload):
    """The one half-float channel of an uncompressed scanline OpenEXR file (common/exr.c's, for
    compression none) as a float32 array, rows top first."""
    pos, attrs = 8, {}
    while payload[pos]:
        name_end = payload.index(b"\0", pos)
        type_end = payload.index(b"\0", name_end + 1)
        size = struct.unpack_from("<i", payload, type_end + 1)[0]
        attrs[payload[pos:name_end].decode()] = payload[type_end + 5:type_end + 5 + size]
        pos = type_end + 5 + size
    x0, y0, x1, y1 = struct.unpack("<4i", attrs["dataWindow"])
    w, h = x1 - x0 + 1, y1 - y0 + 1
    offsets = struct.unpack_from("<%dQ" % h, payload, pos + 1)
    rows = [np.frombuffer(payload, np.float16, w, o + 8) for o in offsets]  # y and size, then the halves
    return np.concatenate(rows).astype(np.float32)


class FxsHeader(ctypes.Structure):  # protocol/fxs_frame.h struct fxs_header
    _fields_ = [("header_bytes", ctypes.c_uint16), ("kind", ctypes.c_uint16), ("channel", ctypes.c_uint32),
                ("param_rev", ctypes.c_uint32), ("seq", ctypes.c_uint64), ("sim_time", ctypes.c_double),
                ("server_time_us", ctypes.c_uint64), ("codec", ctypes.c_uint32),
                ("payload_bytes", ctypes.c_uint32), ("count_or_width", ctypes.c_uint32),
                ("height", ctypes.c_uint32), ("flags", ctypes.c_uint32)]


class FxcTexture(ctypes.Structure):  # clients/c/fxclient.h struct fxc_texture
    _fields_ = [("capacity", ctypes.c_size_t), ("texels", ctypes.POINTER(ctypes.c_float)),
                ("width", ctypes.c_uint32), ("height", ctypes.c_uint32), ("channels", ctypes.c_uint32)]


def engine_texels(f):
    """The texels of an engine-encoded texture frame, decoded by libfxclient, or None."""
    lib = ctypes.CDLL(os.path.join(ROOT, "build", "libfxclient.so.0.1.0"))
    h = FxsHeader(64, f["kind"], f["channel"], f["param_rev"], f["seq"], f["sim_time"], f["server_time_us"],
                  f["codec"], f["payload_bytes"], f["width"], f["height"], f["flags"])
    out = np.zeros(f["width"] * f["height"] * 4, np.float32)
    tex = FxcTexture(out.size, out.ctypes.data_as(ctypes.POINTER(ctypes.c_float)))
    err = ctypes.create_string_buffer(256)
    if lib.fxc_decode_texture(ctypes.byref(h), f["payload"], ctypes.byref(tex), err, len(err)):
        print("fxc_decode_texture: %s" % err.value.decode())
        return None
    return out[:tex.width * tex.height * tex.channels]


async def test_new_encoding_during_a_long_step(t):
    with Daemon("--config", config_file({"streams": []})) as d:
        c, e = await Client.connect(d), await Client.connect(d)
        r = await c.request("create", effect="energy_wave", stream="pulse", params=HEAVY_PULSE)
        t.check(r["op"] == "created", "create a 2048^2 energy_wave stream with a running pulse")
        await c.request("subscribe", stream="pulse")
        await c.frame(60, kind=2)  # the kernel is built, the frames' pace settled
        first = await c.frame(60, kind=2)
        t0 = time.monotonic()
        await e.ws.send(json.dumps({"op": "subscribe", "id": 1, "stream": "pulse", "encoding": "engine"}))
        f = await e.frame(10, kind=2)
        took = time.monotonic() - t0
        nxt = await c.frame(60, kind=2)
        step = time.monotonic() - t0
        t.check(f["codec"] == 16 and f["seq"] == first["seq"] and nxt["seq"] > first["seq"] and took < step / 2,
                "a subscriber of the engine encoding gets the latest frame (%d, codec %d) %.2f s after asking, "
                "before the next one (%d, %.2f s after asking) is complete" % (f["seq"], f["codec"], took, nxt["seq"], step))
        a, b = exr_halves(first["payload"]), engine_texels(f)
        same = b is not None and a.size == b.size and np.max(np.abs(a - b)) <= 1e-3 * np.max(np.abs(a))
        t.check(same, "it is the frame the EXR carried, texel for texel (max difference %s of %s)"
                % (None if b is None or a.size != b.size else np.max(np.abs(a - b)), np.max(np.abs(a))))
        await c.close()
        await e.close()


if __name__ == "__main__":
    s = Suite("test_fairshare")
    s.run([test_heavy_beside_default, test_change_and_destroy_reach_a_long_step, test_new_encoding_during_a_long_step],
          timeout=240)
