/* store.h — stream definitions and parameters persisted in the state directory.
 *
 * The whole set of streams (name, effect, revision, parameters) is one JSON file,
 * <state-dir>/streams.json, written atomically (jsonfile_write: temporary file, fsync,
 * rename, directory fsync), so a crash at any moment leaves the old or the new file.
 * Without a state directory nothing is stored.
 *
 * Write before apply: an accepted create, destroy or parameter change is first written as
 * the file will be after it (store_commit); only when that write succeeds is it applied
 * and acknowledged. A write that fails leaves the change unapplied, the request gets
 * `unavailable`, and the condition shows in /healthz ("state") and /metrics
 * (fxs_state_writable 0, fxs_state_write_failures_total) until a write succeeds. One write
 * per change: 0.5 ms on this machine's disk (README "Configuration"). */
#ifndef FX_STORE_H
#define FX_STORE_H

#include <cjson/cJSON.h>

#include "server.h"

/* The stream `stream` as it will be after a change: `params` (borrowed) at `rev` and of
 * `effect`, added when absent; or removed when params is NULL. */
struct store_change {
    const char *stream;
    const char *effect;
    uint64_t rev;
    const cJSON *params;
};

/* Writes streams.json as it will be after `change` (NULL: the streams as they are). 0, or -1
 * with err (code unavailable, naming the file and the reason). Without a state dir: 0. */
int store_commit(struct server *srv, const struct store_change *change, struct fx_err *err);
/* Records the outcome of a state write made elsewhere (presets.json) for /healthz and
 * /metrics: why == NULL for a success. */
void store_note(struct server *srv, const char *why);
/* The stored stream list ([{stream, effect, rev, params}]) or NULL when there is none.
 * Fails (-1, err) when the file exists but cannot be read or parsed. */
int store_load(const struct server *srv, cJSON **streams, struct fx_err *err);
/* Adds entries (stored streams that no longer validate, each with its "reason") to
 * <state-dir>/streams.quarantine.json, written like streams.json, so the next write of
 * streams.json does not erase them with no copy. 0 or -1 (errno). */
int store_quarantine(const struct server *srv, const cJSON *entries);

#endif
