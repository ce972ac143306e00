"""test_install.py — `make install` and `make uninstall`: the files land where README and
deploy/README.md say (DESTDIR staging with the default PREFIX; the client library's own
checks are test_libfxclient.py's), the web client is the one
the daemon serves (every file its pages reference is there, no sources), and a copy
installed under a real PREFIX starts with its installed configuration and serves the
page, its bundle and /healthz. Bounded: make install with everything built takes seconds."""
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fxtest import ROOT, Suite  # noqa: E402

TOKENS = "admin:install-test-token-0123456789"


def make(*args):
    return subprocess.run(["make", "--no-print-directory", "-C", ROOT, *args], capture_output=True, text=True,
                          timeout=300)


def referenced(html):
    """Local files a page loads (src= and href=), relative to the web root."""
    out = []
    for m in re.finditer(r'(?:src|href)="([^"#?]+)"', html):
        u = m.group(1)
        if not re.match(r"^[a-z]+:", u) and not u.startswith("//"):
            out.append(u[2:] if u.startswith("./") else u.lstrip("/"))
    return out


DYNAMIC = ("healthz", "metrics")  # served by the daemon itself, not files


def get(port, path):
    with urllib.request.urlopen("http://127.0.0.1:%d%s" % (port, path), timeout=10) as r:
        return r.status, r.read()


def test_destdir(t):
    d = tempfile.mkdtemp(prefix="fxs-destdir-")
    try:
        r = make("install", "DESTDIR=" + d)
        if not t.check(r.returncode == 0, "make install DESTDIR=%s" % d + ("" if r.returncode == 0 else
                                                                           ": " + r.stderr[-800:])):
            return
        p = d + "/usr/local"
        t.check(all(os.access("%s/bin/%s" % (p, b), os.X_OK) for b in ("fxstreamd", "fxctl", "fxload")),
                "fxstreamd, fxctl, fxload in PREFIX/bin")
        t.check(os.path.islink(p + "/lib/libfxclient.so") and os.path.isfile(p + "/lib/libfxclient.a") and
                os.path.isfile(p + "/include/fxclient/fxclient.h") and os.path.isfile(p + "/lib/pkgconfig/fxclient.pc"),
                "libfxclient in PREFIX/lib, its headers in PREFIX/include/fxclient, fxclient.pc "
                "(test_libfxclient.py builds against them)")
        web = p + "/share/fxstream/web"
        t.check(os.path.isfile(web + "/index.html") and
                all(os.path.isfile(web + "/dist/" + f) for f in ("app.js", "decode_worker.js", "fxs_particles.wasm")),
                "web client (index.html; dist/app.js, the particle decoder's worker and WebAssembly module) "
                "in PREFIX/share/fxstream/web")
        t.check(not os.path.exists(web + "/src") and not os.path.exists(web + "/build.mjs"),
                "the web client's sources are not installed")
        missing = []
        pages = [f for f in os.listdir(web) if f.endswith(".html")]
        for page in pages:
            for ref in referenced(open(os.path.join(web, page)).read()):
                if ref not in DYNAMIC and not os.path.exists(os.path.join(web, ref)):
                    missing.append("%s: %s" % (page, ref))
        t.check(pages and not missing, "every file the installed pages load is installed %s" % missing)
        unit = p + "/lib/systemd/system/fxstreamd.service"
        text = open(unit).read() if os.path.exists(unit) else ""
        t.check("ExecStart=/usr/local/bin/fxstreamd --config /usr/local/etc/fxstream/fxstreamd.json" in text,
                "systemd unit in PREFIX/lib/systemd/system, starting the installed binary with its config")
        cfg_path = p + "/etc/fxstream/fxstreamd.json"
        cfg = json.load(open(cfg_path)) if os.path.exists(cfg_path) else {}
        t.check(cfg.get("web_root") == "/usr/local/share/fxstream/web" and cfg.get("state_dir") == "/var/lib/fxstream",
                "config in PREFIX/etc/fxstream points at the installed web client and the unit's state dir")
        t.check(all(os.path.isfile(p + "/share/doc/fxstream/" + f) for f in
                    ("README.md", "DEPLOY.md", "fxstreamd.json", "tokens.env.example", "fxstream.conf",
                     "PROTOCOL.md")),
                "docs, example config, tokens example and nginx config in PREFIX/share/doc/fxstream")
        with open(cfg_path, "a") as f:
            f.write("\n")  # the operator's edit
        r = make("install", "DESTDIR=" + d)
        t.check(r.returncode == 0 and open(cfg_path).read().endswith("}\n\n"), "reinstalling keeps an edited config")
        r = make("uninstall", "DESTDIR=" + d)
        left = sorted(os.path.relpath(os.path.join(a, f), d) for a, _, fs in os.walk(d) for f in fs)
        t.check(r.returncode == 0 and left == ["usr/local/etc/fxstream/fxstreamd.json"],
                "make uninstall removes everything but the config: %s" % left[:8])
    finally:
        shutil.rmtree(d, ignore_errors=True)


def test_prefix_runs(t):
    p = tempfile.mkdtemp(prefix="fxs-prefix-")
    proc = None
    try:
        r = make("install", "PREFIX=" + p)
        if not t.check(r.returncode == 0, "make install PREFIX=%s" % p):
            return
        conf = p + "/etc/fxstream/fxstreamd.json"
        t.check(json.load(open(conf)).get("web_root") == p + "/share/fxstream/web", "config rewritten for PREFIX")
        unit = open(p + "/lib/systemd/system/fxstreamd.service").read()
        t.check("ExecStart=%s/bin/fxstreamd --config %s" % (p, conf) in unit and
                "EnvironmentFile=-%s/etc/fxstream/tokens.env" % p in unit, "unit rewritten for PREFIX")
        v = subprocess.run(["systemd-analyze", "verify", p + "/lib/systemd/system/fxstreamd.service"],
                           capture_output=True, text=True, timeout=60)
        t.check(v.returncode == 0 and not v.stderr.strip() and not v.stdout.strip(),
                "systemd-analyze verify accepts the installed unit" + (v.stderr[-400:] if v.stderr.strip() else ""))
        # The shipped config listens on 0.0.0.0: without a token the daemon must refuse.
        env = {k: v for k, v in os.environ.items() if k != "FXSTREAMD_TOKENS"}
        r = subprocess.run([p + "/bin/fxstreamd", "--config", conf, "--port", "0", "--state-dir", p + "/state"],
                           capture_output=True, text=True, timeout=30, env=env)
        t.check(r.returncode == 2 and "token" in r.stderr, "with no tokens the installed config refuses to start")
        # As installed (web root from the config), with a token, kept on loopback for the test.
        proc = subprocess.Popen([p + "/bin/fxstreamd", "--config", conf, "--listen", "127.0.0.1", "--port", "0",
                                 "--state-dir", p + "/state", "--log-level", "warn"], stdout=subprocess.PIPE,
                                stderr=tempfile.TemporaryFile(), text=True, env=dict(env, FXSTREAMD_TOKENS=TOKENS))
        line = proc.stdout.readline()
        if not t.check("listening on" in line, "the installed daemon starts with its installed config"):
            return
        port = int(line.split("127.0.0.1:")[1].split("/")[0])
        status, body = get(port, "/healthz")
        t.check(status == 200 and json.loads(body).get("status") == "ok", "installed daemon serves /healthz")
        status, body = get(port, "/")
        t.check(status == 200 and body == open(p + "/share/fxstream/web/index.html", "rb").read(),
                "installed daemon serves the installed web page at /")
        status, body = get(port, "/dist/app.js")
        t.check(status == 200 and len(body) > 1000, "installed daemon serves the web client's bundle")
        status, body = get(port, "/dist/fxs_particles.wasm")
        t.check(status == 200 and body[:4] == b"\0asm", "installed daemon serves the particle decoder's WebAssembly module")
        web = p + "/share/fxstream/web"
        refs = sorted({r for f in os.listdir(web) if f.endswith(".html") for r in referenced(open(os.path.join(web, f)).read())})
        bad = []
        for ref in refs:
            try:
                if get(port, "/" + ref)[0] != 200:
                    bad.append(ref)
            except OSError as e:
                bad.append("%s (%s)" % (ref, e))
        t.check(refs and not bad, "everything the installed pages load answers 200 (%d URLs) %s" % (len(refs), bad))
    finally:
        if proc:
            proc.terminate()
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
        shutil.rmtree(p, ignore_errors=True)


def main():
    t = Suite("test_install")
    t0 = time.monotonic()
    for test in (test_destdir, test_prefix_runs):
        try:
            test(t)
        except Exception as e:
            t.check(False, "%s raised %s: %s" % (test.__name__, type(e).__name__, e))
    print("(%.1f s)" % (time.monotonic() - t0))
    print("%s: %d passed, %d failed" % (t.name, t.passed, t.failed))
    sys.exit(1 if t.failed else 0)


if __name__ == "__main__":
    main()
