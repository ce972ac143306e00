/* test_energy_kernel.c — the energy_wave OpenCL kernels (kernels/energy_wave.cl through
 * server/effects/energy_wave.h) against the double-precision reference (tests/ref/).
 *
 * Device helpers (cubic roots, B-spline, nearest curve point) are compared value by
 * value. Full renders of small random non-square scenes are compared with the
 * reference Simpson sum of the same n in mode "simpson" (tight) and with the converged
 * integral in every other mode listed in the `mode` parameter's choices (RMS relative
 * error), so a new mode is tested without editing this file. Digest §7 properties
 * (torus symmetry, torus axis = point source, straight curve = line, linearity,
 * monotonicity, epsilon bound) and the eq. 5.1 animation are checked on renders. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../ref/energy_ref.h"
#include "../ref/kernel_probe.h"
#include "check.h"
#include "effects/energy_wave.h"
#include "fxs_frame.h"
#include "slices.h"
#include "effects/wave_sources.h"
#include "ocl.h"
#include "params.h"
#include "wave_scenes.h"

/* the device functions' test entry points (tests/ref/), compiled after energy_wave.cl */
#define TEK_PROBE_CL "energy_wave_probe.cl"
#define TEK_MAX_MODES 8
#define TEK_MAX_TEXELS (64 * 64)

static struct ocl *tek_ocl;
static cJSON *tek_defaults;
static const char *tek_modes[TEK_MAX_MODES];
static int tek_nmodes;

/* ---------------------------------------------------------------- setup */

static unsigned long long tek_rng;

static double tek_rand(double lo, double hi)
{
    tek_rng ^= tek_rng << 13;
    tek_rng ^= tek_rng >> 7;
    tek_rng ^= tek_rng << 17;
    return lo + (hi - lo) * ((tek_rng >> 11) * (1.0 / 9007199254740992.0));
}

/* ---------------------------------------------------------------- device helpers */

/* Cubic x^3 + a x^2 + b x + c = 0 on the device (ew_test_cubic): abc is 3n floats; roots 3n
 * floats (the real roots ascending, unused slots 0); nroots n ints. */
static int tek_dev_cubic(int n, const float *abc, float *roots, int *nroots, struct fx_err *err)
{
    size_t f = sizeof(float);
    const struct probe_arg args[] = {
        {3 * (size_t)n * f, abc, NULL, 0},
        {3 * (size_t)n * f, NULL, roots, 0},
        {(size_t)n * sizeof(int), NULL, nroots, 0},
    };
    return probe_run(tek_ocl, ENERGY_WAVE_CL, TEK_PROBE_CL, ENERGY_WAVE_CL_OPTS, "ew_test_cubic", (size_t)n, args, 3, err);
}

/* Quadratic B-spline strength S(t) (digest §2.3) of weights w[0..nw-1] at n parameters t. */
static int tek_dev_bspline(int nw, const double *w, int n, const float *t, float *out, struct fx_err *err)
{
    size_t f = sizeof(float);
    float spl[3 * WAVE_MAX_W];
    int spans = nw - 2;
    energy_wave_pack_strength(spl, nw, w);
    const struct probe_arg args[] = {
        {(size_t)spans * 3 * f, spl, NULL, 0},
        {0, &spans, NULL, sizeof spans},
        {(size_t)n * f, t, NULL, 0},
        {(size_t)n * f, NULL, out, 0},
    };
    return probe_run(tek_ocl, ENERGY_WAVE_CL, TEK_PROBE_CL, ENERGY_WAVE_CL_OPTS, "ew_test_bspline", (size_t)n, args, 4, err);
}

/* Nearest point of the Bézier b = {B0, B1, B2} (9 floats) to n points p (3n floats): distance
 * and curve parameter t* in [0,1]. */
static int tek_dev_curve_nearest(const float b[9], int n, const float *p, float *dist, float *tparam,
                                 struct fx_err *err)
{
    size_t f = sizeof(float);
    double bd[3][3];
    float rec[16];
    for (int k = 0; k < 9; k++) bd[k / 3][k % 3] = b[k];
    energy_wave_pack_curve(rec, bd, 1.0, 3, 0.0, 1.0);
    const struct probe_arg args[] = {
        {sizeof rec, rec, NULL, 0},
        {3 * (size_t)n * f, p, NULL, 0},
        {(size_t)n * f, NULL, dist, 0},
        {(size_t)n * f, NULL, tparam, 0},
    };
    return probe_run(tek_ocl, ENERGY_WAVE_CL, TEK_PROBE_CL, ENERGY_WAVE_CL_OPTS, "ew_test_curve_nearest", (size_t)n, args, 4, err);
}

static int tek_is_simpson(const char *mode) { return strcmp(mode, "simpson") == 0; }

static void tek_find_modes(void)
{
    for (const struct param_def *d = energy_wave_params; d->name; d++)
        if (strcmp(d->name, "mode") == 0 && d->type == PARAM_ENUM)
            for (const char *const *c = d->choices; *c && tek_nmodes < TEK_MAX_MODES; c++)
                tek_modes[tek_nmodes++] = *c;
}

/* A complete document: defaults merged with `partial` (consumed). NULL on failure. */
static cJSON *tek_doc(cJSON *partial)
{
    cJSON *out = NULL;
    struct fx_err err = {0};
    if (params_merge(energy_wave_params, tek_defaults, partial, &out, &err))
        CHECK(0, "params_merge: %s (%s): %s", err.code, err.param, err.message);
    cJSON_Delete(partial);
    return out;
}

/* A renderer of the complete document doc (its typed parameters). */
static struct energy_wave *tek_new(const cJSON *doc, struct fx_err *err)
{
    struct energy_wave_config c;
    return params_load(energy_wave_params, doc, &c, sizeof c, err) ? NULL : energy_wave_new(tek_ocl, &c, err);
}

/* Renders doc at sim_time into out; 0 on success. */
static int tek_render(const cJSON *doc, double sim_time, float *out)
{
    struct fx_err err = {0};
    struct energy_wave *ew = tek_new(doc, &err);
    if (!ew) {
        CHECK(0, "energy_wave_new: %s: %s", err.code, err.message);
        return -1;
    }
    int rc = energy_wave_render(ew, sim_time, out, &err);
    CHECK(rc == 0, "energy_wave_render: %s: %s", err.code, err.message);
    energy_wave_free(ew);
    return rc;
}

static int tek_scene(const cJSON *doc, double sim_time, struct energy_ref_scene *sc)
{
    char msg[160];
    int rc = energy_ref_scene_from_json(doc, sim_time, sc, msg, sizeof msg);
    CHECK(rc == 0, "reference scene: %s", msg);
    return rc;
}

static cJSON *tek_vec(double x, double y, double z)
{
    double v[3] = {x, y, z};
    return cJSON_CreateDoubleArray(v, 3);
}

static cJSON *tek_rvec(double lo, double hi)
{
    return tek_vec(tek_rand(lo, hi), tek_rand(lo, hi), tek_rand(lo, hi));
}

static void tek_set_mode(cJSON *partial, const char *mode, int divisions)
{
    cJSON_AddStringToObject(partial, "mode", mode);
    if (divisions > 0) cJSON_AddNumberToObject(partial, "divisions", divisions);
}

static void tek_camera(cJSON *o, const double eye[3], const double center[3], const double up[3], double size,
                       int w, int h)
{
    cJSON_AddItemToObject(o, "eye", cJSON_CreateDoubleArray(eye, 3));
    cJSON_AddItemToObject(o, "center", cJSON_CreateDoubleArray(center, 3));
    cJSON_AddItemToObject(o, "up", cJSON_CreateDoubleArray(up, 3));
    cJSON_AddNumberToObject(o, "size", size);
    cJSON_AddNumberToObject(o, "width", w);
    cJSON_AddNumberToObject(o, "height", h);
    cJSON_AddNumberToObject(o, "nu", 2.0);
    cJSON_AddNumberToObject(o, "alpha", 1.0);
    cJSON_AddNumberToObject(o, "beta", 1.0);
    cJSON_AddBoolToObject(o, "animate", 0); /* the default animates W, which is 0 at frame 0 */
}

/* ---------------------------------------------------------------- random scenes */

static void tek_add_point(cJSON *arr, double coef)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddItemToObject(o, "pos", tek_rvec(-1, 1));
    cJSON_AddNumberToObject(o, "coef", coef);
    cJSON_AddItemToArray(arr, o);
}

static void tek_add_line(cJSON *arr, double coef)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddItemToObject(o, "pos", tek_rvec(-0.5, 0.5));
    cJSON_AddItemToObject(o, "dir", tek_vec(tek_rand(-1, 1), tek_rand(0.3, 1), tek_rand(-1, 1)));
    cJSON_AddNumberToObject(o, "coef", coef);
    cJSON_AddItemToArray(arr, o);
}

static void tek_add_torus(cJSON *arr, double coef)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddItemToObject(o, "center", tek_rvec(-0.5, 0.5));
    cJSON_AddItemToObject(o, "axis", tek_vec(tek_rand(-1, 1), tek_rand(-1, 1), tek_rand(0.2, 1)));
    cJSON_AddNumberToObject(o, "R", tek_rand(0.6, 1.5));
    cJSON_AddNumberToObject(o, "coef", coef);
    cJSON_AddItemToArray(arr, o);
}

static void tek_add_curve(cJSON *arr, double coef)
{
    cJSON *o = cJSON_CreateObject();
    double w[9];
    int nw = 3 + (int)tek_rand(0, 6.99);
    for (int k = 0; k < nw; k++) w[k] = tek_rand(0.1, 1);
    cJSON_AddItemToObject(o, "p0", tek_rvec(-1.5, 1.5));
    cJSON_AddItemToObject(o, "p1", tek_rvec(-1.5, 1.5));
    cJSON_AddItemToObject(o, "p2", tek_rvec(-1.5, 1.5));
    cJSON_AddNumberToObject(o, "coef", coef);
    cJSON_AddItemToObject(o, "W", cJSON_CreateDoubleArray(w, nw));
    cJSON_AddItemToArray(arr, o);
}

/* Random scene `seed`: 0-2 points, 0-1 lines, 0-1 tori, 1-2 curves, random camera, 32x24. */
static cJSON *tek_random_partial(int seed, double coef_scale)
{
    tek_rng = 0x9E3779B97F4A7C15ULL * (unsigned long long)(seed + 1);
    cJSON *o = cJSON_CreateObject();
    cJSON *pts = cJSON_AddArrayToObject(o, "points"), *lns = cJSON_AddArrayToObject(o, "lines");
    cJSON *tor = cJSON_AddArrayToObject(o, "tori"), *cur = cJSON_AddArrayToObject(o, "curves");
    int np = (int)tek_rand(0, 2.99), nl = (int)tek_rand(0, 1.99), nt = (int)tek_rand(0, 1.99), nc = 1 + (int)tek_rand(0, 1.99);
    for (int k = 0; k < np; k++) tek_add_point(pts, coef_scale * tek_rand(0.3, 2));
    for (int k = 0; k < nl; k++) tek_add_line(lns, coef_scale * tek_rand(0.1, 0.5));
    for (int k = 0; k < nt; k++) tek_add_torus(tor, coef_scale * tek_rand(0.5, 2));
    for (int k = 0; k < nc; k++) tek_add_curve(cur, coef_scale * tek_rand(0.5, 2));
    double th = tek_rand(0, 6.283), el = tek_rand(-0.6, 0.6), d = tek_rand(5, 8);
    double eye[3] = {d * cos(el) * cos(th), d * sin(el), d * cos(el) * sin(th)};
    double ctr[3] = {tek_rand(-0.3, 0.3), tek_rand(-0.3, 0.3), tek_rand(-0.3, 0.3)};
    for (int k = 0; k < 3; k++) ctr[k] += 0.3 * eye[k] / d; /* billboard a little in front of the origin */
    double up[3] = {tek_rand(-0.3, 0.3), 1, tek_rand(-0.3, 0.3)};
    tek_camera(o, eye, ctr, up, tek_rand(3.5, 5), 32, 24);
    cJSON_AddNumberToObject(o, "epsilon", 0.01);
    return o;
}

/* ---------------------------------------------------------------- comparisons */

static double tek_max_abs(const double *v, int n)
{
    double m = 0;
    for (int k = 0; k < n; k++) m = fmax(m, fabs(v[k]));
    return m;
}

/* 1 when every value is finite; else 0 and *first = the first bad index. */
static int tek_finite_at(const float *v, int n, int *first)
{
    for (int k = 0; k < n; k++)
        if (!isfinite(v[k])) {
            if (first) *first = k;
            return 0;
        }
    return 1;
}

static int tek_finite(const float *v, int n) { return tek_finite_at(v, n, NULL); }

/* RMS of (dev - ref)/ref over texels with ref above 1% of the maximum. */
static double tek_rms_rel(const float *dev, const double *ref, int n, int *worst)
{
    double mx = tek_max_abs(ref, n), sum = 0, wr = -1;
    int cnt = 0;
    for (int k = 0; k < n; k++) {
        if (fabs(ref[k]) <= 0.01 * mx) continue;
        double r = (dev[k] - ref[k]) / ref[k];
        sum += r * r;
        cnt++;
        if (fabs(r) > wr) wr = fabs(r), *worst = k;
    }
    return cnt ? sqrt(sum / cnt) : 0;
}

static void tek_ref_image(const struct energy_ref_scene *sc, int simpson_n, double *out)
{
    for (int j = 0; j < sc->cam.height; j++)
        for (int i = 0; i < sc->cam.width; i++)
            out[j * sc->cam.width + i] = simpson_n > 0 ? energy_ref_texel_simpson(sc, i, j, simpson_n)
                                                       : energy_ref_texel_converged(sc, i, j);
}

/* ---------------------------------------------------------------- device helpers */

static void tek_abc_from_roots(const double r[3], float *abc)
{
    abc[0] = (float)-(r[0] + r[1] + r[2]);
    abc[1] = (float)(r[0] * r[1] + r[0] * r[2] + r[1] * r[2]);
    abc[2] = (float)(-r[0] * r[1] * r[2]);
}

/* n cubics: the digest §7 sets, then random ones (three separated real roots, or one real
 * root and a complex pair). */
static int tek_cubic_inputs(float *abc, int max)
{
    static const double sets[3][3] = {{0.2, 0.5, 0.9}, {-1, 0.3, 2}, {0.25, 0.25, 0.7}};
    int n = 0;
    for (int s = 0; s < 3; s++) tek_abc_from_roots(sets[s], abc + 3 * n++);
    abc[3 * n] = -2.4f, abc[3 * n + 1] = 5.8f, abc[3 * n + 2] = -2.0f, n++;
    tek_rng = 12345;
    while (n < max) {
        double r[3] = {tek_rand(-1, 2), tek_rand(-1, 2), tek_rand(-1, 2)};
        if (n % 2) { /* (x - r0)(x^2 - 2 re x + re^2 + im^2) */
            double re = tek_rand(-1, 2), im = tek_rand(0.3, 2), p = -2 * re, q = re * re + im * im;
            abc[3 * n] = (float)(p - r[0]), abc[3 * n + 1] = (float)(q - p * r[0]), abc[3 * n + 2] = (float)(-q * r[0]);
            n++;
            continue;
        }
        if (fabs(r[0] - r[1]) < 0.1 || fabs(r[0] - r[2]) < 0.1 || fabs(r[1] - r[2]) < 0.1) continue;
        tek_abc_from_roots(r, abc + 3 * n++);
    }
    return n;
}

static int tek_root_sets_match(const float *got, int ng, const double *want, int nw, double tol)
{
    for (int i = 0; i < ng; i++) {
        int hit = 0;
        for (int k = 0; k < nw; k++) hit |= fabs(got[i] - want[k]) <= tol;
        if (!hit) return 0;
    }
    for (int k = 0; k < nw; k++) {
        int hit = 0;
        for (int i = 0; i < ng; i++) hit |= fabs(got[i] - want[k]) <= tol;
        if (!hit) return 0;
    }
    return 1;
}

static void test_dev_cubic(void)
{
    enum { N = 600 };
    static float abc[3 * N], roots[3 * N];
    static int nroots[N];
    int n = tek_cubic_inputs(abc, N), bad = 0;
    struct fx_err err = {0};
    int rc = tek_dev_cubic(n, abc, roots, nroots, &err);
    CHECK(rc == 0, "tek_dev_cubic: %s", err.message);
    if (rc) return;
    for (int k = 0; k < n; k++) {
        double want[3];
        int nw = energy_ref_cubic(abc[3 * k], abc[3 * k + 1], abc[3 * k + 2], want);
        int ng = nroots[k], dbl = (k == 2);
        if (dbl) { /* float rounding splits the double root either way: compare with the exact set */
            static const double exact[3] = {0.25, 0.25, 0.7};
            memcpy(want, exact, sizeof want);
            nw = 3;
        }
        int ok = ng >= 1 && ng <= 3 && tek_root_sets_match(roots + 3 * k, ng, want, nw, dbl ? 3e-3 : 2e-4);
        ok = ok && (dbl || ng == nw);
        for (int i = 1; i < ng; i++) ok = ok && roots[3 * k + i - 1] <= roots[3 * k + i];
        for (int i = ng; i < 3 && ng >= 0; i++) ok = ok && roots[3 * k + i] == 0;
        if (!ok && bad++ < 8)
            CHECK(0, "cubic %d (a,b,c)=(%.9g,%.9g,%.9g): device %d roots [%.7g %.7g %.7g], reference %d [%.9g %.9g %.9g]",
                  k, abc[3 * k], abc[3 * k + 1], abc[3 * k + 2], ng, roots[3 * k], roots[3 * k + 1], roots[3 * k + 2],
                  nw, want[0], nw > 1 ? want[1] : 0, nw > 2 ? want[2] : 0);
    }
    CHECK(bad == 0, "%d of %d cubics wrong", bad, n);
}

static void test_dev_bspline(void)
{
    enum { NT = 203, NSETS = 7 };
    static const int nws[NSETS] = {3, 4, 5, 7, 9, 12, WAVE_MAX_W};
    float t[NT], out[NT];
    tek_rng = 777;
    for (int s = 0; s < NSETS; s++) {
        int nw = nws[s];
        double w[WAVE_MAX_W], U[WAVE_MAX_W + 3];
        for (int k = 0; k < nw; k++) w[k] = tek_rand(0, 1);
        if (s == 3) { /* the Fig 3.8 weights */
            static const double f38[7] = {1.0, 0.6, 0.2, 0.4, 0.8, 0.6, 1.0};
            for (int k = 0; k < 7; k++) w[k] = f38[k];
        }
        int m = energy_ref_knots(nw, U), nt = 0;
        for (int k = 0; k < m; k++) t[nt++] = (float)U[k]; /* every knot, t = 0 and t = 1 included */
        t[nt++] = 1.0f - 1e-7f;
        while (nt < NT) t[nt++] = (float)tek_rand(0, 1);
        struct fx_err err = {0};
        int rc = tek_dev_bspline(nw, w, NT, t, out, &err);
        CHECK(rc == 0, "tek_dev_bspline: %s", err.message);
        if (rc) return;
        int bad = 0;
        for (int k = 0; k < NT; k++) {
            double want = energy_ref_bspline(nw, w, t[k]);
            if (!(fabs(out[k] - want) <= 2e-6) && bad++ < 5)
                CHECK(0, "bspline nw=%d t=%.9g: device %.9g reference %.9g", nw, t[k], out[k], want);
        }
        CHECK(bad == 0, "nw=%d: %d B-spline values wrong", nw, bad);
    }
}

static double tek_dist_at(const double b[3][3], const double P[3], double t)
{
    double C[3];
    energy_ref_curve_eval(b, t, C);
    return sqrt((C[0] - P[0]) * (C[0] - P[0]) + (C[1] - P[1]) * (C[1] - P[1]) + (C[2] - P[2]) * (C[2] - P[2]));
}

/* Device nearest points for curve b at n points; checks distance against the reference
 * and that the returned t* really gives that distance. Returns the number of bad points. */
static int tek_nearest_check(const float bf[9], int n, const float *p, int report)
{
    static float dist[1024], tp[1024];
    struct fx_err err = {0};
    if (tek_dev_curve_nearest(bf, n, p, dist, tp, &err)) {
        CHECK(0, "tek_dev_curve_nearest: %s", err.message);
        return n;
    }
    double b[3][3], scale = 0;
    for (int k = 0; k < 9; k++) b[k / 3][k % 3] = bf[k], scale = fmax(scale, fabs(bf[k]));
    int bad = 0;
    for (int i = 0; i < n; i++) {
        double P[3] = {p[3 * i], p[3 * i + 1], p[3 * i + 2]}, tr, dr = energy_ref_curve_nearest(b, P, &tr);
        double tol = 2e-5 * (1 + scale + fabs(P[0]) + fabs(P[1]) + fabs(P[2]));
        double self = tek_dist_at(b, P, tp[i]);
        int ok = fabs(dist[i] - dr) <= tol && fabs(self - dr) <= tol && tp[i] >= 0 && tp[i] <= 1;
        if (!ok && bad++ < report)
            CHECK(0, "curve [%g %g %g | %g %g %g | %g %g %g] P=(%.7g,%.7g,%.7g): device d=%.7g t=%.7g (|C(t)-P|=%.7g), "
                     "reference d=%.9g t=%.9g",
                  bf[0], bf[1], bf[2], bf[3], bf[4], bf[5], bf[6], bf[7], bf[8], P[0], P[1], P[2], dist[i], tp[i],
                  self, dr, tr);
    }
    return bad;
}

static void test_dev_curve_nearest_vectors(void)
{
    static const float b[9] = {0, 0, 0, 1, 2, 0, 2, 0, 0}, s[9] = {0, 0, 0, 1, 0, 0, 2, 0, 0};
    static const float p[9] = {1, 0.5f, 0, 1, 3, 0, -1, -1, 0}, ps[3] = {0.7f, 1, 0};
    float d[3], t[3];
    struct fx_err err = {0};
    CHECK(tek_dev_curve_nearest(b, 3, p, d, t, &err) == 0, "%s", err.message);
    static const double L[3] = {0.5, 2.0, 1.4142135623730951}, T[3] = {0.5, 0.5, 0};
    for (int k = 0; k < 3; k++) {
        CHECK_NEAR(d[k], L[k], 1e-5);
        CHECK_NEAR(t[k], T[k], 1e-4);
    }
    CHECK(tek_dev_curve_nearest(s, 1, ps, d, t, &err) == 0, "%s", err.message);
    CHECK_NEAR(d[0], 1.0, 1e-5);
    CHECK_NEAR(t[0], 0.35, 1e-5);
}

static void test_dev_curve_nearest_random(void)
{
    enum { NP = 400 };
    static float p[3 * NP];
    tek_rng = 4242;
    int bad = 0;
    for (int c = 0; c < 24; c++) {
        float b[9];
        for (int k = 0; k < 9; k++) b[k] = (float)tek_rand(-2, 2);
        if (c == 22) b[3] = 0.5f * (b[0] + b[6]), b[4] = 0.5f * (b[1] + b[7]), b[5] = 0.5f * (b[2] + b[8]);
        if (c == 23) for (int k = 0; k < 3; k++) b[3 + k] = b[k] + 0.3f * (b[6 + k] - b[k]); /* straight, C2 != 0 */
        for (int k = 0; k < 3 * NP; k++) p[k] = (float)tek_rand(-3, 3);
        bad += tek_nearest_check(b, NP, p, 3);
    }
    CHECK(bad == 0, "%d of %d random nearest points wrong", bad, 24 * NP);
}

static void test_dev_anim_weights(void)
{
    for (double f = -5; f <= 100; f += 0.75) {
        double a[9], b[9];
        wave_anim_weights(f, 9, a);
        energy_ref_anim_weights(f, 9, b);
        for (int i = 0; i < 9; i++) CHECK(fabs(a[i] - b[i]) <= 1e-12, "frame %g w%d: %.12g vs %.12g", f, i, a[i], b[i]);
    }
    for (int n = 3; n <= 32; n += 5) /* the looping pulses (fmod + ages) against the reference's sum over starts */
        for (double f = -20; f <= 400; f += 1.25) {
            double a[32], b[32];
            wave_loop_weights(f, n, a);
            energy_ref_loop_weights(f, n, b);
            for (int i = 0; i < n; i++)
                CHECK(fabs(a[i] - b[i]) <= 1e-9, "n %d frame %g w%d: %.12g vs %.12g", n, f, i, a[i], b[i]);
        }
}

static int tek_cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* With the joined curves and their pulse (wave_scenes.h) no frame of two loops of the
 * longest curve carries less than half the median total energy (sum of B over a 64 x 32
 * texture): the pulse must not leave every weight near zero at once. Each frame is also lit
 * somewhere. */
static void test_loop_energy(void)
{
    cJSON *doc = tek_doc(wave_fig56_partial("{\"width\":64,\"height\":32}"));
    struct fx_err err = {0};
    struct energy_wave *ew = doc ? tek_new(doc, &err) : NULL;
    CHECK(ew != NULL, "energy_wave_new: %s", err.message);
    if (!ew) {
        cJSON_Delete(doc);
        return;
    }
    int longest = 3;
    const cJSON *c;
    cJSON_ArrayForEach(c, cJSON_GetObjectItemCaseSensitive(doc, "curves")) {
        int nw = cJSON_GetArraySize(cJSON_GetObjectItemCaseSensitive(c, "W"));
        if (nw > longest) longest = nw;
    }
    int frames = (int)(2 * wave_anim_period(longest));
    double rate = 0, *sum = calloc((size_t)frames, sizeof *sum);
    CHECK(params_number(doc, "anim_rate", &rate) == 0 && rate > 0, "anim_rate");
    static float tex[64 * 32];
    for (int f = 0; f < frames && !energy_wave_render(ew, f / rate, tex, &err); f++)
        for (int k = 0; k < 64 * 32; k++) sum[f] += tex[k];
    double *sorted = malloc(sizeof(double) * (size_t)frames);
    memcpy(sorted, sum, sizeof(double) * (size_t)frames);
    qsort(sorted, (size_t)frames, sizeof *sorted, tek_cmp);
    double median = sorted[frames / 2], least = sorted[0];
    int worst = 0;
    for (int f = 0; f < frames; f++) if (sum[f] == least) worst = f;
    printf("  info: %d frames: total B min %.4g (frame %d), median %.4g, max %.4g\n", frames, least, worst, median,
           sorted[frames - 1]);
    CHECK(median > 0 && least >= 0.5 * median, "frame %d carries %.3g of the median %.3g", worst, least, median);
    free(sorted);
    free(sum);
    energy_wave_free(ew);
    cJSON_Delete(doc);
}

/* ---------------------------------------------------------------- full renders */

static void test_render_simpson_random(void)
{
    static float dev[TEK_MAX_TEXELS];
    static double ref[TEK_MAX_TEXELS];
    for (int seed = 0; seed < 4; seed++) {
        cJSON *partial = tek_random_partial(seed, 1.0);
        tek_set_mode(partial, "simpson", seed % 2 ? 64 : 40);
        cJSON *doc = tek_doc(partial);
        struct energy_ref_scene sc;
        if (!doc || tek_scene(doc, 0, &sc) || tek_render(doc, 0, dev)) {
            cJSON_Delete(doc);
            return;
        }
        int n = sc.cam.width * sc.cam.height, worst = 0;
        tek_ref_image(&sc, sc.divisions, ref);
        double mx = tek_max_abs(ref, n), md = 0;
        for (int k = 0; k < n; k++)
            if (fabs(dev[k] - ref[k]) > md) md = fabs(dev[k] - ref[k]), worst = k;
        CHECK(tek_finite(dev, n) && md <= 1e-4 * mx,
              "seed %d n=%d: max |dev-ref| %.3g = %.3g of max %.5g at texel (%d,%d): dev %.7g ref %.7g", seed,
              sc.divisions, md, md / mx, mx, worst % sc.cam.width, worst / sc.cam.width, dev[worst], ref[worst]);
        cJSON_Delete(doc);
    }
}

static void test_render_modes_converged(void)
{
    static float dev[TEK_MAX_TEXELS];
    static double ref[4][TEK_MAX_TEXELS];
    int have[4] = {0};
    for (int m = 0; m < tek_nmodes; m++) {
        if (tek_is_simpson(tek_modes[m])) continue;
        for (int seed = 0; seed < 4; seed++) {
            cJSON *partial = tek_random_partial(seed, 1.0);
            tek_set_mode(partial, tek_modes[m], 0);
            cJSON *doc = tek_doc(partial);
            struct energy_ref_scene sc;
            if (!doc || tek_scene(doc, 0, &sc) || tek_render(doc, 0, dev)) {
                cJSON_Delete(doc);
                return;
            }
            int n = sc.cam.width * sc.cam.height, worst = 0;
            if (!have[seed]) tek_ref_image(&sc, 0, ref[seed]), have[seed] = 1;
            double rms = tek_rms_rel(dev, ref[seed], n, &worst);
            printf("  mode %s seed %d: RMS relative error %.4f%% (worst texel (%d,%d) dev %.6g ref %.6g)\n",
                   tek_modes[m], seed, 100 * rms, worst % sc.cam.width, worst / sc.cam.width, dev[worst], ref[seed][worst]);
            CHECK(tek_finite(dev, n) && rms <= 0.005, "mode %s seed %d: RMS relative error %.4g > 0.5%%", tek_modes[m],
                  seed, rms);
            cJSON_Delete(doc);
        }
    }
}

/* Torus seen along its axis, square image: invariant under 90-degree rotation and mirrors.
 * The second pose is off the origin with a tilted axis (checks the local frame). */
static cJSON *tek_torus_partial(const double c[3], const double ax[3], double R, int w, double dist, double back)
{
    cJSON *o = cJSON_CreateObject(), *tor = cJSON_AddArrayToObject(o, "tori");
    cJSON *t = cJSON_CreateObject();
    cJSON_AddItemToObject(t, "center", cJSON_CreateDoubleArray(c, 3));
    cJSON_AddItemToObject(t, "axis", cJSON_CreateDoubleArray(ax, 3));
    cJSON_AddNumberToObject(t, "R", R);
    cJSON_AddNumberToObject(t, "coef", 1.0);
    cJSON_AddItemToArray(tor, t);
    cJSON_AddArrayToObject(o, "points"), cJSON_AddArrayToObject(o, "lines"), cJSON_AddArrayToObject(o, "curves");
    double eye[3], ctr[3], up[3] = {ax[1] + 0.3, ax[2] - 0.2, ax[0] + 0.7};
    for (int k = 0; k < 3; k++) eye[k] = c[k] - (dist + back) * ax[k], ctr[k] = c[k] - dist * ax[k];
    tek_camera(o, eye, ctr, up, 4.0, w, w);
    cJSON_AddNumberToObject(o, "epsilon", 1e-3);
    return o;
}

static double tek_sym_err(const float *b, int w)
{
    double e = 0;
    for (int j = 0; j < w; j++)
        for (int i = 0; i < w; i++) {
            double v = b[j * w + i];
            e = fmax(e, fabs(v - b[i * w + (w - 1 - j)]));     /* rotation by 90 degrees */
            e = fmax(e, fabs(v - b[j * w + (w - 1 - i)]));     /* left-right mirror */
            e = fmax(e, fabs(v - b[(w - 1 - j) * w + i]));     /* top-bottom mirror */
            e = fmax(e, fabs(v - b[i * w + j]));               /* diagonal mirror */
        }
    return e;
}

static void test_torus_symmetry(void)
{
    static float dev[32 * 32];
    static const double c0[3] = {0, 0, 0}, a0[3] = {0, 0, 1}, c1[3] = {0.7, -0.4, 1.1}, a1[3] = {0.48, 0.6, 0.64};
    for (int m = 0; m < tek_nmodes; m++)
        for (int pose = 0; pose < 2; pose++) {
            cJSON *p = tek_torus_partial(pose ? c1 : c0, pose ? a1 : a0, 1.2, 32, 1.5, 5.0);
            tek_set_mode(p, tek_modes[m], tek_is_simpson(tek_modes[m]) ? 128 : 0);
            cJSON *doc = tek_doc(p);
            if (!doc || tek_render(doc, 0, dev)) {
                cJSON_Delete(doc);
                return;
            }
            double mx = 0;
            for (int k = 0; k < 32 * 32; k++) mx = fmax(mx, fabs(dev[k]));
            double e = tek_sym_err(dev, 32), tol = (tek_is_simpson(tek_modes[m]) ? 1e-4 : 1e-3) * mx;
            CHECK(e <= tol && mx > 0, "mode %s pose %d: symmetry error %.3g of max %.5g", tek_modes[m], pose, e / mx, mx);
            cJSON_Delete(doc);
        }
}

/* Digest §7 item 3: R=0.9, S=(0,0,-5), E=(0,0,5) -> 0.2301312261 (the centre texel of 33x33). */
static void test_torus_axis_texel(void)
{
    static float dev[33 * 33];
    static const double c[3] = {0, 0, 0}, a[3] = {0, 0, 1};
    for (int m = 0; m < tek_nmodes; m++) {
        cJSON *p = tek_torus_partial(c, a, 0.9, 33, 5.0, 10.0); /* S=(0,0,-5), V=(0,0,-15), E=(0,0,5) */
        tek_set_mode(p, tek_modes[m], tek_is_simpson(tek_modes[m]) ? 200 : 0);
        cJSON *doc = tek_doc(p);
        if (!doc || tek_render(doc, 0, dev)) {
            cJSON_Delete(doc);
            return;
        }
        double got = dev[16 * 33 + 16], rel = tek_is_simpson(tek_modes[m]) ? 1e-4 : 5e-3;
        CHECK(fabs(got - 0.2301312261) <= rel * 0.2301312261, "mode %s: axis texel %.9g, closed form 0.2301312261",
              tek_modes[m], got);
        cJSON_Delete(doc);
    }
}

/* Digest §7 item 5: straight Bezier, W == 1, rays perpendicular to it crossing its span:
 * B equals the line-kernel closed form. The centre column of a 33-wide image. */
static void test_straight_curve(void)
{
    static float dev[33 * 33];
    for (int m = 0; m < tek_nmodes; m++) {
        cJSON *o = cJSON_CreateObject(), *cur = cJSON_AddArrayToObject(o, "curves"), *cv = cJSON_CreateObject();
        double w[5] = {1, 1, 1, 1, 1};
        cJSON_AddItemToObject(cv, "p0", tek_vec(-2, 0, 0));
        cJSON_AddItemToObject(cv, "p1", tek_vec(-0.5, 0, 0)); /* collinear, non-uniform speed: C2 != 0 */
        cJSON_AddItemToObject(cv, "p2", tek_vec(2, 0, 0));
        cJSON_AddNumberToObject(cv, "coef", 1.0);
        cJSON_AddItemToObject(cv, "W", cJSON_CreateDoubleArray(w, 5));
        cJSON_AddItemToArray(cur, cv);
        cJSON_AddArrayToObject(o, "points"), cJSON_AddArrayToObject(o, "lines"), cJSON_AddArrayToObject(o, "tori");
        /* every ray passes the x axis at height >= 0.5, so Simpson n=200 is exact to ~1e-9 */
        static const double eye[3] = {0, 3.5, -10}, ctr[3] = {0, 3.5, -5}, up[3] = {0, 1, 0};
        tek_camera(o, eye, ctr, up, 3.0, 33, 33);
        cJSON_AddNumberToObject(o, "epsilon", 1e-3);
        tek_set_mode(o, tek_modes[m], tek_is_simpson(tek_modes[m]) ? 200 : 0);
        cJSON *doc = tek_doc(o);
        struct energy_ref_scene sc;
        if (!doc || tek_scene(doc, 0, &sc) || tek_render(doc, 0, dev)) {
            cJSON_Delete(doc);
            return;
        }
        double rel = tek_is_simpson(tek_modes[m]) ? 1e-4 : 5e-3, worst = 0;
        int wj = 0;
        for (int j = 0; j < 33; j++) {
            double S[3], E[3], q[3];
            static const double M[3] = {0, 0, 0}, D[3] = {1, 0, 0};
            energy_ref_texel_ray(&sc, 16, j, S, E);
            energy_ref_line_quad(M, D, S, E, q);
            double want = energy_ref_zeta_integral(q[0], q[1], q[2], 1, 1), r = fabs(dev[j * 33 + 16] - want) / want;
            if (r > worst) worst = r, wj = j;
        }
        CHECK(worst <= rel, "mode %s: centre column differs from the line closed form by %.3g (row %d, dev %.7g)",
              tek_modes[m], worst, wj, dev[wj * 33 + 16]);
        cJSON_Delete(doc);
    }
}

/* Linearity (scale all coefficients), superposition (two halves of the scene) and
 * monotonicity (grow one coefficient), digest §7 item 10. */
static cJSON *tek_subset(int seed, int half, double scale)
{
    cJSON *p = tek_random_partial(seed, scale);
    static const char *names[2][2] = {{"points", "lines"}, {"tori", "curves"}};
    if (half >= 0)
        for (int k = 0; k < 2; k++) cJSON_ReplaceItemInObject(p, names[1 - half][k], cJSON_CreateArray());
    return p;
}

static int tek_render_partial(cJSON *partial, const char *mode, float *out)
{
    tek_set_mode(partial, mode, tek_is_simpson(mode) ? 64 : 0);
    cJSON *doc = tek_doc(partial);
    int rc = doc ? tek_render(doc, 0, out) : -1;
    cJSON_Delete(doc);
    return rc;
}

static void test_linearity_superposition(void)
{
    static float all[32 * 24], dbl[32 * 24], h0[32 * 24], h1[32 * 24];
    const int n = 32 * 24, seed = 2;
    for (int m = 0; m < tek_nmodes; m++) {
        const char *mode = tek_modes[m];
        if (tek_render_partial(tek_subset(seed, -1, 1.0), mode, all) || tek_render_partial(tek_subset(seed, -1, 2.5), mode, dbl) ||
            tek_render_partial(tek_subset(seed, 0, 1.0), mode, h0) || tek_render_partial(tek_subset(seed, 1, 1.0), mode, h1))
            return;
        double mx = 0, es = 0, ep = 0;
        for (int k = 0; k < n; k++) mx = fmax(mx, fabs(all[k]));
        for (int k = 0; k < n; k++) {
            es = fmax(es, fabs(dbl[k] - 2.5 * all[k]) / 2.5);
            ep = fmax(ep, fabs(h0[k] + h1[k] - all[k]));
        }
        int simp = tek_is_simpson(mode);
        CHECK(es <= (simp ? 1e-5 : 1e-3) * mx, "mode %s: scaling coefficients by 2.5: error %.3g of max", mode, es / mx);
        CHECK(ep <= (simp ? 1e-5 : 1e-2) * mx, "mode %s: superposition error %.3g of max", mode, ep / mx);
    }
}

static void test_monotonicity(void)
{
    static float lo[32 * 24], hi[32 * 24];
    const int n = 32 * 24;
    for (int m = 0; m < tek_nmodes; m++) {
        const char *mode = tek_modes[m];
        cJSON *a = tek_random_partial(1, 1.0), *b = tek_random_partial(1, 1.0);
        cJSON *cv = cJSON_GetArrayItem(cJSON_GetObjectItem(b, "curves"), 0);
        cJSON_ReplaceItemInObject(cv, "coef", cJSON_CreateNumber(cJSON_GetObjectItem(cv, "coef")->valuedouble + 0.7));
        if (tek_render_partial(a, mode, lo) || tek_render_partial(b, mode, hi)) return;
        double mx = 0, worst = 0;
        for (int k = 0; k < n; k++) mx = fmax(mx, fabs(hi[k]));
        for (int k = 0; k < n; k++) worst = fmax(worst, lo[k] - hi[k]);
        CHECK(worst <= (tek_is_simpson(mode) ? 1e-6 : 1e-3) * mx, "mode %s: B decreased by %.3g of max", mode, worst / mx);
    }
}

/* Digest §7 item 11: rays through a point, along a line, through the torus circle and
 * through the curve stay finite and under sum|coef|/eps * alpha/beta^2. */
static void test_epsilon_no_nan(void)
{
    static float dev[33 * 33];
    for (int m = 0; m < tek_nmodes; m++) {
        cJSON *o = cJSON_CreateObject();
        cJSON *pts = cJSON_AddArrayToObject(o, "points"), *lns = cJSON_AddArrayToObject(o, "lines");
        cJSON *tor = cJSON_AddArrayToObject(o, "tori"), *cur = cJSON_AddArrayToObject(o, "curves");
        cJSON *p = cJSON_CreateObject(), *l = cJSON_CreateObject(), *t = cJSON_CreateObject(), *c = cJSON_CreateObject();
        cJSON_AddItemToObject(p, "pos", tek_vec(0, 0, 0)), cJSON_AddNumberToObject(p, "coef", 2);
        cJSON_AddItemToObject(l, "pos", tek_vec(0, 0, 0)), cJSON_AddItemToObject(l, "dir", tek_vec(0, 0, 1));
        cJSON_AddNumberToObject(l, "coef", 1);
        cJSON_AddItemToObject(t, "center", tek_vec(0, 0, 0.5)), cJSON_AddItemToObject(t, "axis", tek_vec(0, 0, 1));
        cJSON_AddNumberToObject(t, "R", 1.0), cJSON_AddNumberToObject(t, "coef", 3);
        double w[3] = {1, 1, 1};
        cJSON_AddItemToObject(c, "p0", tek_vec(-1, 0, 0)), cJSON_AddItemToObject(c, "p1", tek_vec(0, 0, 0));
        cJSON_AddItemToObject(c, "p2", tek_vec(1, 0, 0)), cJSON_AddNumberToObject(c, "coef", 1.5);
        cJSON_AddItemToObject(c, "W", cJSON_CreateDoubleArray(w, 3));
        cJSON_AddItemToArray(pts, p), cJSON_AddItemToArray(lns, l), cJSON_AddItemToArray(tor, t), cJSON_AddItemToArray(cur, c);
        static const double eye[3] = {0, 0, -4}, ctr[3] = {0, 0, -1}, up[3] = {0, 1, 0};
        tek_camera(o, eye, ctr, up, 2.0, 33, 33); /* centre texel's ray runs along the line */
        cJSON_AddNumberToObject(o, "epsilon", 1e-3);
        tek_set_mode(o, tek_modes[m], tek_is_simpson(tek_modes[m]) ? 64 : 0);
        cJSON *doc = tek_doc(o);
        if (!doc || tek_render(doc, 0, dev)) {
            cJSON_Delete(doc);
            return;
        }
        double bound = (2 + 1 + 3 + 1.5) / 1e-3 * 1.0001, lo = 0, hi = 0;
        int bad = -1, nbad = 0, fin = tek_finite_at(dev, 33 * 33, &bad);
        for (int k = 0; k < 33 * 33; k++) {
            nbad += !isfinite(dev[k]);
            if (isfinite(dev[k])) lo = fmin(lo, dev[k]), hi = fmax(hi, dev[k]);
        }
        CHECK(fin && lo >= 0 && hi <= bound, "mode %s: %d non-finite texels (first (%d,%d) = %g), finite range [%g, %g], bound %g",
              tek_modes[m], nbad, bad % 33, bad / 33, bad >= 0 ? dev[bad] : 0.0, lo, hi, bound);
        cJSON_Delete(doc);
    }
}

/* Point and line sources at, and close to, the eye V. With beta = 1 and nu = 2 the ray
 * parameter s = -beta is V itself, where closed forms in y = 1/(s + beta) degenerate. */
static cJSON *tek_near_eye_partial(double off, int line)
{
    cJSON *o = cJSON_CreateObject(), *pts = cJSON_AddArrayToObject(o, "points"), *lns = cJSON_AddArrayToObject(o, "lines");
    cJSON_AddArrayToObject(o, "tori"), cJSON_AddArrayToObject(o, "curves");
    cJSON *src = cJSON_CreateObject();
    cJSON_AddItemToObject(src, "pos", tek_vec(0.3, 0.2, -4 - off));
    if (line) cJSON_AddItemToObject(src, "dir", tek_vec(1, 0, 0.3));
    cJSON_AddNumberToObject(src, "coef", 1.0);
    cJSON_AddItemToArray(line ? lns : pts, src);
    static const double eye[3] = {0.3, 0.2, -4}, ctr[3] = {0, 0, -1}, up[3] = {0, 1, 0};
    tek_camera(o, eye, ctr, up, 2.0, 16, 16);
    cJSON_AddNumberToObject(o, "epsilon", 1e-3);
    return o;
}

static void test_sources_near_eye(void)
{
    static float dev[16 * 16];
    static double ref[16 * 16];
    static const double offs[3] = {0, 0.01, 0.1};
    for (int m = 0; m < tek_nmodes; m++)
        for (int c = 0; c < 6; c++) {
            int simp = tek_is_simpson(tek_modes[m]), line = c % 2, worst = 0, bad = -1;
            cJSON *p = tek_near_eye_partial(offs[c / 2], line);
            tek_set_mode(p, tek_modes[m], simp ? 64 : 0);
            cJSON *doc = tek_doc(p);
            struct energy_ref_scene sc;
            if (!doc || tek_scene(doc, 0, &sc) || tek_render(doc, 0, dev)) {
                cJSON_Delete(doc);
                return;
            }
            tek_ref_image(&sc, simp ? 64 : 0, ref);
            int fin = tek_finite_at(dev, 256, &bad);
            double err = simp ? 0 : tek_rms_rel(dev, ref, 256, &worst), mx = tek_max_abs(ref, 256);
            if (simp)
                for (int k = 0; k < 256; k++)
                    if (fabs(dev[k] - ref[k]) > err) err = fabs(dev[k] - ref[k]), worst = k;
            if (simp) err /= mx;
            CHECK(fin && err <= (simp ? 1e-4 : 0.005),
                  "mode %s, %s at distance %g from the eye: %s error %.3g (texel (%d,%d): dev %g, reference %g)%s",
                  tek_modes[m], line ? "line" : "point", offs[c / 2], simp ? "max/max" : "RMS relative", err,
                  (fin ? worst : bad) % 16, (fin ? worst : bad) / 16, dev[fin ? worst : bad], ref[fin ? worst : bad],
                  fin ? "" : " NON-FINITE");
            cJSON_Delete(doc);
        }
}

/* "animate": curve W scaled by eq. (5.1) at frame sim_time * anim_rate (digest §4). */
static void test_animation_render(void)
{
    static float dev[TEK_MAX_TEXELS];
    static double ref[TEK_MAX_TEXELS];
    cJSON *partial = tek_random_partial(0, 1.0); /* points and a curve, no line (see the Simpson test) */
    tek_set_mode(partial, "simpson", 48);
    cJSON_ReplaceItemInObject(partial, "animate", cJSON_CreateTrue());
    cJSON_AddNumberToObject(partial, "anim_rate", 20.0);
    cJSON *doc = tek_doc(partial);
    struct energy_ref_scene sc;
    if (!doc || tek_scene(doc, 1.6, &sc) || tek_render(doc, 1.6, dev)) { /* frame 32 */
        cJSON_Delete(doc);
        return;
    }
    int n = sc.cam.width * sc.cam.height;
    tek_ref_image(&sc, 48, ref);
    double mx = tek_max_abs(ref, n), md = 0;
    for (int k = 0; k < n; k++) md = fmax(md, fabs(dev[k] - ref[k]));
    CHECK(mx > 0 && md <= 1e-4 * mx, "animated render: max |dev-ref| %.3g of max %.5g", md / mx, mx);
    cJSON_Delete(doc);
}

/* A frame stepped by a new energy_wave effect with the given budget per call (slices.h). */
static int tek_sliced_frame(const cJSON *doc, double budget, struct slices_frame *out)
{
    struct fx_err err = {0};
    void *typed = effect_typed(&energy_wave_effect, doc, &err);
    void *ew = typed ? energy_wave_effect.create(tek_ocl, typed, &err) : NULL;
    free(typed);
    int rc = ew ? slices_step(&energy_wave_effect, ew, 0.7, budget, out, &err) : -1;
    CHECK(rc == 0, "step with %g s per call: %s", budget, err.message);
    if (ew) energy_wave_effect.destroy(ew);
    return rc;
}

/* Slices do not change the picture: a frame stepped a work-group per call, and a few
 * milliseconds per call, is the frame stepped whole, byte for byte (its EXR payload), raw Y and
 * colour-mapped RGBA, on a texture whose rows are no whole number of work-groups (of 8 or 16
 * texels a work-item). */
static void test_sliced_frames(void)
{
    static const char *const outputs[] = {"Y", "RGBA"};
    for (int o = 0; o < 2; o++) {
        char partial[128];
        snprintf(partial, sizeof partial, "{\"width\":300,\"height\":40,\"output\":\"%s\"}", outputs[o]);
        cJSON *doc = tek_doc(cJSON_Parse(partial));
        struct slices_frame whole = {.kind = FXS_KIND_TEXTURE}, piece = {.kind = FXS_KIND_TEXTURE},
                            ms = {.kind = FXS_KIND_TEXTURE};
        if (doc && !tek_sliced_frame(doc, INFINITY, &whole) && !tek_sliced_frame(doc, 0, &piece) &&
            !tek_sliced_frame(doc, 0.003, &ms)) {
            CHECK(whole.calls == 1 && piece.calls >= 40, "%s: %d calls whole, %d a group at a time", outputs[o],
                  whole.calls, piece.calls);
            CHECK(whole.payload && piece.len == whole.len && !memcmp(piece.payload, whole.payload, whole.len),
                  "%s: the frame in pieces of a group is the whole frame", outputs[o]);
            CHECK(ms.len == whole.len && !memcmp(ms.payload, whole.payload, whole.len),
                  "%s: the frame in 3 ms slices (%d) is the whole frame", outputs[o], ms.calls);
        }
        slices_free(&whole);
        slices_free(&piece);
        slices_free(&ms);
        cJSON_Delete(doc);
    }
}

static int tek_keep_texture(void *ctx, const struct effect_frame *f)
{
    if (f->kind == FXS_KIND_TEXTURE) *(struct effect_frame *)ctx = *f;
    return 0;
}

/* The frame a step emitted stays as it was while the next one is computed in slices (effect.h),
 * so the engine can still encode it for a subscriber of another encoding: its texels and its
 * EXR, after part of the next frame of a pulse running along the curves (a different picture). */
static void test_emitted_frame_kept(void)
{
    cJSON *doc = tek_doc(cJSON_Parse("{\"tori\":[],\"size\":20.4,\"curves\":[{\"p0\":[-13.2,-4.2,1.8],"
                                     "\"p1\":[-6.6,9.0,-1.8],\"p2\":[0,0,0],\"coef\":8.0}],\"animate\":true,"
                                     "\"width\":200,\"height\":40,\"output\":\"RGBA\"}"));
    struct fx_err err = {0};
    void *typed = doc ? effect_typed(&energy_wave_effect, doc, &err) : NULL;
    void *ew = typed ? energy_wave_effect.create(tek_ocl, typed, &err) : NULL;
    free(typed);
    struct effect_frame first = {0}, next = {0};
    const size_t bytes = (size_t)200 * 40 * 4 * sizeof(float);
    float *texels = malloc(bytes);
    int rc = ew ? energy_wave_effect.step(ew, 0.3, 1.0 / 30, INFINITY, tek_keep_texture, &first, &err) : -1;
    CHECK(rc == 0 && first.texels && first.channels == 4 && texels, "frame 1: %s", err.message);
    struct effect_frame exr = first;
    if (rc || !first.texels || !texels || effect_frame_encode(&exr, &err)) {
        CHECK(0, "frame 1's EXR: %s", err.message);
        goto out;
    }
    memcpy(texels, first.texels, bytes);
    uint8_t *payload = malloc(exr.payload_bytes);
    size_t len = exr.payload_bytes;
    if (payload) memcpy(payload, exr.payload, len);
    int calls = 0;
    while ((rc = energy_wave_effect.step(ew, 0.9, calls ? 0 : 0.6, 0, tek_keep_texture, &next, &err)) == EFFECT_MORE &&
           ++calls < 4) {}
    CHECK(rc == EFFECT_MORE && !next.texels, "frame 2 in progress after %d calls (rc %d)", calls, rc);
    CHECK(!memcmp(first.texels, texels, bytes), "frame 1's texels are as emitted while frame 2 runs");
    exr = first;
    exr.payload = NULL;
    CHECK(payload && !effect_frame_encode(&exr, &err) && exr.payload_bytes == len && !memcmp(exr.payload, payload, len),
          "frame 1's EXR made again while frame 2 runs is the same: %s", err.message);
    while (rc == EFFECT_MORE) rc = energy_wave_effect.step(ew, 0.9, 0, INFINITY, tek_keep_texture, &next, &err);
    CHECK(rc == 0 && next.texels && memcmp(next.texels, texels, bytes), "frame 2 completes, another picture: %s",
          err.message);
    free(payload);
out:
    free(texels);
    if (ew) energy_wave_effect.destroy(ew);
    cJSON_Delete(doc);
}

int main(void)
{
    struct fx_err err = {0};
    if (ocl_open(&tek_ocl, CHECK_DEVICE(), &err)) return CHECK_ABORT("ocl_open(%s): %s: %s", CHECK_DEVICE(), err.code, err.message);
    tek_defaults = params_defaults(energy_wave_params);
    if (!tek_defaults) return CHECK_ABORT("params_defaults(energy_wave_params) failed");
    tek_find_modes();
    printf("  modes:");
    for (int m = 0; m < tek_nmodes; m++) printf(" %s", tek_modes[m]);
    printf("\n");
    RUN(test_dev_cubic);
    RUN(test_dev_bspline);
    RUN(test_dev_curve_nearest_vectors);
    RUN(test_dev_curve_nearest_random);
    RUN(test_dev_anim_weights);
    RUN(test_loop_energy);
    RUN(test_render_simpson_random);
    RUN(test_render_modes_converged);
    RUN(test_torus_symmetry);
    RUN(test_torus_axis_texel);
    RUN(test_straight_curve);
    RUN(test_linearity_superposition);
    RUN(test_monotonicity);
    RUN(test_epsilon_no_nan);
    RUN(test_sources_near_eye);
    RUN(test_animation_render);
    RUN(test_sliced_frames);
    RUN(test_emitted_frame_kept);
    cJSON_Delete(tek_defaults);
    ocl_close(tek_ocl);
    return CHECK_DONE();
}
