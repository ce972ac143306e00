"""rawws.py — a WebSocket client built from RFC 6455's framing rules alone (tests only), for
what a conforming library will not send: unmasked frames, headers split across writes, frames
sent with the handshake. Frames are built by frame(); read_frame() parses what the server
sends (unmasked, RFC 6455 5.2)."""
import base64
import os
import socket
import struct

OP_CONT, OP_TEXT, OP_BINARY, OP_CLOSE, OP_PING, OP_PONG = 0, 1, 2, 8, 9, 10


def handshake(port, extra=b"", version="13", eol="\r\n", path="/v1/ws", headers=()):
    """The upgrade request for fxstream.v1 on path, lines ended by eol, with headers (lines)
    before the standard ones and extra bytes sent in the same write."""
    key = base64.b64encode(os.urandom(16)).decode()
    lines = ["GET %s HTTP/1.1" % path, *headers, "Host: 127.0.0.1:%d" % port, "Upgrade: websocket",
             "Connection: Upgrade", "Sec-WebSocket-Key: " + key, "Sec-WebSocket-Version: " + version,
             "Sec-WebSocket-Protocol: fxstream.v1", "", ""]
    return eol.join(lines).encode() + extra


def frame(payload, op=OP_TEXT, fin=True, masked=True):
    """One frame; the shortest length encoding (7, 16 or 64 bits), masked with a random key
    unless masked is False."""
    if isinstance(payload, str):
        payload = payload.encode()
    n = len(payload)
    head = bytes([(0x80 if fin else 0) | op])
    bit = 0x80 if masked else 0
    if n < 126:
        head += bytes([bit | n])
    elif n < 65536:
        head += bytes([bit | 126]) + struct.pack(">H", n)
    else:
        head += bytes([bit | 127]) + struct.pack(">Q", n)
    if not masked:
        return head + payload
    mask = os.urandom(4)
    return head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))


class Conn:
    """A raw connection: connect() sends the handshake (and extra bytes in the same write),
    reads the response head byte by byte so no frame byte is consumed with it."""

    def __init__(self, sock):
        self.s = sock
        self.buf = b""
        self.head = b""  # the server's response head
        self.status = b""  # its first line

    @classmethod
    def connect(cls, port, extra=b"", wrap=None, timeout=10, rcvbuf=None, version="13", request=None):
        """rcvbuf: the socket's receive buffer, set before connecting (a client that reads
        slowly or never); version: Sec-WebSocket-Version; request: bytes sent instead of
        handshake(port, extra, version)."""
        s = socket.socket()
        if rcvbuf:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
        s.settimeout(timeout)
        s.connect(("127.0.0.1", port))
        if wrap:
            s = wrap(s)
        c = cls(s)
        s.sendall(request if request is not None else handshake(port, extra, version))
        while b"\r\n\r\n" not in c.head:
            b = s.recv(1)
            if not b:
                break
            c.head += b
        c.status = c.head.split(b"\r\n")[0]
        return c

    def send(self, data):
        self.s.sendall(data)

    def _need(self, n):
        while len(self.buf) < n:
            chunk = self.s.recv(65536)
            if not chunk:
                raise ConnectionError("closed by the server")
            self.buf += chunk
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def read_frame(self):
        """(fin, opcode, payload) of the next frame; ConnectionError when the socket closes."""
        b0, b1 = self._need(2)
        n = b1 & 0x7F
        if n == 126:
            n = struct.unpack(">H", self._need(2))[0]
        elif n == 127:
            n = struct.unpack(">Q", self._need(8))[0]
        mask = self._need(4) if b1 & 0x80 else None
        data = self._need(n)
        if mask:
            data = bytes(b ^ mask[i % 4] for i, b in enumerate(data))
        return bool(b0 & 0x80), b0 & 0x0F, data

    def read_text(self):
        """The next whole text message (continuations joined), skipping binary frames."""
        parts, op = [], None
        while True:
            fin, o, data = self.read_frame()
            if o == OP_CLOSE:
                raise ConnectionError("close frame %r" % close_code(data))
            if o in (OP_TEXT, OP_BINARY):
                op, parts = o, [data]
            elif o == OP_CONT:
                parts.append(data)
            if fin and op == OP_TEXT and o in (OP_TEXT, OP_CONT):
                return b"".join(parts).decode("utf-8")

    def close_code(self):
        """The status code of the server's close frame, skipping the frames before it; None
        when the socket closed without one."""
        try:
            while True:
                _, op, data = self.read_frame()
                if op == OP_CLOSE:
                    return close_code(data)
        except (ConnectionError, OSError):
            return None

    def close(self):
        try:
            self.s.close()
        except OSError:
            pass


def close_code(payload):
    return struct.unpack(">H", payload[:2])[0] if len(payload) >= 2 else None
