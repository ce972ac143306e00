/* energy_wave.cl — OpenCL kernels of effect energy_wave (seed 000, Watanabe 2016).
 *
 * Each work item renders EW_LANES adjacent texels of one row as vector lanes (float16 where
 * the device's native float vector is 16 wide, AVX-512; else float8): the code is written
 * branch-free on vectors (select instead of if), so PoCL on a CPU emits AVX code for it,
 * and GPUs run it just as well. Per texel (column i, row j from
 * the top) it computes B = ∫₀¹ ψ(L(s)) ζ(s) ds along L(s) = S + s(E − S),
 * ζ(s) = α/(s+β)², ψ = the sum of point / line / torus / Bézier kernels (digest §2).
 *   ew_render_simpson   the thesis's method: composite Simpson, n+1 samples, fused
 *                       into one kernel (no A array).
 *   ew_render_adaptive  ψ is a sum, so each primitive is integrated on its own:
 *                       closed forms for points and lines (digest §2.6); for tori and
 *                       curves the ray's closest approach s* (two for a split ray) is
 *                       found directly (circle search + Newton, or the nearest-point
 *                       cubic of the curve projected along the ray), and [0,1] is
 *                       integrated with s = s* + w·sinh(u) (w = peak half-width) and
 *                       Gauss–Legendre in u, where the 1/distance peak is smooth (10
 *                       nodes a curve's span, 6 either side of a torus's peak). Where
 *                       S(t*) jumps (the curve's medial set) the span is split at the
 *                       jump, found by bisection.
 * The unit tests reach the device functions through test-only kernels compiled after this
 * file (tests/ref/energy_wave_probe.cl); the daemon's program has none.
 * The buffer layouts (record strides, camera block) come from energy_wave_layout.h, which the
 * build prepends and server/effects/energy_wave.c includes. */

#define EW_BIG 1e30f /* "none yet" (finite: the build may assume finite math) */

/* Gauss–Legendre rules on [0,1], measured RMS error against the converged reference
 * (bench_energy_accuracy; the bound is 0.5%): curves take 10 points per span (Bézier
 * scenes 0.15-0.32%; 12 points: 0.11-0.15% at 1.2x the time), tori 6 on each side of the
 * peak (Fig. 5.1's torus 0.18%; 5 a side: 0.35%; 12 across the peak: 0.32%, 10: 0.57%).
 * Points and lines use the closed form and these only near the eye. The two pieces of a
 * span redone at a jump take 8 points. */
#define EW_GL10_N 10
__constant float ew_gl10_x[10] = {0.013046736f, 0.067468317f, 0.160295216f, 0.283302303f, 0.425562831f,
                                  0.574437169f, 0.716697697f, 0.839704784f, 0.932531683f, 0.986953264f};
__constant float ew_gl10_w[10] = {0.033335672f, 0.074725675f, 0.109543181f, 0.134633360f, 0.147762112f,
                                  0.147762112f, 0.134633360f, 0.109543181f, 0.074725675f, 0.033335672f};
#define EW_GL6_N 6
__constant float ew_gl6_x[6] = {0.033765243f, 0.169395307f, 0.380690407f, 0.619309593f, 0.830604693f, 0.966234757f};
__constant float ew_gl6_w[6] = {0.085662246f, 0.180380787f, 0.233956967f, 0.233956967f, 0.180380787f, 0.085662246f};
#define EW_GL8_N 8
__constant float ew_gl8_x[8] = {0.019855072f, 0.101666761f, 0.237233795f, 0.408282679f,
                                0.591717321f, 0.762766205f, 0.898333239f, 0.980144928f};
__constant float ew_gl8_w[8] = {0.050614268f, 0.111190517f, 0.156853323f, 0.181341892f,
                                0.181341892f, 0.156853323f, 0.111190517f, 0.050614268f};

#ifndef EW_LANES
#define EW_LANES EW_LANES_NARROW
#endif
#if EW_LANES == EW_LANES_WIDE
typedef float16 fv;
typedef int16 iv;
#define EW_CONVERT_F convert_float16
#define EW_CONVERT_I convert_int16
#define EW_VSTORE vstore16
#define EW_AS_F as_float16
#define EW_AS_I as_int16
#define EW_LANE_IDS (iv)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15)
#define EW_GATHER(b, i)                                                                                        \
    (fv)(b[i.s0], b[i.s1], b[i.s2], b[i.s3], b[i.s4], b[i.s5], b[i.s6], b[i.s7], b[i.s8], b[i.s9], b[i.sa],    \
         b[i.sb], b[i.sc], b[i.sd], b[i.se], b[i.sf])
#else
typedef float8 fv;
typedef int8 iv;
#define EW_CONVERT_F convert_float8
#define EW_CONVERT_I convert_int8
#define EW_VSTORE vstore8
#define EW_LANE_IDS (iv)(0, 1, 2, 3, 4, 5, 6, 7)
#define EW_GATHER(b, i) (fv)(b[i.s0], b[i.s1], b[i.s2], b[i.s3], b[i.s4], b[i.s5], b[i.s6], b[i.s7])
#define EW_AS_F as_float8
#define EW_AS_I as_int8
#endif
typedef struct {
    fv x, y, z;
} v3;

/* any() and all() of a lane mask as an OR / AND tree: PoCL lowers the built-ins lane by lane,
 * a test and a branch for every pair of lanes. */
static int ew_any(iv m)
{
#if EW_LANES == EW_LANES_WIDE
    int8 m8 = m.lo | m.hi;
#else
    int8 m8 = m;
#endif
    int4 m4 = m8.lo | m8.hi;
    int2 m2 = m4.lo | m4.hi;
    return (m2.x | m2.y) < 0;
}
static int ew_all(iv m)
{
#if EW_LANES == EW_LANES_WIDE
    int8 m8 = m.lo & m.hi;
#else
    int8 m8 = m;
#endif
    int4 m4 = m8.lo & m8.hi;
    int2 m2 = m4.lo & m4.hi;
    return (m2.x & m2.y) < 0;
}

typedef struct {
    __global const float *pts, *lns, *tor, *cur, *spl;
    int np, nl, nt, nc;
    float alpha, beta, eps;
} ew_scene;

/* ---- 3-vectors of lanes ------------------------------------------------------------ */

static v3 v3_make(fv x, fv y, fv z)
{
    v3 r = {x, y, z};
    return r;
}
static v3 v3_load(__global const float *p) { return v3_make((fv)(p[0]), (fv)(p[1]), (fv)(p[2])); }
static v3 v3_add(v3 a, v3 b) { return v3_make(a.x + b.x, a.y + b.y, a.z + b.z); }
static v3 v3_sub(v3 a, v3 b) { return v3_make(a.x - b.x, a.y - b.y, a.z - b.z); }
static v3 v3_mul(v3 a, fv k) { return v3_make(a.x * k, a.y * k, a.z * k); }
static fv v3_dot(v3 a, v3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
static v3 v3_cross(v3 a, v3 b)
{
    return v3_make(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}
/* a + k·b */
static v3 v3_mad(v3 a, fv k, v3 b) { return v3_make(mad(k, b.x, a.x), mad(k, b.y, a.y), mad(k, b.z, a.z)); }
/* The component of a normal to the unit vector n. */
static v3 v3_perp(v3 a, v3 n) { return v3_mad(a, -v3_dot(a, n), n); }

static fv ew_zeta(const ew_scene *sc, fv s)
{
    fv d = s + sc->beta;
    return sc->alpha / (d * d);
}

/* ---- cubic solver (digest §2.2 recommended solver) ------------------------------- */

/* 1/∛x for x > 0 by a bit-level first guess (3.5% off) and three Newton steps
 * y ← y(4 − x·y³)/3 (error squared each): no division, no transcendental call. */
static fv ew_rcbrt(fv x)
{
    fv y = EW_AS_F(0x54a23280 - EW_CONVERT_I(EW_CONVERT_F(EW_AS_I(x)) * (1.0f / 3.0f)));
    for (int k = 0; k < 3; k++) y *= (4.0f - x * (y * y * y)) * (1.0f / 3.0f);
    return y;
}

/* Real roots of x³ + a x² + b x + c = 0, ascending in r0 ≤ r1 ≤ r2; returns the lanes
 * with three real roots (elsewhere r0 = r1 = r2 is the single real root).
 * digest 000 §8 #5/#6/#7: the thesis's Cardano uses θ = arctan(q/r), omits the −a/3
 * shift and picks roots by "imag == 0"; here, with the −a/3 shift: one real root by
 * Cardano's ∛(−q ∓ √r) (the larger in size, v = −p/u); three (the double root r ≈ 0
 * included) as the largest, y = 2√(−p) cos(φ/3) with cos φ = −q/√(−p)³, found as the root
 * z = y/√(−p) ∈ [1, 2] of z³ − 3z = 2 cos φ by Newton from a fit exact at both ends, and
 * the other two from the quadratic left after dividing it out. One Newton step per root on
 * the cubic itself finishes them. No trigonometric call. */
static inline __attribute__((always_inline)) iv ew_cubic(fv a, fv b, fv c, fv *r0, fv *r1, fv *r2)
{
    fv p = b / 3.0f - a * a / 9.0f;
    fv q = a * a * a / 27.0f - a * b / 6.0f + c / 2.0f;
    fv disc = p * p * p + q * q, shift = -a / 3.0f;
    iv three = (p < 0.0f) & (disc <= 1e-5f * q * q);
    int any3 = ew_any(three);
    fv x[3];
    x[0] = x[1] = x[2] = shift;
    if (!ew_all(three)) {
        fv d = fmax(disc, 0.0f), v = -q - copysign(d * rsqrt(fmax(d, 1e-30f)), q), av = fabs(v);
        fv y = copysign(ew_rcbrt(av), v); /* 1/u for u = ∛v = v·y² */
        fv one = select(v * y * y - p * y, (fv)(0.0f), av == 0.0f) + shift;
        x[0] = x[1] = x[2] = one;
    }
    if (any3) {
        fv m = sqrt(fmax(-p, 0.0f)), X1 = 1.0f + clamp(-q / fmax(m * m * m, 1e-30f), -1.0f, 1.0f);
        fv z = 1.0f + sqrt(X1 * (2.0f / 3.0f)) - 0.0773503f * X1; /* 1 at cos φ = −1, 2 at 1 */
        for (int k = 0; k < 2; k++) {
            fv fp = 3.0f * (z * z - 1.0f);
            z = select(z, z - (z * (z * z - 3.0f) - 2.0f * (X1 - 1.0f)) / fp, fp > 1e-6f);
        }
        fv big = m * z + shift, h = -0.5f * (a + big), g = sqrt(fmax(h * h - (b + big * (a + big)), 0.0f));
        x[0] = select(x[0], h - g, three);
        x[1] = select(x[1], h + g, three);
        x[2] = select(x[2], big, three);
    }
    for (int k = 0; k < (any3 ? 3 : 1); k++) { /* lanes with one root: x[0] = x[1] = x[2] */
        fv f = ((x[k] + a) * x[k] + b) * x[k] + c, fp = (3.0f * x[k] + 2.0f * a) * x[k] + b;
        x[k] = select(x[k] - f / fp, x[k], fp == 0.0f);
    }
    if (!any3) {
        *r0 = *r1 = *r2 = x[0];
        return three;
    }
    fv lo = fmin(x[0], x[1]), hi = fmax(x[0], x[1]);
    *r0 = fmin(lo, x[2]);
    *r2 = fmax(hi, x[2]);
    *r1 = fmax(lo, fmin(hi, x[2]));
    return three;
}

/* ---- B-spline strength S(t) (digest §2.3) ----------------------------------------- */

static fv ew_gather(__global const float *base, iv idx)
{
    return EW_GATHER(base, idx);
}

/* S(t) = Σ w_i N_i²(t) from the host's quadratic of the span holding t (energy_wave_layout.h).
 * digest 000 §8 #10: the last span is closed at t = 1 (half-open spans give S(1) = 0, a dark
 * end cap). Up to 16 spans the coefficients are chosen by selects, beyond by gathers, which
 * PoCL's AVX-512 code runs at several times the cost of an arithmetic instruction (a 512²
 * frame of Fig. 5.6's curves: 4–10% faster by selects with 7 to 18 weights, 4–9% slower with
 * 24 and 32). */
#define EW_SELECT_SPANS 16
static fv ew_bspline(__global const float *spl, int spans, fv t)
{
    fv f = t * (float)spans;
    iv k = clamp(EW_CONVERT_I(f), 0, spans - 1);
    fv x = f - EW_CONVERT_F(k), c0, c1, c2;
    if (spans > EW_SELECT_SPANS) {
        k *= 3;
        c0 = ew_gather(spl, k);
        c1 = ew_gather(spl + 1, k);
        c2 = ew_gather(spl + 2, k);
    } else {
        c0 = spl[0];
        c1 = spl[1];
        c2 = spl[2];
        for (int s = 1; s < spans; s++) {
            iv m = k >= s;
            c0 = select(c0, (fv)(spl[3 * s]), m);
            c1 = select(c1, (fv)(spl[3 * s + 1]), m);
            c2 = select(c2, (fv)(spl[3 * s + 2]), m);
        }
    }
    return mad(x, mad(x, c2, c1), c0);
}

/* ---- kernels of the primitives (digest §2.2) ------------------------------------- */

static fv ew_point_k(__global const float *pt, v3 P, float eps)
{
    v3 v = v3_sub(P, v3_load(pt));
    return pt[3] / fmax(eps, sqrt(v3_dot(v, v)));
}

static fv ew_line_k(__global const float *ln, v3 P, float eps)
{
    v3 v = v3_sub(P, v3_load(ln));
    /* Distance through the perpendicular vector v − (v·D)D, not sqrt(|v|² − (v·D)²):
     * the difference of squares cancels in float near the line (1e-3 relative at d≈0.02). */
    v3 perp = v3_perp(v, v3_load(ln + 4));
    return ln[3] / fmax(eps, sqrt(v3_dot(perp, perp)));
}

/* P in the torus frame: P_local = Rᵀ(P − centre), axis = local z.
 * digest 000 §8 #20: the thesis fixes the torus at the origin; this is the pose. */
static v3 ew_torus_local(__global const float *to, v3 P)
{
    v3 v = v3_sub(P, v3_load(to));
    return v3_make(v3_dot(v, v3_load(to + 4)), v3_dot(v, v3_load(to + 8)), v3_dot(v, v3_load(to + 12)));
}

/* (3.6)/(3.7): coef / max(ε, distance to the centre circle of radius R). */
static fv ew_torus_k(__global const float *to, v3 P, float eps)
{
    v3 l = ew_torus_local(to, P);
    fv dr = sqrt(l.x * l.x + l.y * l.y) - to[3];
    return to[7] / fmax(eps, sqrt(dr * dr + l.z * l.z));
}

static v3 ew_curve_at(__global const float *cv, fv t)
{
    return v3_mad(v3_mad(v3_load(cv), t, v3_load(cv + 4)), t * t, v3_load(cv + 8));
}

/* Nearest point of C(t) = C₂t² + C₁t + C₀, t in [0,1], to P: squared distance, and t* in *t.
 * digest 000 §8 #4: thesis eq. 3.12 lacks −2C₂·P in the t coefficient (and flips the
 * sign); the cubic is 2|C₂|²t³ + 3(C₁·C₂)t² + (2C₂·(C₀−P) + |C₁|²)t + C₁·(C₀−P) = 0,
 * normalised by 2|C₂|² (§8 #6), with the straight case C₂ ≈ 0 solved linearly. */
static fv ew_curve_nearest_sq(__global const float *cv, v3 P, fv *t)
{
    v3 D = v3_sub(v3_load(cv), P), C1 = v3_load(cv + 4), C2 = v3_load(cv + 8);
    float c2sq = cv[7], c12 = cv[11], c1sq = cv[12];
    fv c1d = v3_dot(C1, D), r0, r1, r2;
    iv three = 0;
    if (c2sq <= 1e-6f * c1sq) {
        r0 = r1 = r2 = clamp(-c1d / fmax(c1sq, 1e-30f), 0.0f, 1.0f);
    } else {
        float inv = 0.5f / c2sq;
        three = ew_cubic((fv)(3.0f * c12 * inv), (2.0f * v3_dot(C2, D) + c1sq) * inv, c1d * inv, &r0, &r1, &r2);
    }
    /* candidates: both ends and the roots clamped to [0,1] (r1, r2 repeat r0 unless three) */
    fv cand[5] = {0.0f, 1.0f, clamp(r0, 0.0f, 1.0f), clamp(r1, 0.0f, 1.0f), clamp(r2, 0.0f, 1.0f)};
    int ncand = ew_any(three) ? 5 : 3;
    /* C(t) − P = (C₀ − P) + t(C₁ + tC₂): relative to P, so no cancellation far from 0 */
    v3 v = v3_mad(D, cand[0], v3_mad(C1, cand[0], C2));
    fv best = v3_dot(v, v), bt = cand[0];
    for (int k = 1; k < ncand; k++) {
        v = v3_mad(D, cand[k], v3_mad(C1, cand[k], C2));
        fv d2 = v3_dot(v, v);
        iv better = d2 < best;
        best = select(best, d2, better);
        bt = select(bt, cand[k], better);
    }
    *t = bt;
    return best;
}

static __global const float *ew_curve_spline(const ew_scene *sc, __global const float *cv)
{
    return sc->spl + (cv - sc->cur) / EW_CV_STRIDE * EW_SPL_ROW;
}

/* (3.27): coef · S(t*) / max(ε, L(P, curve)), with t* in *t and S(t*) in *str. Inlined, as is
 * the cubic: a call costs PoCL's code a spill of every live vector register around it. */
static inline __attribute__((always_inline)) fv ew_curve_kt(const ew_scene *sc, __global const float *cv, v3 P, fv *t,
                                                            fv *str)
{
    fv d2 = ew_curve_nearest_sq(cv, P, t);
    *str = ew_bspline(ew_curve_spline(sc, cv), (int)cv[13], *t);
    return cv[3] * *str * fmin(1.0f / sc->eps, rsqrt(d2));
}

static fv ew_curve_k(const ew_scene *sc, __global const float *cv, v3 P)
{
    fv t, str;
    return ew_curve_kt(sc, cv, P, &t, &str);
}

/* (3.28): ψ(P), the sum over every source. */
static fv ew_psi(const ew_scene *sc, v3 P)
{
    fv psi = 0.0f;
    for (int i = 0; i < sc->np; i++) psi += ew_point_k(sc->pts + i * EW_PT_STRIDE, P, sc->eps);
    for (int i = 0; i < sc->nl; i++) psi += ew_line_k(sc->lns + i * EW_LN_STRIDE, P, sc->eps);
    for (int i = 0; i < sc->nt; i++) psi += ew_torus_k(sc->tor + i * EW_TO_STRIDE, P, sc->eps);
    for (int i = 0; i < sc->nc; i++) psi += ew_curve_k(sc, sc->cur + i * EW_CV_STRIDE, P);
    return psi;
}

/* ---- camera and output -------------------------------------------------------------- */

static ew_scene ew_scene_make(__constant const float *cam, __global const float *pts, int np,
                              __global const float *lns, int nl, __global const float *tor, int nt,
                              __global const float *cur, int nc, __global const float *spl)
{
    ew_scene sc = {pts, lns, tor, cur, spl, np, nl, nt, nc, cam[EW_CAM_ALPHA], cam[EW_CAM_BETA], cam[EW_CAM_EPS]};
    return sc;
}

/* The work item's 8 texels (i0 … i0+7, j) → ray starts S and Q = E − S, with
 * E = V + ν(S − V). digest 000 §8 #14/#17: translation-invariant E, pixel centres. */
static void ew_texel_rays(__constant const float *cam, int i0, int j, int width, int height, v3 *S, v3 *Q)
{
    fv i = EW_CONVERT_F(min((iv)(i0) + EW_LANE_IDS, width - 1));
    fv x = (i + 0.5f) / (float)width - 0.5f;
    fv y = (fv)(0.5f - ((float)j + 0.5f) / (float)height);
    v3 V = v3_make((fv)(cam[EW_CAM_EYE]), (fv)(cam[EW_CAM_EYE + 1]), (fv)(cam[EW_CAM_EYE + 2]));
    v3 C = v3_make((fv)(cam[EW_CAM_CENTER]), (fv)(cam[EW_CAM_CENTER + 1]), (fv)(cam[EW_CAM_CENTER + 2]));
    v3 R = v3_make((fv)(cam[EW_CAM_RIGHT]), (fv)(cam[EW_CAM_RIGHT + 1]), (fv)(cam[EW_CAM_RIGHT + 2]));
    v3 U = v3_make((fv)(cam[EW_CAM_UP]), (fv)(cam[EW_CAM_UP + 1]), (fv)(cam[EW_CAM_UP + 2]));
    *S = v3_mad(v3_mad(C, x, R), y, U);
    *Q = v3_mul(v3_sub(*S, V), (fv)(cam[EW_CAM_NU] - 1.0f));
}

static void ew_store(__global float *out, fv B, int i0, int j, int width)
{
    __global float *row = out + j * width;
    if (i0 + EW_LANES <= width) {
        EW_VSTORE(B, 0, row + i0);
        return;
    }
    float b[EW_LANES];
    EW_VSTORE(B, 0, b);
    for (int k = 0; i0 + k < width; k++) row[i0 + k] = b[k];
}

/* ---- Simpson (thesis §3.5.3, §4) --------------------------------------------------- */

/* digest 000 §8 #16: the thesis samples k = 0…d−1 and reuses A^{d−1} as f(1); here
 * n+1 samples k = 0…n with weights 1,4,2,…,4,1. */
__kernel void ew_render_simpson(__global float *out, __constant const float *cam, __global const float *pts,
                                int np, __global const float *lns, int nl, __global const float *tor, int nt,
                                __global const float *cur, int nc, __global const float *spl, int width,
                                int height, int divisions)
{
    int i0 = get_global_id(0) * EW_LANES, j = get_global_id(1);
    if (i0 >= width || j >= height) return;
    ew_scene sc = ew_scene_make(cam, pts, np, lns, nl, tor, nt, cur, nc, spl);
    v3 S, Q;
    ew_texel_rays(cam, i0, j, width, height, &S, &Q);
    float inv_n = 1.0f / (float)divisions;
    fv acc = 0.0f;
    for (int k = 0; k <= divisions; k++) {
        float s = (float)k * inv_n;
        float wk = (k == 0 || k == divisions) ? 1.0f : ((k & 1) ? 4.0f : 2.0f);
        acc += wk * ew_psi(&sc, v3_mad(S, (fv)(s), Q)) * ew_zeta(&sc, (fv)(s));
    }
    ew_store(out, acc * (inv_n / 3.0f), i0, j, width);
}

/* ---- closed forms for points and lines (digest §2.6) ------------------------------ */

/* asinh(z1/k) − asinh(z0/k) for k = √k2; where z0, z1 share a sign it is a log ratio,
 * exact even when k → 0 (a ray through the source). */
static fv ew_asinh_diff(fv z0, fv z1, fv k2)
{
    fv a0 = fabs(z0), a1 = fabs(z1);
    fv l = log((a1 + sqrt(a1 * a1 + k2)) / (a0 + sqrt(a0 * a0 + k2)));
    fv k = sqrt(fmax(k2, 1e-30f));
    return select(asinh(z1 / k) - asinh(z0 / k), select(-l, l, z1 > 0.0f), z0 * z1 > 0.0f);
}

/* ∫_{s0}^{s1} α ds / ((s+β)² √(As² + 2Bs + C)), k2 = AC − B² (computed as a cross
 * product by the caller). With y = 1/(s+β), a' = U(−β), b' = B − Aβ it is
 * α[G(y0) − G(y1)], G(y) = √(a'y²+2b'y+A)/a' − b'a'^{−3/2} asinh((a'y+b')/√k2).
 * digest 000 §8 #2: the thesis's (2.8) lacks the square root in the asinh argument. */
static fv ew_quad_piece(const ew_scene *sc, fv A, fv B, fv C, fv k2, fv s0, fv s1)
{
    float be = sc->beta;
    fv ap = (A * be - 2.0f * B) * be + C, bp = B - A * be;
    fv y0 = 1.0f / (s0 + be), y1 = 1.0f / (s1 + be);
    fv u0 = fmax((A * s0 + 2.0f * B) * s0 + C, 0.0f), u1 = fmax((A * s1 + 2.0f * B) * s1 + C, 0.0f);
    fv t1 = (y0 * sqrt(u0) - y1 * sqrt(u1)) / ap;
    fv t2 = bp / (ap * sqrt(ap)) * ew_asinh_diff(ap * y1 + bp, ap * y0 + bp, k2);
    return select((fv)(0.0f), sc->alpha * (t1 - t2), s1 > s0);
}

/* ∫₀¹ ζ(s) / max(ε, √(As² + 2Bs + C)) ds: inside the ε-ball (h² < ε²) the kernel is
 * 1/ε; elsewhere the core [lo, hi] is empty and the two pieces meet at s*. Lanes where
 * a' = U(−β) is small (the ray passes the source just behind the texel, e.g. a source
 * at the eye) lose the closed form to cancellation: they are flagged in *unstable. */
static fv ew_quad_int(const ew_scene *sc, fv A, fv B, fv C, fv k2, iv *unstable)
{
    float e2 = sc->eps * sc->eps, be = sc->beta;
    *unstable = (A * be - 2.0f * B) * be + C <= 1e-2f * A * be * be;
    fv sstar = -B / A, delta = sqrt(fmax((e2 - k2 / A) / A, 0.0f));
    fv lo = clamp(sstar - delta, 0.0f, 1.0f), hi = clamp(sstar + delta, 0.0f, 1.0f);
    fv core = sc->alpha / sc->eps * (1.0f / (lo + sc->beta) - 1.0f / (hi + sc->beta));
    return ew_quad_piece(sc, A, B, C, k2, (fv)(0.0f), lo) + core + ew_quad_piece(sc, A, B, C, k2, hi, (fv)(1.0f));
}

/* The peak of a point or line source along the ray: s* and half-width h/√A. */
static fv ew_quad_peak(const ew_scene *sc, fv A, fv B, fv C, fv *w)
{
    fv s = clamp(-B / A, 0.0f, 1.0f);
    *w = fmax(sqrt(fmax((A * s + 2.0f * B) * s + C, 0.0f)), sc->eps) * rsqrt(A);
    return s;
}

static fv ew_span(const ew_scene *sc, int kind, __global const float *prim, v3 S, v3 Q, fv c, fv w, fv a, fv b);

static fv ew_point_int(const ew_scene *sc, __global const float *pt, v3 S, v3 Q)
{
    v3 v = v3_sub(S, v3_load(pt)), x = v3_cross(Q, v);
    fv A = v3_dot(Q, Q), B = v3_dot(Q, v), C = v3_dot(v, v), w;
    iv unstable;
    fv closed = pt[3] * ew_quad_int(sc, A, B, C, v3_dot(x, x), &unstable);
    if (!ew_any(unstable)) return closed;
    fv s = ew_quad_peak(sc, A, B, C, &w);
    return select(closed, ew_span(sc, 2, pt, S, Q, s, w, (fv)(0.0f), (fv)(1.0f)), unstable);
}

/* The line kernel is the point kernel in the plane normal to the line (2.14)–(2.16). */
static fv ew_line_int(const ew_scene *sc, __global const float *ln, v3 S, v3 Q)
{
    v3 D = v3_load(ln + 4);
    v3 qp = v3_perp(Q, D), vp = v3_perp(v3_sub(S, v3_load(ln)), D), x = v3_cross(qp, vp);
    fv A = v3_dot(qp, qp), B = v3_dot(qp, vp), C = v3_dot(vp, vp), w;
    iv parallel = A <= 1e-10f * v3_dot(Q, Q), unstable; /* parallel: constant distance */
    fv flat = sc->alpha * (1.0f / sc->beta - 1.0f / (1.0f + sc->beta)) / fmax(sc->eps, sqrt(C));
    fv A1 = select(A, (fv)(1.0f), parallel);
    fv closed = ln[3] * select(ew_quad_int(sc, A1, B, C, v3_dot(x, x), &unstable), flat, parallel);
    unstable &= ~parallel;
    if (!ew_any(unstable)) return closed;
    fv s = ew_quad_peak(sc, A1, B, C, &w);
    return select(closed, ew_span(sc, 3, ln, S, Q, s, w, (fv)(0.0f), (fv)(1.0f)), unstable);
}

/* ---- peak-adapted quadrature for tori and curves ---------------------------------- */

/* Up to two closest approaches per lane, s0 <= s1 (s1 = s0 where there is one). */
typedef struct {
    fv s0, w0, s1, w1;
    iv two;
} ew_peaks;

/* kind 1: curve, 2: point, 3: line (t*: the nearest curve parameter, str: S(t*); both 0
 * for the others). Tori have their own span (ew_torus_span). */
static fv ew_prim_k(const ew_scene *sc, int kind, __global const float *prim, v3 P, fv *t, fv *str)
{
    *t = *str = 0.0f;
    switch (kind) {
    case 1: return ew_curve_kt(sc, prim, P, t, str);
    case 2: return ew_point_k(prim, P, sc->eps);
    default: return ew_line_k(prim, P, sc->eps);
    }
}

/* Between two nodes, t* moving by more than EW_JUMP_T while S(t*) changes by more than
 * EW_JUMP_S is taken as a crossing of the curve's medial set, where S(t*) jumps
 * (digest §2.3 note); a false alarm only costs time. */
#define EW_JUMP_T 0.15f
#define EW_JUMP_S 0.02f
#define EW_JUMP_BISECT 6

/* The node s = c + w·sinh(u) at u = ua + du·x, and 2 cosh(u) in *jac (ds/du = w·jac/2). */
static fv ew_sinh_node(fv c, fv w, fv ua, fv du, float x, fv *jac)
{
    fv e = exp(mad(du, x, ua)), ie = 1.0f / e;
    *jac = e + ie;
    return c + w * 0.5f * (e - ie);
}

/* Where S(t*) jumps between two nodes: the lanes, the bracket [a, b] and t* at its ends. */
typedef struct {
    iv jumped;
    fv a, b, ta, tb;
} ew_jump;

/* ∫_a^b ψ_prim ζ ds with s = c + w·sinh(u) (c: a peak of half-width w, usually inside
 * [a, b]): in u the 1/distance peak is smooth, so one Gauss–Legendre rule covers it.
 * The first jump of S(t*) between two nodes of each lane goes to *jp (kept in registers
 * during the loop: through the pointer it was stored and loaded at every node). */
static fv ew_span_nodes(const ew_scene *sc, int kind, __global const float *prim, v3 S, v3 Q, fv c, fv w, fv a, fv b,
                        int n, __constant const float *gx, __constant const float *gw, ew_jump *jp)
{
    fv ua = asinh((a - c) / w), du = asinh((b - c) / w) - ua, acc = 0.0f;
    fv t, str, tprev = 0.0f, strprev = 0.0f, sprev = a;
    ew_jump j = {0, 0.0f, 0.0f, 0.0f, 0.0f};
    for (int k = 0; k < n; k++) {
        fv jac, s = ew_sinh_node(c, w, ua, du, gx[k], &jac);
        acc += gw[k] * jac * ew_prim_k(sc, kind, prim, v3_mad(S, s, Q), &t, &str) * ew_zeta(sc, s);
        iv jump = (k > 0 ? (iv)(-1) : (iv)(0)) & ~j.jumped & (fabs(t - tprev) > EW_JUMP_T) &
                  (fabs(str - strprev) > EW_JUMP_S);
        j.a = select(j.a, sprev, jump);
        j.b = select(j.b, s, jump);
        j.ta = select(j.ta, tprev, jump);
        j.tb = select(j.tb, t, jump);
        j.jumped |= jump;
        tprev = t;
        strprev = str;
        sprev = s;
    }
    *jp = j;
    return acc * 0.5f * du * w;
}

static fv ew_span_plain(const ew_scene *sc, int kind, __global const float *prim, v3 S, v3 Q, fv c, fv w, fv a, fv b)
{
    ew_jump j;
    return ew_span_nodes(sc, kind, prim, S, Q, c, w, a, b, EW_GL8_N, ew_gl8_x, ew_gl8_w, &j);
}

/* Bisects [a, b] (t* there: ta, tb) for the jump of t*. */
static fv ew_jump_locate(const ew_scene *sc, __global const float *cv, v3 S, v3 Q, fv a, fv b, fv ta, fv tb)
{
    fv str;
    for (int it = 0; it < EW_JUMP_BISECT; it++) {
        fv m = 0.5f * (a + b), tm;
        ew_curve_kt(sc, cv, v3_mad(S, m, Q), &tm, &str);
        iv left = fabs(tm - ta) < fabs(tm - tb);
        a = select(a, m, left);
        ta = select(ta, tm, left);
        b = select(m, b, left);
        tb = select(tm, tb, left);
    }
    return 0.5f * (a + b);
}

/* One span; where S(t*) jumps, it is split at the jump and redone as two 8-point pieces. */
static fv ew_span(const ew_scene *sc, int kind, __global const float *prim, v3 S, v3 Q, fv c, fv w, fv a, fv b)
{
    ew_jump j;
    fv acc = ew_span_nodes(sc, kind, prim, S, Q, c, w, a, b, EW_GL10_N, ew_gl10_x, ew_gl10_w, &j);
    if (!ew_any(j.jumped)) return acc;
    fv sj = select(b, ew_jump_locate(sc, prim, S, Q, j.a, j.b, j.ta, j.tb), j.jumped); /* other lanes: plain redo */
    fv redo = ew_span_plain(sc, kind, prim, S, Q, c, w, a, sj) + ew_span_plain(sc, kind, prim, S, Q, c, w, sj, b);
    return select(acc, redo, j.jumped);
}

/* [0,1] as one span per peak (split halfway between two peaks). */
static fv ew_peaks_int(const ew_scene *sc, int kind, __global const float *prim, v3 S, v3 Q, const ew_peaks *pk)
{
    if (!ew_any(pk->two)) return ew_span(sc, kind, prim, S, Q, pk->s0, pk->w0, (fv)(0.0f), (fv)(1.0f));
    fv mid = select((fv)(1.0f), 0.5f * (pk->s0 + pk->s1), pk->two);
    return ew_span(sc, kind, prim, S, Q, pk->s0, pk->w0, (fv)(0.0f), mid) +
           ew_span(sc, kind, prim, S, Q, pk->s1, pk->w1, mid, (fv)(1.0f));
}

/* The approach of ray (S, Q) to point X with tangent T (T = 0: a point-like end):
 * its ray parameter s, and half-width w = h/k, with k the ray's speed across the
 * primitive (|Q| past a point, |Q × T̂| past a curve). */
static fv ew_approach(float eps, v3 S, v3 Q, v3 X, v3 T, fv *w)
{
    fv qq = v3_dot(Q, Q), tt = v3_dot(T, T), qt = v3_dot(Q, T);
    fv s = clamp(v3_dot(v3_sub(X, S), Q) / qq, 0.0f, 1.0f);
    v3 d = v3_sub(v3_mad(S, s, Q), X);
    fv along = select((fv)(0.0f), qt * qt / tt, tt > 0.0f);
    *w = fmax(sqrt(v3_dot(d, d)), eps) / sqrt(fmax(qq - along, 1e-4f * qq));
    return s;
}

static void ew_peaks_make(ew_peaks *pk, fv sa, fv wa, fv sb, fv wb, iv two)
{
    /* peaks closer than the wider one's half-width: the narrower one's sinh map resolves both */
    iv merge = fabs(sb - sa) < fmax(wa, wb);
    iv b_first = merge & (wb < wa);
    sa = select(sa, sb, b_first);
    wa = select(wa, wb, b_first);
    two &= ~merge;
    sb = select(sa, sb, two);
    wb = select(wa, wb, two);
    iv swap = sb < sa;
    pk->s0 = select(sa, sb, swap);
    pk->w0 = select(wa, wb, swap);
    pk->s1 = select(sb, sa, swap);
    pk->w1 = select(wb, wa, swap);
    pk->two = two;
}

/* Squared distance from the ray line to the circle point at φ, expanded as
 * f = aa c² + bb s² + 2ab cs − 2ac c − 2bc s + cc (c = cos φ, s = sin φ). */
typedef struct {
    fv aa, bb, ab, ac, bc, cc;
} ew_circle;

static fv ew_circle_f(const ew_circle *K, float c, float s)
{
    return K->aa * (c * c) + K->bb * (s * s) + 2.0f * K->ab * (c * s) - 2.0f * K->ac * c - 2.0f * K->bc * s + K->cc;
}

/* A point of the circle as the unit vector (c, s) = (cos φ, sin φ). */
typedef struct {
    fv c, s;
} ew_angle;

/* Newton on f'(φ) = 0 from a coarse minimum, steps limited to ±0.4 rad: two steps from the
 * search's 0.39 rad at most (a third changed the RMS error against the converged reference
 * by under 0.01% and cost 9% of a torus frame). The angle is carried as (c, s) and turned by
 * each step with sin/cos series (error < 1e-4 rad at 0.4) and a renormalisation, so the
 * search calls no trigonometric function. */
static ew_angle ew_circle_refine(const ew_circle *K, ew_angle a)
{
    for (int it = 0; it < 2; it++) {
        fv c = a.c, s = a.s;
        fv g = (K->bb - K->aa) * s * c + K->ab * (c * c - s * s) + K->ac * s - K->bc * c;
        fv h = (K->bb - K->aa) * (c * c - s * s) - 4.0f * K->ab * s * c + K->ac * c + K->bc * s;
        fv d = select((fv)(0.0f), clamp(g / h, -0.4f, 0.4f), h > 0.0f), d2 = d * d;
        fv sd = d * (1.0f - d2 / 6.0f), cd = 1.0f - d2 * (0.5f - d2 / 24.0f); /* φ ← φ − d */
        fv nc = c * cd + s * sd, ns = s * cd - c * sd, inv = rsqrt(nc * nc + ns * ns);
        a.c = nc * inv;
        a.s = ns * inv;
    }
    return a;
}

static fv ew_circle_approach(__global const float *to, float eps, v3 Sl, v3 Ql, ew_angle a, fv *w)
{
    fv R = (fv)(to[3]);
    return ew_approach(eps, Sl, Ql, v3_make(R * a.c, R * a.s, (fv)(0.0f)), v3_make(-a.s, a.c, (fv)(0.0f)), w);
}

/* cos and sin of kπ/4, k = 0…7: the circle search's start points. f is a trigonometric
 * polynomial of degree 2 (at most two local minima); 8 samples find each minimum's
 * neighbourhood (16 gave the same pictures within 0.7% of a texel's value, and the same RMS
 * error against the converged reference, for a sixth more search time), and Newton steps of
 * up to 0.4 rad cover the 0.39 rad to the nearest sample. */
#define EW_CIRCLE_N 8
__constant float ew_circle_c[EW_CIRCLE_N] = {1.0f,  0.707106781f,  0.0f, -0.707106781f,
                                             -1.0f, -0.707106781f, 0.0f, 0.707106781f};
__constant float ew_circle_s[EW_CIRCLE_N] = {0.0f, 0.707106781f,  1.0f,  0.707106781f,
                                             0.0f, -0.707106781f, -1.0f, -0.707106781f};

/* Closest approaches of the ray line (Sl, Ql: in the torus frame) to the torus centre circle
 * (at most two local minima of the distance): 8-point search around the circle, then Newton. */
static void ew_torus_peaks(__global const float *to, float eps, v3 Sl, v3 Ql, ew_peaks *pk)
{
    fv R = (fv)(to[3]), inv = rsqrt(v3_dot(Ql, Ql));
    v3 qn = v3_mul(Ql, inv);
    v3 a = v3_mul(v3_mad(v3_make((fv)(1.0f), (fv)(0.0f), (fv)(0.0f)), -qn.x, qn), R);
    v3 b = v3_mul(v3_mad(v3_make((fv)(0.0f), (fv)(1.0f), (fv)(0.0f)), -qn.y, qn), R);
    v3 c = v3_perp(Sl, qn);
    ew_circle K = {v3_dot(a, a), v3_dot(b, b), v3_dot(a, b), v3_dot(a, c), v3_dot(b, c), v3_dot(c, c)};
    fv f[EW_CIRCLE_N];
    for (int k = 0; k < EW_CIRCLE_N; k++) f[k] = ew_circle_f(&K, ew_circle_c[k], ew_circle_s[k]);
    /* lanes without a strict minimum (a ray along the axis) keep φ = 0 */
    fv b0 = EW_BIG, b1 = EW_BIG;
    ew_angle a0 = {(fv)(1.0f), (fv)(0.0f)}, a1 = a0;
    for (int k = 0; k < EW_CIRCLE_N; k++) {
        iv is_min = (f[k] <= f[(k + EW_CIRCLE_N - 1) % EW_CIRCLE_N]) & (f[k] < f[(k + 1) % EW_CIRCLE_N]);
        iv first = is_min & (f[k] < b0), second = is_min & ~first & (f[k] < b1);
        fv ck = (fv)(ew_circle_c[k]), sk = (fv)(ew_circle_s[k]);
        b1 = select(select(b1, f[k], second), b0, first);
        a1.c = select(select(a1.c, ck, second), a0.c, first);
        a1.s = select(select(a1.s, sk, second), a0.s, first);
        b0 = select(b0, f[k], first);
        a0.c = select(a0.c, ck, first);
        a0.s = select(a0.s, sk, first);
    }
    fv w0, w1;
    fv s0 = ew_circle_approach(to, eps, Sl, Ql, ew_circle_refine(&K, a0), &w0);
    fv s1 = ew_circle_approach(to, eps, Sl, Ql, ew_circle_refine(&K, a1), &w1);
    ew_peaks_make(pk, s0, w0, s1, w1, b1 < EW_BIG);
}

/* ∫ of the torus term ζ coef/max(ε, d) along the ray Sl + sQl (torus frame) over u in
 * [u0, u0 + du] of the sinh map around the peak (c, w), by 6 Gauss–Legendre nodes. */
static fv ew_torus_piece(const ew_scene *sc, __global const float *to, v3 Sl, v3 Ql, fv c, fv w, fv u0, fv du)
{
    float R = to[3];
    fv acc = 0.0f;
    for (int k = 0; k < EW_GL6_N; k++) {
        fv jac, s = ew_sinh_node(c, w, u0, du, ew_gl6_x[k], &jac);
        v3 P = v3_mad(Sl, s, Ql);
        fv dr = sqrt(P.x * P.x + P.y * P.y) - R;
        acc += ew_gl6_w[k] * jac * ew_zeta(sc, s) / fmax(sc->eps, sqrt(dr * dr + P.z * P.z));
    }
    return acc * du;
}

/* ∫_a^b of the torus term with the span's sinh map around the peak (c, w), in two pieces
 * split at the peak (u = 0; halfway where the peak lies outside [a, b]): on each side the
 * integrand in u is smoother than across the peak. */
static fv ew_torus_span(const ew_scene *sc, __global const float *to, v3 Sl, v3 Ql, fv c, fv w, fv a, fv b)
{
    fv ua = asinh((a - c) / w), ub = asinh((b - c) / w), um = clamp((fv)(0.0f), ua, ub);
    um = select(um, 0.5f * (ua + ub), (um == ua) | (um == ub));
    fv acc = ew_torus_piece(sc, to, Sl, Ql, c, w, ua, um - ua) + ew_torus_piece(sc, to, Sl, Ql, c, w, um, ub - um);
    return acc * 0.5f * w * to[7];
}

/* One torus: its closest approaches, then one span per peak (split halfway between two). */
static fv ew_torus_int(const ew_scene *sc, __global const float *to, v3 S, v3 Q)
{
    v3 Sl = ew_torus_local(to, S), Ql = ew_torus_local(to, v3_add(Q, v3_load(to)));
    ew_peaks pk;
    ew_torus_peaks(to, sc->eps, Sl, Ql, &pk);
    if (!ew_any(pk.two)) return ew_torus_span(sc, to, Sl, Ql, pk.s0, pk.w0, (fv)(0.0f), (fv)(1.0f));
    fv mid = select((fv)(1.0f), 0.5f * (pk.s0 + pk.s1), pk.two);
    return ew_torus_span(sc, to, Sl, Ql, pk.s0, pk.w0, (fv)(0.0f), mid) +
           ew_torus_span(sc, to, Sl, Ql, pk.s1, pk.w1, mid, (fv)(1.0f));
}

/* Closest approaches of the ray line to the lit part [t_lo, t_hi] of a curve (where
 * S(t) > 0): local minima over t of f(t) = |p(t)|², p = the curve projected on the
 * plane normal to the ray, relative to S. f'/2 is the nearest-point cubic of the
 * projected curve, so the same solver finds them; the ends of the range count where f
 * rises away from them. At most two; the two smallest are kept. */
static void ew_curve_peaks(__global const float *cv, float eps, v3 S, v3 Q, ew_peaks *pk)
{
    v3 qn = v3_mul(Q, rsqrt(v3_dot(Q, Q)));
    v3 C1 = v3_load(cv + 4), C2 = v3_load(cv + 8);
    v3 C1p = v3_perp(C1, qn), C2p = v3_perp(C2, qn), Dp = v3_perp(v3_sub(v3_load(cv), S), qn);
    fv c2 = v3_dot(C2p, C2p), c12 = v3_dot(C1p, C2p), c1 = v3_dot(C1p, C1p);
    fv c2d = v3_dot(C2p, Dp), c1d = v3_dot(C1p, Dp);
    float lo = cv[14], hi = cv[15];
    iv straight = c2 <= 1e-6f * c1;
    fv inv = 0.5f / select(c2, (fv)(1.0f), straight), r[3];
    ew_cubic(3.0f * c12 * inv, (2.0f * c2d + c1) * inv, c1d * inv, &r[0], &r[1], &r[2]);
    fv lin = clamp(-c1d / fmax(c1, 1e-30f), lo, hi);
    fv cand[5] = {(fv)(lo), r[0], r[1], r[2], (fv)(hi)};
    iv ok[5];
    ok[0] = ~straight & (((2.0f * c2 * lo + 3.0f * c12) * lo + 2.0f * c2d + c1) * lo + c1d > 0.0f);
    for (int k = 0; k < 3; k++)
        ok[k + 1] = ~straight & (r[k] > lo) & (r[k] < hi) & ((6.0f * c2 * r[k] + 6.0f * c12) * r[k] + 2.0f * c2d + c1 > 0.0f);
    ok[4] = ~straight & (((2.0f * c2 * hi + 3.0f * c12) * hi + 2.0f * c2d + c1) * hi + c1d < 0.0f);
    fv b0 = EW_BIG, b1 = EW_BIG, t0 = select((fv)(0.5f * (lo + hi)), lin, straight), t1 = t0;
    for (int k = 0; k < 5; k++) {
        v3 p = v3_mad(v3_mad(Dp, cand[k], C1p), cand[k] * cand[k], C2p);
        fv f = v3_dot(p, p);
        iv first = ok[k] & (f < b0), second = ok[k] & ~first & (f < b1);
        b1 = select(select(b1, f, second), b0, first);
        t1 = select(select(t1, cand[k], second), t0, first);
        b0 = select(b0, f, first);
        t0 = select(t0, cand[k], first);
    }
    fv w0, w1;
    v3 T0 = v3_mul(v3_mad(C1, 2.0f * t0, C2), select((fv)(1.0f), (fv)(0.0f), (t0 <= 0.0f) | (t0 >= 1.0f)));
    v3 T1 = v3_mul(v3_mad(C1, 2.0f * t1, C2), select((fv)(1.0f), (fv)(0.0f), (t1 <= 0.0f) | (t1 >= 1.0f)));
    fv s0 = ew_approach(eps, S, Q, ew_curve_at(cv, t0), T0, &w0);
    fv s1 = ew_approach(eps, S, Q, ew_curve_at(cv, t1), T1, &w1);
    ew_peaks_make(pk, s0, w0, s1, w1, b1 < EW_BIG);
}

__kernel void ew_render_adaptive(__global float *out, __constant const float *cam, __global const float *pts,
                                 int np, __global const float *lns, int nl, __global const float *tor, int nt,
                                 __global const float *cur, int nc, __global const float *spl, int width,
                                 int height)
{
    int i0 = get_global_id(0) * EW_LANES, j = get_global_id(1);
    if (i0 >= width || j >= height) return;
    ew_scene sc = ew_scene_make(cam, pts, np, lns, nl, tor, nt, cur, nc, spl);
    v3 S, Q;
    ew_texel_rays(cam, i0, j, width, height, &S, &Q);
    ew_peaks pk;
    fv acc = 0.0f;
    for (int k = 0; k < np; k++) acc += ew_point_int(&sc, pts + k * EW_PT_STRIDE, S, Q);
    for (int k = 0; k < nl; k++) acc += ew_line_int(&sc, lns + k * EW_LN_STRIDE, S, Q);
    for (int k = 0; k < nt; k++) acc += ew_torus_int(&sc, tor + k * EW_TO_STRIDE, S, Q);
    for (int k = 0; k < nc; k++) {
        ew_curve_peaks(cur + k * EW_CV_STRIDE, sc.eps, S, Q, &pk);
        acc += ew_peaks_int(&sc, 1, cur + k * EW_CV_STRIDE, S, Q, &pk);
    }
    ew_store(out, acc, i0, j, width);
}
