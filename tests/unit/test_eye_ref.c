/* test_eye_ref.c — the digest §6 properties of the compound-eye model, checked on the
 * double-precision reference (tests/ref/eye_ref) and, where the server has its own
 * version (the UV frame of eye_model.c), on both: UV frame round trip and lift, cell
 * centre, Snell at entry and exit, the undeviated central ray, the paraxial magnifier
 * n/(2-n), D4 symmetry of the square lattice, pupil counts non-decreasing in r with the
 * side pupils on the lattice axes (4 square, 6 hex), distance scaling, and l = 3 close
 * to l = 10. Each check compares against an independent number, so each can fail. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../ref/eye_ref.h"
#include "check.h"
#include "effects/eye_model.h"

static unsigned long long ter_rng = 0x2545f4914f6cdd1dull;

static double ter_rand(double lo, double hi)
{
    ter_rng ^= ter_rng << 13;
    ter_rng ^= ter_rng >> 7;
    ter_rng ^= ter_rng << 17;
    return lo + (hi - lo) * ((ter_rng >> 11) * (1.0 / 9007199254740992.0));
}

static struct eye_ref_optics ter_optics(int hex, double r, int passes)
{
    struct eye_ref_optics o = {hex, r, 1.491, 2 * r, passes, 0, 0, 0};
    return o;
}

static double ter_dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static void ter_cross(const double a[3], const double b[3], double c[3])
{
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}

/* §6.1: P_c + T_k.u D_u + T_k.v D_v = P_k; the lift (5.26-27) inverts (5.2); the server's
 * frame (eye_uv_frame) equals the reference's. */
static void test_uv_frame_round_trip(void)
{
    for (int t = 0; t < 200; t++) {
        double P[3][3], T[3][2], Pc[3], Du[3], Dv[3], sPc[3], sDu[3], sDv[3];
        float Pf[9], Tf[6];
        for (int k = 0; k < 3; k++) {
            for (int c = 0; c < 3; c++) Pf[3 * k + c] = (float)(P[k][c] = ter_rand(-2, 2));
            for (int c = 0; c < 2; c++) Tf[2 * k + c] = (float)(T[k][c] = ter_rand(0, 1));
        }
        for (int k = 0; k < 3; k++) {
            for (int c = 0; c < 3; c++) P[k][c] = Pf[3 * k + c];
            for (int c = 0; c < 2; c++) T[k][c] = Tf[2 * k + c];
        }
        double det = (T[1][0] - T[0][0]) * (T[2][1] - T[0][1]) - (T[2][0] - T[0][0]) * (T[1][1] - T[0][1]);
        if (fabs(det) < 0.05) continue;
        eye_ref_uv_frame(P, T, Pc, Du, Dv);
        CHECK(eye_uv_frame(Pf, Tf, sPc, sDu, sDv) == 0, "server frame");
        for (int k = 0; k < 3; k++)
            for (int c = 0; c < 3; c++) {
                CHECK_NEAR(Pc[c] + T[k][0] * Du[c] + T[k][1] * Dv[c], P[k][c], 1e-9);
                CHECK_NEAR(sDu[c], Du[c], 1e-6 * (1 + fabs(Du[c])));
                CHECK_NEAR(sDv[c], Dv[c], 1e-6 * (1 + fabs(Dv[c])));
            }
        double a = ter_rand(-3, 3), b = ter_rand(-3, 3), Q[3], ra, rb;
        for (int c = 0; c < 3; c++) Q[c] = Pc[c] + a * Du[c] + b * Dv[c];
        eye_ref_lift(Pc, Du, Dv, Q, &ra, &rb);
        CHECK_NEAR(ra, a, 1e-9);
        CHECK_NEAR(rb, b, 1e-9);
    }
    float flat[6] = {0.1f, 0.1f, 0.2f, 0.2f, 0.3f, 0.3f}, pos[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    double x[3], y[3], z[3];
    CHECK(eye_uv_frame(pos, flat, x, y, z) == -1, "degenerate UVs are refused");
}

/* §6.3: floor(a)+1/2 equals the thesis's piecewise (5.17-5.20) off the integers. */
static void test_cell_centre(void)
{
    for (int i = 0; i < 1000; i++) {
        double a = ter_rand(-50, 50);
        if (a == floor(a)) continue;
        CHECK_NEAR(floor(a) + 0.5, eye_ref_cell_centre(a), 0.0);
    }
    double c[2];
    eye_ref_nearest(0, -0.3, 2.7, c);
    CHECK(c[0] == -0.5 && c[1] == 2.5, "square nearest (%g, %g)", c[0], c[1]);
}

/* §6.5: n1 sin(t1) = n2 sin(t2) at entry and exit, refracted ray coplanar with d and m. */
static void test_snell(void)
{
    struct eye_ref_optics o = ter_optics(0, 1.0, 10);
    int checked = 0, exits = 0;
    for (int i = 0; i < 500; i++) {
        double th = ter_rand(0, 1.3), ph = ter_rand(0, 6.3), d[3] = {sin(th) * cos(ph), sin(th) * sin(ph), -cos(th)};
        struct eye_ref_hit h;
        eye_ref_trace(&o, ter_rand(0, 1), ter_rand(0, 1), d, &h);
        if (!h.entered) continue;
        double x[3], s1, s2;
        checked++;
        CHECK_NEAR(sqrt(ter_dot(h.entry_normal, h.entry_normal)), 1.0, 1e-9);
        ter_cross(d, h.entry_normal, x);
        s1 = sqrt(ter_dot(x, x));
        ter_cross(h.r_in, h.entry_normal, x);
        s2 = sqrt(ter_dot(x, x));
        CHECK_NEAR(1.0 * s1, o.n * s2, 1e-9);
        ter_cross(d, h.entry_normal, x);
        CHECK_NEAR(ter_dot(x, h.r_in), 0.0, 1e-9);
        if (h.status != EYE_REF_LANDED || h.bounces) continue;
        exits++;
        double din[3]; /* the direction arriving at the exit: last segment inside = r_in (no bounce) */
        memcpy(din, h.r_in, sizeof din);
        ter_cross(din, h.exit_normal, x);
        s1 = sqrt(ter_dot(x, x));
        ter_cross(h.r_out, h.exit_normal, x);
        s2 = sqrt(ter_dot(x, x));
        CHECK_NEAR(o.n * s1, 1.0 * s2, 1e-9);
        ter_cross(din, h.exit_normal, x);
        CHECK_NEAR(ter_dot(x, h.r_out), 0.0, 1e-9);
    }
    CHECK(checked > 400 && exits > 200, "%d entries, %d exits checked", checked, exits);
    /* l = 0: a single sphere never gives TIR (exit angle = entry angle) */
    o = ter_optics(0, 1.0, 0);
    int tir = 0;
    for (int i = 0; i < 2000; i++) {
        double th = ter_rand(0, 1.45), ph = ter_rand(0, 6.3), d[3] = {sin(th) * cos(ph), sin(th) * sin(ph), -cos(th)};
        struct eye_ref_hit h;
        eye_ref_trace(&o, ter_rand(0, 1), ter_rand(0, 1), d, &h);
        tir += h.bounces > 0; /* policy reflect counts every TIR as a bounce */
    }
    CHECK(tir == 0, "%d TIR events with l = 0", tir);
}

/* §6.5: a ray through the sphere centre is undeviated; §6.6: paraxial magnifier. */
static void test_central_ray_and_magnifier(void)
{
    struct eye_ref_optics o = ter_optics(0, 1.0, 0);
    for (int i = 0; i < 20; i++) {
        double th = ter_rand(0, 0.5), ph = ter_rand(0, 6.3), d[3] = {sin(th) * cos(ph), sin(th) * sin(ph), -cos(th)};
        double t = o.r / -d[2], px = 0.5 - d[0] * t, py = 0.5 - d[1] * t;
        struct eye_ref_hit h;
        eye_ref_trace(&o, px, py, d, &h);
        double tl = o.plane / -d[2];
        CHECK(h.entered && h.status == EYE_REF_LANDED, "central ray lands");
        CHECK_NEAR(h.land[0], px + d[0] * tl, 1e-9);
        CHECK_NEAR(h.land[1], py + d[1] * tl, 1e-9);
    }
    double down[3] = {0, 0, -1};
    for (int k = 0; k < 3; k++) {
        double n = k == 0 ? 1.491 : k == 1 ? 1.3 : 1.7, hgt = 1e-3;
        o.n = n;
        struct eye_ref_hit h;
        eye_ref_trace(&o, 0.5 + hgt, 0.5, down, &h);
        CHECK_NEAR((h.land[0] - 0.5) / hgt, (2 - n) / n, 1e-4);
    }
}

/* §6.8: the lens-averaged darkness has D4 symmetry on the square lattice. */
static void test_square_d4_symmetry(void)
{
    struct eye_ref_optics o = ter_optics(0, 1.0, 10);
    for (int i = 0; i < 12; i++) {
        double tx = ter_rand(0, 1.5), ty = ter_rand(0, 1.5), l = sqrt(tx * tx + ty * ty + 1);
        double w[8][3] = {{tx, ty, 1}, {-tx, ty, 1}, {tx, -ty, 1}, {-tx, -ty, 1},
                          {ty, tx, 1}, {-ty, tx, 1}, {ty, -tx, 1}, {-ty, -tx, 1}};
        double v[8];
        for (int k = 0; k < 8; k++) {
            for (int c = 0; c < 3; c++) w[k][c] /= l;
            v[k] = eye_ref_lens_dark(&o, 0.2, w[k], 16);
        }
        for (int k = 1; k < 8; k++) CHECK_NEAR(v[k], v[0], 0.02);
    }
}

/* §6.9/6.10: pupils grow in number with r; the first ring sits on the lattice axes. */
static int ter_ring(const double *cx, const double *cy, int n, double *ang, int max)
{
    double rmin = INFINITY;
    for (int i = 0; i < n; i++) {
        double d = hypot(cx[i], cy[i]);
        if (d > 0.2 && d < rmin) rmin = d;
    }
    int k = 0;
    for (int i = 0; i < n && k < max; i++) {
        double d = hypot(cx[i], cy[i]);
        if (d > 0.2 && d < 1.2 * rmin) ang[k++] = atan2(cy[i], cx[i]) * 180 / M_PI;
    }
    return k;
}

static void ter_check_axes(const double *ang, int k, double step, const char *what)
{
    for (int i = 0; i < k; i++) {
        double off = fmod(fabs(ang[i]) + step / 2, step) - step / 2;
        CHECK(fabs(off) < 8, "%s side pupil %d at %.1f deg is off the lattice axes", what, i, ang[i]);
    }
}

static void test_pupils(void)
{
    const double rs[] = {0.6, 0.75, 1.0, 1.5, 2.0};
    double cx[64], cy[64], ang[16];
    int prev = 0;
    for (int i = 0; i < 5; i++) {
        struct eye_ref_optics o = ter_optics(0, rs[i], 10);
        int n = eye_ref_pupils(&o, 0.2, 3.0, 49, 8, cx, cy, 64);
        printf("  square r/s=%.2f: %d pupils\n", rs[i], n);
        CHECK(n >= prev, "pupil count %d at r/s = %g is below %d at the smaller radius", n, rs[i], prev);
        CHECK(n >= 1, "a central pupil at r/s = %g", rs[i]);
        prev = n;
        if (rs[i] == 1.0) {
            int k = ter_ring(cx, cy, n < 64 ? n : 64, ang, 16);
            CHECK(k == 4, "square lattice: %d first-ring side pupils (want 4)", k);
            ter_check_axes(ang, k, 90, "square");
        }
    }
    struct eye_ref_optics o = ter_optics(1, 1.0, 10);
    int n = eye_ref_pupils(&o, 0.2, 3.0, 49, 8, cx, cy, 64);
    int k = ter_ring(cx, cy, n < 64 ? n : 64, ang, 16);
    printf("  hex r/s=1.00: %d pupils, %d in the first ring\n", n, k);
    CHECK(k == 6, "hex lattice: %d first-ring side pupils (want 6)", k);
    ter_check_axes(ang, k, 60, "hex");
}

/* §6.11: seen from height D, the first side pupil sits at D*tan(theta_1) from the foot. */
static double ter_side_pupil_x(double D)
{
    struct eye_ref_optics o = ter_optics(0, 1.0, 10);
    double num = 0, den = 0;
    for (int i = 0; i < 120; i++) {
        double x = 0.4 * D + 1.6 * D * i / 119, l = sqrt(x * x + D * D), w[3] = {x / l, 0, D / l};
        double dk = eye_ref_lens_dark(&o, 0.2, w, 8);
        if (dk > 0.5) num += dk * x, den += dk;
    }
    return den > 0 ? num / den : 0;
}

static void test_distance_scaling(void)
{
    double far = ter_side_pupil_x(2.0), near = ter_side_pupil_x(1.0);
    CHECK(far > 0 && near > 0, "side pupil found (%g, %g)", far, near);
    CHECK_NEAR(near / far, 0.5, 0.02);
}

/* §6.12: l = 3 is close to l = 10 (RMS of lens-averaged darkness over view directions),
 * while l = 0 is clearly different. */
static void test_l_convergence(void)
{
    struct eye_ref_optics o3 = ter_optics(0, 1.0, 3), o10 = ter_optics(0, 1.0, 10), o0 = ter_optics(0, 1.0, 0);
    double e3 = 0, e0 = 0;
    int n = 0;
    for (int j = 0; j < 15; j++)
        for (int i = 0; i < 15; i++, n++) {
            double tx = -2 + 4 * i / 14.0, ty = -2 + 4 * j / 14.0, l = sqrt(tx * tx + ty * ty + 1);
            double w[3] = {tx / l, ty / l, 1 / l};
            double a = eye_ref_lens_dark(&o10, 0.2, w, 8), b = eye_ref_lens_dark(&o3, 0.2, w, 8);
            double c = eye_ref_lens_dark(&o0, 0.2, w, 8);
            e3 += (a - b) * (a - b);
            e0 += (a - c) * (a - c);
        }
    e3 = sqrt(e3 / n);
    e0 = sqrt(e0 / n);
    printf("  RMS vs l=10: l=3 %.4f, l=0 %.4f\n", e3, e0);
    CHECK(e3 < 0.05, "l = 3 differs from l = 10 by RMS %.3f", e3);
    CHECK(e0 > 2 * e3, "l = 0 (RMS %.3f) should differ more than l = 3 (%.3f)", e0, e3);
}

int main(void)
{
    RUN(test_uv_frame_round_trip);
    RUN(test_cell_centre);
    RUN(test_snell);
    RUN(test_central_ray_and_magnifier);
    RUN(test_square_d4_symmetry);
    RUN(test_pupils);
    RUN(test_distance_scaling);
    RUN(test_l_convergence);
    return CHECK_DONE();
}
