"""test_budget.py — subscribe's `max_particles` (PROTOCOL.md §3.5) through a real daemon, on its
default flame (about 10k particles): budgeted subscribers get subsets of exactly the served
step whose header `total` is the particle count of the unbudgeted subscribers' frame of the
same seq; two subscribers of one step get the same payload bytes (one encode); a budget the
frame fits gets the very bytes the unbudgeted get; the engine encoding takes a budget too;
subscribing again without it gives full frames; every bad value is bad_request (param
max_particles) and changes nothing on a connection that stays usable; fxctl --max-particles
and fxload --max-particles end to end."""
import asyncio
import json
import os
import subprocess
import tempfile

from fxtest import ROOT, Client, Daemon, Suite

D = None
FXCTL = os.path.join(ROOT, "build", "fxctl")
FXLOAD = os.path.join(ROOT, "build", "fxload")


async def collect(c, n):
    """The next n particle frames of c, by seq."""
    out = {}
    for _ in range(n):
        f = await c.frame(kind=1)
        out[f["seq"]] = f
    return out


async def subscribed(t, c, what, **fields):
    r = await c.request("subscribe", stream="flame", **fields)
    t.check(r["op"] == "subscribed", "%s: subscribed (%s)" % (what, r.get("message", "")))
    return r


async def grown(c, n=3000, timeout=30):
    """Waits for a particle frame of more than n particles (a fresh flame starts small)."""
    deadline = asyncio.get_running_loop().time() + timeout
    while asyncio.get_running_loop().time() < deadline:
        if (await c.frame(kind=1))["width"] > n:
            return True
    return False


async def test_subsets(t):
    full, b1, b2, fits, eng = [await Client.connect(D) for _ in range(5)]
    await subscribed(t, full, "no budget")
    t.check(await grown(full), "the flame grows past 3000 particles")
    r1 = await subscribed(t, b1, "max_particles 1500", max_particles=1500)
    r2 = await subscribed(t, b2, "max_particles 1000", max_particles=1000)
    t.check(r1.get("max_particles") == 1000 and r2.get("max_particles") == 1000,
            "1500 and 1000 are both served as the step 1000 (%s, %s)" % (r1.get("max_particles"), r2.get("max_particles")))
    rf = await subscribed(t, fits, "max_particles 4194304", max_particles=4194304)
    t.check(rf.get("max_particles") == 2000000, "4194304 is served as 2000000 (%s)" % rf.get("max_particles"))
    re = await subscribed(t, eng, "engine, max_particles 2000", encoding="engine", max_particles=2000)
    t.check(re.get("max_particles") == 2000 and re["encoding"] == "engine", "the engine encoding with a budget")
    F, B1, B2, FITS, E = await asyncio.gather(*(collect(c, 20) for c in (full, b1, b2, fits, eng)))
    t.check(all(f["width"] > 2000 and f["total"] == 0 for f in F.values()),
            "unbudgeted: full frames above 2000 particles, total 0 (%s)" % sorted(f["width"] for f in F.values())[:3])
    t.check(all(f["width"] == 1000 and f["total"] > 1000 for f in list(B1.values()) + list(B2.values())),
            "budget 1000: subsets of exactly 1000 with their total")
    same = [s for s in B1 if s in F]
    t.check(len(same) >= 5 and all(B1[s]["total"] == F[s]["width"] for s in same),
            "total is the unbudgeted frame's count of the same seq (%d compared)" % len(same))
    pair = [s for s in B1 if s in B2]
    t.check(len(pair) >= 5 and all(B1[s]["payload"] == B2[s]["payload"] for s in pair),
            "two subscribers of one step get the same payload bytes (%d compared)" % len(pair))
    t.check(all(B1[s]["payload"] != F[s]["payload"] for s in same), "a subset's payload is not the full one")
    both = [s for s in FITS if s in F]
    t.check(len(both) >= 5 and all(FITS[s]["payload"] == F[s]["payload"] and FITS[s]["total"] == 0 and
                                   FITS[s]["width"] == F[s]["width"] for s in both),
            "a budget the frame fits gets the unbudgeted frame's bytes, total 0 (%d compared)" % len(both))
    e_same = [s for s in E if s in F]
    t.check(all(f["codec"] == 16 and f["width"] == 2000 for f in E.values()) and len(e_same) >= 5 and
            all(E[s]["total"] == F[s]["width"] for s in e_same),
            "engine encoding: codec 16 subsets of 2000 with the full count as total (%d compared)" % len(e_same))
    t.check(all(E[s]["payload"][:4] == b"FXE1" and int.from_bytes(E[s]["payload"][20:24], "little") == 2000
                for s in e_same), "the engine payload holds 2000 particles")
    r = await b1.request("subscribe", stream="flame")
    t.check(r["op"] == "subscribed" and "max_particles" not in r, "subscribing again without it: no max_particles")
    again = await collect(b1, 6)
    late = sorted(again)[2:]  # past any frame already on its way
    t.check(all(again[s]["total"] == 0 and again[s]["width"] > 2000 for s in late), "then full frames")
    for c in (full, b1, b2, fits, eng):
        await c.close()


BAD = [999, 4194305, 1500.5, -1000, 0, "2000", True, None, [2000], {"n": 2000}, 1e300]


async def test_bad_values(t):
    c = await Client.connect(D)
    await subscribed(t, c, "max_particles 1000", max_particles=1000)
    await collect(c, 1)
    for v in BAD:
        r = await c.request("subscribe", stream="flame", max_particles=v)
        t.check(r["op"] == "error" and r["code"] == "bad_request" and r.get("param") == "max_particles",
                "max_particles %s: bad_request, param max_particles (%s)" % (json.dumps(v), r.get("message")))
    r = await c.request("subscribe", stream="nope", max_particles=10)
    t.check(r.get("param") == "max_particles", "checked before the stream")
    r = await c.request("subscribe", stream="flame", encoding="bogus", max_particles=10)
    t.check(r.get("param") == "encoding", "checked after the encoding")
    lst = await c.request("list")
    flame = [s for s in lst.get("streams", []) if s["stream"] == "flame"]
    t.check(lst["op"] == "list" and flame and flame[0]["subscribers"] == 1, "the connection is usable, one subscriber")
    fs = await collect(c, 3)
    t.check(all(f["width"] == 1000 and f["total"] > 1000 for f in fs.values()), "the budget is as it was")
    await c.close()


async def test_fxctl(t):
    out = tempfile.mkdtemp(prefix="fxs-budget-")
    p = subprocess.run([FXCTL, "--url", D.url, "subscribe", "flame", "--frames", "3", "--max-particles", "5000",
                        "--out", out], capture_output=True, text=True, timeout=60)
    t.check(p.returncode == 0, "fxctl subscribe --max-particles 5000 --out (%s)" % p.stderr.strip()[:200])
    lines = [json.loads(x) for x in p.stdout.splitlines() if x.startswith("{")]
    t.check(lines and lines[0].get("op") == "subscribed" and lines[0].get("max_particles") == 5000,
            "fxctl prints the reply's max_particles")
    frames = [x for x in lines[1:] if x.get("kind") == 1]
    t.check(len(frames) == 3 and all(x["count"] == 5000 and x["total"] > 5000 for x in frames),
            "fxctl prints count 5000 and the total (%s)" % [(x.get("count"), x.get("total")) for x in frames])
    plys = sorted(f for f in os.listdir(out) if f.endswith(".ply"))
    counts = []
    for name in plys:
        with open(os.path.join(out, name), "rb") as f:
            head = f.read(512).split(b"end_header")[0].decode("ascii", "replace")
        counts += [int(x.split()[-1]) for x in head.splitlines() if x.startswith("element vertex")]
    t.check(len(plys) == 3 and counts == [5000] * 3, "the saved PLYs hold the 5000 decoded particles (%s)" % counts)
    saved = [json.load(open(os.path.join(out, f))) for f in os.listdir(out) if f.endswith(".json")]
    t.check(len(saved) == 3 and all(x["total"] > 5000 for x in saved), "the saved lines carry the total")
    p = subprocess.run([FXCTL, "--url", D.url, "subscribe", "flame", "--frames", "1", "--max-particles", "999"],
                       capture_output=True, text=True, timeout=30)
    t.check(p.returncode == 2 and "--max-particles" in p.stderr, "fxctl --max-particles 999: a usage error")


async def test_fxload(t):
    report = os.path.join(tempfile.mkdtemp(prefix="fxs-budget-"), "run.json")
    p = subprocess.run([FXLOAD, "--url", D.url, "--streams", "flame", "--connections", "4", "--duration", "3",
                        "--max-particles", "2000", "--json", report, "--quiet"], capture_output=True, text=True,
                       timeout=60)
    t.check(p.returncode == 0, "fxload --max-particles 2000 (%s)" % p.stderr.strip()[:200])
    with open(report) as f:
        rep = json.load(f)
    t.check(rep["options"].get("max_particles") == 2000, "the report names the budget")
    k = rep["streams"][0]["kinds"].get("1", {}) if rep.get("streams") else {}
    per_frame = k.get("bytes", 0) / max(1, k.get("frames", 0))
    t.check(k.get("frames", 0) > 10 and per_frame < 16000,
            "%d particle frames of %.0f B: 2000 particles, not the whole flame's ~10k" % (k.get("frames", 0), per_frame))


if __name__ == "__main__":
    D = Daemon()
    s = Suite("test_budget")
    try:
        s.run([test_subsets, test_bad_values, test_fxctl, test_fxload], timeout=120)
    finally:
        D.stop()
