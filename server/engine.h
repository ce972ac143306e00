/* engine.h — the worker thread that steps every stream at its `fps`.
 *
 * The engine owns effect state and the OpenCL device. Between two steps of a stream it
 * applies the newest parameter document from the hub (all-or-nothing: a document is
 * complete and validated before it reaches the hub), re-creates the effect when a
 * restart-only parameter changed, and honours `reset`. Each step's outputs are encoded
 * once into frames and published to the hub. One thread is enough on purpose: PoCL
 * already spreads every kernel over all cores, and a second stepping thread would only
 * contend for them. Long steps run in slices, and the streams share the thread by the rules
 * in engine.c's header: cheap frames first, a floor for every stream, a destroy or change
 * reaching a long step within a slice. A stream with no subscribers pauses (its simulated
 * time stops) unless pause_idle is off.
 *
 * In cluster mode the engine computes only the streams whose lease this daemon holds (hub.h
 * struct stream_lease): a stream taken over starts its effect afresh and continues the previous
 * owner's frame numbers; one lost is dropped at once. Subscribers on other daemons count as
 * subscribers. Every frame also goes to `export` (lease.h publishes it through Redis). */
#ifndef FX_ENGINE_H
#define FX_ENGINE_H

#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>

#include "hub.h"

struct ocl;
struct engine_slot;

struct engine {
    struct hub *hub;
    struct ocl *ocl;
    bool pause_idle;
    pthread_t thread;
    bool started;
    struct engine_slot *slots; /* engine thread only: */
    int nslots;
    double decay_t;            /* when the slots' usage was last aged */
    const struct stream *last; /* the stream that ran the last slice */
    atomic_uint_fast64_t busy_ns; /* time spent stepping, for the cluster's load measure (lease.c) */
    /* Cluster mode: called from the engine thread with each new frame (a reference the callee
     * owns) and the lease generation it was computed under; NULL on a single node. */
    void (*export_frame)(void *ctx, struct stream *s, uint64_t lease_gen, struct frame *f);
    void *export_ctx;
};

/* eng zero-initialized or stopped, with export_frame and export_ctx set (or NULL). */
int engine_start(struct engine *eng, struct hub *hub, struct ocl *ocl, bool pause_idle, struct fx_err *err);
/* Stops the thread (after its current step) and frees every effect. */
void engine_stop(struct engine *eng);

#endif
