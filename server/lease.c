/* lease.c — see lease.h. */
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <hiredis/hiredis.h>

#include "clock.h"
#include "cluster.h"
#include "fxs_bytes.h"
#include "lease.h"
#include "log.h"

#define LEASE_MARGIN_S 0.5      /* a lease counts as held locally until TTL - this after its renewal was sent */
#define LEASE_STREAM_COST "0.05" /* load added per lease held (spreads idle streams, breaks ties) */
#define LEASE_RETRY_S 1.0       /* after a failed connection, the next try waits this long */
#define LEASE_LOG_S 10.0        /* a script Redis keeps refusing (e.g. out of memory) is logged this often */

enum { LS_TICK, LS_PUBLISH, LS_RELEASE, LS_COUNT };

/* Lua shared by the tick and the publisher: lease_ok(k, v) says whether v, read at k, is a
 * lease: "GEN NODE" with a TTL of at most ttl. Anything else (no expiry, another form, another
 * type) is no lease: nobody holds the stream, and the tick that finds it takes its place. */
#define LEASE_LUA_OK                                                                     \
    CLUSTER_LUA_LIB                                                                      \
    "local function lease_ok(k, v)\n"                                                    \
    "  if not v or #v > 96 or not string.match(v, '^%d+ [%w_.%-]+$') then return false end\n" \
    "  local left = redis.call('PTTL', k)\n"                                             \
    "  return left > 0 and left <= ttl\n"                                                \
    "end\n"                                                                              \
    "local function digits(v) return v and #v <= 15 and string.match(v, '^%d+$') and tonumber(v) end\n"

static const char *const lease_scripts[LS_COUNT] = {
    /* ARGV node, compute (1/0), load, ttl ms, this daemon's claim on its node id and its ttl ms
     * (cluster.h), then n + (name, field) wanted here (field: the node, for subscribers of the
     * default encoding, or NODE|engine), n + (name, token) of the leases held, n + the names this
     * daemon could compute. The claim is renewed first: when another daemon holds the node id,
     * nothing else is done and the reply is {{'node_taken', claim}}. A lease held is kept while
     * nobody else has taken it; it is written again once its stream exists (a Redis that lost its
     * data is seeded again by the daemons a moment later: no stream changes owner then, and
     * fxs:leasegen is raised to the generations held). Returns {'unseeded'} first when Redis lost
     * its data (no fxs:seeded), then one entry per held or taken lease: {'held', name, token,
     * demand} {'lost', name} {'taken', name, token, demand, head1, head2, head3, head4, head1e,
     * head2e} (demand: the encodings other daemons want, bit 0 the default, bit 1 the engine
     * encoding; headK: the first 24 bytes of the latest frame of kind K, or ""; headKe: of the
     * latest engine-encoded one), and {'bad', key, value as read, what was done} per value that
     * was not what this script writes (lease_ok, a demand's expiry, a start time or generation
     * that is not a number, a claim that is not one). */
    [LS_TICK] =
        "local P, node, compute, ttl = '" CLUSTER_KEY "', ARGV[1], ARGV[2] == '1', tonumber(ARGV[4])\n"
        LEASE_LUA_OK
        "local t = redis.call('TIME')\n"
        "local now = tonumber(t[1]) * 1000 + math.floor(tonumber(t[2]) / 1000)\n"
        "local out, held = {}, 0\n"
        "local function bad(k, v, vt, done) out[#out + 1] = {'bad', k, fxs_show(v, vt), done} end\n"
        "local mk = P .. 'member:' .. node\n"
        "local mv, mt = fxs_get(mk)\n"
        "if mv ~= false and mv ~= ARGV[5] then\n"
        "  local left = redis.call('PTTL', mk)\n"
        "  if mv and string.match(mv, '^%x+ %d+ %S+$') and left > 0 and left <= tonumber(ARGV[6]) then\n"
        "    return {{'node_taken', mv}}\n"
        "  end\n"
        "  bad(mk, mv, mt, 'replaced by this daemon\\'s claim')\n"
        "end\n"
        "redis.call('SET', mk, ARGV[5], 'PX', ARGV[6])\n"
        "if redis.call('EXISTS', P .. 'seeded') == 0 then table.insert(out, 1, {'unseeded'}) end\n"
        "local i = 7\n"
        "for _ = 1, tonumber(ARGV[i]) do\n"
        "  local w, f = P .. 'want:' .. ARGV[i + 1], ARGV[i + 2]\n"
        "  i = i + 2\n"
        "  local r = redis.pcall('HSET', w, f, now + ttl)\n"
        "  if type(r) == 'table' and r.err then\n"
        "    bad(w, nil, redis.call('TYPE', w).ok, 'removed')\n"
        "    redis.call('DEL', w)\n"
        "    redis.call('HSET', w, f, now + ttl)\n"
        "  end\n"
        "  redis.call('PEXPIRE', w, ttl)\n"
        "end\n"
        "local function demand(name)\n"
        "  local w, d = P .. 'want:' .. name, 0\n"
        "  local h = redis.pcall('HGETALL', w)\n"
        "  if h.err then return 0 end\n"
        "  for j = 1, #h, 2 do\n"
        "    local e = digits(h[j + 1])\n"
        "    if not e or e > now + ttl then\n"
        "      bad(w .. ' ' .. h[j], h[j + 1], nil, 'removed')\n"
        "      redis.call('HDEL', w, h[j])\n"
        "    elseif h[j] ~= node and h[j] ~= node .. '|engine' and e > now then\n"
        "      d = bit.bor(d, string.sub(h[j], -7) == '|engine' and 2 or 1)\n"
        "    end\n"
        "  end\n"
        "  return d\n"
        "end\n"
        "local gk = P .. 'leasegen'\n"
        "local g, gt = fxs_get(gk)\n"
        "if g ~= false and not digits(g) then bad(gk, g, gt, 'set to 0'); redis.call('SET', gk, '0') end\n"
        "i = i + 1\n"
        "for _ = 1, tonumber(ARGV[i]) do\n"
        "  local name, token = ARGV[i + 1], ARGV[i + 2]\n"
        "  i = i + 2\n"
        "  local k = P .. 'lease:' .. name\n"
        "  local v, vt = fxs_get(k)\n"
        "  if v ~= false and v ~= token and not lease_ok(k, v) then bad(k, v, vt, 'replaced by this daemon\\'s lease'); v = false end\n"
        "  if v == token or not v then\n"
        "    if redis.call('EXISTS', P .. 'stream:' .. name) == 1 then\n"
        "      local gen = tonumber(string.match(token, '^%d+'))\n"
        "      if not v and (digits(fxs_get(gk)) or 0) < gen then redis.call('SET', gk, string.format('%d', gen)) end\n"
        "      redis.call('SET', k, token, 'PX', ttl)\n"
        "    end\n"
        "    held = held + 1\n"
        "    local d = demand(name)\n"
        "    out[#out + 1] = {'held', name, token, d}\n"
        "  else\n"
        "    out[#out + 1] = {'lost', name}\n"
        "  end\n"
        "end\n"
        "i = i + 1\n"
        "if not compute then return out end\n"
        "local nk = P .. 'node:' .. node\n"
        "local sv, st = fxs_get(nk)\n"
        "local since = digits(sv)\n"
        "if sv ~= false and (not since or since > now) then bad(nk, sv, st, 'set to now'); since = nil end\n"
        "since = since or now\n"
        "redis.call('SET', nk, string.format('%d', since), 'PX', ttl)\n"
        "local score = tonumber(ARGV[3]) + " LEASE_STREAM_COST " * held\n"
        "redis.call('ZADD', P .. 'computes', score, node)\n"
        "if now - since < ttl then return out end\n"
        "local least = nil\n"
        "local all = redis.call('ZRANGE', P .. 'computes', 0, -1, 'WITHSCORES')\n"
        "for j = 1, #all, 2 do\n"
        "  if all[j] ~= node then\n"
        "    if redis.call('EXISTS', P .. 'node:' .. all[j]) == 1 then\n"
        "      local s = tonumber(all[j + 1])\n"
        "      if not least or s < least then least = s end\n"
        "    else redis.call('ZREM', P .. 'computes', all[j]) end\n"
        "  end\n"
        "end\n"
        "for _ = 1, tonumber(ARGV[i]) do\n"
        "  i = i + 1\n"
        "  if least and score > least then break end\n"
        "  local name = ARGV[i]\n"
        "  local k = P .. 'lease:' .. name\n"
        "  local v, vt = fxs_get(k)\n"
        "  if v ~= false and not lease_ok(k, v) then bad(k, v, vt, 'replaced by a new lease'); v = false end\n"
        "  if not v and redis.call('EXISTS', P .. 'stream:' .. name) == 1 then\n"
        "    local token = redis.call('INCR', gk) .. ' ' .. node\n"
        "    redis.call('SET', k, token, 'PX', ttl)\n"
        "    local e = {'taken', name, token, demand(name)}\n"
        "    for kind = 1, 4 do e[#e + 1] = redis.call('GETRANGE', P .. 'frame:' .. name .. ':' .. kind, 0, 23) end\n"
        "    for kind = 1, 2 do e[#e + 1] = redis.call('GETRANGE', P .. 'frame:' .. name .. ':' .. kind .. ':engine', 0, 23) end\n"
        "    out[#out + 1] = e\n"
        "    score = score + " LEASE_STREAM_COST "\n"
        "    redis.call('ZADD', P .. 'computes', score, node)\n"
        "  end\n"
        "end\n"
        "return out\n",
    /* KEYS lease, latest frame; ARGV token, channel, frame, ttl ms. 1: published; 0: another
     * daemon holds the lease now; -1: nobody does (a Redis that lost its data, or a value that
     * is no lease: the next tick writes it again, or says it was lost). */
    [LS_PUBLISH] = "local ttl = tonumber(ARGV[4])\n"
                   LEASE_LUA_OK
                   "local v = fxs_get(KEYS[1])\n"
                   "if v ~= ARGV[1] then return lease_ok(KEYS[1], v) and 0 or -1 end\n"
                   "redis.call('SET', KEYS[2], ARGV[3])\n"
                   "redis.call('PUBLISH', ARGV[2], ARGV[3])\n"
                   "return 1\n",
    /* ARGV node, its claim, then (name, token) of the leases held: each still ours is given up,
     * so another daemon takes the stream at its next tick instead of after the TTL; so is the
     * node id, so a daemon started again with it need not wait for the claim to expire. */
    [LS_RELEASE] = "local P = '" CLUSTER_KEY "'\n"
                   "redis.call('DEL', P .. 'node:' .. ARGV[1])\n"
                   "redis.call('ZREM', P .. 'computes', ARGV[1])\n"
                   "if redis.call('GET', P .. 'member:' .. ARGV[1]) == ARGV[2] then redis.call('DEL', P .. 'member:' .. ARGV[1]) end\n"
                   "for i = 3, #ARGV, 2 do\n"
                   "  if redis.call('GET', P .. 'lease:' .. ARGV[i]) == ARGV[i + 1] then redis.call('DEL', P .. 'lease:' .. ARGV[i]) end\n"
                   "end\n"
                   "return 1\n",
};

/* A frame waiting to be published: the newest of its stream and kind. */
struct lease_out {
    struct stream *s;
    uint64_t gen;
    struct frame *f;
};

struct lease {
    struct server *srv;
    const struct cluster_config *cfg;
    pthread_t thread;
    bool started;

    /* The agent's. */
    redisContext *c;
    double retry_at, busy_t, error_logged; /* error_logged: Redis's refusals are logged every LEASE_LOG_S */
    uint64_t busy_ns;
    bool node_taken; /* another daemon holds this node id now: this one stops, touching nothing in Redis */

    pthread_mutex_t mu; /* guards what follows */
    pthread_cond_t cv;
    bool stopping;
    struct lease_out *out;
    int nout, capout;
};

/* ---- Redis ---- */

static void lease_drop_conn(struct lease *l, const char *why)
{
    if (l->c) log_warn("cluster: lease agent lost %s: %s", l->cfg->url, why);
    redisFree(l->c);
    l->c = NULL;
    l->retry_at = clock_now() + LEASE_RETRY_S;
}

static bool lease_conn(struct lease *l)
{
    if (l->c && cluster_closed(l->c)) {
        log_info("cluster: %s closed the lease agent's connection (its timeout, or CLIENT KILL): reconnecting", l->cfg->url);
        redisFree(l->c);
        l->c = NULL;
        l->retry_at = 0;
    }
    if (l->c) return true;
    if (clock_now() < l->retry_at) return false;
    char why[256];
    if (!(l->c = cluster_dial(l->srv->cluster, why, sizeof why))) {
        l->retry_at = clock_now() + LEASE_RETRY_S;
        log_debug("cluster: lease agent cannot reach %s: %s", l->cfg->url, why);
    }
    return l->c != NULL;
}

/* Runs script s (EVAL: the scripts are short, and a restarted Redis needs no reloading);
 * NULL after a connection failure (dropped) or an error reply (logged). */
static redisReply *lease_eval(struct lease *l, int s, int nkeys, int argc, const char **argv, const size_t *lens)
{
    if (!lease_conn(l)) return NULL;
    int n = argc + 3;
    const char **v = malloc(sizeof *v * (size_t)n);
    size_t *vl = malloc(sizeof *vl * (size_t)n);
    char nk[8];
    snprintf(nk, sizeof nk, "%d", nkeys);
    redisReply *r = NULL;
    if (v && vl) {
        v[0] = "EVAL", v[1] = lease_scripts[s], v[2] = nk;
        for (int i = 0; i < 3; i++) vl[i] = strlen(v[i]);
        for (int i = 0; i < argc; i++) v[3 + i] = argv[i], vl[3 + i] = lens ? lens[i] : strlen(argv[i]);
        r = redisCommandArgv(l->c, n, v, vl);
    }
    free(v);
    free(vl);
    if (!r) lease_drop_conn(l, l->c->errstr[0] ? l->c->errstr : "no answer");
    else if (r->type == REDIS_REPLY_ERROR) {
        if (clock_now() - l->error_logged >= LEASE_LOG_S) {
            log_error("cluster: %s refused a lease script: %s", l->cfg->url, r->str);
            l->error_logged = clock_now();
        }
        freeReplyObject(r);
        r = NULL;
    }
    return r;
}

/* ---- the tick ---- */

/* The arguments of one tick, from the hub. */
struct lease_args {
    const char **v;
    char (*tokens)[96];
    char counts[3][16], load[32], ttl[16], member_ttl[16], engine_field[STREAM_NAME_MAX + 8];
    int n;
};

static void lease_token(char *out, size_t cap, uint64_t gen, const char *node)
{
    snprintf(out, cap, "%llu %s", (unsigned long long)gen, node);
}

/* The engine's busy fraction since the last call. */
static double lease_load(struct lease *l)
{
    double now = clock_now();
    uint64_t ns = atomic_load(&l->srv->engine.busy_ns);
    double load = l->busy_t > 0 && now > l->busy_t ? (double)(ns - l->busy_ns) * 1e-9 / (now - l->busy_t) : 0;
    l->busy_t = now;
    l->busy_ns = ns;
    return load;
}

static int lease_args_build(struct lease *l, struct stream **ss, int n, struct lease_args *a)
{
    bool compute = l->cfg->role != CLUSTER_ROLE_EDGE;
    a->v = calloc((size_t)(9 + 7 * n), sizeof *a->v);
    a->tokens = calloc((size_t)n + 1, sizeof *a->tokens);
    if (!a->v || !a->tokens) return -1;
    snprintf(a->load, sizeof a->load, "%.4f", compute ? lease_load(l) : 0.0);
    snprintf(a->ttl, sizeof a->ttl, "%d", (int)(LEASE_TTL_S * 1000));
    snprintf(a->member_ttl, sizeof a->member_ttl, "%d", (int)(CLUSTER_MEMBER_TTL_S * 1000));
    a->v[a->n++] = l->cfg->node_id;
    a->v[a->n++] = compute ? "1" : "0";
    a->v[a->n++] = a->load;
    a->v[a->n++] = a->ttl;
    a->v[a->n++] = cluster_member(l->srv->cluster);
    a->v[a->n++] = a->member_ttl;
    struct stream_status st[n > 0 ? n : 1];
    for (int i = 0; i < n; i++) hub_status(&l->srv->hub, ss[i], &st[i]);
    int at = a->n++, k = 0; /* wanted here, per encoding */
    snprintf(a->engine_field, sizeof a->engine_field, "%s|engine", l->cfg->node_id);
    for (int i = 0; i < n; i++) {
        if (st[i].subscribers_by[budget_form(FXS_ENCODING_DEFAULT, 0)] > 0)
            a->v[a->n++] = ss[i]->name, a->v[a->n++] = l->cfg->node_id, k++;
        if (st[i].subscribers_by[budget_form(FXS_ENCODING_ENGINE, 0)] > 0)
            a->v[a->n++] = ss[i]->name, a->v[a->n++] = a->engine_field, k++;
    }
    snprintf(a->counts[0], sizeof a->counts[0], "%d", k);
    a->v[at] = a->counts[0];
    at = a->n++, k = 0; /* held */
    for (int i = 0; i < n; i++)
        if (st[i].lease.owned) {
            lease_token(a->tokens[k], sizeof a->tokens[k], st[i].lease.gen, l->cfg->node_id);
            a->v[a->n++] = ss[i]->name;
            a->v[a->n++] = a->tokens[k++];
        }
    snprintf(a->counts[1], sizeof a->counts[1], "%d", k);
    a->v[at] = a->counts[1];
    snprintf(a->counts[2], sizeof a->counts[2], "%d", compute ? n : 0); /* could compute */
    a->v[a->n++] = a->counts[2];
    for (int i = 0; compute && i < n; i++) a->v[a->n++] = ss[i]->name;
    return 0;
}

static uint64_t lease_gen_of(const char *token) { return strtoull(token, NULL, 10); }

/* A tick's demand: the encodings other daemons want (the script's bits 1 << enum fxs_encoding),
 * as the forms of their full frames (bits 1 << form, budget.h; budgets are not offered in
 * cluster mode). */
static unsigned lease_demand(const redisReply *r)
{
    unsigned forms = 0;
    for (int e = 0; e < FXS_ENCODING_COUNT && r->type == REDIS_REPLY_INTEGER; e++)
        if (r->integer >> e & 1) forms |= 1u << budget_form((enum fxs_encoding)e, 0);
    return forms;
}

/* The number of the latest frame of kind k in encoding enc in Redis, from its first 24 bytes
 * (h): a taken stream's frames go on from there. 0 when there is none, or it is not a frame of
 * that kind (counted) or its number is past CLUSTER_SEQ_MAX (counted: not trusted). */
static uint64_t lease_seq_from(struct lease *l, const char *name, int k, enum fxs_encoding enc, const redisReply *h)
{
    if (h->type != REDIS_REPLY_STRING || h->len == 0) return 0;
    const uint8_t *b = (const uint8_t *)h->str;
    uint64_t seq = h->len == 24 ? fxs_get_u64(b + 16) : 0;
    if (h->len == 24 && !memcmp(b, FXS_MAGIC, 4) && fxs_get_u16(b + 6) == k && seq < CLUSTER_SEQ_MAX) return seq;
    cluster_bad(l->srv->cluster, CLUSTER_BAD_FRAME, CLUSTER_KEY "frame:%s:%d%s in %s is not a frame of that kind, or "
                "its number is out of range: the stream's frames are numbered from 1", name, k,
                enc == FXS_ENCODING_ENGINE ? ":engine" : "", l->cfg->url);
    return 0;
}

/* One entry of the tick's reply, into the hub. */
static void lease_apply(struct lease *l, const redisReply *e, double until)
{
    if (e->type != REDIS_REPLY_ARRAY || e->elements < 2) return;
    for (size_t i = 0; i < e->elements; i++)
        if (e->element[i]->type != REDIS_REPLY_STRING && e->element[i]->type != REDIS_REPLY_INTEGER) return;
    const char *what = e->element[0]->str, *name = e->element[1]->str;
    struct stream *s = hub_find(&l->srv->hub, name);
    if (!s) return;
    struct stream_status st;
    hub_status(&l->srv->hub, s, &st);
    struct stream_lease nl = st.lease;
    struct counters *c = &l->srv->counters;
    if (!strcmp(what, "lost") && nl.owned) {
        nl = (struct stream_lease){0};
        atomic_fetch_add(&c->cluster_leases_lost, 1);
        log_warn("cluster: stream %s: lost its lease (another daemon computes it now)", name);
    } else if (!strcmp(what, "held") && e->elements == 4) {
        nl.until = until;
        nl.remote_demand = lease_demand(e->element[3]);
    } else if (!strcmp(what, "taken") && e->elements == 10) {
        nl = (struct stream_lease){.owned = true, .gen = lease_gen_of(e->element[2]->str), .until = until,
                                   .remote_demand = lease_demand(e->element[3])};
        for (int k = 1; k <= FXS_KIND_MAX; k++) { /* on from the newest of either encoding */
            nl.seq_from[k] = lease_seq_from(l, name, k, FXS_ENCODING_DEFAULT, e->element[3 + k]);
            uint64_t engine = fxs_kind_has_engine_form(k)
                                  ? lease_seq_from(l, name, k, FXS_ENCODING_ENGINE, e->element[7 + k]) : 0;
            if (engine > nl.seq_from[k]) nl.seq_from[k] = engine;
        }
        atomic_fetch_add(&c->cluster_leases_taken, 1);
        log_info("cluster: stream %s: took its lease (generation %llu)", name, (unsigned long long)nl.gen);
    }
    hub_set_lease(&l->srv->hub, s, &nl);
    stream_unref(s);
}

/* Redis did not answer: the leases held stay held (lease.h) until it does. */
static void lease_keep_all(struct lease *l, struct stream **ss, int n)
{
    for (int i = 0; i < n; i++) {
        struct stream_status st;
        hub_status(&l->srv->hub, ss[i], &st);
        if (!st.lease.owned || isinf(st.lease.until)) continue;
        st.lease.until = INFINITY;
        hub_set_lease(&l->srv->hub, ss[i], &st.lease);
    }
}

/* Another daemon holds this node id: this one computes nothing more and stops (cluster.h). */
static void lease_node_taken(struct lease *l, struct stream **ss, int n, const char *claim)
{
    l->node_taken = true;
    for (int i = 0; i < n; i++) {
        struct stream_status st;
        hub_status(&l->srv->hub, ss[i], &st);
        if (st.lease.owned) hub_set_lease(&l->srv->hub, ss[i], &(struct stream_lease){0});
    }
    cluster_node_taken(l->srv->cluster, claim);
}

/* One entry of the tick's reply. */
static void lease_entry(struct lease *l, const redisReply *e, struct stream **ss, int n, double until)
{
    const char *what = e->type == REDIS_REPLY_ARRAY && e->elements && e->element[0]->type == REDIS_REPLY_STRING
                           ? e->element[0]->str : "";
    if (!strcmp(what, "node_taken") && e->elements == 2 && e->element[1]->type == REDIS_REPLY_STRING)
        lease_node_taken(l, ss, n, e->element[1]->str);
    else if (!strcmp(what, "unseeded"))
        cluster_emptied(l->srv->cluster);
    else if (!strcmp(what, "bad") && e->elements == 4 && e->element[1]->type == REDIS_REPLY_STRING &&
             e->element[2]->type == REDIS_REPLY_STRING && e->element[3]->type == REDIS_REPLY_STRING)
        cluster_bad(l->srv->cluster, CLUSTER_BAD_LEASE, "%s in %s held %s, not what the daemons write: %s",
                    e->element[1]->str, l->cfg->url, e->element[2]->str, e->element[3]->str);
    else
        lease_apply(l, e, until);
}

static void lease_tick(struct lease *l)
{
    if (l->node_taken) return;
    int n;
    struct stream **ss = hub_snapshot(&l->srv->hub, &n);
    struct lease_args a = {0};
    double sent = clock_now();
    redisReply *r = lease_args_build(l, ss, n, &a) ? NULL : lease_eval(l, LS_TICK, 0, a.n, a.v, NULL);
    if (!r) lease_keep_all(l, ss, n);
    for (size_t i = 0; r && r->type == REDIS_REPLY_ARRAY && i < r->elements && !l->node_taken; i++)
        lease_entry(l, r->element[i], ss, n, sent + LEASE_TTL_S - LEASE_MARGIN_S);
    freeReplyObject(r);
    free(a.v);
    free(a.tokens);
    hub_release_all(ss, n);
}

/* ---- frames ---- */

static enum fxs_encoding lease_encoding(const struct frame *f) { return fxs_frame_encoding(f->hdr.kind, f->hdr.codec); }

void lease_export(void *ctx, struct stream *s, uint64_t lease_gen, struct frame *f)
{
    struct lease *l = ctx;
    pthread_mutex_lock(&l->mu);
    int i = 0;
    while (i < l->nout && !(l->out[i].s == s && l->out[i].f->hdr.kind == f->hdr.kind &&
                            lease_encoding(l->out[i].f) == lease_encoding(f)))
        i++;
    if (i == l->nout && l->nout == l->capout) {
        int cap = l->capout ? 2 * l->capout : 16;
        struct lease_out *p = realloc(l->out, (size_t)cap * sizeof *p);
        if (p) l->out = p, l->capout = cap;
    }
    if (i < l->nout) { /* not yet published: the newer frame replaces it */
        frame_unref(l->out[i].f);
        l->out[i].f = f;
        l->out[i].gen = lease_gen;
    } else if (i < l->capout) {
        stream_ref(s);
        l->out[l->nout++] = (struct lease_out){s, lease_gen, f};
    } else {
        frame_unref(f);
    }
    pthread_cond_signal(&l->cv);
    pthread_mutex_unlock(&l->mu);
}

/* The lease the frame was computed under is gone: stop computing at once. */
static void lease_fenced(struct lease *l, struct stream *s, uint64_t gen)
{
    atomic_fetch_add(&l->srv->counters.cluster_frames_fenced, 1);
    struct stream_status st;
    hub_status(&l->srv->hub, s, &st);
    if (!st.lease.owned || st.lease.gen != gen) return;
    log_warn("cluster: stream %s: Redis refused a frame of lease generation %llu (taken over): not computing it",
             s->name, (unsigned long long)gen);
    atomic_fetch_add(&l->srv->counters.cluster_leases_lost, 1);
    hub_set_lease(&l->srv->hub, s, &(struct stream_lease){0});
}

static void lease_publish(struct lease *l, const struct lease_out *o)
{
    char lease_key[96], frame_key[100], channel[112], token[96];
    snprintf(lease_key, sizeof lease_key, CLUSTER_KEY "lease:%s", o->s->name);
    snprintf(frame_key, sizeof frame_key, CLUSTER_KEY "frame:%s:%u%s", o->s->name, (unsigned)o->f->hdr.kind,
             lease_encoding(o->f) == FXS_ENCODING_ENGINE ? ":engine" : "");
    snprintf(channel, sizeof channel, CLUSTER_FRAMES_CHANNEL "%d:%s", l->cfg->db, o->s->name);
    lease_token(token, sizeof token, o->gen, l->cfg->node_id);
    char ttl[16];
    snprintf(ttl, sizeof ttl, "%d", (int)(LEASE_TTL_S * 1000));
    const char *v[] = {lease_key, frame_key, token, channel, (const char *)o->f->bytes, ttl};
    size_t lens[] = {strlen(lease_key), strlen(frame_key), strlen(token), strlen(channel), o->f->len, strlen(ttl)};
    redisReply *r = lease_eval(l, LS_PUBLISH, 2, 6, v, lens);
    if (r && r->type == REDIS_REPLY_INTEGER && r->integer == 1) atomic_fetch_add(&l->srv->counters.cluster_frames_published, 1);
    else if (r && r->type == REDIS_REPLY_INTEGER && r->integer == 0) lease_fenced(l, o->s, o->gen);
    freeReplyObject(r);
}

/* Publishes what the engine queued (each frame once, newest first come). */
static void lease_flush(struct lease *l)
{
    pthread_mutex_lock(&l->mu);
    struct lease_out *out = l->out;
    int n = l->nout;
    l->out = NULL;
    l->nout = l->capout = 0;
    pthread_mutex_unlock(&l->mu);
    for (int i = 0; i < n; i++) {
        if (l->c || lease_conn(l)) lease_publish(l, &out[i]);
        frame_unref(out[i].f);
        stream_unref(out[i].s);
    }
    free(out);
}

/* A clean stop gives the leases up (the engine has stopped: nothing more is computed here). */
static void lease_release(struct lease *l)
{
    int n;
    struct stream **ss = hub_snapshot(&l->srv->hub, &n);
    const char **v = calloc((size_t)(2 + 2 * n), sizeof *v);
    char (*tokens)[96] = calloc((size_t)n + 1, sizeof *tokens);
    int argc = 0, held = 0;
    if (v && tokens) {
        v[argc++] = l->cfg->node_id;
        v[argc++] = cluster_member(l->srv->cluster);
        for (int i = 0; i < n; i++) {
            struct stream_status st;
            hub_status(&l->srv->hub, ss[i], &st);
            if (!st.lease.owned) continue;
            lease_token(tokens[held], sizeof tokens[held], st.lease.gen, l->cfg->node_id);
            v[argc++] = ss[i]->name;
            v[argc++] = tokens[held++];
        }
        l->retry_at = 0;
        freeReplyObject(lease_eval(l, LS_RELEASE, 0, argc, v, NULL));
        if (held) log_info("cluster: gave up %d leases", held);
    }
    free(v);
    free(tokens);
    hub_release_all(ss, n);
}

static void *lease_main(void *arg)
{
    struct lease *l = arg;
    double next_tick = 0;
    for (;;) {
        double now = clock_now();
        if (now >= next_tick) {
            lease_tick(l);
            next_tick = now + LEASE_TICK_S;
        }
        lease_flush(l);
        struct timespec until;
        clock_gettime(CLOCK_MONOTONIC, &until);
        double wait = fmax(next_tick - clock_now(), 0.0);
        until.tv_sec += (time_t)wait;
        until.tv_nsec += (long)((wait - floor(wait)) * 1e9);
        if (until.tv_nsec >= 1000000000L) until.tv_sec++, until.tv_nsec -= 1000000000L;
        pthread_mutex_lock(&l->mu);
        while (!l->stopping && !l->nout && !pthread_cond_timedwait(&l->cv, &l->mu, &until)) continue;
        bool stop = l->stopping;
        pthread_mutex_unlock(&l->mu);
        if (stop) break;
    }
    if (!l->node_taken) lease_release(l); /* another daemon's now: nothing here is this one's to give up */
    return NULL;
}

/* ---- life ---- */

int lease_start(struct lease **out, struct server *srv, struct fx_err *err)
{
    struct lease *l = calloc(1, sizeof *l);
    if (!l) return fx_fail(err, "internal", NULL, "out of memory");
    l->srv = srv;
    l->cfg = cluster_config_of(srv->cluster);
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    pthread_mutex_init(&l->mu, NULL);
    pthread_cond_init(&l->cv, &ca);
    pthread_condattr_destroy(&ca);
    if (pthread_create(&l->thread, NULL, lease_main, l)) {
        lease_stop(l);
        return fx_fail(err, "internal", NULL, "cannot start the cluster's lease thread");
    }
    l->started = true;
    *out = l;
    return 0;
}

void lease_stop(struct lease *l)
{
    if (!l) return;
    if (l->started) {
        pthread_mutex_lock(&l->mu);
        l->stopping = true;
        pthread_cond_signal(&l->cv);
        pthread_mutex_unlock(&l->mu);
        pthread_join(l->thread, NULL);
    }
    for (int i = 0; i < l->nout; i++) {
        frame_unref(l->out[i].f);
        stream_unref(l->out[i].s);
    }
    free(l->out);
    redisFree(l->c);
    pthread_mutex_destroy(&l->mu);
    pthread_cond_destroy(&l->cv);
    free(l);
}
