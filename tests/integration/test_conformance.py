"""test_conformance.py — RFC 6455 framing cases in the manner of the Autobahn suite, sent by a
client built from the RFC's rules (rawws.py) to a real daemon:
- a client frame must be masked (5.1): an unmasked text, binary, ping or continuation frame,
  one split across writes, one after long masked frames (16- and 64-bit lengths) and one sent
  together with the handshake each close the connection with 1002, and nothing of that frame
  is acted on;
- masked frames split byte by byte, fragmented messages and pings are served;
- a text frame that is not UTF-8 closes with 1007 (8.1), also when split inside a character
  across fragments, while a character split across fragments is accepted;
- every reply is valid UTF-8 (the raw reader decodes strictly);
- over TLS the same unmasked frame closes with 1002 (the guard reads SSL_read's bytes);
- whatever libwebsockets takes as the end of a handshake (bare \n line endings, \r\r\n, a
  header name that swallows the line end, an escaped line end in the path, a request before
  the upgrade on the same connection), the guard sees the same end: an unmasked frame after
  it is never acted on, over plain and TLS, and a handshake it can follow is served;
- a client's close frame (5.5.1, 7.4) is answered with its own code when it is valid, with
  1002 for a one-byte payload or a code a client may not send, with 1007 for a reason that is
  not UTF-8 (cut inside a character too), and nothing sent after it is acted on.
After each case the daemon still serves a new connection."""
import json
import ssl
import struct
import tempfile
import time

from fxtest import Daemon, Suite, refusal
from rawws import OP_BINARY, OP_CLOSE, OP_CONT, OP_PING, OP_PONG, OP_TEXT, Conn, frame, handshake
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


def close_answer(payload, after=b""):
    """The server's close frame (code, reason) in answer to a client close with payload (and the
    bytes after it in the same write), and the text messages before it."""
    c = opened()
    c.send(frame(payload, op=OP_CLOSE) + after)
    texts, answer = [], None
    try:
        while answer is None:
            fin, op, data = c.read_frame()
            if op == OP_CLOSE:
                answer = (int.from_bytes(data[:2], "big") if len(data) >= 2 else None, data[2:])
            elif op == OP_TEXT:
                texts.append(data.decode("utf-8"))
    except (ConnectionError, OSError):
        pass
    c.close()
    return answer, texts


async def test_close_frames(t):
    """Close frames as RFC 6455 5.5.1 and 7.4 have them: left to itself lws 4.1 echoes a
    one-byte payload, codes 5000 and 65535 and a reason cut inside a character, and acts on a
    request sent after the client's close."""
    code = lambda n: struct.pack(">H", n)
    for payload, want, what in ((b"", (None, b""), "an empty close is echoed empty"),
                                (code(1000) + b"bye", (1000, b"bye"), "1000 with a reason is echoed"),
                                (code(3000), (3000, b""), "a registered code (3000) is echoed"),
                                (code(4999) + "\u00e9".encode(), (4999, "\u00e9".encode()), "a private code with a UTF-8 reason"),
                                (b"\x03", (1002, b"close frame of one byte"), "a one-byte close: 1002"),
                                (code(5000), (1002, b"close status code not allowed"), "code 5000: 1002"),
                                (code(65535), (1002, b"close status code not allowed"), "code 65535: 1002"),
                                (code(999), (1002, b""), "code 999: 1002 (lws rewrites the code)"),
                                (code(1000) + "\u00e9".encode()[:1], (1007, b"close reason not UTF-8"),
                                 "a reason cut inside a character: 1007")):
        answer, _ = close_answer(payload)
        t.check(answer == want, "%s (%s)" % (what, answer))
    # a destroy after the client's close, in the same write: not acted on
    answer, texts = close_answer(code(1000), frame('{"op":"destroy","stream":"flame","id":7}'))
    c = opened()
    c.send(frame(LIST))
    names = [s["stream"] for s in json.loads(c.read_text())["streams"]]
    c.close()
    t.check(answer == (1000, b"") and not texts and "flame" in names,
            "a request after the client's close frame is not acted on (%s, %s, %s)" % (answer, texts, names))
    await served(t, "close frames")


VICTIM = '{"op":"destroy","stream":"victim","id":7}'


def victim_there(port=None, wrap=None):
    """Whether the stream "victim" exists (created when not: the next case starts with it)."""
    c = opened(wrap, port)
    c.send(frame('{"op":"list","id":1}'))
    there = any(s["stream"] == "victim" for s in json.loads(c.read_text())["streams"])
    if not there:
        c.send(frame('{"op":"create","effect":"energy_wave","stream":"victim","id":2}'))
        c.read_text()
    c.close()
    return there


def boundary_cases(port):
    """(what, request bytes) that end a handshake where lws ends it, each followed (in the same
    write) by an unmasked destroy of "victim"."""
    std = handshake(port)
    return (("bare \\n line endings", handshake(port, eol="\n")),
            ("\\r\\n lines ended by a bare \\n", std[:-2] + b"\n"),
            ("\\r\\r\\n line endings", handshake(port, eol="\r\r\n")),
            ("mixed line endings", handshake(port).replace(b"Upgrade\r\n", b"Upgrade\n")),
            ("a header without a colon last", std[:-2] + b"X-Junk\r\n\r\n"),
            ("a header name that ends at its colon", handshake(port, headers=("A: b",))),
            ("an escaped line end in the path", handshake(port, path="/v1/ws?x=%0a")),
            ("an escaped line end, then a bare \\n", handshake(port, eol="\n", path="/v1/ws%0A")),
            ("a request before the upgrade", b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n" + std),
            ("a request with a body before it", b"GET /healthz HTTP/1.1\r\nContent-Length: 2\r\n\r\nab" + std),
            ("Upgrade: h2c", std.replace(b"Upgrade: websocket", b"Upgrade: h2c")),
            ("Upgrade: WebSocket twice", std.replace(b"Upgrade: websocket", b"Upgrade: WebSocket\r\nUpgrade: x")))


async def test_handshake_boundaries(t, port=None, wrap=None, label=""):
    """The guard sees each handshake end where lws sees it: a handshake with bare \\n line
    endings then an unmasked destroy must be refused, not answered `destroyed`, over plain and
    TLS."""
    port = port or D.port
    victim_there(port, wrap)
    for what, request in boundary_cases(port):
        try:
            c = Conn.connect(port, wrap=wrap, request=request + frame(VICTIM, masked=False), timeout=5)
            texts, code = until_close(c) if b" 101" in c.status else ([], None)
            c.close()
        except OSError as e:  # lws waits for the rest of a request it cannot end
            c, texts, code = Conn(None), [], None
            c.status = ("(%s)" % type(e).__name__).encode()
        kept = victim_there(port, wrap)
        t.check(kept and not any('"destroyed"' in x for x in texts) and (code == 1002 or b" 101" not in c.status),
                "%s%s, then an unmasked destroy: not acted on (%s, close %s, stream kept %s)"
                % (label, what, c.status.decode(errors="replace"), code, kept))
    for what, request in (("bare \\n line endings", handshake(port, eol="\n")),
                          ("mixed line endings", handshake(port).replace(b"Upgrade\r\n", b"Upgrade\n")),
                          ("Upgrade: WebSocket", handshake(port).replace(b"Upgrade: websocket", b"Upgrade: WebSocket")),
                          ("a header name that ends at its colon", handshake(port, headers=("A: b", "Accept: x")))):
        c = Conn.connect(port, wrap=wrap, request=request)
        ok = b" 101" in c.status and json.loads(c.read_text())["op"] == "hello"
        c.send(frame(LIST))
        t.check(ok and json.loads(c.read_text())["id"] == 7, "%sa handshake with %s is served" % (label, what))
        c.close()
    # a proxy's kept-alive link (nginx): a GET, its response, then the upgrade on the same connection
    c = Conn.connect(port, wrap=wrap, request=b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
    c._need(int(c.head.lower().split(b"content-length:")[1].split(b"\r\n")[0]))
    c.send(handshake(port, eol="\n") + frame(LIST))
    data = c.buf  # what was read past the body: the 101's start
    while b"\r\n\r\n" not in data:
        chunk = c.s.recv(4096)
        if not chunk:
            break
        data += chunk
    head, _, c.buf = data.partition(b"\r\n\r\n")
    ok = b" 101" in head.split(b"\r\n")[0] and json.loads(c.read_text())["op"] == "hello"
    t.check(ok and json.loads(c.read_text())["id"] == 7, "%san upgrade after a GET answered on the same connection "
            "(a proxy's kept-alive link) is served" % label)
    c.send(frame(VICTIM, masked=False))
    texts, code = until_close(c)
    c.close()
    t.check(code == 1002 and victim_there(port, wrap), "%sand an unmasked frame on it closes with 1002 (%s)" % (label, code))


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
        await test_handshake_boundaries(t, d.port, wrap, "TLS: ")
        c = opened(wrap, d.port)
        c.send(frame(LIST))
        t.check(json.loads(c.read_text())["id"] == 7, "TLS: the daemon serves the next connection")
        c.close()


if __name__ == "__main__":
    D = Daemon()
    try:
        Suite("test_conformance").run([test_masked_served, test_unmasked, test_utf8, test_close_frames,
                                        test_handshake_boundaries, test_tls])
    finally:
        D.stop()
