/* bench_eye.c — performance of effect compound_eye through PoCL (or any OpenCL device).
 *
 * One line per figure: the default lens table (kernel, then packing into the kind 4
 * container), the tracer's rays per second (random rays on the default optics, l = 8),
 * and bake frames per second on the built-in hemisphere at 512² and 1024² for
 * l = 0, 3 and 10 (kernel and read-back, as the engine sees them, without the EXR
 * encoding, reported separately). Times are best of several runs. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

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
    struct compound_eye *ce = compound_eye_new(ocl, doc, &err);
    cJSON_Delete(doc);
    if (!ce) {
        fprintf(stderr, "bench_eye: %s\n", err.message);
        exit(1);
    }
    return ce;
}

static void bench_table(struct ocl *ocl)
{
    struct compound_eye *ce = bench_new(ocl, "{}");
    struct fx_err err = {0};
    const void *data;
    size_t len = 0;
    double best = INFINITY;
    for (int rep = 0; rep < 5; rep++) {
        double t0 = bench_now();
        if (compound_eye_table(ce, &data, &len, &err)) {
            fprintf(stderr, "bench_eye: %s\n", err.message);
            exit(1);
        }
        best = fmin(best, bench_now() - t0);
    }
    printf("lut default table (1088^2 atlas, C=32 D=32 SS=1, 1.05 M rays, l=8): %.0f ms incl. packing, %.2f MB payload\n",
           best * 1e3, len / 1e6);
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
    struct eye_optics o;
    eye_optics_from_params(doc, &o);
    cJSON_Delete(doc);
    struct eye_rays_out out = {.land = land};
    struct fx_err err = {0};
    double best = INFINITY;
    for (int rep = 0; rep < 3; rep++) {
        double t0 = bench_now();
        if (eye_trace_rays(ocl, &o, n, p, d, &out, &err)) {
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
    double best = INFINITY;
    for (int rep = 0; rep < 5; rep++) {
        double t0 = bench_now();
        if (compound_eye_bake(ce, rgba, &err)) {
            fprintf(stderr, "bench_eye: %s\n", err.message);
            exit(1);
        }
        best = fmin(best, bench_now() - t0);
    }
    printf("bake %4d^2 l=%-2d: %6.1f fps (%.1f ms/frame, hemisphere, default view)\n", size, l, 1.0 / best, best * 1e3);
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
