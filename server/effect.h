/* effect.h — the small interface every effect implements.
 *
 * An effect owns its simulation or generator state and its OpenCL objects; it runs
 * only on the engine thread and never sees sockets. It declares its parameters as a
 * param_def table (params.h) over its typed parameter struct, and is handed that struct
 * (filled by params_load), never the JSON document; each step emits zero or more outputs through a
 * callback: each with its content (particles, texels) and its default payload, made at
 * once or on demand. The engine makes one frame (header + payload) of each encoding
 * subscribers take (PROTOCOL.md §3.5), once, and the hub fans it out to them. */
#ifndef FX_EFFECT_H
#define FX_EFFECT_H

#include <stddef.h>
#include <stdint.h>
#include <cjson/cJSON.h>

#include "err.h"
#include "fxs_particles.h"
#include "params.h"

struct ocl;

/* One output of a step. The engine copies what it sends before emit returns; payload,
 * particles and texels stay valid until the effect emits another frame of the kind (or is
 * applied, reset or destroyed), so the engine may encode the output again for a subscriber
 * that asks for another encoding later, also between the slices of a step in progress (so a
 * step computed in slices does not write into the content it emitted last). */
struct effect_frame {
    uint16_t kind;           /* enum fxs_kind */
    uint32_t codec;          /* kind-specific codec id of payload (protocol/PROTOCOL.md) */
    uint32_t count_or_width; /* particles, or texture width */
    uint32_t height;         /* texture height, or 0 */
    uint32_t flags;
    const void *payload;     /* the default encoding, or NULL: encode makes it when wanted */
    size_t payload_bytes;
    double encode_ms;        /* time spent encoding this payload, for /metrics */
    /* The default payload made on demand (payload NULL): sets codec, payload, payload_bytes
     * and encode_ms of fr, valid as payload is above. Called only while a subscriber takes
     * the default encoding (so a costly codec costs nothing while nobody reads it). */
    int (*encode)(void *self, struct effect_frame *fr, struct fx_err *err);
    void *self;
    /* The content the engine encoding is made of (fxs_engine.h): kind 1 its particles; kind 2
     * its texels, count_or_width x height x channels floats, row 0 at the top. */
    struct fxs_particles particles;
    const float *texels;
    uint32_t channels;
    /* Kind 1, for subscribers' budgets (budget.h): each particle's stable id (particles.n of
     * them; the same particle keeps its id from frame to frame), and the options the effect's
     * default payload is encoded with, so a subset is encoded alike. Required of kind 1 outputs
     * (without ids a budget cannot be served: the engine reports an internal error). */
    const uint32_t *ids;
    struct fxs_particles_opts particle_opts;
};

/* Makes the default payload of a frame whose effect defers it (no-op otherwise): 0, or -1 with err. */
static inline int effect_frame_encode(struct effect_frame *fr, struct fx_err *err)
{
    return fr->payload || !fr->encode ? 0 : fr->encode(fr->self, fr, err);
}

/* A built-in preset (presets.h): a partial document over the effect's defaults. */
struct effect_preset {
    const char *name; /* 1-63 characters of [A-Za-z0-9_.-] */
    const char *doc;  /* one line: what it shows and where it comes from */
    const char *params;
};

/* What the daemon hands every effect once at start (effects_init). */
struct effect_env {
    const char *assets_dir; /* "" = none */
};

typedef int (*effect_emit_fn)(void *ctx, const struct effect_frame *frame);

/* What step returns when it stopped at its slice's end with work left (see step). */
#define EFFECT_MORE 1

struct effect_ops {
    const char *name;             /* protocol name, e.g. "energy_wave" */
    const char *doc;              /* one paragraph for describe */
    const struct param_def *params; /* {0}-terminated; must contain "fps" (PARAM_FLOAT) */
    size_t params_size;           /* sizeof the typed parameter struct params names places in */
    int param_slots;              /* floats of the kernel-argument array its PARAM_SLOTs index (0: none) */
    const char *outputs_json;     /* JSON array describing the outputs, for describe */
    const struct effect_preset *presets; /* built-in read-only presets, {0}-terminated (may be NULL) */

    /* Once at start, before any stream is created (may be NULL): e.g. scan the assets that
     * some parameter's choices name. Fails when the environment is unusable. */
    int (*init)(const struct effect_env *env, struct fx_err *err);

    /* Cross-parameter rules beyond the table (may be NULL). Called on the typed struct of
     * every merged document before it is accepted; code bad_param with err->param set. */
    int (*check)(const void *params, struct fx_err *err);

    /* Creates the state from the typed struct of a complete validated document (the
     * effect keeps a copy of what it needs; params is the caller's). Returns NULL and fills
     * err (code internal, with the OpenCL build log when a build fails). */
    void *(*create)(struct ocl *ocl, const void *params, struct fx_err *err);

    /* Applies new parameters between two steps (live change), typed as create's. A
     * parameter flagged PARAM_RESTART never reaches apply: the engine re-creates instead. */
    int (*apply)(void *self, const void *params, struct fx_err *err);

    /* Advances to sim_time (dt seconds after the previous step) and emits frames; 0 once the
     * step is complete. A step that can take long is done in slices: the effect stops between
     * two launches when the next would end after slice_end (clock.h seconds; INFINITY: no
     * limit), with no device work left in flight, keeps its place and returns EFFECT_MORE; the
     * engine calls it again later, after other streams' slices, with the same sim_time and
     * dt 0, and it goes on. Each call makes progress; a step emits its frames in the call that
     * completes it, and what it emitted before stays as struct effect_frame says meanwhile.
     * apply, reset and destroy abandon a step in progress: the next call starts afresh. */
    int (*step)(void *self, double sim_time, double dt, double slice_end, effect_emit_fn emit, void *ctx,
                struct fx_err *err);

    /* Restarts the state as if just created (the protocol's `reset`). */
    int (*reset)(void *self, struct fx_err *err);

    void (*destroy)(void *self);

    /* Simulated seconds since create/reset, for effects whose own clock differs from the
     * stream's (a fixed-step simulation); /metrics reports its rate against wall time as
     * the real-time factor. May be NULL (the factor is then 1 by construction). */
    double (*sim_seconds)(void *self);
};

/* The registry (effects/registry.c). */
const struct effect_ops *effect_find(const char *name);
const struct effect_ops *const *effect_all(void); /* NULL-terminated */
/* Checks every effect's parameter table against its typed struct (params_table_check), then
 * runs every effect's init with env; the first failure is returned. */
int effects_init(const struct effect_env *env, struct fx_err *err);

/* The one validation path for an effect's parameters (create, set, config, restored
 * state): partial (NULL: none) merged into base (NULL: the effect's defaults) by its
 * table, then its cross-parameter rules. A new complete document, or NULL with err. */
cJSON *effect_params(const struct effect_ops *ops, const cJSON *base, const cJSON *partial, struct fx_err *err);

/* The typed struct of a complete validated document (params_load into a new allocation of
 * ops->params_size bytes; free it), or NULL with err. */
void *effect_typed(const struct effect_ops *ops, const cJSON *doc, struct fx_err *err);

#endif
