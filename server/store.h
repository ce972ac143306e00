/* store.h — stream definitions and parameters persisted in the state directory.
 *
 * The whole set of streams (name, effect, revision, parameters) is one JSON file,
 * <state-dir>/streams.json, rewritten atomically after every accepted change: written
 * to a temporary file, fsync'ed, renamed over the old one, and the directory fsync'ed,
 * so a crash at any moment leaves either the old or the new file, never a torn one.
 * Without a state directory nothing is stored. */
#ifndef FX_STORE_H
#define FX_STORE_H

#include <cjson/cJSON.h>

#include "server.h"

/* Saves every stream; logs (does not fail the request) when the disk refuses. */
void store_save(struct server *srv);
/* The stored stream list ([{stream, effect, rev, params}]) or NULL when there is none.
 * Fails (-1, err) when the file exists but cannot be read or parsed. */
int store_load(const struct server *srv, cJSON **streams, struct fx_err *err);

#endif
