/* fxpool.c — see fxpool.h: many fxstream.v1 client connections on one lws context.
 *
 * Owns the context, every struct fxp_conn (a doubly linked list, so closing is O(1)),
 * the parsed targets (one per distinct URL, shared by its connections), and the list
 * of connections whose end is still to be reported.
 *
 * Shape: lws callbacks record what happened and run the caller's message callbacks
 * directly; ends of connections are queued and reported from fxp_service() after
 * lws_service() returns, because lws may report a failed connect from inside
 * lws_client_connect_via_info() and because the wsi must be gone before the conn is
 * freed. As in fxclient.c, a self-re-arming timer (sul) bounds each poll wait, since
 * lws_service() ignores its timeout argument. */
#include "fxpool.h"
#include "fxclient.h"
#include "fxws.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>

#include <netdb.h>
#include <libwebsockets.h>

#define FXP_FD_SLACK 64
#define FXP_KEEP_HEADER 256           /* bytes of a message kept when payloads are off */
#define FXP_RX_KEEP_CAP (64 * 1024)   /* a bigger reassembly buffer is freed after use */
#define FXP_RX_CHUNK (16 * 1024)      /* lws's per-connection receive buffer */
#define FXP_REARM_US 1000

struct fxp_target {
    struct fxp_target *next;
    char *url;
    struct fxws_url u;
    int probed, probe_errno; /* fxws_probe_errno done once per target */
};

#define FXP_CONN_MAGIC 0x66787063u /* "fxpc": tells our conns from other user pointers */

struct fxp_conn {
    uint32_t magic;
    struct fxp_pool *pool;
    struct fxp_target *target;
    struct lws *wsi;
    void *user;
    struct fxp_conn *prev, *next;  /* pool->conns */
    struct fxp_conn *next_ended;   /* pool->ended */
    struct fxws_rx rx;
    struct fxws_outq out;
    unsigned tcp_up : 1, established : 1, hello : 1, closing : 1, ended : 1, by_client : 1;
    int close_code;
    char why[200];
};

struct fxp_pool {
    struct lws_context *ctx;
    struct lws_protocols protocols[2];
    lws_sorted_usec_list_t tick;
    struct fxp_callbacks cb;
    struct fxp_options o;
    struct fxp_target *targets;
    struct fxp_conn *conns;
    struct fxp_conn *ended, *ended_tail;
    int live;
    int destroying;
    struct fxp_stats stats;
};

/* ---- connection end ----------------------------------------------------------- */

/* Marks c ended (once) and queues the report for fxp_service. */
static void fxp_mark_ended(struct fxp_conn *c, const char *why_if_none)
{
    struct fxp_pool *p = c->pool;
    if (c->ended) return;
    c->ended = 1;
    c->wsi = NULL;
    if (!c->why[0]) fxws_set_err(c->why, sizeof c->why, "%s", why_if_none);
    c->next_ended = NULL;
    if (p->ended_tail) p->ended_tail->next_ended = c;
    else p->ended = c;
    p->ended_tail = c;
}

static void fxp_conn_free(struct fxp_conn *c)
{
    struct fxp_pool *p = c->pool;
    if (c->prev) c->prev->next = c->next;
    else p->conns = c->next;
    if (c->next) c->next->prev = c->prev;
    fxws_outq_free(&c->out);
    fxws_rx_free(&c->rx);
    p->live--;
    c->magic = 0;
    free(c);
}

static void fxp_deliver_ended(struct fxp_pool *p)
{
    while (p->ended) {
        struct fxp_conn *c = p->ended;
        struct fxp_close_info info = { c->close_code, c->why, c->established, c->hello, c->by_client };
        p->ended = c->next_ended;
        if (!p->ended) p->ended_tail = NULL;
        p->stats.closed++;
        if (p->cb.on_close) p->cb.on_close(c, &info, c->user);
        fxp_conn_free(c);
    }
}

/* ---- receiving ------------------------------------------------------------------ */

static void fxp_on_message(struct fxp_conn *c)
{
    struct fxp_pool *p = c->pool;
    uint64_t now = (uint64_t)fxws_now_us(CLOCK_REALTIME);
    if (c->rx.binary) {
        struct fxs_header h;
        /* fxs_header_unpack reads only the first 64 bytes and checks them against the
           message length, so a kept prefix with the true total length is enough. */
        if (fxs_header_unpack(c->rx.buf, c->rx.total, &h)) {
            p->stats.bad_messages++;
        } else {
            p->stats.frames++;
            p->stats.frame_bytes += c->rx.total;
            if (p->cb.on_frame)
                p->cb.on_frame(c, &h, p->o.payloads ? c->rx.buf + h.header_bytes : NULL, c->rx.total, now, c->user);
        }
    } else {
        cJSON *j = p->o.payloads || c->rx.len == c->rx.total
                       ? cJSON_ParseWithLength((const char *)c->rx.buf, c->rx.len) : NULL;
        const cJSON *op = cJSON_GetObjectItemCaseSensitive(j, "op");
        p->stats.texts++;
        if (!cJSON_IsObject(j) || !cJSON_IsString(op)) {
            p->stats.bad_messages++;
        } else if (!c->hello && !strcmp(op->valuestring, "hello")) {
            c->hello = 1;
            if (p->cb.on_open) p->cb.on_open(c, j, c->user);
        } else if (p->cb.on_text) {
            p->cb.on_text(c, j, now, c->user);
        }
        cJSON_Delete(j);
    }
    if (c->rx.cap > FXP_RX_KEEP_CAP) fxws_rx_free(&c->rx);
}

static int fxp_on_receive(struct fxp_conn *c, struct lws *wsi, const void *in, size_t len)
{
    /* Text (control) messages are always kept whole: they are small and parsed. */
    size_t keep = c->pool->o.payloads || (c->rx.active ? !c->rx.binary : !lws_frame_is_binary(wsi))
                      ? SIZE_MAX : FXP_KEEP_HEADER;
    int r = fxws_rx_append(&c->rx, wsi, in, len, c->pool->o.max_message_bytes, keep, c->why, sizeof c->why);
    if (r == -1) lws_close_reason(wsi, LWS_CLOSE_STATUS_MESSAGE_TOO_LARGE, NULL, 0);
    if (r < 0) return -1;
    if (r == 1 && !c->closing) fxp_on_message(c);
    return 0;
}

/* ---- lws callbacks -------------------------------------------------------------- */

static void fxp_on_connect_error(struct fxp_conn *c, const char *why)
{
    struct fxp_target *t = c->target;
    const char *w = why ? why : "unknown error";
    int e = 0;
    if (c->why[0]) return; /* our own filter explained it already */
    if (c->by_client) {
        fxws_set_err(c->why, sizeof c->why, "closed by the client");
        return;
    }
    if (fxws_connect_needs_probe(c->tcp_up, w)) {
        if (!t->probed) { /* at most one blocking probe per target, not one per connection */
            t->probe_errno = fxws_probe_errno(&t->u);
            t->probed = 1;
        }
        e = t->probe_errno;
    }
    fxws_connect_error(&t->u, c->tcp_up, w, e, c->why, sizeof c->why);
}

static int fxp_lws_cb(struct lws *wsi, enum lws_callback_reasons reason, void *user, void *in, size_t len)
{
    struct fxp_conn *c = user ? user : (wsi ? lws_get_opaque_user_data(wsi) : NULL);
    if (!c || c->magic != FXP_CONN_MAGIC || c->pool->destroying) return 0;
    switch (reason) {
    case LWS_CALLBACK_CLIENT_CONNECTION_ERROR:
        fxp_on_connect_error(c, in);
        fxp_mark_ended(c, "connect failed");
        return 0;
    case LWS_CALLBACK_CLIENT_APPEND_HANDSHAKE_HEADER:
        c->tcp_up = 1;
        return fxws_append_auth(wsi, in, len, c->pool->o.token);
    case LWS_CALLBACK_CLIENT_FILTER_PRE_ESTABLISH:
        return fxws_check_subprotocol(&c->target->u, wsi, c->why, sizeof c->why);
    case LWS_CALLBACK_CLIENT_ESTABLISHED:
        c->established = 1;
        c->target->probed = 0;
        c->pool->stats.established++;
        if (c->closing) lws_callback_on_writable(wsi);
        else if (c->out.head) lws_callback_on_writable(wsi);
        return 0;
    case LWS_CALLBACK_CLIENT_RECEIVE:
        return fxp_on_receive(c, wsi, in, len);
    case LWS_CALLBACK_CLIENT_WRITEABLE:
        if (c->closing) return -1; /* lws_close_reason was set: lws sends the close frame */
        return fxws_outq_write(&c->out, wsi, c->why, sizeof c->why);
    case LWS_CALLBACK_WS_PEER_INITIATED_CLOSE:
        if (!c->closing)
            fxws_peer_close(in, len, &c->close_code, c->why, sizeof c->why, NULL, 0);
        return 0;
    case LWS_CALLBACK_CLIENT_CLOSED:
        if (c->wsi == wsi || !c->wsi) {
            char lost[300];
            snprintf(lost, sizeof lost, "connection to %s:%d lost", c->target->u.host, c->target->u.port);
            fxp_mark_ended(c, c->by_client ? "closed by the client" : lost);
        }
        return 0;
    case LWS_CALLBACK_WSI_DESTROY:
        /* Safety net: every wsi of ours ends in one of the two callbacks above. */
        if (c->wsi == wsi) fxp_mark_ended(c, "connection closed");
        return 0;
    default:
        return 0;
    }
}

/* ---- pool ----------------------------------------------------------------------- */

static void fxp_tick_cb(lws_sorted_usec_list_t *sul)
{
    struct fxp_pool *p = lws_container_of(sul, struct fxp_pool, tick);
    lws_sul_schedule(p->ctx, 0, &p->tick, fxp_tick_cb, FXP_REARM_US);
}

static int fxp_raise_fd_limit(int need, char *eb, size_t el)
{
    struct rlimit rl;
    if (getrlimit(RLIMIT_NOFILE, &rl)) {
        fxws_set_err(eb, el, "cannot read the file descriptor limit: %s", strerror(errno));
        return -1;
    }
    if (rl.rlim_cur != RLIM_INFINITY && rl.rlim_cur >= (rlim_t)need) return 0;
    if (rl.rlim_max != RLIM_INFINITY && rl.rlim_max < (rlim_t)need) {
        fxws_set_err(eb, el,
                    "%d connections need %d file descriptors but the hard limit is %llu "
                    "(raise it, e.g. ulimit -Hn or LimitNOFILE=)",
                    need - FXP_FD_SLACK, need, (unsigned long long)rl.rlim_max);
        return -1;
    }
    rl.rlim_cur = (rlim_t)need;
    if (setrlimit(RLIMIT_NOFILE, &rl)) {
        fxws_set_err(eb, el, "cannot raise the file descriptor limit to %d: %s", need, strerror(errno));
        return -1;
    }
    return 0;
}

int fxp_pool_create(struct fxp_pool **out, const struct fxp_callbacks *cb, const struct fxp_options *o,
                    char *eb, size_t el)
{
    struct lws_context_creation_info info;
    struct fxp_pool *p;
    int need;
    *out = NULL;
    if (!o || o->max_connections < 1 || o->max_connections > FXP_MAX_CONNECTIONS) {
        fxws_set_err(eb, el, "max_connections must be 1..%d", FXP_MAX_CONNECTIONS);
        return -1;
    }
    need = o->max_connections + FXP_FD_SLACK;
    if (fxp_raise_fd_limit(need, eb, el)) return -1;
    if (!(p = calloc(1, sizeof *p))) {
        fxws_set_err(eb, el, "out of memory");
        return -1;
    }
    if (cb) p->cb = *cb;
    p->o = *o;
    if (!p->o.max_message_bytes) p->o.max_message_bytes = FXC_MAX_MESSAGE_BYTES;
    p->protocols[0] = (struct lws_protocols){ .name = FXWS_SUBPROTOCOL, .callback = fxp_lws_cb,
                                              .rx_buffer_size = FXP_RX_CHUNK };
    memset(&info, 0, sizeof info);
    info.port = CONTEXT_PORT_NO_LISTEN;
    info.protocols = p->protocols;
    info.gid = (gid_t)-1;
    info.uid = (uid_t)-1;
    info.fd_limit_per_thread = (unsigned)need;
    info.pt_serv_buf_size = FXWS_READ_BUF;
    info.user = p;
    fxws_tls_context(&info, o->ca_file); /* any target may be wss:// */
    fxws_log_default();
    if (!(p->ctx = lws_create_context(&info))) {
        free(p);
        fxws_set_err(eb, el, "cannot create a libwebsockets context for %d connections", o->max_connections);
        return -1;
    }
    *out = p;
    return 0;
}

/* The parsed target of url, created on first use. */
static struct fxp_target *fxp_target(struct fxp_pool *p, const char *url, int *rc, char *eb, size_t el)
{
    struct fxp_target *t;
    struct addrinfo *ai;
    for (t = p->targets; t; t = t->next)
        if (!strcmp(t->url, url)) return t;
    if (!(t = calloc(1, sizeof *t)) || !(t->url = strdup(url))) {
        free(t);
        fxws_set_err(eb, el, "out of memory");
        *rc = -1;
        return NULL;
    }
    if (fxws_url_parse(&t->u, url, eb, el)) {
        *rc = -2;
    } else if (!(ai = fxws_resolve(&t->u, eb, el))) {
        *rc = -1;
    } else {
        freeaddrinfo(ai);
        t->next = p->targets;
        p->targets = t;
        return t;
    }
    free(t->url);
    free(t);
    return NULL;
}

int fxp_connect(struct fxp_pool *p, const char *url, void *user, struct fxp_conn **out, char *eb, size_t el)
{
    struct lws_client_connect_info ci;
    struct fxp_target *t;
    struct fxp_conn *c;
    int rc = -1;
    if (out) *out = NULL;
    if (!url) {
        fxws_set_err(eb, el, "bad URL: none given");
        return -2;
    }
    if (!(t = fxp_target(p, url, &rc, eb, el))) return rc;
    if (p->live >= p->o.max_connections) {
        fxws_set_err(eb, el, "connection limit of the pool reached (%d open)", p->o.max_connections);
        return -1;
    }
    if (!(c = calloc(1, sizeof *c))) {
        fxws_set_err(eb, el, "out of memory");
        return -1;
    }
    c->magic = FXP_CONN_MAGIC;
    c->pool = p;
    c->target = t;
    c->user = user;
    c->next = p->conns;
    if (p->conns) p->conns->prev = c;
    p->conns = c;
    p->live++;
    p->stats.connects++;
    fxws_connect_info(&ci, p->ctx, &t->u);
    ci.userdata = c;
    ci.opaque_user_data = c;
    ci.pwsi = &c->wsi;
    if (!lws_client_connect_via_info(&ci)) {
        /* lws may have called CONNECTION_ERROR already; either way report it later */
        if (!c->ended) {
            if (!c->why[0]) fxp_on_connect_error(c, "connect failed");
            fxp_mark_ended(c, "connect failed");
        }
    }
    if (out) *out = c;
    return 0;
}

int fxp_send_text(struct fxp_conn *c, const char *text, size_t len)
{
    if (c->ended || c->closing || c->out.n >= FXP_MAX_QUEUED || fxws_outq_push(&c->out, text, len)) return -1;
    if (c->established && c->wsi) lws_callback_on_writable(c->wsi);
    return 0;
}

int fxp_send_json(struct fxp_conn *c, const cJSON *msg)
{
    char *text = cJSON_PrintUnformatted(msg);
    int r = text ? fxp_send_text(c, text, strlen(text)) : -1;
    free(text);
    return r;
}

void fxp_close(struct fxp_conn *c)
{
    if (c->ended || c->closing) return;
    c->closing = 1;
    c->by_client = 1;
    if (!c->wsi) return;
    if (c->established) {
        lws_close_reason(c->wsi, LWS_CLOSE_STATUS_NORMAL, NULL, 0);
        lws_callback_on_writable(c->wsi); /* the writeable callback returns -1: lws sends the close */
    } else {
        lws_set_timeout(c->wsi, PENDING_TIMEOUT_CLOSE_SEND, LWS_TO_KILL_ASYNC);
    }
}

int fxp_service(struct fxp_pool *p, int timeout_ms)
{
    int r = 0;
    fxp_deliver_ended(p); /* connects that failed inside fxp_connect */
    lws_sul_schedule(p->ctx, 0, &p->tick, fxp_tick_cb, timeout_ms > 0 ? (lws_usec_t)timeout_ms * 1000 : 1);
    if (lws_service(p->ctx, 0) < 0) r = -1;
    fxp_deliver_ended(p);
    return r;
}

int fxp_live(const struct fxp_pool *p) { return p->live; }
void *fxp_conn_user(const struct fxp_conn *c) { return c->user; }
void fxp_conn_set_user(struct fxp_conn *c, void *user) { c->user = user; }
struct fxp_pool *fxp_conn_pool(const struct fxp_conn *c) { return c->pool; }
void fxp_stats(const struct fxp_pool *p, struct fxp_stats *out) { *out = p->stats; }

void fxp_pool_destroy(struct fxp_pool *p)
{
    if (!p) return;
    p->destroying = 1;
    lws_sul_cancel(&p->tick);
    lws_context_destroy(p->ctx);
    while (p->conns) fxp_conn_free(p->conns);
    while (p->targets) {
        struct fxp_target *t = p->targets;
        p->targets = t->next;
        free(t->url);
        free(t);
    }
    free(p);
}

/* ---- latency histogram ------------------------------------------------------------ */

#define FXP_HIST_SUB (1u << FXP_HIST_SUB_BITS)

static unsigned fxp_hist_index(uint64_t v)
{
    int msb, s;
    if (v > FXP_HIST_MAX_US) v = FXP_HIST_MAX_US;
    if (v < 2 * FXP_HIST_SUB) return (unsigned)v;
    msb = 63 - __builtin_clzll(v);
    s = msb - FXP_HIST_SUB_BITS;
    return (unsigned)s * FXP_HIST_SUB + (unsigned)(v >> s);
}

/* Lowest value and width of bucket i. */
static void fxp_hist_bucket(unsigned i, uint64_t *lo, uint64_t *width)
{
    unsigned s;
    if (i < 2 * FXP_HIST_SUB) {
        *lo = i;
        *width = 1;
        return;
    }
    s = i / FXP_HIST_SUB - 1;
    *lo = (uint64_t)(i - s * FXP_HIST_SUB) << s;
    *width = (uint64_t)1 << s;
}

void fxp_hist_reset(struct fxp_hist *h) { memset(h, 0, sizeof *h); }

void fxp_hist_add(struct fxp_hist *h, int64_t us)
{
    uint64_t v = us < 0 ? 0 : (uint64_t)us;
    if (v > FXP_HIST_MAX_US) h->clamped++;
    h->bucket[fxp_hist_index(v)]++;
    if (!h->count || v < h->min_us) h->min_us = v;
    if (v > h->max_us) h->max_us = v;
    h->count++;
    h->sum_us += (double)v;
}

void fxp_hist_merge(struct fxp_hist *dst, const struct fxp_hist *src)
{
    if (!src->count) return;
    if (!dst->count || src->min_us < dst->min_us) dst->min_us = src->min_us;
    if (src->max_us > dst->max_us) dst->max_us = src->max_us;
    dst->count += src->count;
    dst->sum_us += src->sum_us;
    dst->clamped += src->clamped;
    for (unsigned i = 0; i < FXP_HIST_BUCKETS; i++) dst->bucket[i] += src->bucket[i];
}

double fxp_hist_quantile(const struct fxp_hist *h, double q)
{
    uint64_t rank, seen = 0, lo, width;
    double v;
    if (!h->count) return 0;
    if (q >= 1) return (double)h->max_us;
    if (q <= 0) return (double)h->min_us;
    rank = (uint64_t)(q * (double)h->count);
    if ((double)rank < q * (double)h->count) rank++;
    if (rank < 1) rank = 1;
    for (unsigned i = 0; i < FXP_HIST_BUCKETS; i++) {
        seen += h->bucket[i];
        if (seen < rank) continue;
        fxp_hist_bucket(i, &lo, &width);
        v = width == 1 ? (double)lo : (double)lo + (double)(width - 1) / 2.0;
        if (v < (double)h->min_us) v = (double)h->min_us;
        if (v > (double)h->max_us) v = (double)h->max_us;
        return v;
    }
    return (double)h->max_us;
}
