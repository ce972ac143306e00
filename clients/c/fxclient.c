/* fxclient.c — libfxclient: one blocking fxstream.v1 connection over libwebsockets.
 *
 * Owns the client's lws context, its single wsi, the reassembly buffer for
 * fragmented messages, the one outgoing message in flight, the pending request id
 * and the bounded queue of events and frames (see fxclient.h for the contract).
 *
 * Shape: lws callbacks only record what happened into struct fxc_client; the
 * public calls run fxc_pump(), which services lws in the caller's thread until a
 * condition holds, the connection ends or a deadline passes. lws_service() ignores
 * its timeout since v3.2, so a self-re-arming timer (sul) bounds every poll wait.
 * URL parsing, connect diagnosis, the handshake checks and fragment reassembly are
 * shared with fxpool.c through fxws.c. */
#include "fxclient.h"
#include "fxws.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <libwebsockets.h>

#define FXC_CLOSE_WAIT_MS 500
#define FXC_TICK_US 100000 /* longest lws poll wait of one fxc_pump round */
#define FXC_REARM_US 1000  /* poll wait after a tick fired before lws polled */

enum fxc_state { FXC_CONNECTING, FXC_OPEN, FXC_CLOSED };

struct fxc_node {
    struct fxc_node *next;
    struct fxc_msg msg;
};

struct fxc_client {
    struct lws_context *ctx;
    struct lws *wsi;
    lws_sorted_usec_list_t tick;   /* wakes lws_service() at our deadlines */
    enum fxc_state state;
    int tcp_up;                    /* connected; the handshake request went out */
    int closing;                   /* fxc_close asked lws to close */
    char err[256];                 /* why the connection failed or ended */
    struct fxws_url url;           /* host, port, path, host_header */
    char *token;                   /* sent in the handshake, or NULL */

    struct fxws_rx rx;             /* message being reassembled */

    unsigned char *tx;             /* LWS_PRE + text of the message to send */
    size_t tx_len;

    double next_id, want_id;
    int want;                      /* a request is waiting for want_id */
    cJSON *reply;
    cJSON *hello;

    struct fxc_node *head, *tail;
    size_t n_events;
    struct fxc_stats stats;
};

static int64_t fxc_deadline(int timeout_ms)
{
    return timeout_ms < 0 ? INT64_MAX : fxws_now_us(CLOCK_MONOTONIC) + (int64_t)timeout_ms * 1000;
}

/* ---- queue ---------------------------------------------------------------- */

void fxc_msg_free(struct fxc_msg *m)
{
    if (!m) return;
    cJSON_Delete(m->event);
    free(m->data);
    memset(m, 0, sizeof *m);
}

static void fxc_queue_push(struct fxc_client *c, struct fxc_node *n)
{
    n->next = NULL;
    if (c->tail) c->tail->next = n;
    else c->head = n;
    c->tail = n;
    if (n->msg.type == FXC_MSG_EVENT) c->n_events++;
}

static struct fxc_node *fxc_queue_unlink(struct fxc_client *c, struct fxc_node *prev, struct fxc_node *n)
{
    if (prev) prev->next = n->next;
    else c->head = n->next;
    if (c->tail == n) c->tail = prev;
    if (n->msg.type == FXC_MSG_EVENT) c->n_events--;
    return n;
}

/* Drops the oldest queued message matching (type, channel) when `limit` or more are
 * queued. Returns 1 when one was dropped. */
static int fxc_queue_trim(struct fxc_client *c, enum fxc_msg_type type, uint32_t channel, size_t limit)
{
    struct fxc_node *n, *prev = NULL, *oldest = NULL, *oldest_prev = NULL;
    size_t count = 0;
    for (n = c->head; n; prev = n, n = n->next) {
        if (n->msg.type != type || (type == FXC_MSG_FRAME && n->msg.header.channel != channel)) continue;
        if (!oldest) { oldest = n; oldest_prev = prev; }
        count++;
    }
    if (count < limit) return 0;
    fxc_queue_unlink(c, oldest_prev, oldest);
    fxc_msg_free(&oldest->msg);
    free(oldest);
    return 1;
}

static void fxc_queue_free(struct fxc_client *c)
{
    while (c->head) {
        struct fxc_node *n = fxc_queue_unlink(c, NULL, c->head);
        fxc_msg_free(&n->msg);
        free(n);
    }
}

/* ---- received messages ------------------------------------------------------ */

static void fxc_on_frame(struct fxc_client *c, int64_t now)
{
    struct fxc_node *n;
    struct fxs_header h;
    uint8_t *fit;
    if (fxs_header_unpack(c->rx.buf, c->rx.len, &h) || !(n = calloc(1, sizeof *n))) {
        c->stats.bad_messages++;
        return;
    }
    if ((fit = realloc(c->rx.buf, c->rx.len))) c->rx.buf = fit; /* the frame keeps the buffer: trim it */
    c->stats.frames_received++;
    if (fxc_queue_trim(c, FXC_MSG_FRAME, h.channel, FXC_QUEUE_FRAMES_PER_CHANNEL)) c->stats.frames_dropped++;
    n->msg.type = FXC_MSG_FRAME;
    n->msg.header = h;
    n->msg.data = c->rx.buf;
    n->msg.data_bytes = c->rx.len;
    n->msg.payload = c->rx.buf + h.header_bytes;
    n->msg.recv_time_us = (uint64_t)now;
    c->rx.buf = NULL;
    c->rx.cap = 0;
    fxc_queue_push(c, n);
}

static void fxc_on_event(struct fxc_client *c, cJSON *j, int64_t now)
{
    struct fxc_node *n = calloc(1, sizeof *n);
    if (!n) { cJSON_Delete(j); c->stats.bad_messages++; return; }
    if (c->n_events >= FXC_QUEUE_EVENTS && fxc_queue_trim(c, FXC_MSG_EVENT, 0, FXC_QUEUE_EVENTS))
        c->stats.events_dropped++;
    n->msg.type = FXC_MSG_EVENT;
    n->msg.event = j;
    n->msg.recv_time_us = (uint64_t)now;
    fxc_queue_push(c, n);
}

/* Routes one complete text message: the hello, the awaited reply, a stray reply
 * (dropped), or an event (queued). */
static void fxc_on_text(struct fxc_client *c, int64_t now)
{
    cJSON *j = cJSON_ParseWithLength((const char *)c->rx.buf, c->rx.len);
    const cJSON *op = cJSON_GetObjectItemCaseSensitive(j, "op");
    const cJSON *id = cJSON_GetObjectItemCaseSensitive(j, "id");
    if (!cJSON_IsObject(j) || !cJSON_IsString(op)) {
        c->stats.bad_messages++;
        cJSON_Delete(j);
    } else if (!c->hello && strcmp(op->valuestring, "hello") == 0) {
        c->hello = j;
    } else if (id && c->want && cJSON_IsNumber(id) && id->valuedouble == c->want_id) {
        c->reply = j;
        c->want = 0;
    } else if (id) {
        c->stats.bad_messages++;
        cJSON_Delete(j);
    } else {
        fxc_on_event(c, j, now);
    }
}

/* Appends one received chunk; returns -1 (and closes) when the message is too big. */
static int fxc_on_receive(struct fxc_client *c, struct lws *wsi, const void *in, size_t len)
{
    int r = fxws_rx_append(&c->rx, wsi, in, len, FXC_MAX_MESSAGE_BYTES, SIZE_MAX, c->err, sizeof c->err);
    if (r == -1) lws_close_reason(wsi, LWS_CLOSE_STATUS_MESSAGE_TOO_LARGE, NULL, 0);
    if (r <= 0) return r < 0 ? -1 : 0;
    if (c->rx.binary) fxc_on_frame(c, fxws_now_us(CLOCK_REALTIME));
    else fxc_on_text(c, fxws_now_us(CLOCK_REALTIME));
    return 0;
}

/* ---- lws callbacks ---------------------------------------------------------- */

/* Turns lws's connection-error text into one of the documented messages. */
static void fxc_on_connect_error(struct fxc_client *c, const char *why)
{
    const char *w = why ? why : "unknown error";
    int e = 0;
    if (c->err[0]) return; /* our own filter already explained it */
    if (fxws_connect_needs_probe(c->tcp_up, w)) e = fxws_probe_errno(&c->url);
    fxws_connect_error(&c->url, c->tcp_up, w, e, c->err, sizeof c->err);
}

/* Rejects a server that did not agree to our subprotocol. */
static int fxc_check_subprotocol(struct fxc_client *c, struct lws *wsi)
{
    return fxws_check_subprotocol(&c->url, wsi, c->err, sizeof c->err);
}

static void fxc_on_peer_close(struct fxc_client *c, const uint8_t *in, size_t len)
{
    int code;
    fxws_peer_close(in, len, &code, c->err, sizeof c->err, NULL, 0);
}

static int fxc_on_writeable(struct fxc_client *c, struct lws *wsi)
{
    int n;
    if (!c->tx_len) return 0;
    n = lws_write(wsi, c->tx + LWS_PRE, c->tx_len, LWS_WRITE_TEXT);
    c->tx_len = 0;
    if (n < 0) {
        fxws_set_err(c->err, sizeof c->err, "write to server failed");
        return -1;
    }
    return 0;
}

static int fxc_lws_cb(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len)
{
    struct fxc_client *c = lws_context_user(lws_get_context(wsi));
    (void)user;
    switch (reason) {
    case LWS_CALLBACK_CLIENT_CONNECTION_ERROR:
        fxc_on_connect_error(c, in);
        c->state = FXC_CLOSED;
        c->wsi = NULL;
        return 0;
    case LWS_CALLBACK_CLIENT_APPEND_HANDSHAKE_HEADER:
        c->tcp_up = 1;
        return fxws_append_auth(wsi, in, len, c->token);
    case LWS_CALLBACK_CLIENT_FILTER_PRE_ESTABLISH:
        return fxc_check_subprotocol(c, wsi);
    case LWS_CALLBACK_CLIENT_ESTABLISHED:
        c->state = FXC_OPEN;
        return 0;
    case LWS_CALLBACK_CLIENT_RECEIVE:
        return fxc_on_receive(c, wsi, in, len);
    case LWS_CALLBACK_CLIENT_WRITEABLE:
        if (c->closing) return -1;
        return fxc_on_writeable(c, wsi);
    case LWS_CALLBACK_WS_PEER_INITIATED_CLOSE:
        fxc_on_peer_close(c, in, len);
        return 0;
    case LWS_CALLBACK_CLIENT_CLOSED:
        if (!c->err[0]) fxws_set_err(c->err, sizeof c->err, "connection to %s:%d lost", c->url.host, c->url.port);
        c->state = FXC_CLOSED;
        c->wsi = NULL;
        return 0;
    default:
        return 0;
    }
}

static const struct lws_protocols fxc_protocols[] = {
    { .name = FXC_SUBPROTOCOL, .callback = fxc_lws_cb, .rx_buffer_size = 65536 },
    { .name = NULL },
};

/* ---- service loop ----------------------------------------------------------- */

/* lws runs ripe timers before it computes its poll wait, so a tick that expired
 * just then would leave the poll unbounded: the tick re-arms itself. */
static void fxc_tick_cb(lws_sorted_usec_list_t *sul)
{
    struct fxc_client *c = lws_container_of(sul, struct fxc_client, tick);
    lws_sul_schedule(c->ctx, 0, &c->tick, fxc_tick_cb, FXC_REARM_US);
}

typedef int (*fxc_cond)(const struct fxc_client *c);

/* Services lws until cond(c) holds (1), the connection is closed (-1) or the
 * deadline passes (0). cond is checked first, so queued results win over a close. */
static int fxc_pump(struct fxc_client *c, int64_t deadline, fxc_cond cond)
{
    for (;;) {
        int64_t now = fxws_now_us(CLOCK_MONOTONIC);
        if (cond(c)) return 1;
        if (c->state == FXC_CLOSED) return -1;
        if (now >= deadline) return 0;
        lws_sul_schedule(c->ctx, 0, &c->tick, fxc_tick_cb, deadline - now < FXC_TICK_US ? deadline - now : FXC_TICK_US);
        if (lws_service(c->ctx, 0) < 0) {
            fxws_set_err(c->err, sizeof c->err, "libwebsockets service failed");
            c->state = FXC_CLOSED;
        }
    }
}

static int fxc_has_hello(const struct fxc_client *c) { return c->hello != NULL; }
static int fxc_has_reply(const struct fxc_client *c) { return c->reply != NULL; }
static int fxc_has_msg(const struct fxc_client *c) { return c->head != NULL; }

/* ---- public API --------------------------------------------------------------- */

static int fxc_start(struct fxc_client *c, const char *ca_file, char *eb, size_t el)
{
    struct lws_context_creation_info info;
    struct lws_client_connect_info ci;
    struct addrinfo *ai = fxws_resolve(&c->url, eb, el);
    if (!ai) return -1;
    freeaddrinfo(ai);
    memset(&info, 0, sizeof info);
    info.port = CONTEXT_PORT_NO_LISTEN;
    info.protocols = fxc_protocols;
    info.gid = (gid_t)-1;
    info.uid = (uid_t)-1;
    info.fd_limit_per_thread = 16;
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
    fxc_queue_free(c);
    cJSON_Delete(c->hello);
    cJSON_Delete(c->reply);
    fxws_rx_free(&c->rx);
    free(c->tx);
    free(c->token);
    free(c);
}

int fxc_connect(struct fxc_client **out, const char *url, int timeout_ms, char *eb, size_t el)
{
    return fxc_connect_with(out, url, NULL, timeout_ms, eb, el);
}

int fxc_connect_with(struct fxc_client **out, const char *url, const struct fxc_options *o, int timeout_ms,
                     char *eb, size_t el)
{
    struct fxc_client *c = calloc(1, sizeof *c);
    int r;
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
    r = fxc_pump(c, fxc_deadline(timeout_ms), fxc_has_hello);
    if (r == 1) {
        *out = c;
        return 0;
    }
    if (r == 0)
        fxws_set_err(eb, el, "timeout after %d ms %s %s://%s%s", timeout_ms,
                    c->state == FXC_OPEN ? "waiting for the hello of" : "connecting to", fxws_scheme(&c->url),
                    c->url.host_header, c->url.path);
    else
        fxws_set_err(eb, el, "%s", c->err);
    fxc_free(c);
    return -1;
}

const cJSON *fxc_hello(const struct fxc_client *c) { return c->hello; }

/* Serializes req plus "id": c->next_id into c->tx and asks lws for a write. */
static int fxc_queue_request(struct fxc_client *c, const cJSON *req, char *eb, size_t el)
{
    cJSON *copy = cJSON_Duplicate(req, 1);
    char *text;
    size_t n;
    if (!copy || !cJSON_IsObject(copy)) {
        cJSON_Delete(copy);
        fxws_set_err(eb, el, "request must be a JSON object");
        return -1;
    }
    cJSON_DeleteItemFromObjectCaseSensitive(copy, "id");
    cJSON_AddNumberToObject(copy, "id", ++c->next_id);
    text = cJSON_PrintUnformatted(copy);
    cJSON_Delete(copy);
    n = text ? strlen(text) : 0;
    free(c->tx);
    if (!text || !(c->tx = malloc(LWS_PRE + n))) {
        free(text);
        c->tx = NULL;
        fxws_set_err(eb, el, "out of memory");
        return -1;
    }
    memcpy(c->tx + LWS_PRE, text, n);
    free(text);
    c->tx_len = n;
    c->want_id = c->next_id;
    c->want = 1;
    lws_callback_on_writable(c->wsi);
    return 0;
}

/* Fills errbuf from an error reply: "code: message (param p)". */
static void fxc_reply_error(const cJSON *r, char *eb, size_t el)
{
    const cJSON *code = cJSON_GetObjectItemCaseSensitive(r, "code");
    const cJSON *msg = cJSON_GetObjectItemCaseSensitive(r, "message");
    const cJSON *param = cJSON_GetObjectItemCaseSensitive(r, "param");
    fxws_set_err(eb, el, "%s: %s%s%s%s", cJSON_IsString(code) ? code->valuestring : "error",
                cJSON_IsString(msg) ? msg->valuestring : "(no message)",
                cJSON_IsString(param) ? " (param " : "", cJSON_IsString(param) ? param->valuestring : "",
                cJSON_IsString(param) ? ")" : "");
}

int fxc_request(struct fxc_client *c, const cJSON *req, cJSON **reply, int timeout_ms, char *eb, size_t el)
{
    const cJSON *op;
    int r;
    *reply = NULL;
    if (c->state != FXC_OPEN) { fxws_set_err(eb, el, "%s", c->err); return -1; }
    if (fxc_queue_request(c, req, eb, el)) return -1;
    r = fxc_pump(c, fxc_deadline(timeout_ms), fxc_has_reply);
    if (r != 1) {
        c->want = 0;
        c->tx_len = 0;
        op = cJSON_GetObjectItemCaseSensitive(req, "op");
        if (r == 0)
            fxws_set_err(eb, el, "timeout after %d ms waiting for the reply to \"%s\"", timeout_ms,
                        cJSON_IsString(op) ? op->valuestring : "?");
        else
            fxws_set_err(eb, el, "%s", c->err);
        return -1;
    }
    *reply = c->reply;
    c->reply = NULL;
    op = cJSON_GetObjectItemCaseSensitive(*reply, "op");
    if (strcmp(op->valuestring, "error") != 0) return 0;
    fxc_reply_error(*reply, eb, el);
    return 1;
}

int fxc_next(struct fxc_client *c, struct fxc_msg *m, int timeout_ms, char *eb, size_t el)
{
    struct fxc_node *n;
    int r = fxc_pump(c, fxc_deadline(timeout_ms), fxc_has_msg);
    memset(m, 0, sizeof *m);
    if (r != 1) {
        if (r < 0) fxws_set_err(eb, el, "%s", c->err);
        return r;
    }
    n = fxc_queue_unlink(c, NULL, c->head);
    *m = n->msg;
    free(n);
    return 1;
}

void fxc_stats(const struct fxc_client *c, struct fxc_stats *out) { *out = c->stats; }

static int fxc_is_closed(const struct fxc_client *c) { return c->state == FXC_CLOSED; }

void fxc_close(struct fxc_client *c)
{
    if (!c) return;
    if (c->state == FXC_OPEN && c->wsi) {
        fxws_set_err(c->err, sizeof c->err, "closed by the client");
        lws_close_reason(c->wsi, LWS_CLOSE_STATUS_NORMAL, NULL, 0);
        c->closing = 1; /* the writeable callback returns -1: lws sends the close */
        lws_callback_on_writable(c->wsi);
        fxc_pump(c, fxc_deadline(FXC_CLOSE_WAIT_MS), fxc_is_closed);
    }
    fxc_free(c);
}
