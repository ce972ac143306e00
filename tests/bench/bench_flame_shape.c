/* bench_flame_shape.c — the flame's shape figures on the default scene, its
 * difference-form variant and a sideways wind (a 2 m/s wind_velocity, digest §2.14's drag
 * model, and for comparison a uniform wind_accel of 10 m/s^2), as a client measures them on the stream:
 * 5 s of warm-up, then one state every 1/30 s of simulated time for 10 s (tests/ref/
 * flame_shape.c: H90, W90, share below the source plane, flicker, centroid). Simulated time,
 * not wall time: the figures do not depend on the machine (real time is bench_flame's).
 * BENCH_FLAME_SCENE adds JSON overrides to every case, for experiments; BENCH_SHAPE_ONLY
 * names one case (default, difference, wind, candle, fire-pit, large: the GPU preset, run
 * unnamed only on a GPU device). One line per figure. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../ref/flame_shape.h"
#include "ocl.h"

static void bs_die(const char *what, const struct fx_err *err)
{
    fprintf(stderr, "bench_flame_shape: %s: %s\n", what, err->message);
    exit(1);
}

/* The default document with two layers of JSON overrides (either may be NULL). */
static cJSON *bs_doc(const char *a, const char *b)
{
    struct fx_err err;
    cJSON *doc = params_defaults(flame_params);
    const char *layers[2] = {a, b};
    for (int i = 0; i < 2; i++) {
        if (!layers[i]) continue;
        cJSON *o = cJSON_Parse(layers[i]), *out = NULL;
        if (!o || params_merge(flame_params, doc, o, &out, &err)) bs_die("bad overrides", &err);
        cJSON_Delete(o);
        cJSON_Delete(doc);
        doc = out;
    }
    return doc;
}

/* Runs one case and prints its figures. */
static void bs_case(struct ocl *ocl, const char *name, const char *ov, double warm_s, double seconds,
                    struct flame_shape *out)
{
    struct fx_err err;
    cJSON *doc = bs_doc(getenv("BENCH_FLAME_SCENE"), ov);
    if (flame_shape_run(ocl, doc, warm_s, seconds, out, &err)) bs_die(name, &err);
    printf("flame shape %s: H90 %.1f cm, W90 %.1f cm, H90/W90 %.2f, below the source %.1f%%, flicker %.1f%%, "
           "centroid %.1f cm up %+.1f cm x, particles %.0f (burning %.0f)\n",
           name, out->H90 * 100, out->W90 * 100, out->W90 > 0 ? out->H90 / out->W90 : 0, out->below * 100,
           out->flicker * 100, out->centroid_h * 100, out->centroid_lat[0] * 100, out->particles, out->burning);
    cJSON_Delete(doc);
}

int main(int argc, char **argv)
{
    struct fx_err err;
    struct ocl *ocl;
    if (ocl_open(&ocl, argc > 1 ? argv[1] : NULL, &err)) bs_die("ocl_open", &err);
    const char *only = getenv("BENCH_SHAPE_ONLY");
    struct flame_shape calm = {0}, windy, diff;
    if (!only || !strcmp(only, "default") || !strcmp(only, "wind")) bs_case(ocl, "default", NULL, 5, 10, &calm);
    if (!only || !strcmp(only, "wind")) {
        /* the lean target is the wind velocity's; a uniform acceleration is shown beside it */
        static const struct { const char *name, *ov, *goal; } winds[] = {
            {"wind_velocity 2 m/s along x", "{\"wind_velocity\":[2,0,0]}", " (target >= 0.30)"},
            {"wind_accel 10 m/s^2 along x", "{\"wind_accel\":[10,0,0]}", ""},
        };
        for (size_t i = 0; i < sizeof winds / sizeof winds[0]; i++) {
            bs_case(ocl, winds[i].name, winds[i].ov, 5, 10, &windy);
            printf("flame shape %s: centroid moved %.1f cm sideways = %.2f x H90%s\n", winds[i].name,
                   (windy.centroid_lat[0] - calm.centroid_lat[0]) * 100,
                   calm.H90 > 0 ? (windy.centroid_lat[0] - calm.centroid_lat[0]) / calm.H90 : 0, winds[i].goal);
        }
    }
    static const char *const presets[] = {"candle", "fire-pit", "large"};
    for (size_t i = 0; i < sizeof presets / sizeof presets[0]; i++) /* large: on a GPU, or when named */
        if (only ? !strcmp(only, presets[i]) : strcmp(presets[i], "large") || !ocl_is_cpu(ocl)) {
            struct flame_shape s;
            char name[64];
            snprintf(name, sizeof name, "preset %s", presets[i]);
            bs_case(ocl, name, flame_shape_preset(presets[i]), 3, 5, &s);
        }
    if (!only || !strcmp(only, "difference"))
        bs_case(ocl, "difference form at 2.5-3 s", "{\"pressure_form\":\"difference\"}", 2.5, 0.5, &diff);
    ocl_close(ocl);
    return 0;
}
