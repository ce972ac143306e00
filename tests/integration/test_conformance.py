"""test_conformance.py — RFC 6455 framing cases in the manner of the Autobahn suite, sent by a
client built from the RFC's rules (rawws.py) to a real daemon (issue 15 items 8 and 13):
- a client frame must be masked (5.1): an unmasked text, binary, ping or continuation frame,
  one split across writes, one after long masked frames (16- and 64-bit lengths) and one sent
  together with the handshake each close the connection with 1002, and nothing of that frame
  is acted on;
- masked frames split byte by byte, fragmented messages and pings are served;
- a text frame that is not UTF-8 closes with 1007 (8.1), also when split inside a character
  across fragments, while a character split across fragments is accepted;
- every reply is valid UTF-8 (the raw reader decodes strictly);
- over TLS the same unmasked frame closes with 1002 (the guard reads SSL_read's bytes).
After each case the daemon still serves a new connection."""
import json
import ssl
import tempfile
import time

from fxtest import Daemon, Suite, refusal
from rawws import OP_BINARY, OP_CONT, OP_PING, OP_PONG, OP_TEXT, Conn, frame
from test_access import self_signed

D = None
LIST = '{"op":"list","id":7}'


def until_close(c):
    """(text messages received, close code) until the server closes; code None when it
    closed without a close frame. A text that is not UTF-8 raises."""
    texts = []
    try:
        while True:
            fin, op, data = c.read_frame()
            if op == 8:
                return texts, (int.from_bytes(data[:2], "big") if len(data) >= 2 else None)
            if op == OP_TEXT:
                texts.append(data.decode("utf-8"))
    except (ConnectionError, OSError):
        return texts, None


def opened(wrap=None, port=None):
    """A connection past its hello."""
    c = Conn.connect(port or D.port, wrap=wrap)
    hello = json.loads(c.read_text())
    assert hello["op"] == "hello", hello
    return c


async def served(t, what):
    t.check(await refusal(D, read=True) is None, "%s: the daemon serves the next connection" % what)


async def test_masked_served(t):
    c = opened()
    for b in frame(LIST):  # one byte per write: the guard follows headers across reads
        c.send(bytes([b]))
        time.sleep(0.002)
    r = json.loads(c.read_text())
    t.check(r["op"] == "list" and r["id"] == 7, "a masked frame sent byte by byte is served (%s)" % r["op"])
    c.send(frame('{"op":"list","id":8' + " " * 300 + "}"))  # 16-bit length
    t.check(json.loads(c.read_text())["id"] == 8, "a masked frame with a 16-bit length is served")
    c.send(frame('{"op":"list","id":9' + " " * 70000 + "}"))  # 64-bit length, past max_message_bytes
    r = json.loads(c.read_text())
    t.check(r["op"] == "error" and r["code"] == "limit", "a masked frame with a 64-bit length is read to its end (%s)" % r.get("code"))
    c.send(frame('{"op":', fin=False) + frame(b'"list","id":10}', op=OP_CONT))
    t.check(json.loads(c.read_text())["id"] == 10, "a fragmented masked message is served")
    c.send(frame(b"ab", op=OP_PING))
    fin, op, data = c.read_frame()
    t.check(op == OP_PONG and data == b"ab", "a masked ping gets its pong")
    c.close()
    await served(t, "masked frames")


async def unmasked_case(t, what, prefix, bad, port=None, wrap=None):
    """Sends prefix (masked frames, answered) then the unmasked bytes bad: a close with 1002 and
    no reply to the unmasked frame."""
    c = opened(wrap, port)
    if prefix:
        c.send(prefix)
        c.read_text()
    c.send(bad)
    texts, code = until_close(c)
    c.close()
    t.check(code == 1002 and not any('"id":7' in x for x in texts),
            "%s: closed with 1002, not acted on (close %s, replies %s)" % (what, code, texts))


async def test_unmasked(t):
    await unmasked_case(t, "an unmasked text frame", b"", frame(LIST, masked=False))
    await unmasked_case(t, "an unmasked binary frame", b"", frame(b"\0\1\2", op=OP_BINARY, masked=False))
    await unmasked_case(t, "an unmasked ping", b"", frame(b"x", op=OP_PING, masked=False))
    await unmasked_case(t, "an unmasked continuation of a masked first fragment", b"",
                        frame('{"op":', fin=False) + frame(b'"list","id":7}', op=OP_CONT, masked=False))
    await unmasked_case(t, "an unmasked frame after masked 16- and 64-bit frames",
                        frame('{"op":"list","id":1' + " " * 300 + "}"), frame(LIST, masked=False))
    c = opened()
    bad = frame(LIST, masked=False)
    c.send(bad[:1])  # the header split between writes
    time.sleep(0.05)
    c.send(bad[1:])
    texts, code = until_close(c)
    c.close()
    t.check(code == 1002 and not texts, "an unmasked frame whose header is split across writes: 1002 (%s)" % code)
    c = Conn.connect(D.port, extra=frame(LIST, masked=False))  # in the handshake's own write
    texts, code = until_close(c)
    c.close()
    t.check(b" 101" in c.status and code == 1002 and not texts,
            "an unmasked frame sent with the handshake: 101, then 1002 before any message (%s, %s)" % (code, texts))
    t.check("unmasked frame" in D.log(), "the log names the unmasked frame")
    await served(t, "unmasked frames")


async def test_utf8(t):
    c = opened()
    c.send(frame('{"op":"list","id":"\u00e9'.encode()[:-1], fin=False) + frame(b"\xa9" + b'"}', op=OP_CONT))
    r = json.loads(c.read_text())
    t.check(r["op"] == "list" and r["id"] == "\u00e9", "a character split across fragments is accepted (%s)" % r.get("id"))
    c.send(frame(b'{"op":"list","id":"\xc3', fin=False) + frame(b'x"}', op=OP_CONT))
    texts, code = until_close(c)
    c.close()
    t.check(code == 1007, "a character cut off by the next fragment: closed with 1007 (%s)" % code)
    c = opened()
    c.send(frame(b'{"op":"' + b"x" * 63 + "\u00e9".encode() + b'"}'))  # an unknown op quoted back
    r = json.loads(c.read_text())
    t.check(r["op"] == "error", "an unknown op cut inside a character is quoted back as valid UTF-8 (%s)" % r["message"][-20:])
    c.close()
    await served(t, "UTF-8")


async def test_tls(t):
    tmp = tempfile.mkdtemp(prefix="fxs-tls-")
    cert, key = self_signed(tmp)
    with Daemon("--tls-cert", cert, "--tls-key", key) as d:
        ctx = ssl.create_default_context(cafile=cert)
        wrap = lambda s: ctx.wrap_socket(s, server_hostname="127.0.0.1")
        c = opened(wrap, d.port)
        c.send(frame(LIST))
        t.check(json.loads(c.read_text())["id"] == 7, "TLS: a masked frame is served")
        c.close()
        await unmasked_case(t, "TLS: an unmasked text frame", b"", frame(LIST, masked=False), d.port, wrap)
        await unmasked_case(t, "TLS: an unmasked frame after a masked one", frame('{"op":"list","id":1}'),
                            frame(LIST, masked=False), d.port, wrap)
        c = opened(wrap, d.port)
        c.send(frame(LIST))
        t.check(json.loads(c.read_text())["id"] == 7, "TLS: the daemon serves the next connection")
        c.close()


if __name__ == "__main__":
    D = Daemon()
    try:
        Suite("test_conformance").run([test_masked_served, test_unmasked, test_utf8, test_tls])
    finally:
        D.stop()
