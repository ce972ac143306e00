/* fxws.h — WebSocket client helpers shared by libfxclient's two front ends (internal: not
 * installed, its symbols hidden in the shared library).
 *
 * fxclient.c (one connection, the public API) and fxpool.c (many event-driven connections,
 * fxload's) speak the same handshake to the same server, so what they must agree on lives here
 * once: parsing ws:// URLs, resolving and diagnosing failed connects, the checks and
 * one-line messages of the handshake (subprotocol fxstream.v1), decoding the server's
 * close frame, queueing outgoing text, reassembling fragmented messages under a size bound,
 * and keeping
 * libwebsockets quiet unless fxc_set_log asked otherwise (its one global). Everything else
 * here is plain functions over caller-owned structs: no lws context. */
#ifndef FXWS_H
#define FXWS_H

#include <stddef.h>
#include <stdint.h>
#include <time.h>

struct lws;
struct addrinfo;

#define FXWS_DEFAULT_PORT 7681
#define FXWS_DEFAULT_PATH "/v1/ws"
#define FXWS_SUBPROTOCOL "fxstream.v1"
#define FXWS_READ_BUF (128 * 1024) /* lws's per-thread read size: bytes one service reads */

/* libwebsockets logs levels (LLL_* bits) through emit (NULL: stderr), process-wide: fxc_set_log. */
void fxws_log_set(int levels, void (*emit)(int level, const char *line));
/* Before a context is created: silences libwebsockets (its banner included) unless
 * fxws_log_set was called. Once per process. */
void fxws_log_default(void);

/* printf into buf (len bytes; either may be NULL/0: nothing is written): the one-line
 * error messages of libfxclient. */
void fxws_set_err(char *buf, size_t len, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

/* A parsed ws:// or wss://host[:port][/path] URL. */
struct fxws_url {
    int tls;               /* wss:// */
    char host[256];        /* without [] for IPv6 */
    char path[512];        /* FXWS_DEFAULT_PATH when the URL has none (or just "/") */
    char host_header[300]; /* host[:port] as written, for Host: and messages */
    int port;
};

/* Parses url into u. Returns 0, or -1 with one line in errbuf: "bad URL ...". */
int fxws_url_parse(struct fxws_url *u, const char *url, char *errbuf, size_t errlen);

/* getaddrinfo for u (TCP, any family). NULL with "cannot resolve host ..." on failure;
 * the caller frees the list with freeaddrinfo. */
struct addrinfo *fxws_resolve(const struct fxws_url *u, char *errbuf, size_t errlen);

/* lws reports a failed TCP connect as "Unable to connect" without errno; this makes a
 * second, bounded (1 s) connect attempt to recover it. 0 when it now works. */
int fxws_probe_errno(const struct fxws_url *u);

/* Whether a connect failure reported by lws as `why` (tcp_up: the handshake request
 * went out) needs fxws_probe_errno to be explained. */
int fxws_connect_needs_probe(int tcp_up, const char *why);

/* Turns lws's connection-error text `why` into one of the documented messages:
 * "connection refused by HOST:PORT" (or strerror(probed_errno) HOST:PORT), "WebSocket
 * handshake failed with ws://...", "cannot connect to HOST:PORT (...)". probed_errno:
 * what fxws_probe_errno found when fxws_connect_needs_probe said so, else 0. */
void fxws_connect_error(const struct fxws_url *u, int tcp_up, const char *why, int probed_errno, char *out,
                        size_t outlen);

/* Checks that the server selected subprotocol fxstream.v1. Returns 0 when it did,
 * else 1 with the reason in out ("WebSocket handshake failed with ...: ..."). */
int fxws_check_subprotocol(const struct fxws_url *u, struct lws *wsi, char *out, size_t outlen);

/* Decodes a close frame's payload (2-byte code, then the reason): *code = the code or 0
 * when there is none, out = "server closed the connection (code C: reason)" or
 * "server closed the connection (no close code)". reason_out (may be NULL) gets the
 * reason text alone. */
void fxws_peer_close(const uint8_t *in, size_t len, int *code, char *out, size_t outlen, char *reason_out,
                     size_t reason_len);

/* Client options that go into the lws context: TLS set-up for wss:// (ca_file: PEM
 * bundle to verify the server with, NULL: the system's; certificates are always
 * verified, host name included). */
struct lws_context_creation_info;
void fxws_tls_context(struct lws_context_creation_info *info, const char *ca_file);

/* The lws client connection flags for u (LCCSCF_USE_SSL for wss://). */
int fxws_ssl_flags(const struct fxws_url *u);

/* Fills ci (zeroed first) to connect to u on ctx: address, port, path, Host, TLS flags and
 * subprotocol fxstream.v1, and no Origin (this is not a browser, PROTOCOL.md §1). */
struct lws_client_connect_info;
struct lws_context;
void fxws_connect_info(struct lws_client_connect_info *ci, struct lws_context *ctx, const struct fxws_url *u);

/* "ws" or "wss". */
const char *fxws_scheme(const struct fxws_url *u);

/* Adds "Authorization: Bearer TOKEN" to a client handshake, from
 * LWS_CALLBACK_CLIENT_APPEND_HANDSHAKE_HEADER (its in/len). token NULL or "": nothing.
 * Returns 0, or -1 when it does not fit (the handshake then fails). */
int fxws_append_auth(struct lws *wsi, void *in, size_t len, const char *token);

/* Text messages waiting for the socket, oldest first: each one lws_write in its own
 * writeable callback, as lws wants. */
struct fxws_out;
struct fxws_outq {
    struct fxws_out *head, *tail;
    int n;
};

/* Queues a copy of text (len bytes). 0, or -1 when memory runs out. */
int fxws_outq_push(struct fxws_outq *q, const char *text, size_t len);
/* From LWS_CALLBACK_CLIENT_WRITEABLE: writes the oldest message to wsi and asks for another
 * turn while more wait. 0, or -1 with "write to server failed" in err (the callback returns
 * it: lws closes the connection). */
int fxws_outq_write(struct fxws_outq *q, struct lws *wsi, char *err, size_t errlen);
void fxws_outq_free(struct fxws_outq *q);

/* Reassembly of one message from its fragments. */
struct fxws_rx {
    uint8_t *buf;  /* the first min(total, keep) bytes of the message */
    size_t len;    /* bytes in buf */
    size_t cap;    /* allocated size of buf */
    size_t total;  /* bytes of the message so far (all fragments) */
    int active;    /* a message is being assembled */
    int binary;    /* it is a binary message */
};

/* Appends one received chunk (the callback's in/len on wsi). Keeps at most `keep`
 * bytes of the message in rx->buf (SIZE_MAX: all of it) and counts the rest in
 * rx->total. Returns 1 when the message is complete (rx->active is then 0 again and
 * rx->buf/len/total describe it until the next append), 0 when more fragments follow,
 * -1 when the message grows beyond max_bytes ("message larger than N bytes from
 * server" in err), -2 when memory runs out ("out of memory reassembling ..."). */
int fxws_rx_append(struct fxws_rx *rx, struct lws *wsi, const void *in, size_t len, size_t max_bytes,
                   size_t keep, char *err, size_t errlen);

/* Frees rx's buffer and zeroes it. */
void fxws_rx_free(struct fxws_rx *rx);

static inline int64_t fxws_now_us(clockid_t clk)
{
    struct timespec ts;
    clock_gettime(clk, &ts);
    return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

#endif
