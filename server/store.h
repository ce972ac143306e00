/* store.h — stream definitions and parameters persisted in the state directory.
 *
 * The whole set of streams (name, effect, revision, parameters) is one JSON file,
 * <state-dir>/streams.json, rewritten atomically after every accepted change: written
 * to a temporary file, fsync'ed, renamed over the old one, and the directory fsync'ed,
 * so a crash at any moment leaves either the old or the new file, never a torn one.
 * Without a state directory nothing is stored.
 *
 * Group commit: an accepted change marks the store dirty (store_mark) and holds its
 * session's replies; the network loop writes the file once per round of events
 * (store_flush) and only then releases the held replies, so a change is acknowledged
 * only after it is on disk while a burst of changes costs one fsync, not one each. */
#ifndef FX_STORE_H
#define FX_STORE_H

#include <cjson/cJSON.h>

#include "server.h"

/* Marks the state changed; true when it will be written (a state directory is set). */
bool store_mark(struct server *srv);
/* Writes every stream when marked; logs (does not fail requests) when the disk refuses. */
void store_flush(struct server *srv);
/* The stored stream list ([{stream, effect, rev, params}]) or NULL when there is none.
 * Fails (-1, err) when the file exists but cannot be read or parsed. */
int store_load(const struct server *srv, cJSON **streams, struct fx_err *err);
/* Adds entries (stored streams that no longer validate, each with its "reason") to
 * <state-dir>/streams.quarantine.json, written like streams.json, so the next write of
 * streams.json does not erase them with no copy. 0 or -1 (errno). */
int store_quarantine(const struct server *srv, const cJSON *entries);

#endif
