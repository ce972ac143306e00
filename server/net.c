/* net.c — see net.h.
 *
 * Sending: a session sends one message at a time. Queued text replies go first;
 * otherwise the newest unsent frame of any subscription (round-robin, honouring each
 * subscription's max_fps) is sent in chunks of NET_CHUNK bytes, one chunk per writable
 * callback, as one fragmented WebSocket message. Frame bytes are shared by every
 * subscriber and never copied: the WebSocket framing goes into the FRAME_HEADROOM
 * bytes before the frame, and for later chunks into the bytes before the chunk, which
 * are saved and restored around the write (all sends run on this one thread, and
 * lws_write either sends or buffers before it returns). A subscriber that cannot keep
 * up simply picks the newest frame when it is ready again: latest frame wins.
 *
 * Retries: a connection held back (backlogged socket, or max_fps) is woken again later.
 * libwebsockets keeps its timers in one sorted list, so a timer per connection costs O(n)
 * per insert: with 1536 backlogged subscribers that was 38% of the daemon's CPU. The
 * sessions waiting instead sit in one unsorted list here, walked by a single timer. */
#include <dlfcn.h>
#include <limits.h>
#include <signal.h>
#include <sys/stat.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <time.h>

#include <linux/sockios.h>
#include <sys/ioctl.h>

#include <libwebsockets.h>

#include "clock.h"
#include "log.h"
#include "metrics.h"
#include "net.h"
#include "replica.h"
#include "session.h"
#include "store.h"
#include "wsguard.h"

#define NET_CHUNK (64 * 1024)
#define NET_WS_PATH "/v1/ws"
#define NET_SHUTDOWN_GRACE_S 2.0
#define NET_BACKLOG_RETRY_S 0.01 /* a backlogged connection looks again after 10 ms */

_Static_assert(LWS_PRE <= FRAME_HEADROOM, "frame headroom must hold the WebSocket framing");

#define NET_PENDING_MAX 128     /* connections waiting for their first request */
#define NET_PENDING_TIMEOUT_S 3 /* ... for at most this long */

/* A WebSocket connection: its protocol session (session.h) and what only the network layer
 * keeps about it. lws allocates it as the per-session data; the session comes first, so a
 * session pointer is its connection's pointer (net_conn_of). */
struct net_conn {
    struct session ss;
    struct lws *wsi;
    double last_write; /* CLOCK_MONOTONIC seconds of the last write to the socket */
    struct net_conn *retry_next, *retry_prev; /* the list of connections to wake at retry_at */
    double retry_at;
    bool retry_queued;
    bool rx_paused;   /* no request is read while the session is backlogged (session_backlogged) */
    bool peer_closed; /* the client sent its close frame: nothing after it is acted on */
};

static struct net_conn *net_conn_of(struct session *ss) { return (struct net_conn *)ss; }

struct net {
    struct server *srv;
    struct lws_context *ctx;
    struct lws_vhost *vh;
    struct net_conn *retry_head; /* connections to wake at their retry_at (net_retry_later) */
    lws_sorted_usec_list_t retry_sul;
    double retry_sul_at;        /* when retry_sul fires; 0 = not scheduled */
    struct lws_protocols protocols[3];
    struct lws_http_mount mount;
    struct lws *pending[NET_PENDING_MAX]; /* connections without a request yet, oldest first */
    int npending;
    char web_root[PATH_MAX];    /* the web root's real path ("" when there is none) */
    volatile sig_atomic_t stop_requested;
    bool stopping;
};

/* Connections that have not yet sent a whole request (HTTP or WebSocket handshake): at most
 * NET_PENDING_MAX at once, the oldest dropped to make room, each for at most
 * NET_PENDING_TIMEOUT_S. A real client's request arrives within milliseconds, so a flood of
 * half-open handshakes (sockets that send a partial GET and wait) can no longer hold every
 * file descriptor and lock sessions and /healthz out. */
static void net_pending_drop(struct net *net, struct lws *wsi)
{
    for (int i = 0; i < net->npending; i++)
        if (net->pending[i] == wsi) {
            memmove(net->pending + i, net->pending + i + 1, sizeof wsi * (size_t)(net->npending - i - 1));
            net->npending--;
            return;
        }
}

static void net_pending_add(struct net *net, struct lws *wsi)
{
    if (net->npending == NET_PENDING_MAX) {
        lws_set_timeout(net->pending[0], PENDING_TIMEOUT_HTTP_KEEPALIVE_IDLE, LWS_TO_KILL_ASYNC);
        net_pending_drop(net, net->pending[0]);
        atomic_fetch_add(&net->srv->counters.handshakes_evicted, 1);
    }
    net->pending[net->npending++] = wsi;
    lws_set_timeout(wsi, PENDING_TIMEOUT_HTTP_KEEPALIVE_IDLE, NET_PENDING_TIMEOUT_S);
}

struct net_http {
    struct fx_buf body; /* LWS_PRE bytes, then the response body */
};

/* ---- HTTP: /healthz and /metrics ---- */

/* The file under the web root that path names, when it is a regular file whose real path
 * (symlinks resolved) lies inside the root; "/" and "/dir/" give index.html. 0 or -1. */
static int net_static_path(const struct net *net, const char *path, char *real)
{
    char want[PATH_MAX + 300];
    struct stat st;
    size_t rl = strlen(net->web_root), pl = strlen(path);
    if (!rl || path[0] != '/' || strstr(path, "/..")) return -1;
    snprintf(want, sizeof want, "%s%s%s", net->web_root, path, path[pl - 1] == '/' ? "index.html" : "");
    if (!realpath(want, real) || strncmp(real, net->web_root, rl) || real[rl] != '/') return -1;
    return stat(real, &st) || !S_ISREG(st.st_mode) ? -1 : 0;
}

static const char *net_mime(const char *file)
{
    static const char *const types[][2] = {
        {".html", "text/html; charset=utf-8"}, {".js", "text/javascript"}, {".mjs", "text/javascript"},
        {".css", "text/css"}, {".json", "application/json"}, {".png", "image/png"}, {".svg", "image/svg+xml"},
        {".ico", "image/x-icon"}, {".wasm", "application/wasm"}, {".txt", "text/plain; charset=utf-8"}};
    const char *dot = strrchr(file, '.');
    for (size_t i = 0; dot && i < sizeof types / sizeof types[0]; i++)
        if (!strcmp(dot, types[i][0])) return types[i][1];
    return "application/octet-stream";
}

/* Ends an HTTP transaction: lws reads the connection's next request (keep-alive) afresh, and
 * the masking guard follows it from its first byte. -1: the connection is to close. */
static int net_http_done(struct lws *wsi)
{
    if (lws_http_transaction_completed(wsi)) return -1;
    wsguard_next_request(wsi);
    return 0;
}

static int net_http_request(struct lws *wsi, struct net *net, struct net_http *h, const char *path)
{
    uint8_t hdr[LWS_PRE + 1024], *start = hdr + LWS_PRE, *p = start, *end = hdr + sizeof hdr - 1;
    fx_buf_free(&h->body);
    fx_buf_reserve(&h->body, LWS_PRE);
    h->body.len = LWS_PRE;
    const char *type = "application/json";
    int status = HTTP_STATUS_OK;
    if (!strcmp(path, "/healthz")) {
        metrics_health(net->srv, &h->body);
    } else if (!strcmp(path, "/metrics")) {
        type = "text/plain; version=0.0.4";
        metrics_render(net->srv, &h->body);
    } else {
        char real[PATH_MAX];
        if (!net_static_path(net, path, real)) {
            int n = lws_serve_http_file(wsi, real, net_mime(real), NULL, 0);
            return n < 0 || (n > 0 && net_http_done(wsi)) ? -1 : 0;
        }
        status = HTTP_STATUS_NOT_FOUND;
        fx_buf_append(&h->body, "{\"error\":\"not found\"}", 21);
    }
    size_t n = h->body.len - LWS_PRE;
    if (lws_add_http_common_headers(wsi, (unsigned)status, type, n, &p, end) ||
        lws_add_http_header_by_token(wsi, WSI_TOKEN_HTTP_CACHE_CONTROL, (const uint8_t *)"no-store", 8, &p, end) ||
        lws_finalize_write_http_header(wsi, start, &p, end))
        return 1;
    lws_callback_on_writable(wsi);
    return 0;
}

/* 405 with "Allow: GET" (RFC 9110 15.5.6) for any method but GET; the connection closes. */
static int net_http_not_allowed(struct lws *wsi)
{
    uint8_t hdr[LWS_PRE + 256], *start = hdr + LWS_PRE, *p = start, *end = hdr + sizeof hdr - 1;
    if (!lws_add_http_header_status(wsi, HTTP_STATUS_METHOD_NOT_ALLOWED, &p, end) &&
        !lws_add_http_header_by_name(wsi, (const uint8_t *)"allow:", (const uint8_t *)"GET", 3, &p, end) &&
        !lws_add_http_header_content_length(wsi, 0, &p, end) && !lws_finalize_http_header(wsi, &p, end))
        lws_write(wsi, start, (size_t)(p - start), LWS_WRITE_HTTP_HEADERS);
    return -1;
}

/* libwebsockets 4.1 answers two kinds of request itself, before any callback, with 403: an
 * unknown method (TRACE) and a request target that is not a path (OPTIONS *). The daemon
 * serves GET only, so those get the 405 that every other method gets (net_http_not_allowed).
 * lws calls this function through its PLT, so the executable's definition is the one it uses;
 * any other status, and a 403 for a GET, goes to lws's own. */
int lws_return_http_status(struct lws *wsi, unsigned int code, const char *html_body)
{
    static int (*next)(struct lws *, unsigned int, const char *);
    if (code == HTTP_STATUS_FORBIDDEN && lws_hdr_total_length(wsi, WSI_TOKEN_GET_URI) <= 0) {
        net_http_not_allowed(wsi);
        return 0;
    }
    if (!next) next = (int (*)(struct lws *, unsigned int, const char *))dlsym(RTLD_NEXT, "lws_return_http_status");
    return next ? next(wsi, code, html_body) : -1;
}

static int net_http_cb(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len)
{
    struct net *net = lws_context_user(lws_get_context(wsi));
    struct net_http *h = user;
    switch (reason) {
    case LWS_CALLBACK_SERVER_NEW_CLIENT_INSTANTIATED:
        wsguard_open(wsi, lws_get_socket_fd(wsi));
        net_pending_add(net, wsi);
        break;
    case LWS_CALLBACK_WSI_DESTROY: /* every connection's, whatever its protocol */
        wsguard_close(wsi);
        net_pending_drop(net, wsi);
        break;
    case LWS_CALLBACK_RAW_ADOPT: { /* lws turns a CONNECT request into a raw socket: 405 too */
        static const char r[] = "HTTP/1.1 405 Method Not Allowed\r\nallow: GET\r\ncontent-length: 0\r\n\r\n";
        uint8_t buf[LWS_PRE + sizeof r];
        memcpy(buf + LWS_PRE, r, sizeof r - 1);
        lws_write(wsi, buf + LWS_PRE, sizeof r - 1, LWS_WRITE_RAW);
        return -1;
    }
    case LWS_CALLBACK_HTTP_FILE_COMPLETION: /* lws ends the transaction right after */
        wsguard_next_request(wsi);
        break;
    case LWS_CALLBACK_HTTP_CONFIRM_UPGRADE: /* h2c (HTTP/2 in the clear) is not spoken here */
        return strcasecmp((const char *)in, "websocket") ? -1 : 0;
    case LWS_CALLBACK_FILTER_PROTOCOL_CONNECTION:
        net_pending_drop(net, wsi);
        /* A WebSocket upgrade without subprotocol fxstream.v1 lands here: refuse it. */
        log_info("refused WebSocket without subprotocol fxstream.v1");
        return 1;
    case LWS_CALLBACK_HTTP: {
        char path[256] = "";
        net_pending_drop(net, wsi);
        if (lws_hdr_total_length(wsi, WSI_TOKEN_GET_URI) <= 0) return net_http_not_allowed(wsi);
        lws_hdr_copy(wsi, path, sizeof path, WSI_TOKEN_GET_URI); /* too long: "" -> 404 */
        return net_http_request(wsi, net, h, path);
    }
    case LWS_CALLBACK_HTTP_WRITEABLE: {
        if (!h || h->body.len <= LWS_PRE) break;
        size_t n = h->body.len - LWS_PRE;
        int w = lws_write(wsi, h->body.data + LWS_PRE, n, LWS_WRITE_HTTP_FINAL);
        fx_buf_free(&h->body);
        if (w < (int)n) return -1;
        return net_http_done(wsi);
    }
    case LWS_CALLBACK_CLOSED_HTTP:
        if (h) fx_buf_free(&h->body);
        break;
    default:
        break;
    }
    return lws_callback_http_dummy(wsi, reason, user, in, len);
}

/* ---- WebSocket: sending ---- */

static void net_wake(struct session *ss) { lws_callback_on_writable(net_conn_of(ss)->wsi); }

static void net_retry_unlink(struct net *net, struct net_conn *c)
{
    if (!c->retry_queued) return;
    if (c->retry_prev) c->retry_prev->retry_next = c->retry_next;
    else net->retry_head = c->retry_next;
    if (c->retry_next) c->retry_next->retry_prev = c->retry_prev;
    c->retry_next = c->retry_prev = NULL;
    c->retry_queued = false;
}

static void net_retry_fire(lws_sorted_usec_list_t *sul);

/* The delay is clamped to [0, NET_RETRY_MAX_S] before it becomes microseconds, so no interval
 * (a subscription's 1/max_fps included) can overflow lws's 64-bit timer or schedule it in the past. */
#define NET_RETRY_MAX_S 3600.0
static void net_retry_schedule(struct net *net, double at, double now)
{
    double delay = at - now;
    if (!(delay > 0)) delay = 0;
    if (delay > NET_RETRY_MAX_S) delay = NET_RETRY_MAX_S;
    net->retry_sul_at = now + delay;
    lws_sul_schedule(net->ctx, 0, &net->retry_sul, net_retry_fire, (lws_usec_t)(delay * 1e6) + 1);
}

/* Wakes ss after `delay` seconds (or earlier, when it is already due sooner). */
static void net_retry_later(struct net *net, struct session *ss, double delay)
{
    struct net_conn *c = net_conn_of(ss);
    double now = clock_now(), at = now + delay;
    if (c->retry_queued && c->retry_at <= at) return;
    if (!c->retry_queued) {
        c->retry_next = net->retry_head;
        c->retry_prev = NULL;
        if (net->retry_head) net->retry_head->retry_prev = c;
        net->retry_head = c;
        c->retry_queued = true;
    }
    c->retry_at = at;
    if (net->retry_sul_at == 0 || at < net->retry_sul_at) net_retry_schedule(net, at, now);
}

/* The one retry timer: wakes the connections that are due, then waits for the next. */
static void net_retry_fire(lws_sorted_usec_list_t *sul)
{
    struct net *net = lws_container_of(sul, struct net, retry_sul);
    double now = clock_now(), next = 0;
    net->retry_sul_at = 0;
    for (struct net_conn *c = net->retry_head, *nx; c; c = nx) {
        nx = c->retry_next;
        if (c->retry_at <= now) {
            net_retry_unlink(net, c);
            lws_callback_on_writable(c->wsi);
        } else if (next == 0 || c->retry_at < next) {
            next = c->retry_at;
        }
    }
    if (next > 0) net_retry_schedule(net, next, now);
}

static bool net_pick_frame(struct net *net, struct session *ss)
{
    double now = clock_now(), wait = -1;
    for (int n = 0; n < ss->nsubs; n++) {
        int i = (ss->rr + n) % ss->nsubs;
        struct sub *sub = &ss->subs[i];
        for (int k = 1; k <= FXS_KIND_MAX; k++) {
            struct frame *f = hub_latest(&ss->srv->hub, sub->s, sub->form, k);
            if (!f || f->hdr.seq <= sub->last_seq[k]) {
                frame_unref(f);
                continue;
            }
            /* max_fps counts steps: the other kinds of a step already started (same sim_time,
             * e.g. a texture's light rig) go with it */
            double ready = f->hdr.sim_time == sub->step_time ? now : sub->last_sent + sub->min_interval;
            if (now < ready) {
                frame_unref(f);
                if (wait < 0 || ready - now < wait) wait = ready - now;
                break;
            }
            if (sub->last_seq[k] && f->hdr.seq > sub->last_seq[k] + 1) {
                uint64_t skipped = f->hdr.seq - sub->last_seq[k] - 1;
                atomic_fetch_add(&sub->s->frames_skipped, skipped);
                atomic_fetch_add(&ss->srv->counters.frames_skipped, skipped);
            }
            sub->last_seq[k] = f->hdr.seq;
            if (f->hdr.sim_time != sub->step_time) {
                sub->step_time = f->hdr.sim_time;
                sub->last_sent = now;
            }
            ss->rr = i + 1;
            ss->cur = f;
            ss->cur_off = 0;
            ss->cur_paused = f->hdr.seq <= sub->paused_seq[k];
            stream_ref(ss->cur_stream = sub->s);
            return true;
        }
    }
    if (wait >= 0) net_retry_later(net, ss, wait);
    return false;
}

/* Reads the connection's requests only while its queue is not backlogged: a client that asks
 * for more than it reads waits (TCP backpressure), and every reply it asked for is sent. */
static void net_rx_follow(struct session *ss)
{
    struct net_conn *c = net_conn_of(ss);
    bool pause = session_backlogged(ss);
    if (pause == c->rx_paused) return;
    c->rx_paused = pause;
    lws_rx_flow_control(c->wsi, !pause);
}

/* The first chunk p[0..n) of a frame computed before its stream paused, copied (the frame's
 * bytes are shared) with FXS_FLAG_BEFORE_PAUSE set, LWS_PRE bytes of room before it; free
 * from the returned pointer - LWS_PRE. NULL when out of memory. */
static uint8_t *net_paused_copy(const uint8_t *p, size_t n)
{
    uint8_t *c = malloc(LWS_PRE + n);
    if (!c) return NULL;
    memcpy(c + LWS_PRE, p, n);
    fxs_put_u32(c + LWS_PRE + 56, fxs_get_u32(p + 56) | FXS_FLAG_BEFORE_PAUSE);
    return c + LWS_PRE;
}

/* Sends the next chunk of the current frame as a fragment of one binary message. */
static int net_send_chunk(struct session *ss)
{
    struct frame *f = ss->cur;
    size_t left = f->len - ss->cur_off, n = left < NET_CHUNK ? left : NET_CHUNK;
    bool start = ss->cur_off == 0, end = n == left;
    uint8_t *p = f->bytes + ss->cur_off, saved[LWS_PRE], *copy = NULL;
    if (!start) memcpy(saved, p - LWS_PRE, LWS_PRE);
    else hist_observe(&ss->cur_stream->frame_age, (double)clock_wall_us() * 1e-6 - (double)f->hdr.server_time_us * 1e-6);
    if (start && ss->cur_paused && !(p = copy = net_paused_copy(p, n))) return -1;
    int w = lws_write(net_conn_of(ss)->wsi, p, n, (enum lws_write_protocol)lws_write_ws_flags(LWS_WRITE_BINARY, start, end));
    if (copy) free(copy - LWS_PRE);
    if (!start) memcpy(p - LWS_PRE, saved, LWS_PRE);
    if (w < (int)n) return -1;
    ss->cur_off += n;
    if (end) {
        atomic_fetch_add(&ss->cur_stream->frames_sent, 1);
        if (f->hdr.kind <= FXS_KIND_MAX) atomic_fetch_add(&ss->cur_stream->sent_by_kind[f->hdr.kind], 1);
        atomic_fetch_add(&ss->cur_stream->bytes_sent, f->len);
        atomic_fetch_add(&ss->srv->counters.frames_sent, 1);
        atomic_fetch_add(&ss->srv->counters.bytes_sent, f->len);
        frame_unref(f);
        stream_unref(ss->cur_stream);
        ss->cur = NULL;
        ss->cur_stream = NULL;
    }
    return 0;
}

static bool net_has_frame(struct session *ss)
{
    for (int i = 0; i < ss->nsubs; i++)
        for (int k = 1; k <= FXS_KIND_MAX; k++) {
            struct frame *f = hub_latest(&ss->srv->hub, ss->subs[i].s, ss->subs[i].form, k);
            bool fresh = f && f->hdr.seq > ss->subs[i].last_seq[k];
            frame_unref(f);
            if (fresh) return true;
        }
    return false;
}

/* Bytes written to the socket that the peer has not acknowledged yet (Linux SIOCOUTQ). */
static size_t net_unsent(struct lws *wsi)
{
    int n = 0;
    return ioctl(lws_get_socket_fd(wsi), SIOCOUTQ, &n) == 0 && n > 0 ? (size_t)n : 0;
}

/* Whether the connection holds max_buffered_bytes or more that the client has not read:
 * then no new frame starts (frames are skipped, latest frame wins), so a slow client's
 * latency stays about max_buffered_bytes / its read rate instead of the kernel's buffer. */
static bool net_backlogged(const struct net *net, struct session *ss)
{
    return lws_send_pipe_choked(net_conn_of(ss)->wsi) || net_unsent(net_conn_of(ss)->wsi) >= (size_t)net->srv->cfg.limits.max_buffered_bytes;
}

static int net_writable(struct net *net, struct session *ss)
{
    if (net->stopping) {
        lws_close_reason(net_conn_of(ss)->wsi, LWS_CLOSE_STATUS_GOINGAWAY, (uint8_t *)"server shutting down", 20);
        return -1;
    }
    if (ss->kill) {
        lws_close_reason(net_conn_of(ss)->wsi, LWS_CLOSE_STATUS_POLICY_VIOLATION, (uint8_t *)ss->kill, strlen(ss->kill));
        return -1;
    }
    if (wsguard_close_if_bad(net_conn_of(ss)->wsi)) return -1; /* an unmasked frame: 1002 */
    struct outmsg *m;
    if (ss->cur) {
        if (net_send_chunk(ss)) return -1;
    } else if ((m = session_pop(ss))) {
        int w = lws_write(net_conn_of(ss)->wsi, m->data + FRAME_HEADROOM, m->len, LWS_WRITE_TEXT);
        size_t len = m->len;
        free(m);
        if (w < (int)len) return -1;
        net_rx_follow(ss);
    } else if (net_has_frame(ss) && net_backlogged(net, ss)) {
        net_retry_later(net, ss, NET_BACKLOG_RETRY_S);
        return 0;
    } else if (net_pick_frame(net, ss)) {
        if (net_send_chunk(ss)) return -1;
    } else {
        return 0;
    }
    net_conn_of(ss)->last_write = clock_now();
    if (ss->cur || ss->q_head || net_has_frame(ss)) lws_callback_on_writable(net_conn_of(ss)->wsi);
    return 0;
}

/* ---- WebSocket: connection life ---- */

/* A header's value, or NULL when absent or longer than the buffer. */
static const char *net_header(struct lws *wsi, enum lws_token_indexes t, char *buf, int cap)
{
    int n = lws_hdr_total_length(wsi, t);
    if (n <= 0 || n >= cap || lws_hdr_copy(wsi, buf, cap, t) != n) return NULL;
    return buf;
}

static bool net_accept(struct net *net, struct lws *wsi)
{
    char uri[256] = "", origin[ACCESS_ORIGIN_MAX], host[ACCESS_ORIGIN_MAX];
    if (net->stopping) return false;
    if (!wsguard_upgrade_ok(wsi)) { /* the guard could not place its end (wsguard.h): frames unchecked */
        log_info("refused WebSocket: the handshake, or a request before it, is not one the masking guard follows");
        return false;
    }
    if (lws_hdr_copy(wsi, uri, sizeof uri, WSI_TOKEN_GET_URI) <= 0 || strcmp(uri, NET_WS_PATH) != 0) {
        log_info("refused WebSocket on \"%.64s\" (the endpoint is %s)", uri, NET_WS_PATH);
        return false;
    }
    char version[8] = "";
    if (lws_hdr_copy(wsi, version, sizeof version, WSI_TOKEN_VERSION) <= 0 || strcmp(version, "13") != 0) {
        /* RFC 6455 4.4: only version 13 exists; say so with 426 and the version we speak */
        uint8_t hdr[LWS_PRE + 256], *start = hdr + LWS_PRE, *p = start, *end = hdr + sizeof hdr - 1;
        log_info("refused WebSocket version \"%.7s\" (only 13)", version);
        if (!lws_add_http_header_status(wsi, 426, &p, end) &&
            !lws_add_http_header_by_name(wsi, (const uint8_t *)"sec-websocket-version:", (const uint8_t *)"13", 2, &p,
                                         end) &&
            !lws_add_http_header_content_length(wsi, 0, &p, end) && !lws_finalize_http_header(wsi, &p, end))
            lws_write(wsi, start, (size_t)(p - start), LWS_WRITE_HTTP_HEADERS);
        return false;
    }
    bool has_origin = lws_hdr_total_length(wsi, WSI_TOKEN_ORIGIN) > 0;
    const char *o = net_header(wsi, WSI_TOKEN_ORIGIN, origin, sizeof origin);
    const char *h = net_header(wsi, WSI_TOKEN_HOST, host, sizeof host);
    if (!access_host_ok(&net->srv->cfg.access, h)) {
        log_warn("refused WebSocket for host \"%.80s\" (no tokens: only loopback names and allowed_hosts)",
                 h ? h : "(none or too long)");
        return false;
    }
    if (has_origin && (!o || !access_origin_ok(&net->srv->cfg.access, o, h, lws_is_ssl(wsi)))) {
        log_warn("refused WebSocket from origin \"%.80s\" (not in allowed_origins)", o ? o : "(too long)");
        return false;
    }
    return true;
}

/* The role the handshake establishes: "Authorization: Bearer TOKEN", else the default.
 * *bad is set when a token was presented and matches none. */
static enum access_role net_role(struct net *net, struct lws *wsi, bool *bad)
{
    char auth[ACCESS_TOKEN_MAX + 16];
    const struct access *a = &net->srv->cfg.access;
    bool present = lws_hdr_total_length(wsi, WSI_TOKEN_HTTP_AUTHORIZATION) > 0;
    const char *v = net_header(wsi, WSI_TOKEN_HTTP_AUTHORIZATION, auth, sizeof auth);
    *bad = false;
    if (!present) return access_default_role(a);
    enum access_role r = v && !strncmp(v, "Bearer ", 7) ? access_lookup(a, v + 7, strlen(v + 7)) : ACCESS_NONE;
    *bad = r == ACCESS_NONE;
    return r;
}

/* A client that stops reading fills its socket; frames are then skipped (latest frame wins)
 * and after stall_timeout_s without a write the connection is closed, so it holds no
 * server memory beyond the socket's buffers and one chunk. Checked on every wake. */
static void net_check_stall(struct net *net, struct session *ss, double now)
{
    if (ss->kill || now - net_conn_of(ss)->last_write < net->srv->cfg.limits.stall_timeout_s || !net_backlogged(net, ss)) return;
    char peer[64] = "?", subs[256] = "";
    lws_get_peer_simple(net_conn_of(ss)->wsi, peer, sizeof peer);
    for (int i = 0; i < ss->nsubs; i++)
        snprintf(subs + strlen(subs), sizeof subs - strlen(subs), "%s%s", i ? ", " : "", ss->subs[i].s->name);
    log_warn("closing the connection from %s (subscribed to %s) that has not read for %d s", peer,
             ss->nsubs ? subs : "nothing", net->srv->cfg.limits.stall_timeout_s);
    atomic_fetch_add(&net->srv->counters.stalled_closed, 1);
    ss->kill = "not reading";
    lws_set_timeout(net_conn_of(ss)->wsi, PENDING_TIMEOUT_USER_OK, LWS_TO_KILL_ASYNC);
}

/* The engine published frames or errors, the cluster's follower queued changes, or a stop
 * was requested. */
static void net_on_wake(struct net *net)
{
    if (net->stop_requested && !net->stopping) {
        net->stopping = true;
        log_info("shutting down: closing %d connections", net->srv->nsessions);
    }
    replica_poll(net->srv, &(struct fx_err){0}); /* a failed reload is logged and retried */
    double now = clock_now();
    for (struct session *ss = net->srv->sessions; ss; ss = ss->next) {
        net_check_stall(net, ss, now);
        session_poll_errors(ss);
        if (net->stopping || ss->cur || ss->q_head || net_has_frame(ss)) lws_callback_on_writable(net_conn_of(ss)->wsi);
    }
}

static int net_established(struct net *net, struct session *ss, struct lws *wsi)
{
    bool bad;
    if (net->srv->nsessions >= net->srv->cfg.limits.max_connections) {
        log_warn("connection refused: limit of %d connections", net->srv->cfg.limits.max_connections);
        lws_close_reason(wsi, (enum lws_close_status)1013 /* try again later */, (uint8_t *)"connection limit reached", 24);
        return -1;
    }
    net_conn_of(ss)->wsi = wsi; /* before session_open: its hello wakes the connection */
    net_conn_of(ss)->last_write = clock_now();
    session_open(ss, net->srv, net_role(net, wsi, &bad));
    if (bad) {
        log_warn("connection closed: invalid token in its Authorization header");
        ss->kill = "invalid token in the Authorization header";
    }
    return 0;
}

static int net_ws_cb(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len)
{
    struct lws_context *ctx = lws_get_context(wsi);
    struct net *net = ctx ? lws_context_user(ctx) : NULL;
    struct session *ss = user;
    switch (reason) {
    case LWS_CALLBACK_FILTER_PROTOCOL_CONNECTION:
        return net_accept(net, wsi) ? 0 : 1;
    case LWS_CALLBACK_ESTABLISHED:
        net_pending_drop(net, wsi);
        if (wsguard_close_if_bad(wsi)) return -1; /* an unmasked frame came with the handshake */
        return net_established(net, ss, wsi);
    case LWS_CALLBACK_WS_PEER_INITIATED_CLOSE: {
        const char *why;
        int code = wsguard_close_status(in, len, &why);
        net_conn_of(ss)->peer_closed = true;
        if (!code) return 0; /* lws echoes it */
        lws_close_reason(wsi, (enum lws_close_status)code, (uint8_t *)why, strlen(why));
        return -1;
    }
    case LWS_CALLBACK_RECEIVE: /* other daemons' changes first: the request is checked against them */
        if (net_conn_of(ss)->peer_closed) break;
        replica_poll(net->srv, &(struct fx_err){0});
        session_receive(ss, in, len, lws_is_final_fragment(wsi), lws_frame_is_binary(wsi));
        net_rx_follow(ss);
        break;
    case LWS_CALLBACK_SERVER_WRITEABLE:
        return net_writable(net, ss);
    case LWS_CALLBACK_CLOSED:
        if (ss && ss->srv) {
            net_retry_unlink(net, net_conn_of(ss));
            session_close(ss);
        }
        break;
    case LWS_CALLBACK_EVENT_WAIT_CANCELLED:
        if (net) net_on_wake(net);
        break;
    default:
        break;
    }
    return 0;
}

/* ---- set-up and loop ---- */

static void net_lws_log(int level, const char *line)
{
    size_t n = strlen(line);
    while (n && (line[n - 1] == '\n' || line[n - 1] == '\r')) n--;
    log_msg(level == LLL_ERR ? LOG_ERROR : LOG_WARN, "lws: %.*s", (int)n, line);
}

void net_notify(void *ctx)
{
    struct net *net = ctx;
    lws_cancel_service(net->ctx);
}

/* Every path goes to net_http_cb: /healthz, /metrics and the web root's files (served only
 * when they resolve inside the root: net_static_path). */
static void net_setup_mounts(struct net *net)
{
    struct lws_http_mount *m = &net->mount;
    m->mountpoint = "/";
    m->mountpoint_len = 1;
    m->origin = "http";
    m->origin_protocol = LWSMPRO_CALLBACK;
    if (!net->srv->cfg.web_root[0] || !realpath(net->srv->cfg.web_root, net->web_root)) net->web_root[0] = 0;
}

int net_open(struct net **out, struct server *srv, struct fx_err *err)
{
    struct net *net = calloc(1, sizeof *net);
    if (!net) return fx_fail(err, "internal", NULL, "out of memory");
    net->srv = srv;
    net->protocols[0] = (struct lws_protocols){"http", net_http_cb, sizeof(struct net_http), 0, 0, NULL, 0};
    net->protocols[1] = (struct lws_protocols){"fxstream.v1", net_ws_cb, sizeof(struct net_conn),
                                               (size_t)srv->cfg.limits.max_message_bytes + 1024, 0, NULL, 0};
    net_setup_mounts(net);
    lws_set_log_level(LLL_ERR | LLL_WARN, net_lws_log);

    struct lws_context_creation_info info;
    memset(&info, 0, sizeof info);
    /* VALIDATE_UTF8: a text frame that is not UTF-8 closes the connection with 1007 (RFC 6455 8.1) */
    info.options = LWS_SERVER_OPTION_EXPLICIT_VHOSTS | LWS_SERVER_OPTION_DISABLE_IPV6 | LWS_SERVER_OPTION_VALIDATE_UTF8;
    if (srv->cfg.tls_cert[0]) info.options |= LWS_SERVER_OPTION_DO_SSL_GLOBAL_INIT;
    info.user = net;
    /* fds: the sessions, the connections still before their first request, and a margin */
    info.fd_limit_per_thread = (unsigned)srv->cfg.limits.max_connections + NET_PENDING_MAX + 64;
    net->ctx = lws_create_context(&info);
    if (!net->ctx) {
        free(net);
        return fx_fail(err, "internal", NULL, "cannot create the libwebsockets context");
    }
    info.port = srv->cfg.port; /* 0: the kernel picks a free port */
    info.iface = srv->cfg.listen;
    info.protocols = net->protocols;
    info.mounts = &net->mount;
    info.vhost_name = "default";
    if (srv->cfg.tls_cert[0]) { /* TLS only: a plain-text connection fails its handshake */
        info.ssl_cert_filepath = srv->cfg.tls_cert;
        info.ssl_private_key_filepath = srv->cfg.tls_key;
        info.alpn = "http/1.1"; /* not h2: the masking guard follows HTTP/1.1 handshakes only */
    }
    net->vh = lws_create_vhost(net->ctx, &info);
    if (!net->vh) {
        lws_context_destroy(net->ctx);
        free(net);
        return fx_fail(err, "internal", NULL, "cannot listen on %s:%d (address in use or not local%s?)",
                       srv->cfg.listen, srv->cfg.port, srv->cfg.tls_cert[0] ? ", or a bad TLS certificate or key" : "");
    }
    srv->wake = net_wake;
    srv->hub.notify = net_notify;
    srv->hub.notify_ctx = net;
    *out = net;
    return 0;
}

int net_port(const struct net *net) { return lws_get_vhost_listen_port(net->vh); }

void net_request_stop(struct net *net)
{
    net->stop_requested = 1;
    lws_cancel_service(net->ctx);
}

void net_run(struct net *net)
{
    double deadline = 0;
    wsguard_start(net->srv->cfg.tls_cert[0] != 0);
    for (;;) {
        if (lws_service(net->ctx, 0) < 0) break;
        if (!net->stopping) continue;
        if (deadline == 0) deadline = clock_now() + NET_SHUTDOWN_GRACE_S;
        if (net->srv->nsessions == 0 || clock_now() > deadline) break;
    }
}

void net_close(struct net *net)
{
    if (!net) return;
    net->srv->hub.notify = NULL;
    lws_sul_cancel(&net->retry_sul);
    lws_context_destroy(net->ctx);
    wsguard_stop();
    net->srv->wake = NULL;
    free(net);
}
