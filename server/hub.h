/* hub.h — streams by name, and where the engine and the network meet.
 *
 * A stream is the unit of compute: one effect instance stepped by the engine. The hub
 * holds each stream's parameter document and revision (written by the network thread
 * on `set`, read by the engine between steps), the latest encoded frame per form and
 * kind (written by the engine, read by the network thread: latest frame wins; a form is an
 * encoding and a particle budget, budget.h), the subscribers of each form (what the engine
 * encodes), and its counters. Everything mutable is guarded by one mutex held only for pointer
 * swaps and copies, never during a step or a send. The engine sleeps on the hub's condition
 * variable; the network thread is woken through a callback (lws_cancel_service). */
#ifndef FX_HUB_H
#define FX_HUB_H

#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>
#include <cjson/cJSON.h>

#include "budget.h"
#include "effect.h"
#include "err.h"
#include "frame.h"
#include "histogram.h"

#define STREAM_NAME_MAX 64

/* Revisions stay below 10^15: every integer there is exact in a double and prints exactly with
 * cJSON's 15 significant digits (a 32-bit revision would wrap to 0 at 2^32). A stream that
 * reaches it takes no more changes (at a change a millisecond, 31 700 years). */
#define HUB_REV_MAX 1e15

/* Who computes a stream. On a single node: this daemon, always. In cluster mode (lease.h) the
 * daemon holding the stream's lease in Redis: owned under lease generation `gen` until `until`
 * (CLOCK_MONOTONIC seconds; the lease's TTL counted from before its last renewal was sent, so a
 * daemon that was paused past it stops by itself; INFINITY while Redis is unreachable: the
 * owner keeps serving its own subscribers), continuing the frame numbers of the previous owner
 * from seq_from; remote_demand: the forms other daemons' subscribers of it take (bits
 * 1 << form, budget.h; 0: none). */
struct stream_lease {
    bool owned;
    unsigned remote_demand;
    uint64_t gen;
    double until;
    uint64_t seq_from[FXS_KIND_MAX + 1];
};

struct stream {
    atomic_int refs;
    char name[STREAM_NAME_MAX];
    const struct effect_ops *effect;
    uint32_t channel; /* unique for the daemon's lifetime; the `subscribed` reply's channel */

    /* Guarded by hub.mu; read outside hub.c through hub_status. */
    cJSON *params;    /* complete, validated */
    double fps;       /* params' "fps", read once per change (the engine's tick needs it) */
    uint64_t rev;     /* +1 per accepted change, starts at 1; below HUB_REV_MAX (cluster mode: Redis's) */
    uint64_t params_gen; /* +1 per hub_set_params, from 1: how the engine tells a change (in cluster
                            mode rev is Redis's, and a reload can bring other params at the same rev) */
    uint64_t reset_gen;
    struct stream_lease lease;
    bool destroyed;
    int subscribers;
    int subscribers_by[BUDGET_FORMS]; /* of each form (budget.h) */
    /* The newest frame of each form and kind; kind 2 only at level 0 of each encoding, kinds 3
     * and 4 only in BUDGET_FORM_DEFAULT (budget_kind_form). */
    struct frame *latest[BUDGET_FORMS][FXS_KIND_MAX + 1];
    char error[320];  /* last stream-level error, for subscribers and /healthz */
    uint64_t error_gen;
    bool failing;     /* since that error the stream has not stepped successfully */
    double realtime;  /* effect-simulated seconds per wall second, recent steps */
    double achieved_fps, engine_share; /* the engine's pace of the stream (hub_set_pace) */

    /* For /metrics. */
    atomic_uint_fast64_t steps, frames_produced, frames_sent, frames_skipped, bytes_sent;
    atomic_uint_fast64_t engine_ns;  /* engine time spent stepping the stream, every slice */
    atomic_uint_fast64_t sent_by_kind[FXS_KIND_MAX + 1]; /* frames sent, per kind */
    atomic_uint particles;           /* of the latest particle frame (kind 1) */
    struct histogram step_time, encode_time, frame_age; /* engine, engine, network thread */
    /* Network thread only: frames of each kind per subscriber per second over the last
     * second or more (net.c), and the counts that rate started from. */
    double delivered_fps[FXS_KIND_MAX + 1];
    uint64_t rate_base[FXS_KIND_MAX + 1];
    double rate_time;
};

struct hub {
    pthread_mutex_t mu;
    pthread_cond_t cv;  /* engine wakes on any change */
    uint64_t gen;       /* bumped on every change the engine must see */
    bool stopping;
    bool clustered;     /* new streams start without a lease (struct stream_lease) */
    struct stream **streams;
    int n, cap, max_streams;
    uint32_t next_channel;
    void (*notify)(void *ctx); /* frames or errors published: wake the network thread */
    void *notify_ctx;
};

/* clustered: cluster mode (streams are computed where their lease is, lease.h). */
int hub_init(struct hub *hub, int max_streams, bool clustered);
/* A revision given as JSON (a stored or configured stream's "rev"): the integer from 1 to
 * HUB_REV_MAX - 1 it holds, or 0 when it is not one. */
uint64_t hub_rev_from_json(const cJSON *v);
/* Whether a change may follow revision rev of stream `name`: 0, or -1 with err (limit). */
int hub_rev_check(const char *name, uint64_t rev, struct fx_err *err);
/* The name rule of streams (and presets): 1-63 characters of [A-Za-z0-9_.-]. */
bool hub_valid_name(const char *name);
void hub_free(struct hub *hub);

/* Adds a stream at revision rev (1 for a new one; stored streams keep theirs). Takes
 * ownership of params on success. Errors: exists, limit, bad_request
 * (invalid name: 1-63 characters of [A-Za-z0-9_.-]). */
int hub_create(struct hub *hub, const struct effect_ops *effect, const char *name, cJSON *params,
               uint64_t rev, struct fx_err *err);
/* Removes a stream by name; returns it with a reference so the caller can tell its
 * subscribers (unknown_stream when absent). */
struct stream *hub_destroy(struct hub *hub, const char *name, struct fx_err *err);
/* A reference to the named stream, or NULL. */
struct stream *hub_find(struct hub *hub, const char *name);
/* References to every live stream in creation order; free with hub_release_all. */
struct stream **hub_snapshot(struct hub *hub, int *n);
void hub_release_all(struct stream **streams, int n);
void stream_ref(struct stream *s);
void stream_unref(struct stream *s);

/* The guarded fields of a stream at one instant. */
struct stream_status {
    uint64_t rev, params_gen, reset_gen, error_gen;
    struct stream_lease lease;
    int subscribers, subscribers_by[BUDGET_FORMS];
    double fps, realtime, achieved_fps, engine_share;
    bool failing;
    char error[320]; /* the latest stream error ("" if none) */
};
void hub_status(struct hub *hub, struct stream *s, struct stream_status *out);
/* Engine side: the real-time factor of the stream's recent steps. */
void hub_set_realtime(struct hub *hub, struct stream *s, double factor);
/* Engine side: the steps per second the stream completed and its share of the engine thread,
 * both over the last second or more. */
void hub_set_pace(struct hub *hub, struct stream *s, double achieved_fps, double engine_share);
/* The hub's change generation, and whether it is stopping. */
uint64_t hub_generation(struct hub *hub, bool *stopping);

/* Replaces the parameters (takes ownership of doc) and the revision (the change's: the stored
 * one, store.h; in cluster mode Redis's, which may jump, or go back when Redis's state wins). */
void hub_set_params(struct hub *hub, struct stream *s, cJSON *doc, uint64_t rev);
/* A copy of the parameters and their revision. */
cJSON *hub_get_params(struct hub *hub, struct stream *s, uint64_t *rev);
void hub_request_reset(struct hub *hub, struct stream *s);
/* Cluster mode (lease.c): the stream's lease as Redis last said. */
void hub_set_lease(struct hub *hub, struct stream *s, const struct stream_lease *lease);
/* A subscription of a form (budget.h) added (delta +1) or dropped (-1). */
void hub_add_subscriber(struct hub *hub, struct stream *s, int form, int delta);

/* Engine side: publish a frame (takes the reference) as the newest of its kind in a form; again:
 * the frame is already published in another form (a full particle frame within a budget), so
 * it does not count as a frame made again. */
void hub_publish(struct hub *hub, struct stream *s, int form, struct frame *f, bool again);
/* Engine side: reports a stream error. */
void hub_stream_error(struct hub *hub, struct stream *s, const char *message);
/* Engine side: drops the newest frame of a kind in a form when it is older than seq (that form
 * is no longer made: a subscriber taking it later waits for the frame of seq). */
void hub_drop(struct hub *hub, struct stream *s, int form, int kind, uint64_t seq);
/* The stream stepped successfully after errors (clears `failing`; the error text stays). */
void hub_stream_recovered(struct hub *hub, struct stream *s);
/* Network side: a reference to the newest frame of a kind for a subscription of a form (kinds
 * other than 1 in the form budget_kind_form gives; NULL if none). */
struct frame *hub_latest(struct hub *hub, struct stream *s, int form, int kind);
/* The number (header seq) of the newest frame of a kind in any form, 0 if none. Frames a
 * daemon publishes must number above it: sessions send a frame only when it is newer than the
 * last they sent. */
uint64_t hub_latest_seq(struct hub *hub, struct stream *s, int kind);
/* The number of the newest frame of a kind in one form (as hub_latest), 0 if none. */
uint64_t hub_latest_seq_of(struct hub *hub, struct stream *s, int form, int kind);

/* Engine: waits until the hub changes or the absolute CLOCK_MONOTONIC deadline (seconds). */
void hub_wait(struct hub *hub, uint64_t seen_gen, double deadline);
void hub_stop(struct hub *hub);

#endif
