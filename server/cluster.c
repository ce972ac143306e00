/* cluster.c — see cluster.h. */
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

#define CLUSTER_TIMEOUT_S 1         /* to connect, and per command: the longest the network thread waits */
#define CLUSTER_PING_S 1.0          /* the follower pings a quiet subscription this often... */
#define CLUSTER_PING_TIMEOUT_S 3.0  /* ...and gives the link up when no answer comes this long */
#define CLUSTER_BACKOFF_MIN_S 0.1   /* reconnection: first pause, doubled per failure... */
#define CLUSTER_BACKOFF_MAX_S 1.0   /* ...up to this */
#define CLUSTER_FIRST_WAIT_S 10.0   /* cluster_follow waits this long for the first subscription */

/* ---- the scripts (Lua, run atomically by Redis) ---- */

enum { CS_CREATE, CS_SET, CS_DESTROY, CS_RESET, CS_LOAD, CS_SEED, CS_COUNT };

/* Each ends by publishing "SEQ EVENT" (the change's number, then the caller's JSON). */
#define CLUSTER_PUBLISH(event, channel) \
    "redis.call('PUBLISH', ARGV[" channel "], string.format('%d ', seq) .. ARGV[" event "])\n"

static const char *const cluster_scripts[CS_COUNT] = {
    /* KEYS stream, streams, seq; ARGV name, effect, params, max_streams, event, channel */
    [CS_CREATE] = "if redis.call('EXISTS', KEYS[1]) == 1 then return {'exists'} end\n"
                  "if redis.call('ZCARD', KEYS[2]) >= tonumber(ARGV[4]) then return {'limit'} end\n"
                  "local seq = redis.call('INCR', KEYS[3])\n"
                  "redis.call('HSET', KEYS[1], 'effect', ARGV[2], 'rev', '1', 'params', ARGV[3])\n"
                  "redis.call('ZADD', KEYS[2], seq, ARGV[1])\n" CLUSTER_PUBLISH("5", "6") "return {'ok', seq}\n",
    /* KEYS stream, seq; ARGV effect, base rev, new rev, params, event, channel */
    [CS_SET] = "local cur = redis.call('HMGET', KEYS[1], 'effect', 'rev', 'params')\n"
               "if not cur[1] then return {'gone'} end\n"
               "if cur[1] ~= ARGV[1] or cur[2] ~= ARGV[2] then return {'moved', cur[1], cur[2], cur[3]} end\n"
               "local seq = redis.call('INCR', KEYS[2])\n"
               "redis.call('HSET', KEYS[1], 'rev', ARGV[3], 'params', ARGV[4])\n" CLUSTER_PUBLISH("5", "6")
               "return {'ok', seq}\n",
    /* KEYS stream, streams, seq; ARGV name, event, channel */
    [CS_DESTROY] = "if redis.call('DEL', KEYS[1]) == 0 then return {'gone'} end\n"
                   "redis.call('ZREM', KEYS[2], ARGV[1])\n"
                   "local p = '" CLUSTER_KEY "'\n"
                   "redis.call('DEL', p .. 'lease:' .. ARGV[1], p .. 'want:' .. ARGV[1], p .. 'frame:' .. ARGV[1] .. ':1',\n"
                   "           p .. 'frame:' .. ARGV[1] .. ':2', p .. 'frame:' .. ARGV[1] .. ':3', p .. 'frame:' .. ARGV[1] .. ':4',\n"
                   "           p .. 'frame:' .. ARGV[1] .. ':1:engine', p .. 'frame:' .. ARGV[1] .. ':2:engine')\n"
                   "local seq = redis.call('INCR', KEYS[3])\n" CLUSTER_PUBLISH("2", "3") "return {'ok', seq}\n",
    /* KEYS stream, streams, seq; ARGV name, event, channel (as CS_DESTROY's) */
    [CS_RESET] = "if redis.call('EXISTS', KEYS[1]) == 0 then return {'gone'} end\n"
                 "local seq = redis.call('INCR', KEYS[3])\n" CLUSTER_PUBLISH("2", "3") "return {'ok', seq}\n",
    /* KEYS streams, seq; ARGV key prefix. Returns seq, then name, effect, rev, params per stream. */
    [CS_LOAD] = "local out = {redis.call('GET', KEYS[2]) or '0'}\n"
                "for _, n in ipairs(redis.call('ZRANGE', KEYS[1], 0, -1)) do\n"
                "  local h = redis.call('HMGET', ARGV[1] .. n, 'effect', 'rev', 'params')\n"
                "  if h[1] and h[2] and h[3] then\n"
                "    out[#out + 1] = n; out[#out + 1] = h[1]; out[#out + 1] = h[2]; out[#out + 1] = h[3]\n"
                "  end\n"
                "end\n"
                "return out\n",
    /* KEYS seeded, streams, seq; ARGV node, key prefix, event, channel, then name, effect, rev,
     * params per stream. 0 when the database was seeded before, else 1 + the streams added. */
    [CS_SEED] = "if redis.call('SETNX', KEYS[1], ARGV[1]) == 0 then return 0 end\n"
                "local n = 1\n"
                "for i = 5, #ARGV, 4 do\n"
                "  local k = ARGV[2] .. ARGV[i]\n"
                "  if redis.call('EXISTS', k) == 0 then\n"
                "    local seq = redis.call('INCR', KEYS[3])\n"
                "    redis.call('HSET', k, 'effect', ARGV[i + 1], 'rev', ARGV[i + 2], 'params', ARGV[i + 3])\n"
                "    redis.call('ZADD', KEYS[2], seq, ARGV[i])\n"
                "    n = n + 1\n"
                "  end\n"
                "end\n"
                "local seq = redis.call('INCR', KEYS[3])\n" CLUSTER_PUBLISH("3", "4") "return n\n",
};

struct cluster {
    struct cluster_config cfg;
    char channel[48];

    /* Network thread only (in_sync is also read by the follower, which wakes the network thread
     * every CLUSTER_PING_S while the copy is stale, so a failed reload is retried when idle). */
    redisContext *cmd;
    char sha[CS_COUNT][48]; /* SCRIPT LOAD's answers on cmd */
    atomic_bool in_sync;
    uint64_t seq;

    /* The follower. */
    pthread_t thread;
    bool started;
    int stop_fd; /* eventfd: cluster_close wakes the follower's polls through it */
    atomic_bool stopping, link_up;
    atomic_bool cmd_stale;   /* the link was lost since the command connection was made */
    atomic_bool cmd_suspect; /* a command got no answer: none is sent until the subscription hears Redis again */
    atomic_uint_fast64_t link_losses;
    void (*wake)(void *ctx);
    void *wake_ctx;

    pthread_mutex_t mu; /* guards what follows */
    pthread_cond_t first_cv;
    int first;          /* the follower's first attempt: 0 pending, 1 subscribed, -1 failed */
    struct cluster_item *head, *tail;
    char last_error[320];
};

/* ---- configuration ---- */

static int cluster_url_fail(const char *what, const char *url, const char *why, struct fx_err *err)
{
    return fx_fail(err, "bad_request", "cluster", "%s: %s, got \"%.200s\" (expected redis://HOST[:PORT][/DB])", what, why,
                   url);
}

/* "[v6]" or a name / IPv4 address of [A-Za-z0-9.-]; returns the rest of s, or NULL. */
static const char *cluster_url_host(const char *s, char *host, size_t cap)
{
    const char *end;
    if (*s == '[') {
        end = strchr(s, ']');
        if (!end || end == s + 1 || strspn(s + 1, "0123456789abcdefABCDEF:.") != (size_t)(end - s - 1)) return NULL;
        s++;
    } else {
        end = s + strspn(s, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.-");
        if (end == s) return NULL;
    }
    if ((size_t)(end - s) >= cap) return NULL;
    memcpy(host, s, (size_t)(end - s));
    host[end - s] = 0;
    return *end == ']' ? end + 1 : end;
}

/* Digits only, in [min, max]; returns the rest of s, or NULL. */
static const char *cluster_url_num(const char *s, long min, long max, int *out)
{
    size_t n = strspn(s, "0123456789");
    if (n == 0 || n > 6) return NULL;
    long v = strtol(s, NULL, 10);
    if (v < min || v > max) return NULL;
    *out = (int)v;
    return s + n;
}

int cluster_parse_url(const char *what, const char *url, struct cluster_config *cfg, struct fx_err *err)
{
    if (strchr(url, '@')) /* not echoed: it may hold a password */
        return fx_fail(err, "bad_request", "cluster", "%s: credentials do not go in the URL (the password comes from "
                       "FXS_REDIS_PASSWORD)", what);
    if (!strncmp(url, "rediss://", 9)) return cluster_url_fail(what, url, "TLS to Redis (rediss://) is not supported", err);
    if (strncmp(url, "redis://", 8)) return cluster_url_fail(what, url, "not a redis:// URL", err);
    if (strlen(url) >= sizeof cfg->url) return cluster_url_fail(what, url, "too long", err);
    const char *p = cluster_url_host(url + 8, cfg->host, sizeof cfg->host);
    if (!p) return cluster_url_fail(what, url, "bad host", err);
    cfg->port = 6379;
    cfg->db = 0;
    if (*p == ':' && !(p = cluster_url_num(p + 1, 1, 65535, &cfg->port)))
        return cluster_url_fail(what, url, "the port must be 1-65535", err);
    if (*p == '/' && !(p = cluster_url_num(p + 1, 0, 9999, &cfg->db)))
        return cluster_url_fail(what, url, "the database must be a number from 0 to 9999", err);
    if (*p) return cluster_url_fail(what, url, "unexpected text after the host, port and database", err);
    snprintf(cfg->url, sizeof cfg->url, "%s", url);
    return 0;
}

static const char *const cluster_roles[] = {[CLUSTER_ROLE_BOTH] = "both", [CLUSTER_ROLE_COMPUTE] = "compute",
                                            [CLUSTER_ROLE_EDGE] = "edge"};

int cluster_parse_role(const char *what, const char *s, struct cluster_config *cfg, struct fx_err *err)
{
    for (int r = 0; r < 3; r++)
        if (!strcmp(s, cluster_roles[r])) {
            cfg->role = (enum cluster_role)r;
            cfg->role_set = true;
            return 0;
        }
    return fx_fail(err, "bad_request", "role", "%s: expected compute, edge or both, got \"%.64s\"", what, s);
}

const char *cluster_role_name(enum cluster_role role) { return cluster_roles[role]; }

const struct cluster_config *cluster_config_of(const struct cluster *cl) { return &cl->cfg; }

/* ---- connections ---- */

static void cluster_note_error(struct cluster *cl, const char *why)
{
    pthread_mutex_lock(&cl->mu);
    snprintf(cl->last_error, sizeof cl->last_error, "%s", why);
    pthread_mutex_unlock(&cl->mu);
}

static void cluster_clear_error(struct cluster *cl)
{
    pthread_mutex_lock(&cl->mu);
    cl->last_error[0] = 0;
    pthread_mutex_unlock(&cl->mu);
}

/* A command that must answer OK (AUTH, SELECT); 0, or -1 with why. */
static int cluster_expect_ok(redisContext *c, char *why, size_t cap, const char *what, int argc, const char **argv)
{
    redisReply *r = redisCommandArgv(c, argc, argv, NULL);
    int rc = r && r->type == REDIS_REPLY_STATUS ? 0 : -1;
    if (rc) snprintf(why, cap, "%s: %s", what, r ? (r->str ? r->str : "unexpected answer") : c->errstr);
    freeReplyObject(r);
    return rc;
}

redisContext *cluster_dial(const struct cluster *cl, char *why, size_t cap)
{
    struct timeval tv = {CLUSTER_TIMEOUT_S, 0};
    redisContext *c = redisConnectWithTimeout(cl->cfg.host, cl->cfg.port, tv);
    if (!c || c->err || redisSetTimeout(c, tv) != REDIS_OK) { /* the timeout bounds every command too */
        snprintf(why, cap, "%s", c ? c->errstr : "out of memory");
        redisFree(c);
        return NULL;
    }
    redisEnableKeepAlive(c);
    char db[16];
    snprintf(db, sizeof db, "%d", cl->cfg.db);
    const char *auth[] = {"AUTH", cl->cfg.password}, *sel[] = {"SELECT", db};
    if ((cl->cfg.password[0] && cluster_expect_ok(c, why, cap, "AUTH (FXS_REDIS_PASSWORD)", 2, auth)) ||
        (cl->cfg.db && cluster_expect_ok(c, why, cap, "SELECT", 2, sel))) {
        redisFree(c);
        return NULL;
    }
    return c;
}

/* ---- the follower ---- */

static void cluster_push(struct cluster *cl, enum cluster_item_kind kind, uint64_t seq, cJSON *doc)
{
    struct cluster_item *it = calloc(1, sizeof *it);
    if (!it) { /* a lost event is a gap the next one reveals; a lost LINK item is not */
        log_error("cluster: out of memory queueing a change");
        cJSON_Delete(doc);
        return;
    }
    *it = (struct cluster_item){.kind = kind, .seq = seq, .doc = doc};
    pthread_mutex_lock(&cl->mu);
    if (cl->tail) cl->tail->next = it;
    else cl->head = it;
    cl->tail = it;
    pthread_mutex_unlock(&cl->mu);
    if (cl->wake) cl->wake(cl->wake_ctx);
}

/* The first attempt's outcome, for cluster_follow. */
static void cluster_first(struct cluster *cl, int outcome)
{
    pthread_mutex_lock(&cl->mu);
    if (!cl->first) cl->first = outcome;
    pthread_cond_broadcast(&cl->first_cv);
    pthread_mutex_unlock(&cl->mu);
}

/* A connection SUBSCRIBEd to the channel, or NULL with why. */
static redisContext *cluster_subscribe(struct cluster *cl, char *why, size_t cap)
{
    redisContext *c = cluster_dial(cl, why, cap);
    if (!c) return NULL;
    redisReply *r = redisCommand(c, "SUBSCRIBE %s", cl->channel);
    bool ok = r && r->type == REDIS_REPLY_ARRAY && r->elements == 3;
    if (!ok) snprintf(why, cap, "SUBSCRIBE: %s", r ? (r->str ? r->str : "unexpected answer") : c->errstr);
    freeReplyObject(r);
    if (ok) return c;
    redisFree(c);
    return NULL;
}

/* A pub/sub message: "SEQ JSON". */
static void cluster_on_message(struct cluster *cl, const char *text, size_t len)
{
    char *end;
    uint64_t seq = strtoull(text, &end, 10);
    cJSON *doc = end > text && *end == ' ' ? cJSON_ParseWithLength(end + 1, len - (size_t)(end + 1 - text)) : NULL;
    if (!cJSON_IsObject(doc)) { /* queued all the same: the copy cannot follow past it, so it reloads */
        log_warn("cluster: unreadable message on %s: %.80s", cl->channel, text);
        cJSON_Delete(doc);
        doc = NULL;
    }
    cluster_push(cl, CLUSTER_EVENT, seq, doc);
}

/* Handles one reply on the subscription; clears *ping when it is PING's answer. */
static void cluster_on_reply(struct cluster *cl, const redisReply *r, double *ping)
{
    if (r->type != REDIS_REPLY_ARRAY || r->elements < 2 || r->element[0]->type != REDIS_REPLY_STRING) return;
    const char *kind = r->element[0]->str;
    if (!strcmp(kind, "pong")) *ping = 0;
    else if (!strcmp(kind, "message") && r->elements == 3 && r->element[2]->type == REDIS_REPLY_STRING)
        cluster_on_message(cl, r->element[2]->str, r->element[2]->len);
}

static int cluster_send_ping(redisContext *c)
{
    int done = 0;
    if (redisAppendCommand(c, "PING") != REDIS_OK) return -1;
    while (!done)
        if (redisBufferWrite(c, &done) != REDIS_OK) return -1;
    return 0;
}

/* Reads the subscription until it fails (why filled) or the link is closed. */
static void cluster_listen(struct cluster *cl, redisContext *c, char *why, size_t cap)
{
    double ping = 0; /* when the unanswered PING was sent; 0: none */
    while (!atomic_load(&cl->stopping)) {
        void *reply = NULL;
        if (redisGetReplyFromReader(c, &reply) != REDIS_OK) break;
        if (reply) {
            atomic_store(&cl->cmd_suspect, false); /* Redis answers again */
            cluster_on_reply(cl, reply, &ping);
            freeReplyObject(reply);
            continue;
        }
        struct pollfd p[2] = {{.fd = c->fd, .events = POLLIN}, {.fd = cl->stop_fd, .events = POLLIN}};
        int n = poll(p, 2, (int)(CLUSTER_PING_S * 1000));
        if (n < 0 && errno != EINTR) {
            snprintf(why, cap, "poll: %s", strerror(errno));
            return;
        }
        if (n == 0 && ping && clock_now() - ping > CLUSTER_PING_TIMEOUT_S) {
            snprintf(why, cap, "no answer to PING for %.0f s", CLUSTER_PING_TIMEOUT_S);
            return;
        }
        if (n == 0 && !atomic_load(&cl->in_sync) && cl->wake) cl->wake(cl->wake_ctx); /* reload to retry */
        if (n == 0 && !ping) {
            ping = clock_now();
            if (cluster_send_ping(c)) break;
        }
        if (n > 0 && (p[0].revents & (POLLIN | POLLHUP | POLLERR)) && redisBufferRead(c) != REDIS_OK) break;
    }
    snprintf(why, cap, "%s", c->err ? c->errstr : "closed");
}

/* Sleeps `s` seconds, or less when the link is closed. */
static void cluster_pause(struct cluster *cl, double s)
{
    struct pollfd p = {.fd = cl->stop_fd, .events = POLLIN};
    poll(&p, 1, (int)(s * 1000));
}

static void cluster_link(struct cluster *cl, bool up, const char *why)
{
    bool was = atomic_exchange(&cl->link_up, up);
    if (up) {
        atomic_store(&cl->cmd_suspect, false);
        cluster_clear_error(cl);
        log_info("cluster: subscribed to %s on %s", cl->channel, cl->cfg.url);
        cluster_push(cl, CLUSTER_LINK_UP, 0, NULL);
        return;
    }
    char msg[320];
    snprintf(msg, sizeof msg, "cannot reach %s: %s", cl->cfg.url, why);
    cluster_note_error(cl, msg);
    if (!was) return; /* one warning and one LINK_DOWN per loss, not per retry */
    atomic_fetch_add(&cl->link_losses, 1);
    atomic_store(&cl->cmd_stale, true);
    log_warn("cluster: lost %s (%s): changes are refused until it is back", cl->cfg.url, why);
    cluster_push(cl, CLUSTER_LINK_DOWN, 0, NULL);
}

static void *cluster_follower(void *arg)
{
    struct cluster *cl = arg;
    double backoff = CLUSTER_BACKOFF_MIN_S;
    while (!atomic_load(&cl->stopping)) {
        char why[256] = "";
        redisContext *c = cluster_subscribe(cl, why, sizeof why);
        if (c) {
            backoff = CLUSTER_BACKOFF_MIN_S;
            cluster_link(cl, true, NULL);
            cluster_first(cl, 1);
            cluster_listen(cl, c, why, sizeof why);
            redisFree(c);
        }
        if (atomic_load(&cl->stopping)) break;
        cluster_link(cl, false, why);
        cluster_first(cl, -1);
        cluster_pause(cl, backoff);
        backoff = fmin(2 * backoff, CLUSTER_BACKOFF_MAX_S);
    }
    return NULL;
}

/* ---- life ---- */

int cluster_open(struct cluster **out, const struct cluster_config *cfg, struct fx_err *err)
{
    struct cluster *cl = calloc(1, sizeof *cl);
    if (!cl) return fx_fail(err, "internal", NULL, "out of memory");
    cl->cfg = *cfg;
    snprintf(cl->channel, sizeof cl->channel, CLUSTER_KEY "events:%d", cfg->db);
    cl->stop_fd = eventfd(0, EFD_CLOEXEC);
    if (cl->stop_fd < 0) {
        free(cl);
        return fx_fail(err, "internal", NULL, "eventfd: %s", strerror(errno));
    }
    pthread_mutex_init(&cl->mu, NULL);
    pthread_cond_init(&cl->first_cv, NULL);
    *out = cl;
    return 0;
}

int cluster_follow(struct cluster *cl, void (*wake)(void *ctx), void *ctx, struct fx_err *err)
{
    cl->wake = wake;
    cl->wake_ctx = ctx;
    if (pthread_create(&cl->thread, NULL, cluster_follower, cl))
        return fx_fail(err, "internal", NULL, "cannot start the cluster thread");
    cl->started = true;
    struct timespec until;
    clock_gettime(CLOCK_REALTIME, &until);
    until.tv_sec += (time_t)CLUSTER_FIRST_WAIT_S;
    pthread_mutex_lock(&cl->mu);
    while (!cl->first && !pthread_cond_timedwait(&cl->first_cv, &cl->mu, &until)) continue;
    int first = cl->first;
    char why[320];
    snprintf(why, sizeof why, "%s", cl->last_error[0] ? cl->last_error : "no answer");
    pthread_mutex_unlock(&cl->mu);
    if (first == 1) return 0;
    return fx_fail(err, "unavailable", NULL, "cluster: %s", why);
}

void cluster_item_free(struct cluster_item *it)
{
    if (!it) return;
    cJSON_Delete(it->doc);
    free(it);
}

void cluster_close(struct cluster *cl)
{
    if (!cl) return;
    atomic_store(&cl->stopping, true);
    if (cl->started) {
        uint64_t one = 1;
        if (write(cl->stop_fd, &one, sizeof one) != sizeof one) log_error("cluster: cannot wake the follower");
        pthread_join(cl->thread, NULL);
    }
    struct cluster_item *it;
    while ((it = cl->head)) {
        cl->head = it->next;
        cluster_item_free(it);
    }
    redisFree(cl->cmd);
    close(cl->stop_fd);
    pthread_mutex_destroy(&cl->mu);
    pthread_cond_destroy(&cl->first_cv);
    free(cl);
}

/* ---- the network thread's side: the queue and the copy's position ---- */

struct cluster_item *cluster_next(struct cluster *cl)
{
    pthread_mutex_lock(&cl->mu);
    struct cluster_item *it = cl->head;
    if (it && !(cl->head = it->next)) cl->tail = NULL;
    pthread_mutex_unlock(&cl->mu);
    if (it && it->kind != CLUSTER_EVENT) cl->in_sync = false;
    return it;
}

enum cluster_fit cluster_fit(struct cluster *cl, uint64_t seq)
{
    if (!cl->in_sync || seq <= cl->seq) return CLUSTER_SKIP;
    if (seq == cl->seq + 1) {
        cl->seq = seq;
        return CLUSTER_APPLY;
    }
    cl->in_sync = false;
    return CLUSTER_GAP;
}

bool cluster_in_sync(struct cluster *cl) { return atomic_load(&cl->in_sync); }
bool cluster_link_up(struct cluster *cl) { return atomic_load(&cl->link_up); }
void cluster_stale(struct cluster *cl) { cl->in_sync = false; }

void cluster_loaded(struct cluster *cl, uint64_t seq)
{
    cl->seq = seq;
    cl->in_sync = true;
}

void cluster_status(struct cluster *cl, struct cluster_status *out)
{
    *out = (struct cluster_status){.node = cl->cfg.node_id, .url = cl->cfg.url, .link_up = cluster_link_up(cl),
                                   .in_sync = cluster_in_sync(cl), .seq = cl->seq,
                                   .link_losses = atomic_load(&cl->link_losses)};
    pthread_mutex_lock(&cl->mu);
    snprintf(out->last_error, sizeof out->last_error, "%s", cl->last_error);
    pthread_mutex_unlock(&cl->mu);
}

/* ---- commands (network thread) ---- */

static int cluster_unavailable(struct cluster *cl, struct fx_err *err, const char *fmt, const char *why)
{
    char msg[320];
    snprintf(msg, sizeof msg, fmt, cl->cfg.url, why);
    cluster_note_error(cl, msg);
    return fx_fail(err, "unavailable", NULL, "cluster: %s", msg);
}

/* The command connection, (re)made with the scripts loaded; only while the follower is
 * subscribed, so a Redis known to be down costs no connect timeout. */
static int cluster_cmd(struct cluster *cl, struct fx_err *err)
{
    char why[320];
    if (!cluster_link_up(cl)) {
        pthread_mutex_lock(&cl->mu);
        snprintf(why, sizeof why, "%s", cl->last_error[0] ? cl->last_error : "not connected");
        pthread_mutex_unlock(&cl->mu);
        return fx_fail(err, "unavailable", NULL, "cluster: %s (nothing changed)", why);
    }
    if (atomic_load(&cl->cmd_suspect)) /* a hung Redis would hold the network thread a timeout per request */
        return fx_fail(err, "unavailable", NULL, "cluster: %s did not answer the last command within %d s; changes "
                       "wait until it answers again (nothing changed)", cl->cfg.url, CLUSTER_TIMEOUT_S);
    if (atomic_exchange(&cl->cmd_stale, false)) { /* Redis went away since: this socket is dead */
        redisFree(cl->cmd);
        cl->cmd = NULL;
    }
    if (cl->cmd) return 0;
    if (!(cl->cmd = cluster_dial(cl, why, sizeof why))) {
        atomic_store(&cl->cmd_suspect, true);
        return cluster_unavailable(cl, err, "cannot reach %s: %s (nothing changed)", why);
    }
    for (int i = 0; i < CS_COUNT; i++) {
        redisReply *r = redisCommand(cl->cmd, "SCRIPT LOAD %s", cluster_scripts[i]);
        bool ok = r && r->type == REDIS_REPLY_STRING && r->len < sizeof cl->sha[i];
        if (ok) snprintf(cl->sha[i], sizeof cl->sha[i], "%s", r->str);
        else snprintf(why, sizeof why, "SCRIPT LOAD: %s", r ? (r->str ? r->str : "unexpected answer") : cl->cmd->errstr);
        if (!r) atomic_store(&cl->cmd_suspect, true);
        freeReplyObject(r);
        if (!ok) {
            redisFree(cl->cmd);
            cl->cmd = NULL;
            return cluster_unavailable(cl, err, "%s refused the scripts: %s (nothing changed)", why);
        }
    }
    return 0;
}

/* Changes are made only while the local copy follows Redis (the caller's request was checked
 * against it; replica_poll reloads a stale copy before each request). */
static int cluster_writable(struct cluster *cl, struct fx_err *err)
{
    if (cl->in_sync || !cluster_link_up(cl)) return 0; /* a link down: cluster_cmd says so */
    char why[320];
    pthread_mutex_lock(&cl->mu);
    snprintf(why, sizeof why, "%s", cl->last_error);
    pthread_mutex_unlock(&cl->mu);
    return fx_fail(err, "unavailable", NULL, "cluster: this daemon's copy of the streams in %s is being reloaded%s%s "
                   "(nothing changed)", cl->cfg.url, why[0] ? ": " : "", why);
}

/* Runs script s with keys then args (argc of them, lens NULL: C strings): its reply, or NULL
 * with err. A reply lost after sending leaves the outcome unknown: the copy goes stale. */
static redisReply *cluster_eval(struct cluster *cl, int s, int nkeys, int argc, const char *const *argv,
                                struct fx_err *err)
{
    if (cluster_cmd(cl, err)) return NULL;
    const char **v = malloc(sizeof *v * (size_t)(argc + 3));
    if (!v) {
        fx_fail(err, "internal", NULL, "out of memory");
        return NULL;
    }
    char n[16];
    snprintf(n, sizeof n, "%d", nkeys);
    v[0] = "EVALSHA";
    v[1] = cl->sha[s];
    v[2] = n;
    memcpy(v + 3, argv, sizeof *v * (size_t)argc);
    redisReply *r = redisCommandArgv(cl->cmd, argc + 3, v, NULL);
    if (r && r->type == REDIS_REPLY_ERROR && !strncmp(r->str, "NOSCRIPT", 8)) { /* SCRIPT FLUSH since */
        freeReplyObject(r);
        v[0] = "EVAL";
        v[1] = cluster_scripts[s];
        r = redisCommandArgv(cl->cmd, argc + 3, v, NULL);
    }
    int e = errno;
    free(v);
    if (!r) {
        char why[256];
        if (e == EAGAIN || e == EWOULDBLOCK) snprintf(why, sizeof why, "no answer within %d s", CLUSTER_TIMEOUT_S);
        else snprintf(why, sizeof why, "%s", cl->cmd->errstr);
        redisFree(cl->cmd);
        cl->cmd = NULL;
        cl->in_sync = false;
        atomic_store(&cl->cmd_suspect, true);
        cluster_unavailable(cl, err, "lost %s during the command (%s): a change may or may not have been made; "
                            "this daemon reloads the state from Redis", why);
        return NULL;
    }
    if (r->type == REDIS_REPLY_ERROR) {
        cluster_unavailable(cl, err, "%s refused the change: %s (nothing changed)", r->str);
        freeReplyObject(r);
        return NULL;
    }
    cluster_clear_error(cl);
    return r;
}

/* The status word of a change script's reply ({'ok', seq}, {'gone'}, ...), "" if none. */
static const char *cluster_outcome(const redisReply *r)
{
    return r->type == REDIS_REPLY_ARRAY && r->elements && r->element[0]->type == REDIS_REPLY_STRING
               ? r->element[0]->str : "";
}

/* An {'ok', seq} reply: the change was made; the copy, which applies it next, moves to seq. */
static int cluster_done(struct cluster *cl, redisReply *r, struct fx_err *err)
{
    bool ok = r->elements == 2 && r->element[1]->type == REDIS_REPLY_INTEGER && r->element[1]->integer > 0;
    if (ok) cluster_fit(cl, (uint64_t)r->element[1]->integer);
    else cl->in_sync = false;
    freeReplyObject(r);
    return ok ? 0 : fx_fail(err, "internal", NULL, "cluster: unexpected answer from %s", cl->cfg.url);
}

/* The message of a change: {op, node[, stream[, effect, rev, params]]}, as text. */
static char *cluster_event(const struct cluster *cl, const char *op, const char *stream, const char *effect,
                           uint64_t rev, const cJSON *params)
{
    cJSON *e = cJSON_CreateObject();
    cJSON_AddStringToObject(e, "op", op);
    cJSON_AddStringToObject(e, "node", cl->cfg.node_id);
    if (stream) cJSON_AddStringToObject(e, "stream", stream);
    if (effect) {
        cJSON_AddStringToObject(e, "effect", effect);
        cJSON_AddNumberToObject(e, "rev", (double)rev);
        cJSON_AddItemToObject(e, "params", cJSON_Duplicate(params, 1));
    }
    char *text = cJSON_PrintUnformatted(e);
    cJSON_Delete(e);
    return text;
}

static void cluster_key(char *key, size_t cap, const char *stream)
{
    snprintf(key, cap, CLUSTER_KEY "stream:%s", stream);
}

int cluster_create(struct cluster *cl, const char *stream, const char *effect, const cJSON *params, int max_streams,
                   struct fx_err *err)
{
    if (cluster_writable(cl, err)) return -1;
    char key[128], max[16];
    cluster_key(key, sizeof key, stream);
    snprintf(max, sizeof max, "%d", max_streams);
    char *doc = cJSON_PrintUnformatted(params), *ev = cluster_event(cl, "created", stream, effect, 1, params);
    redisReply *r = NULL;
    if (!doc || !ev) fx_fail(err, "internal", NULL, "out of memory");
    else
        r = cluster_eval(cl, CS_CREATE, 3, 9,
                         (const char *[]){key, CLUSTER_KEY "streams", CLUSTER_KEY "seq", stream, effect, doc, max, ev,
                                          cl->channel}, err);
    cJSON_free(doc);
    cJSON_free(ev);
    if (!r) return -1;
    const char *o = cluster_outcome(r);
    if (!strcmp(o, "ok")) return cluster_done(cl, r, err);
    if (!strcmp(o, "exists"))
        fx_fail(err, "exists", "stream", "a stream named \"%s\" already exists in the cluster (made on another daemon)", stream);
    else
        fx_fail(err, "limit", "stream", "stream limit reached (%d in the cluster)", max_streams);
    freeReplyObject(r);
    return -1;
}

static int cluster_gone(const char *stream, struct fx_err *err)
{
    return fx_fail(err, "unknown_stream", "stream", "no stream named \"%s\" in the cluster (destroyed on another daemon)",
                   stream);
}

/* A 'moved' reply's current document into cur; 1, or -1 with err when it is unreadable. */
static int cluster_moved(const struct cluster *cl, const redisReply *r, struct cluster_current *cur,
                         struct fx_err *err)
{
    char *end = NULL;
    bool ok = r->elements == 4;
    for (size_t i = 1; ok && i < 4; i++) ok = r->element[i]->type == REDIS_REPLY_STRING;
    if (ok) {
        snprintf(cur->effect, sizeof cur->effect, "%s", r->element[1]->str);
        cur->rev = strtoull(r->element[2]->str, &end, 10);
        cur->params = cJSON_ParseWithLength(r->element[3]->str, r->element[3]->len);
        ok = *end == 0 && cur->rev >= 1 && cJSON_IsObject(cur->params);
    }
    if (ok) return 1;
    cJSON_Delete(cur->params);
    cur->params = NULL;
    return fx_fail(err, "internal", NULL, "cluster: unreadable stream document in %s", cl->cfg.url);
}

int cluster_set(struct cluster *cl, const char *stream, const char *effect, uint64_t base, const cJSON *params,
                struct cluster_current *cur, struct fx_err *err)
{
    if (cluster_writable(cl, err)) return -1;
    char key[128], from[24], to[24];
    cluster_key(key, sizeof key, stream);
    snprintf(from, sizeof from, "%llu", (unsigned long long)base);
    snprintf(to, sizeof to, "%llu", (unsigned long long)base + 1);
    char *doc = cJSON_PrintUnformatted(params), *ev = cluster_event(cl, "params", stream, effect, base + 1, params);
    redisReply *r = NULL;
    if (!doc || !ev) fx_fail(err, "internal", NULL, "out of memory");
    else
        r = cluster_eval(cl, CS_SET, 2, 8,
                         (const char *[]){key, CLUSTER_KEY "seq", effect, from, to, doc, ev, cl->channel}, err);
    cJSON_free(doc);
    cJSON_free(ev);
    if (!r) return -1;
    const char *o = cluster_outcome(r);
    if (!strcmp(o, "ok")) return cluster_done(cl, r, err);
    int rc = !strcmp(o, "moved") ? cluster_moved(cl, r, cur, err) : cluster_gone(stream, err);
    freeReplyObject(r);
    return rc;
}

/* A destroy or a reset (script s, the event's op): both only need the stream to exist. */
static int cluster_stream_change(struct cluster *cl, int s, const char *op, const char *stream, struct fx_err *err)
{
    if (cluster_writable(cl, err)) return -1;
    char key[128], *ev = cluster_event(cl, op, stream, NULL, 0, NULL);
    cluster_key(key, sizeof key, stream);
    redisReply *r = ev ? cluster_eval(cl, s, 3, 6,
                                      (const char *[]){key, CLUSTER_KEY "streams", CLUSTER_KEY "seq", stream, ev,
                                                       cl->channel}, err)
                       : NULL;
    if (!ev) fx_fail(err, "internal", NULL, "out of memory");
    cJSON_free(ev);
    if (!r) return -1;
    if (!strcmp(cluster_outcome(r), "ok")) return cluster_done(cl, r, err);
    freeReplyObject(r);
    return cluster_gone(stream, err);
}

int cluster_destroy(struct cluster *cl, const char *stream, struct fx_err *err)
{
    return cluster_stream_change(cl, CS_DESTROY, "destroyed", stream, err);
}

int cluster_reset(struct cluster *cl, const char *stream, struct fx_err *err)
{
    return cluster_stream_change(cl, CS_RESET, "reset", stream, err);
}

/* ---- the whole state ---- */

int cluster_seed(struct cluster *cl, const cJSON *streams, struct fx_err *err)
{
    int n = cJSON_GetArraySize(streams), argc = 7 + 4 * n, i = 0;
    const char **v = calloc((size_t)argc, sizeof *v);
    struct { char rev[24]; char *doc; } *a = calloc((size_t)n + 1, sizeof *a);
    char *ev = cluster_event(cl, "seeded", NULL, NULL, 0, NULL);
    bool ok = v && a && ev;
    if (ok) {
        const char *head[] = {CLUSTER_KEY "seeded", CLUSTER_KEY "streams", CLUSTER_KEY "seq", cl->cfg.node_id,
                              CLUSTER_KEY "stream:", ev, cl->channel};
        memcpy(v, head, sizeof head);
    }
    for (const cJSON *s = streams->child; ok && s; s = s->next, i++) {
        const char **p = v + 7 + 4 * i;
        snprintf(a[i].rev, sizeof a[i].rev, "%.0f", cJSON_GetObjectItemCaseSensitive(s, "rev")->valuedouble);
        a[i].doc = cJSON_PrintUnformatted(cJSON_GetObjectItemCaseSensitive(s, "params"));
        p[0] = cJSON_GetObjectItemCaseSensitive(s, "stream")->valuestring;
        p[1] = cJSON_GetObjectItemCaseSensitive(s, "effect")->valuestring;
        p[2] = a[i].rev;
        p[3] = a[i].doc;
        ok = a[i].doc != NULL;
    }
    redisReply *r = ok ? cluster_eval(cl, CS_SEED, 3, argc, v, err) : NULL;
    if (!ok) fx_fail(err, "internal", NULL, "out of memory");
    for (int j = 0; a && j < i; j++) cJSON_free(a[j].doc);
    free(a);
    free(v);
    cJSON_free(ev);
    if (!r) return -1;
    if (r->type == REDIS_REPLY_INTEGER && r->integer > 0) log_info("cluster: %s was never seeded: seeded it with %lld streams", cl->cfg.url, r->integer - 1);
    freeReplyObject(r);
    return 0;
}

/* One stream of CS_LOAD's reply (name, effect, rev, params at e), or NULL when unreadable. */
static cJSON *cluster_load_entry(const struct cluster *cl, redisReply *const *e)
{
    for (int i = 0; i < 4; i++)
        if (e[i]->type != REDIS_REPLY_STRING) return NULL;
    char *end;
    uint64_t rev = strtoull(e[2]->str, &end, 10);
    cJSON *params = cJSON_ParseWithLength(e[3]->str, e[3]->len);
    if (*end || rev < 1 || !cJSON_IsObject(params)) {
        log_warn("cluster: stream %.64s in %s is unreadable (rev \"%.24s\"), left out", e[0]->str, cl->cfg.url, e[2]->str);
        cJSON_Delete(params);
        return NULL;
    }
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "stream", e[0]->str);
    cJSON_AddStringToObject(o, "effect", e[1]->str);
    cJSON_AddNumberToObject(o, "rev", (double)rev);
    cJSON_AddItemToObject(o, "params", params);
    return o;
}

int cluster_load(struct cluster *cl, cJSON **streams, uint64_t *seq, struct fx_err *err)
{
    redisReply *r = cluster_eval(cl, CS_LOAD, 2, 3,
                                 (const char *[]){CLUSTER_KEY "streams", CLUSTER_KEY "seq", CLUSTER_KEY "stream:"}, err);
    if (!r) return -1;
    if (r->type != REDIS_REPLY_ARRAY || r->elements % 4 != 1 || r->element[0]->type != REDIS_REPLY_STRING) {
        freeReplyObject(r);
        return fx_fail(err, "internal", NULL, "cluster: unexpected answer from %s", cl->cfg.url);
    }
    *seq = strtoull(r->element[0]->str, NULL, 10);
    *streams = cJSON_CreateArray();
    for (size_t i = 1; i < r->elements; i += 4) {
        cJSON *o = cluster_load_entry(cl, r->element + i);
        if (o) cJSON_AddItemToArray(*streams, o);
    }
    freeReplyObject(r);
    return 0;
}
