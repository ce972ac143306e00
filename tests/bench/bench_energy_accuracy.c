/* bench_energy_accuracy.c — accuracy against time for every energy_wave integration mode.
 *
 * For a torus scene (thesis Fig 5.1: R = 0.9, t = 5.1) and the default two-Bezier scene
 * (Figs 5.3-5.6: b = 8, W of Fig 5.6) at 256x256, each mode listed in the `mode`
 * parameter's choices is timed (ms/frame through energy_wave_render, readback included)
 * and compared with the converged double-precision reference (tests/ref/) on every 4th
 * texel in each direction. Simpson is swept over the division count; other modes run at
 * the document's defaults. The headline per scene is the fastest setting reaching
 * RMS relative error <= 0.5% versus Simpson n = 200 (the thesis's "sufficient" n), and
 * their ratio (target >= 10x). One line per figure; the reference is computed once. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../ref/energy_ref.h"
#include "../unit/wave_scenes.h"
#include "effects/energy_wave.h"
#include "ocl.h"
#include "params.h"

#define BEA_SIZE 256
#define BEA_STRIDE 4
#define BEA_NS (BEA_SIZE / BEA_STRIDE)
#define BEA_GOAL 0.005

static struct ocl *bea_ocl;
static cJSON *bea_defaults;

struct bea_best {
    char label[64];
    double ms, simpson200_ms;
};

static double bea_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

static cJSON *bea_doc(const char *scene_json, const char *mode, int divisions)
{
    cJSON *partial = cJSON_Parse(scene_json), *out = NULL;
    struct fx_err err = {0};
    cJSON_AddStringToObject(partial, "mode", mode);
    if (divisions > 0) cJSON_AddNumberToObject(partial, "divisions", divisions);
    if (params_merge(energy_wave_params, bea_defaults, partial, &out, &err))
        fprintf(stderr, "bench_energy_accuracy: params_merge: %s: %s\n", err.param, err.message);
    cJSON_Delete(partial);
    return out;
}

/* Converged reference on the sampled texels; returns its maximum. */
static double bea_reference(const cJSON *doc, double *ref)
{
    struct energy_ref_scene *sc = malloc(sizeof *sc);
    char msg[160];
    if (!sc || energy_ref_scene_from_json(doc, 0, sc, msg, sizeof msg)) {
        fprintf(stderr, "bench_energy_accuracy: reference scene: %s\n", sc ? msg : "out of memory");
        free(sc);
        return -1;
    }
    double mx = 0;
    for (int j = 0; j < BEA_NS; j++)
        for (int i = 0; i < BEA_NS; i++) {
            double b = energy_ref_texel_converged(sc, i * BEA_STRIDE + BEA_STRIDE / 2, j * BEA_STRIDE + BEA_STRIDE / 2);
            ref[j * BEA_NS + i] = b;
            mx = fmax(mx, fabs(b));
        }
    free(sc);
    return mx;
}

static double bea_rms(const float *img, const double *ref, double mx)
{
    double sum = 0;
    int n = 0;
    for (int j = 0; j < BEA_NS; j++)
        for (int i = 0; i < BEA_NS; i++) {
            double r = ref[j * BEA_NS + i];
            if (fabs(r) <= 0.01 * mx) continue;
            double d = img[(j * BEA_STRIDE + BEA_STRIDE / 2) * BEA_SIZE + i * BEA_STRIDE + BEA_STRIDE / 2];
            sum += (d - r) * (d - r) / (r * r);
            n++;
        }
    return n ? sqrt(sum / n) : NAN;
}

/* Median ms/frame of up to 7 timed renders (at least 3, or until ~0.6 s) after a warm-up. */
static double bea_time(struct energy_wave *ew, float *img)
{
    double t[7], spent = 0;
    int n = 0;
    struct fx_err err = {0};
    if (energy_wave_render(ew, 0, img, &err)) {
        fprintf(stderr, "bench_energy_accuracy: render: %s\n", err.message);
        return -1;
    }
    while (n < 7 && (n < 3 || spent < 600)) {
        double t0 = bea_now_ms();
        energy_wave_render(ew, 0, img, &err);
        t[n] = bea_now_ms() - t0;
        spent += t[n++];
        if (t[n - 1] > 1500) break; /* slow settings: one timed frame is enough */
    }
    for (int a = 1; a < n; a++)
        for (int b = a; b > 0 && t[b] < t[b - 1]; b--) {
            double x = t[b];
            t[b] = t[b - 1];
            t[b - 1] = x;
        }
    return t[n / 2];
}

static void bea_one(const char *scene, const char *json, const char *mode, int divisions, const double *ref,
                    double mx, float *img, struct bea_best *best)
{
    cJSON *doc = bea_doc(json, mode, divisions);
    struct fx_err err = {0};
    struct energy_wave *ew = doc ? energy_wave_new(bea_ocl, wave_typed(doc), &err) : NULL;
    if (!ew) {
        fprintf(stderr, "bench_energy_accuracy: %s %s: %s\n", scene, mode, err.message);
        cJSON_Delete(doc);
        return;
    }
    int n = wave_typed(doc)->divisions;
    double ms = bea_time(ew, img), rms = bea_rms(img, ref, mx);
    char label[64];
    if (strcmp(mode, "simpson") == 0) snprintf(label, sizeof label, "simpson n=%d", n);
    else snprintf(label, sizeof label, "%s (defaults)", mode);
    printf("energy_accuracy %s %s: %.2f ms/frame, RMS relative error %.4f%%\n", scene, label, ms, 100 * rms);
    fflush(stdout);
    if (rms <= BEA_GOAL && ms >= 0 && (best->ms < 0 || ms < best->ms)) {
        snprintf(best->label, sizeof best->label, "%s", label);
        best->ms = ms;
    }
    if (strcmp(mode, "simpson") == 0 && n == 200) best->simpson200_ms = ms;
    energy_wave_free(ew);
    cJSON_Delete(doc);
}

static void bea_scene(const char *scene, const char *json, const struct param_def *mode_def)
{
    static const int divs[] = {16, 32, 64, 100, 128, 200, 256};
    static double ref[BEA_NS * BEA_NS];
    float *img = malloc(sizeof(float) * BEA_SIZE * BEA_SIZE);
    cJSON *doc = bea_doc(json, "simpson", 200);
    double t0 = bea_now_ms(), mx = doc ? bea_reference(doc, ref) : -1;
    cJSON_Delete(doc);
    if (!img || mx <= 0) {
        free(img);
        return;
    }
    printf("energy_accuracy %s reference: %d texels converged in %.0f ms\n", scene, BEA_NS * BEA_NS, bea_now_ms() - t0);
    struct bea_best best = {"", -1, -1};
    for (const char *const *m = mode_def->choices; *m; m++) {
        if (strcmp(*m, "simpson") == 0)
            for (size_t k = 0; k < sizeof divs / sizeof divs[0]; k++) bea_one(scene, json, *m, divs[k], ref, mx, img, &best);
        else
            bea_one(scene, json, *m, 0, ref, mx, img, &best);
    }
    if (best.ms < 0)
        printf("energy_accuracy %s headline: no mode reached RMS <= 0.5%%\n", scene);
    else
        printf("energy_accuracy %s headline: fastest with RMS <= 0.5%% is %s at %.2f ms/frame; simpson n=200 %.2f ms/frame; "
               "speedup %.1fx (target >= 10x)\n",
               scene, best.label, best.ms, best.simpson200_ms, best.simpson200_ms / best.ms);
    free(img);
}

static const char bea_torus[] =
    "{\"points\":[],\"lines\":[],\"curves\":[],\"animate\":false,\"width\":256,\"height\":256,\"size\":1.8,"
    "\"tori\":[{\"center\":[0,0,0],\"axis\":[0,0.6,0.8],\"R\":0.9,\"coef\":5.1}]}";

int main(void)
{
    struct fx_err err = {0};
    if (ocl_open(&bea_ocl, "cpu", &err)) {
        fprintf(stderr, "bench_energy_accuracy: ocl_open: %s\n", err.message);
        return 1;
    }
    bea_defaults = params_defaults(energy_wave_params);
    const struct param_def *mode_def = NULL;
    for (const struct param_def *d = energy_wave_params; d->name; d++)
        if (strcmp(d->name, "mode") == 0) mode_def = d;
    if (!bea_defaults || !mode_def) {
        fprintf(stderr, "bench_energy_accuracy: no defaults or no mode parameter\n");
        return 1;
    }
    printf("energy_accuracy device: %s\n", ocl_device_name(bea_ocl));
    bea_scene("torus", bea_torus, mode_def);
    /* the two joined Beziers of Fig. 5.6 (b = 8, its W) without animation */
    cJSON *fig56 = wave_fig56_partial("{\"animate\":false,\"width\":256,\"height\":256}");
    char *bezier = fig56 ? cJSON_PrintUnformatted(fig56) : NULL;
    cJSON_Delete(fig56);
    if (!bezier) {
        fprintf(stderr, "bench_energy_accuracy: no thesis-fig5.6 preset\n");
        return 1;
    }
    bea_scene("bezier", bezier, mode_def);
    free(bezier);
    cJSON_Delete(bea_defaults);
    ocl_close(bea_ocl);
    return 0;
}
