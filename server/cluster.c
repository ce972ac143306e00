/* cluster.c — see cluster.h. */
#include <errno.h>
#include <math.h>
#include <poll.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <sys/random.h>
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
#define CLUSTER_DONE_MS "60000"     /* how long Redis remembers a change's id (a change sent again is made once) */
#define CLUSTER_CLAIM_LOOK_S 0.25   /* cluster_claim looks at a node id held by another daemon this often */

/* ---- the scripts (Lua, run atomically by Redis) ---- */

enum { CS_CREATE, CS_SET, CS_DESTROY, CS_RESET, CS_REPAIR, CS_LOAD, CS_SEED, CS_CLAIM, CS_COUNT };

/* fxs_counter(k, floor): the change counter at k, never below floor (the change the caller's
 * copy has reached): a value that is not a number below 10^15, or is below floor, is set to
 * floor first and comes back shown as the second result; an absent one starts at floor. */
#define CLUSTER_LUA_COUNTER                                                              \
    CLUSTER_LUA_LIB                                                                      \
    "local function fxs_counter(k, floor)\n"                                             \
    "  local v, t = fxs_get(k)\n"                                                        \
    "  local n = v and #v <= 15 and string.match(v, '^%d+$') and tonumber(v)\n"          \
    "  floor = tonumber(floor)\n"                                                        \
    "  if n and n >= floor then return n end\n"                                          \
    "  if v ~= false or floor > 0 then redis.call('SET', k, string.format('%d', floor)) end\n" \
    "  if v == false then return floor end\n"                                            \
    "  return floor, fxs_show(v, t)\n"                                                   \
    "end\n"

/* Each ends by publishing "SEQ EVENT" (the change's number, then the caller's JSON). */
#define CLUSTER_PUBLISH(event, channel) \
    "redis.call('PUBLISH', ARGV[" channel "], string.format('%d ', seq) .. ARGV[" event "])\n"

/* The changes (create, set, destroy, reset, repair) share their first keys and arguments:
 *   KEYS[1] this node's record of its last change (fxs:done:NODE, "ID SEQ"), KEYS[2]
 *   fxs:seeded, KEYS[3] the change counter fxs:seq; ARGV[1] the change's id (unique per daemon
 *   and change), ARGV[2] its event, ARGV[3] the channel, ARGV[4] the change the caller's copy
 *   has reached (fxs_counter's floor); then their own from KEYS[4], ARGV[5].
 * A database that lost fxs:seeded lost its data (FLUSHALL, a restart without persistence):
 * {'unseeded'}, nothing done (the daemon reloads, which seeds it again). A change whose id is
 * recorded was made: its number is answered again, so a change sent again after its
 * connection was lost is made once. Each made change answers {'ok', its number}, plus what the
 * counter held when it had to be repaired. */
#define CLUSTER_BEGIN                                                                    \
    CLUSTER_LUA_COUNTER                                                                  \
    "if redis.call('EXISTS', KEYS[2]) == 0 then return {'unseeded'} end\n"              \
    "local done = fxs_get(KEYS[1])\n"                                                   \
    "if done then\n"                                                                   \
    "  local id, n = string.match(done, '^(%S+) (%d+)$')\n"                             \
    "  if id == ARGV[1] then return {'ok', tonumber(n)} end\n"                          \
    "end\n"
#define CLUSTER_NEXT                                     \
    "local seq, bad = fxs_counter(KEYS[3], ARGV[4])\n" \
    "seq = redis.call('INCR', KEYS[3])\n"
#define CLUSTER_MADE                                                                                     \
    "redis.call('SET', KEYS[1], ARGV[1] .. ' ' .. string.format('%d', seq), 'PX', " CLUSTER_DONE_MS ")\n" \
    CLUSTER_PUBLISH("2", "3") "return {'ok', seq, bad}\n"

static const char *const cluster_scripts[CS_COUNT] = {
    /* KEYS stream, streams; ARGV name, effect, params, max_streams */
    [CS_CREATE] = CLUSTER_BEGIN
                  "if redis.call('EXISTS', KEYS[4]) == 1 then return {'exists'} end\n"
                  "if redis.call('ZCARD', KEYS[5]) >= tonumber(ARGV[8]) then return {'limit'} end\n"
                  CLUSTER_NEXT
                  "redis.call('HSET', KEYS[4], 'effect', ARGV[6], 'rev', '1', 'params', ARGV[7])\n"
                  "redis.call('ZADD', KEYS[5], seq, ARGV[5])\n" CLUSTER_MADE,
    /* KEYS stream; ARGV effect, base rev, new rev, params. {'moved', effect, rev, params} when
     * the stream is not at that effect and rev (rev and params as Redis holds them: not trusted;
     * a key of another type answers them as missing). */
    [CS_SET] = CLUSTER_BEGIN
               "local cur = redis.pcall('HMGET', KEYS[4], 'effect', 'rev', 'params')\n"
               "if cur.err then cur = {'', false, false} end\n"
               "if not cur[1] then return {'gone'} end\n"
               "if cur[1] ~= ARGV[5] or cur[2] ~= ARGV[6] then return {'moved', cur[1], cur[2], cur[3]} end\n"
               CLUSTER_NEXT
               "redis.call('HSET', KEYS[4], 'rev', ARGV[7], 'params', ARGV[8])\n" CLUSTER_MADE,
    /* KEYS stream, streams; ARGV name */
    [CS_DESTROY] = CLUSTER_BEGIN
                   "if redis.call('DEL', KEYS[4]) == 0 then return {'gone'} end\n"
                   "redis.call('ZREM', KEYS[5], ARGV[5])\n"
                   "local p = '" CLUSTER_KEY "'\n"
                   "redis.call('DEL', p .. 'lease:' .. ARGV[5], p .. 'want:' .. ARGV[5], p .. 'frame:' .. ARGV[5] .. ':1',\n"
                   "           p .. 'frame:' .. ARGV[5] .. ':2', p .. 'frame:' .. ARGV[5] .. ':3', p .. 'frame:' .. ARGV[5] .. ':4',\n"
                   "           p .. 'frame:' .. ARGV[5] .. ':1:engine', p .. 'frame:' .. ARGV[5] .. ':2:engine')\n"
                   CLUSTER_NEXT CLUSTER_MADE,
    /* KEYS stream (streams and ARGV name, as CS_DESTROY's, unused) */
    [CS_RESET] = CLUSTER_BEGIN
                 "if redis.call('EXISTS', KEYS[4]) == 0 then return {'gone'} end\n" CLUSTER_NEXT CLUSTER_MADE,
    /* KEYS stream; ARGV its rev as read (not a revision), the rev that replaces it. {'gone'} when
     * the field holds something else now. */
    [CS_REPAIR] = CLUSTER_BEGIN
                  "if (redis.call('HGET', KEYS[4], 'rev') or '') ~= ARGV[5] then return {'gone'} end\n"
                  CLUSTER_NEXT "redis.call('HSET', KEYS[4], 'rev', ARGV[6])\n" CLUSTER_MADE,
    /* KEYS streams, seq, seeded; ARGV key prefix, the change the caller's copy has reached.
     * Returns {'ok', seq, what the counter held when repaired or '', then name, effect, rev,
     * params per stream} (rev and params '' when missing, effect '' for a key of another type:
     * the caller checks them), or {'unseeded'} when the database lost its data (as the changes). */
    [CS_LOAD] = CLUSTER_LUA_COUNTER
                "if redis.call('EXISTS', KEYS[3]) == 0 then return {'unseeded'} end\n"
                "local seq, bad = fxs_counter(KEYS[2], ARGV[2])\n"
                "local out = {'ok', seq, bad or ''}\n"
                "for _, n in ipairs(redis.call('ZRANGE', KEYS[1], 0, -1)) do\n"
                "  local h = redis.pcall('HMGET', ARGV[1] .. n, 'effect', 'rev', 'params')\n"
                "  if h.err then h = {'', '', ''} end\n"
                "  if h[1] then\n"
                "    out[#out + 1] = n; out[#out + 1] = h[1]; out[#out + 1] = h[2] or ''; out[#out + 1] = h[3] or ''\n"
                "  end\n"
                "end\n"
                "return out\n",
    /* KEYS seeded, streams, seq; ARGV node, key prefix, event, channel, the change this daemon's
     * copy has reached (the counter goes on from there, so that daemons whose copy is there too
     * see the new changes, rather than skip them as old ones), then name, effect, rev, params per
     * stream. 0 when the database was seeded before, else 1 + the streams added. */
    [CS_SEED] = CLUSTER_LUA_COUNTER
                "if redis.call('SETNX', KEYS[1], ARGV[1]) == 0 then return 0 end\n"
                "fxs_counter(KEYS[3], ARGV[5])\n"
                "local n = 1\n"
                "for i = 6, #ARGV, 4 do\n"
                "  local k = ARGV[2] .. ARGV[i]\n"
                "  if redis.call('EXISTS', k) == 0 then\n"
                "    local seq = redis.call('INCR', KEYS[3])\n"
                "    redis.call('HSET', k, 'effect', ARGV[i + 1], 'rev', ARGV[i + 2], 'params', ARGV[i + 3])\n"
                "    redis.call('ZADD', KEYS[2], seq, ARGV[i])\n"
                "    n = n + 1\n"
                "  end\n"
                "end\n"
                "local seq = redis.call('INCR', KEYS[3])\n" CLUSTER_PUBLISH("3", "4") "return n\n",
    /* KEYS member; ARGV this daemon's claim, ttl ms. {'ok'}: claimed (a claim whose daemon stopped
     * renewing it has expired), plus the value replaced when it was not a claim ("INSTANCE PID
     * HOST" with a TTL); {'held', claim, ms left}: another daemon's, with its time left. */
    [CS_CLAIM] = CLUSTER_LUA_LIB
                 "local v, t = fxs_get(KEYS[1])\n"
                 "if v == ARGV[1] or v == false then\n"
                 "  redis.call('SET', KEYS[1], ARGV[1], 'PX', ARGV[2])\n"
                 "  return {'ok'}\n"
                 "end\n"
                 "local left = redis.call('PTTL', KEYS[1])\n"
                 "if v and string.match(v, '^%x+ %d+ %S+$') and left > 0 and left <= tonumber(ARGV[2]) then\n"
                 "  return {'held', v, left}\n"
                 "end\n"
                 "redis.call('SET', KEYS[1], ARGV[1], 'PX', ARGV[2])\n"
                 "return {'ok', fxs_show(v, t)}\n",
};

struct cluster {
    struct cluster_config cfg;
    char channel[48];
    char done_key[96];  /* fxs:done:NODE (CLUSTER_BEGIN) */
    char instance[17];  /* this process's random id, in hex: the changes' ids start with it */
    char member[128];   /* this daemon's claim on its node id: "INSTANCE PID HOST" */

    /* Network thread only (in_sync is also read by the follower, which wakes the network thread
     * every CLUSTER_PING_S while the copy is stale, so a failed reload is retried when idle). */
    redisContext *cmd;
    char sha[CS_COUNT][48]; /* SCRIPT LOAD's answers on cmd */
    atomic_bool in_sync;
    uint64_t seq;
    uint64_t changes;       /* changes sent: the last one's id is INSTANCE-changes */

    /* The follower. */
    pthread_t thread;
    bool started;
    int stop_fd; /* eventfd: cluster_close wakes the follower's polls through it */
    atomic_bool stopping, link_up;
    atomic_bool cmd_stale;   /* the link was lost since the command connection was made */
    atomic_bool cmd_suspect; /* a command got no answer: none is sent until the subscription hears Redis again */
    atomic_uint_fast64_t link_losses;
    void (*wake)(void *ctx), (*stop)(void *ctx);
    void *wake_ctx;

    pthread_mutex_t mu; /* guards what follows */
    pthread_cond_t first_cv;
    int first;          /* the follower's first attempt: 0 pending, 1 subscribed, -1 failed */
    struct cluster_item *head, *tail;
    char last_error[320];
    char aborted[768];  /* why this daemon had to stop (cluster_node_taken), "" if it need not */
    atomic_uint_fast64_t bad[CLUSTER_BAD_COUNT]; /* cluster_bad's counts, any thread */
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

/* ---- values read from Redis ---- */

static const char *const cluster_bad_names[CLUSTER_BAD_COUNT] = {
    [CLUSTER_BAD_SEQ] = "seq", [CLUSTER_BAD_STREAM] = "stream", [CLUSTER_BAD_LEASE] = "lease",
    [CLUSTER_BAD_MESSAGE] = "message", [CLUSTER_BAD_FRAME] = "frame"};

const char *cluster_bad_name(enum cluster_bad what) { return cluster_bad_names[what]; }

void cluster_bad(struct cluster *cl, enum cluster_bad what, const char *fmt, ...)
{
    char msg[400];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    atomic_fetch_add(&cl->bad[what], 1);
    log_warn("cluster: %s", msg);
}

/* A change script repaired the counter (CLUSTER_NEXT), which held `was`. */
static void cluster_bad_counter(struct cluster *cl, const char *was)
{
    cluster_bad(cl, CLUSTER_BAD_SEQ, CLUSTER_KEY "seq in %s held %.60s, not a change number at or above the %llu "
                "this daemon has seen: set to %llu", cl->cfg.url, was, (unsigned long long)cl->seq,
                (unsigned long long)cl->seq);
}

/* A revision as Redis holds it: 1 to 10^15 - 1, in decimal digits without a leading zero. */
static bool cluster_rev(const char *s, uint64_t *rev)
{
    size_t n = strspn(s, "0123456789");
    if (s[n] || n < 1 || n > 15 || s[0] == '0') return false;
    *rev = strtoull(s, NULL, 10);
    return true;
}

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

bool cluster_closed(const redisContext *c)
{
    struct pollfd p = {.fd = c->fd, .events = POLLIN};
    return poll(&p, 1, 0) != 0; /* no answer is due: readable means end of file, a reset, or an error */
}

/* Whether a command failed because Redis closed the connection (it did not hang): errno as
 * the command left it. */
static bool cluster_peer_closed(const redisContext *c, int e)
{
    return c->err == REDIS_ERR_EOF || (c->err == REDIS_ERR_IO && (e == ECONNRESET || e == EPIPE));
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

/* A pub/sub message: "SEQ JSON", SEQ 1 to 15 digits. The messages of one subscription come in
 * the order of their numbers (each change counts and publishes at once); *heard is the last
 * one's. One that does not read, or whose number is not above the last (the counter went
 * back), is queued without its document all the same: the copy cannot follow past it, so it
 * reloads. */
static void cluster_on_message(struct cluster *cl, const char *text, size_t len, uint64_t *heard)
{
    size_t digits = strspn(text, "0123456789");
    uint64_t seq = digits >= 1 && digits <= 15 ? strtoull(text, NULL, 10) : 0;
    cJSON *doc = seq && text[digits] == ' ' ? cJSON_ParseWithLength(text + digits + 1, len - digits - 1) : NULL;
    if (!cJSON_IsObject(doc)) {
        cluster_bad(cl, CLUSTER_BAD_MESSAGE, "a message on %s does not read as a change: %.80s (reloading)", cl->channel,
                    text);
        cJSON_Delete(doc);
        doc = NULL;
    } else if (seq <= *heard) {
        cluster_bad(cl, CLUSTER_BAD_SEQ, "change %llu on %s came after change %llu: " CLUSTER_KEY "seq went back "
                    "(reloading)", (unsigned long long)seq, cl->channel, (unsigned long long)*heard);
        cJSON_Delete(doc);
        doc = NULL;
    }
    if (seq > *heard) *heard = seq;
    cluster_push(cl, CLUSTER_EVENT, seq, doc);
}

/* Handles one reply on the subscription; clears *ping when it is PING's answer. */
static void cluster_on_reply(struct cluster *cl, const redisReply *r, double *ping, uint64_t *heard)
{
    if (r->type != REDIS_REPLY_ARRAY || r->elements < 2 || r->element[0]->type != REDIS_REPLY_STRING) return;
    const char *kind = r->element[0]->str;
    if (!strcmp(kind, "pong")) *ping = 0;
    else if (!strcmp(kind, "message") && r->elements == 3 && r->element[2]->type == REDIS_REPLY_STRING)
        cluster_on_message(cl, r->element[2]->str, r->element[2]->len, heard);
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
    double ping = 0;    /* when the unanswered PING was sent; 0: none */
    uint64_t heard = 0; /* the last change number on this subscription */
    while (!atomic_load(&cl->stopping)) {
        void *reply = NULL;
        if (redisGetReplyFromReader(c, &reply) != REDIS_OK) break;
        if (reply) {
            atomic_store(&cl->cmd_suspect, false); /* Redis answers again */
            cluster_on_reply(cl, reply, &ping, &heard);
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
    snprintf(cl->done_key, sizeof cl->done_key, CLUSTER_KEY "done:%s", cfg->node_id);
    uint64_t id;
    if (getrandom(&id, sizeof id, 0) != sizeof id) id = (uint64_t)time(NULL) << 20 ^ (uint64_t)getpid();
    snprintf(cl->instance, sizeof cl->instance, "%016llx", (unsigned long long)id);
    char host[64] = "";
    if (gethostname(host, sizeof host - 1) || !host[0]) snprintf(host, sizeof host, "?");
    snprintf(cl->member, sizeof cl->member, "%s %d %s", cl->instance, (int)getpid(), host);
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

int cluster_follow(struct cluster *cl, void (*wake)(void *ctx), void (*stop)(void *ctx), void *ctx, struct fx_err *err)
{
    cl->wake = wake;
    cl->stop = stop;
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

void cluster_emptied(struct cluster *cl)
{
    if (atomic_exchange(&cl->in_sync, false))
        log_warn("cluster: %s has lost its data (no " CLUSTER_KEY "seeded: FLUSHALL, or a restart without "
                 "persistence): seeding it again", cl->cfg.url);
    if (cl->wake) cl->wake(cl->wake_ctx);
}

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
    for (int k = 0; k < CLUSTER_BAD_COUNT; k++) out->bad[k] = atomic_load(&cl->bad[k]);
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
    if (cl->cmd && cluster_closed(cl->cmd)) {
        log_info("cluster: %s closed the command connection while it was idle (its timeout, or CLIENT KILL): "
                 "reconnecting", cl->cfg.url);
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

/* Sends script s (EVALSHA, or EVAL after a SCRIPT FLUSH) on the command connection: v holds
 * the command's n words, v[1] left for the hash. NULL when the connection failed; errno then
 * says how. */
static redisReply *cluster_send(struct cluster *cl, int s, int n, const char **v)
{
    v[0] = "EVALSHA";
    v[1] = cl->sha[s];
    redisReply *r = redisCommandArgv(cl->cmd, n, v, NULL);
    if (r && r->type == REDIS_REPLY_ERROR && !strncmp(r->str, "NOSCRIPT", 8)) {
        freeReplyObject(r);
        v[0] = "EVAL";
        v[1] = cluster_scripts[s];
        r = redisCommandArgv(cl->cmd, n, v, NULL);
    }
    return r;
}

/* Runs script s with keys then args (argc of them, lens NULL: C strings): its reply, or NULL
 * with err. When Redis closed the connection under the command (CLIENT KILL, its timeout) the
 * script is sent once more on a new one: every script is safe to repeat (CLUSTER_BEGIN). A reply
 * lost otherwise (no answer in time, or the second try failed too) leaves the outcome unknown:
 * the copy goes stale. */
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
    v[2] = n;
    memcpy(v + 3, argv, sizeof *v * (size_t)argc);
    redisReply *r = cluster_send(cl, s, argc + 3, v);
    int e = errno;
    char why[256] = "";
    if (!r && cluster_peer_closed(cl->cmd, e)) {
        snprintf(why, sizeof why, "%s, and no new connection could be made", cl->cmd->errstr);
        log_info("cluster: %s closed the command connection during a change (%s): sending it again on a new one",
                 cl->cfg.url, cl->cmd->errstr);
        redisFree(cl->cmd);
        cl->cmd = NULL;
        if (!cluster_cmd(cl, &(struct fx_err){0})) {
            why[0] = 0;
            r = cluster_send(cl, s, argc + 3, v);
            e = errno;
        }
    }
    free(v);
    if (!r) {
        if (!why[0] && (e == EAGAIN || e == EWOULDBLOCK))
            snprintf(why, sizeof why, "no answer within %d s", CLUSTER_TIMEOUT_S);
        else if (!why[0])
            snprintf(why, sizeof why, "%s", cl->cmd->errstr);
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
    bool ok = (r->elements == 2 || r->elements == 3) && r->element[1]->type == REDIS_REPLY_INTEGER &&
              r->element[1]->integer > 0;
    if (ok && r->elements == 3 && r->element[2]->type == REDIS_REPLY_STRING)
        cluster_bad_counter(cl, r->element[2]->str);
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

#define CLUSTER_CHANGE_MAX_ARGS 8 /* a change script's own keys and arguments, at most */

/* Runs change script s (CLUSTER_BEGIN) with a new id, its event, the copy's change number, and
 * its own nk keys and na arguments: the reply, or NULL with err. An {'unseeded'} reply is
 * turned into err here. */
static redisReply *cluster_change(struct cluster *cl, int s, const char *event, int nk, const char *const *keys, int na,
                                  const char *const *args, struct fx_err *err)
{
    if (!event) {
        fx_fail(err, "internal", NULL, "out of memory");
        return NULL;
    }
    char id[48], floor[24];
    snprintf(id, sizeof id, "%s-%llu", cl->instance, (unsigned long long)++cl->changes);
    snprintf(floor, sizeof floor, "%llu", (unsigned long long)cl->seq);
    const char *v[7 + 2 * CLUSTER_CHANGE_MAX_ARGS];
    int n = 0;
    v[n++] = cl->done_key;
    v[n++] = CLUSTER_KEY "seeded";
    v[n++] = CLUSTER_KEY "seq";
    for (int i = 0; i < nk; i++) v[n++] = keys[i];
    v[n++] = id;
    v[n++] = event;
    v[n++] = cl->channel;
    v[n++] = floor;
    for (int i = 0; i < na; i++) v[n++] = args[i];
    redisReply *r = cluster_eval(cl, s, 3 + nk, n, v, err);
    if (r && !strcmp(cluster_outcome(r), "unseeded")) {
        freeReplyObject(r);
        cluster_emptied(cl);
        fx_fail(err, "unavailable", NULL, "cluster: %s has lost its data (emptied by FLUSHALL, or restarted without "
                "persistence); this daemon seeds it again with the cluster's streams: try again (nothing changed)",
                cl->cfg.url);
        return NULL;
    }
    return r;
}

int cluster_create(struct cluster *cl, const char *stream, const char *effect, const cJSON *params, int max_streams,
                   struct fx_err *err)
{
    if (cluster_writable(cl, err)) return -1;
    char key[128], max[16];
    cluster_key(key, sizeof key, stream);
    snprintf(max, sizeof max, "%d", max_streams);
    char *doc = cJSON_PrintUnformatted(params), *ev = doc ? cluster_event(cl, "created", stream, effect, 1, params) : NULL;
    redisReply *r = cluster_change(cl, CS_CREATE, ev, 2, (const char *[]){key, CLUSTER_KEY "streams"}, 4,
                                   (const char *[]){stream, effect, doc, max}, err);
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

/* A 'moved' reply's current document into cur: 1. When it does not read as one (a revision
 * out of range, params that are not a JSON object), it is counted, the copy goes stale (its
 * reload repairs the revision, replica.c) and the set is refused: -1 with err. */
static int cluster_moved(struct cluster *cl, const char *stream, const redisReply *r, struct cluster_current *cur,
                         struct fx_err *err)
{
    bool ok = r->elements == 4;
    for (size_t i = 1; ok && i < 4; i++) ok = r->element[i]->type == REDIS_REPLY_STRING;
    if (ok) {
        snprintf(cur->effect, sizeof cur->effect, "%s", r->element[1]->str);
        cur->params = cJSON_ParseWithLength(r->element[3]->str, r->element[3]->len);
        ok = cluster_rev(r->element[2]->str, &cur->rev) && cJSON_IsObject(cur->params);
    }
    if (ok) return 1;
    cJSON_Delete(cur->params);
    cur->params = NULL;
    cl->in_sync = false;
    cluster_bad(cl, CLUSTER_BAD_STREAM, "stream %s in %s has a revision or parameters that do not read (rev %.24s): "
                "the copy is reloaded, which repairs the revision", stream, cl->cfg.url,
                r->elements == 4 && r->element[2]->type == REDIS_REPLY_STRING ? r->element[2]->str : "missing");
    return fx_fail(err, "unavailable", NULL, "cluster: stream %s in %s did not read as a stream; this daemon reloads "
                   "the state from Redis and repairs it: try again (nothing changed)", stream, cl->cfg.url);
}

int cluster_set(struct cluster *cl, const char *stream, const char *effect, uint64_t base, const cJSON *params,
                struct cluster_current *cur, struct fx_err *err)
{
    if (cluster_writable(cl, err)) return -1;
    char key[128], from[24], to[24];
    cluster_key(key, sizeof key, stream);
    snprintf(from, sizeof from, "%llu", (unsigned long long)base);
    snprintf(to, sizeof to, "%llu", (unsigned long long)base + 1);
    char *doc = cJSON_PrintUnformatted(params);
    char *ev = doc ? cluster_event(cl, "params", stream, effect, base + 1, params) : NULL;
    redisReply *r = cluster_change(cl, CS_SET, ev, 1, (const char *[]){key}, 4, (const char *[]){effect, from, to, doc},
                                   err);
    cJSON_free(doc);
    cJSON_free(ev);
    if (!r) return -1;
    const char *o = cluster_outcome(r);
    if (!strcmp(o, "ok")) return cluster_done(cl, r, err);
    int rc = !strcmp(o, "moved") ? cluster_moved(cl, stream, r, cur, err) : cluster_gone(stream, err);
    freeReplyObject(r);
    return rc;
}

/* A destroy or a reset (script s, the event's op): both only need the stream to exist. */
static int cluster_stream_change(struct cluster *cl, int s, const char *op, const char *stream, struct fx_err *err)
{
    if (cluster_writable(cl, err)) return -1;
    char key[128], *ev = cluster_event(cl, op, stream, NULL, 0, NULL);
    cluster_key(key, sizeof key, stream);
    redisReply *r = cluster_change(cl, s, ev, 2, (const char *[]){key, CLUSTER_KEY "streams"}, 1,
                                   (const char *[]){stream}, err);
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
    int n = cJSON_GetArraySize(streams), argc = 8 + 4 * n, i = 0;
    const char **v = calloc((size_t)argc, sizeof *v);
    struct { char rev[24]; char *doc; } *a = calloc((size_t)n + 1, sizeof *a);
    char *ev = cluster_event(cl, "seeded", NULL, NULL, 0, NULL), floor[24];
    snprintf(floor, sizeof floor, "%llu", (unsigned long long)cl->seq);
    bool ok = v && a && ev;
    if (ok) {
        const char *head[] = {CLUSTER_KEY "seeded", CLUSTER_KEY "streams", CLUSTER_KEY "seq", cl->cfg.node_id,
                              CLUSTER_KEY "stream:", ev, cl->channel, floor};
        memcpy(v, head, sizeof head);
    }
    for (const cJSON *s = streams->child; ok && s; s = s->next, i++) {
        const char **p = v + 8 + 4 * i;
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

/* One stream of CS_LOAD's reply (name, effect, rev, params at e), or NULL when it is not one
 * (counted, left out). A revision that does not read as one comes as "bad_rev" (as read)
 * instead of "rev", for the caller to repair. */
static cJSON *cluster_load_entry(struct cluster *cl, redisReply *const *e)
{
    for (int i = 0; i < 4; i++)
        if (e[i]->type != REDIS_REPLY_STRING) return NULL;
    uint64_t rev;
    bool rev_ok = cluster_rev(e[2]->str, &rev);
    cJSON *params = cJSON_ParseWithLength(e[3]->str, e[3]->len);
    if (!e[1]->str[0] || !cJSON_IsObject(params)) {
        cluster_bad(cl, CLUSTER_BAD_STREAM, "stream %.64s in %s is not a stream definition (effect \"%.24s\", params "
                    "\"%.24s\"): left out", e[0]->str, cl->cfg.url, e[1]->str, e[3]->str);
        cJSON_Delete(params);
        return NULL;
    }
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "stream", e[0]->str);
    cJSON_AddStringToObject(o, "effect", e[1]->str);
    if (rev_ok) cJSON_AddNumberToObject(o, "rev", (double)rev);
    else cJSON_AddStringToObject(o, "bad_rev", e[2]->str);
    cJSON_AddItemToObject(o, "params", params);
    return o;
}

int cluster_load(struct cluster *cl, cJSON **streams, uint64_t *seq, struct fx_err *err)
{
    char floor[24];
    snprintf(floor, sizeof floor, "%llu", (unsigned long long)cl->seq);
    redisReply *r = cluster_eval(cl, CS_LOAD, 3, 5,
                                 (const char *[]){CLUSTER_KEY "streams", CLUSTER_KEY "seq", CLUSTER_KEY "seeded",
                                                  CLUSTER_KEY "stream:", floor}, err);
    if (!r) return -1;
    const char *o = cluster_outcome(r);
    if (!strcmp(o, "unseeded")) {
        freeReplyObject(r);
        return 1;
    }
    if (strcmp(o, "ok") || r->elements % 4 != 3 || r->element[1]->type != REDIS_REPLY_INTEGER ||
        r->element[1]->integer < 0 || r->element[2]->type != REDIS_REPLY_STRING) {
        freeReplyObject(r);
        return fx_fail(err, "internal", NULL, "cluster: unexpected answer from %s", cl->cfg.url);
    }
    if (r->element[2]->str[0]) cluster_bad_counter(cl, r->element[2]->str);
    *seq = (uint64_t)r->element[1]->integer;
    *streams = cJSON_CreateArray();
    for (size_t i = 3; i < r->elements; i += 4) {
        cJSON *e = cluster_load_entry(cl, r->element + i);
        if (e) cJSON_AddItemToArray(*streams, e);
    }
    freeReplyObject(r);
    return 0;
}

int cluster_repair_rev(struct cluster *cl, const char *stream, const char *effect, const char *bad, uint64_t rev,
                       const cJSON *params, struct fx_err *err)
{
    char key[128], to[24];
    cluster_key(key, sizeof key, stream);
    snprintf(to, sizeof to, "%llu", (unsigned long long)rev);
    char *ev = cluster_event(cl, "params", stream, effect, rev, params);
    redisReply *r = cluster_change(cl, CS_REPAIR, ev, 1, (const char *[]){key}, 2, (const char *[]){bad, to}, err);
    cJSON_free(ev);
    if (!r) return -1;
    bool made = !strcmp(cluster_outcome(r), "ok");
    cluster_bad(cl, CLUSTER_BAD_STREAM, "stream %s in %s had rev \"%.24s\", not a revision: %s", stream, cl->cfg.url,
                bad, made ? "set to the one this daemon had, + 1" : "it changed meanwhile");
    if (made) {
        if (r->elements == 3 && r->element[2]->type == REDIS_REPLY_STRING) cluster_bad_counter(cl, r->element[2]->str);
        cl->in_sync = false; /* the caller loads again */
    }
    freeReplyObject(r);
    return 0;
}

/* ---- this daemon's node id ---- */

const char *cluster_member(const struct cluster *cl) { return cl->member; }

/* Who holds a node id, from its claim ("INSTANCE PID HOST"), for people. */
static void cluster_holder(const char *claim, char *out, size_t cap)
{
    char host[64];
    int pid;
    if (sscanf(claim, "%*16[0-9a-f] %d %63s", &pid, host) == 2) snprintf(out, cap, "pid %d on host %s", pid, host);
    else snprintf(out, cap, "claim \"%.40s\"", claim);
}

/* How a node id is named in messages: the default one says where it came from. */
static const char *cluster_node_origin(const struct cluster *cl)
{
    return cl->cfg.node_id_default ? " (the host name)" : "";
}

int cluster_claim(struct cluster *cl, struct fx_err *err)
{
    char key[96], ttl[16], who[128];
    snprintf(key, sizeof key, CLUSTER_KEY "member:%s", cl->cfg.node_id);
    snprintf(ttl, sizeof ttl, "%d", (int)(CLUSTER_MEMBER_TTL_S * 1000));
    double deadline = clock_now() + CLUSTER_MEMBER_TTL_S + 1.0;
    long long last = -1; /* the claim's time left at the previous look */
    for (;;) {
        redisReply *r = cluster_eval(cl, CS_CLAIM, 1, 3, (const char *[]){key, cl->member, ttl}, err);
        if (!r) return -1;
        bool held = !strcmp(cluster_outcome(r), "held") && r->elements == 3 &&
                    r->element[1]->type == REDIS_REPLY_STRING && r->element[2]->type == REDIS_REPLY_INTEGER;
        long long left = held ? r->element[2]->integer : 0;
        if (held) cluster_holder(r->element[1]->str, who, sizeof who);
        if (!held && r->elements == 2 && r->element[1]->type == REDIS_REPLY_STRING)
            cluster_bad(cl, CLUSTER_BAD_LEASE, "%s in %s held %s, not a daemon's claim: replaced", key, cl->cfg.url,
                        r->element[1]->str);
        freeReplyObject(r);
        if (!held) return 0;
        if (left > last && last >= 0) /* renewed since the last look: its daemon runs */
            return fx_fail(err, "exists", "node-id", "cluster: node id \"%s\"%s is in use by another running fxstreamd "
                           "(%s) on %s: give each daemon its own --node-id", cl->cfg.node_id, cluster_node_origin(cl),
                           who, cl->cfg.url);
        if (clock_now() > deadline)
            return fx_fail(err, "exists", "node-id", "cluster: node id \"%s\"%s is still held by another fxstreamd "
                           "(%s) on %s after %.0f s: give each daemon its own --node-id", cl->cfg.node_id,
                           cluster_node_origin(cl), who, cl->cfg.url, CLUSTER_MEMBER_TTL_S + 1.0);
        if (last < 0)
            log_info("cluster: node id %s is held by %s (%lld ms left): waiting to see whether it is renewed",
                     cl->cfg.node_id, who, left);
        last = left;
        cluster_pause(cl, CLUSTER_CLAIM_LOOK_S);
    }
}

void cluster_node_taken(struct cluster *cl, const char *claim)
{
    char who[128];
    cluster_holder(claim, who, sizeof who);
    pthread_mutex_lock(&cl->mu);
    bool first = !cl->aborted[0];
    if (first)
        snprintf(cl->aborted, sizeof cl->aborted, "cluster: node id \"%s\"%s was taken by another fxstreamd (%s) "
                 "while this daemon could not renew it (paused, or cut off from %s, for more than %.0f s); two "
                 "daemons must not share a node id", cl->cfg.node_id, cluster_node_origin(cl), who, cl->cfg.url,
                 CLUSTER_MEMBER_TTL_S);
    pthread_mutex_unlock(&cl->mu);
    if (!first) return;
    log_error("%s: stopping", cl->aborted);
    if (cl->stop) cl->stop(cl->wake_ctx);
}

bool cluster_aborted(struct cluster *cl, char *why, size_t cap)
{
    pthread_mutex_lock(&cl->mu);
    bool aborted = cl->aborted[0];
    snprintf(why, cap, "%s", cl->aborted);
    pthread_mutex_unlock(&cl->mu);
    return aborted;
}
