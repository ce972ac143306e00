/* test_wsguard.c — the masking guard's parts that need no libwebsockets connection:
 * lwsreq ends a request's headers at the byte where libwebsockets 4.1's parser ends
 * them (bare \n line ends, names that run on to their colon, escapes in the path, the first
 * Upgrade's value, a body after which it cannot follow the next request), and the guard follows only the sockets it was given, each until it is
 * told the connection is gone, so any other socket read with recv() on its thread (a Redis
 * link with hiredis 1.x) passes untouched. That unmasked frames are refused on a real
 * connection, plain and TLS, is test_conformance's. */
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "check.h"
#include "lwsreq.h"
#include "wsguard.h"

/* Where lwsreq says the headers of text end: the index of that byte (-1: not within text) and
 * how, or where it gave up (LWSREQ_LOST). */
static int tw_end(const char *text, enum lwsreq_end *how)
{
    struct lwsreq r;
    lwsreq_start(&r);
    for (int i = 0; text[i]; i++)
        if ((*how = lwsreq_byte(&r, (uint8_t)text[i])) != LWSREQ_MORE) return i;
    *how = LWSREQ_MORE;
    return -1;
}

/* Expects text to end at byte `at` (from the end when negative) as `want`. */
static void tw_case(const char *text, int at, enum lwsreq_end want)
{
    enum lwsreq_end how;
    int end = tw_end(text, &how);
    if (want == LWSREQ_MORE) at = -1;           /* not within text */
    else if (at < 0) at = (int)strlen(text) + at; /* from the end */
    CHECK(end == at && how == want, "%s: ends at %d as %d, expected %d as %d", text, end, how, at, want);
}

#define UP "Upgrade: websocket"

static void test_request_ends(void)
{
    lwsreq_init();
    tw_case("GET / HTTP/1.1\r\nHost: x\r\n\r\n", -1, LWSREQ_OTHER);
    tw_case("GET /v1/ws HTTP/1.1\r\nHost: x\r\n" UP "\r\n\r\nFRAME", -6, LWSREQ_WEBSOCKET);
    tw_case("GET /v1/ws HTTP/1.1\n" UP "\n\nFRAME", -6, LWSREQ_WEBSOCKET);        /* bare \n */
    tw_case("GET /v1/ws HTTP/1.1\r\n" UP "\r\n\nFRAME", -6, LWSREQ_WEBSOCKET);    /* \r\n then \n */
    tw_case("GET /v1/ws HTTP/1.1\r\n" UP "\r\r\n\r\nFRAME", -6, LWSREQ_WEBSOCKET); /* a value's \r\r\n */
    tw_case("G\n", 1, LWSREQ_OTHER); /* lws takes the request's second byte as a line's start too */
    /* a name lws does not know runs on, line ends included, to the first ':' after it ends */
    tw_case("GET / HTTP/1.1\nA: b\n\nX: y\n\n", -1, LWSREQ_OTHER);
    tw_case("GET / HTTP/1.1\r\nX-Junk\r\n\r\n", -1, LWSREQ_MORE);
    tw_case("GET / HTTP/1.1\r\nX-Junk\r\n\r\nZ: 1\r\n\r\n", -1, LWSREQ_OTHER);
    tw_case("GET / HTTP/1.1\r\r\nHost: x\r\r\n\r\r\n", -1, LWSREQ_MORE);         /* \r\r\n at a line's start */
    tw_case("GET / HTTP/1.1\r\nAccept: */*\r\nX-Any: 1\r\n\r\n", -1, LWSREQ_OTHER); /* known and unknown names */
    /* the first Upgrade's value, as lws compares it (strcasecmp after leading spaces) */
    tw_case("GET / HTTP/1.1\r\nUpgrade:   WebSocket\r\n\r\n", -1, LWSREQ_WEBSOCKET);
    tw_case("GET / HTTP/1.1\r\nUpgrade: websocket \r\n\r\n", -1, LWSREQ_OTHER);
    tw_case("GET / HTTP/1.1\r\nUpgrade: h2c\r\n\r\n", -1, LWSREQ_OTHER);
    tw_case("GET / HTTP/1.1\r\nUpgrade: x\r\n" UP "\r\n\r\n", -1, LWSREQ_OTHER);
    tw_case("GET / HTTP/1.1\r\n" UP "\r\nUpgrade: x\r\n\r\n", -1, LWSREQ_WEBSOCKET);
    /* what it does not follow */
    tw_case("GET /v1/ws%0a HTTP/1.1\r\n", 12, LWSREQ_LOST);
    tw_case("GET /a%0D", 8, LWSREQ_LOST);
    tw_case("GET /a%00", 8, LWSREQ_LOST);
    tw_case("GET /a%zz", 7, LWSREQ_LOST);
    tw_case("GET /a%20b?c=%41 HTTP/1.1\r\n\r\n", -1, LWSREQ_OTHER); /* other escapes are fine */
    tw_case("GET / HTTP/1.1\r\nPOST / HTTP/1.1\r\n", 20, LWSREQ_LOST);  /* a second method */
    tw_case("CONNECT a:1 HTTP/1.1\r\n\r\n", 7, LWSREQ_LOST);             /* lws makes it a raw socket */
    tw_case("FOO / HTTP/1.1\r\n\r\n", 1, LWSREQ_LOST);                    /* lws refuses the method */
    tw_case("put /x HTTP/1.1\n\n", -1, LWSREQ_OTHER);                     /* lower case, no space in lws's "put" */
    tw_case("GET / HTTP/1.1\r\nContent-Length: 3\r\n\r\nabc", -4, LWSREQ_LOST); /* the next starts after a body */
    tw_case("GET / HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n", -1, LWSREQ_LOST);
}

/* n bytes written to one end of a socket pair, read back with recv() at the other. */
static ssize_t tw_through(int w, int r, const void *bytes, size_t n, uint8_t *back)
{
    if (write(w, bytes, n) != (ssize_t)n) return -2;
    return recv(r, back, 256, 0);
}

static void test_follows_only_its_sockets(void)
{
    static const uint8_t unmasked[] = {0x81, 0x02, 'h', 'i'};
    static const char hs[] = "GET /v1/ws HTTP/1.1\nUpgrade: websocket\n\n";
    uint8_t back[256];
    int a[2], b[2];
    struct lws *fake = (struct lws *)&a; /* never dereferenced: no frame here is refused */
    wsguard_start(false);
    CHECK(!socketpair(AF_UNIX, SOCK_STREAM, 0, a), "socketpair");
    CHECK(tw_through(a[0], a[1], unmasked, 4, back) == 4, "a socket it was not given: an unmasked frame passes");
    wsguard_open(fake, a[1]);
    CHECK(tw_through(a[0], a[1], hs, sizeof hs - 1, back) == (ssize_t)sizeof hs - 1, "a handshake passes");
    static const uint8_t masked[] = {0x81, 0x82, 1, 2, 3, 4, 'h' ^ 1, 'i' ^ 2};
    CHECK(tw_through(a[0], a[1], masked, sizeof masked, back) == sizeof masked, "then a masked frame");
    wsguard_close(fake); /* lws destroyed the connection, */
    close(a[0]);
    close(a[1]); /* and closed its socket; the next socket takes its number */
    CHECK(!socketpair(AF_UNIX, SOCK_STREAM, 0, b) && (b[0] == a[1] || b[1] == a[1]), "the number is reused");
    int r = b[0] == a[1] ? b[0] : b[1], w = b[0] == a[1] ? b[1] : b[0];
    CHECK(tw_through(w, r, unmasked, 4, back) == 4 && !memcmp(back, unmasked, 4),
          "a new socket on a destroyed connection's number is not followed: its bytes pass");
    close(b[0]);
    close(b[1]);
    wsguard_stop();
}

int main(void)
{
    RUN(test_request_ends);
    RUN(test_follows_only_its_sockets);
    return CHECK_DONE();
}
