"""test_fairshare.py — streams share the engine (engine.c's scheduling): a default energy_wave
stream keeps at least 80% of its rate beside a stream whose every frame takes seconds (a
2048^2 texture), both rates measured the same way in alternating phases of one run; the heavy
stream still gets some of the engine, and /metrics shows each stream's configured and achieved
fps and engine time. A `set` reaches a stream in the middle of a long step (a 64x64x8 lens
table) within a second, and after a `destroy` the daemon stops computing within a second."""
import asyncio
import re
import time
import urllib.request

from fxtest import Client, Daemon, Suite, config_file, cpu_seconds

HEAVY_WAVE = {"width": 2048, "height": 2048}  # ~64 x the default's work per frame
HEAVY_TABLE = {"lut_cells": 64, "lut_dirs": 64, "lut_supersample": 8}  # ~1e9 rays: tens of seconds
SMALL_TABLE = {"lut_cells": 8, "lut_dirs": 8, "lut_supersample": 1}
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
        t.check(engine.get("light", 0) > 0 and 0 < share.get("heavy", 0) < share.get("light", 0) <= 1.05,
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


if __name__ == "__main__":
    s = Suite("test_fairshare")
    s.run([test_heavy_beside_default, test_change_and_destroy_reach_a_long_step], timeout=240)
