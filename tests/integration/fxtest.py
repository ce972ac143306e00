"""fxtest.py — shared helpers for the integration suites: start a real fxstreamd on a
random loopback port, connect real WebSocket clients (Debian's python3-websockets),
parse binary frame headers, and count named checks into the suite's summary line.
Every wait is bounded, so a hung daemon fails a check instead of hanging the run."""
import asyncio
import json
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time

import websockets

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
DAEMON = os.path.join(ROOT, "build", "fxstreamd")
HEADER = struct.Struct("<4sHHIIQdQIIIIII")  # the 64-byte v1 header, PROTOCOL.md §7.1


def parse_frame(data):
    """Returns the header fields as a dict plus 'payload'."""
    (magic, hbytes, kind, channel, rev, seq, sim_time, t_us, codec, nbytes, w, h, flags,
     total) = HEADER.unpack_from(data)
    return dict(magic=magic, header_bytes=hbytes, kind=kind, channel=channel, param_rev=rev,
                seq=seq, sim_time=sim_time, server_time_us=t_us, codec=codec,
                payload_bytes=nbytes, width=w, height=h, flags=flags, total=total,
                payload=data[hbytes:])


def free_port():
    """A TCP port free on 127.0.0.1 at the moment of asking."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def config_file(doc):
    """Writes doc as a JSON configuration file for --config; returns its path."""
    fd, path = tempfile.mkstemp(suffix=".json")
    with os.fdopen(fd, "w") as f:
        json.dump(doc, f)
    return path


class Daemon:
    """A fxstreamd on 127.0.0.1 with a kernel-chosen port; `with Daemon(...) as d:` stops it."""

    def __init__(self, *args, state_dir=None, env=None, wrapper=(), binary=DAEMON):
        self.state_dir = state_dir or tempfile.mkdtemp(prefix="fxs-state-")
        cmd = [*wrapper, binary, "--port", "0", "--state-dir", self.state_dir, "--log-level", "warn", *args]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     env=dict(os.environ, **(env or {})))
        line = self.proc.stdout.readline()  # bounded by the daemon's own start-up
        if "listening on" not in line:
            self.proc.kill()
            raise RuntimeError("daemon did not start: %r %s" % (line, self.proc.stderr.read()))
        # Drain both pipes from now on: a daemon whose log fills an unread 64 KiB pipe blocks
        # in write() (its event loop with it), which looks like a hung daemon to every check.
        self._err = []
        self._readers = [threading.Thread(target=self._drain, args=(self.proc.stderr, self._err), daemon=True),
                         threading.Thread(target=self._drain, args=(self.proc.stdout, []), daemon=True)]
        for r in self._readers:
            r.start()
        self.port = int(line.split("127.0.0.1:")[1].split("/")[0])
        self.url = "ws://127.0.0.1:%d/v1/ws" % self.port
        self.http = "http://127.0.0.1:%d" % self.port

    @staticmethod
    def _drain(pipe, into):
        for line in pipe:
            into.append(line)

    def log(self):
        """The daemon's stderr so far; all of it once the daemon has exited."""
        if self.proc.poll() is not None:
            for r in self._readers:
                r.join(10)
        return "".join(self._err)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()

    def stop(self, sig=signal.SIGTERM, timeout=10):
        """Signals the daemon and returns its exit status."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return None


def cpu_seconds(daemon):
    """User + system CPU time of the daemon so far (/proc/PID/stat)."""
    with open("/proc/%d/stat" % daemon.proc.pid) as f:
        rest = f.read().rsplit(")", 1)[1].split()
    return (int(rest[11]) + int(rest[12])) / os.sysconf("SC_CLK_TCK")


async def refusal(daemon, url=None, read=False, **kw):
    """How the daemon refused a WebSocket: "http N" (handshake answered with status N),
    "closed" (the connection was dropped during the handshake, or, with read=True, closed
    before the first message) or None (accepted). A daemon that no longer runs or does not
    listen is no refusal: that raises, so a dead daemon cannot pass a "refused" check."""
    kw.setdefault("subprotocols", ["fxstream.v1"])
    try:
        ws = await asyncio.wait_for(websockets.connect(url or daemon.url, **kw), 10)
        try:
            if read:
                await asyncio.wait_for(ws.recv(), 5)
        finally:
            await ws.close()
        result = None
    except websockets.exceptions.InvalidStatusCode as e:
        result = "http %d" % e.status_code
    except (websockets.exceptions.InvalidHandshake, websockets.exceptions.ConnectionClosed,
            ConnectionResetError, asyncio.IncompleteReadError):
        result = "closed"
    if daemon.proc.poll() is not None:
        raise RuntimeError("the daemon exited (%s) during a refusal check" % daemon.proc.returncode)
    return result


class Client:
    """One WebSocket connection speaking fxstream.v1; keeps events and frames apart."""

    def __init__(self, ws):
        self.ws = ws
        self.next_id = 1

    @classmethod
    async def connect(cls, daemon, path="/v1/ws", timeout=10):
        # No keepalive pings: every wait in the suites has its own bound, and the library's
        # 20 s ping timeout dropped connections to a daemon busy building a kernel under valgrind.
        ws = await asyncio.wait_for(websockets.connect(
            "ws://127.0.0.1:%d%s" % (daemon.port, path), subprotocols=["fxstream.v1"],
            max_size=64 << 20, ping_interval=None), timeout)
        c = cls(ws)
        c.hello = await c.text(timeout)
        return c

    async def recv(self, timeout=10):
        return await asyncio.wait_for(self.ws.recv(), timeout)

    async def text(self, timeout=10):
        """The next text message, skipping binary frames."""
        deadline = time.monotonic() + timeout
        while True:
            m = await self.recv(max(0.01, deadline - time.monotonic()))
            if isinstance(m, str):
                return json.loads(m)

    async def frame(self, timeout=20, kind=None):
        """The next binary frame (of `kind` when given: an energy_wave stream also sends its
        light rig), skipping text messages, within timeout s."""
        deadline = time.monotonic() + timeout
        while True:
            m = await self.recv(max(0.01, deadline - time.monotonic()))
            if isinstance(m, bytes) and (kind is None or m[6] == kind):  # kind: header byte 6 (u16 LE)
                return parse_frame(m)

    async def request(self, op, timeout=10, **fields):
        """Sends op with a fresh id; returns the reply with that id."""
        rid = self.next_id
        self.next_id += 1
        await self.ws.send(json.dumps(dict(op=op, id=rid, **fields)))
        deadline = time.monotonic() + timeout
        while True:
            m = await self.text(max(0.01, deadline - time.monotonic()))
            if m.get("id") == rid:
                return m

    async def raw(self, text, timeout=10):
        """Sends text as is; returns the next text message."""
        await self.ws.send(text)
        return await self.text(timeout)

    async def close(self):
        await self.ws.close()


class Suite:
    """Runs async checks in order and prints '<name>: N passed, M failed'."""

    def __init__(self, name):
        self.name, self.passed, self.failed = name, 0, 0

    def check(self, cond, what):
        if cond:
            self.passed += 1
            print("ok   " + what)
        else:
            self.failed += 1
            print("FAIL " + what)
        sys.stdout.flush()
        return cond

    def run(self, tests, timeout=60):
        for t in tests:
            try:
                asyncio.run(asyncio.wait_for(t(self), timeout))
            except Exception as e:  # a crashed test is a failed check, and the suite goes on
                self.check(False, "%s raised %s: %s" % (t.__name__, type(e).__name__, e))
        print("%s: %d passed, %d failed" % (self.name, self.passed, self.failed))
        sys.exit(1 if self.failed else 0)
