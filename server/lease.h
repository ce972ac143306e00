/* lease.h — cluster mode: which streams this daemon computes, and the frames it publishes.
 *
 * Each stream is computed by exactly one compute daemon: the one holding its lease in Redis,
 * fxs:lease:NAME = "GEN NODE" with a TTL of LEASE_TTL_S. One thread (the agent) with its own
 * Redis connection runs, every LEASE_TICK_S, one script that atomically
 *   - renews this daemon's claim on its node id (cluster.h); when another daemon holds it now,
 *     does nothing else, and this daemon stops (cluster_node_taken);
 *   - records which streams have subscribers here and in which encodings (PROTOCOL.md §3.5):
 *     fxs:want:NAME, field NODE (the default encoding) or NODE|engine -> expiry in ms, so their
 *     owners compute them, in those encodings, even with no subscriber of their own;
 *   - renews the leases this daemon holds and says which it lost (taken by another daemon after
 *     this one stopped renewing: it was paused, or cut off from Redis), and for each held one
 *     which encodings other daemons' subscribers of it take;
 *   - on a compute daemon (--role compute or both) that is the least loaded live one and has
 *     been live for a TTL (after a Redis that lost its data, the owners renew first), takes
 *     the streams nobody holds: a new generation from fxs:leasegen, and the frame numbers the
 *     previous owner reached (from the latest frames, below). Load = the engine's measured busy
 *     fraction (step time per second) + LEASE_STREAM_COST per lease held, kept in the sorted
 *     set fxs:computes; a daemon is live while its fxs:node:NAME key (TTL LEASE_TTL_S) is.
 * What it learns goes to the hub (hub_set_lease), which the engine follows. Streams move only
 * when their owner stops holding them: a running stream is never taken from a live owner.
 *
 * Frames: the engine hands every frame it makes to lease_export (it never waits on Redis:
 * latest frame wins per stream, kind and encoding while the agent is busy). The agent publishes
 * each on the stream's channel fxs:frames:DB:NAME and keeps it in fxs:frame:NAME:KIND, or
 * fxs:frame:NAME:KIND:engine (a new subscriber anywhere gets it at once, relay.h), through a
 * script that first checks that the lease is still the one the frame was computed under:
 * fencing. A paused owner whose lease was taken
 * meanwhile is refused at Redis (fxs_cluster_frames_fenced_total), and its engine stopped
 * computing by itself when the lease's time ran out locally.
 *
 * A clean stop gives the leases and the node id's claim up.
 *
 * Redis unreachable: the leases held are kept locally (the owner goes on computing for its own
 * subscribers; nothing can be published anyway) and checked again when Redis answers. */
#ifndef FX_LEASE_H
#define FX_LEASE_H

#include "server.h"

#define LEASE_TTL_S 3.0
#define LEASE_TICK_S 0.5

struct lease;

/* Starts the agent (cluster mode only). */
int lease_start(struct lease **out, struct server *srv, struct fx_err *err);
/* Stops it and frees everything; NULL is a no-op. */
void lease_stop(struct lease *l);
/* The engine's export_frame (engine.h): ctx is the struct lease. */
void lease_export(void *ctx, struct stream *s, uint64_t lease_gen, struct frame *f);

#endif
