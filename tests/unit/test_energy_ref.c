/* test_energy_ref.c — checks the energy_wave C reference (tests/ref/energy_ref.c) against
 * the analytic properties and exact vectors of digest §7 (and §4 for eq. 5.1).
 *
 * The reference is the ground truth for the kernel tests, so it is tested on its own
 * first: closed forms, nearest point, cubic roots (including a regression showing the
 * thesis's literal Cardano is wrong), B-spline tables, Simpson order, linearity, the
 * epsilon bound, camera-distance scaling and the parameter-document reader. */
#include <complex.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../ref/energy_ref.h"
#include "check.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* ---------------------------------------------------------------- helpers */

static unsigned long long ter_rng = 0x2545F4914F6CDD1DULL;

static double ter_rand(double lo, double hi)
{
    ter_rng ^= ter_rng << 13;
    ter_rng ^= ter_rng >> 7;
    ter_rng ^= ter_rng << 17;
    return lo + (hi - lo) * ((ter_rng >> 11) * (1.0 / 9007199254740992.0));
}

static void ter_scene(struct energy_ref_scene *sc)
{
    memset(sc, 0, sizeof *sc);
    sc->epsilon = 1e-9;
    sc->alpha = 1;
    sc->beta = 1;
    sc->divisions = 200;
}

static void ter_point_scene(struct energy_ref_scene *sc, double x, double y, double z)
{
    ter_scene(sc);
    sc->npoints = 1;
    sc->points[0] = (struct energy_ref_point){{x, y, z}, 1.0};
}

static void ter_line_scene(struct energy_ref_scene *sc)
{
    ter_scene(sc);
    sc->nlines = 1;
    sc->lines[0] = (struct energy_ref_line){{0, 0, 0}, {0, 0, 1}, 1.0};
}

static int ter_rel(double got, double want, double rel)
{
    return fabs(got - want) <= rel * fabs(want);
}

#define CHECK_REL(got, want, rel) \
    CHECK(ter_rel((got), (want), (rel)), "%.12g vs %.12g (rel %.2g)", (double)(got), (double)(want), (double)(rel))

/* ---------------------------------------------------------------- items 1-3 */

static void test_abe_point_vectors(void)
{
    static const double M[3] = {0, 0, 0};
    static const struct { double S[3], E[3], plain, zeta; } v[3] = {
        {{-5, 1, 0}, {5, 1, 0}, 0.4624876683, 0.2207654147},
        {{-5, 1, 3}, {5, 1, 3}, 0.2477888730, 0.1215001171},
        {{0, 0.5, -4}, {0.3, 0.2, 6}, 0.6405081504, 0.3303187665},
    };
    double q[3];
    energy_ref_point_quad(M, v[0].S, v[0].E, q);
    CHECK_NEAR(q[0], 100, 1e-12);
    CHECK_NEAR(q[1], -50, 1e-12);
    CHECK_NEAR(q[2], 26, 1e-12);
    CHECK_NEAR(energy_ref_abe_integral(100, -50, 26), 0.2 * asinh(5), 1e-14);
    for (int k = 0; k < 3; k++) {
        energy_ref_point_quad(M, v[k].S, v[k].E, q);
        CHECK_NEAR(energy_ref_abe_integral(q[0], q[1], q[2]), v[k].plain, 1e-10);
        CHECK_NEAR(energy_ref_zeta_integral(q[0], q[1], q[2], 1, 1), v[k].zeta, 1e-10);
        struct energy_ref_scene sc;
        ter_point_scene(&sc, 0, 0, 0);
        CHECK_REL(energy_ref_ray_converged(&sc, v[k].S, v[k].E), v[k].zeta, 1e-9);
        sc.no_attenuation = 1;
        CHECK_REL(energy_ref_ray_converged(&sc, v[k].S, v[k].E), v[k].plain, 1e-9);
    }
}

static void test_abe_simpson_vectors(void)
{
    struct energy_ref_scene sc;
    ter_point_scene(&sc, 0, 0, 0);
    static const double S1[3] = {-5, 1, 0}, E1[3] = {5, 1, 0}, S3[3] = {0, 0.5, -4}, E3[3] = {0.3, 0.2, 6};
    CHECK_NEAR(energy_ref_ray_simpson(&sc, S1, E1, 64), 0.2207654130, 2e-10);
    CHECK_NEAR(energy_ref_ray_simpson(&sc, S1, E1, 200), 0.2207654147, 2e-10);
    double rel = (energy_ref_ray_simpson(&sc, S3, E3, 64) - 0.3303187665) / 0.3303187665;
    CHECK(fabs(fabs(rel) - 1.2e-5) < 0.15e-5, "Simpson n=64 relative error %.3g, digest 1.2e-5", rel);
}

static void test_line_vectors(void)
{
    static const double M[3] = {0, 0, 0}, D[3] = {0, 0, 1};
    static const double S[3][3] = {{-5, 1, 0}, {-5, 1, 3}, {0, 0.5, -4}}, E[3][3] = {{5, 1, 0}, {5, 1, 3}, {0.3, 0.2, 6}};
    static const double want[3][5] = {{100, -50, 26, 0.4624876683, 0.2207654147},
                                      {100, -50, 26, 0.4624876683, 0.2207654147},
                                      {0.18, -0.15, 0.25, 2.5457345484, 1.2189897426}};
    struct energy_ref_scene sc;
    ter_line_scene(&sc);
    for (int k = 0; k < 3; k++) {
        double q[3];
        energy_ref_line_quad(M, D, S[k], E[k], q);
        for (int c = 0; c < 3; c++) CHECK_NEAR(q[c], want[k][c], 1e-12);
        CHECK_NEAR(energy_ref_abe_integral(q[0], q[1], q[2]), want[k][3], 1e-10);
        CHECK_NEAR(energy_ref_zeta_integral(q[0], q[1], q[2], 1, 1), want[k][4], 1e-10);
        CHECK_REL(energy_ref_ray_converged(&sc, S[k], E[k]), want[k][4], 1e-9);
        /* the compact D, E, F really are V(t) = squared distance to the line */
        for (double t = 0; t <= 1.0; t += 0.25) {
            double P[3];
            for (int c = 0; c < 3; c++) P[c] = S[k][c] + t * (E[k][c] - S[k][c]);
            double d = energy_ref_line_dist(&sc.lines[0], P);
            CHECK_NEAR(d * d, q[0] * t * t + 2 * q[1] * t + q[2], 1e-12);
        }
    }
}

static void test_torus_axis_point_source(void)
{
    struct energy_ref_scene sc;
    ter_scene(&sc);
    sc.epsilon = 1e-3;
    sc.ntori = 1;
    sc.tori[0] = (struct energy_ref_torus){{0, 0, 0}, {0, 0, 1}, 0.9, 1.0};
    static const double S[3] = {0, 0, -5}, E[3] = {0, 0, 5}, M[3] = {0.9, 0, 0};
    double q[3];
    energy_ref_point_quad(M, S, E, q);
    double closed = energy_ref_zeta_integral(q[0], q[1], q[2], 1, 1);
    CHECK_NEAR(closed, 0.2301312261, 1e-10);
    CHECK_NEAR(energy_ref_ray_simpson(&sc, S, E, 200), closed, 1e-10);
    CHECK_REL(energy_ref_ray_converged(&sc, S, E), closed, 1e-9);
    const struct energy_ref_torus *t = &sc.tori[0];
    static const double O[3] = {0, 0, 0}, onc[3] = {0.9, 0, 0}, z[3] = {0, 0, 1.7};
    CHECK_NEAR(1 / fmax(1e-3, energy_ref_torus_dist(t, O)), 1 / 0.9, 1e-12);
    CHECK_NEAR(1 / fmax(1e-3, energy_ref_torus_dist(t, onc)), 1e3, 1e-9);
    CHECK_NEAR(1 / energy_ref_torus_dist(t, z), 1 / sqrt(0.81 + 1.7 * 1.7), 1e-12);
}

/* A posed torus: P_local = R^T (P - center); the same three pointwise values hold. */
static void test_torus_pose(void)
{
    double ax[3] = {1, 2, 2}, c[3] = {0.3, -1, 2}, perp[3] = {2, -1, 0}, n = sqrt(5.0);
    for (int k = 0; k < 3; k++) ax[k] /= 3, perp[k] /= n;
    struct energy_ref_torus t = {{c[0], c[1], c[2]}, {ax[0], ax[1], ax[2]}, 1.5, 1.0};
    double P0[3], P1[3], P2[3];
    for (int k = 0; k < 3; k++) {
        P0[k] = c[k];
        P1[k] = c[k] + 1.5 * perp[k];
        P2[k] = c[k] - 0.8 * ax[k];
    }
    CHECK_NEAR(energy_ref_torus_dist(&t, P0), 1.5, 1e-12);
    CHECK_NEAR(energy_ref_torus_dist(&t, P1), 0, 1e-7);
    CHECK_NEAR(energy_ref_torus_dist(&t, P2), sqrt(1.5 * 1.5 + 0.64), 1e-12);
}

/* ---------------------------------------------------------------- item 6 */

static void test_nearest_vectors(void)
{
    static const double b[3][3] = {{0, 0, 0}, {1, 2, 0}, {2, 0, 0}};
    static const double P[3][3] = {{1, 0.5, 0}, {1, 3, 0}, {-1, -1, 0}};
    static const double L[3] = {0.5, 2.0, 1.4142135623730951}, T[3] = {0.5, 0.5, 0};
    for (int k = 0; k < 3; k++) {
        double t, d = energy_ref_curve_nearest(b, P[k], &t);
        CHECK_NEAR(d, L[k], 1e-12);
        CHECK_NEAR(t, T[k], 1e-9);
    }
    static const double s[3][3] = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}}, Ps[3] = {0.7, 1, 0};
    double t, d = energy_ref_curve_nearest(s, Ps, &t);
    CHECK_NEAR(d, 1.0, 1e-12);
    CHECK_NEAR(t, 0.35, 1e-12);
}

static void test_nearest_random_vs_brute(void)
{
    int bad = 0;
    for (int it = 0; it < 150; it++) {
        double b[3][3], P[3], tb, tr;
        for (int k = 0; k < 3; k++) {
            for (int c = 0; c < 3; c++) b[k][c] = ter_rand(-2, 2);
            P[k] = ter_rand(-3, 3);
        }
        double db = energy_ref_curve_nearest_brute(b, P, 200000, &tb);
        double dr = energy_ref_curve_nearest(b, P, &tr);
        double C[3];
        energy_ref_curve_eval(b, tr, C);
        double self = sqrt((C[0] - P[0]) * (C[0] - P[0]) + (C[1] - P[1]) * (C[1] - P[1]) + (C[2] - P[2]) * (C[2] - P[2]));
        if (fabs(db - dr) > 1e-5 || fabs(self - dr) > 1e-12 || dr > db + 1e-12) {
            bad++;
            CHECK(0, "curve %d: solver %.12g (t %.9g) brute %.12g (t %.9g)", it, dr, tr, db, tb);
        }
    }
    CHECK(bad == 0, "%d of 150 random nearest points disagree with brute force", bad);
}

/* ---------------------------------------------------------------- item 7 */

static int ter_sets_match(const double *got, int ng, const double *want, int nw, double tol)
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

static void ter_abc(const double r[3], double abc[3])
{
    abc[0] = -(r[0] + r[1] + r[2]);
    abc[1] = r[0] * r[1] + r[0] * r[2] + r[1] * r[2];
    abc[2] = -r[0] * r[1] * r[2];
}

static void test_cubic_sets(void)
{
    static const double sets[3][3] = {{0.2, 0.5, 0.9}, {-1, 0.3, 2}, {0.25, 0.25, 0.7}};
    double abc[3], r[3];
    for (int s = 0; s < 3; s++) {
        ter_abc(sets[s], abc);
        int n = energy_ref_cubic(abc[0], abc[1], abc[2], r);
        CHECK(ter_sets_match(r, n, sets[s], 3, s == 2 ? 1e-7 : 1e-12), "set %d: got %d roots %.12g %.12g %.12g", s,
              n, r[0], n > 1 ? r[1] : 0, n > 2 ? r[2] : 0);
        for (int k = 1; k < n; k++) CHECK(r[k - 1] <= r[k], "set %d roots not ascending", s);
    }
    int n = energy_ref_cubic(-2.4, 5.8, -2.0, r);
    CHECK(n == 1, "one real root expected, got %d", n);
    CHECK_NEAR(r[0], 0.4, 1e-13);
    n = energy_ref_cubic(-1.5, 0.75, -0.125, r); /* triple root 0.5 */
    CHECK(n >= 1 && fabs(r[0] - 0.5) < 1e-5, "triple root: %d roots, first %.12g", n, r[0]);
}

static void test_cubic_random(void)
{
    int bad = 0;
    for (int it = 0; it < 2000; it++) {
        double want[3], abc[3], r[3];
        for (int k = 0; k < 3; k++) want[k] = ter_rand(-2, 3);
        double gap = fmin(fabs(want[0] - want[1]), fmin(fabs(want[0] - want[2]), fabs(want[1] - want[2])));
        if (gap < 1e-3) continue;
        ter_abc(want, abc);
        int n = energy_ref_cubic(abc[0], abc[1], abc[2], r);
        if (n != 3 || !ter_sets_match(r, n, want, 3, 1e-9)) bad++;
    }
    CHECK(bad == 0, "%d random three-root cubics wrong", bad);
}

/* The thesis's Cardano applied literally (§3.2.4): theta = arctan(q/r), no -a/3 shift,
 * roots = the sums u_i + v_j whose imaginary part is zero. */
static int ter_cardano_literal(double a, double b, double c, double out[9])
{
    double p = -a * a / 9 + b / 3, q = a * a * a / 27 - a * b / 6 + c / 2, r = p * p * p + q * q;
    double complex u, v;
    if (r > 0) {
        double s = -q + sqrt(r), t = -q - sqrt(r);
        u = s >= 0 ? cbrt(s) : -cbrt(-s);
        v = t >= 0 ? cbrt(t) : -cbrt(-t);
    } else {
        double complex z = -q + sqrt(-r) * I;
        double th = atan(q / r);
        u = cbrt(cabs(z)) * (cos(th / 3) + I * sin(th / 3));
        v = conj(u);
    }
    double complex w[3] = {1, cexp(2 * M_PI * I / 3), cexp(4 * M_PI * I / 3)};
    int n = 0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            double complex x = w[i] * u + w[j] * v;
            if (fabs(cimag(x)) < 1e-12) out[n++] = creal(x);
        }
    return n;
}

static void test_cubic_literal_thesis_fails(void)
{
    static const double truth[3] = {0.2, 0.5, 0.9}, printed[3] = {0.353, -0.349, -0.004};
    double abc[3], r[9];
    ter_abc(truth, abc);
    int n = ter_cardano_literal(abc[0], abc[1], abc[2], r);
    CHECK(n == 3, "literal variant kept %d sums", n);
    CHECK(ter_sets_match(r, n, printed, 3, 1e-3), "literal variant gave %.4g %.4g %.4g, digest {0.353,-0.349,-0.004}",
          r[0], n > 1 ? r[1] : 0, n > 2 ? r[2] : 0);
    CHECK(!ter_sets_match(r, n, truth, 3, 1e-2), "literal variant unexpectedly right");
}

/* ---------------------------------------------------------------- item 8 */

static void test_bspline_knots(void)
{
    double U[16];
    static const double u7[10] = {0, 0, 0, .2, .4, .6, .8, 1, 1, 1};
    CHECK(energy_ref_knots(7, U) == 10, "n=7 knot count");
    for (int k = 0; k < 10; k++) CHECK_NEAR(U[k], u7[k], 1e-15);
    CHECK(energy_ref_knots(3, U) == 6, "n=3 knot count");
    for (int k = 0; k < 6; k++) CHECK_NEAR(U[k], k < 3 ? 0 : 1, 0);
}

static void test_bspline_partition_and_ends(void)
{
    double maxerr = 0;
    for (int nw = 3; nw <= 12; nw++) {
        double w[12];
        for (int i = 0; i < nw; i++) w[i] = ter_rand(0, 1);
        for (int k = 0; k <= 1000; k++) {
            double t = k / 1000.0, sum = 0;
            for (int i = 0; i < nw; i++) sum += energy_ref_bspline_basis(nw, i, t);
            maxerr = fmax(maxerr, fabs(sum - 1));
            double s = energy_ref_bspline(nw, w, t), lo = 1, hi = 0;
            for (int i = 0; i < nw; i++) lo = fmin(lo, w[i]), hi = fmax(hi, w[i]);
            CHECK(s >= lo - 1e-14 && s <= hi + 1e-14, "convex hull n=%d t=%g: %g not in [%g,%g]", nw, t, s, lo, hi);
        }
        CHECK_NEAR(energy_ref_bspline(nw, w, 0), w[0], 1e-15);
        CHECK_NEAR(energy_ref_bspline(nw, w, 1), w[nw - 1], 1e-15);
    }
    CHECK(maxerr <= 1e-15, "partition of unity error %.3g", maxerr);
}

static void test_bspline_fig38(void)
{
    static const double W[7] = {1.0, 0.6, 0.2, 0.4, 0.8, 0.6, 1.0};
    static const double tab[11] = {1.0, 0.65, 0.40, 0.275, 0.30, 0.425, 0.60, 0.725, 0.70, 0.725, 1.0};
    for (int k = 0; k <= 10; k++) CHECK_NEAR(energy_ref_bspline(7, W, k / 10.0), tab[k], 1e-12);
    static const double knot[4] = {0.4, 0.3, 0.6, 0.7};
    for (int k = 0; k < 4; k++) CHECK_NEAR(energy_ref_bspline(7, W, 0.2 * (k + 1)), knot[k], 1e-12);
    CHECK_NEAR(energy_ref_bspline(7, W, 1.0 / 3), 0.26666666667, 1e-10);
    CHECK_NEAR(energy_ref_bspline(7, W, 0.84), 0.68, 1e-12);
    double mx = 0, tmx = 0;
    for (int k = 600; k <= 800; k++) {
        double s = energy_ref_bspline(7, W, k / 1000.0);
        if (s > mx) mx = s, tmx = k / 1000.0;
    }
    CHECK_NEAR(mx, 0.73333333, 1e-4);
    CHECK_NEAR(tmx, 0.733, 2e-3);
}

static void test_bspline_fig56(void)
{
    static const double W[7] = {1.0, 0.2, 0.6, 1.0, 0.5, 0.8, 1.0};
    static const double tab[11] = {1.0, .45, .40, .60, .80, .8875, .75, .60, .65, .8125, 1.0};
    for (int k = 0; k <= 10; k++) CHECK_NEAR(energy_ref_bspline(7, W, k / 10.0), tab[k], 1e-12);
    double mn = 2, tmn = 0;
    for (int k = 0; k <= 400; k++) {
        double s = energy_ref_bspline(7, W, k / 1000.0);
        if (s < mn) mn = s, tmn = k / 1000.0;
    }
    CHECK_NEAR(mn, 0.36, 1e-4);
    CHECK_NEAR(tmn, 0.16, 2e-3);
}

static void test_bspline_locality_c1(void)
{
    double U[10], w[7] = {0.3, 0.9, 0.1, 0.5, 0.7, 0.2, 0.8}, w2[7];
    energy_ref_knots(7, U);
    for (int i = 0; i < 7; i++) {
        memcpy(w2, w, sizeof w);
        w2[i] += 0.25;
        for (int k = 0; k <= 500; k++) {
            double t = k / 500.0, d = energy_ref_bspline(7, w2, t) - energy_ref_bspline(7, w, t);
            int inside = (t >= U[i] && t < U[i + 3]) || (t == 1 && i == 6);
            if (!inside) CHECK(fabs(d) < 1e-15, "w%d changed S at t=%g by %g", i, t, d);
        }
    }
    for (int k = 3; k <= 6; k++) { /* one-sided slopes agree at interior knots: C1 */
        double u = U[k], h = 1e-6, s = energy_ref_bspline(7, w, u);
        double left = (s - energy_ref_bspline(7, w, u - h)) / h, right = (energy_ref_bspline(7, w, u + h) - s) / h;
        CHECK_NEAR(left, right, 1e-4);
    }
}

/* ---------------------------------------------------------------- eq. 5.1 */

static void test_anim_weights(void)
{
    double w[7];
    static const double want[7] = {0.327, 0.891, 1, 1, 0.491, 0, 0};
    energy_ref_anim_weights(40, 7, w);
    for (int i = 0; i < 7; i++) CHECK_NEAR(w[i], want[i], 1e-3);
    energy_ref_anim_weights(0, 7, w);
    for (int i = 0; i < 7; i++) CHECK_NEAR(w[i], 0, 0);
    for (int i = 0; i < 7; i++) {
        energy_ref_anim_weights(7 * i + 25, 7, w);
        CHECK_NEAR(w[i], 1, 0);
        energy_ref_anim_weights(7 * i + 51, 7, w);
        CHECK_NEAR(w[i], 0, 0);
    }
    energy_ref_anim_weights(93, 7, w);
    for (int i = 0; i < 7; i++) CHECK_NEAR(w[i], 0, 0);
}

/* ---------------------------------------------------------------- item 9 */

static double ter_cube(double s, void *ctx)
{
    (void)ctx;
    return s * s * s;
}

/* Thesis (4.5)/(4.7) literally: samples k = 0..n-1, A[n-1] standing in for f(1). */
static double ter_simpson_literal(const struct energy_ref_scene *sc, const double S[3], const double E[3], int n)
{
    double A[1025], P[3];
    for (int k = 0; k < n; k++) {
        double s = (double)k / n;
        for (int c = 0; c < 3; c++) P[c] = S[c] + s * (E[c] - S[c]);
        A[k] = energy_ref_psi(sc, P) * energy_ref_zeta(sc, s);
    }
    double sum = A[0] + A[n - 1];
    for (int k = 1; k <= n / 2 - 1; k++) sum += 2 * A[2 * k];
    for (int k = 1; k <= n / 2; k++) sum += 4 * A[2 * k - 1];
    return sum / (3.0 * n);
}

static void test_simpson_order(void)
{
    for (int n = 2; n <= 12; n += 2) CHECK_NEAR(energy_ref_simpson(ter_cube, NULL, 0, 1, n), 0.25, 1e-15);
    struct energy_ref_scene sc;
    ter_point_scene(&sc, 0, 0, 0);
    static const double S[3] = {-5, 1, 0}, E[3] = {5, 1, 0};
    double q[3], err[3];
    energy_ref_point_quad(sc.points[0].pos, S, E, q);
    double exact = energy_ref_zeta_integral(q[0], q[1], q[2], 1, 1);
    for (int k = 0; k < 3; k++) err[k] = fabs(energy_ref_ray_simpson(&sc, S, E, 64 << k) - exact);
    CHECK(fabs(err[0] / err[1] - 16) < 1, "error ratio 64->128: %.3g", err[0] / err[1]);
    CHECK(fabs(err[1] / err[2] - 16) < 1, "error ratio 128->256: %.3g", err[1] / err[2]);
    CHECK_REL(err[0] / exact, 7.7e-9, 0.05);
    double l64 = fabs(ter_simpson_literal(&sc, S, E, 64) - exact), l128 = fabs(ter_simpson_literal(&sc, S, E, 128) - exact);
    CHECK(fabs(l64 / l128 - 4) < 0.5, "literal (4.5)/(4.7) ratio %.3g, expected ~4 (order 2)", l64 / l128);
    CHECK(l64 > 1000 * err[0], "literal variant error %.3g not far above Simpson %.3g", l64, err[0]);
}

/* ---------------------------------------------------------------- item 10 */

static void ter_mixed_scene(struct energy_ref_scene *sc)
{
    ter_scene(sc);
    sc->epsilon = 1e-2;
    sc->npoints = 1;
    sc->points[0] = (struct energy_ref_point){{0.2, 0.1, 0.3}, 1.3};
    sc->nlines = 1;
    sc->lines[0] = (struct energy_ref_line){{0.5, -0.2, 0}, {0.6, 0, 0.8}, 0.7};
    sc->ntori = 1;
    sc->tori[0] = (struct energy_ref_torus){{0, 0, 0.5}, {0, 0.6, 0.8}, 1.2, 2.0};
    sc->ncurves = 1;
    sc->curves[0] = (struct energy_ref_curve){{{-1, 0, 0}, {0, 1.5, 0.5}, {1, -0.5, 0}}, 1.5, 7,
                                              {1.0, 0.6, 0.2, 0.4, 0.8, 0.6, 1.0}};
}

static double ter_mixed_ray(const struct energy_ref_scene *sc, int converged)
{
    static const double S[3] = {-0.3, 0.4, -2}, E[3] = {0.1, 0.2, 4};
    return converged ? energy_ref_ray_converged(sc, S, E) : energy_ref_ray_simpson(sc, S, E, 100);
}

static void test_linearity(void)
{
    struct energy_ref_scene sc, one;
    ter_mixed_scene(&sc);
    for (int conv = 0; conv < 2; conv++) {
        double all = ter_mixed_ray(&sc, conv), sum = 0;
        for (int p = 0; p < 4; p++) {
            ter_mixed_scene(&one);
            one.npoints = p == 0, one.nlines = p == 1, one.ntori = p == 2, one.ncurves = p == 3;
            sum += ter_mixed_ray(&one, conv);
        }
        CHECK_REL(sum, all, conv ? 1e-8 : 1e-12);
        struct energy_ref_scene dbl = sc;
        dbl.points[0].coef *= 2, dbl.lines[0].coef *= 2, dbl.tori[0].coef *= 2, dbl.curves[0].coef *= 2;
        CHECK_REL(ter_mixed_ray(&dbl, conv), 2 * all, conv ? 1e-8 : 1e-12);
        struct energy_ref_scene more = sc;
        more.tori[0].coef += 0.5;
        CHECK(ter_mixed_ray(&more, conv) >= all, "B decreased when a coefficient grew");
    }
}

/* The ground truth itself: converged B agrees with a very fine Simpson sum (W == 1, so the
 * integrand has kinks but no jumps and Simpson converges at least as O(h^2)). */
static void test_converged_vs_fine_simpson(void)
{
    struct energy_ref_scene sc;
    ter_mixed_scene(&sc);
    for (int k = 0; k < 7; k++) sc.curves[0].w[k] = 1.0;
    static const double rays[4][2][3] = {
        {{-0.3, 0.4, -2}, {0.1, 0.2, 4}},
        {{-1.5, 0.3, -1}, {1.4, -0.2, 2}},
        {{0, 0.96, -1}, {0, 0.96, 2.2}},
        {{-0.9, 0.2, -3}, {0.7, 0.9, 3.5}},
    };
    for (int k = 0; k < 4; k++) {
        double c = energy_ref_ray_converged(&sc, rays[k][0], rays[k][1]);
        double f = energy_ref_ray_simpson(&sc, rays[k][0], rays[k][1], 100000);
        CHECK_REL(c, f, 1e-7);
    }
}

/* ---------------------------------------------------------------- item 11 */

static void test_epsilon_bound(void)
{
    struct energy_ref_scene sc;
    ter_mixed_scene(&sc);
    sc.epsilon = 1e-3;
    double bound = (1.3 + 0.7 + 2.0 + 1.5) / sc.epsilon * sc.alpha / (sc.beta * sc.beta);
    double rays[5][2][3] = {
        {{0.2, 0.1, -1}, {0.2, 0.1, 1.6}},       /* through the point (a Simpson node) */
        {{0.5, -0.2, 0}, {1.1, -0.2, 0.8}},      /* along the line */
        {{-0.5, -0.2, -0.4}, {1.7, -0.2, 2.6}},  /* through the line */
        {{0, 1.2 * 0.8, 0.5 - 1.2 * 0.6}, {0, 1.2 * 0.8, 3}}, /* through the torus circle */
        {{0, 0, -3}, {0, 0, 3}},                 /* along the torus... near its axis */
    };
    for (int k = 0; k < 5; k++) {
        double bs = energy_ref_ray_simpson(&sc, rays[k][0], rays[k][1], 64);
        double bc = energy_ref_ray_converged(&sc, rays[k][0], rays[k][1]);
        CHECK(isfinite(bs) && isfinite(bc) && bs <= bound && bc <= bound && bs >= 0 && bc >= 0,
              "ray %d: simpson %g converged %g bound %g", k, bs, bc, bound);
    }
    double b[3][3] = {{-1, 0, 0}, {0, 1.5, 0.5}, {1, -0.5, 0}}, P[3];
    energy_ref_curve_eval(b, 0.3, P);
    CHECK(isfinite(energy_ref_psi(&sc, P)) && energy_ref_psi(&sc, P) <= bound / sc.alpha, "psi on the curve");
}

/* ---------------------------------------------------------------- item 13 */

/* With zeta == 1, B * |E - S| is the physical line integral of psi over the segment:
 * a point source at distance h from the ray gives asinh(z1/h) - asinh(z0/h). */
static void test_camera_distance_scaling(void)
{
    struct energy_ref_scene sc;
    ter_point_scene(&sc, 0.4, 0, 0);
    sc.no_attenuation = 1;
    sc.cam = (struct energy_ref_camera){{0, 0, -6}, {0, 0, -1}, {0, 1, 0}, 2.0, 2.0, 33, 33};
    static const double nus[4] = {1.5, 2, 3, 5};
    for (int k = 0; k < 4; k++) {
        sc.cam.nu = nus[k];
        double S[3], E[3];
        energy_ref_texel_ray(&sc, 16, 16, S, E);
        double len = fabs(E[2] - S[2]), phys = asinh(E[2] / 0.4) - asinh(S[2] / 0.4);
        CHECK_REL(energy_ref_texel_converged(&sc, 16, 16) * len, phys, 1e-9);
        CHECK_REL(energy_ref_texel_simpson(&sc, 16, 16, 400) * len, phys, 1e-6);
    }
}

/* ---------------------------------------------------------------- camera, document */

static void test_camera_rays(void)
{
    struct energy_ref_scene sc;
    ter_scene(&sc);
    sc.cam = (struct energy_ref_camera){{0, 0, -8}, {0, 0, 0}, {0, 1, 0}, 4.0, 2.0, 32, 24};
    double S[3], E[3];
    energy_ref_texel_ray(&sc, 0, 0, S, E);
    /* f = +z, r = f x up = -x, u = +y: column 0 lies at +x (screen left), row 0 at +y */
    CHECK_NEAR(S[0], -(0.5 / 32 - 0.5) * 4, 1e-12);
    CHECK_NEAR(S[1], (0.5 - 0.5 / 24) * 4 * 24 / 32, 1e-12);
    CHECK_NEAR(S[2], 0, 1e-12);
    for (int k = 0; k < 3; k++) CHECK_NEAR(E[k], sc.cam.eye[k] + 2 * (S[k] - sc.cam.eye[k]), 1e-12);
    energy_ref_texel_ray(&sc, 31, 23, S, E);
    CHECK_NEAR(S[0], -(31.5 / 32 - 0.5) * 4, 1e-12);
    CHECK_NEAR(S[1], (0.5 - 23.5 / 24) * 3, 1e-12);
}

static void test_scene_from_json(void)
{
    const char *txt = "{\"points\":[{\"pos\":[1,2,3],\"coef\":2}],"
                      "\"lines\":[{\"pos\":[0,0,0],\"dir\":[0,0,2],\"coef\":0.5}],"
                      "\"tori\":[{\"center\":[0,1,0],\"axis\":[0,3,0],\"R\":0.9,\"coef\":5.1}],"
                      "\"curves\":[{\"p0\":[0,0,0],\"p1\":[1,2,0],\"p2\":[2,0,0],\"coef\":8,"
                      "\"W\":[1,1,1,1,1,1,1]}],\"epsilon\":0.01,\"alpha\":1,\"beta\":1,\"divisions\":64,"
                      "\"eye\":[0,0,-5],\"center\":[0,0,0],\"up\":[0,1,0],\"size\":3,\"width\":32,"
                      "\"height\":24,\"nu\":2,\"animate\":true,\"anim_rate\":20}";
    cJSON *doc = cJSON_Parse(txt);
    struct energy_ref_scene sc;
    char msg[128];
    CHECK(energy_ref_scene_from_json(doc, 2.0, &sc, msg, sizeof msg) == 0, "parse: %s", msg);
    CHECK(sc.npoints == 1 && sc.nlines == 1 && sc.ntori == 1 && sc.ncurves == 1, "counts");
    CHECK_NEAR(sc.points[0].pos[2], 3, 0);
    CHECK_NEAR(sc.lines[0].dir[2], 1, 1e-15);
    CHECK_NEAR(sc.tori[0].axis[1], 1, 1e-15);
    CHECK_NEAR(sc.tori[0].R, 0.9, 0);
    CHECK(sc.divisions == 64 && sc.cam.width == 32 && sc.cam.height == 24, "ints");
    static const double want[7] = {0.327, 0.891, 1, 1, 0.491, 0, 0}; /* frame 2 s * 20/s = 40 */
    for (int i = 0; i < 7; i++) CHECK_NEAR(sc.curves[0].w[i], want[i], 1e-3);
    cJSON_Delete(doc);
}

int main(void)
{
    RUN(test_abe_point_vectors);
    RUN(test_abe_simpson_vectors);
    RUN(test_line_vectors);
    RUN(test_torus_axis_point_source);
    RUN(test_torus_pose);
    RUN(test_nearest_vectors);
    RUN(test_nearest_random_vs_brute);
    RUN(test_cubic_sets);
    RUN(test_cubic_random);
    RUN(test_cubic_literal_thesis_fails);
    RUN(test_bspline_knots);
    RUN(test_bspline_partition_and_ends);
    RUN(test_bspline_fig38);
    RUN(test_bspline_fig56);
    RUN(test_bspline_locality_c1);
    RUN(test_anim_weights);
    RUN(test_simpson_order);
    RUN(test_linearity);
    RUN(test_converged_vs_fine_simpson);
    RUN(test_epsilon_bound);
    RUN(test_camera_distance_scaling);
    RUN(test_camera_rays);
    RUN(test_scene_from_json);
    return CHECK_DONE();
}
