/* store.h — stream definitions and parameters persisted in the state directory.
 *
 * The whole set of streams (name, effect, revision, parameters) is one JSON file,
 * <state-dir>/streams.json, written atomically (jsonfile_write: temporary file, fsync,
 * rename, directory fsync), so a crash at any moment leaves the old or the new file.
 * Without a state directory nothing is stored. In cluster mode (--cluster) Redis is the system
 * of record instead (cluster.h): streams.json is neither read nor written.
 *
 * Write before apply: an accepted create, destroy or parameter change is first written as
 * the file will be after it, or made in Redis (store_commit); only when that succeeds is it
 * applied and acknowledged. A write that fails leaves the change unapplied, the request gets
 * `unavailable`, and the condition shows in /healthz ("state"; in cluster mode "cluster") and
 * /metrics (fxs_state_writable 0, fxs_state_write_failures_total; fxs_cluster_*) until a write
 * succeeds. One write per change: 0.5 ms on this machine's disk (README "Configuration").
 * Network thread only. */
#ifndef FX_STORE_H
#define FX_STORE_H

#include <cjson/cJSON.h>

#include "server.h"

enum store_op { STORE_CREATE, STORE_SET, STORE_DESTROY, STORE_RESET };

/* A change to record before it is applied. */
struct store_change {
    enum store_op op;
    const char *stream;
    const char *effect;    /* CREATE, SET */
    const cJSON *params;   /* CREATE, SET: the complete document (borrowed) */
    uint64_t rev;          /* SET: the revision params was validated against. Out, on success: the
                              revision the stream has after the change (CREATE: 1) */
    cJSON *rebased;        /* out, SET: the document actually stored when it was re-made (below), else NULL */
    /* SET, cluster mode: when another daemon changed the stream after `rev`, the change is made
     * again on the current document: rebase returns the new complete document (NULL with err when
     * the change no longer validates there). Without rebase, params is stored as it is. */
    cJSON *(*rebase)(const void *ctx, const cJSON *current, struct fx_err *err);
    const void *rebase_ctx;
};

/* Records `change` before the caller applies it: on a single
 * node, writes streams.json as it will be after it (without a state dir: nothing; a RESET is
 * no state: nothing); in cluster mode, makes it in Redis (cluster.h), where it may find that
 * another daemon got there first (exists, limit, unknown_stream, or a SET re-made through
 * rebase). 0, or -1 with err (unavailable: nothing changed, the message says where and why). */
int store_commit(struct server *srv, struct store_change *change, struct fx_err *err);
/* Every stream of the hub as stored: [{stream, effect, rev, params}] in creation order. */
cJSON *store_streams(struct server *srv);
/* Records the outcome of a state write made elsewhere (presets.json) for /healthz and
 * /metrics: why == NULL for a success. */
void store_note(struct server *srv, const char *why);
/* The stored stream list ([{stream, effect, rev, params}]) or NULL when there is none (and
 * always in cluster mode, where the streams come from Redis: replica.h). Fails (-1, err) when
 * the file exists but cannot be read or parsed. */
int store_load(const struct server *srv, cJSON **streams, struct fx_err *err);
/* Adds entries (stored streams that no longer validate, each with its "reason") to
 * <state-dir>/streams.quarantine.json, written like streams.json, so the next write of
 * streams.json does not erase them with no copy. 0 or -1 (errno). */
int store_quarantine(const struct server *srv, const cJSON *entries);

#endif
