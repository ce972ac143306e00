"""test_cluster_fanout.py — cluster mode, second part: leases and frames through Redis. One
redis-server (started here on a free loopback port, no persistence) and three daemons: p and q
with --role compute, e with --role edge; subscribers on all three.

Checks: the edge opens no device and holds no lease; a stream created on the edge is computed by
exactly one compute daemon and its frames reach subscribers on all three daemons (same rev,
increasing numbers, the edge's own channel number), with the latest frame kept in Redis, which a
new subscriber on a daemon relaying nothing of the stream yet gets at once; a set through the
edge reaches every subscriber's frames; new streams spread over both compute daemons; fxload
with three --url spreads its subscribers over the three daemons; kill -9 of the owner: frames
resume on the other daemons within 5 s through the other compute daemon, with the same
parameters and rev, nothing re-created, frame numbers going on; an owner paused (SIGSTOP) past
its lease is replaced, and after SIGCONT no frame of it reaches Redis's channel (fencing) and it
stops computing the stream; SIGTERM of an owner hands its streams over at once (well inside the
lease's TTL); Redis killed: the owner's subscribers keep getting frames, changes are refused,
and after Redis is back (empty) the cluster converges: changes accepted, one owner, frames at
the edge again. Every wait is bounded."""
import asyncio
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fxtest import DAEMON, Client, Suite, parse_frame  # noqa: E402
from test_cluster import (LEASE_TTL_S, SMALL, Redis, cluster_daemon, frame_made_after, get, http_json,  # noqa: E402
                          leases, metric, names, owner, require_redis, stop_all, until)

R = None
P = Q = E = None  # compute, compute, edge
STREAM = "w"
FXLOAD = os.path.join(os.path.dirname(DAEMON), "fxload")


def compute(node):
    return cluster_daemon(R, node, "--role", "compute")


def relaying(d):
    return http_json(d, "/healthz").get("cluster", {}).get("relaying", [])


async def owner_of(stream, timeout=10.0):
    async def find():
        held = [d for d in (P, Q, E) if d.proc.poll() is None and stream in leases(d)]
        return held[0] if len(held) == 1 else None

    return await until(find, timeout=timeout, step=0.1)


async def subscriber(d, stream=STREAM, **opts):
    c = await Client.connect(d)
    # Unbounded receive queue: a subscriber that stops reading would otherwise stop reading the
    # socket too, and its close would wait out the close timeouts behind unread frames.
    c.ws.max_queue = None
    r = await c.request("subscribe", stream=stream, **opts)
    c.channel = r.get("channel")
    return c


async def frames_after(c, seq, n=1, timeout=10.0, kind=2):
    """The next n frames of kind with a number above seq (older ones still queued are skipped)."""
    out, deadline = [], time.monotonic() + timeout
    while len(out) < n:
        f = await c.frame(timeout=max(0.01, deadline - time.monotonic()), kind=kind)
        if f["seq"] > seq:
            out.append(f)
    return out


class ChannelTap:
    """Reads Redis's frame channel of a stream directly: (arrival time, seq) of every texture frame."""

    def __init__(self, stream):
        self.sock = socket.create_connection(("127.0.0.1", R.port), timeout=30)
        ch = "fxs:frames:0:" + stream
        self.sock.sendall(("*2\r\n$9\r\nSUBSCRIBE\r\n$%d\r\n%s\r\n" % (len(ch), ch)).encode())
        self.f = self.sock.makefile("rb")
        self.seen, self.stop = [], False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _bulk(self):
        n = int(self.f.readline()[1:-2])
        return self.f.read(n + 2)[:-2]

    def _run(self):
        try:
            while not self.stop:
                head = self.f.readline()
                if not head.startswith(b"*"):
                    return
                parts = [self._bulk() if self.f.peek(1)[:1] == b"$" else self.f.readline() for _ in range(int(head[1:-2]))]
                f = parse_frame(parts[2]) if parts[0] == b"message" else None
                if f and f["kind"] == 2:
                    self.seen.append((time.monotonic(), f["seq"]))
        except (OSError, ValueError):
            pass

    def close(self):
        self.stop = True
        self.sock.close()


async def test_roles(t):
    """The edge computes nothing; the compute daemons say their role."""
    h = http_json(E, "/healthz")
    t.check(h["device"] == "none" and h["cluster"]["role"] == "edge" and h["cluster"]["leases"] == [],
            "e: role edge, no OpenCL device, no lease (%s)" % h["cluster"])
    t.check([http_json(d, "/healthz")["cluster"]["role"] for d in (P, Q)] == ["compute", "compute"],
            "p and q: role compute")
    t.check(metric(E, 'fxs_cluster_info{node="e",role="edge"}') == 1 and metric(E, "fxs_cluster_leases") == 0,
            "/metrics: fxs_cluster_info names node and role, fxs_cluster_leases 0")


async def test_fanout(t):
    """A stream created on the edge: one owner, frames on all three daemons, sets reach them."""
    e = await Client.connect(E)
    r = await e.request("create", effect="energy_wave", stream=STREAM, params=SMALL)
    t.check(r.get("op") == "created", "create w through the edge (%s)" % r.get("op"))
    subs = {d: await subscriber(d) for d in (E, P, Q)}
    got = {}
    for d, c in subs.items():
        got[d] = (await frames_after(c, 0, n=3, timeout=15))
    o = await owner_of(STREAM)
    t.check(o in (P, Q), "exactly one compute daemon holds w's lease (%s)" % (o and http_json(o, "/healthz")["cluster"]["node"]))
    others = [d for d in (E, P, Q) if d is not o]
    t.check(all(STREAM in relaying(d) for d in others), "the two others relay it")
    ok = all(f["param_rev"] == 1 and f["channel"] == subs[d].channel for d in got for f in got[d]) and \
        all([f["seq"] for f in fs] == sorted({f["seq"] for f in fs}) for fs in got.values())
    t.check(ok, "frames on all three: rev 1, each daemon's own channel number, increasing numbers")
    t.check(metric(E, "fxs_cluster_frames_relayed_total") > 0 and metric(o, "fxs_cluster_frames_published_total") > 0,
            "the owner publishes, the edge relays (fxs_cluster_frames_*)")
    latest = R.cmd("EXISTS", "fxs:frame:%s:2" % STREAM)
    t.check(latest == 1, "Redis keeps the latest frame (fxs:frame:w:2) for new subscribers")
    s = await e.request("set", stream=STREAM, params={"alpha": 1.25})
    t.check(s.get("rev") == 2, "set through the edge: rev 2")
    ok = True
    for c in subs.values():
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            f = (await frames_after(c, 0))[0]
            if f["param_rev"] == 2:
                break
        ok = ok and f["param_rev"] == 2
    t.check(ok, "every subscriber's frames come at rev 2")
    for c in subs.values():
        await c.close()
    await e.close()


async def test_encodings(t):
    """Subscribers of the engine encoding on daemons that do not compute the stream: the owner
    makes both encodings, the same frame has the same number in both everywhere, Redis keeps
    the latest of each, and a new engine subscriber elsewhere gets it at once."""
    e = await Client.connect(E)
    await e.request("create", effect="energy_wave", stream="enc", params=SMALL)
    eng, dft = await subscriber(E, "enc", encoding="engine"), await subscriber(E, "enc")
    fe = await frames_after(eng, 0, n=4, timeout=15)
    fd = await frames_after(dft, 0, n=4, timeout=15)
    t.check(all(f["codec"] == 16 and f["payload"][:4] == b"FXE1" for f in fe) and all(f["codec"] == 1 for f in fd),
            "the edge relays engine frames (codec 16) to one subscriber and EXR (codec 1) to the other")
    t.check([f["seq"] for f in fe] == sorted({f["seq"] for f in fe}), "engine frames' numbers increase")
    later = await frames_after(dft, fe[-1]["seq"] - 1, n=1, timeout=10)
    t.check(later[0]["seq"] >= fe[-1]["seq"] and fd[0]["seq"] <= fe[-1]["seq"] + 30,
            "both encodings number the same frames alike (engine %d, default %d..%d)" % (fe[-1]["seq"], fd[0]["seq"], later[0]["seq"]))
    t.check(R.cmd("EXISTS", "fxs:frame:enc:2:engine") == 1 and R.cmd("EXISTS", "fxs:frame:enc:2") == 1,
            "Redis keeps the latest frame of each encoding (fxs:frame:enc:2, fxs:frame:enc:2:engine)")
    o = await owner_of("enc")
    other = Q if o is P else P
    c = await subscriber(other, "enc", encoding="engine")
    f = await c.frame(timeout=5, kind=2)
    t.check(f["codec"] == 16 and f["channel"] == c.channel, "a new engine subscriber on the other compute daemon gets one at once")
    for x in (eng, dft, c):
        await x.close()
    await e.request("destroy", stream="enc")
    t.check(R.cmd("EXISTS", "fxs:frame:enc:2:engine") == 0, "destroy removes the engine frames from Redis")
    await e.close()


def idle_scores():
    """Both compute daemons' published scores (fxs:computes) are their leases' cost alone,
    LEASE_STREAM_COST (0.05) each: what an earlier test's work added has decayed."""
    z = R.cmd("ZRANGE", "fxs:computes", 0, -1, "WITHSCORES")
    score = dict(zip(z[0::2], (float(v) for v in z[1::2])))
    return all(d in score and score[d] <= 0.05 * len(leases(h)) + 0.02 for d, h in (("p", P), ("q", Q)))


async def test_spread(t):
    """Streams with subscribers spread over both compute daemons (least loaded takes). A daemon
    takes new streams while its score (engine load + 0.05 a lease) is the least, so the streams
    are made once both daemons' scores are back to their leases' cost (the engine time an
    earlier test left on one would otherwise rightly send all four to the other), and one at a
    time, so each is taken on scores that count the work of the streams before it (four made at
    once were all taken by one daemon in a quiet CI run)."""
    t.check(await until(idle_scores, timeout=10), "both compute daemons idle first: %s" %
            R.cmd("ZRANGE", "fxs:computes", 0, -1, "WITHSCORES"))
    e = await Client.connect(E)
    made, subs = ["sp%d" % i for i in range(4)], []
    for n in made:
        await e.request("create", effect="energy_wave", stream=n, params=SMALL)
        subs.append(await subscriber(E, n))
        await frames_after(subs[-1], 0, timeout=15)
        await owner(n, [P, Q])
    held = {d: [n for n in made if n in leases(d)] for d in (P, Q)}
    t.check(sum(len(v) for v in held.values()) == 4 and all(held.values()),
            "4 streams over 2 compute daemons: %s" % sorted(len(v) for v in held.values()))
    for n in made:
        await e.request("destroy", stream=n)
    t.check(not any(R.cmd("EXISTS", "fxs:lease:" + n) for n in made), "destroy removes their leases from Redis")
    for c in subs:
        await c.close()
    await e.close()


async def test_latest_frame(t):
    """A new subscriber on a daemon that relays nothing of the stream yet gets its latest frame
    at once, from Redis (a 1 fps stream: the next one is up to a second away)."""
    e = await Client.connect(E)
    await e.request("create", effect="energy_wave", stream="slow", params=dict(SMALL, fps=1))
    first = await subscriber(E, "slow")
    seen = (await frames_after(first, 0, timeout=15))[0]
    o = await owner_of("slow")
    other = Q if o is P else P
    start, start_wall = time.monotonic(), time.time()
    c = await subscriber(other, "slow")
    f = await c.frame(timeout=5, kind=2)
    took = time.monotonic() - start
    t.check(took < 0.5 and f["server_time_us"] < start_wall * 1e6 and f["seq"] >= seen["seq"] and
            f["channel"] == c.channel, "a subscriber on the other compute daemon gets, in %.2f s, the latest frame, "
            "made before it subscribed (seq %d)" % (took, f["seq"]))
    for x in (first, c):
        await x.close()
    await e.request("destroy", stream="slow")
    await e.close()


async def test_fxload(t):
    """fxload --url repeated spreads its subscribers over the daemons; every one serves w."""
    sent = 'fxs_stream_frames_sent_total{stream="%s",effect="energy_wave"}' % STREAM
    before = [metric(d, sent) or 0 for d in (E, P, Q)]
    run = subprocess.run([FXLOAD, "--url", E.url, "--url", P.url, "--url", Q.url, "--connections", "6",
                          "--streams", STREAM, "--duration", "3", "--json", "-"], capture_output=True, text=True,
                         timeout=60)
    rep = json.loads(run.stdout) if run.stdout.startswith("{") else {}
    grew = [(metric(d, sent) or 0) > b for d, b in zip((E, P, Q), before)]
    t.check(run.returncode == 0 and rep.get("options", {}).get("urls") == [E.url, P.url, Q.url],
            "fxload with three --url: exit 0, the report names them (%d%s)" %
            (run.returncode, run.returncode and run.stderr[-200:] or ""))
    t.check(all(grew), "each daemon sent w's frames to its share of the subscribers (%s)" % grew)


async def test_failover(t):
    """kill -9 of the owner: the other compute daemon takes over with the same params and rev."""
    global P, Q
    o = await owner_of(STREAM)
    before = await get(E, STREAM)
    subs = [await subscriber(d) for d in (E, P, Q) if d is not o]
    last = [(await frames_after(c, 0))[0]["seq"] for c in subs]
    node = http_json(o, "/healthz")["cluster"]["node"]
    o.stop(signal.SIGKILL)
    killed, killed_wall = time.monotonic(), time.time()
    after = [await frame_made_after(c, killed_wall, timeout=15) for c in subs]
    took = time.monotonic() - killed
    n = await owner_of(STREAM)
    t.check(n is not None and n is not o, "the other compute daemon holds w now")
    t.check(took < 5.0, "frames resume on the other daemons %.1f s after the kill (within 5 s)" % took)
    t.check(all(f["param_rev"] == before["rev"] for f in after), "at the same rev (%d)" % before["rev"])
    g = await get(E, STREAM)
    t.check(g.get("rev") == before["rev"] and g.get("params") == before["params"], "same params and rev in get")
    t.check(all(f["seq"] > s for f, s in zip(after, last)), "frame numbers go on from the old owner's")
    # the killed daemon comes back (same node id) for what follows
    if o is P:
        P = compute(node)
    else:
        Q = compute(node)
    for c in subs:
        await c.close()


async def test_fencing(t):
    """An owner paused past its lease is replaced, and cannot publish after it resumes."""
    o = await owner_of(STREAM)
    other = Q if o is P else P
    e = await subscriber(E)
    await frames_after(e, 0)
    tap = ChannelTap(STREAM)
    lost_before = metric(o, "fxs_cluster_leases_lost_total") or 0
    o.proc.send_signal(signal.SIGSTOP)
    try:
        stopped = time.monotonic()
        taken = await until(lambda: STREAM in leases(other), timeout=10, step=0.1)
        t.check(taken, "the other compute daemon takes w over %.1f s after the pause" % (time.monotonic() - stopped))
        f = await frame_made_after(e, time.time() - 0.2)
        t.check(bool(f), "the edge's subscriber gets frames of the new owner")
        resumed_from = tap.seen[-1][1] if tap.seen else 0
    finally:
        o.proc.send_signal(signal.SIGCONT)
    resumed = time.monotonic()
    await asyncio.sleep(2.5)
    tap.close()
    after = [s for when, s in tap.seen if when >= resumed]
    t.check(len(after) >= 10 and after == sorted(set(after)) and after[0] > resumed_from,
            "after SIGCONT, Redis's channel carries only the new owner's frames: %d, increasing from %d (%s)" %
            (len(after), resumed_from, after[:12]))
    t.check(STREAM not in leases(o) and STREAM in leases(other), "the resumed daemon no longer holds w")
    lost = metric(o, "fxs_cluster_leases_lost_total") or 0
    t.check(lost > lost_before, "it counts the lease lost (fxs_cluster_leases_lost_total %d)" % lost)
    await e.close()


async def test_handover(t):
    """SIGTERM: the owner gives its leases up; the other compute daemon takes over at once."""
    global P, Q
    o = await owner_of(STREAM)
    e = await subscriber(E)
    last = (await frames_after(e, 0))[0]["seq"]
    node = http_json(o, "/healthz")["cluster"]["node"]
    start, start_wall = time.monotonic(), time.time()
    t.check(o.stop() == 0, "the owner exits 0 on SIGTERM")
    f = await frame_made_after(e, start_wall)
    took = time.monotonic() - start
    t.check(f["seq"] > last, "frame numbers go on (%d after %d)" % (f["seq"], last))
    t.check(took < LEASE_TTL_S - 0.5, "frames resume %.1f s after, inside the lease's TTL (%.0f s)" % (took, LEASE_TTL_S))
    if o is P:
        P = compute(node)
    else:
        Q = compute(node)
    await e.close()


async def test_redis_restart(t):
    """Redis killed: the owner's subscribers keep their frames, changes are refused; Redis back
    (empty): the cluster converges."""
    global R
    o = await owner_of(STREAM)
    c, e = await subscriber(o), await subscriber(E)
    last = (await frames_after(c, 0))[0]["seq"]
    lost = [metric(o, "fxs_cluster_leases_lost_total"), metric(o, "fxs_cluster_frames_fenced_total")]
    R.kill()
    await asyncio.sleep(LEASE_TTL_S + 0.5)
    seqs = [f["seq"] for f in await frames_after(c, 0, n=5)]
    t.check(seqs == sorted(set(seqs)), "the owner's subscriber keeps getting frames past the TTL")
    r = await e.request("set", stream=STREAM, params={"alpha": 1.5})
    t.check(r.get("code") == "unavailable", "a set through the edge is refused (%s)" % r.get("code"))
    R = Redis(port=R.port)
    t.check(await until(lambda: R.cmd("EXISTS", "fxs:stream:" + STREAM) == 1, timeout=10, step=0.1),
            "Redis is seeded again with the daemons' state")

    async def accepted():
        r = await e.request("set", stream=STREAM, params={"alpha": 1.5})
        return r if r.get("op") == "params" else None

    s = await until(accepted, timeout=10, step=0.2)
    t.check(s is not None, "changes are accepted again")
    n = await owner_of(STREAM)
    t.check(n is o, "the owner kept w (it renews before anyone may take streams in the new Redis)")
    now = [metric(o, "fxs_cluster_leases_lost_total"), metric(o, "fxs_cluster_frames_fenced_total")]
    t.check(now == lost, "it never let go of it: leases lost and frames fenced unchanged (%s, %s)" % (lost, now))
    ok = False
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and not ok:
        f = (await frames_after(e, 0, timeout=10))[0]
        ok = s is not None and f["param_rev"] == s["rev"]
    t.check(ok, "the edge's subscriber gets frames of the new rev again")
    seqs = [f["seq"] for f in await frames_after(e, 0, n=3)]
    t.check(seqs[0] > last, "their numbers went on (%d after %d)" % (seqs[0], last))
    t.check(await names(E) == await names(P) == await names(Q), "all three list the same streams")
    await c.close()
    await e.close()


async def test_shutdown(t):
    codes = [d.stop() for d in (E, P, Q)]
    t.check(codes == [0, 0, 0], "SIGTERM: all three exit 0 (%s)" % codes)


if __name__ == "__main__":
    s = Suite("test_cluster_fanout")
    require_redis(s)
    R = Redis()
    try:
        P, Q = compute("p"), compute("q")
        E = cluster_daemon(R, "e", "--role", "edge")
        s.run([test_roles, test_fanout, test_spread, test_latest_frame, test_encodings, test_fxload, test_failover, test_fencing,
               test_handover, test_redis_restart, test_shutdown])
    finally:
        stop_all((P, Q, E), R)
