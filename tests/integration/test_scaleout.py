"""test_scaleout.py — scale-out through nginx: three real fxstreamd daemons behind Debian's
nginx running deploy/nginx/fxstream.conf itself (its server lines and listen address
replaced, wrapped in a main config whose pid, logs and temp files live in a temp dir),
as an unprivileged process on loopback ports picked by the kernel.

Checks: clients of one stream reach the same daemon through the proxy (create, subscribe
from two clients, set) and the stream exists on exactly one daemon (asked directly with
`list`); different streams spread over the daemons; killing one daemon moves only its
streams: their clients see the connection close, reconnect through the proxy, land
together on another daemon, re-create the stream and get frames, while clients of the
other daemons' streams keep their connections and their frames throughout.
Every wait is bounded (fxtest), the whole suite takes about 20 s."""
import asyncio
import json
import os
import pwd
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import websockets  # noqa: E402

from fxtest import ROOT, Client, Daemon, Suite, free_port  # noqa: E402

CONF = os.path.join(ROOT, "deploy", "nginx", "fxstream.conf")
NGINX = shutil.which("nginx") or "/usr/sbin/nginx"
FXCTL = os.path.join(ROOT, "build", "fxctl")
SMALL = {"width": 32, "height": 24, "fps": 20}  # cheap frames: 3 daemons share 2 cores

DAEMONS = []
PROXY = None
OWNER = {}  # stream -> index of the daemon that holds it (from `list`, asked directly)


def site_config(text, port, backends):
    """deploy/nginx/fxstream.conf with our daemons as servers and a loopback listen."""
    m = re.search(r"^([ \t]*)# BEGIN fxstream servers.*?\n(.*?)^[ \t]*# END fxstream servers", text, re.S | re.M)
    if not m:
        raise RuntimeError("no BEGIN/END fxstream servers markers in " + CONF)
    first = re.search(r"server\s+\S+(\s+[^;]*);", m.group(2))  # keep the deployed parameters
    params = first.group(1) if first else ""
    lines = "".join("%sserver 127.0.0.1:%d%s;\n" % (m.group(1), p, params) for p in backends)
    text = text[:m.start(2)] + lines + text[m.end(2):]
    text, n = re.subn(r"^(\s*)listen\s+80;", r"\g<1>listen 127.0.0.1:%d;" % port, text, flags=re.M)
    if n != 1:
        raise RuntimeError("expected one 'listen 80;' in " + CONF)
    return text


class Proxy:
    """Debian's nginx in the foreground, unprivileged (as nobody when the tests run as root)."""

    def __init__(self, backends):
        self.dir = tempfile.mkdtemp(prefix="fxs-nginx-")
        self.port = free_port()
        d = self.dir
        site = site_config(open(CONF).read(), self.port, backends)
        with open(os.path.join(d, "nginx.conf"), "w") as f:
            f.write("daemon off;\nmaster_process on;\nworker_processes 2;\npid %s/nginx.pid;\n"
                    "error_log %s/error.log warn;\nevents { worker_connections 256; }\nhttp {\n"
                    "    access_log %s/access.log;\n" % (d, d, d))
            for t in ("client_body", "proxy", "fastcgi", "uwsgi", "scgi"):
                f.write("    %s_temp_path %s/%s;\n" % (t, d, t))
            f.write(site + "\n}\n")
        self.prefix = []
        if os.geteuid() == 0:  # drop to nobody; it must own the directory nginx writes to
            nobody = pwd.getpwnam("nobody")
            os.chmod(d, 0o755)
            for name in os.listdir(d) + [""]:
                os.chown(os.path.join(d, name), nobody.pw_uid, nobody.pw_gid)
            self.prefix = ["setpriv", "--reuid=%d" % nobody.pw_uid, "--regid=%d" % nobody.pw_gid, "--clear-groups"]
        self.cmd = self.prefix + [NGINX, "-p", d, "-c", os.path.join(d, "nginx.conf"), "-e",
                                  os.path.join(d, "error.log")]
        self.proc = None

    def test_config(self):
        return subprocess.run(self.cmd + ["-t", "-q"], capture_output=True, text=True, timeout=20)

    def start(self):
        self.proc = subprocess.Popen(self.cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                with urllib.request.urlopen("http://127.0.0.1:%d/proxy-healthz" % self.port, timeout=2) as r:
                    if r.status == 200:
                        return
            except OSError:
                if self.proc.poll() is not None:
                    break
                time.sleep(0.1)
        raise RuntimeError("nginx did not start: %s" % self.log())

    def log(self):
        try:
            return open(os.path.join(self.dir, "error.log")).read()[-2000:]
        except OSError:
            return ""

    def stop(self):
        if self.proc and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGQUIT)  # graceful: workers finish, master exits
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        shutil.rmtree(self.dir, ignore_errors=True)


async def via_proxy(stream):
    """A connection through the proxy for one stream: ws://PROXY/v1/ws?stream=NAME."""
    ws = await asyncio.wait_for(websockets.connect(
        "ws://127.0.0.1:%d/v1/ws?stream=%s" % (PROXY.port, stream), subprotocols=["fxstream.v1"],
        max_size=64 << 20), 10)
    c = Client(ws)
    c.hello = await c.text()
    return c


async def where(stream):
    """Indices of the live daemons whose `list` holds stream, and its subscriber counts."""
    found = []
    for i, d in enumerate(DAEMONS):
        if d.proc.poll() is not None:
            continue
        c = await Client.connect(d)
        r = await c.request("list")
        await c.close()
        for s in r.get("streams", []):
            if s["stream"] == stream:
                found.append((i, s["subscribers"]))
    return found


def http_get(path):
    with urllib.request.urlopen("http://127.0.0.1:%d%s" % (PROXY.port, path), timeout=10) as r:
        return r.status, r.read()


async def test_config(t):
    text = open(CONF).read()
    t.check(re.search(r"^\s*hash \$arg_stream consistent;", text, re.M) is not None,
            "fxstream.conf hashes $arg_stream consistently")
    t.check(re.search(r"proxy_set_header Upgrade \$http_upgrade;", text) and
            re.search(r"proxy_set_header Connection \$fxstream_connection;", text) and
            re.search(r"proxy_http_version 1\.1;", text), "fxstream.conf passes the WebSocket upgrade")
    t.check(re.search(r"proxy_read_timeout\s+(\d+h|\d{3,}s?);", text) is not None, "long read timeout for WebSockets")
    t.check(re.search(r"server \S+ max_fails=\d+ fail_timeout=\d+s;", text) is not None,
            "servers carry passive health checks (max_fails, fail_timeout)")
    r = PROXY.test_config()
    t.check(r.returncode == 0, "nginx -t accepts the generated configuration" +
            ("" if r.returncode == 0 else ": " + r.stderr[-500:]))


async def test_http(t):
    status, body = http_get("/healthz")
    h = json.loads(body)
    t.check(status == 200 and h.get("status") == "ok", "/healthz passes through the proxy")
    status, body = http_get("/")
    t.check(status == 200 and b"<" in body, "the web page passes through the proxy")


async def test_same_stream(t):
    a = await via_proxy("shared")
    r = await a.request("create", effect="energy_wave", stream="shared", params=SMALL)
    t.check(r.get("op") == "created", "create through the proxy")
    b, c = await via_proxy("shared"), await via_proxy("shared")
    rb = await b.request("subscribe", stream="shared")
    rc = await c.request("subscribe", stream="shared")
    t.check(rb.get("op") == "subscribed" and rc.get("op") == "subscribed",
            "two clients subscribe through the proxy: %s %s" % (rb.get("op"), rc.get("op")))
    fb, fc = await b.frame(), await c.frame()
    t.check(fb["channel"] == rb.get("channel") and fc["channel"] == rc.get("channel") and
            fb["channel"] == fc["channel"], "both get frames on the same channel")
    found = await where("shared")
    t.check(len(found) == 1 and found[0][1] == 2,
            "the stream exists on exactly one daemon, with both subscribers: %s" % found)
    r = await a.request("set", stream="shared", params={"alpha": 1.5})
    t.check(r.get("op") == "params" and r.get("rev") == 2, "set through a third connection reaches the owner")
    deadline = time.monotonic() + 10
    rev = 0
    while time.monotonic() < deadline and rev < 2:
        rev = (await b.frame())["param_rev"]
    t.check(rev == 2, "the subscriber's frames carry the new revision")
    p = subprocess.run([FXCTL, "--url", "ws://127.0.0.1:%d/v1/ws?stream=shared" % PROXY.port, "get", "shared"],
                       capture_output=True, text=True, timeout=20)
    t.check(p.returncode == 0 and '"rev"' in p.stdout, "fxctl --url ...?stream=shared reaches the owner too")
    for x in (a, b, c):
        await x.close()


async def test_spread(t):
    names = ["s%02d" % i for i in range(12)]
    ok = 0
    for n in names:
        c = await via_proxy(n)
        r = await c.request("create", effect="energy_wave", stream=n, params=SMALL)
        ok += r.get("op") == "created"
        await c.close()
    t.check(ok == len(names), "12 streams created through the proxy (%d)" % ok)
    single = 0
    for n in names:
        found = await where(n)
        single += len(found) == 1
        if found:
            OWNER[n] = found[0][0]
    t.check(single == len(names), "each stream lives on exactly one daemon (%d of %d)" % (single, len(names)))
    used = sorted(set(OWNER.values()))
    t.check(len(used) >= 2, "the streams spread over %d daemons: %s" % (len(used), OWNER))
    again = 0
    for n in names:  # a later connection for the same stream finds it: the mapping is stable
        c = await via_proxy(n)
        r = await c.request("get", stream=n)
        again += r.get("op") == "params"
        await c.close()
    t.check(again == len(names), "reconnecting reaches the same owner for every stream (%d)" % again)
    status, body = http_get("/healthz?stream=s00")
    t.check(status == 200 and "s00" in [s["stream"] for s in json.loads(body)["streams"]],
            "/healthz?stream=NAME answers from NAME's owner")


class Watch:
    """Reads one subscribed connection in the background: frame arrival times, close."""

    def __init__(self, client):
        self.c, self.times, self.closed_at = client, [], None
        self.task = asyncio.ensure_future(self.run())

    async def run(self):
        try:
            async for m in self.c.ws:
                if isinstance(m, bytes):
                    self.times.append(time.monotonic())
        except websockets.ConnectionClosed:
            pass
        self.closed_at = time.monotonic()

    def max_gap(self, since, until):
        ts = [since] + [x for x in self.times if since <= x <= until] + [until]
        return max(b - a for a, b in zip(ts, ts[1:]))


async def test_failover(t):
    if len(set(OWNER.values())) < 2:
        t.check(False, "failover needs streams on two daemons")
        return
    # The victim: the daemon holding the most streams; its streams move, the others stay.
    counts = {i: list(OWNER.values()).count(i) for i in set(OWNER.values())}
    victim = max(counts, key=counts.get)
    moved = [n for n, i in OWNER.items() if i == victim][:2]
    stay = []
    for i in sorted(set(OWNER.values()) - {victim}):  # one stream per surviving daemon
        stay.append(next(n for n, o in OWNER.items() if o == i))
    watches = {}
    for n in moved + stay:
        c = await via_proxy(n)
        r = await c.request("subscribe", stream=n)
        if r.get("op") != "subscribed":
            t.check(False, "subscribe %s: %s" % (n, r))
            return
        watches[n] = Watch(c)
    extra = await via_proxy(moved[0])  # a second client of a moving stream
    await extra.request("subscribe", stream=moved[0])
    wx = Watch(extra)
    await asyncio.sleep(1.5)
    t.check(all(len(w.times) > 3 for w in watches.values()), "every subscriber gets frames before the failure")

    t_kill = time.monotonic()
    DAEMONS[victim].proc.kill()  # dies without a goodbye
    DAEMONS[victim].proc.wait(timeout=10)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and not all(watches[n].closed_at for n in moved):
        await asyncio.sleep(0.05)
    t.check(all(watches[n].closed_at for n in moved) and wx.closed_at is not None,
            "clients of the dead daemon's streams see their connections close")

    landed = {}
    for n in moved:  # what a client does: reconnect, re-create if the stream is gone, resubscribe
        c = await via_proxy(n)
        r = await c.request("subscribe", stream=n)
        if r.get("op") == "error" and r.get("code") == "unknown_stream":
            r = await c.request("create", effect="energy_wave", stream=n, params=SMALL)
            r = await c.request("subscribe", stream=n)
        f = await c.frame() if r.get("op") == "subscribed" else None
        landed[n] = (r.get("op"), f is not None and f["channel"] == r.get("channel"), await where(n))
        watches[n] = Watch(c)
    t.check(all(v[0] == "subscribed" and v[1] for v in landed.values()),
            "moved streams re-created through the proxy and frames arrive: %s" %
            {n: v[:2] for n, v in landed.items()})
    t.check(all(len(v[2]) == 1 and v[2][0][0] != victim for v in landed.values()),
            "each moved stream now lives on exactly one surviving daemon: %s" % {n: v[2] for n, v in landed.items()})
    c = await via_proxy(moved[0])  # the second client of moved[0] lands where the first re-created it
    r = await c.request("subscribe", stream=moved[0])
    f = await c.frame() if r.get("op") == "subscribed" else None
    t.check(f is not None, "a second client of a moved stream finds it without re-creating it")
    found = await where(moved[0])
    t.check(len(found) == 1 and found[0][1] == 2, "both clients of the moved stream share one daemon: %s" % found)
    await c.close()

    await asyncio.sleep(1.5)
    now = time.monotonic()
    t.check(all(watches[n].closed_at is None for n in stay),
            "clients of the other daemons' streams keep their connections")
    gaps = {n: round(watches[n].max_gap(t_kill - 1.0, now), 2) for n in stay}
    after = {n: sum(1 for x in watches[n].times if x > t_kill) for n in stay}
    t.check(all(g < 2.0 for g in gaps.values()) and all(a >= 5 for a in after.values()),
            "their frames keep arriving throughout (largest gap %s s, frames since the kill %s)" % (gaps, after))
    unmoved = 0
    for n in stay:
        found = await where(n)
        unmoved += len(found) == 1 and found[0][0] == OWNER[n]
    t.check(unmoved == len(stay), "streams of the surviving daemons did not move")
    for w in list(watches.values()) + [wx]:
        if w.closed_at is None:
            await w.c.close()
        await asyncio.wait_for(w.task, 5)


def main():
    global PROXY
    t = Suite("test_scaleout")
    cfg = tempfile.NamedTemporaryFile("w", suffix=".json", prefix="fxs-scaleout-", delete=False)
    json.dump({"streams": []}, cfg)
    cfg.close()
    try:
        for _ in range(3):
            DAEMONS.append(Daemon("--config", cfg.name))  # own state dir each, no tokens: loopback
        PROXY = Proxy([d.port for d in DAEMONS])
        PROXY.start()
    except Exception as e:
        t.check(False, "start three daemons and nginx: %s" % e)
        for d in DAEMONS:
            d.stop()
        print("%s: %d passed, %d failed" % (t.name, t.passed, t.failed))
        sys.exit(1)
    try:
        t.run([test_config, test_http, test_same_stream, test_spread, test_failover], timeout=45)
    finally:
        if PROXY:
            PROXY.stop()
        for d in DAEMONS:
            d.stop()
            shutil.rmtree(d.state_dir, ignore_errors=True)
        os.unlink(cfg.name)


if __name__ == "__main__":
    main()
