"""test_eye_stream.py — the compound_eye effect end to end through a real daemon: one kind 4
frame per table with its FXL1 container decoded here independently (PROTOCOL.md §7.6),
a shading-only change sends no new table, a table change sends one with the new rev, bake
mode sends EXR frames, an OBJ from --assets-dir is usable while bad names are refused,
and `fxctl subscribe --out` writes openable PNG files."""
import asyncio
import os
import struct
import subprocess
import tempfile
import zlib

from fxtest import ROOT, Client, Daemon, Suite

D = None
FXCTL = os.path.join(ROOT, "build", "fxctl")
SMALL = {"lut_cells": 8, "lut_dirs": 8, "lattice": "square"}  # the test turns hex on later


def unzstd(blob):
    return subprocess.run(["zstd", "-dc"], input=blob, capture_output=True, check=True, timeout=30).stdout


def decode(payload):
    """Returns (header fields, {name: (entry dict, raw bytes)})."""
    magic, version, hb, count, eb, lattice = struct.unpack_from("<4sHHHHI", payload)
    assert magic == b"FXL1" and version == 1, (magic, version)
    tile_h, r, n, depth = struct.unpack_from("<4f", payload, 16)
    passes, cells, dirs, gutter, ss = struct.unpack_from("<5I", payload, 32)
    head = dict(lattice=lattice, tile_h=tile_h, r=r, n=n, cells=cells, dirs=dirs, gutter=gutter, ss=ss)
    out = {}
    for i in range(count):
        name, fmt, codec, w, h, off, stored, raw, tile, tx, ty, inner = struct.unpack_from(
            "<4s11I", payload, hb + i * eb)
        data = unzstd(payload[off:off + stored])
        out[name.decode()] = (dict(fmt=fmt, codec=codec, w=w, h=h, off=off, raw=raw, tile=tile, tiles=tx,
                                   inner=inner), data)
    return head, out


async def test_lut_frames(t):
    c = await Client.connect(D)
    t.check("compound_eye" in c.hello["effects"], "hello lists compound_eye")
    r = await c.request("create", effect="compound_eye", stream="lut", params=SMALL)
    t.check(r["op"] == "created", "create compound_eye stream")
    await c.request("subscribe", stream="lut")
    f = await c.frame(30, kind=4)
    t.check(f["codec"] == 1 and f["width"] == f["height"] == 8 * 10, "kind 4 codec 1, atlas 80x80")
    head, prods = decode(f["payload"])
    t.check(sorted(prods) == ["LLUT", "LMAC", "PIGM"], "three products in one frame")
    e, data = prods["LLUT"]
    t.check(e["w"] == e["h"] == head["dirs"] * (head["cells"] + 2) and len(data) == e["raw"] == e["w"] * e["h"] * 4,
            "LLUT size = D*(C+2), raw bytes match")
    w = e["w"]
    px = lambda x, y: data[4 * (y * w + x):4 * (y * w + x) + 4]
    t.check(px(0, 5) == px(8, 5) and px(9, 5) == px(1, 5), "LLUT gutters repeat the opposite edge")
    pe, pdata = prods["PIGM"]
    t.check(pe["w"] == pe["h"] == 128 and len(pdata) == 128 * 128 * 4, "PIGM 128x128 RGBA8")
    centre = pdata[4 * (64 * 128 + 64):4 * (64 * 128 + 64) + 3]
    t.check(max(centre) < 30, "PIGM: dark dot at the cell centre %s" % list(centre))
    me, _ = prods["LMAC"]
    t.check(me["w"] == me["h"] == 8, "LMAC D x D")
    rev0 = f["param_rev"]
    s = await c.request("set", stream="lut", params={"ka": 0.5, "density": 80})
    t.check(s["op"] == "params", "set shading-only parameters")
    try:  # a table sent for the shading-only change would arrive within this wait
        stray = await c.frame(2, kind=4)
    except asyncio.TimeoutError:
        stray = None
    s2 = await c.request("set", stream="lut", params={"lattice": "hex", "lens_radius": 0.9})
    g = stray or await c.frame(30, kind=4)  # a stream that sends nothing at all fails here
    t.check(stray is None and g["param_rev"] == s2["rev"],
            "no new table after a shading-only change (rev %d): the next table is the table change's "
            "(got rev %d, want %d)" % (s["rev"], g["param_rev"], s2["rev"]))
    t.check(g["param_rev"] > rev0, "a table change sends a table with the new rev")
    head2, prods2 = decode(g["payload"])
    t.check(head2["lattice"] == 1 and abs(head2["tile_h"] - 3 ** 0.5) < 1e-6 and
            prods2["PIGM"][0]["h"] == round(128 * 3 ** 0.5), "hex table: tile_h sqrt 3, PIGM 128 x 222")
    bad = await c.request("set", stream="lut", params={"lattice": "triangle"})
    t.check(bad["op"] == "error" and bad["param"] == "lattice", "bad enum refused")
    bad = await c.request("set", stream="lut", params={"lattice": "square", "lens_radius": 0.6})
    t.check(bad["op"] == "error" and bad["param"] == "lens_radius", "gappy lens radius refused")
    for name in ("../etc/passwd", "/etc/passwd", "a b"):
        bad = await c.request("set", stream="lut", params={"model": name})
        t.check(bad["op"] == "error" and bad["param"] == "model", "model name %r refused" % name)
    await c.close()


async def test_bake_and_obj(t):
    c = await Client.connect(D)
    r = await c.request("create", effect="compound_eye", stream="bake",
                        params={"mode": "bake", "bake_size": 128, "model": "tri"})
    t.check(r["op"] == "created", "create a bake stream on the assets OBJ: %s" % r)
    await c.request("subscribe", stream="bake")
    f = await c.frame(30, kind=2)
    t.check(f["codec"] == 1 and f["width"] == 128 and f["payload"][:4] == b"\x76\x2f\x31\x01", "bake: EXR frames")
    s = await c.request("set", stream="bake", params={"eye": [0.2, 0.1, 2.0]})
    g = await c.frame(30, kind=2)
    t.check(g["param_rev"] >= s["rev"] or g["seq"] > f["seq"], "a view change sends a new frame")
    bad = await c.request("create", effect="compound_eye", stream="b2", params={"model": "broken"})
    t.check(bad["op"] == "error" and bad["param"] == "model" and "line" in bad["message"],
            "malformed OBJ refused with its line: %s" % bad.get("message"))
    # A model that is a symlink (here to a secret outside the assets) is not offered and never
    # read, so no line of the target can be quoted in an error.
    bad = await c.request("create", effect="compound_eye", stream="b3", params={"model": "leak"})
    t.check(bad["op"] == "error" and bad["param"] == "model" and "SECRET" not in bad["message"] and
            '"leak"' not in bad["message"].split("expected one of")[-1],
            "a symlinked OBJ is not a model choice, its content never quoted: %s" % bad.get("message"))
    await c.close()


def png_ok(path):
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        return False
    w, h = struct.unpack(">II", data[16:24])
    i, idat = 8, b""
    while i < len(data):
        n = struct.unpack(">I", data[i:i + 4])[0]
        if data[i + 4:i + 8] == b"IDAT":
            idat += data[i + 8:i + 8 + n]
        i += 12 + n
    return len(zlib.decompress(idat)) == h * (1 + 4 * w)


async def test_fxctl_out(t):
    out = tempfile.mkdtemp(prefix="fxs-eye-")
    p = subprocess.run([FXCTL, "--url", D.url, "subscribe", "lut", "--frames", "1", "--out", out],
                       capture_output=True, text=True, timeout=60)
    t.check(p.returncode == 0, "fxctl subscribe --out: %s" % p.stderr)
    pngs = sorted(f for f in os.listdir(out) if f.endswith(".png"))
    t.check(len(pngs) == 3 and all(png_ok(os.path.join(out, f)) for f in pngs), "three valid PNG files %s" % pngs)


def main():
    global D
    assets = tempfile.mkdtemp(prefix="fxs-assets-")
    with open(os.path.join(assets, "tri.obj"), "w") as f:
        f.write("v -1 -1 0\nv 1 -1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0.5 1\nf 1/1 2/2 3/3\n")
    with open(os.path.join(assets, "broken.obj"), "w") as f:
        f.write("v 0 0 0\nf 1/1 2/2 3/3\n")
    secret = os.path.join(tempfile.mkdtemp(prefix="fxs-secret-"), "secret.obj")
    with open(secret, "w") as f:
        f.write("v 0 0 0\nf SECRET-TOKEN/1 2 3\n")
    os.symlink(secret, os.path.join(assets, "leak.obj"))
    D = Daemon("--assets-dir", assets)
    try:
        Suite("test_eye_stream").run([test_lut_frames, test_bake_and_obj, test_fxctl_out], timeout=120)
    finally:
        D.stop()


if __name__ == "__main__":
    main()
