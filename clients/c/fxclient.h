/* fxclient.h — libfxclient, the blocking C client of protocol fxstream.v1.
 *
 * Owns one WebSocket connection to fxstreamd (ws://host:port/v1/ws, subprotocol
 * "fxstream.v1") built on the libwebsockets client API. There is no background
 * thread: every blocking call services the connection's own lws context in the
 * caller's thread until its answer arrives or its timeout expires. That keeps the
 * library usable from tools (fxctl) and from a game's network thread alike.
 *
 * Threading: one struct fxc_client belongs to one thread at a time; calls on the
 * same client must not overlap. Separate clients are independent.
 *
 * Messages: while a call waits, everything else the server sends is queued in
 * arrival order for fxc_next(): text events (`params` broadcasts, `error` events,
 * `unsubscribed`) as cJSON, binary frames as a parsed 64-byte header plus payload.
 * The queue is bounded: at most FXC_QUEUE_EVENTS text events (the oldest is dropped
 * beyond that) and FXC_QUEUE_FRAMES_PER_CHANNEL frames per channel (latest frame
 * wins: the oldest frame of that channel is dropped; the header's seq shows the gap).
 * Drops are counted in struct fxc_stats. Fragmented WebSocket messages are
 * reassembled up to FXC_MAX_MESSAGE_BYTES; a bigger message closes the connection.
 *
 * Errors: every fallible call takes errbuf/errlen (either may be NULL/0) and writes
 * one line there: "bad URL ...", "connection refused
 * ...", "WebSocket handshake failed ...", "timeout after N ms ...", "server closed
 * the connection (code C: reason)", or the server's "code: message" for a request
 * the server rejected.
 *
 * Logging: libwebsockets logs to stderr through a process-wide setting; this library
 * leaves it alone. Tools usually call lws_set_log_level(LLL_ERR, NULL) or 0. */
#ifndef FXCLIENT_H
#define FXCLIENT_H

#include <stddef.h>
#include <stdint.h>

#include <cjson/cJSON.h>

#include "fxs_frame.h"

#define FXC_DEFAULT_PORT 7681
#define FXC_DEFAULT_PATH "/v1/ws"
#define FXC_SUBPROTOCOL "fxstream.v1"
#define FXC_QUEUE_EVENTS 1024
#define FXC_QUEUE_FRAMES_PER_CHANNEL 4
#define FXC_MAX_MESSAGE_BYTES ((size_t)256 << 20)

struct fxc_client;

enum fxc_msg_type {
    FXC_MSG_EVENT = 1, /* a JSON text message without a request id */
    FXC_MSG_FRAME = 2, /* a binary frame that passed fxs_header_unpack */
};

/* One queued message, owned by the caller after fxc_next(); release with fxc_msg_free. */
struct fxc_msg {
    enum fxc_msg_type type;
    cJSON *event;              /* FXC_MSG_EVENT: the parsed object ("op" is a string) */
    struct fxs_header header;  /* FXC_MSG_FRAME: the parsed header */
    const uint8_t *payload;    /* FXC_MSG_FRAME: header.payload_bytes bytes */
    uint64_t recv_time_us;     /* CLOCK_REALTIME when the last byte arrived (both types);
                                  recv_time_us - header.server_time_us = latency */
    uint8_t *data;             /* FXC_MSG_FRAME: the whole message (header + payload) */
    size_t data_bytes;
};

struct fxc_stats {
    uint64_t frames_received;  /* valid binary frames received */
    uint64_t frames_dropped;   /* dropped from the queue because a newer frame came */
    uint64_t events_dropped;   /* dropped because the event queue was full */
    uint64_t bad_messages;     /* invalid frame headers, non-object JSON, stray ids */
};

/* Connects to url, ws://host[:port][/path] or wss://... (port 7681, path /v1/ws by
 * default; IPv6 as ws://[::1]:7681), completes the WebSocket handshake with subprotocol
 * fxstream.v1 and waits for the server's `hello`, all within timeout_ms (< 0: no
 * limit). Returns 0 and sets *out; on failure *out = NULL, the reason is in errbuf
 * and the result is -2 when url itself is malformed, -1 for everything else (name
 * resolution, connection refused, TLS or handshake failure or wrong subprotocol,
 * timeout, server closed: an unknown token closes with "invalid token ..."). */
int fxc_connect(struct fxc_client **out, const char *url, int timeout_ms, char *errbuf, size_t errlen);

/* Optional connection settings (PROTOCOL.md §3.11, README "Security"). */
struct fxc_options {
    const char *token;   /* access token, sent as "Authorization: Bearer TOKEN"; NULL: none */
    const char *ca_file; /* PEM bundle that signs the server's certificate (wss://); NULL: the system's */
};

/* fxc_connect with options (o NULL: none). */
int fxc_connect_with(struct fxc_client **out, const char *url, const struct fxc_options *o, int timeout_ms,
                     char *errbuf, size_t errlen);

/* The server's hello message ({"op":"hello","protocol","server","device","effects",
 * "limits",...}); owned by the client, valid until fxc_close. */
const cJSON *fxc_hello(const struct fxc_client *c);

/* Sends req (an object with "op" and its fields; req itself is not modified) with a
 * fresh integer "id" added, then waits up to timeout_ms (< 0: no limit) for the
 * message carrying that id. Messages that arrive meanwhile are queued.
 * Returns 0 with the reply in *reply, 1 when the server answered {"op":"error",...}
 * (*reply holds that error and errbuf "code: message"), or -1 on a transport error
 * or timeout (*reply = NULL, reason in errbuf). The caller frees *reply with
 * cJSON_Delete. After a timeout the connection stays usable; a late reply is dropped. */
int fxc_request(struct fxc_client *c, const cJSON *req, cJSON **reply, int timeout_ms,
                char *errbuf, size_t errlen);

/* Takes the next queued event or frame, servicing the connection for up to timeout_ms
 * (0: only what is already there or immediately readable, < 0: no limit).
 * Returns 1 with *m filled, 0 on timeout, or -1 when the connection is closed and the
 * queue is empty (reason in errbuf). */
int fxc_next(struct fxc_client *c, struct fxc_msg *m, int timeout_ms, char *errbuf, size_t errlen);

/* Releases what fxc_next put in m and zeroes it. Safe on a zeroed msg. */
void fxc_msg_free(struct fxc_msg *m);

/* Counters since connect. */
void fxc_stats(const struct fxc_client *c, struct fxc_stats *out);

/* Closes the connection politely (close frame, bounded wait) and frees everything,
 * queued messages included. NULL is a no-op. */
void fxc_close(struct fxc_client *c);

#endif
