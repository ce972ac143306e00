/* relay.h — cluster mode: frames of streams that another daemon computes, for the subscribers
 * here.
 *
 * One thread with two Redis connections of its own: one SUBSCRIBEd to the frame channels
 * (fxs:frames:DB:NAME, lease.h) of the streams that have subscribers here and whose lease this
 * daemon does not hold, one to read a stream's latest frames (fxs:frame:NAME:KIND and, in the
 * engine encoding, fxs:frame:NAME:KIND:engine) when its subscription starts, so a new subscriber
 * gets a picture at once (an engine frame older than the default one of its kind is left out:
 * nobody made it since). Every frame goes into the hub
 * exactly as the engine's do (hub_publish, with this daemon's channel number in its header), so
 * subscribers here are served by the same latest-frame-wins path: a slow daemon skips frames,
 * it never backs Redis up. The set of channels follows the hub every RELAY_POLL_S. The delay
 * from the owner's frame to its arrival here is in fxs_cluster_relay_latency_seconds.
 * A lost connection is re-made with backoff; the subscriptions are made again. */
#ifndef FX_RELAY_H
#define FX_RELAY_H

#include "histogram.h"
#include "server.h"

#define RELAY_POLL_S 0.1

struct relay;

int relay_start(struct relay **out, struct server *srv, struct fx_err *err);
/* Stops it and frees everything; NULL is a no-op. */
void relay_stop(struct relay *r);
/* For /metrics (any thread): owner's frame time to arrival here. */
const struct histogram *relay_latency(const struct relay *r);

#endif
