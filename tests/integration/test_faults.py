"""test_faults.py — fxstreamd under a stalled reader, a kill -9 and a failing simulation.

A client that stops reading gets frames skipped and is closed after stall_timeout_s while
another subscriber of the same stream keeps its frame rate and the daemon's memory stays
bounded; `kill -9` during a burst of `set` loses no acknowledged change; a stream whose
simulation blows up reports `error` events and resets while the other streams run on.
Run from the repository root: /usr/bin/python3 tests/integration/test_faults.py"""
import asyncio
import json
import re
import signal
import socket
import tempfile
import time
import urllib.request

from fxtest import Client, Daemon, Suite, config_file
from rawws import Conn, frame


def metric(d, name):
    with urllib.request.urlopen(d.http + "/metrics", timeout=10) as r:
        m = re.search(r"^%s (\S+)$" % re.escape(name), r.read().decode(), re.M)
    return float(m.group(1)) if m else None


def rss_kib(d):
    with open("/proc/%d/status" % d.proc.pid) as f:
        return int(re.search(r"VmRSS:\s+(\d+)", f.read()).group(1))


def stalled_reader(port, stream, rcvbuf=4096):
    """A raw WebSocket client with a small receive buffer that subscribes and reads nothing
    more itself (the caller may read slowly)."""
    c = Conn.connect(port, rcvbuf=rcvbuf)
    c.send(frame(json.dumps({"op": "subscribe", "stream": stream})))
    return c.s, c.status


def closed_by_peer(s, timeout=10):
    """Drains the socket; True when the server closed it."""
    s.settimeout(timeout)
    try:
        while s.recv(1 << 20):
            pass
        return True
    except ConnectionResetError:
        return True
    except socket.timeout:
        return False


async def test_stalled_reader(t):
    d = Daemon("--config", config_file({"limits": {"stall_timeout_s": 2}, "streams": [
        {"stream": "big", "effect": "energy_wave", "params": {"width": 512, "height": 512, "output": "RGBA",
                                                            "fps": 10}}]}))
    try:
        good = await Client.connect(d)
        await good.request("subscribe", stream="big")
        first = await good.frame(30, kind=2)  # the stream runs
        s, status = stalled_reader(d.port, "big")
        t.check(b" 101 " in status, "the stalled client's handshake succeeded")
        rss0 = rss_kib(d)
        seqs, t0 = [first["seq"]], time.monotonic()
        while time.monotonic() - t0 < 6:  # textures only: each step also sends a light-rig frame
            seqs.append((await good.frame(10, kind=2))["seq"])
        span = seqs[-1] - seqs[0]
        t.check(span > 0 and (len(seqs) - 1) >= 0.9 * span,
                "the other subscriber got %d of %d frames while one client stalled" % (len(seqs) - 1, span))
        stalled = metric(d, "fxs_connections_stalled_total")
        t.check(stalled == 1, "the stalled connection was closed after stall_timeout_s (metric %s)" % stalled)
        t.check(closed_by_peer(s), "the stalled client's socket is closed by the server")
        line = [l for l in d.log().splitlines() if "has not read" in l]
        t.check(line and "127.0.0.1" in line[0] and "subscribed to big" in line[0],
                "the log line names the peer and its subscriptions (%s)" % line[:1])
        growth = rss_kib(d) - rss0
        t.check(growth < 64 * 1024, "daemon memory bounded while stalled (RSS +%d KiB)" % growth)
        t.check(metric(d, "fxs_connections") == 1, "one connection left")
        await good.close()
    finally:
        d.stop()


def ws_frames(sock, buf):
    """Splits complete server WebSocket messages off buf (unmasked, FIN set: frames are sent
    as one message of continuation fragments, which this joins); returns (messages, rest)."""
    out, msg = [], b""
    while True:
        if len(buf) < 2:
            return out, buf
        n, off = buf[1] & 0x7F, 2
        if n == 126:
            if len(buf) < 4:
                return out, buf
            n, off = int.from_bytes(buf[2:4], "big"), 4
        elif n == 127:
            if len(buf) < 10:
                return out, buf
            n, off = int.from_bytes(buf[2:10], "big"), 10
        if len(buf) < off + n:
            return out, buf
        msg += buf[off:off + n]
        fin, buf = buf[0] & 0x80, buf[off + n:]
        if fin:
            out.append(msg)
            msg = b""
        elif not buf:
            return out, b""


async def test_slow_reader_latency(t):
    d = Daemon("--config", config_file({"limits": {"max_buffered_bytes": 131072}, "streams": [
        {"stream": "big", "effect": "energy_wave", "params": {"width": 256, "height": 256, "fps": 30}}]}))
    try:
        s, _ = stalled_reader(d.port, "big", rcvbuf=32768)
        ages, seqs, buf, t0, got = [], [], b"", time.monotonic(), 0
        s.settimeout(1)
        while time.monotonic() - t0 < 8:  # at most 320 kB/s, far below the stream's ~3 MB/s
            try:
                chunk = s.recv(32768)
            except socket.timeout:
                continue
            if not chunk:
                break
            got += len(chunk)
            msgs, buf = ws_frames(s, buf + chunk)
            for m in msgs:
                if len(m) >= 64 and m[:4] == b"FXS1" and m[6] == 2:  # textures only (kind 3 rigs are tiny)
                    seq, t_us = int.from_bytes(m[16:24], "little"), int.from_bytes(m[32:40], "little")
                    ages.append(time.time() - t_us / 1e6)
                    seqs.append(seq)
            await asyncio.sleep(0.1)
        late = ages[len(ages) // 2:]
        t.check(len(seqs) >= 4 and seqs[-1] - seqs[0] > len(seqs),
                "a slow reader gets frames skipped (%d frames, seq %s..%s)" % (len(seqs), seqs[:1], seqs[-1:]))
        t.check(late and max(late) < 2.5, "its frames stay fresh: age at most %.2f s (max_buffered_bytes 128 KiB)"
                % (max(late) if late else -1))
        s.close()
    finally:
        d.stop()


async def test_kill9_burst(t):
    state = tempfile.mkdtemp(prefix="fxs-state-")
    d = Daemon(state_dir=state)
    acked = {}
    try:
        c = await Client.connect(d)

        async def burst():
            for i in range(1000):
                await c.ws.send(json.dumps({"op": "set", "id": i, "stream": "energy", "params": {"fps": 1 + i % 50}}))
            while True:
                m = await c.text(10)
                if m.get("op") == "params" and "id" in m:
                    acked[m["rev"]] = m["params"]["fps"]

        task = asyncio.ensure_future(burst())
        while len(acked) < 100:
            await asyncio.sleep(0.005)
        n_acked = len(acked)
        writes = metric(d, "fxs_state_writes_total")
        t.check(writes is not None and writes >= n_acked,
                "write before apply: %s state writes for %d acknowledged sets" % (writes, n_acked))
        d.proc.send_signal(signal.SIGKILL)
        try:
            await asyncio.wait_for(task, 10)
        except Exception:
            pass
    finally:
        d.stop()
    last = max(acked)
    t.check(d.proc.returncode == -signal.SIGKILL, "killed with -9 after %d acknowledged sets" % len(acked))
    d2 = Daemon(state_dir=state)
    try:
        c = await Client.connect(d2)
        r = await c.request("get", stream="energy")
        t.check(r["rev"] >= last, "restart: revision %d, last acknowledged %d" % (r["rev"], last))
        want = acked.get(r["rev"], 1 + (r["rev"] - 2) % 50)
        t.check(r["params"]["fps"] == want, "restart: fps %s is that of revision %d" % (r["params"]["fps"], r["rev"]))
        await c.close()
    finally:
        d2.stop()


async def test_failing_stream(t):
    d = Daemon()
    try:
        c = await Client.connect(d)
        r = await c.request("create", effect="flame", stream="blowup", params={
            "diffusion_mode": "literal", "k_f": 0.01, "k_h": 0.1, "sources": [{"radius": 0.015}]})
        t.check(r["op"] == "created", "create a flame that blows up (literal diffusion)")
        await c.request("subscribe", stream="blowup")
        await c.request("subscribe", stream="energy")
        errors, energy, t0 = [], 0, time.monotonic()
        while time.monotonic() - t0 < 20 and (len(errors) < 2 or energy < 20):
            m = await c.recv(10)
            if isinstance(m, bytes):
                energy += m[6] == 2  # kind byte of the header
            else:
                m = json.loads(m)
                if m.get("op") == "error":
                    errors.append(m)
        t.check(len(errors) >= 2 and all(e["code"] == "internal" and e["stream"] == "blowup" for e in errors),
                "the failing stream reports error events (%s)" % (errors[0]["message"] if errors else "none"))
        t.check(energy >= 20, "the energy stream keeps sending frames meanwhile (%d)" % energy)
        n = metric(d, 'fxs_stream_errors_total{stream="blowup",effect="flame"}')
        t.check(n is not None and n >= 2, "/metrics counts the stream's errors (%s)" % n)
        with urllib.request.urlopen(d.http + "/healthz", timeout=10) as resp:
            h = json.loads(resp.read())
        t.check(h["status"] == "ok", "the daemon stays up")
        await c.close()
    finally:
        t.check(d.stop() == 0, "clean exit afterwards")


if __name__ == "__main__":
    Suite("test_faults").run([test_stalled_reader, test_slow_reader_latency, test_kill9_burst, test_failing_stream], timeout=90)
