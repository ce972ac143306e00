/* relay.c — see relay.h. */
#include <errno.h>
#include <math.h>
#include <poll.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <hiredis/hiredis.h>

#include "clock.h"
#include "cluster.h"
#include "log.h"
#include "relay.h"

#define RELAY_BACKOFF_MIN_S 0.1
#define RELAY_BACKOFF_MAX_S 1.0

/* A stream whose channel this daemon is subscribed to, and how its frames are numbered here:
 * each kind's numbers go on increasing from the newest frame the hub had when the subscription
 * started (sessions send only frames newer than their last), shifted up when an owner numbers
 * from lower down (after a Redis that lost its data, the latest frames are gone with it). The
 * encodings of one frame share its number (and so one shift); each counts its own last. */
struct relay_sub {
    char name[STREAM_NAME_MAX];
    uint64_t last[FXS_ENCODING_COUNT][FXS_KIND_MAX + 1], shift[FXS_KIND_MAX + 1];
};

struct relay {
    struct server *srv;
    const struct cluster_config *cfg;
    char prefix[48]; /* fxs:frames:DB: */
    pthread_t thread;
    bool started;
    int stop_fd;
    atomic_bool stopping;
    struct histogram latency;

    /* The relay thread's. */
    redisContext *sub, *get;
    struct relay_sub *subs;
    int nsubs;
};

/* ---- frames into the hub ---- */

/* A frame of `s` as its owner sent it: re-headed with this daemon's channel and numbering
 * (struct relay_sub), into the hub. */
static void relay_deliver(struct relay *r, struct relay_sub *sub, struct stream *s, const uint8_t *bytes, size_t len,
                          bool latest)
{
    struct fxs_header h;
    if (fxs_header_unpack(bytes, len, &h) || h.kind < 1 || h.kind > FXS_KIND_MAX || h.seq >= CLUSTER_SEQ_MAX) {
        cluster_bad(r->srv->cluster, CLUSTER_BAD_FRAME, "a frame of stream %s in %s (%zu bytes) does not read as one, "
                    "or its number is out of range: skipped", s->name, r->cfg->url, len);
        return;
    }
    uint64_t *last = &sub->last[fxs_frame_encoding(h.kind, h.codec)][h.kind];
    if (h.seq + sub->shift[h.kind] <= *last) {
        if (latest) return; /* the hub has it, or newer */
        sub->shift[h.kind] = *last + 1 - h.seq;
    }
    h.seq += sub->shift[h.kind];
    *last = h.seq;
    h.channel = s->channel;
    struct frame *f = frame_new(&h, fxs_header_total(bytes), bytes + h.header_bytes, h.payload_bytes);
    if (!f) return;
    if (h.kind == FXS_KIND_PARTICLES) atomic_store(&s->particles, h.count_or_width);
    if (!latest) {
        double age = ((double)clock_wall_us() - (double)h.server_time_us) * 1e-6;
        hist_observe(&r->latency, fmax(age, 0.0));
        atomic_fetch_add(&r->srv->counters.cluster_frames_relayed, 1);
    }
    hub_publish(&r->srv->hub, s, budget_form(fxs_frame_encoding(h.kind, h.codec), 0), f, false);
}

/* Whether frames of s should come through Redis: subscribers here, computed elsewhere. */
static bool relay_wanted(struct relay *r, struct stream *s)
{
    struct stream_status st;
    hub_status(&r->srv->hub, s, &st);
    return st.subscribers > 0 && !st.lease.owned;
}

static struct relay_sub *relay_find(struct relay *r, const char *name)
{
    for (int i = 0; i < r->nsubs; i++)
        if (!strcmp(r->subs[i].name, name)) return &r->subs[i];
    return NULL;
}

static void relay_on_message(struct relay *r, const redisReply *m)
{
    if (m->type != REDIS_REPLY_ARRAY || m->elements != 3 || m->element[0]->type != REDIS_REPLY_STRING ||
        strcmp(m->element[0]->str, "message") || m->element[1]->type != REDIS_REPLY_STRING ||
        m->element[2]->type != REDIS_REPLY_STRING)
        return;
    const char *channel = m->element[1]->str;
    size_t np = strlen(r->prefix);
    struct relay_sub *sub = strncmp(channel, r->prefix, np) ? NULL : relay_find(r, channel + np);
    struct stream *s = sub ? hub_find(&r->srv->hub, sub->name) : NULL;
    if (s && relay_wanted(r, s))
        relay_deliver(r, sub, s, (const uint8_t *)m->element[2]->str, m->element[2]->len, false);
    stream_unref(s);
}

/* A stream just subscribed to: its numbering starts above the hub's frames, and its latest
 * frames come from Redis (on the `get` connection, made again when Redis closed it while idle). */
static int relay_fetch_latest(struct relay *r, struct relay_sub *sub, struct stream *s)
{
    if (cluster_closed(r->get)) {
        char why[256];
        redisFree(r->get);
        if (!(r->get = cluster_dial(r->srv->cluster, why, sizeof why))) return -1;
    }
    for (int k = 1; k <= FXS_KIND_MAX; k++)
        for (int e = 0; e < FXS_ENCODING_COUNT; e++) sub->last[e][k] = hub_latest_seq(&r->srv->hub, s, k);
    for (int k = 1; k <= FXS_KIND_MAX; k++) {
        uint64_t newest_default = 0;
        for (int e = 0; e < (fxs_kind_has_engine_form(k) ? FXS_ENCODING_COUNT : 1); e++) {
            redisReply *q = redisCommand(r->get, "GET " CLUSTER_KEY "frame:%s:%d%s", sub->name, k,
                                         e == FXS_ENCODING_ENGINE ? ":engine" : "");
            if (!q) return -1;
            uint64_t seq = q->type == REDIS_REPLY_STRING && q->len >= FXS_HEADER_BYTES ? fxs_get_u64((const uint8_t *)q->str + 16) : 0;
            if (e == FXS_ENCODING_DEFAULT) newest_default = seq;
            if (seq && seq >= newest_default) relay_deliver(r, sub, s, (const uint8_t *)q->str, q->len, true);
            freeReplyObject(q);
        }
    }
    return 0;
}

/* ---- the subscriptions ---- */

static int relay_send(struct relay *r, const char *cmd, const char *name)
{
    int done = 0;
    if (redisAppendCommand(r->sub, "%s %s%s", cmd, r->prefix, name) != REDIS_OK) return -1;
    while (!done)
        if (redisBufferWrite(r->sub, &done) != REDIS_OK) return -1;
    return 0;
}

/* Makes the subscriptions the hub's streams call for; -1 when a connection failed. */
static int relay_follow_hub(struct relay *r)
{
    for (int i = 0; i < r->nsubs;) {
        struct stream *s = hub_find(&r->srv->hub, r->subs[i].name);
        bool keep = s && relay_wanted(r, s);
        stream_unref(s);
        if (keep) {
            i++;
            continue;
        }
        if (relay_send(r, "UNSUBSCRIBE", r->subs[i].name)) return -1;
        r->subs[i] = r->subs[--r->nsubs];
    }
    int n;
    struct stream **ss = hub_snapshot(&r->srv->hub, &n);
    int rc = 0;
    for (int j = 0; j < n && !rc; j++) {
        bool have = false;
        for (int i = 0; i < r->nsubs && !have; i++) have = !strcmp(r->subs[i].name, ss[j]->name);
        if (have || !relay_wanted(r, ss[j])) continue;
        struct relay_sub *p = realloc(r->subs, (size_t)(r->nsubs + 1) * sizeof *p);
        if (!p) break;
        r->subs = p;
        struct relay_sub *sub = &p[r->nsubs++];
        *sub = (struct relay_sub){0};
        snprintf(sub->name, sizeof sub->name, "%s", ss[j]->name);
        rc = relay_send(r, "SUBSCRIBE", ss[j]->name) || relay_fetch_latest(r, sub, ss[j]) ? -1 : 0;
    }
    hub_release_all(ss, n);
    return rc;
}

/* Reads what the subscription brought; -1 when the connection failed. */
static int relay_read(struct relay *r)
{
    struct pollfd p[2] = {{.fd = r->sub->fd, .events = POLLIN}, {.fd = r->stop_fd, .events = POLLIN}};
    int n = poll(p, 2, (int)(RELAY_POLL_S * 1000));
    if (n < 0) return errno == EINTR ? 0 : -1;
    if (n == 0 || !(p[0].revents & (POLLIN | POLLHUP | POLLERR))) return 0;
    if (redisBufferRead(r->sub) != REDIS_OK) return -1;
    void *m = NULL;
    while (redisGetReplyFromReader(r->sub, &m) == REDIS_OK && m) {
        relay_on_message(r, m);
        freeReplyObject(m);
        m = NULL;
    }
    return r->sub->err ? -1 : 0;
}

static void relay_disconnect(struct relay *r)
{
    redisFree(r->sub);
    redisFree(r->get);
    r->sub = r->get = NULL;
    r->nsubs = 0;
}

static void *relay_main(void *arg)
{
    struct relay *r = arg;
    double backoff = RELAY_BACKOFF_MIN_S, followed_at = 0;
    while (!atomic_load(&r->stopping)) {
        char why[256] = "";
        if (!r->sub && (!(r->sub = cluster_dial(r->srv->cluster, why, sizeof why)) ||
                        !(r->get = cluster_dial(r->srv->cluster, why, sizeof why)))) {
            relay_disconnect(r);
            log_debug("cluster: relay cannot reach %s: %s", r->cfg->url, why);
            struct pollfd p = {.fd = r->stop_fd, .events = POLLIN};
            poll(&p, 1, (int)(backoff * 1000));
            backoff = fmin(2 * backoff, RELAY_BACKOFF_MAX_S);
            continue;
        }
        backoff = RELAY_BACKOFF_MIN_S;
        bool due = clock_now() >= followed_at + RELAY_POLL_S; /* not after every batch of frames */
        if (due) followed_at = clock_now();
        if ((due && relay_follow_hub(r)) || relay_read(r)) { /* idle, Redis's timeout or CLIENT KILL may close it */
            log_msg(r->nsubs ? LOG_WARN : LOG_INFO, "cluster: relay lost %s: %s", r->cfg->url,
                    r->sub->err ? r->sub->errstr : "a command failed");
            relay_disconnect(r);
            followed_at = 0;
        }
    }
    relay_disconnect(r);
    return NULL;
}

/* ---- life ---- */

int relay_start(struct relay **out, struct server *srv, struct fx_err *err)
{
    struct relay *r = calloc(1, sizeof *r);
    if (!r) return fx_fail(err, "internal", NULL, "out of memory");
    r->srv = srv;
    r->cfg = cluster_config_of(srv->cluster);
    snprintf(r->prefix, sizeof r->prefix, CLUSTER_FRAMES_CHANNEL "%d:", r->cfg->db);
    hist_init(&r->latency, hist_age_bounds, hist_age_nb);
    r->stop_fd = eventfd(0, EFD_CLOEXEC);
    if (r->stop_fd < 0 || pthread_create(&r->thread, NULL, relay_main, r)) {
        relay_stop(r);
        return fx_fail(err, "internal", NULL, "cannot start the cluster's relay thread");
    }
    r->started = true;
    *out = r;
    return 0;
}

void relay_stop(struct relay *r)
{
    if (!r) return;
    atomic_store(&r->stopping, true);
    if (r->started) {
        uint64_t one = 1;
        if (write(r->stop_fd, &one, sizeof one) != sizeof one) log_error("cluster: cannot wake the relay");
        pthread_join(r->thread, NULL);
    }
    if (r->stop_fd >= 0) close(r->stop_fd);
    free(r->subs);
    free(r);
}

const struct histogram *relay_latency(const struct relay *r) { return &r->latency; }
