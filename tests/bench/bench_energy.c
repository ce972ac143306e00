/* bench_energy.c — performance of effect energy_wave through PoCL (or any OpenCL device).
 *
 * Reproduces the thesis's tables 5.2 (torus) and 5.3 (Bezier) — 128²/256²/512² × 64/128/256
 * divisions in mode simpson — then the same scenes in mode adaptive, the thesis's animated
 * Fig. 5.6 scene (the joined curves with the eq. 5.1 pulse) at 256² per mode, and accuracy against the converged double-precision
 * reference (tests/ref/energy_ref) so speed-ups are compared at equal accuracy. Times are
 * whole frames as the engine sees them: uploads, kernel and read-back (the thesis's
 * "redraws per second"). One line per figure. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "effects/energy_wave.h"
#include "ocl.h"
#include "params.h"
#include "../ref/energy_ref.h"
#include "../unit/wave_scenes.h"

#define BENCH_ACC_GRID 24 /* accuracy samples per axis */
#define BENCH_ACC_FLOOR 0.01 /* relative error denominator floor (B units) */

static const char *const bench_torus =
    "{\"curves\":[],\"tori\":[{\"center\":[0,0,0],\"axis\":[0,0.5,1],\"R\":5.4,\"coef\":5.1}],\"animate\":false}";

static double bench_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
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
    if (params_merge(energy_wave_params, base, p1, &a, &err) || params_merge(energy_wave_params, a, p2, &b, &err)) {
        fprintf(stderr, "bench_energy: bad document: %s\n", err.message);
        exit(1);
    }
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
    if (!text) {
        fprintf(stderr, "bench_energy: no thesis-fig5.6 preset\n");
        exit(1);
    }
    return text;
}

/* Best-of-`reps` ms per frame, averaging over `frames` stream times 0.33 s apart from
 * 0.5 s (spread over the animation's 3.1 s sweep, so the pulse is everywhere). */
static double bench_ms(struct energy_wave *ew, float *img, int reps, int frames)
{
    struct fx_err err;
    double best = INFINITY;
    if (energy_wave_render(ew, 0.0, img, &err)) { /* warm-up: kernel compilation */
        fprintf(stderr, "bench_energy: %s\n", err.message);
        exit(1);
    }
    for (int r = 0; r < reps; r++) {
        double t0 = bench_now();
        for (int f = 0; f < frames; f++) energy_wave_render(ew, 0.5 + 0.33 * f, img, &err);
        double ms = (bench_now() - t0) * 1e3 / frames;
        if (ms < best) best = ms;
    }
    return best;
}

static double bench_run(struct ocl *ocl, const cJSON *doc, float **img, int reps, int frames)
{
    struct fx_err err;
    const struct energy_wave_config *c = wave_typed(doc);
    int w = c->width, h = c->height;
    struct energy_wave *ew = energy_wave_new(ocl, c, &err);
    if (!ew) {
        fprintf(stderr, "bench_energy: %s\n", err.message);
        exit(1);
    }
    *img = realloc(*img, (size_t)w * h * sizeof(float));
    double ms = bench_ms(ew, *img, reps, frames);
    energy_wave_free(ew);
    return ms;
}

static void bench_line(const char *what, int size, const char *mode, int div, double ms)
{
    char d[32] = "";
    if (div) snprintf(d, sizeof d, " div=%d", div);
    printf("energy %s %dx%d%s mode=%s: %.1f ms/frame (%.1f fps)\n", what, size, size, d, mode, ms, 1e3 / ms);
    fflush(stdout);
}

/* Thesis tables 5.2 / 5.3 in simpson, then the same sizes in adaptive. */
static void bench_tables(struct ocl *ocl, const char *what, const char *scene, float **img)
{
    static const int sizes[] = {128, 256, 512}, divs[] = {64, 128, 256};
    for (int s = 0; s < 3; s++)
        for (int d = 0; d < 3; d++) {
            cJSON *doc = bench_doc(scene, "{\"width\":%d,\"height\":%d,\"divisions\":%d,\"mode\":\"simpson\"}",
                                   sizes[s], sizes[s], divs[d]);
            bench_line(what, sizes[s], "simpson", divs[d], bench_run(ocl, doc, img, s == 2 ? 1 : 3, 1));
            cJSON_Delete(doc);
        }
    for (int s = 0; s < 3; s++) {
        cJSON *doc = bench_doc(scene, "{\"width\":%d,\"height\":%d,\"mode\":\"adaptive\"}", sizes[s], sizes[s]);
        bench_line(what, sizes[s], "adaptive", 0, bench_run(ocl, doc, img, s == 2 ? 2 : 5, 1));
        cJSON_Delete(doc);
    }
}

/* RMS of (B − B_ref)/max(|B_ref|, floor) over the reference grid of texels. */
static double bench_rms(const cJSON *doc, const float *img, const double *ref)
{
    const struct energy_wave_config *c = wave_typed(doc);
    int w = c->width, h = c->height, n = 0;
    double se = 0;
    for (int gj = 0; gj < BENCH_ACC_GRID; gj++)
        for (int gi = 0; gi < BENCH_ACC_GRID; gi++, n++) {
            int i = (gi * w + w / 2) / BENCH_ACC_GRID, j = (gj * h + h / 2) / BENCH_ACC_GRID;
            double r = ref[n], e = (img[j * w + i] - r) / fmax(fabs(r), BENCH_ACC_FLOOR);
            se += e * e;
        }
    return sqrt(se / n);
}

static void bench_reference(const cJSON *doc, double t, double *ref)
{
    struct energy_ref_scene sc;
    char msg[160];
    if (energy_ref_scene_from_json(doc, t, &sc, msg, sizeof msg)) {
        fprintf(stderr, "bench_energy: reference: %s\n", msg);
        exit(1);
    }
    int w = sc.cam.width, h = sc.cam.height, n = 0;
    for (int gj = 0; gj < BENCH_ACC_GRID; gj++)
        for (int gi = 0; gi < BENCH_ACC_GRID; gi++)
            ref[n++] = energy_ref_texel_converged(&sc, (gi * w + w / 2) / BENCH_ACC_GRID, (gj * h + h / 2) / BENCH_ACC_GRID);
}

/* The animated scene at 256² per mode, with accuracy at t = 1 s. */
static void bench_animated(struct ocl *ocl, const char *scene, float **img)
{
    static const struct { const char *mode; int div; } runs[] = {
        {"simpson", 200}, {"simpson", 400}, {"adaptive", 0},
    };
    const double t = 1.0;
    static double ref[BENCH_ACC_GRID * BENCH_ACC_GRID];
    struct fx_err err;
    cJSON *base = bench_doc(scene, "{}");
    bench_reference(base, t, ref);
    double ms[3];
    for (int r = 0; r < 3; r++) {
        cJSON *doc = bench_doc(scene, "{\"mode\":\"%s\",\"divisions\":%d}", runs[r].mode, runs[r].div ? runs[r].div : 200);
        int adaptive = runs[r].div == 0;
        ms[r] = bench_run(ocl, doc, img, adaptive ? 3 : 1, 8);
        struct energy_wave *ew = energy_wave_new(ocl, wave_typed(doc), &err);
        if (!ew || energy_wave_render(ew, t, *img, &err)) {
            fprintf(stderr, "bench_energy: %s\n", err.message);
            exit(1);
        }
        energy_wave_free(ew);
        char label[64];
        snprintf(label, sizeof label, "%s%s", runs[r].mode, adaptive ? "" : (runs[r].div == 200 ? " n=200" : " n=400"));
        printf("energy 256x256 bezier fig5.6 scene fps mode=%s: %.1f fps (%.1f ms/frame), rms rel err %.3f%%\n", label,
               1e3 / ms[r], ms[r], 100 * bench_rms(doc, *img, ref));
        fflush(stdout);
        cJSON_Delete(doc);
    }
    printf("energy 256x256 bezier fig5.6 scene speed-up adaptive vs simpson n=200: %.1fx, vs n=400: %.1fx\n",
           ms[0] / ms[2], ms[1] / ms[2]);
    cJSON_Delete(base);
}

int main(void)
{
    struct ocl *ocl;
    struct fx_err err;
    float *img = NULL;
    if (ocl_open(&ocl, getenv("FX_OCL_DEVICE"), &err)) {
        fprintf(stderr, "bench_energy: %s\n", err.message);
        return 1;
    }
    printf("energy device: %s\n", ocl_device_name(ocl));
    char *animated = bench_fig56(NULL), *still = bench_fig56("{\"animate\":false}");
    bench_animated(ocl, animated, &img);
    bench_tables(ocl, "torus", bench_torus, &img);
    bench_tables(ocl, "bezier", still, &img);
    free(animated);
    free(still);
    free(img);
    ocl_close(ocl);
    return 0;
}
