/* wsguard.c — see wsguard.h.
 *
 * How the reads are seen: the daemon's executable defines recv() and SSL_read() (and
 * SSL_get_error() and SSL_want(), to answer "want read" for a read it withheld), so
 * libwebsockets' calls bind to these, which call the C library's and OpenSSL's own through
 * dlsym(RTLD_NEXT). Only the thread that called wsguard_start looks at the bytes; on every
 * other thread (the engine, the cluster's Redis link, OpenCL's workers) the functions are
 * plain pass-throughs. On that thread only the sockets of connections lws accepted are
 * followed (wsguard_open), each until lws destroys its connection (wsguard_close): any other
 * socket read there, a Redis link's with hiredis 1.x included, passes untouched.
 *
 * Per connection, indexed by its socket: first its HTTP requests, each followed byte by byte
 * as lws parses it (lwsreq.h), up to the byte where lws ends its headers. A request whose
 * Upgrade is websocket is followed by WebSocket frames. After another request without a body
 * the next one is followed from the first byte read once its response went out
 * (wsguard_next_request): lws 4.1 does not parse what arrives before that as a request (it
 * serves the previous one again), so bytes read in between leave the connection unfollowed,
 * like a request lwsreq cannot follow or a body; wsguard_upgrade_ok then refuses an upgrade
 * on it. Then each frame's header is followed byte by byte (RFC 6455 §5.2: 2 bytes,
 * 2 or 8 of extended length, 4 of masking key) and its payload skipped. A header whose mask
 * bit is clear makes the connection bad: that read returns only the bytes before the frame,
 * later reads are drained and return nothing, and the connection is closed with 1002 where
 * net.c can close it (wsguard_close_if_bad: when it is established, for a frame sent with
 * the handshake, else when it is next writable, which the guard asks for), within
 * WSG_CLOSE_S even if the client never reads the close frame. */
#include <dlfcn.h>
#include <errno.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>

#include <libwebsockets.h>
#include <openssl/ssl.h>

#include "log.h"
#include "lwsreq.h"
#include "utf8.h"
#include "wsguard.h"

#define WSG_CLOSE_S 5

enum wsg_state { WSG_REQUEST, WSG_BETWEEN, WSG_HEADER, WSG_PAYLOAD, WSG_BAD, WSG_UNFOLLOWED };

struct wsg_conn {
    struct lws *wsi;  /* NULL: not a connection lws accepted */
    uint8_t state;
    struct lwsreq req; /* WSG_REQUEST */
    uint8_t hlen;     /* bytes of the current frame header seen */
    uint8_t hneed;    /* its length once the second byte is known */
    uint64_t len;     /* payload length, then payload bytes left */
};

static struct {
    struct wsg_conn *conns;
    int cap;
    bool tls;
    const SSL *wouldblock; /* the SSL whose last SSL_read this guard withheld */
} wsg;
static _Thread_local bool wsg_here; /* this thread runs lws_service */

void wsguard_start(bool tls)
{
    lwsreq_init();
    wsg.tls = tls;
    wsg_here = true;
}

void wsguard_stop(void)
{
    wsg_here = false;
    free(wsg.conns);
    memset(&wsg, 0, sizeof wsg);
}

static struct wsg_conn *wsg_conn(int fd)
{
    return fd >= 0 && fd < wsg.cap && wsg.conns[fd].wsi ? &wsg.conns[fd] : NULL;
}

void wsguard_open(struct lws *wsi, int fd)
{
    if (fd < 0) return;
    if (fd >= wsg.cap) {
        int cap = fd + 1 > 2 * wsg.cap ? fd + 1 : 2 * wsg.cap;
        struct wsg_conn *c = realloc(wsg.conns, sizeof *c * (size_t)cap);
        if (!c) {
            log_error("wsguard: out of memory: the connection on socket %d cannot be followed (no WebSocket on it)", fd);
            return;
        }
        memset(c + wsg.cap, 0, sizeof *c * (size_t)(cap - wsg.cap));
        wsg.conns = c;
        wsg.cap = cap;
    }
    wsg.conns[fd] = (struct wsg_conn){.wsi = wsi, .state = WSG_REQUEST};
    lwsreq_start(&wsg.conns[fd].req);
}

void wsguard_close(struct lws *wsi)
{
    for (int fd = 0; fd < wsg.cap; fd++) /* its socket is closed already: found by wsi */
        if (wsg.conns[fd].wsi == wsi) {
            wsg.conns[fd].wsi = NULL;
            return;
        }
}

void wsguard_next_request(struct lws *wsi)
{
    struct wsg_conn *c = wsg_conn(lws_get_socket_fd(wsi));
    if (!c || c->wsi != wsi || c->state != WSG_BETWEEN) return;
    c->state = WSG_REQUEST;
    lwsreq_start(&c->req);
}

bool wsguard_upgrade_ok(struct lws *wsi)
{
    struct wsg_conn *c = wsg_conn(lws_get_socket_fd(wsi));
    return c && c->wsi == wsi && (c->state == WSG_HEADER || c->state == WSG_PAYLOAD || c->state == WSG_BAD);
}

bool wsguard_close_if_bad(struct lws *wsi)
{
    struct wsg_conn *c = wsg_conn(lws_get_socket_fd(wsi));
    if (!c || c->wsi != wsi || c->state != WSG_BAD) return false;
    lws_close_reason(wsi, LWS_CLOSE_STATUS_PROTOCOL_ERR, (uint8_t *)"unmasked frame", 14);
    return true;
}

/* One byte of a request; the state after it. */
static void wsg_request_byte(struct wsg_conn *c, uint8_t b)
{
    switch (lwsreq_byte(&c->req, b)) {
    case LWSREQ_MORE: return;
    case LWSREQ_WEBSOCKET:
        c->state = WSG_HEADER;
        c->hlen = 0;
        return;
    case LWSREQ_OTHER: c->state = WSG_BETWEEN; return; /* until its response went out */
    default: c->state = WSG_UNFOLLOWED; return;
    }
}

/* One byte of a frame header; false when it shows the frame unmasked. */
static bool wsg_header_byte(struct wsg_conn *c, uint8_t b)
{
    uint8_t i = c->hlen++;
    if (i == 1) {
        if (!(b & 0x80)) return false;
        uint8_t l7 = b & 0x7f;
        c->hneed = (uint8_t)(2 + (l7 == 126 ? 2 : l7 == 127 ? 8 : 0) + 4);
        c->len = l7 < 126 ? l7 : 0;
    } else if (i >= 2 && i < c->hneed - 4) {
        c->len = c->len << 8 | b;
    }
    if (i > 0 && c->hlen == c->hneed) {
        c->hlen = 0;
        c->state = c->len ? WSG_PAYLOAD : WSG_HEADER;
    }
    return true;
}

/* Follows n bytes read; returns how many may reach lws (n unless an unmasked frame starts
 * in them; then the connection is bad). */
static size_t wsg_scan(struct wsg_conn *c, const uint8_t *p, size_t n)
{
    size_t frame_start = 0;
    for (size_t i = 0; i < n;) {
        switch (c->state) {
        case WSG_REQUEST:
            wsg_request_byte(c, p[i++]);
            break;
        case WSG_HEADER:
            if (c->hlen == 0) frame_start = i;
            if (!wsg_header_byte(c, p[i])) {
                c->state = WSG_BAD;
                return frame_start; /* 0 when the header began in an earlier read */
            }
            i++;
            break;
        case WSG_PAYLOAD: {
            size_t k = n - i < c->len ? n - i : (size_t)c->len;
            c->len -= k;
            i += k;
            if (!c->len) c->state = WSG_HEADER;
            break;
        }
        case WSG_BETWEEN: /* lws ignores what comes before its response went out: not followed */
            c->state = WSG_UNFOLLOWED;
            return n;
        case WSG_UNFOLLOWED:
            return n;
        default:
            return 0;
        }
    }
    return n;
}

/* The part of a successful read of n bytes on fd that lws gets: n, fewer, or -1 for none
 * (the caller then reports "try again": the bytes were drained). */
static long wsg_filter(int fd, void *buf, long n)
{
    struct wsg_conn *c = wsg_conn(fd);
    if (!c || n <= 0) return n;
    if (c->state == WSG_BAD) return -1;
    bool upgraded = c->state != WSG_REQUEST; /* else lws upgrades on this read, then establishes */
    size_t pass = wsg_scan(c, buf, (size_t)n);
    if (c->state != WSG_BAD) return n;
    char peer[64] = "?";
    lws_get_peer_simple(c->wsi, peer, sizeof peer);
    log_warn("closing the connection from %s: it sent an unmasked frame (RFC 6455 5.1)", peer);
    if (upgraded) { /* close from the writable callback; within WSG_CLOSE_S if it never comes */
        lws_callback_on_writable(c->wsi);
        lws_set_timeout(c->wsi, PENDING_TIMEOUT_USER_OK, WSG_CLOSE_S);
    }
    return pass ? (long)pass : -1;
}

int wsguard_close_status(const uint8_t *payload, size_t len, const char **why)
{
    if (len == 0) return 0;
    if (len == 1) {
        *why = "close frame of one byte";
        return LWS_CLOSE_STATUS_PROTOCOL_ERR;
    }
    unsigned code = (unsigned)payload[0] << 8 | payload[1];
    if (!((code >= 1000 && code <= 1003) || (code >= 1007 && code <= 1011) || (code >= 3000 && code <= 4999))) {
        *why = "close status code not allowed";
        return LWS_CLOSE_STATUS_PROTOCOL_ERR;
    }
    if (!utf8_valid(payload + 2, len - 2)) {
        *why = "close reason not UTF-8";
        return LWS_CLOSE_STATUS_INVALID_PAYLOAD;
    }
    return 0;
}

static void *wsg_next(const char *name)
{
    void *f = dlsym(RTLD_NEXT, name);
    if (!f) abort(); /* the C library and OpenSSL define these: a broken installation */
    return f;
}

ssize_t recv(int fd, void *buf, size_t len, int flags)
{
    static ssize_t (*next)(int, void *, size_t, int);
    if (!next) next = (ssize_t(*)(int, void *, size_t, int))wsg_next("recv");
    ssize_t n = next(fd, buf, len, flags);
    if (!wsg_here || wsg.tls || (flags & MSG_PEEK)) return n;
    long m = wsg_filter(fd, buf, (long)n);
    if (m < 0 && n > 0) errno = EAGAIN;
    return (ssize_t)m;
}

int SSL_read(SSL *ssl, void *buf, int num)
{
    static int (*next)(SSL *, void *, int);
    static int (*get_fd)(const SSL *);
    if (!next) next = (int (*)(SSL *, void *, int))wsg_next("SSL_read");
    int n = next(ssl, buf, num);
    if (!wsg_here || !wsg.tls) return n;
    if (!get_fd) get_fd = (int (*)(const SSL *))wsg_next("SSL_get_fd");
    wsg.wouldblock = NULL;
    long m = wsg_filter(get_fd(ssl), buf, n);
    if (m < 0 && n > 0) wsg.wouldblock = ssl;
    return (int)m;
}

/* lws asks both after a read that returned nothing: "want read" makes it wait for more. */
int SSL_get_error(const SSL *ssl, int ret)
{
    static int (*next)(const SSL *, int);
    if (!next) next = (int (*)(const SSL *, int))wsg_next("SSL_get_error");
    return wsg_here && ret < 0 && ssl == wsg.wouldblock ? SSL_ERROR_WANT_READ : next(ssl, ret);
}

int SSL_want(const SSL *ssl)
{
    static int (*next)(const SSL *);
    if (!next) next = (int (*)(const SSL *))wsg_next("SSL_want");
    if (!wsg_here || ssl != wsg.wouldblock) return next(ssl);
    wsg.wouldblock = NULL;
    return SSL_READING;
}
