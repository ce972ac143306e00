/* test_flame_frames.c — the flame effect's frames through its effect_ops, as the engine
 * drives them: one kind 1 frame per step, the same in slices (a substep per call) as whole,
 * real time from the substep plan, a paused
 * stream that does not move, max_substeps counting the substep run ahead, and the substep that runs beside the encoding (flame.c
 * fl_emit_frame): the frame shows the state before it, and the simulation afterwards is
 * the one flame_run gives, bit for bit. A coarse scene (Table 3.1's h, a few hundred
 * particles) keeps every frame far inside its wall-clock budget, so the plan is never cut. */
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "effects/flame.h"
#include "effects/flame_effect.h"
#include "fxs_frame.h"
#include "fxs_particles.h"
#include "ocl.h"
#include "params.h"
#include "slices.h"

#define TFF_SCENE "{\"h\":0.01125}"

static struct ocl *tff_ocl;

/* What the emit callback saw: frames, and the particles of the latest one. */
struct tff_seen {
    int frames, bad;
    struct fxs_particles last;
};

static int tff_emit(void *ctx, const struct effect_frame *fr)
{
    struct tff_seen *s = ctx;
    struct effect_frame f = *fr;
    struct fx_err err = {0};
    char msg[160];
    s->frames++;
    fxs_particles_free(&s->last);
    if (f.kind != FXS_KIND_PARTICLES || effect_frame_encode(&f, &err) ||
        fxs_particles_decode(f.payload, f.payload_bytes, &s->last, msg, sizeof msg) || s->last.n != f.count_or_width)
        s->bad++;
    return 0;
}

/* A flame effect state (flame_effect.create) of the default scene with `partial` over it. */
static void *tff_new(const char *partial)
{
    struct fx_err err = {0};
    cJSON *def = params_defaults(flame_params), *in = cJSON_Parse(partial), *doc = NULL;
    void *fl = NULL;
    struct flame_config c;
    if (in && params_merge(flame_params, def, in, &doc, &err) == 0 &&
        params_load(flame_params, doc, &c, sizeof c, &err) == 0)
        fl = flame_effect.create(tff_ocl, &c, &err);
    CHECK(fl != NULL, "create(%s): %s", partial, err.message);
    cJSON_Delete(def);
    cJSON_Delete(in);
    cJSON_Delete(doc);
    return fl;
}

/* Steps `frames` frames of 1/30 s through flame_effect.step: one good frame each. */
static void tff_frames(void *fl, int frames, struct tff_seen *seen)
{
    struct fx_err err = {0};
    for (int i = 0; i < frames; i++) {
        int rc = flame_effect.step(fl, (i + 1) / 30.0, 1.0 / 30, INFINITY, tff_emit, seen, &err);
        CHECK(rc == 0, "step %d: %s", i, err.message);
        if (rc) return;
    }
    CHECK(seen->frames == frames && seen->bad == 0, "%d frames, %d bad", seen->frames, seen->bad);
}

/* 30 frames of 1/30 s simulate 1 s: to within the substep that runs ahead of the last frame
 * (dt 3 ms) and the rounding of the plan. */
static void test_real_time(void)
{
    void *fl = tff_new(TFF_SCENE);
    if (!fl) return;
    struct tff_seen seen = {0};
    tff_frames(fl, 30, &seen);
    CHECK_NEAR(flame_effect.sim_seconds(fl), 1.0, 0.0045);
    fxs_particles_free(&seen.last);
    flame_effect.destroy(fl);
}

/* time_scale 0: frames keep coming, nothing steps (not even ahead of the next frame). */
static void test_paused(void)
{
    void *fl = tff_new("{\"h\":0.01125,\"time_scale\":0}");
    if (!fl) return;
    struct tff_seen seen = {0};
    struct flame *sim = flame_effect_sim(fl);
    int n0 = flame_count(sim);
    tff_frames(fl, 10, &seen);
    CHECK(flame_steps(sim) == 0, "%llu steps while paused", (unsigned long long)flame_steps(sim));
    CHECK(flame_effect.sim_seconds(fl) == 0.0, "sim %g s while paused", flame_effect.sim_seconds(fl));
    CHECK(flame_count(sim) == n0 && (int)seen.last.n == n0, "count %d, frame %u, solids %d", flame_count(sim),
          seen.last.n, n0);
    fxs_particles_free(&seen.last);
    flame_effect.destroy(fl);
}

/* max_substeps 2: 2 substeps a frame, the one run ahead of the next frame among them (the
 * last frame's ahead: 10 frames, 21 substeps). */
static void test_max_substeps(void)
{
    void *fl = tff_new("{\"h\":0.01125,\"max_substeps\":2}");
    if (!fl) return;
    struct tff_seen seen = {0};
    tff_frames(fl, 10, &seen);
    uint64_t steps = flame_steps(flame_effect_sim(fl));
    CHECK(steps == 21, "%llu substeps in 10 frames at max_substeps 2", (unsigned long long)steps);
    fxs_particles_free(&seen.last);
    flame_effect.destroy(fl);
}

/* Means of x, y, z and T of a decoded frame or of a read-back state. */
static void tff_means(int n, const float *xyz, int xyz_stride, const float *t, int t_stride, double m[4])
{
    memset(m, 0, 4 * sizeof *m);
    for (int i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++) m[k] += xyz[(size_t)xyz_stride * i + k];
        m[3] += t[(size_t)t_stride * i];
    }
    for (int k = 0; k < 4 && n > 0; k++) m[k] /= n;
}

/* After 40 frames the effect has run one substep past its last frame. The frame equals the
 * state of flame_run one substep short (same count; mean position within the 16-bit grid's
 * step, mean T within the 10-bit step), and one substep more gives the effect's state bit
 * for bit: running ahead changes neither the frame nor the simulation. */
static void test_frame_before_prerun(void)
{
    struct fx_err err = {0};
    void *a = tff_new(TFF_SCENE), *b = tff_new(TFF_SCENE);
    if (!a || !b) goto out;
    struct tff_seen seen = {0};
    tff_frames(a, 40, &seen);
    int steps = (int)flame_steps(flame_effect_sim(a));
    CHECK(steps > 100, "%d steps", steps);
    if (flame_run(flame_effect_sim(b), steps - 1, &err)) {
        CHECK(0, "flame_run: %s", err.message);
        goto out;
    }
    struct flame_particles pb = {0}, pa = {0};
    if (flame_read(flame_effect_sim(b), &pb, &err) == 0) {
        double mf[4], mb[4];
        CHECK((int)seen.last.n == pb.n, "frame %u particles, state one step before %d", seen.last.n, pb.n);
        tff_means((int)seen.last.n, seen.last.xyz, 3, seen.last.temp, 1, mf);
        tff_means(pb.n, pb.pos, 4, pb.pos + 3, 4, mb);
        for (int k = 0; k < 3; k++) CHECK_NEAR(mf[k], mb[k], 2e-5);
        CHECK_NEAR(mf[3], mb[3], 10.0);
        flame_particles_free(&pb);
    }
    if (flame_run(flame_effect_sim(b), 1, &err) || flame_read(flame_effect_sim(b), &pb, &err) ||
        flame_read(flame_effect_sim(a), &pa, &err)) {
        CHECK(0, "run/read: %s", err.message);
    } else {
        CHECK(pa.n == pb.n && memcmp(pa.pos, pb.pos, 16 * (size_t)pa.n) == 0 &&
                  memcmp(pa.vel, pb.vel, 16 * (size_t)pa.n) == 0 && memcmp(pa.id, pb.id, 4 * (size_t)pa.n) == 0,
              "effect and flame_run differ after %d steps (%d vs %d particles)", steps, pa.n, pb.n);
    }
    flame_particles_free(&pa);
    flame_particles_free(&pb);
    fxs_particles_free(&seen.last);
out:
    if (a) flame_effect.destroy(a);
    if (b) flame_effect.destroy(b);
}

/* A frame stepped a substep per call (the engine's slices, slices.h) is the frame stepped
 * whole: the same particles, byte for byte, frame after frame. */
static void test_sliced_frames(void)
{
    void *a = tff_new(TFF_SCENE), *b = tff_new(TFF_SCENE);
    struct slices_frame fa = {.kind = FXS_KIND_PARTICLES}, fb = {.kind = FXS_KIND_PARTICLES};
    struct fx_err err = {0};
    int most = 0, frames = 0, same = 1;
    for (; a && b && frames < 10 && same; frames++) {
        double t = (frames + 1) / 30.0;
        if (slices_step(&flame_effect, a, t, INFINITY, &fa, &err) || slices_step(&flame_effect, b, t, 0, &fb, &err)) {
            CHECK(0, "frame %d: %s", frames, err.message);
            break;
        }
        same = fa.payload && fa.len == fb.len && !memcmp(fa.payload, fb.payload, fa.len);
        most = fb.calls > most ? fb.calls : most;
    }
    CHECK(same, "frame %d in slices differs from the whole one", frames - 1);
    CHECK(most > 2, "a frame took up to %d calls in slices", most);
    slices_free(&fa);
    slices_free(&fb);
    if (a) flame_effect.destroy(a);
    if (b) flame_effect.destroy(b);
}

int main(void)
{
    struct fx_err err = {0};
    if (ocl_open(&tff_ocl, CHECK_DEVICE(), &err)) return CHECK_ABORT("ocl_open(%s): %s", CHECK_DEVICE(), err.message);
    RUN(test_real_time);
    RUN(test_paused);
    RUN(test_max_substeps);
    RUN(test_frame_before_prerun);
    RUN(test_sliced_frames);
    ocl_close(tff_ocl);
    return CHECK_DONE();
}
