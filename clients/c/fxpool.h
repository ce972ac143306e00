/* fxpool.h — libfxclient's internal event-driven API: many fxstream.v1 connections, one thread.
 *
 * Owns ONE libwebsockets context serviced in the caller's thread and any number of
 * client connections on it (up to fxp_options.max_connections, 10,000 and more: the
 * pool raises RLIMIT_NOFILE as far as the hard limit allows and sizes lws's fd table
 * to match). Nothing blocks except fxp_service(), which waits for network events up to
 * a timeout and runs the caller's callbacks for what arrived:
 *
 *   on_open   the server's `hello` arrived (the connection is usable; sending earlier
 *             is allowed too, messages wait for the handshake)
 *   on_text   any later JSON text message (an object with a string "op")
 *   on_frame  a binary frame: its parsed 64-byte header, and the payload when the pool
 *             reassembles payloads (fxp_options.payloads), else NULL
 *   on_close  the connection ended or never came up; the fxp_conn is freed right after
 *             this callback returns
 *
 * Pointers passed to callbacks (hello, msg, header, payload, close info) are valid only
 * during the callback. Callbacks may send, close, and open connections.
 *
 * fxclient.h's client (the installed API) is the tool for one connection; this is for
 * load generators (fxload) and is internal: not installed, hidden in the shared library. It
 * shares URL parsing, the handshake (subprotocol fxstream.v1 at /v1/ws by default) and the
 * error messages with it (fxws.h).
 *
 * Memory per connection is small and bounded: with payloads off only the first bytes of
 * each message are kept (the rest is counted); with payloads on, one reassembly buffer
 * per connection, released after each message larger than 64 KiB. Messages above
 * max_message_bytes close the connection (1009). Outgoing text messages queue per
 * connection up to FXP_MAX_QUEUED.
 *
 * Also here: struct fxp_hist, a latency histogram with bounded memory (log-linear
 * buckets, HDR-style, 1 µs to 67 s, relative error below 0.4%).
 *
 * Threading: a pool and its connections belong to one thread. */
#ifndef FXPOOL_H
#define FXPOOL_H

#include <stddef.h>
#include <stdint.h>

#include <cjson/cJSON.h>

#include "fxs_frame.h"

#define FXP_MAX_CONNECTIONS 100000
#define FXP_MAX_QUEUED 256

struct fxp_pool;
struct fxp_conn;

/* Why a connection ended. */
struct fxp_close_info {
    int code;           /* close code the server sent (1001, 1008, 1013, ...), 0 when none */
    const char *reason; /* one line: the documented fxclient messages ("connection refused by
                           HOST:PORT", "server closed the connection (code C: reason)",
                           "connection to HOST:PORT lost", "closed by the client", ...) */
    int established;    /* the WebSocket handshake had completed */
    int hello;          /* the server's hello had arrived (on_open was called) */
    int by_client;      /* fxp_close() asked for it */
};

struct fxp_callbacks {
    void (*on_open)(struct fxp_conn *c, const cJSON *hello, void *user);
    void (*on_text)(struct fxp_conn *c, const cJSON *msg, uint64_t recv_time_us, void *user);
    /* recv_time_us: CLOCK_REALTIME when the frame's last byte was read;
       recv_time_us - h->server_time_us is its latency. message_bytes: header + payload. */
    void (*on_frame)(struct fxp_conn *c, const struct fxs_header *h, const uint8_t *payload,
                     size_t message_bytes, uint64_t recv_time_us, void *user);
    void (*on_close)(struct fxp_conn *c, const struct fxp_close_info *info, void *user);
};

struct fxp_options {
    int max_connections;      /* open at the same time, 1..FXP_MAX_CONNECTIONS */
    int payloads;             /* 1: reassemble frames, on_frame gets the payload; 0: headers only */
    size_t max_message_bytes; /* 0: FXC_MAX_MESSAGE_BYTES (256 MiB) */
    const char *token;        /* access token sent in every handshake (Authorization: Bearer); NULL: none */
    const char *ca_file;      /* PEM bundle for wss:// servers; NULL: the system's */
};                            /* (the strings are kept by pointer: they must outlive the pool) */

struct fxp_stats {
    uint64_t connects;       /* fxp_connect calls that started a connection */
    uint64_t established;    /* handshakes completed */
    uint64_t closed;         /* on_close delivered */
    uint64_t frames;         /* valid binary frames */
    uint64_t frame_bytes;    /* their bytes, headers included */
    uint64_t texts;          /* text messages (hello included) */
    uint64_t bad_messages;   /* invalid frame headers, JSON that is not an object with "op" */
};

/* Creates a pool. Raises the soft RLIMIT_NOFILE to max_connections + 64 when lower
 * (fails with a message naming the hard limit when that is not possible). Returns 0,
 * or -1 with one line in errbuf. */
int fxp_pool_create(struct fxp_pool **out, const struct fxp_callbacks *cb, const struct fxp_options *o,
                    char *errbuf, size_t errlen);

/* Starts a connection to url (ws://host[:port][/path], as fxc_connect) with `user` as
 * its callbacks' user pointer. The outcome comes through the callbacks (a refused or
 * failed connect as on_close with established = 0), never before the next
 * fxp_service. Returns 0 (and *out when out is not NULL), -2 when url is malformed or
 * unsupported, -1 when the pool is full (max_connections open), the host does not
 * resolve, or memory runs out. */
int fxp_connect(struct fxp_pool *p, const char *url, void *user, struct fxp_conn **out, char *errbuf,
                size_t errlen);

/* Queues one text message (sent in order once the handshake is done). Returns 0, or
 * -1 when the connection is closing or closed or FXP_MAX_QUEUED messages wait. */
int fxp_send_text(struct fxp_conn *c, const char *text, size_t len);

/* fxp_send_text of msg printed unformatted. */
int fxp_send_json(struct fxp_conn *c, const cJSON *msg);

/* Closes politely (close code 1000) or abandons a connect in progress; on_close
 * follows with by_client = 1. No-op when already closing. */
void fxp_close(struct fxp_conn *c);

/* Waits for network events for at most timeout_ms (0: only what is ready now) and runs
 * the callbacks. Returns 0, or -1 when libwebsockets failed. */
int fxp_service(struct fxp_pool *p, int timeout_ms);

/* Connections started and not yet reported closed. */
int fxp_live(const struct fxp_pool *p);

void *fxp_conn_user(const struct fxp_conn *c);
void fxp_conn_set_user(struct fxp_conn *c, void *user);
struct fxp_pool *fxp_conn_pool(const struct fxp_conn *c);
void fxp_stats(const struct fxp_pool *p, struct fxp_stats *out);

/* Closes every connection at once (no callbacks) and frees the pool. NULL: no-op. */
void fxp_pool_destroy(struct fxp_pool *p);

/* ---- latency histogram ---------------------------------------------------------- */

#define FXP_HIST_SUB_BITS 7
#define FXP_HIST_BUCKETS (20 * (1 << FXP_HIST_SUB_BITS)) /* values up to 2^26 - 1 µs */
#define FXP_HIST_MAX_US ((UINT64_C(1) << 26) - 1)

struct fxp_hist {
    uint64_t count;
    uint64_t min_us, max_us; /* exact */
    double sum_us;
    uint64_t clamped;        /* values recorded above FXP_HIST_MAX_US (counted in the top bucket) */
    uint64_t bucket[FXP_HIST_BUCKETS];
};

void fxp_hist_reset(struct fxp_hist *h);
/* Records one value in µs; negative values count as 0. */
void fxp_hist_add(struct fxp_hist *h, int64_t us);
void fxp_hist_merge(struct fxp_hist *dst, const struct fxp_hist *src);
/* The q-quantile (0 < q <= 1) in µs: the middle of the bucket holding the value of
 * rank ceil(q * count), kept within [min, max]; q = 1 gives the exact max. 0 when empty. */
double fxp_hist_quantile(const struct fxp_hist *h, double q);

#endif
