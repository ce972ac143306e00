/* bench_eye.c — performance of effect compound_eye through PoCL (or any OpenCL device).
 *
 * One line per figure: the default lens table (whole, and its kernel alone; the rest is
 * the read-back and packing into the kind 4 container), the tracer's rays per second
 * (random rays on the default optics, l = 8), and bake frames per second on the
 * built-in hemisphere at 512² and 1024² for l = 0, 3 and 10: the whole frame as the
 * stream sends it (kernel, read-back and the EXR encoding with the default compression),
 * with the render and the encoding also shown apart. Times are best of several runs. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "../ref/kernel_probe.h"
#include "exr.h"
#include "effects/compound_eye.h"
#include "ocl.h"
#include "params.h"

static double bench_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

static cJSON *bench_doc(const char *partial)
{
    struct fx_err err = {0};
    cJSON *base = params_defaults(compound_eye_params), *p = cJSON_Parse(partial), *doc = NULL;
    if (params_merge(compound_eye_params, base, p, &doc, &err)) {
        fprintf(stderr, "bench_eye: bad document %s: %s\n", partial, err.message);
        exit(1);
    }
    cJSON_Delete(base);
    cJSON_Delete(p);
    return doc;
}

static struct compound_eye *bench_new(struct ocl *ocl, const char *partial)
{
    struct fx_err err = {0};
    cJSON *doc = bench_doc(partial);
    struct compound_eye_config c;
    struct compound_eye *ce = params_load(compound_eye_params, doc, &c, sizeof c, &err) ? NULL
                                                                                      : compound_eye_new(ocl, &c, &err);
    cJSON_Delete(doc);
    if (!ce) {
        fprintf(stderr, "bench_eye: %s\n", err.message);
        exit(1);
    }
    return ce;
}

/* Total milliseconds the device has spent in kernel `name` so far. */
static double bench_kernel_ms(struct ocl *ocl, const char *name)
{
    struct ocl_kernel_stat st[64];
    int n = ocl_stats(ocl, st, 64);
    for (int i = 0; i < n; i++)
        if (!strcmp(st[i].name, name)) return st[i].total_ms;
    return 0.0;
}

static void bench_table(struct ocl *ocl)
{
    struct compound_eye *ce = bench_new(ocl, "{}");
    struct fx_err err = {0};
    const void *data;
    size_t len = 0;
    double best = INFINITY, best_kernel = INFINITY;
    for (int rep = 0; rep < 5; rep++) {
        double t0 = bench_now(), k0 = bench_kernel_ms(ocl, "eye_lut");
        if (compound_eye_table(ce, &data, &len, &err)) {
            fprintf(stderr, "bench_eye: %s\n", err.message);
            exit(1);
        }
        best = fmin(best, bench_now() - t0);
        best_kernel = fmin(best_kernel, bench_kernel_ms(ocl, "eye_lut") - k0);
    }
    printf("lut default table (1088^2 atlas, C=32 D=32 SS=1, 1.05 M rays, l=8): %.0f ms incl. packing (kernel %.0f ms), "
           "%.2f MB payload\n",
           best * 1e3, best_kernel, len / 1e6);
    compound_eye_free(ce);
}

static void bench_rays(struct ocl *ocl)
{
    const int n = 1 << 20;
    float *p = malloc(sizeof(float) * 2 * n), *d = malloc(sizeof(float) * 3 * n), *land = malloc(sizeof(float) * 2 * n);
    unsigned long long s = 88172645463325252ull;
    for (int i = 0; i < n; i++) {
        double u[4];
        for (int k = 0; k < 4; k++) {
            s ^= s << 13, s ^= s >> 7, s ^= s << 17;
            u[k] = (s >> 11) * (1.0 / 9007199254740992.0);
        }
        double z = 0.2 + 0.8 * u[2], ph = 2 * M_PI * u[3], r = sqrt(1 - z * z); /* theta <= 78 deg */
        p[2 * i] = (float)u[0];
        p[2 * i + 1] = (float)u[1];
        d[3 * i] = (float)(r * cos(ph));
        d[3 * i + 1] = (float)(r * sin(ph));
        d[3 * i + 2] = (float)-z;
    }
    cJSON *doc = bench_doc("{}");
    struct compound_eye_config c;
    struct fx_err perr = {0};
    if (params_load(compound_eye_params, doc, &c, sizeof c, &perr)) {
        fprintf(stderr, "bench_eye: %s\n", perr.message);
        exit(1);
    }
    struct eye_optics o;
    eye_optics_from_params(&c, &o);
    cJSON_Delete(doc);
    struct eye_rays_out out = {.land = land};
    struct fx_err err = {0};
    double best = INFINITY;
    for (int rep = 0; rep < 3; rep++) {
        double t0 = bench_now();
        if (probe_eye_trace(ocl, &o, n, p, d, &out, &err)) {
            fprintf(stderr, "bench_eye: %s\n", err.message);
            exit(1);
        }
        best = fmin(best, bench_now() - t0);
    }
    printf("tracer: %.2f M rays/s (default optics, l=8, random rays theta <= 78 deg, incl. transfers)\n", n / best / 1e6);
    free(p);
    free(d);
    free(land);
}

static void bench_bake(struct ocl *ocl, int size, int l)
{
    char partial[160];
    snprintf(partial, sizeof partial, "{\"mode\":\"bake\",\"bake_size\":%d,\"max_passes\":%d}", size, l);
    struct compound_eye *ce = bench_new(ocl, partial);
    float *rgba = malloc((size_t)size * size * 4 * sizeof(float));
    struct fx_err err = {0};
    struct exr_image im = {size, size, 4, rgba, EXR_CODEC_RLE}; /* the `compression` default */
    struct fx_buf exr = {0};
    double best = INFINITY, best_render = INFINITY, best_encode = INFINITY;
    for (int rep = 0; rep < 5; rep++) {
        double t0 = bench_now(), t1;
        exr.len = 0;
        if (compound_eye_bake(ce, rgba, &err) || ((t1 = bench_now()), exr_write_mem(&im, &exr, &err))) {
            fprintf(stderr, "bench_eye: %s\n", err.message);
            exit(1);
        }
        double t2 = bench_now();
        best = fmin(best, t2 - t0);
        best_render = fmin(best_render, t1 - t0);
        best_encode = fmin(best_encode, t2 - t1);
    }
    printf("bake %4d^2 l=%-2d: %6.1f fps (%.1f ms/frame: render %.1f + EXR rle %.1f; hemisphere, default view)\n", size,
           l, 1.0 / best, best * 1e3, best_render * 1e3, best_encode * 1e3);
    fx_buf_free(&exr);
    free(rgba);
    compound_eye_free(ce);
}

int main(void)
{
    struct ocl *ocl;
    struct fx_err err = {0};
    if (ocl_open(&ocl, "auto", &err)) {
        fprintf(stderr, "bench_eye: %s\n", err.message);
        return 1;
    }
    printf("device: %s\n", ocl_device_name(ocl));
    bench_table(ocl);
    bench_rays(ocl);
    const int sizes[2] = {512, 1024}, ls[3] = {0, 3, 10};
    for (int s = 0; s < 2; s++)
        for (int k = 0; k < 3; k++) bench_bake(ocl, sizes[s], ls[k]);
    ocl_close(ocl);
    return 0;
}
