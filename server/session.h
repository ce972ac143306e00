/* session.h — one per WebSocket connection: the control protocol (fxstream.v1).
 *
 * Parses and validates each JSON control message, dispatches it against the hub, and
 * queues replies and events. It never touches a socket: net.c feeds received bytes in
 * and drains the outgoing queue and subscribed frames, so this layer is unit-testable
 * with no network. Every bad request gets an `error` reply and changes nothing. */
#ifndef FX_SESSION_H
#define FX_SESSION_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <cjson/cJSON.h>

#include "access.h"
#include "buf.h"
#include "frame.h"
#include "server.h"

struct sub {
    struct stream *s;
    int form;             /* the form of kinds 1 and 2 it takes (budget.h: subscribe's `encoding`
                             and `max_particles`) */
    double min_interval;  /* 1 / max_fps, 0 = unlimited */
    double last_sent;     /* CLOCK_MONOTONIC seconds of the last step's first frame sent */
    double step_time;     /* that step's sim_time (NAN before the first): its other kinds are not held back by max_fps */
    uint64_t last_seq[FXS_KIND_MAX + 1];
    uint64_t paused_seq[FXS_KIND_MAX + 1]; /* frames up to these were computed before the stream paused */
    uint64_t error_gen;   /* stream errors already reported */
};

/* A queued text message, with FRAME_HEADROOM spare bytes in front for the framing. */
struct outmsg {
    struct outmsg *next;
    size_t len;
    bool event;           /* sent unasked (not a reply to this connection's request) */
    uint8_t data[];       /* FRAME_HEADROOM + len bytes */
};

struct session {
    struct session *next, *prev;
    struct server *srv;
    struct sub *subs;
    int nsubs, rr;        /* rr: round-robin start for frame sends */
    struct outmsg *q_head, *q_tail;
    int q_count;
    size_t q_bytes;       /* text bytes queued */
    size_t q_event_bytes; /* ... of them events */
    bool replying;        /* handling this connection's own message: what it queues are replies */
    struct frame *cur;    /* frame being sent, how far, and its stream (referenced) */
    size_t cur_off;
    bool cur_paused;      /* it goes out marked FXS_FLAG_BEFORE_PAUSE */
    struct stream *cur_stream;
    struct fx_buf rx;     /* fragments of the message being received */
    bool rx_overflow;
    double tokens, last_refill;
    const char *kill;     /* set: the network layer closes the connection (1008) with this reason */
    enum access_role role;
    int auth_failures;
};

/* Links the session into srv->sessions and queues `hello`; role is what the handshake
 * established (access.h). The network layer keeps its own connection state around the
 * session (net.c's struct net_conn). */
void session_open(struct session *ss, struct server *srv, enum access_role role);
/* Unsubscribes everything, frees queued messages, unlinks. */
void session_close(struct session *ss);
/* One received piece of a WebSocket message; final marks its last piece. */
void session_receive(struct session *ss, const void *data, size_t len, bool final, bool binary);
/* Handles one complete text message (exposed for tests). */
void session_handle(struct session *ss, const char *text, size_t len);
/* Queues msg (takes ownership) and wakes the network layer. A reply is always queued; an event
 * (a message the connection did not ask for) that would make more than max_queued_messages
 * messages, or more than max_queued_bytes of events, queued closes the connection instead
 * (kill): the client is not reading. */
void session_send(struct session *ss, cJSON *msg);
/* Whether more than max_queued_bytes (or max_queued_messages messages) wait to be sent: then
 * the network layer reads no further request until they have gone out, so replies queue at
 * most one past the bound, however large they are, and a client that asks without reading is
 * held back by TCP instead of growing the queue. */
bool session_backlogged(const struct session *ss);
/* Pops the next queued text message (caller frees), or NULL. */
struct outmsg *session_pop(struct session *ss);
/* The events of a change to a stream, sent to every connection but `except` (NULL: to all)
 * exactly as for a change made on one of them (PROTOCOL.md §4): `created` and `destroyed` to
 * each connection that may list streams (destroyed first drops the stream's subscriptions,
 * telling each subscriber: `unsubscribed`), `params` to the stream's subscribers. The
 * replica (cluster mode) sends other daemons' changes through them. */
void session_event_created(struct server *srv, const struct session *except, const struct stream *s, uint64_t rev);
void session_event_destroyed(struct server *srv, const struct session *except, struct stream *s);
void session_event_params(struct server *srv, const struct session *except, struct stream *s, uint64_t rev,
                          const cJSON *doc);
/* Queues error events for stream errors published since the last call. */
void session_poll_errors(struct session *ss);

#endif
