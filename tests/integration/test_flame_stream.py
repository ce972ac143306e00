"""test_flame_stream.py — the flame effect end to end through a real daemon: kind 1 particle
frames (header, codec 2 payload), growth from the burning source, live parameter changes
and reset reaching the frames, and `fxctl subscribe --out` writing readable binary PLY
whose particles are physically plausible (sources hold T_init/F_init, nothing below
ambient); the opt-in velocities (PROTOCOL.md §7.5.7): off by default with no velocity block,
on with the block and vel_bits, PLY velocities plausible (sources at rest, hot gas rising)."""
import os
import struct
import subprocess
import tempfile
import time

from fxtest import ROOT, Client, Daemon, Suite

D = None
FXCTL = os.path.join(ROOT, "build", "fxctl")


async def frames(c, n, timeout=30):
    return [await c.frame(timeout=timeout) for _ in range(n)]


async def test_particle_frames(t):
    c = await Client.connect(D)
    t.check("flame" in c.hello["effects"], "hello lists the flame effect")
    lst = await c.request("list")
    t.check(any(s["stream"] == "flame" and s["effect"] == "flame" for s in lst["streams"]),
            "default streams include flame")
    r = await c.request("subscribe", stream="flame")
    t.check(r["op"] == "subscribed", "subscribe flame")
    fs = await frames(c, 4)
    f = fs[0]
    t.check(f["kind"] == 1 and f["codec"] == 2, "kind 1 frames with codec 2 (one block while small)")
    t.check(f["channel"] == r["channel"] and f["height"] == 0, "channel and height 0")
    t.check(all(x["payload"][:4] == b"FXP2" for x in fs), "payloads are FXP2 particle blocks")
    t.check(all(x["width"] > 0 for x in fs), "frames carry particles (count in the header)")
    t.check(fs[-1]["width"] > fs[0]["width"], "the flame grows from the source (%d -> %d particles)"
            % (fs[0]["width"], fs[-1]["width"]))
    t.check(all(a["seq"] < b["seq"] for a, b in zip(fs, fs[1:])), "seq increases")
    await c.close()


async def test_live_set_and_reset(t):
    c = await Client.connect(D)
    await c.request("subscribe", stream="flame")
    await frames(c, 2)
    r = await c.request("set", stream="flame", params={"wind_accel": [5, 0, 0], "sources": [
        {"center": [0, 0, 0], "radius": 0.02, "F_init": 120}]})
    t.check(r["op"] == "params" and r["params"]["sources"][0]["F_init"] == 120, "set wind and sources")
    deadline, seen = time.monotonic() + 30, False
    while time.monotonic() < deadline and not seen:
        seen = (await c.frame())["param_rev"] == r["rev"]
    t.check(seen, "frames carry the new rev")
    bad = await c.request("set", stream="flame", params={"dt": 1.0})
    t.check(bad["op"] == "error" and bad["code"] == "bad_param" and bad["param"] == "dt", "bad dt rejected")
    before = (await c.frame())["width"]
    rr = await c.request("reset", stream="flame")
    t.check(rr["op"] == "reset", "reset acknowledged")
    after = None
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        after = (await c.frame())["width"]
        if after < before:
            break
    t.check(after is not None and after < before, "reset starts the flame over (%s -> %s)" % (before, after))
    await c.close()


def read_ply(path):
    """Parses fxctl's binary PLY: returns (properties, rows)."""
    with open(path, "rb") as f:
        data = f.read()
    head_end = data.index(b"end_header\n") + len(b"end_header\n")
    head = data[:head_end].decode().splitlines()
    assert head[0] == "ply" and head[1] == "format binary_little_endian 1.0", head[:2]
    n = int(next(l for l in head if l.startswith("element vertex")).split()[2])
    props = [l.split()[1:] for l in head if l.startswith("property")]
    fmt = "<" + "".join({"float": "f", "uchar": "B"}[p[0]] for p in props)
    size = struct.calcsize(fmt)
    body = data[head_end:]
    assert len(body) == n * size, (len(body), n, size)
    return [p[1] for p in props], [struct.unpack_from(fmt, body, i * size) for i in range(n)]


async def test_fxctl_ply(t):
    out = tempfile.mkdtemp(prefix="fxs-ply-")
    p = subprocess.run([FXCTL, "--url", D.url, "subscribe", "flame", "--frames", "3", "--out", out],
                       capture_output=True, text=True, timeout=60)
    t.check(p.returncode == 0, "fxctl subscribe flame --out (%s)" % p.stderr.strip()[:200])
    plys = sorted(f for f in os.listdir(out) if f.endswith(".ply"))
    t.check(len(plys) == 3, "one PLY per frame (%d)" % len(plys))
    if not plys:
        return
    names, rows = read_ply(os.path.join(out, plys[-1]))
    t.check(names == ["x", "y", "z", "temperature", "fuel", "flags"], "PLY properties %s" % names)
    t.check(len(rows) > 0, "PLY has particles (%d)" % len(rows))
    temps = [r[3] for r in rows]
    t.check(min(temps) > 250 and max(temps) < 1e5, "temperatures plausible [%.0f, %.0f] K" % (min(temps), max(temps)))
    t.check(all(r[4] >= 0 for r in rows), "fuel never negative")
    types = {r[5] & 3 for r in rows}
    t.check(types <= {0, 1, 2}, "particle types valid %s" % types)
    src = [r for r in rows if r[5] & 3 == 1]
    t.check(len(src) > 0 and all(abs(r[3] - 2000) < 10 for r in src), "sources hold T_init 2000 K")
    hot = [r for r in rows if r[5] & 4]
    half_step = (max(temps) - min(temps)) / 1023 / 2 + 1e-3  # 10-bit temperatures (PROTOCOL.md §7.5)
    t.check(all(r[3] > 1000 - half_step for r in hot),
            "flame-flagged particles are above T_ign within the codec's bound (%.2f K)" % half_step)


def payload_layout(p):
    """(attr_mode byte, velocity block present, vel_bits or None, sizes consistent)."""
    rc, bits = struct.unpack_from("<II", p, 56)
    vel = bool(p[11] & 0x10)
    head = 80 if vel else 64
    return p[11], vel, (p[64] if vel else None), head + rc + bits == len(p)


async def wait_rev(c, rev, timeout=30):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        f = await c.frame()
        if f["param_rev"] == rev:
            return f
    return None


async def test_velocities(t):
    c = await Client.connect(D)
    g = await c.request("get", stream="flame")
    t.check(g["params"]["velocities"] is False and g["params"]["vel_bits"] == 8, "velocities off by default, vel_bits 8")
    await c.request("subscribe", stream="flame")
    f = await c.frame()
    mode, vel, _, sizes = payload_layout(f["payload"])
    t.check(mode in (0, 1) and not vel and sizes, "off: attr_mode %d, no velocity block, 64 + sections" % mode)
    r = await c.request("set", stream="flame", params={"velocities": True, "vel_bits": 6})
    f = await wait_rev(c, r["rev"])
    t.check(f is not None, "frames with velocities arrive")
    if f is not None:
        mode, vel, vb, sizes = payload_layout(f["payload"])
        t.check(vel and vb == 6 and (mode & 15) in (0, 1) and sizes, "on: bit 4, vel_bits 6 in the block, 80 + sections")
        vmax = struct.unpack_from("<3f", f["payload"], 68)
        t.check(all(0 <= v < 50 for v in vmax) and vmax[2] > 0, "vmax per axis plausible %s m/s" % (vmax,))
    out = tempfile.mkdtemp(prefix="fxs-vel-")
    p = subprocess.run([FXCTL, "--url", D.url, "subscribe", "flame", "--frames", "3", "--out", out],
                       capture_output=True, text=True, timeout=60)
    t.check(p.returncode == 0, "fxctl subscribe flame --out with velocities (%s)" % p.stderr.strip()[:200])
    plys = sorted((f for f in os.listdir(out) if f.endswith(".ply")), key=lambda f: int(f.split("-")[1].split(".")[0]))
    if plys:
        names, rows = read_ply(os.path.join(out, plys[-1]))
        t.check(names == ["x", "y", "z", "temperature", "fuel", "flags", "vx", "vy", "vz"], "PLY properties %s" % names)
        src = [r for r in rows if r[5] & 3 == 1]
        t.check(len(src) > 0 and all(r[6:9] == (0.0, 0.0, 0.0) for r in src), "sources are at rest (exact zeros)")
        hot = [r for r in rows if r[5] & 4]
        mean_vz = sum(r[8] for r in hot) / max(1, len(hot))
        t.check(len(hot) > 0 and mean_vz > 0.05, "burning gas rises: mean vz %.3f m/s over %d" % (mean_vz, len(hot)))
    r = await c.request("set", stream="flame", params={"velocities": False})
    f = await wait_rev(c, r["rev"])
    t.check(f is not None and not payload_layout(f["payload"])[1], "off again: no velocity block")
    await c.close()


if __name__ == "__main__":
    D = Daemon()
    s = Suite("test_flame_stream")
    try:
        s.run([test_particle_frames, test_live_set_and_reset, test_fxctl_ply, test_velocities], timeout=120)
    finally:
        D.stop()
