"""test_access.py — roles by token, the Origin check and TLS on a real fxstreamd.

Tokens come from a config file and from FXSTREAMD_TOKENS; a connection starts with no
role and takes one with the `auth` op or an `Authorization: Bearer` header; each op needs
its least role (PROTOCOL.md §3.11). Browsers' Origin must be the daemon's own or listed.
With TLS configured the daemon speaks only TLS. Without tokens it refuses to listen
beyond loopback. Run from the repository root: /usr/bin/python3 tests/integration/test_access.py"""
import asyncio
import json
import os
import ssl
import subprocess
import tempfile
import urllib.request

import websockets

from fxtest import DAEMON, ROOT, Client, Daemon, Suite, config_file, refusal

FXCTL = os.path.join(ROOT, "build", "fxctl")
FXLOAD = os.path.join(ROOT, "build", "fxload")


def tool(d, args, scheme="ws", env=None):
    """Runs fxctl or fxload (args[0]) against d; returns (exit status, stdout, stderr)."""
    url = "%s://127.0.0.1:%d/v1/ws" % (scheme, d.port)
    e = {k: v for k, v in os.environ.items() if not k.startswith("FXSTREAM_")}
    e.update(env or {})
    p = subprocess.run([args[0], "--url", url] + args[1:], capture_output=True, text=True, timeout=60, env=e)
    return p.returncode, p.stdout, p.stderr

VIEW, TUNE, ADMIN = "view-token-0123456789", "tune-token-0123456789", "admin-token-012345678"


def token_daemon(extra=None, tokens=True):
    """A daemon with view, tune and admin tokens (tokens=False: none at all) and extra config."""
    if not tokens:
        env = {k: v for k, v in os.environ.items() if k != "FXSTREAMD_TOKENS"}
        return Daemon("--config", config_file(extra or {}), env=env)
    cfg = {"tokens": [{"role": "view", "token": VIEW}, {"role": "tune", "token": TUNE}], **(extra or {})}
    return Daemon("--config", config_file(cfg), env={"FXSTREAMD_TOKENS": "admin:" + ADMIN})


async def connect(d, headers=None, origin=None):
    ws = await asyncio.wait_for(websockets.connect(
        d.url, subprotocols=["fxstream.v1"], extra_headers=headers or {}, origin=origin), 10)
    c = Client(ws)
    c.hello = await c.text()
    return c


async def test_roles(t):
    d = token_daemon()
    try:
        c = await connect(d)
        t.check(c.hello["auth"] == {"required": True, "role": "none"}, "hello: auth required, role none")
        r = await c.request("list")
        t.check(r["op"] == "error" and r["code"] == "unauthorized", "list before auth: unauthorized")
        r = await c.request("auth", token="not-a-token-0123456789")
        t.check(r["code"] == "unauthorized" and r["param"] == "token", "a wrong token: unauthorized")
        r = await c.request("auth", token=VIEW)
        t.check(r == {"op": "auth", "id": r["id"], "role": "view"}, "auth with the view token: role view")
        t.check((await c.request("list"))["op"] == "list", "view may list")
        t.check((await c.request("subscribe", stream="energy"))["op"] == "subscribed", "view may subscribe")
        r = await c.request("set", stream="energy", params={"fps": 10})
        t.check(r["code"] == "forbidden" and "needs role tune" in r["message"], "view may not set: forbidden")
        r = await c.request("auth", token=TUNE)
        t.check(r["role"] == "tune", "auth with the tune token: role tune")
        r = await c.request("set", stream="energy", params={"fps": 10})
        t.check(r["op"] == "params" and r["rev"] == 2, "tune may set")
        r = await c.request("create", effect="energy_wave", stream="x")
        t.check(r["code"] == "forbidden", "tune may not create")
        r = await c.request("preset_load", stream="energy", name="thesis-fig5.3")
        t.check(r["op"] == "params", "tune may load a preset")
        r = await c.request("preset_save", stream="energy", name="mine")
        t.check(r["code"] == "forbidden" and "needs role admin" in r["message"], "tune may not save a preset")
        r = await c.request("auth", token=ADMIN)
        t.check(r["role"] == "admin", "the FXSTREAMD_TOKENS admin token works")
        t.check((await c.request("create", effect="energy_wave", stream="x"))["op"] == "created", "admin may create")
        t.check((await c.request("destroy", stream="x"))["op"] == "destroyed", "admin may destroy")
        t.check((await c.request("preset_save", stream="energy", name="mine"))["op"] == "preset_saved",
                "admin may save a preset")
        t.check((await c.request("preset_delete", effect="energy_wave", name="mine"))["op"] == "preset_deleted",
                "admin may delete a preset")
        await c.close()

        c = await connect(d, headers={"Authorization": "Bearer " + TUNE})
        t.check(c.hello["auth"]["role"] == "tune", "Authorization: Bearer gives the role at connect")
        t.check((await c.request("reset", stream="energy"))["op"] == "reset", "tune by header may reset")
        await c.close()

        ws = await asyncio.wait_for(websockets.connect(d.url, subprotocols=["fxstream.v1"], extra_headers={
            "Authorization": "Bearer wrong-token-0123456789"}), 10)
        try:
            await asyncio.wait_for(ws.recv(), 5)
            t.check(False, "an invalid header token closes the connection before hello")
        except websockets.ConnectionClosed as e:
            t.check(e.code == 1008 and "invalid token" in e.reason, "invalid header token: closed 1008 (%s)" % e.reason)

        c = await connect(d)
        closed = None
        for i in range(6):
            try:
                await c.request("auth", token="wrong-token-%010d" % i, timeout=5)
            except websockets.ConnectionClosed as e:
                closed = e
                break
        t.check(closed is not None and closed.code == 1008, "5 wrong tokens close the connection (1008)")

        rc, out, err = tool(d, [FXCTL, "list"])
        t.check(rc == 1 and "unauthorized" in err, "fxctl without a token: unauthorized (%s)" % err.strip())
        rc, out, err = tool(d, [FXCTL, "--token", TUNE, "set", "energy", "fps=12"])
        t.check(rc == 0 and '"fps":12' in out, "fxctl --token (tune) may set")
        rc, out, err = tool(d, [FXCTL, "destroy", "energy"], env={"FXSTREAM_TOKEN": VIEW})
        t.check(rc == 1 and "forbidden" in err, "fxctl with $FXSTREAM_TOKEN (view) may not destroy")
        rc, out, err = tool(d, [FXCTL, "--token", "wrong-token-0123456789", "list"])
        t.check(rc == 1 and "invalid token" in err, "fxctl with a wrong token: %s" % err.strip())
        rc, out, err = tool(d, [FXLOAD, "--token", VIEW, "--connections", "2", "--duration", "2", "--ramp", "0",
                                "--streams", "energy", "--quiet", "--json", "-"])
        rep = json.loads(out) if rc == 0 else {}
        t.check(rc == 0 and rep.get("streams"), "fxload --token subscribes (exit %d)" % rc)
    finally:
        d.stop()


async def test_origin(t):
    d = token_daemon({"allowed_origins": ["https://studio.example"]})
    try:
        c = await connect(d, origin="http://127.0.0.1:%d" % d.port, headers={"Authorization": "Bearer " + VIEW})
        t.check(c.hello["auth"]["role"] == "view", "the daemon's own page origin is accepted")
        await c.close()
        c = await connect(d, origin="https://studio.example")
        t.check(c.hello["op"] == "hello", "a listed origin is accepted")
        await c.close()
        r = await refusal(d, origin="http://evil.example")
        t.check(r is not None, "a foreign origin is refused (%s), the daemon still running" % r)
        t.check(await refusal(d, origin="https://studio.example", read=True) is None, "then a listed origin still gets in")
    finally:
        d.stop()


def handshake(port, host, origin=None):
    """The status line of a raw WebSocket handshake with these Host and Origin headers."""
    import base64
    import socket
    s = socket.create_connection(("127.0.0.1", port), timeout=10)
    s.sendall(("GET /v1/ws HTTP/1.1\r\nHost: %s\r\n%sUpgrade: websocket\r\nConnection: Upgrade\r\n"
               "Sec-WebSocket-Key: %s\r\nSec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: fxstream.v1\r\n\r\n"
               % (host, "Origin: %s\r\n" % origin if origin else "", base64.b64encode(os.urandom(16)).decode())).encode())
    try:
        head = s.recv(4096)
    except ConnectionResetError:
        head = b""
    s.close()
    return head.split(b"\r\n")[0].decode(errors="replace") or "(closed)"


async def test_dns_rebinding(t):
    """Without tokens only this machine's names are accepted as Host: a page on a DNS-rebinding
    domain sends its own name as Host and Origin, and must not get admin."""
    d = token_daemon({"allowed_hosts": ["studio.local"]}, tokens=False)
    try:
        p = d.port
        r = handshake(p, "attacker.example:%d" % p, "http://attacker.example:%d" % p)
        t.check(" 101 " not in r, "no tokens: Host attacker.example refused (%s)" % r)
        t.check(" 101 " not in handshake(p, "attacker.example:%d" % p), "also without an Origin")
        for host in ("127.0.0.1:%d" % p, "localhost:%d" % p, "LOCALHOST", "127.1.2.3:%d" % p, "[::1]:%d" % p,
                     "studio.local:%d" % p):
            r = handshake(p, host, "http://%s" % host)
            t.check(" 101 " in r, "no tokens: Host %s accepted (%s)" % (host, r))
        t.check(" 101 " not in handshake(p, "127.0.0.1.attacker.example:%d" % p), "a name that only starts like 127.0.0.1 is refused")
        t.check(d.proc.poll() is None, "the daemon runs on")
    finally:
        d.stop()
    d = token_daemon({})
    try:  # with tokens the token protects: any Host may connect, and gets no role without one
        r = handshake(d.port, "attacker.example:%d" % d.port, "http://attacker.example:%d" % d.port)
        t.check(" 101 " in r, "with tokens: any Host connects (%s)" % r)
        c = await connect(d, origin="http://127.0.0.1:%d" % d.port)
        t.check(c.hello["auth"]["role"] == "none", "and same origin grants no role without a token (%s)" % c.hello["auth"])
        await c.close()
    finally:
        d.stop()


async def test_loopback_only(t):
    p = subprocess.run([DAEMON, "--listen", "0.0.0.0", "--port", "0"], capture_output=True, text=True, timeout=30,
                       env={k: v for k, v in os.environ.items() if k != "FXSTREAMD_TOKENS"})
    t.check(p.returncode == 2 and "no access tokens" in p.stderr, "no tokens: refuses 0.0.0.0 (%s)" % p.stderr.strip())
    p = subprocess.run([DAEMON, "--port", "0", "--tls-cert", "/nonexistent.pem"], capture_output=True, text=True,
                       timeout=30)
    t.check(p.returncode == 2 and "--tls-key" in p.stderr, "a certificate without a key is an error")
    d = Daemon("--log-level", "info")
    try:
        c = await Client.connect(d)
        t.check(c.hello["auth"] == {"required": False, "role": "admin"}, "no tokens: every client is admin")
        await c.close()
    finally:
        d.stop()
        t.check("every client is admin; listening on loopback only" in d.log(), "says so at start")


def self_signed(tmp):
    cert, key = os.path.join(tmp, "cert.pem"), os.path.join(tmp, "key.pem")
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout", key, "-out", cert,
                    "-days", "2", "-subj", "/CN=127.0.0.1", "-addext", "subjectAltName=IP:127.0.0.1"],
                   check=True, capture_output=True, timeout=60)
    return cert, key


async def test_tls(t):
    tmp = tempfile.mkdtemp(prefix="fxs-tls-")
    cert, key = self_signed(tmp)
    d = Daemon("--tls-cert", cert, "--tls-key", key)
    try:
        ctx = ssl.create_default_context(cafile=cert)
        ws = await asyncio.wait_for(websockets.connect("wss://127.0.0.1:%d/v1/ws" % d.port,
                                                       subprotocols=["fxstream.v1"], ssl=ctx), 10)
        c = Client(ws)
        hello = await c.text()
        t.check(hello["op"] == "hello", "wss:// handshake and hello")
        r = await c.request("subscribe", stream="energy")
        f = await c.frame()
        t.check(r["op"] == "subscribed" and f["kind"] == 2, "frames over TLS")
        await c.close()
        rc, out, err = tool(d, [FXCTL, "--ca-file", cert, "list"], scheme="wss")
        t.check(rc == 0 and '"stream":"energy"' in out, "fxctl over wss:// with --ca-file (%s)" % err.strip())
        rc, out, err = tool(d, [FXCTL, "list"], scheme="wss")
        t.check(rc == 1, "fxctl over wss:// refuses an unknown certificate (%s)" % err.strip())
        rc, out, err = tool(d, [FXLOAD, "--connections", "2", "--duration", "2", "--ramp", "0", "--streams", "energy",
                                "--quiet", "--json", "-"], scheme="wss", env={"FXSTREAM_CA_FILE": cert})
        t.check(rc == 0 and json.loads(out).get("streams"), "fxload over wss:// (exit %d)" % rc)
        with urllib.request.urlopen("https://127.0.0.1:%d/healthz" % d.port, context=ctx, timeout=10) as resp:
            t.check(json.loads(resp.read())["status"] == "ok", "https:// /healthz")
        r = await refusal(d, read=True)
        t.check(r is not None, "plain ws:// is refused when TLS is configured (%s), the daemon still running" % r)
    finally:
        d.stop()


if __name__ == "__main__":
    Suite("test_access").run([test_roles, test_origin, test_dns_rebinding, test_loopback_only, test_tls])
