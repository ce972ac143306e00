/* bench_energy.c — performance of effect energy_wave through PoCL (or any OpenCL device).
 *
 * First the figures with a target, one line each, the target beside it:
 *   - the two-Bézier scene of Fig. 5.6 (still) in mode adaptive at 512² (target >= 30 fps),
 *     with where a frame's time goes: the render kernel and the read-back (profiling events),
 *     host work (curve weights, uploads, launch: the rest of the frame's wall time) and the EXR
 *     encoding of the texture (half Y, the stream's default codec);
 *   - per scene, the default stream's torus (Fig. 5.2) and the Fig. 5.6 curves at 256²: mode
 *     adaptive against Simpson n = 200 (the thesis's "sufficient" n), timed alternately in
 *     the same run, each with its RMS error against the converged double-precision reference
 *     (tests/ref/energy_ref); target: adaptive >= 10x faster at RMS <= 0.5%.
 * Then the thesis's tables 5.2 (torus) and 5.3 (Bézier) — 128²/256²/512² × 64/128/256
 * divisions in mode simpson, and the same sizes in adaptive — and the animated Fig. 5.6 scene.
 * Times are whole frames as the engine sees them (uploads, kernel and read-back: the thesis's
 * "redraws per second"), the best of several, since the machine may be shared. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "effects/energy_wave.h"
#include "exr.h"
#include "ocl.h"
#include "params.h"
#include "../ref/energy_ref.h"
#include "../unit/wave_scenes.h"

#define BENCH_ACC_GRID 32    /* accuracy samples per axis */
#define BENCH_ACC_FLOOR 0.01 /* relative error denominator floor (B units) */
#define BENCH_FPS_GOAL 30.0  /* Fig. 5.6 scene at 512², mode adaptive */
#define BENCH_RATIO_GOAL 10.0
#define BENCH_RMS_GOAL 0.005

/* The thesis tables' torus (a tilted ring filling the default billboard). */
static const char *const bench_torus =
    "{\"curves\":[],\"tori\":[{\"center\":[0,0,0],\"axis\":[0,0.5,1],\"R\":5.4,\"coef\":5.1}],\"animate\":false}";

static double bench_clock(clockid_t id)
{
    struct timespec ts;
    clock_gettime(id, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}
static double bench_now(void) { return bench_clock(CLOCK_MONOTONIC); }

static void bench_die(const char *what, const char *msg)
{
    fprintf(stderr, "bench_energy: %s: %s\n", what, msg);
    exit(1);
}

/* defaults ⊕ scene ⊕ overrides (printf-formatted JSON object). */
static cJSON *bench_doc(const char *scene, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static cJSON *bench_doc(const char *scene, const char *fmt, ...)
{
    char text[512];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    struct fx_err err;
    cJSON *base = params_defaults(energy_wave_params), *a = NULL, *b = NULL;
    cJSON *p1 = cJSON_Parse(scene), *p2 = cJSON_Parse(text);
    if (params_merge(energy_wave_params, base, p1, &a, &err) || params_merge(energy_wave_params, a, p2, &b, &err))
        bench_die("bad document", err.message);
    cJSON_Delete(base);
    cJSON_Delete(a);
    cJSON_Delete(p1);
    cJSON_Delete(p2);
    return b;
}

/* The Fig. 5.6 scene (wave_scenes.h) with extra_json over it, as JSON text (free it). */
static char *bench_fig56(const char *extra_json)
{
    cJSON *p = wave_fig56_partial(extra_json);
    char *text = p ? cJSON_PrintUnformatted(p) : NULL;
    cJSON_Delete(p);
    if (!text) bench_die("scene", "no thesis-fig5.6 preset");
    return text;
}

/* A renderer of doc with its image buffer. */
struct bench_run {
    struct energy_wave *ew;
    float *img;
    int w, h;
};

static void bench_open(struct bench_run *r, struct ocl *ocl, const cJSON *doc)
{
    struct fx_err err;
    const struct energy_wave_config *c = wave_typed(doc);
    r->w = c->width;
    r->h = c->height;
    r->ew = energy_wave_new(ocl, c, &err);
    r->img = malloc((size_t)r->w * r->h * sizeof(float));
    if (!r->ew) bench_die("energy_wave_new", err.message);
    if (!r->img) bench_die("image", "out of memory");
    if (energy_wave_render(r->ew, 0.0, r->img, &err)) bench_die("warm-up", err.message); /* kernel compilation */
}

static void bench_close(struct bench_run *r)
{
    energy_wave_free(r->ew);
    free(r->img);
}

/* One frame at stream time t: its wall ms, its process CPU ms (this thread and PoCL's) in *cpu
 * when given, its device split in *split when given. */
static double bench_frame(struct bench_run *r, double t, double *cpu, struct energy_wave_split *split)
{
    struct fx_err err;
    double t0 = bench_now(), c0 = bench_clock(CLOCK_PROCESS_CPUTIME_ID);
    if (energy_wave_render(r->ew, t, r->img, &err)) bench_die("render", err.message);
    double ms = (bench_now() - t0) * 1e3;
    if (cpu) *cpu = (bench_clock(CLOCK_PROCESS_CPUTIME_ID) - c0) * 1e3;
    if (split) energy_wave_last_split(r->ew, split);
    return ms;
}

/* Best-of-`reps` ms per frame, averaging over `frames` stream times 0.33 s apart from
 * 0.5 s (spread over the animation's 3.1 s sweep, so the pulse is everywhere). */
static double bench_ms(struct bench_run *r, int reps, int frames)
{
    double best = INFINITY;
    for (int k = 0; k < reps; k++) {
        double sum = 0;
        for (int f = 0; f < frames; f++) sum += bench_frame(r, 0.5 + 0.33 * f, NULL, NULL);
        best = fmin(best, sum / frames);
    }
    return best;
}

static double bench_doc_ms(struct ocl *ocl, const cJSON *doc, int reps, int frames)
{
    struct bench_run r;
    bench_open(&r, ocl, doc);
    double ms = bench_ms(&r, reps, frames);
    bench_close(&r);
    return ms;
}

/* ---- the targets --------------------------------------------------------------------- */

/* Fig. 5.6 (still) at 512², adaptive: fps, and the split of its best frame. */
static void bench_fig56_512(struct ocl *ocl)
{
    char *still = bench_fig56("{\"animate\":false}");
    cJSON *doc = bench_doc(still, "{\"width\":512,\"height\":512,\"mode\":\"adaptive\"}");
    struct bench_run r;
    bench_open(&r, ocl, doc);
    struct energy_wave_split split, best_split = {0};
    double best = INFINITY, cpu, best_cpu = INFINITY;
    for (int k = 0; k < 8; k++) {
        double ms = bench_frame(&r, 0.0, &cpu, &split);
        best_cpu = fmin(best_cpu, cpu);
        if (ms < best) {
            best = ms;
            best_split = split;
        }
    }
    /* the texture's EXR as the stream sends it (output Y: one half channel) */
    struct fx_buf exr = {0};
    struct fx_err err;
    struct exr_image im = {r.w, r.h, 1, r.img, wave_typed(doc)->compression};
    double enc = INFINITY;
    for (int k = 0; k < 5; k++) {
        exr.len = 0;
        double t0 = bench_now();
        if (exr_write_mem(&im, &exr, &err)) bench_die("exr", err.message);
        enc = fmin(enc, (bench_now() - t0) * 1e3);
    }
    printf("energy 512x512 bezier fig5.6 adaptive: %.1f fps, %.1f ms/frame (target >= %.0f fps); CPU %.1f ms/frame\n",
           1e3 / best, best, BENCH_FPS_GOAL, best_cpu);
    printf("energy 512x512 bezier fig5.6 adaptive split: kernel %.1f ms, read-back %.2f ms, host and waits %.2f ms "
           "(weights, uploads, %d launch), EXR encoding %.1f ms (%zu kB, by the engine per subscribed frame)\n",
           best_split.kernel_ms, best_split.read_back_ms, best - best_split.kernel_ms - best_split.read_back_ms,
           best_split.pieces, enc, exr.len / 1024);
    fflush(stdout);
    fx_buf_free(&exr);
    bench_close(&r);
    cJSON_Delete(doc);
    free(still);
}

/* The converged reference on a BENCH_ACC_GRID² grid of texels of doc at stream time t. */
static void bench_reference(const cJSON *doc, double t, double *ref)
{
    struct energy_ref_scene *sc = malloc(sizeof *sc);
    char msg[160];
    if (!sc) bench_die("reference", "out of memory");
    if (energy_ref_scene_from_json(doc, t, sc, msg, sizeof msg)) bench_die("reference", msg);
    int w = sc->cam.width, h = sc->cam.height, n = 0;
    for (int gj = 0; gj < BENCH_ACC_GRID; gj++)
        for (int gi = 0; gi < BENCH_ACC_GRID; gi++)
            ref[n++] = energy_ref_texel_converged(sc, (gi * w + w / 2) / BENCH_ACC_GRID, (gj * h + h / 2) / BENCH_ACC_GRID);
    free(sc);
}

/* RMS of (B − B_ref)/max(|B_ref|, floor) over the reference grid of texels. */
static double bench_rms(const struct bench_run *r, const double *ref)
{
    int n = 0;
    double se = 0;
    for (int gj = 0; gj < BENCH_ACC_GRID; gj++)
        for (int gi = 0; gi < BENCH_ACC_GRID; gi++, n++) {
            int i = (gi * r->w + r->w / 2) / BENCH_ACC_GRID, j = (gj * r->h + r->h / 2) / BENCH_ACC_GRID;
            double e = (r->img[j * r->w + i] - ref[n]) / fmax(fabs(ref[n]), BENCH_ACC_FLOOR);
            se += e * e;
        }
    return sqrt(se / n);
}

/* Adaptive against Simpson n = 200 on scene at 256², frames alternating so that both see
 * the same load; accuracy of each at t = 0. */
static void bench_ratio(struct ocl *ocl, const char *what, const char *scene)
{
    static double ref[BENCH_ACC_GRID * BENCH_ACC_GRID];
    cJSON *da = bench_doc(scene, "{\"width\":256,\"height\":256,\"mode\":\"adaptive\"}");
    cJSON *ds = bench_doc(scene, "{\"width\":256,\"height\":256,\"mode\":\"simpson\",\"divisions\":200}");
    bench_reference(da, 0.0, ref);
    struct bench_run a, s;
    bench_open(&a, ocl, da);
    bench_open(&s, ocl, ds);
    double rms_a = bench_rms(&a, ref), rms_s = bench_rms(&s, ref);
    double ms_a = INFINITY, ms_s = INFINITY, cpu_a = INFINITY, cpu_s = INFINITY, cpu;
    for (int k = 0; k < 9; k++) { /* as many of each, alternating */
        ms_s = fmin(ms_s, bench_frame(&s, 0.0, &cpu, NULL));
        cpu_s = fmin(cpu_s, cpu);
        ms_a = fmin(ms_a, bench_frame(&a, 0.0, &cpu, NULL));
        cpu_a = fmin(cpu_a, cpu);
    }
    printf("energy 256x256 %s adaptive vs simpson n=200: %.1fx faster (target >= %.0fx; CPU time %.1fx), adaptive "
           "%.2f ms at RMS %.3f%% (target <= %.1f%%), simpson n=200 %.2f ms at RMS %.3f%%\n",
           what, ms_s / ms_a, BENCH_RATIO_GOAL, cpu_s / cpu_a, ms_a, 100 * rms_a, 100 * BENCH_RMS_GOAL, ms_s,
           100 * rms_s);
    fflush(stdout);
    bench_close(&a);
    bench_close(&s);
    cJSON_Delete(da);
    cJSON_Delete(ds);
}

/* ---- the thesis's tables and the animated scene ----------------------------------------- */

static void bench_line(const char *what, int size, const char *mode, int div, double ms)
{
    char d[32] = "";
    if (div) snprintf(d, sizeof d, " div=%d", div);
    printf("energy %s %dx%d%s mode=%s: %.1f ms/frame (%.1f fps)\n", what, size, size, d, mode, ms, 1e3 / ms);
    fflush(stdout);
}

/* Thesis tables 5.2 / 5.3 in simpson, then the same sizes in adaptive. */
static void bench_tables(struct ocl *ocl, const char *what, const char *scene)
{
    static const int sizes[] = {128, 256, 512}, divs[] = {64, 128, 256};
    for (int s = 0; s < 3; s++)
        for (int d = 0; d < 3; d++) {
            cJSON *doc = bench_doc(scene, "{\"width\":%d,\"height\":%d,\"divisions\":%d,\"mode\":\"simpson\"}",
                                   sizes[s], sizes[s], divs[d]);
            bench_line(what, sizes[s], "simpson", divs[d], bench_doc_ms(ocl, doc, s == 2 ? 1 : 3, 1));
            cJSON_Delete(doc);
        }
    for (int s = 0; s < 3; s++) {
        cJSON *doc = bench_doc(scene, "{\"width\":%d,\"height\":%d,\"mode\":\"adaptive\"}", sizes[s], sizes[s]);
        bench_line(what, sizes[s], "adaptive", 0, bench_doc_ms(ocl, doc, s == 2 ? 3 : 5, 1));
        cJSON_Delete(doc);
    }
}

/* The animated Fig. 5.6 scene (the eq. 5.1 pulse running) at 256² per mode. */
static void bench_animated(struct ocl *ocl)
{
    static const struct { const char *mode; int div; } runs[] = {{"simpson", 200}, {"adaptive", 200}};
    char *animated = bench_fig56(NULL);
    for (int k = 0; k < 2; k++) {
        cJSON *doc = bench_doc(animated, "{\"mode\":\"%s\",\"divisions\":%d}", runs[k].mode, runs[k].div);
        double ms = bench_doc_ms(ocl, doc, k ? 3 : 1, 8);
        printf("energy 256x256 bezier fig5.6 animated mode=%s%s: %.1f fps (%.1f ms/frame)\n", runs[k].mode,
               k ? "" : " n=200", 1e3 / ms, ms);
        fflush(stdout);
        cJSON_Delete(doc);
    }
    free(animated);
}

int main(void)
{
    struct ocl *ocl;
    struct fx_err err;
    if (ocl_open(&ocl, getenv("FX_OCL_DEVICE"), &err)) bench_die("ocl_open", err.message);
    printf("energy device: %s\n", ocl_device_name(ocl));
    bench_fig56_512(ocl);
    cJSON *defaults = params_defaults(energy_wave_params);
    char *torus = cJSON_PrintUnformatted(defaults), *still = bench_fig56("{\"animate\":false}");
    bench_ratio(ocl, "torus fig5.2 (default stream)", torus);
    bench_ratio(ocl, "bezier fig5.6", still);
    bench_animated(ocl);
    bench_tables(ocl, "torus", bench_torus);
    bench_tables(ocl, "bezier", still);
    cJSON_Delete(defaults);
    free(torus);
    free(still);
    ocl_close(ocl);
    return 0;
}
