"""test_godot.py — the Godot add-on (clients/godot/addons/fxstream) in the real engine: runs
tests/godot/test_main.gd in godot3-server against a real daemon, a daemon in cluster mode (on
a redis-server of its own: it refuses particle budgets) and a fake server, and does what the
engine cannot do from inside:

* installs the add-on as a user would, by copying the folder into a project;
* runs fxctl with both encodings while the scene dumps decoded flame frames, and compares the
  same seq: Godot's positions and temperatures equal libfxclient's decoding of the engine
  encoding (to float rounding) and, particle for particle in any order, codec 2's within half
  precision and codec 2's quantisation;
* serves malformed input (cut frames, wrong sizes, unknown kind and codec, corrupt zstd,
  invalid JSON) and then synthetic 100 000-particle frames from a fake server;
* kills the daemon (SIGKILL) when the scene asks and restarts it on the same port;
* opens clients/godot/demo in the editor (headless) and instances its scene.

The scene's own checks (ok/FAIL lines) count in this suite's summary (fxtest.Suite); its exit
status is their failures, so a crashed engine fails the suite. Prints the scene's measurements: client
work per frame, and bytes per particle of the engine encoding beside codec 2."""
import asyncio
import json
import os
import shutil
import struct
import subprocess
import tempfile
import threading
import time

import numpy as np
import websockets

from fxtest import HEADER, ROOT, Daemon, Suite, free_port
from test_cluster import REDIS, Redis, cluster_daemon

GODOT = shutil.which("godot3-server")
FXCTL = os.path.join(ROOT, "build", "fxctl")
# The run's files: the Godot project, its HOME, what the scene writes (out) and what fxctl
# received in either encoding; made by main, shared by the tests in order.
W = {}


# ---- PLY and engine payloads ----

def read_ply(path):
    """The vertex properties of fxctl's binary PLY as a dict of numpy arrays."""
    with open(path, "rb") as f:
        data = f.read()
    head, body = data.split(b"end_header\n", 1)
    n, props = 0, []
    for line in head.decode().splitlines():
        w = line.split()
        if w[:2] == ["element", "vertex"]:
            n = int(w[2])
        elif w[:1] == ["property"]:
            props.append((w[2], "<f4" if w[1] == "float" else "u1"))
    return np.frombuffer(body, dtype=np.dtype(props), count=n)


def engine_particles(xyz, temp, seq, channel=7, total=0):
    """A kind 1 frame in the engine encoding (PROTOCOL.md §7.8) of these particles (a budget's
    subset of `total` when that is not 0)."""
    n = len(temp)
    lo, hi = xyz.min(0), xyz.max(0)
    origin = ((lo.astype(np.float64) + hi) / 2).astype(np.float32)
    extent = np.nextafter(np.maximum(hi - origin, origin - lo).astype(np.float32), np.float32(np.inf))
    rows = max(1, -(-n // 1024))
    texels = np.zeros((rows * 1024, 4), np.float16)
    texels[:n, :3] = (xyz.astype(np.float64) - origin).astype(np.float32)
    texels[:n, 3] = temp
    raw = texels.tobytes()
    z = subprocess.run(["zstd", "-3", "-q", "-c"], input=raw, stdout=subprocess.PIPE, check=True).stdout
    eh = b"FXE1" + struct.pack("<HHHHIIIII3f3fII", 1, 64, 1, 1, 1024, rows, n, len(raw), len(z), *origin, *extent, 0, 0)
    return frame(1, 16, eh + z, n, 0, seq, channel, total=total)


def frame(kind, codec, payload, w, h, seq, channel=7, payload_bytes=None, total=0):
    hdr = HEADER.pack(b"FXS1", 64, kind, channel, 1, seq, seq / 30.0, int(time.time() * 1e6), codec,
                      len(payload) if payload_bytes is None else payload_bytes, w, h, 0, total)
    return hdr + payload


# ---- the fake server: malformed input, then big frames ----

class Fake:
    def __init__(self, big):
        self.big, self.port = big, free_port()
        self.loop = asyncio.new_event_loop()
        self.ready = threading.Event()
        threading.Thread(target=self._run, daemon=True).start()
        self.ready.wait(10)

    def _run(self):
        asyncio.set_event_loop(self.loop)
        srv = websockets.serve(self._serve, "127.0.0.1", self.port, subprotocols=["fxstream.v1"], max_size=None)
        self.loop.run_until_complete(srv)
        self.ready.set()
        self.loop.run_forever()

    async def _serve(self, ws, *_):
        await ws.send(json.dumps({"op": "hello", "protocol": "fxstream.v1", "server": "fake/0",
                                  "encodings": ["default", "engine"]}))
        try:
            async for m in ws:
                req = json.loads(m)
                if req.get("op") == "subscribe":
                    await ws.send(json.dumps({"op": "subscribed", "id": req.get("id"), "stream": req["stream"],
                                              "channel": 7, "encoding": "engine"}))
                    await self._bad_then_good(ws)
                    await self._big(ws)
        except websockets.exceptions.ConnectionClosed:
            pass  # the scene is done with it

    async def _bad_then_good(self, ws):
        """Each in a game frame of its own (the client decodes only the newest frame of a
        stream and kind that arrive together). The good frame is a budget's subset: 500 of 4000."""
        rng = np.random.default_rng(1)
        xyz = rng.normal(0, 0.02, (500, 3)).astype(np.float32)
        good = engine_particles(xyz, np.full(500, 1500, np.float32), seq=1, total=4000)
        hdr_only = good[:64 + 64]
        bad_raw = bytearray(good)
        struct.pack_into("<I", bad_raw, 64 + 24, 999)  # raw_bytes that fits no image
        bad_zstd = bytearray(good)
        bad_zstd[64 + 64 + 8:64 + 64 + 40] = b"\xff" * 32
        for m in [good[:100],                                           # cut short
                  frame(1, 16, good[64:], 500, 0, 2, payload_bytes=len(good) - 60),  # wrong payload size
                  bytes(bad_raw),                                       # wrong raw size
                  frame(9, 16, good[64:], 500, 0, 3),                   # unknown kind
                  frame(1, 2, good[64:], 500, 0, 4),                    # a codec the add-on cannot read
                  frame(1, 16, good[64:], 500, 0, 5, total=10),         # a subset larger than its total
                  bytes(bad_zstd),                                      # corrupt zstd
                  hdr_only,                                             # the headers alone
                  good[:30]]:                                           # shorter than a header
            await ws.send(m)
            await asyncio.sleep(0.15)
        for t in ['{"op": "params", "stream": ', '[1, 2, 3]', '{"stream": "flame"}']:
            await ws.send(t)
        await asyncio.sleep(0.15)
        await ws.send(good)

    async def _big(self, ws):
        await asyncio.sleep(0.5)
        for seq in range(2, 2 + 240):  # 8 s at 30 fps
            await ws.send(self.big[:16] + struct.pack("<Q", seq) + self.big[24:])
            await asyncio.sleep(1 / 30)

    def stop(self):
        self.loop.call_soon_threadsafe(self.loop.stop)


# ---- comparisons ----

async def test_decoded_like_libfxclient(t):
    """Godot's decoding of the dumped frames against libfxclient's of the same seq (fxctl)."""
    out, eng_dir, def_dir = W["out"], W["engine"], W["default"]
    dumps = sorted(f for f in os.listdir(out) if f.startswith("godot-flame-"))
    t.check(len(dumps) >= 3, "the scene dumped decoded flame frames (%d)" % len(dumps))
    compared = 0
    for d in dumps:
        seq = int(d[len("godot-flame-"):-4])
        with open(os.path.join(out, d), "rb") as f:
            n = struct.unpack("<I", f.read(4))[0]
            g = np.frombuffer(f.read(), dtype="<f4").reshape(-1, 4)
        pe, pd = os.path.join(eng_dir, "flame-%d.ply" % seq), os.path.join(def_dir, "flame-%d.ply" % seq)
        if not (os.path.exists(pe) and os.path.exists(pd)):
            continue
        compared += 1
        e, c2 = read_ply(pe), read_ply(pd)
        exyz = np.stack([e["x"], e["y"], e["z"]], 1)
        t.check(n == len(e) == len(c2) == len(g),
                "seq %d: Godot, libfxclient (engine) and codec 2 see %d / %d / %d particles" % (seq, len(g), len(e), len(c2)))
        if not n == len(e) == len(c2) == len(g):
            continue
        t.check(np.allclose(g[:, :3], exyz, rtol=0, atol=1e-6 * max(1.0, np.abs(exyz).max())) and
                np.array_equal(g[:, 3], e["temperature"]),
                "seq %d: Godot's positions and T equal libfxclient's decoding of the same engine frame" % seq)
        cxyz, ct = np.stack([c2["x"], c2["y"], c2["z"]], 1), c2["temperature"]
        off = np.abs(exyz - exyz.min(0) - (exyz.max(0) - exyz.min(0)) / 2).max()
        # half a half-float step at the largest offset (T: at the hottest) + half codec 2's step
        tol = 1.01 * (2.0 ** (np.floor(np.log2(off)) - 11) + (cxyz.max(0) - cxyz.min(0)).max() / 65535 / 2)
        ttol = 1.01 * (2.0 ** (np.floor(np.log2(ct.max())) - 11) + (ct.max() - ct.min()) / 1023 / 2)
        lone = unmatched(g[:, :3], cxyz, g[:, 3], ct, tol, ttol)
        t.check(lone == 0, "seq %d: every particle has one of codec 2's within half precision and codec 2's steps "
                "(%.2g m, %.2f K): %d without" % (seq, tol, ttol, lone))
    t.check(compared >= 3, "%d dumped frames matched fxctl's frames of the same seq" % compared)


def unmatched(a, b, ta, tb, tol, ttol):
    """Particles of a with no particle of b within tol on every axis and ttol in T, and of b
    without one of a (the two encodings order particles differently)."""
    lone = 0
    for x, y, tx, ty in ((a, b, ta, tb), (b, a, tb, ta)):
        for i in range(0, len(x), 256):
            near = (np.abs(x[i:i + 256, None, :] - y[None, :, :]) <= tol).all(2)
            near &= np.abs(tx[i:i + 256, None] - ty[None, :]) <= ttol
            lone += int((~near.any(1)).sum())
    return lone


async def test_bytes_per_particle(t):
    """The engine encoding's size beside codec 2's, over the frames fxctl received in both."""
    sizes = {}
    for name, d in (("engine", W["engine"]), ("codec 2", W["default"])):
        for f in os.listdir(d) if os.path.isdir(d) else []:  # fxctl never ran when the scene stopped early
            if f.endswith(".json"):
                j = json.load(open(os.path.join(d, f)))
                if j["kind"] == 1 and j["count"] > 0:
                    sizes.setdefault(j["seq"], {})[name] = (j["payload_bytes"] + 64) / j["count"]
    both = [v for v in sizes.values() if len(v) == 2]
    if t.check(len(both) >= 10, "fxctl received >= 10 flame frames in both encodings (%d)" % len(both)):
        e = np.mean([v["engine"] for v in both])
        c = np.mean([v["codec 2"] for v in both])
        print("measure bytes per particle (frame header included), the same %d frames: engine %.2f, codec 2 %.2f" % (len(both), e, c))


# ---- the run ----

def fxctl_sub(url, encoding, out):
    os.makedirs(out, exist_ok=True)
    p = subprocess.Popen([FXCTL, "--url", url, "--timeout", "20000", "subscribe", "flame", "--frames", "120",
                          "--encoding", encoding, "--out", out], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    p.stdout.readline()  # the subscribed reply
    return p


def big_frame(url, tmp):
    """A 100 000-particle engine frame: ten copies of a real default flame frame side by side."""
    d = os.path.join(tmp, "seed")
    subprocess.run([FXCTL, "--url", url, "subscribe", "flame", "--frames", "60", "--kind", "1", "--out", d],
                   stdout=subprocess.DEVNULL, check=True, timeout=60)
    plys = sorted((f for f in os.listdir(d) if f.endswith(".ply")), key=lambda f: int(f.split("-")[1][:-4]))
    p = read_ply(os.path.join(d, plys[-1]))
    xyz = np.stack([p["x"], p["y"], p["z"]], 1)
    reps = -(-100000 // len(p))
    big_xyz = np.concatenate([xyz + np.float32([0.04 * (k % 5), 0.04 * (k // 5), 0]) for k in range(reps)])[:100000]
    big_t = np.concatenate([p["temperature"]] * reps)[:100000]
    return engine_particles(big_xyz.astype(np.float32), big_t, seq=2)


async def test_demo(t):
    """The demo opens in the editor (it imports, loads the plugin and parses every script) and
    its scene instances with the add-on's nodes, the flame with the budget FXSTREAM_MAX_PARTICLES
    asks for, shown in the panel's menu."""
    demo, env = os.path.join(W["tmp"], "demo"), W["env"]
    shutil.copytree(os.path.join(ROOT, "clients", "godot", "demo"), demo, symlinks=False)
    p = subprocess.run([GODOT, "-e", "--path", demo, "--quit"], capture_output=True, text=True, env=env, timeout=120)
    bad = [l for l in (p.stdout + p.stderr).splitlines() if "SCRIPT ERROR" in l or "Parse Error" in l]
    t.check(p.returncode == 0 and not bad, "the demo project opens in the editor without script errors %s" % bad[:2])
    with open(os.path.join(demo, "check_demo.gd"), "w") as f:
        f.write('extends SceneTree\nfunc _initialize():\n\tvar d = load("res://demo.tscn").instance()\n'
                '\troot.add_child(d)\n\tprint("demo nodes: ", d.get_node("Flame").stream, " ", d.get_node("Wave").stream, " ",'
                ' d.get_node("Rig").stream, " ", d.get_node("UI/Tuning").get_child_count(), " budget ",'
                ' d.get_node("Flame").get("max_particles"), " ", d.get_node("UI/Tuning").get("_budget").text)\n\tquit(0)\n')
    p = subprocess.run([GODOT, "--path", demo, "-s", "res://check_demo.gd"], capture_output=True, text=True,
                       env=dict(env, FXSTREAM_URL="ws://127.0.0.1:1/v1/ws", FXSTREAM_MAX_PARTICLES="2000"), timeout=60)
    t.check(p.returncode == 0 and "demo nodes: flame energy energy 1 budget 2000 flame: at most 2000 particles" in p.stdout,
          "the demo scene instances: flame with a budget of 2000 (FXSTREAM_MAX_PARTICLES) shown in the panel, energy wave, "
          "light rig, tuning panel (%s)" % [l for l in p.stdout.splitlines() if "demo nodes" in l])


async def test_scene(t):
    """Runs test_main.gd against the daemons and the fake server, doing what its marker files ask."""
    tmp, out = W["tmp"], W["out"]
    proj = os.path.join(tmp, "project")
    shutil.copytree(os.path.join(ROOT, "tests", "godot"), proj)
    shutil.copytree(os.path.join(ROOT, "clients", "godot", "addons", "fxstream"), os.path.join(proj, "addons", "fxstream"))
    port = free_port()
    nice = ("nice", "-n", "10")  # the scene times its calls: the daemon's solver must not crowd it out
    d = Daemon("--port", str(port), state_dir=W["state"], wrapper=nice)
    redis = Redis()
    cluster = cluster_daemon(redis, "godot")
    fake = Fake(big_frame(d.url, tmp))
    env = dict(W["env"], FXS_URL=d.url, FXS_CLUSTER_URL=cluster.url, FXS_FAKE_URL="ws://127.0.0.1:%d/v1/ws" % fake.port,
               FXS_OUT=out)
    g = subprocess.Popen([GODOT, "--path", proj, "-s", "res://test_main.gd"], stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True, env=env)
    lines = []
    reader = threading.Thread(target=lambda: lines.extend(g.stdout), daemon=True)
    reader.start()
    subs, deadline = [], time.monotonic() + 300
    marker = lambda name: os.path.exists(os.path.join(out, name))  # noqa: E731
    try:
        while g.poll() is None and time.monotonic() < deadline:
            if marker("fxctl-go") and not subs:
                subs = [fxctl_sub(d.url, "engine", W["engine"]), fxctl_sub(d.url, "default", W["default"])]
                open(os.path.join(out, "fxctl-running"), "w").close()
            if marker("restart-go") and not marker("restarted"):
                d.proc.kill()
                d.proc.wait(10)
                d = Daemon("--port", str(port), state_dir=W["state"], wrapper=nice)
                open(os.path.join(out, "restarted"), "w").close()
            await asyncio.sleep(0.05)
    finally:
        if g.poll() is None:
            g.kill()
        rc = g.wait(10)
        reader.join(10)
        for p in subs:
            p.wait(60)
        d.stop()
        cluster.stop()
        redis.kill()
        shutil.rmtree(redis.dir, ignore_errors=True)
        fake.stop()
    scene = [l.rstrip("\n") for l in lines]
    for l in scene:
        if l.startswith("ok   ") or l.startswith("FAIL ") or l.startswith("measure ") or l.startswith("game loop"):
            print(("  scene: " if l[:4] in ("ok  ", "FAIL") else "") + l)
    nfail = sum(l.startswith("FAIL ") for l in scene)
    t.passed += sum(l.startswith("ok   ") for l in scene)
    t.failed += nfail
    if not t.check(rc == nfail and any(l.startswith("test_godot_scene:") for l in scene),
                   "the scene ran to its end (exit status %s, %d failed checks)" % (rc, nfail)):
        print("\n".join(scene[-40:]))


def main():
    suite = Suite("test_godot")
    if not suite.check(GODOT is not None and os.access(REDIS, os.X_OK),
                       "godot3-server and redis-server are installed (deploy/install-deps.sh)"):
        suite.run([])
    tmp = tempfile.mkdtemp(prefix="fxs-godot-")
    home = os.path.join(tmp, "home")
    W.update(tmp=tmp, out=os.path.join(tmp, "out"), engine=os.path.join(tmp, "engine"),
             default=os.path.join(tmp, "default"), state=tempfile.mkdtemp(prefix="fxs-godot-state-"),
             env=dict(os.environ, HOME=home, XDG_DATA_HOME=os.path.join(home, "data"),
                      XDG_CONFIG_HOME=os.path.join(home, "config")))
    os.makedirs(W["out"])
    os.makedirs(home)
    try:
        suite.run([test_scene, test_demo, test_decoded_like_libfxclient, test_bytes_per_particle], timeout=400)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(W["state"], ignore_errors=True)


if __name__ == "__main__":
    main()
