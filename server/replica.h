/* replica.h — cluster mode: this daemon's copy of the streams kept in Redis (cluster.h).
 *
 * Network thread only. replica_poll drains what the cluster's follower queued and applies
 * it to the hub: another daemon's change (created, params, destroyed, reset) when it is the
 * next one of Redis's change counter, else a reload of the whole state from Redis, which
 * wins: streams it lacks are destroyed here, streams it has are created or updated here, at
 * its revisions. Local clients get the events of each change exactly as for a change made
 * on this daemon (session_event_*). A reload also seeds a database that was never seeded
 * with this daemon's streams (cluster_seed): the built-in or configured ones at start, the
 * last known state when Redis comes back empty. Without --cluster every call is a no-op. */
#ifndef FX_REPLICA_H
#define FX_REPLICA_H

#include "server.h"

/* Applies what the follower queued; reloads when the copy is stale and the link is up (at
 * most once a second after a failed reload). 0, or -1 with err when a reload was due and
 * failed (the daemon start checks it; the loop retries). */
int replica_poll(struct server *srv, struct fx_err *err);

#endif
