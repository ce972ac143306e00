/* bench_exr.c — size and encode time of every EXR compression on an energy-wave frame.
 *
 * The image imitates what energy_wave produces: a dark background with smooth HDR
 * glows (1/distance falloff around a few lines and a curve, peaks near 5), as a
 * luminance ("Y") and a tinted RGBA frame of 512x512. For each codec it prints the
 * encoded size and the median encode time over RUNS calls of exr_write_mem, reusing
 * one output buffer as the engine does, then names the default the numbers support:
 * the smallest codec that encodes a 512x512 Y frame within BUDGET_MS, and the best
 * lossless one (b44/b44a are lossy). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "exr.h"

#define SIZE 512
#define RUNS 25
#define BUDGET_MS 5.0
#define NCODECS (EXR_CODEC_B44A + 1)

struct bench_result {
    size_t bytes;
    double ms;
};

static double bench_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

/* Distance from (x,y) to the segment (ax,ay)-(bx,by). */
static double bench_segment_dist(double x, double y, double ax, double ay, double bx, double by)
{
    double dx = bx - ax, dy = by - ay;
    double t = ((x - ax) * dx + (y - ay) * dy) / (dx * dx + dy * dy);
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    return hypot(x - ax - t * dx, y - ay - t * dy);
}

/* Glow of the three sources at texel (x,y) in [0,1]^2 coordinates, one value per source. */
static void bench_glow(double x, double y, double g[3])
{
    double wave = 0.5 + 0.18 * sin(9.0 * x + 0.7) * exp(-2.0 * (x - 0.5) * (x - 0.5));
    g[0] = 0.020 / (bench_segment_dist(x, y, 0.1, 0.2, 0.9, 0.35) + 0.012);
    g[1] = 0.015 / (bench_segment_dist(x, y, 0.3, 0.9, 0.7, 0.55) + 0.010);
    g[2] = 0.030 / (fabs(y - wave) + 0.015) * (0.6 + 0.4 * sin(3.0 * x));
}

/* Fills a SIZE x SIZE frame of `channels` (1 or 4) interleaved floats. */
static float *bench_image(int channels)
{
    static const double tint[3][3] = {{1.0, 0.45, 0.15}, {0.3, 0.6, 1.0}, {0.9, 0.9, 0.6}};
    float *px = malloc(sizeof(float) * SIZE * SIZE * (size_t)channels);
    if (!px) return NULL;
    for (int j = 0; j < SIZE; j++)
        for (int i = 0; i < SIZE; i++) {
            double g[3], rgb[3] = {0, 0, 0};
            bench_glow((i + 0.5) / SIZE, (j + 0.5) / SIZE, g);
            for (int s = 0; s < 3; s++)
                for (int c = 0; c < 3; c++) rgb[c] += g[s] * tint[s][c];
            float *p = px + ((size_t)j * SIZE + i) * (size_t)channels;
            double lum = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2];
            if (channels == 1) {
                p[0] = (float)lum;
                continue;
            }
            for (int c = 0; c < 3; c++) p[c] = (float)rgb[c];
            p[3] = (float)(lum > 1 ? 1 : lum);
        }
    return px;
}

static int bench_cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* Median encode time and size of one codec; -1 on an encode error. */
static int bench_codec(const float *px, int channels, int codec, struct fx_buf *out, struct bench_result *r)
{
    struct exr_image img = {SIZE, SIZE, channels, px, codec};
    struct fx_err err;
    double t[RUNS];
    for (int run = -2; run < RUNS; run++) { /* two warm-up calls */
        out->len = 0;
        double t0 = bench_now_ms();
        if (exr_write_mem(&img, out, &err)) {
            fprintf(stderr, "bench_exr: %s\n", err.message);
            return -1;
        }
        if (run >= 0) t[run] = bench_now_ms() - t0;
    }
    qsort(t, RUNS, sizeof t[0], bench_cmp_double);
    r->bytes = out->len;
    r->ms = t[RUNS / 2];
    return 0;
}

static int bench_variant(int channels, struct bench_result res[NCODECS])
{
    float *px = bench_image(channels);
    struct fx_buf out = {0};
    int rc = px ? 0 : -1;
    for (int c = 0; rc == 0 && c < NCODECS; c++) {
        rc = bench_codec(px, channels, c, &out, &res[c]);
        if (rc == 0)
            printf("exr %dx%d %s codec=%s: %zu bytes (%.2f bits/texel), encode %.2f ms\n", SIZE, SIZE,
                   channels == 1 ? "Y" : "RGBA", exr_codec_names[c], res[c].bytes,
                   8.0 * res[c].bytes / (SIZE * SIZE), res[c].ms);
    }
    fx_buf_free(&out);
    free(px);
    return rc;
}

/* Is codec a better default than codec b? Smaller Y file; within 1% in size, faster
 * (times within 10% are noise: then the smaller RGBA file wins). */
static int bench_better(const struct bench_result *y, const struct bench_result *rgba, int a, int b)
{
    if (y[a].bytes < 0.99 * y[b].bytes || y[b].bytes < 0.99 * y[a].bytes) return y[a].bytes < y[b].bytes;
    if (y[a].ms < 0.9 * y[b].ms || y[b].ms < 0.9 * y[a].ms) return y[a].ms < y[b].ms;
    return rgba[a].bytes < rgba[b].bytes;
}

/* The best codec within budget at 512x512 Y, among all or only the lossless ones. */
static int bench_recommend(const struct bench_result *y, const struct bench_result *rgba, int lossless_only)
{
    int best = -1;
    for (int c = 0; c < NCODECS; c++) {
        if (y[c].ms > BUDGET_MS || (lossless_only && (c == EXR_CODEC_B44 || c == EXR_CODEC_B44A))) continue;
        if (best < 0 || bench_better(y, rgba, c, best)) best = c;
    }
    return best;
}

static void bench_print_choice(const char *what, int c, const struct bench_result *y, const struct bench_result *rgba)
{
    if (c < 0) {
        printf("exr %s: none within %.1f ms at %dx%d half Y\n", what, BUDGET_MS, SIZE, SIZE);
        return;
    }
    printf("exr %s: codec=%s (Y %zu bytes, %.2f ms; RGBA %zu bytes, %.2f ms)\n", what, exr_codec_names[c], y[c].bytes,
           y[c].ms, rgba[c].bytes, rgba[c].ms);
}

int main(void)
{
    struct bench_result y[NCODECS], rgba[NCODECS];
    if (bench_variant(1, y) || bench_variant(4, rgba)) return 1;
    int best = bench_recommend(y, rgba, 0);
    bench_print_choice("recommended default (smallest within budget at 512x512 half Y)", best, y, rgba);
    bench_print_choice("best lossless within budget", bench_recommend(y, rgba, 1), y, rgba);
    return best < 0;
}
