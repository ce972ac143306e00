"""test_cluster.py — cluster mode (--cluster), shared state (leases and frames through Redis are
in test_cluster_fanout.py). Three fxstreamd daemons on one redis-server (Debian's, started here
on a free loopback port, as the current user, in a temp dir, without persistence, killed at the
end), plus a second Redis with AOF (appendfsync
always) for one daemon, and a third with a password.

Checks: the first daemon seeds the empty database once and all list the same streams; a create
on A, a set through B and a get through C give the same params and rev, the same as Redis
holds; C's subscriber gets the params event of B's set, A's clients the created/destroyed events
of B's and C's changes; concurrent sets through two daemons all succeed with distinct
consecutive revs and lose no update; a set whose daemon is behind Redis is made again on
Redis's document; racing creates: one wins, everywhere; a reset through B restarts A's stream;
a reload that finds other params at the same rev re-creates the effect; a second daemon given
a node id in use refuses to start, saying so; Redis closing the daemons' connections while idle
or under a change: each change is made, once; FLUSHALL: the daemons seed Redis again with their
state within seconds and go on; leases, the change counter and revisions in Redis that do not
parse or cannot be right are counted and repaired; Redis killed: changes
answer unavailable naming the cluster, /healthz and /metrics say the link is down, streams keep
sending frames and reads keep working; Redis back empty: changes are accepted again within
seconds and the state the daemons had is in Redis again (re-seeded); Redis hung (SIGSTOP): one
change waits the 1 s timeout, the next are refused at once, frames go on; Redis back from its AOF
in an older state: Redis wins, the daemon goes back to it and tells its subscribers; a kill -9 of
Redis with appendfsync always loses no acknowledged change; flags and configuration errors; a
password from FXS_REDIS_PASSWORD; SIGTERM with Redis up or down exits 0. Every wait is bounded;
a missing redis-server fails the suite with a message. About 60 s (more with a cold PoCL cache)."""
import asyncio
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fxtest import DAEMON, Client, Daemon, Suite, free_port  # noqa: E402

REDIS = shutil.which("redis-server") or "/usr/bin/redis-server"
SMALL = {"width": 32, "height": 24, "fps": 20}  # cheap frames: several daemons share 2 cores
LEASE_TTL_S = 3.0  # server/lease.h
CLAIM_TTL_S = 3.0  # a node id's claim, CLUSTER_MEMBER_TTL_S in server/cluster.h
R = None  # the shared Redis
TEMP_DIRS = []  # Redis data dirs, removed at the end
A = B = C = None  # its daemons, node ids a, b, c


def resp_read(f):
    """One RESP2 reply from a binary file object."""
    line = f.readline()
    if not line:
        raise ConnectionError("redis closed the connection")
    kind, rest = line[:1], line[1:-2]
    if kind == b"+":
        return rest.decode()
    if kind == b"-":
        raise RuntimeError("redis error: " + rest.decode())
    if kind == b":":
        return int(rest)
    if kind == b"$":
        n = int(rest)
        if n < 0:
            return None
        data = f.read(n + 2)
        return data[:-2].decode()
    if kind == b"*":
        n = int(rest)
        return None if n < 0 else [resp_read(f) for _ in range(n)]
    raise RuntimeError("unexpected RESP %r" % line)


def resp(*args):
    """One command in Redis's protocol."""
    return ("*%d\r\n" % len(args) + "".join("$%d\r\n%s\r\n" % (len(str(a).encode()), a) for a in args)).encode()


class Redis:
    """A redis-server on 127.0.0.1:port (free by default), data in dir (a temp dir by default)."""

    def __init__(self, port=None, data_dir=None, aof=False, password=None):
        self.port = port or free_port()
        self.dir = data_dir or tempfile.mkdtemp(prefix="fxs-redis-")
        TEMP_DIRS.append(self.dir)
        self.password = password
        self.url = "redis://127.0.0.1:%d" % self.port
        args = [REDIS, "--port", str(self.port), "--bind", "127.0.0.1", "--dir", self.dir, "--save", "",
                "--daemonize", "no", "--logfile", os.path.join(self.dir, "redis.log"),
                "--enable-debug-command", "local"]
        args += ["--appendonly", "yes", "--appendfsync", "always"] if aof else ["--appendonly", "no"]
        if password:
            args += ["--requirepass", password]
        self.proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=self.dir)
        try:
            self._wait_ready()
        except BaseException:
            self.kill()  # never left running behind a failed start
            raise

    def _wait_ready(self):
        deadline = time.monotonic() + 10
        while True:
            try:
                if isinstance(self.cmd("DBSIZE"), int):  # refused (LOADING) while an AOF is read back
                    return
            except (OSError, ConnectionError, RuntimeError):
                pass
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError("redis-server did not start on port %d (%s/redis.log)" % (self.port, self.dir))
            time.sleep(0.05)

    def cmd(self, *args):
        with socket.create_connection(("127.0.0.1", self.port), timeout=5) as s:
            f = s.makefile("rb")
            cmds = ([["AUTH", self.password]] if self.password else []) + [list(args)]
            for c in cmds:
                s.sendall(resp(*c))
                reply = resp_read(f)
            return reply

    def kill(self):
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(10)

    def stream(self, name):
        """Redis's copy of a stream: (effect, rev, params) or None."""
        h = self.cmd("HMGET", "fxs:stream:" + name, "effect", "rev", "params")
        return None if h[0] is None else (h[0], int(h[1]), json.loads(h[2]))


def cluster_daemon(redis, node, *args, env=None):
    return Daemon("--cluster", redis.url, "--node-id", node, *args, env=env)


def http_json(d, path):
    with urllib.request.urlopen(d.http + path, timeout=10) as r:
        return json.loads(r.read().decode())


def http_text(d, path):
    with urllib.request.urlopen(d.http + path, timeout=10) as r:
        return r.read().decode()


def metric(d, name):
    """The value of a metric line (with its labels, if any) in d's /metrics, or None."""
    for line in http_text(d, "/metrics").splitlines():
        if line.split(" ")[0] == name:
            return float(line.split(" ")[1])
    return None


async def until(fn, timeout=8.0, step=0.05):
    """Calls fn (sync or async) until it returns something true; returns its last value."""
    deadline = time.monotonic() + timeout
    while True:
        v = fn()
        if asyncio.iscoroutine(v):
            v = await v
        if v or time.monotonic() > deadline:
            return v
        await asyncio.sleep(step)


async def names(d):
    c = await Client.connect(d)
    r = await c.request("list")
    await c.close()
    return [s["stream"] for s in r["streams"]]


async def get(d, stream):
    c = await Client.connect(d)
    r = await c.request("get", stream=stream)
    await c.close()
    return r


async def get_at(d, stream, rev, timeout=8.0):
    """d's get of stream once it is at rev (or the last answer after timeout)."""
    deadline = time.monotonic() + timeout
    while True:
        g = await get(d, stream)
        if g.get("rev") == rev or time.monotonic() > deadline:
            return g
        await asyncio.sleep(0.05)


async def event(c, op, stream, timeout=8.0, **match):
    """The next event (no id) of op for stream on c with the given members, or None."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            m = await c.text(deadline - time.monotonic())
        except asyncio.TimeoutError:
            return None
        if m.get("op") == op and m.get("stream") == stream and "id" not in m and \
                all(m.get(k) == v for k, v in match.items()):
            return m
    return None


async def frame_made_after(c, wall, timeout=10.0, kind=2):
    """The next frame of kind computed after the wall-clock time `wall` (its header's
    server_time_us; daemons and test share the clock), skipping frames still queued; None when
    none comes within timeout."""
    deadline = time.monotonic() + timeout
    try:
        while True:
            f = await c.frame(timeout=max(0.01, deadline - time.monotonic()), kind=kind)
            if f["server_time_us"] > wall * 1e6:
                return f
    except asyncio.TimeoutError:
        return None


def bad_values(what):
    """fxs_cluster_bad_values_total{what=...} summed over A, B and C."""
    return sum(metric(d, 'fxs_cluster_bad_values_total{what="%s"}' % what) or 0 for d in (A, B, C))


def leases(d):
    return http_json(d, "/healthz").get("cluster", {}).get("leases", [])


async def owner(stream, daemons, timeout=10.0):
    """The daemon among daemons holding the stream's lease (computing it), or None."""
    async def find():
        held = [d for d in daemons if stream in leases(d)]
        return held[0] if len(held) == 1 else None

    return await until(find, timeout=timeout, step=0.1)


# ---- one Redis, three daemons ----

async def test_seeded(t):
    """The first daemon seeds the empty database with the built-in streams, once."""
    lists = [await names(d) for d in (A, B, C)]
    t.check(lists[0] == ["energy", "flame", "eye"] and lists[0] == lists[1] == lists[2],
            "the three daemons list the same seeded streams %s" % lists)
    t.check(R.cmd("ZRANGE", "fxs:streams", "0", "-1") == ["energy", "flame", "eye"] and
            R.cmd("GET", "fxs:seeded") in ("a", "b", "c"),
            "Redis holds them, seeded once by one daemon (fxs:seeded = %s)" % R.cmd("GET", "fxs:seeded"))
    for d, node in ((A, "a"), (B, "b"), (C, "c")):
        h = http_json(d, "/healthz")
        cl = h.get("cluster", {})
        t.check(h["status"] == "ok" and cl.get("node") == node and cl.get("link") == "up" and cl.get("in_sync") and
                cl.get("redis") == R.url, "/healthz of %s: cluster %s" % (node, cl))


async def test_shared_state(t):
    """Create on A, set through B, get through C: the same params and rev, as Redis holds them."""
    a = await Client.connect(A)
    r = await a.request("create", effect="energy_wave", stream="c1", params=SMALL)
    t.check(r.get("op") == "created" and r.get("rev") == 1, "create c1 on A (%s)" % r)
    t.check(R.stream("c1") is not None and R.stream("c1")[:2] == ("energy_wave", 1), "Redis has c1 at rev 1")
    async def listed():
        return "c1" in await names(B) and "c1" in await names(C)

    t.check(await until(listed), "B and C list c1")
    b = await Client.connect(B)
    s = await b.request("set", stream="c1", params={"alpha": 1.5})
    t.check(s.get("op") == "params" and s.get("rev") == 2 and s["params"]["alpha"] == 1.5, "set alpha through B: rev 2")
    g = await get_at(C, "c1", 2)
    t.check(g.get("rev") == 2 and g.get("params") == s.get("params"), "get through C: rev 2 and B's params")
    ga = await get(A, "c1")
    t.check(ga.get("rev") == 2 and ga.get("params") == s.get("params"), "get through A: the same")
    t.check(R.stream("c1") == ("energy_wave", 2, s["params"]), "Redis holds the same document at rev 2")
    await a.close()
    await b.close()


async def test_events(t):
    """Events of changes made elsewhere reach local clients as for local changes."""
    c = await Client.connect(C)
    await c.request("subscribe", stream="c1")
    b = await Client.connect(B)
    s = await b.request("set", stream="c1", params={"beta": 2})
    ev = await event(c, "params", "c1", rev=s.get("rev"))
    t.check(ev is not None and ev["params"] == s["params"], "C's subscriber gets the params event of B's set (%s)"
            % (ev and ev.get("rev")))
    a = await Client.connect(A)  # A's client: created and destroyed events of other daemons' changes
    r = await b.request("create", effect="energy_wave", stream="c2", params=SMALL)
    ev = await event(a, "created", "c2")
    t.check(r.get("op") == "created" and ev is not None and ev.get("effect") == "energy_wave" and ev.get("rev") == 1,
            "A's client gets the created event of B's create (%s)" % ev)
    await a.request("subscribe", stream="c2")
    d = await c.request("destroy", stream="c2")
    gone = await event(a, "unsubscribed", "c2", reason="destroyed")
    ev = await event(a, "destroyed", "c2")
    t.check(d.get("op") == "destroyed" and gone is not None and ev is not None,
            "destroy on C: A's subscriber is unsubscribed (destroyed) and gets the destroyed event")
    t.check("c2" not in await names(A) and "c2" not in await names(B), "c2 is gone from A's and B's lists")
    t.check(R.stream("c2") is None and "c2" not in R.cmd("ZRANGE", "fxs:streams", "0", "-1"), "and from Redis")
    for x in (a, b, c):
        await x.close()


async def test_no_budget(t):
    """subscribe's max_particles is refused in cluster mode, saying why (frames cross Redis per
    encoding only): a budgeted subscriber never receives full frames instead."""
    c = await Client.connect(B)
    r = await c.request("subscribe", stream="flame", max_particles=5000)
    t.check(r.get("op") == "error" and r.get("code") == "bad_request" and r.get("param") == "max_particles" and
            "cluster mode" in r.get("message", ""), "max_particles in cluster mode: bad_request saying why (%s)" % r)
    r = await c.request("subscribe", stream="flame")
    t.check(r.get("op") == "subscribed" and "max_particles" not in r, "the connection goes on: subscribe without it")
    await c.close()


async def test_concurrent_sets(t):
    """Sets through two daemons at once: all succeed, distinct consecutive revs, no update lost."""
    base = (await get(A, "c1"))["rev"]
    a, b = await Client.connect(A), await Client.connect(B)
    n = 12

    async def run(cl, name, values):
        return [await cl.request("set", stream="c1", params={name: v}) for v in values]

    ra, rb = await asyncio.gather(run(a, "alpha", [1 + i / 10 for i in range(n)]),
                                  run(b, "beta", [1 + i / 8 for i in range(n)]))
    replies = ra + rb
    revs = sorted(r.get("rev", -1) for r in replies)
    t.check(all(r.get("op") == "params" for r in replies), "every set through A and B succeeded %s" %
            [r.get("message") for r in replies if r.get("op") != "params"][:2])
    t.check(revs == list(range(base + 1, base + 1 + 2 * n)), "distinct consecutive revs %d..%d (%s)" %
            (base + 1, base + 2 * n, revs))
    want = (1 + (n - 1) / 10, 1 + (n - 1) / 8)
    g = await get_at(C, "c1", base + 2 * n)
    t.check(g.get("rev") == base + 2 * n and (g["params"]["alpha"], g["params"]["beta"]) == want,
            "C ends with both last values, nothing lost (alpha, beta = %s at rev %s)" %
            ((g["params"]["alpha"], g["params"]["beta"]), g.get("rev")))
    red = R.stream("c1")
    t.check(red[1] == base + 2 * n and (red[2]["alpha"], red[2]["beta"]) == want, "Redis holds the same")
    await a.close()
    await b.close()


async def test_rebase(t):
    """A set validated on a document older than Redis's is made again on Redis's document."""
    effect, rev, params = R.stream("c1")
    newer = dict(params, alpha=7.0)
    R.cmd("HSET", "fxs:stream:c1", "rev", str(rev + 5), "params", json.dumps(newer))  # behind every daemon's back
    before = metric(A, "fxs_cluster_rebases_total")
    a = await Client.connect(A)
    s = await a.request("set", stream="c1", params={"beta": 3})
    t.check(s.get("rev") == rev + 6 and s["params"]["alpha"] == 7.0 and s["params"]["beta"] == 3,
            "A's set is made on Redis's document: rev %s, alpha %s, beta %s" %
            (s.get("rev"), s.get("params", {}).get("alpha"), s.get("params", {}).get("beta")))
    t.check(metric(A, "fxs_cluster_rebases_total") == before + 1, "and counted in fxs_cluster_rebases_total")
    g = await get_at(C, "c1", rev + 6)
    t.check(g.get("params") == s.get("params"), "C follows (rev %s)" % g.get("rev"))
    await a.close()


async def test_reload_same_rev(t):
    """A reload that finds other params at the same rev (Redis's history differs from the
    daemon's) takes them: the engine re-creates the effect, frames change size."""
    a = await Client.connect(A)
    await a.request("subscribe", stream="c1")
    f = await a.frame(kind=2)
    effect, rev, params = R.stream("c1")
    R.cmd("HSET", "fxs:stream:c1", "params", json.dumps(dict(params, width=48)))  # same rev, no message
    killed = R.cmd("CLIENT", "KILL", "TYPE", "pubsub")  # every follower loses its link, reconnects, reloads
    width = None
    deadline = time.monotonic() + 10
    while width != 48 and time.monotonic() < deadline:
        width = (await a.frame(kind=2))["width"]
    g = await get(A, "c1")
    t.check(f["width"] == 32 and killed >= 3 and width == 48 and g.get("rev") == rev and g["params"]["width"] == 48,
            "after the reload A's frames are 48 wide (were %s), rev still %s" % (f["width"], g.get("rev")))
    await a.request("unsubscribe", stream="c1")
    await a.close()


async def test_create_race(t):
    """Two daemons create the same name at once: one wins, and every daemon has the winner's."""
    a, b = await Client.connect(A), await Client.connect(B)
    ra, rb = await asyncio.gather(a.request("create", effect="energy_wave", stream="race", params=SMALL),
                                  b.request("create", effect="flame", stream="race"))
    ops = sorted([ra.get("op"), rb.get("op")])
    loser = ra if ra.get("op") == "error" else rb
    t.check(ops == ["created", "error"] and loser.get("code") == "exists",
            "one created, one exists (%s, %s)" % (ra.get("op"), rb.get("code") or rb.get("op")))
    winner = "energy_wave" if ra.get("op") == "created" else "flame"

    async def effects():
        out = []
        for d in (A, B, C):
            c = await Client.connect(d)
            out.append([s["effect"] for s in (await c.request("list"))["streams"] if s["stream"] == "race"])
            await c.close()
        return out if all(e == [winner] for e in out) else None

    t.check(await until(effects) is not None and R.stream("race")[0] == winner,
            "A, B, C and Redis all have the winner's race (%s)" % winner)
    da, dc = await asyncio.gather(a.request("destroy", stream="race"), b.request("destroy", stream="race"))
    t.check(sorted([da.get("op"), dc.get("op")]) == ["destroyed", "error"], "racing destroys: exactly one destroyed")
    await a.close()
    await b.close()


async def test_reset(t):
    """A reset through B restarts the stream computed on A."""
    a = await Client.connect(A)
    await a.request("subscribe", stream="c1")
    last = 0
    deadline = time.monotonic() + 15
    while last < 1.0 and time.monotonic() < deadline:
        last = (await a.frame(kind=2))["sim_time"]
    b = await Client.connect(B)
    r = await b.request("reset", stream="c1")
    back = None
    deadline = time.monotonic() + 8
    while back is None and time.monotonic() < deadline:
        f = await a.frame(kind=2)
        if f["sim_time"] < last - 0.5:
            back = f["sim_time"]
    t.check(r.get("op") == "reset" and last >= 1.0 and back is not None,
            "reset through B: A's frames go back from sim_time %.2f to %s" % (last, back))
    await a.close()
    await b.close()


async def test_metrics(t):
    from prometheus_client.parser import text_string_to_metric_families
    fams = {f.name: f for f in text_string_to_metric_families(http_text(B, "/metrics"))}
    up = [s for s in fams["fxs_cluster_link_up"].samples] if "fxs_cluster_link_up" in fams else []
    t.check(up and up[0].labels == {"node": "b"} and up[0].value == 1, "fxs_cluster_link_up{node=\"b\"} 1")
    val = {n: fams[n].samples[0].value for n in ("fxs_cluster_changes", "fxs_cluster_applied", "fxs_cluster_reloads",
                                                 "fxs_cluster_in_sync") if n in fams}
    t.check(val.get("fxs_cluster_changes", 0) >= 3 and val.get("fxs_cluster_applied", 0) >= 3 and
            val.get("fxs_cluster_reloads", 0) >= 1 and val.get("fxs_cluster_in_sync") == 1,
            "B's cluster counters: %s" % val)


async def test_duplicate_node(t):
    """A daemon given the node id of a running daemon refuses to start, saying why; the running
    one goes on undisturbed."""
    start = time.monotonic()
    code, out = start_refused("--cluster", R.url, "--node-id", "b")
    t.check(code == 1 and 'node id "b"' in out and "--node-id" in out,
            "a second daemon with node id b exits 1 after %.1f s, naming it (%s)" %
            (time.monotonic() - start, out.strip()[-220:]))
    b = await Client.connect(B)
    await b.request("subscribe", stream="c1")
    f = await frame_made_after(b, time.time(), timeout=8)
    t.check(f is not None and http_json(B, "/healthz")["cluster"]["node"] == "b",
            "b goes on: its subscriber of c1 gets new frames")
    await b.close()
    # A daemon paused past its claim's TTL while another starts with its node id stops when it resumes.
    first = cluster_daemon(R, "twin", "--role", "edge")
    first.proc.send_signal(signal.SIGSTOP)
    try:
        await asyncio.sleep(CLAIM_TTL_S + 0.5)
        second = cluster_daemon(R, "twin", "--role", "edge")
    finally:
        first.proc.send_signal(signal.SIGCONT)
    try:
        code = first.proc.wait(timeout=5)
    except subprocess.TimeoutExpired:
        code = None
    t.check(code == 1 and 'node id "twin" was taken by another fxstreamd' in first.log(),
            "one paused past its claim while another started with its node id exits 1 when it resumes, saying why "
            "(%s: %s)" % (code, first.log().strip()[-160:]))
    t.check(http_json(second, "/healthz")["cluster"]["node"] == "twin" and second.stop() == 0,
            "the other one goes on")


async def test_idle_links(t):
    """Redis closes the daemons' command connections while idle (CLIENT KILL TYPE normal, its
    `timeout`), or with a change on its way: each change is made, once."""
    a = await Client.connect(A)
    base = (await get(A, "c1"))["rev"]
    killed = R.cmd("CLIENT", "KILL", "TYPE", "normal")
    r1 = await a.request("set", stream="c1", params={"alpha": 1.1})
    r2 = await a.request("set", stream="c1", params={"alpha": 1.2})
    t.check(killed >= 3 and r1.get("rev") == base + 1 and r2.get("rev") == base + 2,
            "after CLIENT KILL TYPE normal (%d connections) the next two sets are made: rev %s, %s (%s)" %
            (killed, r1.get("rev"), r2.get("rev"), r1.get("message", "")))
    R.cmd("CONFIG", "SET", "timeout", "1")
    try:
        await asyncio.sleep(2.5)
        b = await Client.connect(B)
        r3 = await b.request("set", stream="c1", params={"alpha": 1.3})
        t.check(r3.get("rev") == base + 3, "Redis's timeout at 1 s: a set through B after 2.5 s idle is made: rev %s (%s)"
                % (r3.get("rev"), r3.get("message", "")))
        await b.close()
    finally:
        R.cmd("CONFIG", "SET", "timeout", "0")
    # Redis busy (DEBUG SLEEP), then it closes every connection: A's set, sent meanwhile, is lost with its
    # connection before Redis read it (CLIENT KILL sent with the sleep), or after Redis made it (sent after the set).
    rev = base + 3
    for when in ("before Redis read it", "after Redis made it"):
        with socket.create_connection(("127.0.0.1", R.port), timeout=5) as s, \
                socket.create_connection(("127.0.0.1", R.port), timeout=5) as k:
            kill = resp("CLIENT", "KILL", "TYPE", "normal")
            s.sendall(resp("DEBUG", "SLEEP", "0.8") + (kill if when.startswith("before") else b""))
            await asyncio.sleep(0.15)
            pending = asyncio.ensure_future(a.request("set", stream="c1", params={"alpha": rev / 10}))
            await asyncio.sleep(0.2)
            if when.startswith("after"):
                k.sendall(kill)
            r = await pending
        rev += 1
        t.check(r.get("rev") == rev and R.stream("c1")[1] == rev,
                "a set whose connection Redis closes %s is sent again and made once: rev %s (%s)" %
                (when, r.get("rev"), r.get("message", "")))
    g = await get_at(C, "c1", rev)
    t.check(g.get("params") == r.get("params"), "C follows (rev %s)" % g.get("rev"))
    await a.close()


async def test_flushall(t):
    """FLUSHALL empties Redis under running daemons: as after a restart of an empty Redis they
    seed it again with their state within seconds; changes, events and relayed frames go on."""
    o = await owner("c1", (A, B, C))
    other = B if o is A else A
    sub = await Client.connect(other)
    await sub.request("subscribe", stream="c1")
    await sub.frame(kind=2)
    listed = await names(A)
    before = await get(A, "c1")
    R.cmd("FLUSHALL")
    start, wall = time.monotonic(), time.time()
    a = await Client.connect(A)
    replies = []

    async def accepted():
        r = await a.request("set", stream="c1", params={"alpha": 2.5})
        replies.append(r)
        return r if r.get("op") == "params" else None

    r = await until(accepted, timeout=5, step=0.1)
    t.check(r is not None and r.get("rev") == before["rev"] + 1,
            "a set is made %.1f s after FLUSHALL, at rev %s (answers before: %s)" %
            (time.monotonic() - start, r and r.get("rev"), sorted({x.get("code") for x in replies[:-1]})))
    t.check(R.cmd("ZRANGE", "fxs:streams", "0", "-1") == listed and R.cmd("EXISTS", "fxs:seeded") == 1 and
            R.stream("c1") == ("energy_wave", r and r["rev"], r and r["params"]),
            "Redis holds the daemons' streams again, with the set")
    ok = True
    for d in (B, C):
        g = await get_at(d, "c1", r and r["rev"])
        ok = ok and r is not None and g.get("rev") == r["rev"] and g.get("params") == r["params"] and \
            await names(d) == listed
    t.check(ok, "B and C follow")
    f = await frame_made_after(sub, wall + 1.0, timeout=8)
    t.check(f is not None and f["param_rev"] == (r and r["rev"]),
            "the subscriber on a daemon relaying c1 gets frames of the new rev (%s)" % (f and f["param_rev"]))
    await sub.close()
    await a.close()


async def test_bad_values(t):
    """What Redis holds is read like any input: a lease value that does not parse or never
    expires, a change counter set back or not a number, a revision out of range, a demand whose
    expiry is not a number are logged, counted in fxs_cluster_bad_values_total and repaired; the
    cluster goes on. A valid demand for the engine encoding is followed."""
    a = await Client.connect(A)
    for value in ("0", "abc"):
        before = bad_values("seq")
        R.cmd("SET", "fxs:seq", value)
        s = await a.request("set", stream="c1", params={"alpha": 1.25 if value == "0" else 1.35})
        gs = [await get_at(d, "c1", s.get("rev"), timeout=5) for d in (B, C)]
        t.check(s.get("op") == "params" and all(g.get("rev") == s["rev"] and g.get("params") == s["params"] for g in gs),
                "fxs:seq set to %s: the next set (rev %s) reaches B and C (%s)" % (value, s.get("rev"), s.get("message", "")))
        seq = R.cmd("GET", "fxs:seq")
        t.check(seq.isdigit() and int(seq) > 1 and bad_values("seq") > before,
                "the counter is set forward again (%s) and it is counted" % seq)
    for value in ("-5", "18446744073709551615"):
        before = bad_values("stream")
        R.cmd("HSET", "fxs:stream:c1", "rev", value)
        R.cmd("CLIENT", "KILL", "TYPE", "pubsub")  # every daemon reloads Redis's state

        async def agreed():
            revs = [(await get(d, "c1")).get("rev") for d in (A, B, C)]
            red = R.cmd("HGET", "fxs:stream:c1", "rev")
            return revs if red.isdigit() and len(set(revs)) == 1 and revs[0] == int(red) else None

        revs = await until(agreed, timeout=8, step=0.1)
        t.check(revs is not None and revs[0] >= 1, "rev %s in c1's hash: Redis and every daemon agree on a valid rev "
                "again (%s)" % (value, revs and revs[0]))
        t.check(bad_values("stream") > before, "and it is counted (fxs_cluster_bad_values_total{what=\"stream\"})")
    o = await owner("c1", (A, B, C))
    sub = await Client.connect(o or A)
    await sub.request("subscribe", stream="c1")
    await sub.frame(kind=2)
    for value, what in (("garbage", "a lease value that does not parse"), ("99 ghost", "a lease that never expires")):
        before = bad_values("lease")
        R.cmd("SET", "fxs:lease:c1", value)
        f = await frame_made_after(sub, time.time() + 1.0, timeout=8)
        ttl = R.cmd("PTTL", "fxs:lease:c1")
        t.check(f is not None and await owner("c1", (A, B, C)) is not None and 0 < ttl <= LEASE_TTL_S * 1000,
                "%s in fxs:lease:c1: c1 is still computed, its lease repaired (ttl %s ms)" % (what, ttl))
        t.check(bad_values("lease") > before, "and counted (fxs_cluster_bad_values_total{what=\"lease\"})")
    # The demand names encodings (field NODE or NODE|engine) and is checked like the rest.
    before = bad_values("lease")
    R.cmd("HSET", "fxs:want:c1", "ghost|engine", "soon")
    gone = await until(lambda: R.cmd("HEXISTS", "fxs:want:c1", "ghost|engine") == 0, timeout=5)
    t.check(gone and bad_values("lease") > before,
            "a demand ghost|engine whose expiry is not a number: removed and counted (%s)" % gone)
    t.check(R.cmd("EXISTS", "fxs:frame:c1:2:engine") == 0, "nobody takes c1's engine encoding: none in Redis")

    def engine_kept():
        sec, usec = R.cmd("TIME")
        R.cmd("HSET", "fxs:want:c1", "ghost|engine", str(int(sec) * 1000 + int(usec) // 1000 + 2000))
        return R.cmd("EXISTS", "fxs:frame:c1:2:engine") == 1

    t.check(await until(engine_kept, timeout=8, step=0.5),
            "another daemon's demand for the engine encoding (ghost|engine): c1's owner makes its engine "
            "frames and keeps the latest in fxs:frame:c1:2:engine")
    R.cmd("HDEL", "fxs:want:c1", "ghost|engine")
    await sub.close()
    s = await a.request("set", stream="c1", params={"alpha": 1.0})
    t.check(s.get("op") == "params", "sets go on (rev %s)" % s.get("rev"))
    await a.close()


async def test_redis_down(t):
    """Redis killed: changes are refused with unavailable naming the cluster, nothing changes,
    the owner of a stream keeps sending its frames to its subscribers, reads keep working."""
    o = await owner("c1", (A, B, C))
    t.check(o is not None, "one daemon holds c1's lease")
    a = await Client.connect(o or A)
    await a.request("subscribe", stream="c1")
    await a.frame(kind=2)
    before = await get(C, "c1")
    R.kill()

    async def refused():
        r = await a.request("set", stream="c1", params={"alpha": 9})
        return r if r.get("op") == "error" else None

    r = await until(refused, timeout=5)
    t.check(r is not None and r.get("code") == "unavailable" and R.url in r.get("message", ""),
            "a set answers unavailable naming %s (%s)" % (R.url, r and r.get("message")))
    b = await Client.connect(B)
    codes = [(await b.request(op, **kw)).get("code") for op, kw in
             (("create", dict(effect="flame", stream="x")), ("destroy", dict(stream="c1")), ("reset", dict(stream="c1")))]
    t.check(codes == ["unavailable"] * 3, "create, destroy and reset through B too (%s)" % codes)
    h = http_json(A, "/healthz")
    t.check(h["status"] == "degraded" and h["cluster"]["link"] == "down" and
            R.url in h["cluster"].get("last_error", ""), "/healthz: degraded, link down, last_error %s" %
            h["cluster"].get("last_error"))
    t.check(metric(A, 'fxs_cluster_link_up{node="a"}') == 0, "fxs_cluster_link_up 0")
    seqs = [(await a.frame(kind=2))["seq"] for _ in range(3)]
    t.check(seqs == sorted(seqs) and len(set(seqs)) == 3, "the owner keeps sending frames (seq %s)" % seqs)
    await asyncio.sleep(LEASE_TTL_S)
    t.check("c1" in leases(o or A), "past the lease's TTL it still computes c1 (nobody can take it over)")
    g = await get(C, "c1")
    t.check(g.get("rev") == before["rev"] and g.get("params") == before["params"] and "c1" in await names(B),
            "get and list still answer, nothing changed (rev %s)" % g.get("rev"))
    await a.close()
    await b.close()


async def test_redis_back_empty(t):
    """Redis back on the same port with nothing (no persistence): the first daemon to reconnect
    seeds it with the state they had, and changes are accepted again within seconds."""
    global R
    before = {s: (await get(A, s)) for s in ("c1", "energy")}
    listed = await names(A)
    R = Redis(port=R.port)
    start = time.monotonic()
    a = await Client.connect(A)

    async def accepted():
        r = await a.request("set", stream="c1", params={"alpha": 4})
        return r if r.get("op") == "params" else None

    r = await until(accepted, timeout=10, step=0.1)
    t.check(r is not None and r.get("rev") == before["c1"]["rev"] + 1,
            "a set is accepted again after %.1f s, at rev %s" % (time.monotonic() - start, r and r.get("rev")))
    red = R.stream("c1")
    t.check(R.cmd("ZRANGE", "fxs:streams", "0", "-1") == listed and red and red[1] == before["c1"]["rev"] + 1 and
            R.stream("energy")[1:] == (before["energy"]["rev"], before["energy"]["params"]),
            "Redis holds the daemons' state again (re-seeded by %s)" % R.cmd("GET", "fxs:seeded"))
    ok = True
    for d in (B, C):
        g = await get_at(d, "c1", r.get("rev"))
        ok = ok and g.get("params") == r.get("params") and await names(d) == listed
    t.check(ok, "B and C follow again")
    t.check(all(http_json(d, "/healthz")["cluster"]["link"] == "up" for d in (A, B, C)), "/healthz: link up everywhere")
    await a.close()


async def test_redis_hung(t):
    """Redis stopped (SIGSTOP: connections open, no answers): a set waits at most the command
    timeout, the link is given up within seconds, the owner's frames keep coming; SIGCONT: back to
    normal."""
    o = await owner("c1", (A, B, C))
    a = await Client.connect(o or A)
    await a.request("subscribe", stream="c1")
    await a.frame(kind=2)
    R.proc.send_signal(signal.SIGSTOP)
    try:
        start = time.monotonic()
        r = await a.request("set", stream="c1", params={"alpha": 6})
        took = time.monotonic() - start
        t.check(r.get("code") == "unavailable" and took < 2.5, "a set answers unavailable in %.1f s (%s)" %
                (took, r.get("message")))
        start2 = time.monotonic()
        r = await a.request("set", stream="c1", params={"alpha": 6})
        t.check(r.get("code") == "unavailable" and time.monotonic() - start2 < 0.5,
                "the next one at once, without waiting for Redis again (%s)" % r.get("message"))
        down = await until(lambda: http_json(A, "/healthz")["cluster"]["link"] == "down", timeout=10)
        t.check(down, "the link is given up (no answer to PING) after %.1f s" % (time.monotonic() - start))
        times = []
        for _ in range(5):
            await a.frame(kind=2)
            times.append(time.monotonic())
        gap = max(b - x for x, b in zip(times, times[1:]))
        t.check(gap < 1.5, "frames keep coming (largest gap %.2f s)" % gap)
    finally:
        R.proc.send_signal(signal.SIGCONT)

    async def accepted():
        r = await a.request("set", stream="c1", params={"alpha": 6})
        return r if r.get("op") == "params" else None

    t.check(await until(accepted, timeout=10, step=0.1) is not None, "SIGCONT: changes are accepted again")
    await a.close()


# ---- a Redis with AOF (appendfsync always), one daemon ----

async def test_redis_wins(t):
    """Redis with AOF restarted from an older copy of its files: Redis wins, the daemon goes
    back to its state and tells its subscribers; a kill -9 loses no acknowledged change."""
    p = Redis(aof=True)
    d = cluster_daemon(p, "d")
    try:
        c = await Client.connect(d)
        await c.request("create", effect="energy_wave", stream="p1", params=SMALL)
        s2 = await c.request("set", stream="p1", params={"alpha": 2})
        older = tempfile.mkdtemp(prefix="fxs-redis-older-")
        TEMP_DIRS.append(older)
        shutil.copytree(os.path.join(p.dir, "appendonlydir"), os.path.join(older, "appendonlydir"))
        s3 = await c.request("set", stream="p1", params={"alpha": 3})
        t.check(s2.get("rev") == 2 and s3.get("rev") == 3, "p1 at rev 3 on a Redis with AOF")
        sub = await Client.connect(d)
        await sub.request("subscribe", stream="p1")
        p.kill()
        p = Redis(port=p.port, data_dir=older, aof=True)
        ev = await event(sub, "params", "p1", timeout=10)
        g = await get(d, "p1")
        t.check(ev is not None and ev.get("rev") == 2 and ev["params"]["alpha"] == 2 and g.get("rev") == 2,
                "Redis back with rev 2: the daemon goes back to it, its subscriber gets the event (%s)" %
                (ev and ev.get("rev")))
        s = await c.request("set", stream="p1", params={"alpha": 5})
        t.check(s.get("rev") == 3 and s["params"]["alpha"] == 5, "and changes go on from there (rev %s)" % s.get("rev"))
        p.kill()
        p = Redis(port=p.port, data_dir=older, aof=True)
        t.check(p.stream("p1") is not None and p.stream("p1")[1:] == (3, s["params"]),
                "kill -9 of Redis: the acknowledged rev 3 is in its AOF")
    finally:
        d.stop()
        p.kill()


# ---- flags, configuration, password ----

def run_daemon(*args, env=None, timeout=30):
    p = subprocess.run([DAEMON, "--port", "0", *args], capture_output=True, text=True, timeout=timeout,
                       env=dict(os.environ, **(env or {})))
    return p.returncode, p.stdout + p.stderr


def start_refused(*args, timeout=20):
    """run_daemon for a daemon expected to refuse to start: (exit status, output), or (None,
    why) when it still runs after timeout s (it is killed then)."""
    try:
        return run_daemon(*args, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, "still running after %d s" % timeout


async def test_flags(t):
    for args, word, what in ((["--cluster", "http://127.0.0.1:6379"], "redis://", "a URL that is not redis://"),
                             (["--cluster", "redis://:pw-xyz@127.0.0.1"], "FXS_REDIS_PASSWORD", "a password in the URL"),
                             (["--cluster", "redis://127.0.0.1:99999"], "port", "a bad port"),
                             (["--cluster", "redis://127.0.0.1/x"], "database", "a bad database"),
                             (["--cluster", "rediss://127.0.0.1"], "TLS", "rediss://"),
                             (["--node-id", "a"], "--cluster", "--node-id without --cluster"),
                             (["--cluster", R.url, "--node-id", "a b"], "node id", "a bad node id"),
                             (["--role", "edge"], "--cluster", "--role without --cluster"),
                             (["--cluster", R.url, "--role", "router"], "compute, edge or both", "a bad role")):
        code, out = run_daemon(*args)
        t.check(code == 2 and word in out and "pw-xyz" not in out, "%s: exit 2 naming it (%s)" %
                (what, out.strip()[-120:]))
    cfg = os.path.join(tempfile.mkdtemp(prefix="fxs-cfg-"), "c.json")
    with open(cfg, "w") as f:
        json.dump({"cluster": "redis:/x"}, f)
    code, out = run_daemon("--config", cfg)
    t.check(code == 2 and "cluster: not a redis:// URL" in out,
            "config key cluster is checked the same way (%s)" % out.strip()[-100:])
    nobody = "redis://127.0.0.1:%d" % free_port()
    start = time.monotonic()
    code, out = run_daemon("--cluster", nobody)
    t.check(code == 1 and "cannot reach " + nobody in out and time.monotonic() - start < 20,
            "an unreachable Redis at start: exit 1 naming it (%s)" % out.strip()[-120:])
    with open(cfg, "w") as f:
        json.dump({"cluster": R.url, "node_id": "cfg", "role": "edge"}, f)
    with Daemon("--config", cfg) as d:
        h = http_json(d, "/healthz")
        cl = h.get("cluster", {})
        t.check(cl.get("node") == "cfg" and cl.get("redis") == R.url and cl.get("link") == "up" and
                cl.get("role") == "edge" and h.get("device") == "none",
                "config keys cluster, node_id and role (%s)" % cl)
    with Daemon("--cluster", R.url) as d:
        t.check(http_json(d, "/healthz")["cluster"]["node"] == socket.gethostname()[:63],
                "the node id defaults to the host name")
        code, out = start_refused("--cluster", R.url)
        t.check(code == 1 and "(the host name)" in out and "--node-id" in out,
                "a second daemon on the same host without --node-id exits 1, saying why (%s)" % out.strip()[-220:])


async def test_password(t):
    q = Redis(password="s3cret-pass")
    try:
        with cluster_daemon(q, "p", env={"FXS_REDIS_PASSWORD": "s3cret-pass"}) as d:
            c = await Client.connect(d)
            r = await c.request("create", effect="flame", stream="pw")
            t.check(r.get("op") == "created" and q.stream("pw") is not None, "FXS_REDIS_PASSWORD authenticates")
            await c.close()
        code, out = run_daemon("--cluster", q.url, env={"FXS_REDIS_PASSWORD": "wrong"})
        t.check(code == 1 and "AUTH" in out and "s3cret" not in out, "a wrong password: exit 1, AUTH named (%s)" %
                out.strip()[-120:])
    finally:
        q.kill()


async def test_shutdown(t):
    """SIGTERM: each daemon stops its follower and exits 0, with Redis up (A) or down (B)."""
    t.check(A.stop() == 0, "A exits 0")
    R.kill()
    t.check(B.stop() == 0, "B exits 0 while its follower retries a dead Redis")


def require_redis(suite):
    """Fails the suite at once, naming what is missing, when redis-server is not installed."""
    if not os.access(REDIS, os.X_OK):
        suite.check(False, "redis-server is installed (%s missing: deploy/install-deps.sh installs it)" % REDIS)
        suite.run([])


def stop_all(daemons, redis):
    """Kills what a suite started (a stopped daemon is continued first) and removes Redis's dirs."""
    for d in daemons:
        if d and d.proc.poll() is None:
            d.proc.send_signal(signal.SIGCONT)
            d.stop(signal.SIGKILL)
    redis.kill()
    for path in TEMP_DIRS:
        shutil.rmtree(path, ignore_errors=True)


if __name__ == "__main__":
    s = Suite("test_cluster")
    require_redis(s)
    R = Redis()
    try:
        A = cluster_daemon(R, "a")
        B = cluster_daemon(R, "b")
        C = cluster_daemon(R, "c")
        s.run([test_seeded, test_shared_state, test_events, test_no_budget, test_concurrent_sets, test_rebase, test_reload_same_rev, test_create_race,
               test_reset, test_metrics, test_duplicate_node, test_idle_links, test_flushall, test_bad_values,
               test_redis_down, test_redis_back_empty, test_redis_hung, test_redis_wins, test_flags,
               test_password, test_shutdown])
    finally:
        stop_all((A, B, C), R)
