/* bench_flame.c — throughput of effect flame through PoCL (or any OpenCL device).
 *
 * 1. Particle-steps per second on three lattice blocks, named by their particle count once
 *    warmed up (about 23k, 59k and 195k; the target: >= 10 M at ~50k). Scene: a cubic
 *    lattice block of gas at spacing d = h/2 (the §8 A3 lattice, 32 neighbours inside) loaded
 *    with flame_load (22^3, 37^3, 58^3), every particle a flame particle (T 1500 K, F 1) with
 *    k_rs = 0 and k_buo = 0, so resampling keeps them and the block stays put; the full step
 *    runs (sort, density, forces, integration, resampling every 5 steps); the insertions at
 *    the faces double the smallest block in the warm-up and grow the others less.
 *    Per-kernel split from the profiling events (ms per step and share), and the step's wall
 *    time beside the kernels' sum: the rest is launches, the resampling read-back and the
 *    host's waits.
 * 2. The default scene (one source, defaults): N after warm-up and the achievable real-time
 *    factor through effect_ops.step at 30 frames per second (substeps + read-back + encode),
 *    and the particle encoding's share of that step time, as /metrics computes it
 *    (fxs_stream_encode_seconds over fxs_stream_step_seconds: the frames' encode_ms over the
 *    wall time of the step calls).
 * One line per figure; under two minutes on a 2-core PoCL. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "../ref/flame_shape.h"
#include "effects/flame.h"
#include "effects/flame_effect.h"
#include "fxs_particles.h"
#include "ocl.h"
#include "params.h"

#define BENCH_MAX_STATS 32
#define BENCH_TARGET_K 37 /* the block of ~59k particles, which carries the target ">= 10 M particle-steps/s at ~50k" */

/* CPU seconds of this process (all its threads): on a shared machine, process CPU time
 * divided by the cores gives the wall time the work would take with the machine to itself
 * (PoCL keeps both cores busy during the kernels; the host thread waits without spinning). */
static double bench_cpu(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

static double bench_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static void bench_die(const char *what, const struct fx_err *err)
{
    fprintf(stderr, "bench_flame: %s: %s\n", what, err->message);
    exit(1);
}

/* The typed parameters of a complete document. */
static struct flame_config bench_typed(const cJSON *doc)
{
    struct flame_config c;
    struct fx_err err = {0};
    if (params_load(flame_params, doc, &c, sizeof c, &err)) bench_die("parameters", &err);
    return c;
}

static cJSON *bench_doc(const char *overrides)
{
    struct fx_err err;
    cJSON *base = params_defaults(flame_params), *out = NULL, *o = cJSON_Parse(overrides);
    if (!base || !o || params_merge(flame_params, base, o, &out, &err)) bench_die("bad document", &err);
    cJSON_Delete(base);
    cJSON_Delete(o);
    return out;
}

/* A k^3 lattice at spacing d centred at the origin, all gas flame particles. */
static void bench_lattice(struct flame_particles *p, int k, double d)
{
    if (flame_particles_alloc(p, k * k * k)) exit(1);
    int n = 0;
    for (int x = 0; x < k; x++)
        for (int y = 0; y < k; y++)
            for (int z = 0; z < k; z++, n++) {
                float *r = p->pos + 4 * n;
                r[0] = (float)(d * (x - k / 2));
                r[1] = (float)(d * (y - k / 2));
                r[2] = (float)(d * (z - k / 2));
                r[3] = 1500.0f;
                p->vel[4 * n + 3] = 1.0f;
                p->flags[n] = FLAME_GAS | FLAME_IS_FLAME;
                p->id[n] = (uint32_t)n;
            }
}

static int bench_cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static int bench_stats(struct ocl *ocl, struct ocl_kernel_stat *s)
{
    return ocl_stats(ocl, s, BENCH_MAX_STATS);
}

/* Per-kernel ms per step between two ocl_stats snapshots; returns their total ms. */
static double bench_split(const char *label, struct ocl_kernel_stat *a, int na, struct ocl_kernel_stat *b, int nb,
                          int steps)
{
    double total = 0;
    for (int i = 0; i < nb; i++) {
        double prev = 0;
        for (int j = 0; j < na; j++)
            if (strcmp(a[j].name, b[i].name) == 0) prev = a[j].total_ms;
        b[i].total_ms -= prev;
        total += b[i].total_ms;
    }
    for (int i = 0; i < nb; i++)
        if (b[i].total_ms > 0)
            printf("flame %-6s kernel %-16s %8.3f ms/step  %5.1f%%\n", label, b[i].name, b[i].total_ms / steps,
                   100.0 * b[i].total_ms / total);
    return total;
}

/* One lattice block of k^3 particles stepped `steps` times; mode: "" (the device's own sort and
 * compaction), "blocks" or "wide" (flame_set_wide), named after the label. */
static void bench_size(struct ocl *ocl, int k, int steps, const char *mode)
{
    char label[24];
    struct fx_err err;
    cJSON *doc = bench_doc("{\"sources\":[],\"k_rs\":0,\"k_buo\":0,\"k_h\":0,\"k_f\":0,\"insert_nbr_threshold\":4,"
                           "\"max_particles\":4000000}");
    struct flame_config c = bench_typed(doc);
    struct flame *fl = flame_new(ocl, &c, &err);
    if (!fl) bench_die("flame_new", &err);
    if (*mode) flame_set_wide(fl, !strcmp(mode, "wide"));
    struct flame_particles p;
    bench_lattice(&p, k, c.h * c.particle_diameter);
    if (flame_load(fl, &p, &err) || flame_run(fl, 5, &err)) bench_die("warm-up", &err);
    struct ocl_kernel_stat a[BENCH_MAX_STATS], b[BENCH_MAX_STATS];
    int na = bench_stats(ocl, a);
    double t0 = bench_now(), c0 = bench_cpu(), psteps = 0, ms[256];
    for (int s = 0; s < steps; s++) {
        double t1 = bench_now();
        psteps += flame_count(fl);
        if (flame_run(fl, 1, &err)) bench_die("run", &err);
        ms[s < 256 ? s : 255] = (bench_now() - t1) * 1e3;
    }
    double wall = bench_now() - t0, cpu = bench_cpu() - c0, ncpu = (double)sysconf(_SC_NPROCESSORS_ONLN);
    int nb = bench_stats(ocl, b);
    snprintf(label, sizeof label, "%.0fk%s%s", psteps / steps * 1e-3, *mode ? "-" : "", mode); /* mean count */
    /* the median step as well: robust to other load on a shared 2-core machine */
    int m = steps < 256 ? steps : 256;
    qsort(ms, (size_t)m, sizeof ms[0], bench_cmp);
    double med = ms[m / 2];
    printf("flame %-6s N %7.0f  %7.2f ms/step  %6.2f M particle-steps/s  (median step %.2f ms: %.2f M/s)\n", label,
           psteps / steps, wall * 1e3 / steps, psteps / wall * 1e-6, med, psteps / steps / med * 1e-3);
    printf("flame %-6s CPU %.2f s for %d steps: %.2f M particle-steps/s with %.0f cores to itself%s\n", label, cpu,
           steps, psteps / (cpu / ncpu) * 1e-6, ncpu, k == BENCH_TARGET_K ? " (target >= 10 M)" : "");
    double kms = bench_split(label, a, na, b, nb, steps) / steps;
    const char *goal = ocl_is_cpu(ocl) ? "" : k >= 100 ? " (target >= 300 M at >= 1 M)"
                       : !strcmp(mode, "wide") ? " (target >= 100 M at 200k)" : ""; /* the GPU's targets */
    printf("flame %-6s step %.2f ms wall: kernels %.2f ms (the device busy %.0f%% of the time), launches, read-back "
           "and host waits %.2f ms%s\n", label, wall * 1e3 / steps, kms, 100 * kms / (wall * 1e3 / steps),
           wall * 1e3 / steps - kms, goal);
    flame_particles_free(&p);
    flame_free(fl);
    cJSON_Delete(doc);
}

#define BENCH_ENC_THREADS 4 /* the encodings of one frame compared: 1, 4, 8 and 16 threads */
static const int bench_enc_threads[BENCH_ENC_THREADS] = {1, 4, 8, 16};

struct bench_out {
    size_t bytes;
    double encode_ms;
    int frames_left;               /* the last frame is kept for bench_enc_scaling */
    struct fxs_particles last;     /* its arrays in one allocation (last.xyz) */
    struct fxs_particles_opts opts; /* the stream's encoding options (threads: what it may use) */
};

/* A copy of the frame's particles in o->last. */
static void bench_keep(struct bench_out *o, const struct effect_frame *fr)
{
    const struct fxs_particles *p = &fr->particles;
    size_t n = p->n, per = 3 + 1 + 1 + (p->vel ? 3 : 0);
    float *m = malloc(sizeof(float) * per * n + n + 1);
    if (!m) exit(1);
    o->last = (struct fxs_particles){(uint32_t)n, m, m + 3 * n, m + 4 * n, (uint8_t *)(m + per * n),
                                     p->vel ? m + 5 * n : NULL};
    memcpy(o->last.xyz, p->xyz, 12 * n);
    memcpy(o->last.temp, p->temp, 4 * n);
    memcpy(o->last.fuel, p->fuel, 4 * n);
    memcpy(o->last.flags, p->flags, n);
    if (p->vel) memcpy(o->last.vel, p->vel, 12 * n);
    o->opts = fr->particle_opts;
}

/* The kept frame encoded on each of bench_enc_threads (the best of 3 each), after the timed
 * frames: how the encoding scales with the host's cores. */
static void bench_enc_scaling(const char *name, struct bench_out *o)
{
    double ms[BENCH_ENC_THREADS];
    size_t bytes[BENCH_ENC_THREADS];
    for (int t = 0; t < BENCH_ENC_THREADS; t++) {
        struct fxs_particles_opts opts = o->opts;
        opts.threads = bench_enc_threads[t];
        ms[t] = INFINITY;
        for (int r = 0; r < 3; r++) {
            uint8_t *pay = NULL;
            char msg[160];
            double t0 = bench_now();
            if (fxs_particles_encode(&o->last, &opts, &pay, &bytes[t], msg, sizeof msg)) {
                fprintf(stderr, "bench_flame: encode: %s\n", msg);
                exit(1);
            }
            ms[t] = fmin(ms[t], (bench_now() - t0) * 1e3);
            free(pay);
        }
    }
    printf("flame %s encoding of the last frame (%u particles) on 1 / 4 / 8 / 16 threads: %.2f / %.2f / %.2f / %.2f ms, "
           "%zu / %zu / %zu / %zu bytes (this host: %.0f cores; the stream uses %d)\n", name, o->last.n, ms[0], ms[1],
           ms[2], ms[3], bytes[0], bytes[1], bytes[2], bytes[3], (double)sysconf(_SC_NPROCESSORS_ONLN),
           o->opts.threads > 1 ? o->opts.threads : 1);
    free(o->last.xyz);
}

static int bench_emit(void *ctx, const struct effect_frame *fr)
{
    struct bench_out *o = ctx;
    struct effect_frame f = *fr;
    struct fx_err err = {0};
    if (effect_frame_encode(&f, &err)) bench_die("encode", &err);
    o->bytes += f.payload_bytes;
    o->encode_ms += f.encode_ms;
    if (--o->frames_left == 0) bench_keep(o, fr);
    return 0;
}

/* Default scene: warm up `warm_s` simulated seconds, then frames paced at 30 fps of wall time
 * as the daemon's engine runs them (each step gets the wall time since the last one, at most
 * 0.25 s; a frame that overruns starts the next at once): real-time factor = simulated
 * seconds / wall seconds, the figure /metrics reports. */
static void bench_default(struct ocl *ocl, const char *name, const char *ov, double warm_s, int frames)
{
    struct fx_err err;
    cJSON *doc = bench_doc(ov ? ov : "{}");
    struct flame_config c = bench_typed(doc);
    void *st = flame_effect.create(ocl, &c, &err);
    if (!st) bench_die("create", &err);
    struct flame *fl = flame_effect_sim(st);
    double dt = c.dt;
    double t0 = bench_now();
    if (flame_run(fl, (int)(warm_s / dt), &err)) bench_die("warm-up", &err);
    double warm_wall = bench_now() - t0;
    struct bench_out out = {.frames_left = frames};
    double sim0 = flame_effect.sim_seconds(st);
    uint64_t st0 = flame_steps(fl);
    struct ocl_kernel_stat ka[BENCH_MAX_STATS], kb[BENCH_MAX_STATS];
    int nka = bench_stats(ocl, ka);
    t0 = bench_now();
    double c0 = bench_cpu(), nsum = 0;
    double busy = 0;
    double due = t0, last = t0 - 1.0 / 30; /* as if the frame before had started a period ago */
    for (int f = 0; f < frames; f++) {
        nsum += flame_count(fl);
        double f0 = bench_now();
        if (flame_effect.step(st, 0, fmin(f0 - last, 0.25), INFINITY, bench_emit, &out, &err)) bench_die("step", &err);
        last = f0;
        busy += bench_now() - f0;
        due = fmax(due + 1.0 / 30, bench_now()); /* engine_run_due: an overrun starts the next frame at once */
        double wait = due - bench_now();
        if (wait > 0) nanosleep(&(struct timespec){0, (long)(wait * 1e9)}, NULL);
    }
    double wall = bench_now() - t0, sim = flame_effect.sim_seconds(st) - sim0;
    double cpu = bench_cpu() - c0, ncpu = (double)sysconf(_SC_NPROCESSORS_ONLN);
    int steps = (int)(flame_steps(fl) - st0);
    double ps = nsum / frames * steps / busy, kernel_ms = bench_split(name, ka, nka, kb, bench_stats(ocl, kb), steps);
    struct flame_particles rb;
    if (flame_read(fl, &rb, &err)) bench_die("read", &err);
    int nflame = 0;
    double zf = 0, zmax = 0;
    for (int i = 0; i < rb.n; i++)
        if ((rb.flags[i] & FLAME_TYPE_MASK) == FLAME_GAS && (rb.flags[i] & FLAME_IS_FLAME)) {
            nflame++;
            zf += rb.pos[4 * i + 2];
            if (rb.pos[4 * i + 2] > zmax) zmax = rb.pos[4 * i + 2];
        }
    flame_particles_free(&rb);
    printf("flame %s warm-up %.1f s simulated (%llu steps) in %.1f s wall, N %d, gas flame particles %d "
           "(mean z %.4f m, top %.4f m)\n", name, warm_s, (unsigned long long)st0, warm_wall, flame_count(fl), nflame,
           nflame ? zf / nflame : 0.0, zmax);
    printf("flame %s N %.0f dt %.4f s: %.2f ms of work per frame of 1/30 s, real-time factor %.2f, %.2f M "
           "particle-steps/s, %.0f kB/frame\n",
           name, nsum / frames, dt, busy * 1e3 / frames, sim / wall, ps * 1e-6, out.bytes / 1024.0 / frames);
    printf("flame %s encoding %.3f ms per frame (%.1f ns per particle): %.2f%% of the %.2f ms step (target "
           "<= 5%%)\n", name, out.encode_ms / frames, out.encode_ms * 1e6 / nsum, 100 * out.encode_ms / (busy * 1e3),
           busy * 1e3 / frames);
    bench_enc_scaling(name, &out);
    printf("flame %s CPU %.2f s for %.3f s simulated: real-time factor %.2f with %.0f cores to itself\n", name, cpu, sim,
           sim / (cpu / ncpu), ncpu);
    printf("flame %s kernels %.2f ms of the %.2f ms of work per frame (the rest: launches, waits, read-back, "
           "encoding)\n", name, kernel_ms / frames, busy * 1e3 / frames);
    flame_effect.destroy(st);
    cJSON_Delete(doc);
}

int main(int argc, char **argv)
{
    struct fx_err err;
    struct ocl *ocl;
    if (ocl_open(&ocl, argc > 1 ? argv[1] : NULL, &err)) bench_die("ocl_open", &err);
    printf("flame device: %s\n", ocl_device_name(ocl));
    const char *only = getenv("BENCH_FLAME_ONLY"); /* one part: "sizes", "default", "large" or "59k" (one block) */
    if (only && !*only) only = NULL;
    bool gpu = !ocl_is_cpu(ocl);
    if (only && strcmp(only, "59k") == 0) bench_size(ocl, BENCH_TARGET_K, 20, ""); /* quick comparisons of two builds */
    if (!only || strcmp(only, "sizes") == 0) {
        bench_size(ocl, 22, 60, "");
        bench_size(ocl, BENCH_TARGET_K, gpu ? 60 : 20, "");
        bench_size(ocl, 58, gpu ? 60 : 8, "");
        if (gpu) { /* the GPU targets' sizes (~1.2 M and ~2.2 M); ~216k in the wide passes and the CPU's serial blocks */
            bench_size(ocl, 100, 40, "");
            bench_size(ocl, 126, 30, "");
            bench_size(ocl, 58, 20, "wide");
            bench_size(ocl, 58, 20, "blocks");
        }
    }
    const char *frames = getenv("BENCH_FLAME_FRAMES"); /* frames of the default scene (60) and of `large` (150) */
    if (!only || strcmp(only, "default") == 0) /* BENCH_FLAME_SCENE: JSON overrides of the scene, for experiments */
        bench_default(ocl, "default", getenv("BENCH_FLAME_SCENE"), 3.0, frames ? atoi(frames) : 60);
    if ((!only && gpu) || (only && strcmp(only, "large") == 0)) /* the GPU preset: real time with ~220k particles */
        bench_default(ocl, "large", flame_shape_preset("large"), 3.0, frames ? atoi(frames) : 150);
    ocl_close(ocl);
    return 0;
}
