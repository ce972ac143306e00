/* bench_eye.c — performance of effect compound_eye through PoCL (or any OpenCL device).
 *
 * One line per figure, the targets of the performance issue beside theirs: the default lens
 * table, then where its time goes (compound_eye_split: the kernel, its launch, read-back and
 * ordering, the packing stages, the share of its lanes that did work, and the pigment tile
 * made when parameters are set); the tracer's rays per second (random rays on the default
 * optics, l = 8); and bake frames per second on the built-in hemisphere, 512² at l = 10 first
 * (the target), then 512² and 1024² at l = 0, 3 and 10: the whole frame as the stream sends
 * it (kernel, read-back and the EXR encoding with the default compression), each with its
 * split. A stream traces its rays in the order of what they cost its run before (eye_order.h),
 * so each run makes a new stream and measures its first table or view (index order) and its
 * second (cost order, the figure) side by side. Times are the best of several runs, the
 * median beside it (the machine is shared); a split is the best run's. */
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

static int bench_cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* Median of n values (sorts them). */
static double bench_median(double *v, int n)
{
    qsort(v, (size_t)n, sizeof *v, bench_cmp);
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

#define BENCH_REPS 9

/* "lanes busy N%", or that the device keeps index order (eye_order.h: only CPUs sort). */
static const char *bench_lanes(double use, char *buf, size_t len)
{
    if (isnan(use)) snprintf(buf, len, "rays in index order on this device");
    else snprintf(buf, len, "lanes busy %.0f%%", 100 * use);
    return buf;
}

/* The default table, a new stream each run: its first table in index order, its second (the
 * table an artist's next change makes) in cost order. */
static void bench_table(struct ocl *ocl)
{
    struct fx_err err = {0};
    struct compound_eye_split sp, best_sp[2] = {{0}};
    const void *data;
    size_t len = 0;
    double ms[2][BENCH_REPS], best[2] = {INFINITY, INFINITY};
    for (int rep = 0; rep < BENCH_REPS; rep++) {
        struct compound_eye *ce = bench_new(ocl, "{}");
        for (int v = 0; v < 2; v++) {
            double t0 = bench_now();
            if (compound_eye_table(ce, &data, &len, &err)) {
                fprintf(stderr, "bench_eye: %s\n", err.message);
                exit(1);
            }
            ms[v][rep] = (bench_now() - t0) * 1e3;
            compound_eye_split(ce, &sp);
            if (ms[v][rep] < best[v]) best[v] = ms[v][rep], best_sp[v] = sp;
        }
        compound_eye_free(ce);
    }
    printf("eye lens table (default: 1088^2 atlas, C=32 D=32 SS=1, l=8): %.1f ms (target <= 30; median %.1f; the "
           "first table: %.1f, median %.1f), %.2f MB payload\n",
           best[1], bench_median(ms[1], BENCH_REPS), best[0], bench_median(ms[0], BENCH_REPS), len / 1e6);
    char l0[64], l1[64];
    printf("eye lens table split: kernel %.1f + launch, read-back and ordering %.1f + atlas %.1f + macro map %.1f + zstd "
           "%.1f ms; %s (the first table: kernel %.1f ms, %s); pigment tile %.1f ms at set\n",
           best_sp[1].kernel, best_sp[1].launch_read, best_sp[1].atlas, best_sp[1].macro, best_sp[1].zstd,
           bench_lanes(best_sp[1].lane_use, l1, sizeof l1), best_sp[0].kernel,
           bench_lanes(best_sp[0].lane_use, l0, sizeof l0), best_sp[1].pigment);
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

/* A bake frame as the stream sends it: the view (kernel, read-back) and its EXR with the default
 * compression, into ms and sp. */
static void bench_bake_frame(struct compound_eye *ce, float *rgba, struct fx_buf *exr, double *ms,
                             struct compound_eye_split *sp, double *exr_ms)
{
    struct fx_err err = {0};
    struct exr_image im = {compound_eye_bake_size(ce), compound_eye_bake_size(ce), 4, rgba, EXR_CODEC_RLE};
    double t0 = bench_now(), t1;
    exr->len = 0;
    if (compound_eye_bake(ce, rgba, &err) || ((t1 = bench_now()), exr_write_mem(&im, exr, &err))) {
        fprintf(stderr, "bench_eye: %s\n", err.message);
        exit(1);
    }
    double t2 = bench_now();
    *ms = (t2 - t0) * 1e3;
    *exr_ms = (t2 - t1) * 1e3;
    compound_eye_split(ce, sp);
}

/* Bake frames of size^2 at l passes, a new stream each run: its first view in atlas order, its
 * second in cost order. With target > 0 the line names it. */
static void bench_bake(struct ocl *ocl, int size, int l, double target)
{
    char partial[160];
    snprintf(partial, sizeof partial, "{\"mode\":\"bake\",\"bake_size\":%d,\"max_passes\":%d}", size, l);
    float *rgba = malloc((size_t)size * size * 4 * sizeof(float));
    struct fx_buf exr = {0};
    struct compound_eye_split sp[2], best_sp[2] = {{0}};
    double ms[2][BENCH_REPS], best[2] = {INFINITY, INFINITY}, exr_ms[2], best_exr = 0;
    for (int rep = 0; rep < BENCH_REPS; rep++) {
        struct compound_eye *ce = bench_new(ocl, partial);
        for (int v = 0; v < 2; v++) {
            bench_bake_frame(ce, rgba, &exr, &ms[v][rep], &sp[v], &exr_ms[v]);
            if (ms[v][rep] < best[v]) best[v] = ms[v][rep], best_sp[v] = sp[v], best_exr = v ? exr_ms[v] : best_exr;
        }
        compound_eye_free(ce);
    }
    char goal[32] = "";
    if (target > 0) snprintf(goal, sizeof goal, "target >= %.0f; ", target);
    printf("eye bake %d^2 l=%d: %.1f fps (%smedian %.1f fps; hemisphere, default view)\n", size, l, 1e3 / best[1], goal,
           1e3 / bench_median(ms[1], BENCH_REPS));
    char l0[64], l1[64];
    printf("eye bake %d^2 l=%d split: kernel %.1f + launch, read-back and ordering %.1f + EXR rle %.1f = %.1f ms; "
           "%s (the first view: kernel %.1f ms, %s, %.1f fps)\n", size, l, best_sp[1].kernel, best_sp[1].launch_read,
           best_exr, best[1], bench_lanes(best_sp[1].lane_use, l1, sizeof l1), best_sp[0].kernel,
           bench_lanes(best_sp[0].lane_use, l0, sizeof l0), 1e3 / best[0]);
    fx_buf_free(&exr);
    free(rgba);
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
    bench_bake(ocl, 512, 10, 120.0);
    const int sizes[2] = {512, 1024}, ls[3] = {0, 3, 10};
    for (int s = 0; s < 2; s++)
        for (int k = 0; k < 3; k++)
            if (sizes[s] != 512 || ls[k] != 10) bench_bake(ocl, sizes[s], ls[k], 0.0);
    ocl_close(ocl);
    return 0;
}
