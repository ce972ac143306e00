/* cluster.h — the Redis link of cluster mode (--cluster redis://HOST[:PORT][/DB]).
 *
 * Redis is then the system of record of the stream definitions, in the configured database:
 *   fxs:stream:NAME   hash {effect, rev, params (the complete document as JSON text)}
 *   fxs:streams       sorted set of the names, scored by their creation's change number
 *   fxs:seq           the change counter: +1 per change, whichever daemon made it; each change
 *                     passes the number its daemon's copy has reached, and a counter below it
 *                     (or not a number) is set there first (cluster_bad)
 *   fxs:seeded        set once, by the daemon that first filled an empty database
 *   fxs:done:NODE     "ID SEQ": the id of the node's last change and its number, for a minute
 *   fxs:member:NODE   "INSTANCE PID HOST": the running daemon of that node id (its claim),
 *                     with a TTL of CLUSTER_MEMBER_TTL_S, renewed by its lease agent (lease.h)
 *   (leases, demand, frames: lease.h and relay.h)
 * and the channel fxs:events:DB (pub/sub is server-wide, hence the database in its name)
 * carries one message per change, "SEQ JSON": the change's number, then {op, node, stream,
 * effect, rev, params} (op created, params, destroyed or reset; destroyed and reset carry
 * only the stream; op seeded, with no stream, when a daemon filled the database anew: every
 * daemon reloads). Each change is one Lua script that checks (the stream exists or not, its
 * effect and rev are those the change was validated against), writes, counts and publishes,
 * so Redis holds every change or none, and the messages come in the changes' order. Each
 * change carries an id of its own, kept in fxs:done:NODE: one sent again (below) is made once.
 *
 * Threads. Everything here runs on the network thread except the follower: a thread with
 * its own connection SUBSCRIBEd to the channel, which queues each message as it comes, a
 * LINK_UP item after each (re)subscription and a LINK_DOWN item when the link is lost
 * (then it reconnects with backoff), and wakes the network thread through the callback given
 * to cluster_follow. The queue and the last error are guarded by a mutex inside cluster.c,
 * the link state is atomic; the command connection, the scripts' hashes and the change number
 * the local copy has reached belong to the network thread. The follower never touches the hub.
 * A command connection that Redis closed while idle (its `timeout`, CLIENT KILL) is replaced
 * before use; one closed under a command is replaced and the command sent once more.
 *
 * The local copy (replica.c applies what is queued) follows Redis exactly while `in sync`:
 * it has applied every change up to `seq`. A write of this daemon, or a message, numbered
 * seq + 1 keeps it in sync; anything else (a gap, a reconnection, a write whose answer was
 * lost, a database emptied under it, a message numbered at or below the previous one on the
 * subscription: the counter went back) marks it stale, and replica.c reloads the whole state
 * from Redis (Redis wins). A daemon's own messages come back to it too and are skipped by
 * their number (its write already moved the copy there); `node` names the author, for logs
 * and for people reading the channel. */
#ifndef FX_CLUSTER_H
#define FX_CLUSTER_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <cjson/cJSON.h>

#include "err.h"

/* --role: a compute daemon takes leases and computes (it opens an OpenCL device); an edge
 * computes nothing and only relays frames (lease.h, relay.h); both (the default) does both. */
enum cluster_role { CLUSTER_ROLE_BOTH, CLUSTER_ROLE_COMPUTE, CLUSTER_ROLE_EDGE };

struct cluster_config {
    char url[256];  /* as given, for messages ("" = single node); it never holds a password */
    char host[256];
    int port, db;
    char node_id[64];   /* in every message this daemon publishes; default: the host name */
    bool node_id_default; /* node_id is the host name (no --node-id or "node_id" given) */
    char password[512]; /* FXS_REDIS_PASSWORD; never logged nor reported */
    enum cluster_role role;
    bool role_set;      /* --role or "role" given (it needs --cluster) */
};

/* Parses redis://HOST[:PORT][/DB] (port 6379 and database 0 by default; HOST a name, an
 * IPv4 address or [IPv6]) into cfg's url, host, port and db; errors name `what` (the flag or
 * the configuration key). */
int cluster_parse_url(const char *what, const char *url, struct cluster_config *cfg, struct fx_err *err);

/* Parses compute, edge or both into cfg->role; errors name `what`. */
int cluster_parse_role(const char *what, const char *s, struct cluster_config *cfg, struct fx_err *err);
const char *cluster_role_name(enum cluster_role role);

/* Keys and channels beside fxs:stream:NAME (lease.c, relay.c): */
#define CLUSTER_KEY "fxs:"
#define CLUSTER_FRAMES_CHANNEL CLUSTER_KEY "frames:" /* + DB ":" NAME: the stream's frames, as sent to clients */

struct cluster;

/* What Redis holds is read like any input: a value that does not parse, or cannot be right (a
 * change counter behind what a daemon has seen, a lease that never expires, a frame number
 * past CLUSTER_SEQ_MAX), is logged, counted by kind for /metrics, and repaired or ignored. */
enum cluster_bad {
    CLUSTER_BAD_SEQ,     /* fxs:seq, and change numbers on the channel that go back */
    CLUSTER_BAD_STREAM,  /* fxs:stream:NAME (its rev, effect or params) */
    CLUSTER_BAD_LEASE,   /* fxs:lease:NAME, fxs:leasegen, fxs:want:NAME, fxs:node:NAME, fxs:member:NODE */
    CLUSTER_BAD_MESSAGE, /* messages on fxs:events:DB */
    CLUSTER_BAD_FRAME,   /* frames on fxs:frames:DB:NAME and in fxs:frame:NAME:KIND[:engine] */
    CLUSTER_BAD_COUNT
};
const char *cluster_bad_name(enum cluster_bad what);
/* Any thread: logs one such value (a warning: what it was and what was done) and counts it. */
void cluster_bad(struct cluster *cl, enum cluster_bad what, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
/* Frame numbers read from Redis are trusted below this (a client's double holds them exactly). */
#define CLUSTER_SEQ_MAX (UINT64_C(1) << 53)

/* Lua shared by the scripts of cluster.c and lease.c: fxs_get(k) is the string at k (false
 * when absent; nil and the key's type when k holds another type, which would make GET fail
 * the script); fxs_show(v, t) is such a value as reported ('"..."', 'nothing', 'a hash'). */
#define CLUSTER_LUA_LIB                                                                  \
    "local function fxs_get(k)\n"                                                        \
    "  local v = redis.pcall('GET', k)\n"                                                \
    "  if type(v) == 'table' and v.err then return nil, redis.call('TYPE', k).ok end\n"  \
    "  return v\n"                                                                       \
    "end\n"                                                                              \
    "local function fxs_show(v, t)\n"                                                    \
    "  if t then return 'a ' .. t end\n"                                                 \
    "  if not v then return 'nothing' end\n"                                             \
    "  return '\"' .. string.sub(v, 1, 48) .. '\"'\n"                                     \
    "end\n"

/* Allocates the link (no connection yet). */
int cluster_open(struct cluster **out, const struct cluster_config *cfg, struct fx_err *err);
/* Starts the follower and waits for its first subscription: -1 with err (unavailable,
 * naming the URL and the reason) when Redis cannot be reached or refuses it. wake(ctx) is
 * called from the follower whenever it queued something; stop(ctx), from any thread, when
 * this daemon must stop (cluster_node_taken). */
int cluster_follow(struct cluster *cl, void (*wake)(void *ctx), void (*stop)(void *ctx), void *ctx, struct fx_err *err);
/* A new connection to Redis (authenticated, on the database; every command bounded by the
 * 1 s timeout), for a thread of its own; NULL with why. Any thread. */
struct redisContext *cluster_dial(const struct cluster *cl, char *why, size_t cap);
/* Whether Redis closed c while it sat idle between commands (its `timeout`, CLIENT KILL): the
 * owner of a connection checks before using it, and makes a new one instead. */
bool cluster_closed(const struct redisContext *c);
const struct cluster_config *cluster_config_of(const struct cluster *cl);
/* Stops the follower (within the connect timeout) and frees everything; NULL is a no-op. */
void cluster_close(struct cluster *cl);

enum cluster_item_kind { CLUSTER_EVENT, CLUSTER_LINK_UP, CLUSTER_LINK_DOWN };
struct cluster_item {
    struct cluster_item *next;
    enum cluster_item_kind kind;
    uint64_t seq; /* EVENT: the change's number */
    cJSON *doc;   /* EVENT: the message's JSON, NULL when it could not be read */
};
/* The oldest queued item (the caller frees it with cluster_item_free), or NULL. A LINK_DOWN
 * or LINK_UP marks the local copy stale. */
struct cluster_item *cluster_next(struct cluster *cl);
void cluster_item_free(struct cluster_item *it);

/* What the local copy does with a change numbered seq (a message, or a write of this daemon
 * that the caller applies): */
enum cluster_fit {
    CLUSTER_APPLY, /* the next change: apply it; the copy stays in sync at seq */
    CLUSTER_SKIP,  /* already in the copy, or the copy is stale (a reload will bring it) */
    CLUSTER_GAP,   /* changes were missed: the copy is now stale */
};
enum cluster_fit cluster_fit(struct cluster *cl, uint64_t seq);
bool cluster_in_sync(struct cluster *cl);
/* Whether the follower is subscribed (any thread). */
bool cluster_link_up(struct cluster *cl);
/* Marks the copy stale (an event that does not fit what it holds). */
void cluster_stale(struct cluster *cl);

/* Seeds a database never seeded with `streams` ([{stream, effect, rev, params}]), atomically
 * and at most once per database (fxs:seeded; logged when this call did it). */
int cluster_seed(struct cluster *cl, const cJSON *streams, struct fx_err *err);
/* The whole state, atomically: [{stream, effect, rev or bad_rev, params}] in creation order
 * (a stream whose effect or params do not read is left out, counted), and the number of the
 * last change it includes: 0. The copy is in sync at that number once the caller has applied
 * it (cluster_loaded). 1 when the database lost its data since it was seeded (nothing loaded:
 * seed it again), -1 with err. */
int cluster_load(struct cluster *cl, cJSON **streams, uint64_t *seq, struct fx_err *err);
void cluster_loaded(struct cluster *cl, uint64_t seq);
/* A stream of the loaded state whose "bad_rev" (its rev field as read: not a revision) is set
 * to rev, if Redis still holds the same there: a change like a set of `params` (numbered,
 * published as its params event). Counted and logged. 0 (the copy is then stale: load again),
 * or -1 with err. */
int cluster_repair_rev(struct cluster *cl, const char *stream, const char *effect, const char *bad, uint64_t rev,
                       const cJSON *params, struct fx_err *err);
/* Any thread: Redis lost its data (no fxs:seeded: FLUSHALL, or a restart without persistence),
 * as a change or the lease agent found: the copy goes stale and the network thread is woken to
 * reload it, which seeds Redis again with this daemon's streams (as after a restart of an empty
 * Redis). Changes answer unavailable meanwhile. */
void cluster_emptied(struct cluster *cl);

/* The changes. Each fails with unavailable (the link is down, the local copy is stale, Redis
 * lost its data, or Redis did not answer or refused: the message names the URL; when the
 * answer to a sent change was lost, on a second connection too, the message says the outcome
 * is unknown, and the copy is reloaded), or with what Redis's state says: exists and limit
 * (create, limit = max_streams), unknown_stream (set, destroy, reset: no longer in Redis). */
int cluster_create(struct cluster *cl, const char *stream, const char *effect, const cJSON *params, int max_streams,
                   struct fx_err *err);
/* The document as Redis holds it when a set finds that the stream moved on. */
struct cluster_current {
    char effect[64];
    uint64_t rev;
    cJSON *params; /* the caller's to delete */
};
/* Stores params at rev base + 1 if the stream is still at `base` with this effect: 0; 1 when
 * it is not (cur filled: the caller re-makes the change on it, or gives up); -1 with err. */
int cluster_set(struct cluster *cl, const char *stream, const char *effect, uint64_t base, const cJSON *params,
                struct cluster_current *cur, struct fx_err *err);
int cluster_destroy(struct cluster *cl, const char *stream, struct fx_err *err);
/* Tells every daemon to restart the stream's simulation (no state changes). */
int cluster_reset(struct cluster *cl, const char *stream, struct fx_err *err);

/* A node id belongs to one running daemon: its claim fxs:member:NODE lives this long unless
 * renewed (each lease agent tick renews it). */
#define CLUSTER_MEMBER_TTL_S 3.0

/* Claims this daemon's node id before anything else is done in Redis. A claim left by a
 * daemon that stopped renewing it (killed, or cut off) is waited for until it expires (at most
 * CLUSTER_MEMBER_TTL_S); one that another daemon renews fails with err naming the node id and
 * that daemon (its pid and host). Network thread, at start. */
int cluster_claim(struct cluster *cl, struct fx_err *err);
/* This daemon's claim ("INSTANCE PID HOST"), for the lease agent to renew. */
const char *cluster_member(const struct cluster *cl);
/* Any thread: another daemon holds this node id now (`claim`, its value): this one was paused or
 * cut off past the claim's TTL while another started with the same id. Logs why and asks the
 * daemon to stop (the stop callback); cluster_aborted says why afterwards. */
void cluster_node_taken(struct cluster *cl, const char *claim);
bool cluster_aborted(struct cluster *cl, char *why, size_t cap);

/* For /healthz and /metrics (network thread). */
struct cluster_status {
    const char *node, *url;
    bool link_up, in_sync;
    uint64_t seq;          /* the change the local copy has reached */
    uint64_t link_losses;  /* times the follower lost its subscription */
    char last_error[320];  /* the latest failure to reach Redis or of a change sent to it ("" if none) */
    uint64_t bad[CLUSTER_BAD_COUNT]; /* values read from Redis that were not trusted (cluster_bad) */
};
void cluster_status(struct cluster *cl, struct cluster_status *out);

#endif
