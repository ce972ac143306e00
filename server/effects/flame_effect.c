/* flame_effect.c — effect `flame` as the engine runs it (effect_ops): the simulation
 * (flame.c) advanced by a frame plan (../frame_plan.h: how many substeps each frame runs,
 * carrying undone simulated time), and the frames: the particles read back once a frame,
 * scaled into the codec's arrays and encoded only when a subscriber takes the default
 * encoding. The next frame's first substep runs beside the encoding, so the device, or PoCL's
 * workers on the CPU's other cores, do not wait for the host. */
#include "flame_effect.h"

#include <stdlib.h>
#include <unistd.h>

#include "../clock.h"
#include "../frame_plan.h"
#include "../ocl.h"
#include "flame.h"
#include "fxs_frame.h"
#include "fxs_particles.h"

/* On a GPU device a frame of 2 x 4096 particles or more is encoded as up to this many blocks
 * on as many of the host's cores (PROTOCOL.md §7.5.8), which are free during the device's
 * work: a 50k-particle frame encodes nearly 4x faster as 8 blocks, for 1-2% more bytes, and
 * the `large` preset's 220k particles need 16 to leave room in a 30 fps frame (README). On
 * a CPU device (PoCL) one thread: the other cores are the ones PoCL's workers step on, so a
 * second encoding thread slows the simulation more than it speeds the encoding. */
#define FL_ENC_THREADS_MAX 16

/* The frame's arrays: as read back (pos, vel 4 floats a particle, flags, stable ids), and as the
 * codec takes them (xyz and vel scaled, T, F, the flag byte). */
struct fl_frame_arrays {
    float *h_pos, *h_vel, *xyz, *temp, *fuel, *vel; /* vel: 3 per particle, the frame's velocities */
    uint32_t *h_flags, *h_id;
    uint8_t *flags8;
    int cap;
};

/* How frames are made of the state, from the parameters. */
struct fl_output {
    double space_scale;
    int pos_bits, vel_bits;
    bool velocities;
    int enc_threads; /* threads a frame's encoding may use: 1 on a CPU device, else the cores up to FL_ENC_THREADS_MAX */
};

struct flame_stream {
    struct flame *sim;
    struct frame_plan plan;
    struct fl_output out;
    struct fl_frame_arrays frame;
    uint8_t *payload; /* the latest frame's codec 2/3 payload, made when wanted (fl_encode) */
};

struct flame *flame_effect_sim(void *state) { return ((struct flame_stream *)state)->sim; }

static void fl_frame_arrays_free(struct fl_frame_arrays *f)
{
    void *a[] = {f->h_pos, f->h_vel, f->xyz, f->temp, f->fuel, f->vel, f->h_flags, f->h_id, f->flags8};
    for (size_t i = 0; i < sizeof a / sizeof a[0]; i++) free(a[i]);
}

static int fl_frame_buffers(struct fl_frame_arrays *f, int n)
{
    if (n <= f->cap) return 0;
    int cap = n + n / 2 + 1024;
    float **fp[] = {&f->h_pos, &f->h_vel, &f->xyz, &f->temp, &f->fuel, &f->vel};
    size_t fs[] = {4, 4, 3, 1, 1, 3};
    for (int i = 0; i < 6; i++) {
        free(*fp[i]);
        *fp[i] = malloc(fs[i] * sizeof(float) * (size_t)cap);
    }
    free(f->h_flags);
    free(f->h_id);
    free(f->flags8);
    f->h_flags = malloc(sizeof(uint32_t) * (size_t)cap);
    f->h_id = malloc(sizeof(uint32_t) * (size_t)cap);
    f->flags8 = malloc((size_t)cap);
    f->cap = 0;
    if (!f->h_pos || !f->h_vel || !f->xyz || !f->temp || !f->fuel || !f->vel || !f->h_flags || !f->h_id || !f->flags8)
        return -1;
    f->cap = cap;
    return 0;
}

/* Reads the particles once (with the error flag) into the frame arrays; returns n, or -1. */
static int fl_read_frame(struct flame_stream *fs, struct fx_err *err)
{
    struct fl_frame_arrays *f = &fs->frame;
    int n = flame_count(fs->sim);
    if (fl_frame_buffers(f, n)) return fx_fail(err, "internal", "", "out of memory for %d particles", n);
    if (flame_read_frame(fs->sim, f->h_pos, f->h_vel, f->h_flags, f->h_id, err) < 0) return -1;
    float s = (float)fs->out.space_scale;
    for (int i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++) f->xyz[3 * i + k] = s * f->h_pos[4 * i + k];
        for (int k = 0; k < 3 && fs->out.velocities; k++) f->vel[3 * i + k] = s * f->h_vel[4 * i + k];
        f->temp[i] = f->h_pos[4 * i + 3];
        f->fuel[i] = f->h_vel[4 * i + 3];
        f->flags8[i] = (uint8_t)f->h_flags[i];
    }
    return n;
}

/* The frame's codec 2/3 payload (effect_frame.encode): made only when a subscriber takes it. */
static int fl_encode(void *self, struct effect_frame *fr, struct fx_err *err)
{
    struct flame_stream *fs = self;
    size_t len = 0;
    char msg[160];
    double t0 = clock_now() * 1e3;
    free(fs->payload);
    fs->payload = NULL;
    if (fxs_particles_encode(&fr->particles, &fr->particle_opts, &fs->payload, &len, msg, sizeof msg))
        return fx_fail(err, "internal", "", "flame: particle encoding failed: %s", msg);
    fr->codec = fxs_particles_codec(fs->payload, len);
    fr->payload = fs->payload;
    fr->payload_bytes = len;
    fr->encode_ms = clock_now() * 1e3 - t0;
    return 0;
}

/* Reads the particles and emits one kind 1 frame. The next frame's first substep is enqueued
 * before the encoding (when that frame will step at all), so that the device, or PoCL's
 * workers on the CPU's other cores, compute it while the host encodes: the encoding no longer
 * leaves the device idle. It completes before this returns, so no work is left in flight
 * between frames, and its time counts in emit_ms, which the next frame's budget leaves out. */
static int fl_emit_frame(struct flame_stream *fs, effect_emit_fn emit, void *ctx, struct fx_err *err)
{
    double t_read = clock_now() * 1e3;
    int n = fl_read_frame(fs, err);
    if (n < 0) return -1;
    bool pre = frame_plan_run_ahead(&fs->plan);
    if (pre && flame_substep_begin(fs->sim, err)) return -1;
    const struct fl_frame_arrays *f = &fs->frame;
    struct effect_frame fr = {
        .kind = FXS_KIND_PARTICLES,
        .count_or_width = (uint32_t)n,
        .encode = fl_encode,
        .self = fs,
        .particles = {(uint32_t)n, f->xyz, f->temp, f->fuel, f->flags8, fs->out.velocities ? f->vel : NULL},
        .ids = f->h_id,
        .particle_opts = {.pos_bits = fs->out.pos_bits, .vel_bits = fs->out.vel_bits, .threads = fs->out.enc_threads},
    };
    int ret = emit(ctx, &fr);
    struct fx_err end_err = {0};
    if (pre && (flame_substep_end(fs->sim, &end_err) || flame_finish(fs->sim, &end_err)) && ret == 0) {
        *err = end_err;
        ret = -1;
    }
    frame_plan_emitted(&fs->plan, clock_now() * 1e3 - t_read);
    return ret;
}

/* The simulation as the frame plan drives it. */
static int fl_plan_substep(void *self, struct fx_err *err) { return flame_substep(self, err); }
static bool fl_plan_syncs(void *self) { return flame_substep_syncs(self); }
static int fl_plan_finish(void *self, struct fx_err *err) { return flame_finish(self, err); }
static double fl_plan_now_ms(void *self)
{
    (void)self;
    return clock_now() * 1e3;
}

static int fl_step(void *self, double sim_time, double dt, double slice_end, effect_emit_fn emit, void *ctx,
                   struct fx_err *err)
{
    struct flame_stream *fs = self;
    (void)sim_time;
    if (!fs->plan.busy) frame_plan_begin(&fs->plan, dt);
    struct frame_plan_sim sim = {fs->sim, fl_plan_substep, fl_plan_syncs, fl_plan_finish, fl_plan_now_ms};
    int rc = frame_plan_run(&fs->plan, &sim, slice_end, err);
    return rc ? rc : fl_emit_frame(fs, emit, ctx, err);
}

/* The frame plan's and the frames' settings of c. */
static void fl_stream_settings(struct flame_stream *fs, const struct flame_config *c)
{
    frame_plan_set(&fs->plan, c->dt, c->fps, c->time_scale, c->max_substeps);
    fs->out.space_scale = c->space_scale;
    fs->out.pos_bits = c->pos_bits;
    fs->out.vel_bits = c->vel_bits;
    fs->out.velocities = c->velocities;
}

static void fl_destroy(void *self)
{
    struct flame_stream *fs = self;
    if (!fs) return;
    flame_free(fs->sim);
    fl_frame_arrays_free(&fs->frame);
    free(fs->payload);
    free(fs);
}

static void *fl_create(struct ocl *ocl, const void *params, struct fx_err *err)
{
    struct flame_stream *fs = calloc(1, sizeof *fs);
    if (!fs) {
        fx_fail(err, "internal", "", "out of memory");
        return NULL;
    }
    if (!(fs->sim = flame_new(ocl, params, err))) {
        fl_destroy(fs);
        return NULL;
    }
    long cores = ocl_is_cpu(ocl) ? 1 : sysconf(_SC_NPROCESSORS_ONLN);
    fs->out.enc_threads = cores < 1 ? 1 : cores > FL_ENC_THREADS_MAX ? FL_ENC_THREADS_MAX : (int)cores;
    fl_stream_settings(fs, params);
    frame_plan_reset(&fs->plan);
    return fs;
}

static int fl_apply(void *self, const void *params, struct fx_err *err)
{
    struct flame_stream *fs = self;
    frame_plan_abandon(&fs->plan);
    fl_stream_settings(fs, params);
    return flame_set(fs->sim, params, err);
}

static int fl_reset(void *self, struct fx_err *err)
{
    struct flame_stream *fs = self;
    frame_plan_reset(&fs->plan);
    return flame_reset(fs->sim, err);
}

static double fl_sim_seconds(void *self) { return flame_sim_seconds(((struct flame_stream *)self)->sim); }

const struct effect_ops flame_effect = {
    .name = "flame",
    .doc = "SPH flame (Mabuchi 2012): weakly compressible SPH gas carrying temperature and fuel, combustion "
           "S = k_rs T F, stabilised heat and fuel diffusion, buoyancy, wind, burning solid sources and moving "
           "obstacles, with particles born next to flame particles and deleted away from them; every step on "
           "the OpenCL device, advancing in real time (time_scale) and streamed as particle frames.",
    .params = flame_params,
    .params_size = sizeof(struct flame_config),
    .param_slots = FP_COUNT,
    .presets = flame_presets,
    .outputs_json = "[{\"kind\":1,\"codec\":\"particles\",\"fields\":\"xyz (x space_scale), T, F, flags "
                    "(type bits 0-1, flame bit 2), with velocities on vx vy vz (x space_scale)\",\"count\":"
                    "\"particles\",\"rate\":\"fps\"}]",
    .create = fl_create,
    .apply = fl_apply,
    .step = fl_step,
    .reset = fl_reset,
    .destroy = fl_destroy,
    .sim_seconds = fl_sim_seconds,
};
