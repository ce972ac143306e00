/* test_light_rig.c — the energy wave's light rig (digest 003; PROTOCOL.md §7.7): the
 * segments and strengths derived from energy_wave's sources and pulse, the byte encoding,
 * and the C references of the client's shading against the digest's golden values
 * (§5 items 1-4, 8, 9, 11), including the shadow-direction sign fix (§6 gap 1).
 *
 * `test_light_rig --dump DIR` also writes real encoder output for the JavaScript decoder's
 * test (tests/integration/test_web_decoders.sh): DIR/rig-N.bin (a whole frame: 64-byte
 * header + payload) and DIR/rig-N.json (the values it must decode to). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "effect.h"
#include "effects/energy_wave.h"
#include "effects/light_rig.h"
#include "effects/wave_sources.h"
#include "fxs_frame.h"
#include "../ref/energy_ref.h"
#include "../ref/light_ref.h"
#include "wave_scenes.h"

static cJSON *rig_doc(cJSON *partial)
{
    struct fx_err err = {0};
    cJSON *doc = effect_params(&energy_wave_effect, NULL, partial, &err);
    cJSON_Delete(partial);
    if (!doc) fprintf(stderr, "  params: %s\n", err.message);
    return doc;
}

/* The defaults with partial_json over them. */
static cJSON *rig_params(const char *partial_json)
{
    return rig_doc(partial_json ? cJSON_Parse(partial_json) : NULL);
}

/* The thesis's joined curves with the pulse (wave_scenes.h), extra_json over them. */
static cJSON *rig_curves(const char *extra_json) { return rig_doc(wave_fig56_partial(extra_json)); }

/* The rig energy_wave sends for document p at stream time t (its step's path: sources and
 * settings read once, the frame's weights, then the segments). */
static void rig_at(const cJSON *p, double t, struct fxs_rig *rig)
{
    static struct wave_sources src;
    static double w[WAVE_MAX_SRC][WAVE_MAX_W];
    static struct energy_wave_config c;
    struct light_rig lr;
    struct fx_err err = {0};
    CHECK(params_load(energy_wave_params, p, &c, sizeof c, &err) == 0, "typed parameters: %s", err.message);
    wave_sources_read(&c, &src);
    light_rig_read(&c, &lr);
    wave_sources_weights(&src, t, w);
    light_rig_build(&lr, &src, w, rig);
}

static struct fxs_rig_consts eq25_ramp(void)
{
    struct fxs_rig_consts k = {0};
    struct fxs_rig_band b[3] = {{-1, {0.0, 0.2, 0.4}}, {-0.3, {0.5, 0.7, 0.9}}, {0, {0.9, 0.9, 1.0}}};
    k.n_bands = 3;
    memcpy(k.bands, b, sizeof b);
    return k;
}

static struct fxs_rig halfline_rig(void)
{
    struct fxs_rig rig = {0};
    rig.n_seg = 1;
    rig.seg[0] = (struct fxs_rig_seg){{0, 0, 0}, {1, 0, 0}, 0, INFINITY, 1, FXS_RIG_LINE, 0};
    rig.k = eq25_ramp();
    return rig;
}

/* Digest §5 item 4: golden shading with C = 0, D = (1,0,0), the thesis's half-line. */
static void test_golden_shading(void)
{
    struct fxs_rig rig = halfline_rig();
    struct { double M[3], N[3], m, rgb[3]; } g[] = {
        {{2, 1, 0}, {0, -1, 0}, 1, {0.9, 0.9, 1.0}},
        {{2, 1, 0}, {1, 0, 0}, 0, {0.9, 0.9, 1.0}},
        {{-1, 1, 0}, {0, 1, 0}, -0.70710678, {0, 0.2, 0.4}},
        {{2, 1, 0}, {0.9798, 0.2, 0}, -0.2, {0.5, 0.7, 0.9}},
    };
    for (size_t i = 0; i < sizeof g / sizeof g[0]; i++) {
        double E[3], rgb[3];
        CHECK(light_ref_point_light(&rig, g[i].M, E) == 0, "row %zu: no light", i);
        double m = light_ref_m(E, g[i].M, g[i].N);
        CHECK_NEAR(m, g[i].m, 1e-4);
        light_ref_ramp(&rig.k, m, rgb);
        for (int c = 0; c < 3; c++) CHECK_NEAR(rgb[c], g[i].rgb[c], 1e-12);
    }
    double M[3] = {-1, 1, 0}, E[3];
    light_ref_point_light(&rig, M, E);
    CHECK(E[0] == 0 && E[1] == 0 && E[2] == 0, "a <= 0 gives E = C (eq. 2.2)");
}

/* §5 items 1-3: E is the nearest point of the half-line; axis invariance; ranges. */
static void test_nearest_properties(void)
{
    struct fxs_rig rig = halfline_rig();
    double D[3] = {0.48, 0.6, 0.64}; /* unit */
    memcpy(rig.seg[0].d, D, sizeof D);
    rig.seg[0].c[0] = 0.3;
    srand(7);
    for (int n = 0; n < 200; n++) {
        double M[3], N[3], E[3];
        for (int c = 0; c < 3; c++) {
            M[c] = 4.0 * rand() / RAND_MAX - 2.0;
            N[c] = 2.0 * rand() / RAND_MAX - 1.0;
        }
        double nn = sqrt(N[0] * N[0] + N[1] * N[1] + N[2] * N[2]);
        for (int c = 0; c < 3; c++) N[c] /= nn;
        light_ref_point_light(&rig, M, E);
        const double *C = rig.seg[0].c;
        double a = (M[0] - C[0]) * D[0] + (M[1] - C[1]) * D[1] + (M[2] - C[2]) * D[2];
        double dE = 0;
        for (int c = 0; c < 3; c++) dE += (E[c] - M[c]) * (E[c] - M[c]);
        if (a <= 0) {
            CHECK(E[0] == C[0] && E[1] == C[1] && E[2] == C[2], "a <= 0 but E != C");
        } else {
            double perp = (E[0] - M[0]) * D[0] + (E[1] - M[1]) * D[1] + (E[2] - M[2]) * D[2];
            CHECK_NEAR(perp, 0, 1e-12);
        }
        for (double s = 0; s < 6; s += 0.05) {
            double d2 = 0;
            for (int c = 0; c < 3; c++) d2 += (C[c] + s * D[c] - M[c]) * (C[c] + s * D[c] - M[c]);
            CHECK(dE <= d2 + 1e-12, "a point of the line at s=%g is nearer", s);
        }
        double m = light_ref_m(E, M, N);
        CHECK(m >= -1 && m <= 1 && isfinite(m), "m = %g out of [-1,1]", m);
        if (a > 0) { /* axis invariance: moving M along D changes neither L nor m */
            double M2[3], E2[3];
            for (int c = 0; c < 3; c++) M2[c] = M[c] + 3 * D[c];
            light_ref_point_light(&rig, M2, E2);
            CHECK_NEAR(light_ref_m(E2, M2, N), m, 1e-12);
        }
    }
}

/* Digest §5 item 9 (with the gap-1 sign fix). */
static void test_golden_shadow(void)
{
    struct fxs_rig_consts k = {0};
    double Y[3] = {0, 1, 0}, X[3] = {1, 0, 0}, Z[3] = {0, 0, 1};
    memcpy(k.plane_y, Y, sizeof Y);
    memcpy(k.plane_x, X, sizeof X);
    memcpy(k.plane_z, Z, sizeof Z);
    k.shadow_theta = 60 * M_PI / 180;
    double B[3] = {0, 1, 0}, W[3] = {-3, 0.5, 0}, e[3], kd[3], lam;
    for (int c = 0; c < 3; c++) e[c] = B[c] - W[c];
    int clamped = light_ref_shadow_dir(&k, e, NULL, kd, &lam);
    CHECK(clamped == 1, "lambda > theta must clamp");
    CHECK_NEAR(lam * 180 / M_PI, 99.46, 0.005);
    CHECK_NEAR(kd[0], 0.8660254, 1e-6);
    CHECK_NEAR(kd[1], -0.5, 1e-12);
    CHECK_NEAR(kd[2], 0, 1e-12);
    /* angle(k, -Y) = min(lambda, theta) */
    CHECK_NEAR(acos(-kd[1]), k.shadow_theta, 1e-9);
    double P[3] = {0.2, 1.7, 0.1}, I[3] = {0, 0, 0};
    double t = ((I[1] - P[1]) * Y[1]) / (kd[1] * Y[1]); /* gap 2: t = ((I - P)·Y)/(k·Y) */
    CHECK_NEAR(t, 3.4, 1e-12);
    CHECK_NEAR(P[0] + t * kd[0], 3.1445, 5e-5);
    CHECK_NEAR(P[1] + t * kd[1], 0, 1e-12);
    CHECK_NEAR(P[2] + t * kd[2], 0.1, 1e-12);
    double P2[3] = {0, -0.1, 0};
    CHECK_NEAR((I[1] - P2[1]) / kd[1], -0.2, 1e-12); /* t < 0: r = 0 (eq. 2.32) */
    /* The thesis taken literally (eqs. 2.17-2.22: j = i x Y, k = q i q^-1) is 120 degrees
     * from -Y for theta = 60 degrees: the error the fix removes. */
    double i[3] = {1, 0, 0}, j[3] = {i[1] * Y[2] - i[2] * Y[1], i[2] * Y[0] - i[0] * Y[2], i[0] * Y[1] - i[1] * Y[0]};
    double phi = M_PI / 2 - k.shadow_theta, s = cos(phi / 2), V[3], VxI[3], lit[3];
    for (int c = 0; c < 3; c++) V[c] = j[c] * sin(phi / 2);
    VxI[0] = V[1] * i[2] - V[2] * i[1];
    VxI[1] = V[2] * i[0] - V[0] * i[2];
    VxI[2] = V[0] * i[1] - V[1] * i[0];
    double VV = V[0] * V[0] + V[1] * V[1] + V[2] * V[2], Vi = V[0] * i[0] + V[1] * i[1] + V[2] * i[2];
    for (int c = 0; c < 3; c++) lit[c] = (s * s - VV) * i[c] + 2 * s * VxI[c] + 2 * Vi * V[c];
    CHECK_NEAR(acos(-lit[1]) * 180 / M_PI, 120, 1e-9);
    CHECK(fabs(acos(-kd[1]) - acos(-lit[1])) > 0.5, "the fixed k differs from the literal one");
    /* unclamped: k = e, and a vertical light gives a vertical drop */
    double down[3] = {0, -2, 0};
    CHECK(light_ref_shadow_dir(&k, down, NULL, kd, &lam) == 0 && kd[1] == -1 && lam == 0, "lambda 0: straight down");
    /* horizontal offset at height h is at most h tan(theta), even with the light below */
    for (double ey = -1; ey <= 1; ey += 0.1) {
        double ee[3] = {0.7, ey, -0.3};
        light_ref_shadow_dir(&k, ee, NULL, kd, &lam);
        double h = 1.0, tt = h / -kd[1], off = tt * sqrt(kd[0] * kd[0] + kd[2] * kd[2]);
        CHECK(kd[1] < 0 && off <= h * tan(k.shadow_theta) + 1e-9, "offset %g at ey %g", off, ey);
        CHECK(kd[0] * 0.7 + kd[2] * -0.3 >= 0, "horizontal part points away from the light");
    }
}

/* §5 item 11: no NaN on degenerate input. */
static void test_degenerate(void)
{
    struct fxs_rig_consts k = {0};
    k.plane_y[1] = 1;
    k.plane_x[0] = 1;
    k.plane_z[2] = 1;
    k.shadow_theta = 1.0;
    double zero[3] = {0, 0, 0}, up[3] = {0, 3, 0}, kd[3], lam, prev[3] = {0, 0, 0};
    light_ref_shadow_dir(&k, zero, prev, kd, &lam);
    CHECK(isfinite(kd[0]) && isfinite(kd[1]) && isfinite(kd[2]) && kd[1] == -1, "B on the axis: straight down");
    double side[3] = {0, 0, 1};
    light_ref_shadow_dir(&k, side, prev, kd, &lam); /* sets prev i = +Z */
    light_ref_shadow_dir(&k, up, prev, kd, &lam);    /* light directly below: f = 0 */
    CHECK(isfinite(kd[0] + kd[1] + kd[2]), "f = 0 gives NaN");
    CHECK_NEAR(kd[2], sin(1.0), 1e-12);
    struct fxs_rig rig = halfline_rig();
    double M[3] = {2, 0, 0}, N[3] = {0, 0, 1}, E[3];
    light_ref_point_light(&rig, M, E);
    CHECK(light_ref_m(E, M, N) == 1.0, "M on the axis: m = 1");
    rig.seg[0].strength = 0;
    CHECK(light_ref_point_light(&rig, M, E) == -1, "a zero-strength segment lights");
}

static void test_bspline(void)
{
    double w[7] = {1.0, 0.2, 0.6, 1.0, 0.5, 0.8, 1.0}, ones[7] = {1, 1, 1, 1, 1, 1, 1};
    for (int nw = 3; nw <= 7; nw++)
        for (double t = 0; t <= 1.0; t += 1.0 / 64) {
            CHECK_NEAR(light_rig_bspline(nw, w, t), energy_ref_bspline(nw, w, t), 1e-12);
            CHECK_NEAR(light_rig_bspline(nw, ones, t), 1.0, 1e-12); /* partition of unity */
        }
    CHECK_NEAR(light_rig_bspline(7, w, 1.0), 1.0, 1e-12); /* end span closed: S(1) = w[n-1] */
}

/* Segments of the joined curves: 2 curves x curve_segments chords on the Bezier, strength =
 * coef x S(t_mid) with the pulse at the frame's time (as the texture's kernel sees it). */
static void test_segments_curves(void)
{
    cJSON *p = rig_curves("{\"curve_segments\":8}");
    CHECK(p != NULL, "joined curves");
    if (!p) return;
    static struct fxs_rig rig;
    const double times[] = {0.0, 0.4, 1.3, 2.9};
    for (size_t ti = 0; ti < sizeof times / sizeof times[0]; ti++) {
        double t = times[ti];
        rig_at(p, t, &rig);
        CHECK(rig.n_seg == 16, "n_seg %d", rig.n_seg);
        const cJSON *cv = cJSON_GetObjectItemCaseSensitive(p, "curves"), *it;
        int ci = 0;
        cJSON_ArrayForEach(it, cv) {
            static const char *const bn[3] = {"p0", "p1", "p2"};
            double b[3][3], w[32], anim[32], coef = cJSON_GetObjectItemCaseSensitive(it, "coef")->valuedouble;
            for (int k = 0; k < 3; k++)
                for (int c = 0; c < 3; c++)
                    b[k][c] = cJSON_GetArrayItem(cJSON_GetObjectItemCaseSensitive(it, bn[k]), c)->valuedouble;
            int nw = 0;
            const cJSON *x;
            cJSON_ArrayForEach(x, cJSON_GetObjectItemCaseSensitive(it, "W")) w[nw++] = x->valuedouble;
            energy_ref_loop_weights(t * 30.0, nw, anim);
            for (int k = 0; k < nw; k++) w[k] *= anim[k];
            for (int j = 0; j < 8; j++) {
                const struct fxs_rig_seg *s = &rig.seg[ci * 8 + j];
                double a[3], e[3];
                energy_ref_curve_eval(b, j / 8.0, a);
                energy_ref_curve_eval(b, (j + 1) / 8.0, e);
                CHECK(s->source == FXS_RIG_CURVE && s->index == ci, "source");
                for (int c = 0; c < 3; c++) {
                    CHECK_NEAR(s->c[c], a[c], 1e-9);
                    CHECK_NEAR(s->c[c] + s->a_hi * s->d[c], e[c], 1e-9);
                }
                CHECK(s->a_lo == 0, "chord starts at C");
                CHECK_NEAR(s->strength, coef * energy_ref_bspline(nw, w, (j + 0.5) / 8), 1e-9);
            }
            ci++;
        }
    }
    /* the pulse moves: some segment's strength differs between two times */
    static struct fxs_rig r2;
    rig_at(p, 0.4, &rig);
    rig_at(p, 1.3, &r2);
    int differ = 0;
    for (int i = 0; i < 16; i++) differ |= fabs(rig.seg[i].strength - r2.seg[i].strength) > 1e-3;
    CHECK(differ, "the pulse does not move the strengths");
    cJSON_Delete(p);
    p = rig_curves("{\"animate\":false}");
    rig_at(p, 1.3, &rig);
    CHECK_NEAR(rig.seg[0].strength, 8 * energy_ref_bspline(7, (double[]){1.0, 0.2, 0.6, 1.0, 0.5, 0.8, 1.0}, 1.0 / 16),
               1e-9);
    cJSON_Delete(p);
}

/* With the joined curves and their pulse the rig never switches off: at every frame of several
 * loops the total segment strength is at least 30% of its median (measured: 48%; the texture's
 * total energy, test_energy_kernel, keeps 63%), where a single looped sweep would reach 0. */
static int rig_cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static void test_loop_never_dark(void)
{
    cJSON *p = rig_curves(NULL);
    CHECK(p != NULL, "joined curves");
    if (!p) return;
    static struct fxs_rig rig;
    enum { FRAMES = 240 }; /* 8 s at 30 frames/s: several loops of every curve */
    double total[FRAMES], sorted[FRAMES];
    double rate = 0;
    CHECK(params_number(p, "anim_rate", &rate) == 0 && rate > 0, "anim_rate");
    for (int f = 0; f < FRAMES; f++) {
        rig_at(p, f / rate, &rig);
        total[f] = 0;
        for (int i = 0; i < rig.n_seg; i++) total[f] += rig.seg[i].strength;
        sorted[f] = total[f];
    }
    qsort(sorted, FRAMES, sizeof *sorted, rig_cmp);
    double median = sorted[FRAMES / 2];
    printf("  info: rig strength over %d frames: min %.3g, median %.3g\n", FRAMES, sorted[0], median);
    CHECK(median > 0 && sorted[0] >= 0.3 * median, "least total strength %.3g, median %.3g", sorted[0], median);
    cJSON_Delete(p);
}

/* The default ramp follows color_energy (the light the wave casts takes its colour);
 * an explicit ramp is used as given. */
static void test_ramp_follows_energy_colour(void)
{
    static struct fxs_rig a, b, c;
    cJSON *pa = rig_params("{}"), *pb = rig_params("{\"color_energy\":[1,0.3,0.1]}");
    cJSON *pc = rig_params("{\"color_energy\":[1,0.3,0.1],\"ramp\":[{\"m_min\":-1,\"color\":[0,1,0]}]}");
    CHECK(pa && pb && pc, "documents");
    if (!pa || !pb || !pc) return;
    rig_at(pa, 0, &a);
    rig_at(pb, 0, &b);
    rig_at(pc, 0, &c);
    CHECK(a.k.n_bands == 3 && b.k.n_bands == 3 && a.k.bands[1].m_min == -0.3, "three default bands");
    CHECK(fabs(a.k.bands[2].rgb[2] - 1.0) < 1e-12 && fabs(a.k.bands[2].rgb[0] - 0.24) < 1e-12 &&
              fabs(b.k.bands[2].rgb[0] - 1.0) < 1e-12 && fabs(b.k.bands[2].rgb[2] - 0.28) < 1e-12 &&
              fabs(b.k.bands[1].rgb[0] - 0.65) < 1e-12 && fabs(b.k.bands[0].rgb[1] - 0.09) < 1e-12,
          "the bands are 0.3 C_e, 0.05 + 0.6 C_e, 0.2 + 0.8 C_e: blue for the default C_e, orange for an orange "
          "one (lit %g %g %g)", b.k.bands[2].rgb[0], b.k.bands[2].rgb[1], b.k.bands[2].rgb[2]);
    CHECK(c.k.n_bands == 1 && c.k.bands[0].rgb[1] == 1.0, "an explicit ramp is used as given");
    cJSON_Delete(pa);
    cJSON_Delete(pb);
    cJSON_Delete(pc);
}

static void test_segments_other_sources(void)
{
    cJSON *p = rig_params("{\"points\":[{\"pos\":[1,2,3],\"coef\":3}],\"lines\":[{\"pos\":[0,1,0],\"dir\":[0,0,2],"
                          "\"coef\":-2}],\"tori\":[{\"center\":[0,0,5],\"axis\":[0,0,1],\"R\":2,\"coef\":5}],"
                          "\"curves\":[],\"torus_segments\":12}");
    CHECK(p != NULL, "params");
    if (!p) return;
    static struct fxs_rig rig;
    rig_at(p, 0, &rig);
    CHECK(rig.n_seg == 1 + 1 + 12, "n_seg %d", rig.n_seg);
    const struct fxs_rig_seg *s = &rig.seg[0];
    CHECK(s->source == FXS_RIG_POINT && s->c[0] == 1 && s->c[1] == 2 && s->c[2] == 3 && s->a_lo == 0 && s->a_hi == 0 &&
              s->strength == 3, "point segment");
    s = &rig.seg[1];
    CHECK(s->source == FXS_RIG_LINE && s->d[2] == 1 && isinf(s->a_lo) && s->a_lo < 0 && isinf(s->a_hi) &&
              s->strength == -2, "line segment (normalised, infinite)");
    for (int j = 0; j < 12; j++) {
        s = &rig.seg[2 + j];
        double e[3];
        for (int c = 0; c < 3; c++) e[c] = s->c[c] + s->a_hi * s->d[c];
        CHECK_NEAR(hypot(s->c[0], s->c[1]), 2, 1e-9);
        CHECK_NEAR(hypot(e[0], e[1]), 2, 1e-9);
        CHECK_NEAR(s->c[2], 5, 1e-12);
        CHECK_NEAR(s->a_hi, 2 * 2 * sin(M_PI / 12), 1e-9); /* chord of 30 degrees */
        CHECK(s->source == FXS_RIG_TORUS && s->strength == 5, "torus chord");
    }
    /* a point on the torus axis is lit; the negative line does not light */
    double M[3] = {0, 1, 0}, E[3];
    int i = light_ref_point_light(&rig, M, E);
    CHECK(i >= 0 && rig.seg[i].source != FXS_RIG_LINE, "negative coefficient lit (segment %d)", i);
    cJSON_Delete(p);
    /* the cap: 16 curves x 32 chords */
    char buf[4096];
    size_t n = (size_t)snprintf(buf, sizeof buf, "{\"curve_segments\":32,\"curves\":[");
    for (int c = 0; c < 16; c++) n += (size_t)snprintf(buf + n, sizeof buf - n, "%s{}", c ? "," : "");
    snprintf(buf + n, sizeof buf - n, "]}");
    p = rig_params(buf);
    rig_at(p, 0, &rig);
    CHECK(rig.n_seg == FXS_RIG_MAX_SEG, "cap: %d", rig.n_seg);
    cJSON_Delete(p);
}

static float le_f32(const uint8_t *p)
{
    uint32_t u = fxs_get_u32(p);
    float f;
    memcpy(&f, &u, 4);
    return f;
}

static void test_encoding(void)
{
    cJSON *p = rig_curves("{\"light_rig\":true}");
    CHECK(p != NULL, "params");
    if (!p) return;
    static struct fxs_rig rig, back;
    static uint8_t buf[FXS_RIG_MAX_PAYLOAD];
    rig_at(p, 0.7, &rig);
    size_t n = fxs_rig_encode(&rig, 1, buf);
    size_t cb = 96 + 16 * 3;
    CHECK(n == 32 + 16 * 40 + cb, "payload %zu bytes", n);
    CHECK(memcmp(buf, "FXR1", 4) == 0, "magic");
    CHECK(fxs_get_u16(buf + 4) == 1 && fxs_get_u16(buf + 6) == 32 && fxs_get_u16(buf + 8) == 16 &&
              fxs_get_u16(buf + 10) == 40, "version, header_bytes, n_seg, seg_bytes");
    CHECK(fxs_get_u32(buf + 12) == 1 && fxs_get_u32(buf + 20) == cb, "flags, constants_bytes");
    CHECK(fxs_get_u32(buf + 24) == 0 && fxs_get_u32(buf + 28) == 0, "reserved");
    uint32_t h = 2166136261u;
    for (size_t i = 32 + 640; i < n; i++) h = (h ^ buf[i]) * 16777619u;
    CHECK(fxs_get_u32(buf + 16) == h, "constants_id is FNV-1a of the constants block");
    const uint8_t *s1 = buf + 32 + 40; /* segment 1 */
    CHECK(le_f32(s1) == (float)rig.seg[1].c[0] && le_f32(s1 + 8) == (float)rig.seg[1].c[2], "C");
    CHECK(le_f32(s1 + 16) == (float)rig.seg[1].d[1] && le_f32(s1 + 28) == (float)rig.seg[1].a_hi, "D, a_hi");
    CHECK(le_f32(s1 + 32) == (float)rig.seg[1].strength && fxs_get_u16(s1 + 36) == 4 && fxs_get_u16(s1 + 38) == 0,
          "strength, source, index");
    const uint8_t *k = buf + 32 + 640;
    CHECK(fxs_get_u16(k) == 3 && fxs_get_u16(k + 2) == 7, "n_bands, flags");
    CHECK(le_f32(k + 4) == 1.0f && le_f32(k + 8) == 0.005f, "strength, outline_width");
    CHECK(le_f32(k + 24) == (float)(M_PI / 3) && le_f32(k + 28) == 0.65f, "theta in radians, opacity");
    CHECK(le_f32(k + 48) == -9.0f && le_f32(k + 60) == 1.0f, "plane I, Y");
    CHECK(le_f32(k + 68) == 1.0f && le_f32(k + 88) == 1.0f, "plane X, Z");
    CHECK(le_f32(k + 96 + 16) == -0.3f && le_f32(k + 96 + 16 + 12) == 0.65f, "band 1");
    uint32_t id;
    int hc;
    CHECK(fxs_rig_decode(buf, n, &back, &id, &hc) == 0 && hc && id == h, "decode");
    CHECK(back.n_seg == 16 && back.k.n_bands == 3 && back.seg[5].strength == (float)rig.seg[5].strength &&
              back.k.bands[2].rgb[2] == 1.0f, "round trip");
    CHECK(fxs_rig_decode(buf, n - 1, &back, &id, &hc) == -1, "short payload accepted");
    buf[0] = 'X';
    CHECK(fxs_rig_decode(buf, n, &back, &id, &hc) == -1, "bad magic accepted");
    /* without constants: same id, 672 bytes */
    size_t n2 = fxs_rig_encode(&rig, 0, buf);
    CHECK(n2 == 32 + 640 && fxs_get_u32(buf + 12) == 0 && fxs_get_u32(buf + 20) == 0 && fxs_get_u32(buf + 16) == h,
          "no constants");
    CHECK(fxs_rig_decode(buf, n2, &back, &id, &hc) == 0 && !hc, "decode without constants");
    /* the id follows the constants, not the segments */
    rig_at(p, 2.0, &back);
    CHECK(fxs_rig_constants_id(&back.k) == h, "segments changed the id");
    cJSON_Delete(p);
    p = rig_params("{\"ramp\":[{\"m_min\":-1,\"color\":[1,0,0]}]}");
    rig_at(p, 0.7, &back);
    CHECK(fxs_rig_constants_id(&back.k) != h, "ramp change kept the id");
    cJSON_Delete(p);
}

static void test_params_rules(void)
{
    struct fx_err err = {0};
    cJSON *partial = cJSON_Parse("{\"ramp\":[{\"m_min\":-1},{\"m_min\":0.2},{\"m_min\":0.2}]}");
    cJSON *doc = effect_params(&energy_wave_effect, NULL, partial, &err);
    CHECK(doc == NULL && !strcmp(err.code, "bad_param") && !strcmp(err.param, "ramp[2].m_min"), "%s %s", err.code,
          err.param);
    cJSON_Delete(doc);
    cJSON_Delete(partial);
    partial = cJSON_Parse("{\"shadow_theta\":90}");
    doc = effect_params(&energy_wave_effect, NULL, partial, &err);
    CHECK(doc == NULL && !strcmp(err.param, "shadow_theta"), "theta 90 accepted");
    cJSON_Delete(doc);
    cJSON_Delete(partial);
}

/* ---- vectors for the JavaScript decoder ---------------------------------------------- */

static void dump_num(FILE *f, double v)
{
    if (isinf(v)) fprintf(f, "\"%sinf\"", v < 0 ? "-" : "");
    else fprintf(f, "%.9g", (double)(float)v);
}

static void dump_vec(FILE *f, const char *name, const double *v, int n)
{
    fprintf(f, "\"%s\":[", name);
    for (int i = 0; i < n; i++) {
        if (i) fputc(',', f);
        dump_num(f, v[i]);
    }
    fputc(']', f);
}

static int dump_one(const char *dir, int idx, const char *params, double t, int with_constants)
{
    cJSON *p = rig_params(params);
    if (!p) return -1;
    static struct fxs_rig rig;
    static uint8_t frame[64 + FXS_RIG_MAX_PAYLOAD];
    rig_at(p, t, &rig);
    size_t n = fxs_rig_encode(&rig, with_constants, frame + 64);
    struct fxs_header h = {.kind = FXS_KIND_LIGHT_RIG, .channel = 3, .param_rev = 7, .seq = 42, .sim_time = t,
                           .server_time_us = 1795313709549000ull, .codec = FXS_CODEC_LIGHT_RIG,
                           .payload_bytes = (uint32_t)n, .count_or_width = (uint32_t)rig.n_seg};
    fxs_header_pack(&h, frame);
    char path[1024];
    snprintf(path, sizeof path, "%s/rig-%d.bin", dir, idx);
    FILE *f = fopen(path, "wb");
    if (!f || fwrite(frame, 1, 64 + n, f) != 64 + n) return -1;
    fclose(f);
    snprintf(path, sizeof path, "%s/rig-%d.json", dir, idx);
    if (!(f = fopen(path, "w"))) return -1;
    fprintf(f, "{\"payload_bytes\":%zu,\"sim_time\":%.17g,\"constants_id\":%u,\"has_constants\":%s,\"segments\":[",
            n, t, fxs_rig_constants_id(&rig.k), with_constants ? "true" : "false");
    for (int i = 0; i < rig.n_seg; i++) {
        const struct fxs_rig_seg *s = &rig.seg[i];
        fprintf(f, "%s{", i ? "," : "");
        dump_vec(f, "c", s->c, 3);
        fputc(',', f);
        dump_vec(f, "d", s->d, 3);
        fprintf(f, ",\"a_lo\":");
        dump_num(f, s->a_lo);
        fprintf(f, ",\"a_hi\":");
        dump_num(f, s->a_hi);
        fprintf(f, ",\"strength\":");
        dump_num(f, s->strength);
        fprintf(f, ",\"source\":%d,\"index\":%d}", s->source, s->index);
    }
    const struct fxs_rig_consts *k = &rig.k;
    fprintf(f, "],\"constants\":{\"flags\":%u,\"strength\":", k->flags);
    dump_num(f, k->strength);
    fprintf(f, ",\"outline_width\":");
    dump_num(f, k->outline_width);
    fputc(',', f);
    dump_vec(f, "outline_rgb", k->outline_rgb, 3);
    fprintf(f, ",\"shadow_theta\":");
    dump_num(f, k->shadow_theta);
    fprintf(f, ",\"shadow_opacity\":");
    dump_num(f, k->shadow_opacity);
    fputc(',', f);
    dump_vec(f, "shadow_rgb", k->shadow_rgb, 3);
    fputc(',', f);
    dump_vec(f, "plane_i", k->plane_i, 3);
    fputc(',', f);
    dump_vec(f, "plane_y", k->plane_y, 3);
    fputc(',', f);
    dump_vec(f, "plane_x", k->plane_x, 3);
    fputc(',', f);
    dump_vec(f, "plane_z", k->plane_z, 3);
    fprintf(f, ",\"bands\":[");
    for (int i = 0; i < k->n_bands; i++) {
        fprintf(f, "%s{\"m_min\":", i ? "," : "");
        dump_num(f, k->bands[i].m_min);
        fputc(',', f);
        dump_vec(f, "rgb", k->bands[i].rgb, 3);
        fputc('}', f);
    }
    fprintf(f, "]}}\n");
    fclose(f);
    cJSON_Delete(p);
    return 0;
}

static int dump(const char *dir)
{
    int rc = 0;
    rc |= dump_one(dir, 0, "{\"light_rig\":true}", 1.3, 1);
    rc |= dump_one(dir, 1, "{\"light_rig\":true}", 1.3, 0);
    rc |= dump_one(dir, 2,
                   "{\"points\":[{\"pos\":[1,2,3],\"coef\":3}],\"lines\":[{\"pos\":[0,1,0],\"dir\":[0,1,1]}],"
                   "\"tori\":[{\"R\":2}],\"curves\":[],\"ramp\":[{\"m_min\":-1,\"color\":[0.1,0,0]},{\"m_min\":-0.5,"
                   "\"color\":[0.3,0.1,0]},{\"m_min\":0,\"color\":[0.8,0.5,0.2]},{\"m_min\":0.5,\"color\":[1,0.9,0.6]}],"
                   "\"outline\":false,\"shadow_theta\":45,\"shadow_plane_normal\":[0,1,0.2]}",
                   0.0, 1);
    printf("dumped 3 light-rig frames to %s\n", dir);
    return rc ? 1 : 0;
}

int main(int argc, char **argv)
{
    if (argc == 3 && !strcmp(argv[1], "--dump")) return dump(argv[2]);
    RUN(test_golden_shading);
    RUN(test_nearest_properties);
    RUN(test_golden_shadow);
    RUN(test_degenerate);
    RUN(test_bspline);
    RUN(test_segments_curves);
    RUN(test_loop_never_dark);
    RUN(test_ramp_follows_energy_colour);
    RUN(test_segments_other_sources);
    RUN(test_encoding);
    RUN(test_params_rules);
    return CHECK_DONE();
}
