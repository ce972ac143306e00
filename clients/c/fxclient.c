/* fxclient.c — libfxclient's connection (fxclient.h): one fxstream.v1 WebSocket over
 * libwebsockets, driven from the caller's thread.
 *
 * Owns the client's lws context and its single wsi, the reassembly buffer for fragmented
 * messages, the queue of requests waiting for the socket, the queue of received events, the
 * reply a fxc_wait is waiting for, and the map from channel to stream name (from the
 * `subscribed` replies) that names each frame's stream.
 *
 * Shape: lws callbacks only record what happened into struct fxc_client; the public calls
 * run fxc_pump(), which services lws until a condition holds, the connection ends or a
 * deadline passes. With no time to wait (fxc_poll's 0) it polls without blocking and keeps
 * reading while data comes, within FXC_POLL_BUDGET_US. Otherwise a self-re-arming timer (sul)
 * bounds every poll wait, since lws_service() ignores its timeout since v3.2. cJSON parses
 * and builds the text messages here and never leaves this file. URL parsing, connect
 * diagnosis, the handshake checks and fragment reassembly are shared with fxpool.c (fxws.c). */
#include "fxclient.h"
#include "fxws.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <netdb.h>
#include <cjson/cJSON.h>
#include <libwebsockets.h>

#define FXC_CLOSE_WAIT_MS 500
#define FXC_TICK_US 100000 /* longest lws poll wait of one fxc_pump round */
#define FXC_REARM_US 1000  /* poll wait after a tick fired before lws polled */
#define FXC_STREAM_MAX 64  /* a stream name and its NUL (PROTOCOL.md §3.10: 63 characters) */

/* An event and what its pointers point into. */
struct fxc_node {
    struct fxc_node *next;
    struct fxc_event ev;
    cJSON *tree;                 /* TEXT: the parsed message */
    uint8_t *data;               /* the message's bytes (TEXT: NUL-terminated) */
    char stream[FXC_STREAM_MAX]; /* FRAME: its stream's name */
};

struct fxc_chan {
    uint32_t channel;
    char stream[FXC_STREAM_MAX];
};

struct fxc_client {
    struct lws_context *ctx;
    struct lws *wsi;
    lws_sorted_usec_list_t tick;   /* wakes lws_service() at our deadlines */
    enum fxc_state state;
    int established;               /* the WebSocket handshake is done: requests may go out */
    int tcp_up;                    /* connected; the handshake request went out */
    int closing;                   /* fxc_close asked lws to close */
    char err[256];                 /* why the connection failed or ended */
    struct fxws_url url;
    char *token;                   /* sent in the handshake, or NULL */
    uint64_t rx_bytes;             /* bytes received so far: fxc_poll's progress */

    struct fxws_rx rx;             /* message being reassembled */
    struct fxws_outq out;          /* requests waiting for the socket */

    int64_t next_id;
    int64_t want_id;               /* the reply fxc_wait waits for, 0: none */
    struct fxc_node *reply;        /* ... once it came */
    char *hello;

    struct fxc_node *head, *tail;
    size_t n_events;               /* queued text events without an id */
    struct fxc_chan *chans;
    int n_chans, cap_chans;
    struct fxc_stats stats;
};

const char *fxc_version(void) { return FXC_VERSION; }

void fxc_set_log(int levels, void (*emit)(int level, const char *line)) { fxws_log_set(levels, emit); }

static int64_t fxc_deadline(int timeout_ms)
{
    return timeout_ms < 0 ? INT64_MAX : fxws_now_us(CLOCK_MONOTONIC) + (int64_t)timeout_ms * 1000;
}

/* ---- events and their queue ----------------------------------------------------------- */

static void fxc_node_free(struct fxc_node *n)
{
    if (!n) return;
    cJSON_Delete(n->tree);
    free(n->data);
    free(n);
}

uint32_t fxc_frame_total(const struct fxc_event *ev)
{
    if (ev->type != FXC_EVENT_FRAME || ev->header.kind != FXS_KIND_PARTICLES || !ev->payload) return 0;
    return fxs_header_total(ev->payload - ev->header.header_bytes); /* the message's bytes, header first */
}

void fxc_event_free(struct fxc_event *ev)
{
    if (!ev) return;
    fxc_node_free(ev->internal);
    memset(ev, 0, sizeof *ev);
}

/* Hands n to the caller as *ev. */
static void fxc_node_give(struct fxc_node *n, struct fxc_event *ev)
{
    *ev = n->ev;
    ev->internal = n;
}

static int fxc_counts_as_event(const struct fxc_node *n) { return n->ev.type == FXC_EVENT_TEXT && !n->ev.id; }

static void fxc_queue_push(struct fxc_client *c, struct fxc_node *n)
{
    n->next = NULL;
    if (c->tail) c->tail->next = n;
    else c->head = n;
    c->tail = n;
    if (fxc_counts_as_event(n)) c->n_events++;
}

static struct fxc_node *fxc_queue_unlink(struct fxc_client *c, struct fxc_node *prev, struct fxc_node *n)
{
    if (prev) prev->next = n->next;
    else c->head = n->next;
    if (c->tail == n) c->tail = prev;
    if (fxc_counts_as_event(n)) c->n_events--;
    return n;
}

/* Whether n is what fxc_queue_trim limits: a frame of `channel`, or (channel 0) an event. */
static int fxc_trim_match(const struct fxc_node *n, int frames, uint32_t channel)
{
    return frames ? n->ev.type == FXC_EVENT_FRAME && n->ev.channel == channel : fxc_counts_as_event(n);
}

/* Drops the oldest queued frame of `channel` (frames) or event without an id (!frames) when
 * `limit` or more are queued. Returns 1 when one was dropped. */
static int fxc_queue_trim(struct fxc_client *c, int frames, uint32_t channel, size_t limit)
{
    struct fxc_node *n, *prev = NULL, *oldest = NULL, *oldest_prev = NULL;
    size_t count = 0;
    for (n = c->head; n; prev = n, n = n->next) {
        if (!fxc_trim_match(n, frames, channel)) continue;
        if (!oldest) { oldest = n; oldest_prev = prev; }
        count++;
    }
    if (count < limit) return 0;
    fxc_node_free(fxc_queue_unlink(c, oldest_prev, oldest));
    return 1;
}

static void fxc_queue_free(struct fxc_client *c)
{
    while (c->head) fxc_node_free(fxc_queue_unlink(c, NULL, c->head));
}

/* ---- channels ------------------------------------------------------------------------------ */

static struct fxc_chan *fxc_chan_find(struct fxc_client *c, uint32_t channel, const char *stream)
{
    for (int i = 0; i < c->n_chans; i++)
        if (stream ? !strcmp(c->chans[i].stream, stream) : c->chans[i].channel == channel) return &c->chans[i];
    return NULL;
}

/* Follows the subscriptions: `subscribed` maps its channel to its stream, `unsubscribed`
 * (reply or event) forgets the stream. */
static void fxc_chan_follow(struct fxc_client *c, const struct fxc_event *ev)
{
    struct fxc_chan *ch;
    if (!ev->stream || strlen(ev->stream) >= FXC_STREAM_MAX) return;
    ch = fxc_chan_find(c, 0, ev->stream);
    if (!strcmp(ev->op, "unsubscribed") && ch) {
        *ch = c->chans[--c->n_chans];
    } else if (!strcmp(ev->op, "subscribed") && ev->channel) {
        if (!ch && c->n_chans == c->cap_chans) {
            int cap = c->cap_chans ? 2 * c->cap_chans : 8;
            struct fxc_chan *grown = realloc(c->chans, (size_t)cap * sizeof *grown);
            if (!grown) return; /* frames of this stream then come without its name */
            c->chans = grown;
            c->cap_chans = cap;
        }
        if (!ch) ch = &c->chans[c->n_chans++];
        ch->channel = ev->channel;
        snprintf(ch->stream, sizeof ch->stream, "%s", ev->stream);
    }
}

/* ---- received messages ------------------------------------------------------------------- */

/* Takes the reassembled message out of c->rx into a new node (NUL-terminated); NULL when
 * memory runs out. */
static struct fxc_node *fxc_take_rx(struct fxc_client *c, int64_t now)
{
    struct fxc_node *n = calloc(1, sizeof *n);
    uint8_t *fit = realloc(c->rx.buf, c->rx.len + 1); /* the node keeps the buffer: trim it */
    if (!n || !fit) {
        free(n);
        return NULL;
    }
    fit[c->rx.len] = 0;
    n->data = fit;
    n->ev.recv_time_us = (uint64_t)now;
    c->rx.buf = NULL;
    c->rx.cap = 0;
    return n;
}

static void fxc_on_frame(struct fxc_client *c, int64_t now)
{
    struct fxs_header h;
    struct fxc_node *n;
    struct fxc_chan *ch;
    if (fxs_header_unpack(c->rx.buf, c->rx.len, &h) || !(n = fxc_take_rx(c, now))) {
        c->stats.bad_messages++;
        return;
    }
    c->stats.frames_received++;
    if (fxc_queue_trim(c, 1, h.channel, FXC_QUEUE_FRAMES_PER_CHANNEL)) c->stats.frames_dropped++;
    n->ev.type = FXC_EVENT_FRAME;
    n->ev.header = h;
    n->ev.channel = h.channel;
    n->ev.payload = n->data + h.header_bytes;
    if ((ch = fxc_chan_find(c, h.channel, NULL))) {
        memcpy(n->stream, ch->stream, sizeof n->stream);
        n->ev.stream = n->stream;
    }
    fxc_queue_push(c, n);
}

static const char *fxc_str(const cJSON *o, const char *name)
{
    return cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, name));
}

/* An integral JSON number in [0, 2^53) as int64, else 0. */
static int64_t fxc_int(const cJSON *o, const char *name)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, name);
    double d = cJSON_IsNumber(v) ? v->valuedouble : 0;
    return d >= 0 && d < 9007199254740992.0 && d == (double)(int64_t)d ? (int64_t)d : 0;
}

/* Parses n's text into its tree and the event's fields. Returns -1 when it is not an object
 * with a string "op". */
static int fxc_parse_text(struct fxc_node *n, size_t len)
{
    struct fxc_event *ev = &n->ev;
    int64_t channel;
    n->tree = cJSON_ParseWithLength((const char *)n->data, len);
    ev->type = FXC_EVENT_TEXT;
    ev->json = (const char *)n->data;
    ev->json_len = len;
    if (!cJSON_IsObject(n->tree) || !(ev->op = fxc_str(n->tree, "op"))) return -1;
    ev->id = fxc_int(n->tree, "id");
    ev->stream = fxc_str(n->tree, "stream");
    channel = fxc_int(n->tree, "channel");
    ev->channel = channel <= UINT32_MAX ? (uint32_t)channel : 0;
    ev->rev = fxc_int(n->tree, "rev");
    ev->code = fxc_str(n->tree, "code");
    ev->message = fxc_str(n->tree, "message");
    ev->param = fxc_str(n->tree, "param");
    return 0;
}

/* Routes one complete text message: the hello (kept, and queued), the reply fxc_wait waits
 * for, or the queue. */
static void fxc_on_text(struct fxc_client *c, int64_t now)
{
    size_t len = c->rx.len;
    struct fxc_node *n = fxc_take_rx(c, now);
    if (!n || fxc_parse_text(n, len)) {
        c->stats.bad_messages++;
        fxc_node_free(n);
        return;
    }
    if (!c->hello && !strcmp(n->ev.op, "hello")) {
        if (!(c->hello = strdup(n->ev.json))) {
            fxws_set_err(c->err, sizeof c->err, "out of memory");
            c->state = FXC_CLOSED;
        } else if (c->state == FXC_CONNECTING) {
            c->state = FXC_OPEN;
        }
    }
    fxc_chan_follow(c, &n->ev);
    if (c->want_id && n->ev.id == c->want_id && !c->reply) {
        c->reply = n;
        return;
    }
    if (fxc_counts_as_event(n) && fxc_queue_trim(c, 0, 0, FXC_QUEUE_EVENTS)) c->stats.events_dropped++;
    fxc_queue_push(c, n);
}

/* Appends one received chunk; returns -1 (and closes) when the message is too big. */
static int fxc_on_receive(struct fxc_client *c, struct lws *wsi, const void *in, size_t len)
{
    int r = fxws_rx_append(&c->rx, wsi, in, len, FXC_MAX_MESSAGE_BYTES, SIZE_MAX, c->err, sizeof c->err);
    c->rx_bytes += len;
    if (r == -1) lws_close_reason(wsi, LWS_CLOSE_STATUS_MESSAGE_TOO_LARGE, NULL, 0);
    if (r <= 0) return r < 0 ? -1 : 0;
    if (c->rx.binary) fxc_on_frame(c, fxws_now_us(CLOCK_REALTIME));
    else fxc_on_text(c, fxws_now_us(CLOCK_REALTIME));
    return 0;
}

/* ---- lws callbacks ------------------------------------------------------------------------- */

/* Turns lws's connection-error text into one of the documented messages. */
static void fxc_on_connect_error(struct fxc_client *c, const char *why)
{
    const char *w = why ? why : "unknown error";
    int e = 0;
    if (c->err[0]) return; /* our own filter already explained it */
    if (fxws_connect_needs_probe(c->tcp_up, w)) e = fxws_probe_errno(&c->url);
    fxws_connect_error(&c->url, c->tcp_up, w, e, c->err, sizeof c->err);
}

static void fxc_on_closed(struct fxc_client *c)
{
    if (!c->err[0]) fxws_set_err(c->err, sizeof c->err, "connection to %s:%d lost", c->url.host, c->url.port);
    c->state = FXC_CLOSED;
    c->wsi = NULL;
}

static int fxc_lws_cb(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len)
{
    struct fxc_client *c = lws_context_user(lws_get_context(wsi));
    int code;
    (void)user;
    switch (reason) {
    case LWS_CALLBACK_CLIENT_CONNECTION_ERROR:
        fxc_on_connect_error(c, in);
        fxc_on_closed(c);
        return 0;
    case LWS_CALLBACK_CLIENT_APPEND_HANDSHAKE_HEADER:
        c->tcp_up = 1;
        return fxws_append_auth(wsi, in, len, c->token);
    case LWS_CALLBACK_CLIENT_FILTER_PRE_ESTABLISH:
        return fxws_check_subprotocol(&c->url, wsi, c->err, sizeof c->err);
    case LWS_CALLBACK_CLIENT_ESTABLISHED:
        c->established = 1;
        if (c->out.head) lws_callback_on_writable(wsi);
        return 0;
    case LWS_CALLBACK_CLIENT_RECEIVE:
        return fxc_on_receive(c, wsi, in, len);
    case LWS_CALLBACK_CLIENT_WRITEABLE:
        if (c->closing) return -1; /* lws_close_reason was set: lws sends the close frame */
        return fxws_outq_write(&c->out, wsi, c->err, sizeof c->err);
    case LWS_CALLBACK_WS_PEER_INITIATED_CLOSE:
        fxws_peer_close(in, len, &code, c->err, sizeof c->err, NULL, 0);
        return 0;
    case LWS_CALLBACK_CLIENT_CLOSED:
        fxc_on_closed(c);
        return 0;
    default:
        return 0;
    }
}

static const struct lws_protocols fxc_protocols[] = {
    { .name = FXC_SUBPROTOCOL, .callback = fxc_lws_cb, .rx_buffer_size = 65536 },
    { .name = NULL },
};

/* ---- service loop -------------------------------------------------------------------------- */

/* lws runs ripe timers before it computes its poll wait, so a tick that expired
 * just then would leave the poll unbounded: the tick re-arms itself. */
static void fxc_tick_cb(lws_sorted_usec_list_t *sul)
{
    struct fxc_client *c = lws_container_of(sul, struct fxc_client, tick);
    lws_sul_schedule(c->ctx, 0, &c->tick, fxc_tick_cb, FXC_REARM_US);
}

typedef int (*fxc_cond)(const struct fxc_client *c);

static int fxc_service(struct fxc_client *c, int wait)
{
    if (lws_service(c->ctx, wait ? 0 : -1) >= 0) return 0; /* < 0: poll without waiting */
    fxws_set_err(c->err, sizeof c->err, "libwebsockets service failed");
    c->state = FXC_CLOSED;
    return -1;
}

/* Services lws until cond(c) holds (1), the connection is closed (-1) or the deadline
 * passes (0). cond is checked first, so queued results win over a close. A deadline already
 * due still polls: without waiting, for as long as data keeps coming, within the budget. */
static int fxc_pump(struct fxc_client *c, int64_t deadline, fxc_cond cond)
{
    int64_t start = fxws_now_us(CLOCK_MONOTONIC), now = start;
    uint64_t before = c->rx_bytes + 1;
    for (;;) {
        if (cond(c)) return 1;
        if (c->state == FXC_CLOSED) return -1;
        if (now >= deadline) {
            if (c->rx_bytes == before || now - start >= FXC_POLL_BUDGET_US) return 0;
            before = c->rx_bytes;
            fxc_service(c, 0);
        } else {
            lws_sul_schedule(c->ctx, 0, &c->tick, fxc_tick_cb,
                             deadline - now < FXC_TICK_US ? deadline - now : FXC_TICK_US);
            fxc_service(c, 1);
        }
        now = fxws_now_us(CLOCK_MONOTONIC);
    }
}

static int fxc_has_hello(const struct fxc_client *c) { return c->hello != NULL; }
static int fxc_has_reply(const struct fxc_client *c) { return c->reply != NULL; }
static int fxc_has_event(const struct fxc_client *c) { return c->head != NULL; }
static int fxc_is_closed(const struct fxc_client *c) { return c->state == FXC_CLOSED; }

/* ---- connection ------------------------------------------------------------------------------ */

static int fxc_start(struct fxc_client *c, const char *ca_file, char *eb, size_t el)
{
    struct lws_context_creation_info info;
    struct lws_client_connect_info ci;
    struct addrinfo *ai = fxws_resolve(&c->url, eb, el);
    if (!ai) return -1;
    freeaddrinfo(ai);
    fxws_log_default();
    memset(&info, 0, sizeof info);
    info.port = CONTEXT_PORT_NO_LISTEN;
    info.protocols = fxc_protocols;
    info.gid = (gid_t)-1;
    info.uid = (uid_t)-1;
    info.fd_limit_per_thread = 16;
    info.pt_serv_buf_size = FXWS_READ_BUF;
    info.user = c;
    if (c->url.tls) fxws_tls_context(&info, ca_file);
    if (!(c->ctx = lws_create_context(&info))) {
        fxws_set_err(eb, el, "cannot create a libwebsockets context");
        return -1;
    }
    fxws_connect_info(&ci, c->ctx, &c->url);
    ci.pwsi = &c->wsi;
    if (!lws_client_connect_via_info(&ci)) {
        if (!c->err[0]) fxc_on_connect_error(c, "connect failed");
        fxws_set_err(eb, el, "%s", c->err);
        return -1;
    }
    return 0;
}

static void fxc_free(struct fxc_client *c)
{
    if (c->ctx) {
        lws_sul_cancel(&c->tick);
        lws_context_destroy(c->ctx);
    }
    fxws_outq_free(&c->out);
    fxc_queue_free(c);
    fxc_node_free(c->reply);
    fxws_rx_free(&c->rx);
    free(c->chans);
    free(c->hello);
    free(c->token);
    free(c);
}

int fxc_open(struct fxc_client **out, const char *url, const struct fxc_options *o, char *eb, size_t el)
{
    struct fxc_client *c = calloc(1, sizeof *c);
    *out = NULL;
    if (!c) { fxws_set_err(eb, el, "out of memory"); return -1; }
    if (fxws_url_parse(&c->url, url, eb, el)) {
        fxc_free(c);
        return -2;
    }
    if (o && o->token && !(c->token = strdup(o->token))) {
        fxc_free(c);
        fxws_set_err(eb, el, "out of memory");
        return -1;
    }
    if (fxc_start(c, o ? o->ca_file : NULL, eb, el)) {
        fxc_free(c);
        return -1;
    }
    *out = c;
    return 0;
}

int fxc_connect(struct fxc_client **out, const char *url, const struct fxc_options *o, int timeout_ms, char *eb,
                size_t el)
{
    struct fxc_client *c;
    int r = fxc_open(&c, url, o, eb, el);
    if (r) {
        *out = NULL;
        return r;
    }
    r = fxc_pump(c, fxc_deadline(timeout_ms), fxc_has_hello);
    if (r == 1) {
        *out = c;
        return 0;
    }
    if (r == 0)
        fxws_set_err(eb, el, "timeout after %d ms %s %s://%s%s", timeout_ms,
                     c->established ? "waiting for the hello of" : "connecting to", fxws_scheme(&c->url),
                     c->url.host_header, c->url.path);
    else
        fxws_set_err(eb, el, "%s", c->err);
    fxc_free(c);
    *out = NULL;
    return -1;
}

enum fxc_state fxc_state(const struct fxc_client *c) { return c->state; }
const char *fxc_hello(const struct fxc_client *c) { return c->hello; }
const char *fxc_error(const struct fxc_client *c) { return c->err; }
void fxc_stats(const struct fxc_client *c, struct fxc_stats *out) { *out = c->stats; }

void fxc_close(struct fxc_client *c)
{
    if (!c) return;
    if (c->established && c->wsi && c->state != FXC_CLOSED) {
        fxws_set_err(c->err, sizeof c->err, "closed by the client");
        lws_close_reason(c->wsi, LWS_CLOSE_STATUS_NORMAL, NULL, 0);
        c->closing = 1; /* the writeable callback returns -1: lws sends the close */
        lws_callback_on_writable(c->wsi);
        fxc_pump(c, fxc_deadline(FXC_CLOSE_WAIT_MS), fxc_is_closed);
    }
    fxc_free(c);
}

/* ---- requests ---------------------------------------------------------------------------------- */

/* Gives req (consumed) a fresh id and queues its text. Returns the id, or -1. */
static int64_t fxc_send_obj(struct fxc_client *c, cJSON *req, char *eb, size_t el)
{
    char *text = NULL;
    int ok = 0;
    if (c->state == FXC_CLOSED || c->closing) {
        fxws_set_err(eb, el, "%s", c->err[0] ? c->err : "connection closed");
    } else if (c->out.n >= FXC_MAX_QUEUED_SENDS) {
        fxws_set_err(eb, el, "%d requests already wait to be sent", FXC_MAX_QUEUED_SENDS);
    } else {
        cJSON_DeleteItemFromObjectCaseSensitive(req, "id");
        ok = cJSON_AddNumberToObject(req, "id", (double)(c->next_id + 1)) && (text = cJSON_PrintUnformatted(req)) &&
             !fxws_outq_push(&c->out, text, strlen(text));
        if (!ok) fxws_set_err(eb, el, "out of memory");
    }
    cJSON_Delete(req);
    free(text);
    if (!ok) return -1;
    if (c->established && c->wsi) lws_callback_on_writable(c->wsi);
    return ++c->next_id;
}

int64_t fxc_send(struct fxc_client *c, const char *json, char *eb, size_t el)
{
    cJSON *req = json ? cJSON_Parse(json) : NULL;
    if (!cJSON_IsObject(req) || !cJSON_IsString(cJSON_GetObjectItemCaseSensitive(req, "op"))) {
        fxws_set_err(eb, el, "%s", !req ? "request is not valid JSON" : "request must be a JSON object with a string \"op\"");
        cJSON_Delete(req);
        return -1;
    }
    return fxc_send_obj(c, req, eb, el);
}

/* {"op":op,"stream":stream}, or NULL with a message. */
static cJSON *fxc_stream_req(const char *op, const char *stream, char *eb, size_t el)
{
    cJSON *req = cJSON_CreateObject();
    if (!stream) {
        fxws_set_err(eb, el, "%s: no stream given", op);
    } else if (!req || !cJSON_AddStringToObject(req, "op", op) || !cJSON_AddStringToObject(req, "stream", stream)) {
        fxws_set_err(eb, el, "out of memory");
    } else {
        return req;
    }
    cJSON_Delete(req);
    return NULL;
}

int64_t fxc_subscribe(struct fxc_client *c, const char *stream, double max_fps, char *eb, size_t el)
{
    return fxc_subscribe_encoding(c, stream, max_fps, FXS_ENCODING_DEFAULT, eb, el);
}

int64_t fxc_subscribe_encoding(struct fxc_client *c, const char *stream, double max_fps, enum fxs_encoding enc,
                               char *eb, size_t el)
{
    return fxc_subscribe_budget(c, stream, max_fps, enc, 0, eb, el);
}

int64_t fxc_subscribe_budget(struct fxc_client *c, const char *stream, double max_fps, enum fxs_encoding enc,
                             uint32_t max_particles, char *eb, size_t el)
{
    if ((unsigned)enc >= FXS_ENCODING_COUNT) {
        fxws_set_err(eb, el, "subscribe: encoding %d is none of FXS_ENCODING_*", (int)enc);
        return -1;
    }
    if (max_particles && (max_particles < FXS_MAX_PARTICLES_MIN || max_particles > FXS_MAX_PARTICLES_MAX)) {
        fxws_set_err(eb, el, "subscribe: max_particles %u is outside [%u, %u] (0: no budget)", max_particles,
                     FXS_MAX_PARTICLES_MIN, FXS_MAX_PARTICLES_MAX);
        return -1;
    }
    cJSON *req = fxc_stream_req("subscribe", stream, eb, el);
    if (!req) return -1;
    if ((max_fps > 0 && !cJSON_AddNumberToObject(req, "max_fps", max_fps)) ||
        (enc != FXS_ENCODING_DEFAULT && !cJSON_AddStringToObject(req, "encoding", fxs_encoding_name(enc))) ||
        (max_particles && !cJSON_AddNumberToObject(req, "max_particles", max_particles))) {
        cJSON_Delete(req);
        fxws_set_err(eb, el, "out of memory");
        return -1;
    }
    return fxc_send_obj(c, req, eb, el);
}

int64_t fxc_unsubscribe(struct fxc_client *c, const char *stream, char *eb, size_t el)
{
    cJSON *req = fxc_stream_req("unsubscribe", stream, eb, el);
    return req ? fxc_send_obj(c, req, eb, el) : -1;
}

int64_t fxc_get(struct fxc_client *c, const char *stream, char *eb, size_t el)
{
    cJSON *req = fxc_stream_req("get", stream, eb, el);
    return req ? fxc_send_obj(c, req, eb, el) : -1;
}

/* A set request of stream with params (consumed). */
static int64_t fxc_set_obj(struct fxc_client *c, const char *stream, cJSON *params, char *eb, size_t el)
{
    cJSON *req = cJSON_IsObject(params) ? fxc_stream_req("set", stream, eb, el) : NULL;
    if (!cJSON_IsObject(params)) fxws_set_err(eb, el, "set: params must be a JSON object");
    if (!req) {
        cJSON_Delete(params);
        return -1;
    }
    cJSON_AddItemToObject(req, "params", params);
    return fxc_send_obj(c, req, eb, el);
}

int64_t fxc_set(struct fxc_client *c, const char *stream, const char *params_json, char *eb, size_t el)
{
    return fxc_set_obj(c, stream, params_json ? cJSON_Parse(params_json) : NULL, eb, el);
}

int64_t fxc_set_number(struct fxc_client *c, const char *stream, const char *name, double value, char *eb,
                       size_t el)
{
    cJSON *params = cJSON_CreateObject();
    if (!name || !cJSON_AddNumberToObject(params, name, value)) {
        cJSON_Delete(params);
        fxws_set_err(eb, el, name ? "out of memory" : "set: no parameter name given");
        return -1;
    }
    return fxc_set_obj(c, stream, params, eb, el);
}

/* ---- receiving ------------------------------------------------------------------------------------ */

int fxc_poll(struct fxc_client *c, struct fxc_event *ev, int timeout_ms, char *eb, size_t el)
{
    int r = fxc_pump(c, fxc_deadline(timeout_ms), fxc_has_event);
    memset(ev, 0, sizeof *ev);
    if (r != 1) {
        if (r < 0) fxws_set_err(eb, el, "%s", c->err);
        return r;
    }
    fxc_node_give(fxc_queue_unlink(c, NULL, c->head), ev);
    return 1;
}

/* Fills errbuf from an error reply: "code: message (param p)". */
static void fxc_reply_error(const struct fxc_event *r, char *eb, size_t el)
{
    fxws_set_err(eb, el, "%s: %s%s%s%s", r->code ? r->code : "error", r->message ? r->message : "(no message)",
                 r->param ? " (param " : "", r->param ? r->param : "", r->param ? ")" : "");
}

int fxc_wait(struct fxc_client *c, int64_t id, struct fxc_event *reply, int timeout_ms, char *eb, size_t el)
{
    struct fxc_node *n, *prev = NULL;
    int r = 1;
    memset(reply, 0, sizeof *reply);
    if (id <= 0 || id > c->next_id) {
        fxws_set_err(eb, el, "no request has id %lld", (long long)id);
        return -1;
    }
    for (n = c->head; n && !(n->ev.type == FXC_EVENT_TEXT && n->ev.id == id); prev = n, n = n->next) {}
    if (n) {
        c->reply = fxc_queue_unlink(c, prev, n);
    } else {
        c->want_id = id;
        r = fxc_pump(c, fxc_deadline(timeout_ms), fxc_has_reply);
        c->want_id = 0;
    }
    if (r != 1) {
        if (r == 0) fxws_set_err(eb, el, "timeout after %d ms waiting for the reply to request %lld", timeout_ms, (long long)id);
        else fxws_set_err(eb, el, "%s", c->err);
        return -1;
    }
    fxc_node_give(c->reply, reply);
    c->reply = NULL;
    if (strcmp(reply->op, "error")) return 0;
    fxc_reply_error(reply, eb, el);
    return 1;
}

int fxc_request(struct fxc_client *c, const char *json, struct fxc_event *reply, int timeout_ms, char *eb,
                size_t el)
{
    int64_t id = fxc_send(c, json, eb, el);
    if (id < 0) {
        memset(reply, 0, sizeof *reply);
        return -1;
    }
    return fxc_wait(c, id, reply, timeout_ms, eb, el);
}

/* ---- parameters of a params event ------------------------------------------------------------------ */

static const cJSON *fxc_param(const struct fxc_event *ev, const char *name)
{
    const struct fxc_node *n = ev ? ev->internal : NULL;
    if (!n || ev->type != FXC_EVENT_TEXT || !name) return NULL;
    return cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(n->tree, "params"), name);
}

int fxc_param_number(const struct fxc_event *ev, const char *name, double *value)
{
    const cJSON *v = fxc_param(ev, name);
    if (!cJSON_IsNumber(v)) return -1;
    *value = v->valuedouble;
    return 0;
}

int fxc_param_json(const struct fxc_event *ev, const char *name, char *buf, size_t len)
{
    const cJSON *v = fxc_param(ev, name);
    char *text = v ? cJSON_PrintUnformatted(v) : NULL;
    int r = text && strlen(text) < len ? 0 : -1;
    if (!r) memcpy(buf, text, strlen(text) + 1);
    free(text);
    return r;
}
