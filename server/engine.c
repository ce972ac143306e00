/* engine.c — see engine.h.
 *
 * Scheduling. A stream is ready when its next frame is due (every 1/fps s) or a step of it is in
 * progress. The engine runs one ready stream at a time, for one slice: an effect stops a long
 * step at the slice's end and goes on at its next turn (effect.h: EFFECT_MORE), so no step holds
 * the engine for long. Which ready stream goes next:
 *  1. one that has had less than its floor of the engine lately (ENGINE_FLOOR_SHARE split among
 *     the ready streams), the least served first: no stream starves;
 *  2. then the interactive streams, and among them the one that has had the least engine time
 *     lately (usage, decaying with ENGINE_SHARE_TAU_S): streams that need less than an equal
 *     share get what they need, the others split the rest equally;
 *  3. then the background streams, the least used first: those whose frames (the last one, or
 *     the one in progress so far) take more than ENGINE_LONG_S of engine time and more than
 *     ENGINE_HEAVY_RATIO times those of the cheapest other stream with work (a texture or table
 *     far beyond real time). They run in the time the interactive ones leave, below their fps
 *     (/metrics: fxs_stream_achieved_fps), instead of slowing those down. The ratio keeps the
 *     classes as they are when the machine's load slows every stream alike.
 * The stream that ran last keeps its turn until another in its class has used ENGINE_QUANTUM_S
 * less, so equal streams do not alternate at every slice. A slice ends when another stream
 * would come first (it becomes due, falls below its floor, or the running stream turns
 * background), after ENGINE_SLICE_MAX_S at most, so a destroy or a change reaches a long
 * step within that, and not before ENGINE_SLICE_MIN_S, so slicing costs little. Alone, a
 * stream runs its steps whole but for that bound. The engine time of every slice is counted
 * per stream (/metrics).
 *
 * Failures stay inside their stream: a failed creation waits for the next parameter
 * change; a failed step resets the effect (re-creating it when the reset fails too) and
 * the stream pauses ENGINE_BACKOFF_MIN_S before its next step, doubling up to
 * ENGINE_BACKOFF_MAX_S while the failures repeat, so a broken kernel or a lost device
 * costs a few error events and log lines, not a busy loop. A `set` or `reset` retries at
 * once. Each failure reaches the stream's subscribers, the log and /metrics.
 *
 * Forms (budget.h: an encoding, PROTOCOL.md §3.5, and for kind 1 a particle budget): each
 * output of a step becomes one frame per form that subscribers take, all with the output's seq;
 * a form nobody takes is not made, and its older frames leave the hub (a subscriber never gets
 * a frame older than the newest of the kind). A budget's frame is a subset of the output's
 * particles (budget_select), or, when the output fits the budget, the very frame of the full
 * form (made once, published in both). The slot keeps each kind's latest output (struct
 * engine_kept), so a subscriber asking for a form not made yet gets that frame at once, not at
 * the next change of a stream that emits only on change (the compound eye), nor at the end of a
 * step in progress: a step emits in its last slice, and what it emitted before stays valid meanwhile (effect.h). The
 * time such a catch-up spends encoding counts as the stream's engine time. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "budget.h"
#include "clock.h"
#include "engine.h"
#include "fxs_engine.h"
#include "log.h"

#define ENGINE_BACKOFF_MIN_S 0.5
#define ENGINE_BACKOFF_MAX_S 30.0
#define ENGINE_SLICE_MIN_S 0.005
#define ENGINE_SLICE_MAX_S 0.25
#define ENGINE_QUANTUM_S 0.02
#define ENGINE_LONG_S 1.0
#define ENGINE_HEAVY_RATIO 8.0
#define ENGINE_FLOOR_SHARE 0.04
#define ENGINE_SHARE_TAU_S 1.0
#define ENGINE_PACE_MAX_S 10.0 /* longest window of the achieved fps: a stream stuck reads 0 after it */

/* The latest output of a kind as the effect emitted it (its pointers valid as effect.h says),
 * the header its frames carry, the forms published of it (bits 1 << form, budget.h), and for
 * kind 1 its full frame in each encoding once made (a budget the output fits publishes it too)
 * and the subset of the budget step last cut from it (sub_step particles asked; both encodings
 * of a step encode the one selection). */
struct engine_kept {
    bool valid;
    uint32_t published;
    struct frame *full[FXS_ENCODING_COUNT];
    struct fxs_particles sub;
    uint32_t sub_step;
    struct effect_frame ef;
    struct fxs_header hdr;
};

struct engine_slot {
    struct stream *s;
    void *state;         /* effect state, NULL until created (or after a failure) */
    cJSON *params;       /* the document state was created/updated with */
    uint64_t rev;        /* its revision (for the frames' param_rev) */
    uint64_t gen;        /* its hub params_gen: what tells a change (a cluster's rev may repeat) */
    uint64_t failed_gen; /* creation failed at this params_gen: wait for a change */
    uint64_t reset_gen;
    uint64_t seq[FXS_KIND_MAX + 1];
    struct engine_kept kept[FXS_KIND_MAX + 1];
    uint64_t lease_gen;  /* the lease the slot computes under (cluster mode; 0 on a single node) */
    bool running;
    int fails;           /* consecutive failures (steps, creations): the pause after the last */
    uint64_t fail_gen;   /* params_gen and reset request seen by the last failure: */
    uint64_t fail_reset; /* a change of either ends the pause */
    double next_due, last_wall, sim_time;
    double rt_wall, rt_sim; /* start of the current real-time factor window */
    /* scheduling (the header comment) */
    double period;       /* 1/fps */
    bool ready;          /* due, or a step in progress */
    bool working;        /* a step in progress: the effect returned EFFECT_MORE */
    double frame_due;    /* when the frame being computed was due */
    double attained;     /* engine seconds of the frame being computed */
    double cost;         /* engine seconds of the last frame completed */
    double long_s;       /* frames that take longer make it a background stream */
    double usage;        /* engine seconds, decayed with ENGINE_SHARE_TAU_S */
    uint64_t hub_gen, hub_reset; /* the hub's params_gen and reset_gen at the last scan */
    double pace_t;       /* start of the achieved fps window, */
    uint64_t pace_n;     /* the steps completed since, */
    double achieved;     /* the last window's steps per second, */
    double pace_shown;   /* and when it and the share were last published */
};

static void engine_kept_clear(struct engine_kept *k)
{
    for (int e = 0; e < FXS_ENCODING_COUNT; e++) frame_unref(k->full[e]);
    fxs_particles_free(&k->sub);
    *k = (struct engine_kept){0};
}

/* The effect's outputs are about to change (apply, reset, re-creation): nothing kept is valid. */
static void engine_forget(struct engine_slot *sl)
{
    for (int k = 0; k <= FXS_KIND_MAX; k++) engine_kept_clear(&sl->kept[k]);
}

static void engine_drop_fx(struct engine_slot *sl)
{
    engine_forget(sl);
    if (sl->state) sl->s->effect->destroy(sl->state);
    sl->state = NULL;
    sl->working = false;
    cJSON_Delete(sl->params);
    sl->params = NULL;
}

/* Reports a stream-level failure to its subscribers and the log, with what happens next
 * (then: NULL, or e.g. "waiting for a parameter change"; kept when the message is cut). */
static void engine_fail(struct engine *eng, struct engine_slot *sl, const struct fx_err *err, const char *then)
{
    char msg[sizeof err->message];
    int room = (int)sizeof msg - (then ? (int)strlen(then) + 3 : 1);
    snprintf(msg, sizeof msg, "%.*s%s%s", room > 0 ? room : 0, err->message, then ? "; " : "", then ? then : "");
    log_error("stream %s: %s", sl->s->name, msg);
    hub_stream_error(eng->hub, sl->s, msg);
}

/* The pause after the n-th consecutive failure. */
static double engine_backoff(int n)
{
    return fmin(ENGINE_BACKOFF_MIN_S * pow(2.0, n > 1 ? n - 1 : 0), ENGINE_BACKOFF_MAX_S);
}

/* Brings the effect up to the hub's parameter revision: 0 when the state is usable, -1 when its
 * (re)creation failed just now (reported), 1 while waiting for a change after that. */
static int engine_sync_params(struct engine *eng, struct engine_slot *sl)
{
    struct stream *s = sl->s;
    struct stream_status st;
    hub_status(eng->hub, s, &st);
    uint64_t rev, gen = st.params_gen;
    if (sl->state && gen == sl->gen) return 0;
    if (!sl->state && gen == sl->failed_gen) return 1;

    cJSON *doc = hub_get_params(eng->hub, s, &rev);
    struct fx_err err = {0};
    void *typed = doc ? effect_typed(s->effect, doc, &err) : NULL;
    if (!typed) { /* the hub's documents are validated: a bug, or out of memory */
        if (!doc) fx_fail(&err, "internal", NULL, "out of memory");
        engine_drop_fx(sl);
        engine_fail(eng, sl, &err, "waiting for a parameter change");
        cJSON_Delete(doc);
        sl->failed_gen = gen;
        return -1;
    }
    engine_forget(sl);
    bool restart = !sl->state || params_restart_changed(s->effect->params, sl->params, doc);
    if (!restart && s->effect->apply(sl->state, typed, &err) == 0) {
        cJSON_Delete(sl->params);
    } else {
        if (!restart) engine_fail(eng, sl, &err, "re-creating the effect");
        engine_drop_fx(sl);
        memset(&err, 0, sizeof err);
        sl->state = s->effect->create(eng->ocl, typed, &err);
        sl->sim_time = 0;
        if (!sl->state) {
            engine_fail(eng, sl, &err, "waiting for a parameter change");
            free(typed);
            cJSON_Delete(doc);
            sl->failed_gen = gen;
            return -1;
        }
    }
    free(typed);
    sl->params = doc;
    sl->rev = rev;
    sl->gen = gen;
    return 0;
}

/* The forms wanted of a stream's frames of a kind (bits 1 << form, budget_kind_form): those its
 * subscribers here and on other daemons take (cluster mode); the default also while nobody
 * subscribes (a stream that runs idle keeps its newest frame for the next subscriber,
 * PROTOCOL.md §8.3). */
static uint32_t engine_wanted(const struct stream_status *st, int kind)
{
    uint32_t m = 0;
    for (int form = 0; form < BUDGET_FORMS; form++)
        if (st->subscribers_by[form] > 0 || (st->lease.remote_demand >> form & 1)) m |= 1u << budget_kind_form(form, kind);
    return m ? m : 1u << BUDGET_FORM_DEFAULT;
}

/* The payload of an output in an encoding: the effect's default one (made now when deferred), or
 * made here: the engine encoding, or the default codec of a subset's particles (sub: NULL, the
 * output's own); then *buf (free()) holds it. 0, or -1 with err. */
static int engine_payload(struct engine_kept *k, enum fxs_encoding enc, const struct fxs_particles *sub,
                          struct fxs_header *h, const void **payload, size_t *len, uint8_t **buf, double *encode_ms,
                          struct fx_err *err)
{
    struct effect_frame *ef = &k->ef;
    *buf = NULL;
    if (!sub && (enc == FXS_ENCODING_DEFAULT || !fxs_kind_has_engine_form(ef->kind))) {
        if (!ef->payload && effect_frame_encode(ef, err)) return -1;
        if (!ef->payload) return fx_fail(err, "internal", "", "an output of kind %u without a payload", ef->kind);
        *encode_ms += ef->encode_ms;
        h->codec = ef->codec;
        *payload = ef->payload;
        *len = ef->payload_bytes;
        return 0;
    }
    char msg[200];
    double t0 = clock_now();
    const struct fxs_particles *p = sub ? sub : &ef->particles;
    int rc = ef->kind != FXS_KIND_PARTICLES
                 ? (ef->texels ? fxs_engine_encode_texture(ef->texels, ef->count_or_width, ef->height, ef->channels,
                                                           FXS_ENGINE_ZSTD_LEVEL, buf, len, msg, sizeof msg)
                               : (snprintf(msg, sizeof msg, "the effect gave no texels"), -1))
             : enc == FXS_ENCODING_ENGINE ? fxs_engine_encode_particles(p, FXS_ENGINE_ZSTD_LEVEL, buf, len, msg, sizeof msg)
                                          : fxs_particles_encode(p, &ef->particle_opts, buf, len, msg, sizeof msg);
    if (rc) return fx_fail(err, "internal", "", "%s encoding of a kind %u frame: %s", fxs_encoding_name(enc), ef->kind, msg);
    *encode_ms += (clock_now() - t0) * 1e3;
    h->codec = enc == FXS_ENCODING_ENGINE ? FXS_CODEC_ENGINE : fxs_particles_codec(*buf, *len);
    *payload = *buf;
    return 0;
}

/* Cuts the kept output's subset of step particles into k->sub (budget_select, budget_gather),
 * unless it holds that step's already. 0, or -1 with err. */
static int engine_subset(struct engine_kept *k, uint32_t step, struct fx_err *err)
{
    const struct effect_frame *ef = &k->ef;
    if (k->sub_step == step) return 0;
    fxs_particles_free(&k->sub);
    k->sub_step = 0;
    if (!ef->ids) return fx_fail(err, "internal", "", "a particle output without ids: no subset of %u particles", step);
    uint32_t *idx = malloc((size_t)step * sizeof *idx);
    int64_t m = idx ? budget_select(ef->ids, ef->particles.n, step, idx) : -1;
    int rc = m < 0 || budget_gather(&ef->particles, idx, (uint32_t)m, &k->sub);
    free(idx);
    if (rc) return fx_fail(err, "internal", "", "out of memory for a subset of %u particles", step);
    k->sub_step = step;
    return 0;
}

/* A new frame of the kept output in an encoding: of all its particles, or (step > 0) of the
 * subset of step of them (budget_select; total in its header). NULL with err. */
static struct frame *engine_frame(struct engine_kept *k, enum fxs_encoding enc, uint32_t step, double *encode_ms,
                                  struct fx_err *err)
{
    struct fxs_header h = k->hdr;
    if (step && engine_subset(k, step, err)) return NULL;
    if (step) h.count_or_width = k->sub.n;
    uint32_t total = step ? k->ef.particles.n : 0;
    const void *payload = NULL;
    size_t len = 0;
    uint8_t *buf;
    if (engine_payload(k, enc, step ? &k->sub : NULL, &h, &payload, &len, &buf, encode_ms, err)) return NULL;
    h.server_time_us = clock_wall_us();
    struct frame *f = frame_new(&h, total, payload, len);
    free(buf);
    if (!f) fx_fail(err, "internal", "", "out of memory for a frame of %zu bytes", len);
    return f;
}

/* Publishes the kept output of a kind in one form (to the hub, and to export in cluster mode):
 * a subset when the form's budget is below its particles, else its full frame in the form's
 * encoding, made once for every form it serves. */
static int engine_publish(struct engine *eng, struct engine_slot *sl, struct engine_kept *k, int form,
                          double *encode_ms, struct fx_err *err)
{
    enum fxs_encoding enc = budget_form_encoding(form);
    uint32_t step = budget_step(budget_form_level(form));
    bool subset = step && k->ef.particles.n > step;
    struct frame *f = !subset && k->full[enc] ? frame_ref(k->full[enc]) : NULL;
    bool made = !f;
    if (made && !(f = engine_frame(k, enc, subset ? step : 0, encode_ms, err))) return -1;
    if (made && !subset && k->ef.kind == FXS_KIND_PARTICLES) k->full[enc] = frame_ref(f);
    k->published |= 1u << form;
    if (made && eng->export_frame) eng->export_frame(eng->export_ctx, sl->s, sl->lease_gen, frame_ref(f));
    hub_publish(eng->hub, sl->s, form, f, !made);
    return 0;
}

/* Publishes the kept output of a kind in each wanted form not yet published; the hub drops older
 * frames of the forms not wanted. */
static int engine_publish_wanted(struct engine *eng, struct engine_slot *sl, int kind, double *encode_ms,
                                 struct fx_err *err)
{
    struct engine_kept *k = &sl->kept[kind];
    struct stream_status st;
    hub_status(eng->hub, sl->s, &st);
    uint32_t want = engine_wanted(&st, kind);
    for (int form = 0; form < BUDGET_FORMS; form++) {
        if (budget_kind_form(form, kind) != form) continue; /* not a form of this kind */
        if (!(want >> form & 1)) hub_drop(eng->hub, sl->s, form, kind, k->hdr.seq);
        else if (!(k->published >> form & 1) && engine_publish(eng, sl, k, form, encode_ms, err)) return -1;
    }
    return 0;
}

struct engine_emit_ctx {
    struct engine *eng;
    struct engine_slot *sl;
    double encode_ms;
    struct fx_err err; /* why emit failed (the effect returns -1 without a message of its own) */
};

static int engine_emit(void *ctx, const struct effect_frame *ef)
{
    struct engine_emit_ctx *c = ctx;
    if (ef->kind < 1 || ef->kind > FXS_KIND_MAX) return -1;
    struct engine_slot *sl = c->sl;
    struct engine_kept *k = &sl->kept[ef->kind];
    engine_kept_clear(k);
    *k = (struct engine_kept){.valid = true, .ef = *ef};
    k->hdr = (struct fxs_header){
        .kind = ef->kind,
        .channel = sl->s->channel,
        .param_rev = sl->rev,
        .seq = ++sl->seq[ef->kind],
        .sim_time = sl->sim_time,
        .count_or_width = ef->count_or_width,
        .height = ef->height,
        .flags = ef->flags,
    };
    if (ef->kind == FXS_KIND_PARTICLES) atomic_store(&sl->s->particles, ef->count_or_width);
    return engine_publish_wanted(c->eng, sl, ef->kind, &c->encode_ms, &c->err);
}

/* Publishes the kept outputs in the encodings subscribers started to take since they were
 * emitted (a failure is reported as a failed step would be, without pausing the stream). */
static void engine_catch_up(struct engine *eng, struct engine_slot *sl)
{
    for (int kind = 1; kind <= FXS_KIND_MAX; kind++) {
        struct fx_err err = {0};
        double ms = 0;
        if (!sl->kept[kind].valid || !fxs_kind_has_engine_form(kind)) continue;
        if (engine_publish_wanted(eng, sl, kind, &ms, &err)) {
            engine_kept_clear(&sl->kept[kind]);
            log_error("stream %s: %s", sl->s->name, err.message);
            hub_stream_error(eng->hub, sl->s, err.message);
        }
        if (ms > 0) hist_observe(&sl->s->encode_time, ms * 1e-3);
    }
}

/* Updates the stream's real-time factor once a second: effect-simulated seconds per
 * wall second (effects without their own clock follow the stream's, factor 1). */
static void engine_realtime(struct engine *eng, struct engine_slot *sl, double now)
{
    const struct effect_ops *ops = sl->s->effect;
    double sim = ops->sim_seconds && sl->state ? ops->sim_seconds(sl->state) : sl->sim_time;
    if (sl->rt_wall == 0 || sim < sl->rt_sim) { /* first step, or a reset */
        sl->rt_wall = now;
        sl->rt_sim = sim;
        return;
    }
    if (now - sl->rt_wall < 1.0) return;
    hub_set_realtime(eng->hub, sl->s, (sim - sl->rt_sim) / (now - sl->rt_wall));
    sl->rt_wall = now;
    sl->rt_sim = sim;
}

/* After a failed step: starts the effect over (a blown-up state, NaN or runaway, must not
 * fail forever), re-creating it at the next step when even the reset fails, and pauses
 * the stream. */
static void engine_step_failed(struct engine *eng, struct engine_slot *sl, const struct fx_err *err)
{
    struct fx_err reset_err = {0};
    char then[200];
    double pause = engine_backoff(++sl->fails);
    engine_forget(sl);
    if (sl->s->effect->reset(sl->state, &reset_err) == 0) {
        snprintf(then, sizeof then, "state reset, next step in %.1f s", pause);
    } else {
        snprintf(then, sizeof then, "reset failed too, re-creating in %.1f s (%.120s)", pause, reset_err.message);
        engine_drop_fx(sl);
    }
    engine_fail(eng, sl, err, then);
    sl->sim_time = 0;
}

/* Runs one slice of the stream's step: the step in progress, unless a change or reset started
 * it over, or a new one. 0 when the step completed, EFFECT_MORE when it stopped at slice_end, -1
 * when it failed just now (reported; the stream is to pause). */
static int engine_step(struct engine *eng, struct engine_slot *sl, double now, double slice_end)
{
    struct stream *s = sl->s;
    struct fx_err err = {0};
    uint64_t gen = sl->gen;
    int sync = engine_sync_params(eng, sl);
    if (sync < 0) sl->fails++;
    if (sync) return sync < 0 ? -1 : 0;
    if (sl->gen != gen) sl->working = false; /* apply or create dropped the step in progress */

    struct stream_status st;
    hub_status(eng->hub, s, &st);
    uint64_t reset_gen = st.reset_gen;
    if (reset_gen != sl->reset_gen) {
        engine_forget(sl);
        sl->reset_gen = reset_gen;
        sl->sim_time = 0;
        sl->working = false;
        if (s->effect->reset(sl->state, &err)) engine_fail(eng, sl, &err, NULL);
    }

    double dt = 0;
    if (!sl->working) {
        dt = fmin(fmax(now - sl->last_wall, 0.0), 0.25); /* a long stall does not jump time */
        sl->last_wall = now;
        sl->sim_time += dt;
    }
    struct engine_emit_ctx ctx = {.eng = eng, .sl = sl};
    int rc = s->effect->step(sl->state, sl->sim_time, dt, slice_end, engine_emit, &ctx, &err);
    sl->working = rc == EFFECT_MORE;
    if (sl->working) return rc;
    if (rc && ctx.err.code[0]) err = ctx.err;
    if (rc) {
        engine_step_failed(eng, sl, &err);
    } else if (sl->fails) {
        log_info("stream %s: stepping again after %d failed steps", s->name, sl->fails);
        sl->fails = 0;
        hub_stream_recovered(eng->hub, s);
    }
    engine_realtime(eng, sl, now);
    hist_observe(&s->encode_time, ctx.encode_ms * 1e-3);
    return rc ? -1 : 0;
}

/* Matches slots to the hub's live streams: drops destroyed ones, adds new ones. */
static void engine_sync_slots(struct engine *eng)
{
    int n;
    struct stream **live = hub_snapshot(eng->hub, &n);
    for (int i = 0; i < eng->nslots;) {
        bool found = false;
        for (int j = 0; j < n && !found; j++) found = live[j] == eng->slots[i].s;
        if (found) {
            i++;
            continue;
        }
        engine_drop_fx(&eng->slots[i]);
        stream_unref(eng->slots[i].s);
        eng->slots[i] = eng->slots[--eng->nslots];
    }
    for (int j = 0; j < n; j++) {
        bool found = false;
        for (int i = 0; i < eng->nslots && !found; i++) found = eng->slots[i].s == live[j];
        if (found) continue;
        struct engine_slot *p = realloc(eng->slots, (size_t)(eng->nslots + 1) * sizeof *p);
        if (!p) break;
        eng->slots = p;
        memset(&p[eng->nslots], 0, sizeof *p);
        stream_ref(live[j]);
        p[eng->nslots++].s = live[j];
    }
    hub_release_all(live, n);
}

/* Pauses a stream after a failure; a later parameter change or reset ends the pause. */
static void engine_pause(struct engine_slot *sl, uint64_t gen, uint64_t reset_gen, double now)
{
    sl->fail_gen = gen;
    sl->fail_reset = reset_gen;
    sl->next_due = fmax(sl->next_due, now + engine_backoff(sl->fails));
}

/* Whether this daemon computes the stream now (hub.h struct stream_lease). A lease taken
 * (again) starts the effect afresh, numbering frames on from the previous owner's, from this
 * daemon's own and from any relayed here, whichever is highest (a Redis that lost its data
 * knows none); one lost or run out drops the effect. */
static bool engine_holds(struct engine *eng, struct engine_slot *sl, const struct stream_lease *l, double now)
{
    bool mine = l->owned && now < l->until;
    if (mine && l->gen != sl->lease_gen) {
        engine_drop_fx(sl);
        sl->lease_gen = l->gen;
        sl->running = false;
        for (int k = 1; k <= FXS_KIND_MAX; k++) {
            uint64_t relayed = hub_latest_seq(eng->hub, sl->s, k);
            if (l->seq_from[k] > sl->seq[k]) sl->seq[k] = l->seq_from[k];
            if (relayed > sl->seq[k]) sl->seq[k] = relayed;
        }
    }
    if (!mine && sl->state) engine_drop_fx(sl);
    if (!mine) sl->running = false;
    return mine;
}

/* Reads the stream's state from the hub and whether it is ready (the header comment); false
 * when this daemon does not compute it or it pauses for want of subscribers. */
static bool engine_scan(struct engine *eng, struct engine_slot *sl, double now)
{
    struct stream_status st;
    hub_status(eng->hub, sl->s, &st);
    sl->ready = false;
    if (!engine_holds(eng, sl, &st.lease, now)) return false;
    if (eng->pause_idle && st.subscribers == 0 && !st.lease.remote_demand) {
        if (sl->running) hub_set_pace(eng->hub, sl->s, 0, 0);
        sl->running = false;
        sl->rt_wall = 0; /* a pause is not slowness */
        return false;
    }
    if (!sl->running) {
        sl->running = true;
        sl->next_due = sl->last_wall = sl->pace_t = now;
        sl->pace_n = 0;
        sl->achieved = 0;
        sl->usage = fmax(sl->usage, 0.5 * ENGINE_FLOOR_SHARE * ENGINE_SHARE_TAU_S); /* not starved at once */
    }
    sl->period = 1.0 / (st.fps > 0 ? st.fps : 1.0);
    sl->hub_gen = st.params_gen;
    sl->hub_reset = st.reset_gen;
    if (sl->fails && (st.params_gen != sl->fail_gen || st.reset_gen != sl->fail_reset))
        sl->next_due = now; /* a set or reset retries at once */
    if (sl->working && (st.params_gen != sl->gen || st.reset_gen != sl->reset_gen))
        sl->attained = 0; /* the change starts the step over: a new frame */
    sl->ready = sl->working || now >= sl->next_due;
    return true;
}

/* Publishes the stream's share of the engine and, over a window that ends at a completed step
 * a second or more after it began (or after ENGINE_PACE_MAX_S without one), its steps per
 * second; at most once a second. */
static void engine_pace(struct engine *eng, struct engine_slot *sl, double now)
{
    if (now - sl->pace_shown < 1.0) return;
    double span = now - sl->pace_t;
    if (span >= 1.0 && (sl->pace_n > 0 || span >= ENGINE_PACE_MAX_S)) {
        sl->achieved = (double)sl->pace_n / span;
        sl->pace_t = now;
        sl->pace_n = 0;
    }
    hub_set_pace(eng->hub, sl->s, sl->achieved, sl->usage / ENGINE_SHARE_TAU_S);
    sl->pace_shown = now;
}

/* Ages every stream's engine usage to now. */
static void engine_decay(struct engine *eng, double now)
{
    double k = exp(-fmax(now - eng->decay_t, 0.0) / ENGINE_SHARE_TAU_S);
    for (int i = 0; i < eng->nslots; i++) eng->slots[i].usage *= k;
    eng->decay_t = now;
}

/* Engine seconds of the stream's current frame (0 for one not started). */
static double engine_attained(const struct engine_slot *sl) { return sl->working ? sl->attained : 0; }

/* Engine seconds of the stream's frames: the last one's, or the current one's so far if more. */
static double engine_cost(const struct engine_slot *sl) { return fmax(sl->cost, engine_attained(sl)); }

/* Sets each running stream's long_s (the header comment): ENGINE_LONG_S, or ENGINE_HEAVY_RATIO
 * times the cost of the cheapest other stream whose frames take ENGINE_SLICE_MIN_S or more. */
static void engine_long(struct engine *eng)
{
    for (int i = 0; i < eng->nslots; i++) {
        double cheapest = INFINITY;
        for (int j = 0; j < eng->nslots; j++) {
            double c = engine_cost(&eng->slots[j]);
            if (j != i && eng->slots[j].running && c >= ENGINE_SLICE_MIN_S) cheapest = fmin(cheapest, c);
        }
        eng->slots[i].long_s = fmax(ENGINE_LONG_S, isinf(cheapest) ? 0 : ENGINE_HEAVY_RATIO * cheapest);
    }
}

enum { ENGINE_STARVED, ENGINE_INTERACTIVE, ENGINE_BACKGROUND };

/* The stream's class (the header comment); floor: the usage below which it is starved. */
static int engine_class(const struct engine_slot *sl, double floor)
{
    if (sl->usage < floor) return ENGINE_STARVED;
    return engine_cost(sl) > sl->long_s ? ENGINE_BACKGROUND : ENGINE_INTERACTIVE;
}

/* The usage a stream is ranked by in its class: the one that ran last gets ENGINE_QUANTUM_S off. */
static double engine_rank(const struct engine *eng, const struct engine_slot *sl)
{
    return sl->usage - (sl->s == eng->last ? ENGINE_QUANTUM_S : 0);
}

/* Whether ready stream a comes before ready stream b (the header comment). */
static bool engine_before(const struct engine *eng, const struct engine_slot *a, const struct engine_slot *b,
                          double floor)
{
    int ca = engine_class(a, floor), cb = engine_class(b, floor);
    if (ca != cb) return ca < cb;
    double ra = ca == ENGINE_STARVED ? a->usage : engine_rank(eng, a);
    double rb = cb == ENGINE_STARVED ? b->usage : engine_rank(eng, b);
    if (ra != rb) return ra < rb;
    return a->next_due < b->next_due;
}

/* When b's slice ends: when another stream would come before it (the header comment), within
 * [ENGINE_SLICE_MIN_S, ENGINE_SLICE_MAX_S] from now; usage's decay over a slice is neglected.
 * A starved stream catches up ENGINE_QUANTUM_S at a time: seldom enough that the others'
 * frames are cut into few pieces. */
static double engine_slice_end(const struct engine *eng, const struct engine_slot *b, double floor, double now)
{
    int cb = engine_class(b, floor);
    if (cb == ENGINE_STARVED) return now + ENGINE_QUANTUM_S;
    double end = now + ENGINE_SLICE_MAX_S;
    for (int i = 0; i < eng->nslots; i++) {
        const struct engine_slot *o = &eng->slots[i];
        if (o == b || !o->running) continue;
        if (cb == ENGINE_INTERACTIVE) /* b turns background, and o may come first */
            end = fmin(end, now + b->long_s - engine_attained(b));
        int co = engine_class(o, floor);
        double t = INFINITY; /* when o comes before b */
        if (co < cb)
            t = now;
        else if (co == cb) /* b grows from its usage, with the last runner's quantum off */
            t = now + engine_rank(eng, o) - (b->usage - ENGINE_QUANTUM_S);
        if (!o->ready)
            t = fmax(t, o->next_due);
        else if (floor > 0)
            t = fmin(t, now + ENGINE_SHARE_TAU_S * log(fmax(o->usage / floor, 1.0)));
        end = fmin(end, t);
    }
    return fmax(end, now + ENGINE_SLICE_MIN_S);
}

/* Counts engine seconds spent on the stream: in its usage, /metrics and the cluster's load. */
static void engine_account(struct engine *eng, struct engine_slot *sl, double spent)
{
    sl->usage += spent;
    atomic_fetch_add(&eng->busy_ns, (uint_fast64_t)(spent * 1e9));
    atomic_fetch_add(&sl->s->engine_ns, (uint_fast64_t)(spent * 1e9));
}

/* Runs one slice of sl and accounts for its engine time; a completed step schedules the next. */
static void engine_run(struct engine *eng, struct engine_slot *sl, double now, double slice_end)
{
    if (!sl->working) {
        sl->frame_due = sl->next_due;
        sl->attained = 0;
    }
    int rc = engine_step(eng, sl, now, slice_end);
    double end = clock_now(), spent = end - now;
    sl->attained += spent;
    engine_account(eng, sl, spent);
    if (rc == EFFECT_MORE) return;
    atomic_fetch_add(&sl->s->steps, 1);
    hist_observe(&sl->s->step_time, sl->attained);
    sl->cost = sl->attained;
    sl->pace_n++;
    sl->next_due = fmax(sl->frame_due + sl->period, end); /* overrun: no catch-up burst */
    if (rc) engine_pause(sl, sl->hub_gen, sl->hub_reset, end);
}

/* Runs one slice of the ready stream that comes first; returns when to look again: at once
 * while a stream is ready, else at the next due time. */
static double engine_run_due(struct engine *eng)
{
    double now = clock_now(), next = now + 1.0;
    engine_decay(eng, now);
    int nready = 0;
    for (int i = 0; i < eng->nslots; i++) {
        struct engine_slot *sl = &eng->slots[i];
        if (!engine_scan(eng, sl, now)) continue;
        engine_pace(eng, sl, now);
        double t0 = clock_now();
        engine_catch_up(eng, sl);
        engine_account(eng, sl, clock_now() - t0);
        if (sl->ready)
            nready++;
        else
            next = fmin(next, sl->next_due);
    }
    if (!nready) return next;
    now = clock_now(); /* the slice starts after any catch-up's encoding */
    engine_long(eng);
    double floor = nready > 1 ? ENGINE_FLOOR_SHARE * ENGINE_SHARE_TAU_S / nready : 0;
    struct engine_slot *first = NULL;
    for (int i = 0; i < eng->nslots; i++)
        if (eng->slots[i].ready && (!first || engine_before(eng, &eng->slots[i], first, floor)))
            first = &eng->slots[i];
    engine_run(eng, first, now, engine_slice_end(eng, first, floor, now));
    eng->last = first->s;
    return clock_now();
}

static void *engine_main(void *arg)
{
    struct engine *eng = arg;
    for (;;) {
        bool stopping;
        uint64_t gen = hub_generation(eng->hub, &stopping);
        if (stopping) break;
        engine_sync_slots(eng);
        double next = engine_run_due(eng);
        hub_wait(eng->hub, gen, next);
    }
    return NULL;
}

int engine_start(struct engine *eng, struct hub *hub, struct ocl *ocl, bool pause_idle, struct fx_err *err)
{
    eng->slots = NULL; /* export_frame and export_ctx are the caller's (engine.h) */
    eng->nslots = 0;
    atomic_store(&eng->busy_ns, 0);
    eng->hub = hub;
    eng->ocl = ocl;
    eng->pause_idle = pause_idle;
    eng->decay_t = clock_now();
    eng->last = NULL;
    if (pthread_create(&eng->thread, NULL, engine_main, eng))
        return fx_fail(err, "internal", NULL, "cannot start the engine thread");
    eng->started = true;
    return 0;
}

void engine_stop(struct engine *eng)
{
    if (!eng->started) return;
    hub_stop(eng->hub);
    pthread_join(eng->thread, NULL);
    for (int i = 0; i < eng->nslots; i++) {
        engine_drop_fx(&eng->slots[i]);
        stream_unref(eng->slots[i].s);
    }
    free(eng->slots);
    eng->slots = NULL;
    eng->nslots = 0;
    eng->started = false;
}
