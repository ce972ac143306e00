/* lwsreq.h — where libwebsockets 4.1 ends an HTTP request's headers, byte by byte, so the
 * masking guard (wsguard.h) knows where a WebSocket handshake ends and its frames begin
 * exactly where lws does. lws's parser (lws_parse) is lenient: a bare \n ends a line, a header
 * name it does not know runs on, line ends included, until its first ':', "%0a" in the path
 * ends the request line. A guard that looked for "\r\n\r\n" read frames sent after a
 * handshake with bare \n line endings as more of the request and let an unmasked one
 * through.
 *
 * This follows lws_parse's states as far as the end depends on them: the header names lws
 * knows (its own table, lws_token_to_string), line ends in values, and its one quirk (an
 * empty line is seen as such at the request's second byte too). What it does not follow
 * exactly ends as LWSREQ_LOST: a percent escape in the request line that is a control
 * character or no escape at all, a second method, CONNECT (lws turns it into a raw socket),
 * a first line that lws refuses, and the end of a request with a body (Content-Length,
 * Transfer-Encoding: the next request starts after the body). The caller then treats the
 * connection as one whose upgrade is not to be accepted. A request without a body is followed
 * by the next one on the same connection (keep-alive: a proxy such as nginx may send an
 * upgrade on a connection that served a GET before). */
#ifndef FX_LWSREQ_H
#define FX_LWSREQ_H

#include <stdbool.h>
#include <stdint.h>

enum lwsreq_end {
    LWSREQ_MORE,      /* the headers go on */
    LWSREQ_WEBSOCKET, /* they ended with this byte: a request whose (first) Upgrade is websocket */
    LWSREQ_OTHER,     /* they ended with this byte: another request without a body; the next starts */
    LWSREQ_LOST,      /* not followed (see above) */
};

struct lwsreq {
    uint8_t part;      /* a name, the request line after its method, the rest of a line */
    bool line_start;   /* no byte of the current name read yet (lws: unk_pos == 0) */
    bool started;      /* a byte of the request was read */
    bool method;       /* a method was read */
    bool unknown;      /* the current name is no header lws knows */
    bool body;         /* a Content-Length or Transfer-Encoding header was read */
    uint8_t lo, hi;    /* the known names the current name starts: the sorted table's [lo, hi) */
    uint8_t nlen;      /* its length */
    uint8_t esc, hex;  /* request line: bytes of a %XX escape read; its first digit's value */
    uint8_t up, upn;   /* the first Upgrade header's value, compared with "websocket" */
};

/* Reads lws's header names (once, on the thread that calls it first). */
void lwsreq_init(void);
/* A new request: r is zeroed. */
void lwsreq_start(struct lwsreq *r);
/* One byte of the request: whether the headers go on, end with it, or cannot be followed. */
enum lwsreq_end lwsreq_byte(struct lwsreq *r, uint8_t b);

#endif
