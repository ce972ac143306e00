/* energy_wave.cl — OpenCL kernels of effect energy_wave (seed 000, Watanabe 2016).
 *
 * One work item per texel (2-D NDRange, column i, row j from the top). Each computes
 * B = ∫₀¹ ψ(L(s)) ζ(s) ds along the ray L(s) = S + s(E − S), ζ(s) = α/(s+β)², where ψ
 * is the sum of point / line / torus / Bézier-curve kernels (digest §2). Two renderers:
 *   ew_render_simpson   the thesis's method: composite Simpson, n+1 samples, fused
 *                       into one kernel (no A array).
 *   ew_render_adaptive  ψ is a sum, so each primitive is integrated on its own:
 *                       closed forms for points and lines (digest §2.6), and for tori
 *                       and curves the ray's closest approach s* (at most two per
 *                       primitive) splits [0,1]; each side is integrated with
 *                       s = s* ± w·sinh(u) (w = peak width) and EW_GL_N-point
 *                       Gauss–Legendre, which turns the 1/distance peak smooth.
 * The ew_test_* kernels expose the solver pieces to the unit tests; they call the same
 * functions as the renderers. Buffer layouts below must match energy_wave.c. */

#define EW_PT_STRIDE 4  /* pos.xyz, coef */
#define EW_LN_STRIDE 8  /* pos.xyz, coef, dir.xyz (unit), 0 */
#define EW_TO_STRIDE 16 /* center.xyz, R, e1.xyz, coef, e2.xyz, 0, axis.xyz (unit), 0 */
#define EW_CV_STRIDE 16 /* C0.xyz, coef, C1.xyz, |C2|², C2.xyz, C1·C2, |C1|², nw, t_lo, t_hi */
#define EW_MAX_W 32     /* curve i's weights start at wts[i·EW_MAX_W] */
/* Camera buffer: billboard centre (0..2), l·r (4..6), l·(H/W)·u (8..10), eye (12..14),
 * nu (15), alpha (16), beta (17), epsilon (18). */

#ifndef EW_GL_N
#define EW_GL_N 8
#endif

#if EW_GL_N == 6
__constant float ew_gl_x[6] = {0.033765243f, 0.169395307f, 0.380690407f, 0.619309593f, 0.830604693f, 0.966234757f};
__constant float ew_gl_w[6] = {0.085662246f, 0.180380787f, 0.233956967f, 0.233956967f, 0.180380787f, 0.085662246f};
#elif EW_GL_N == 8
__constant float ew_gl_x[8] = {0.019855072f, 0.101666761f, 0.237233795f, 0.408282679f,
                               0.591717321f, 0.762766205f, 0.898333239f, 0.980144928f};
__constant float ew_gl_w[8] = {0.050614268f, 0.111190517f, 0.156853323f, 0.181341892f,
                               0.181341892f, 0.156853323f, 0.111190517f, 0.050614268f};
#elif EW_GL_N == 12
__constant float ew_gl_x[12] = {0.009219683f, 0.047941372f, 0.115048663f, 0.206341023f, 0.316084251f, 0.437383296f,
                                0.562616704f, 0.683915749f, 0.793658977f, 0.884951337f, 0.952058628f, 0.990780317f};
__constant float ew_gl_w[12] = {0.023587668f, 0.053469663f, 0.080039164f, 0.101583713f, 0.116746268f, 0.124573523f,
                                0.124573523f, 0.116746268f, 0.101583713f, 0.080039164f, 0.053469663f, 0.023587668f};
#else
#error "EW_GL_N must be 6, 8 or 12"
#endif

typedef struct {
    __global const float *pts, *lns, *tor, *cur, *wts;
    int np, nl, nt, nc;
    float alpha, beta, eps;
} ew_scene;

typedef struct {
    int n;
    float s[2];  /* closest-approach ray parameters, ascending */
    float w[2];  /* peak half-widths in s */
    float split; /* a jump of the integrand (curve medial plane), or -1 */
} ew_peaks;

static float ew_zeta(const ew_scene *sc, float s)
{
    float d = s + sc->beta;
    return sc->alpha / (d * d);
}

/* ---- cubic solver (digest §2.2 recommended solver) ------------------------------- */

/* Real roots of x³ + a x² + b x + c = 0, ascending; returns how many (1 or 3).
 * digest 000 §8 #5/#6/#7: the thesis's Cardano uses θ = arctan(q/r), omits the −a/3
 * shift and picks roots by "imag == 0"; this is the trigonometric form instead, with the
 * −a/3 shift, the double root (r ≈ 0) in the trig branch and one Newton step per root. */
static int ew_cubic(float a, float b, float c, float *r)
{
    float p = b / 3.0f - a * a / 9.0f;
    float q = a * a * a / 27.0f - a * b / 6.0f + c / 2.0f;
    float disc = p * p * p + q * q, shift = -a / 3.0f;
    int n = 1;
    if (p < 0.0f && disc <= 1e-5f * q * q) {
        float m = 2.0f * sqrt(-p);
        float phi = acos(clamp(-q / sqrt(-p * p * p), -1.0f, 1.0f));
        for (int k = 0; k < 3; k++) r[k] = m * cos((phi + 2.0f * M_PI_F * (float)k) / 3.0f) + shift;
        n = 3;
    } else if (disc > 0.0f) {
        float sq = sqrt(disc);
        r[0] = cbrt(-q + sq) + cbrt(-q - sq) + shift;
    } else {
        r[0] = shift; /* p = q = 0: triple root */
    }
    for (int k = 0; k < n; k++) {
        float x = r[k], f = ((x + a) * x + b) * x + c, fp = (3.0f * x + 2.0f * a) * x + b;
        if (fp != 0.0f) r[k] = x - f / fp;
    }
    for (int i = 1; i < n; i++)
        for (int k = i; k > 0 && r[k - 1] > r[k]; k--) {
            float t = r[k];
            r[k] = r[k - 1];
            r[k - 1] = t;
        }
    return n;
}

/* ---- B-spline strength S(t) (digest §2.3) ----------------------------------------- */

/* Clamped uniform knot u_i of (3.26) for nw weights: [0,0,0, 1/(nw−2), …, 1,1,1]. */
static float ew_knot(int i, int nw)
{
    return clamp((float)(i - 2) / (float)(nw - 2), 0.0f, 1.0f);
}

/* S(t) = Σ w_i N_i²(t) by de Boor's algorithm on the span holding t. digest 000 §8 #10:
 * the last span is closed at t = 1 (half-open spans give S(1) = 0, a dark end cap). */
static float ew_bspline(__global const float *w, int nw, float t)
{
    int spans = nw - 2;
    int j = clamp((int)(t * (float)spans), 0, spans - 1);
    int k = j + 2; /* u_k <= t < u_{k+1} */
    float d0 = w[k - 2], d1 = w[k - 1], d2 = w[k];
    float u_km1 = ew_knot(k - 1, nw), u_k = ew_knot(k, nw);
    float u_kp1 = ew_knot(k + 1, nw), u_kp2 = ew_knot(k + 2, nw);
    float a = (t - u_k) / (u_kp2 - u_k);
    d2 = (1.0f - a) * d1 + a * d2;
    a = (t - u_km1) / (u_kp1 - u_km1);
    d1 = (1.0f - a) * d0 + a * d1;
    a = (t - u_k) / (u_kp1 - u_k);
    return (1.0f - a) * d1 + a * d2;
}

/* ---- kernels of the primitives (digest §2.2) ------------------------------------- */

static float3 ew_load3(__global const float *p) { return (float3)(p[0], p[1], p[2]); }

static float ew_point_k(__global const float *pt, float3 P, float eps)
{
    float3 v = P - ew_load3(pt);
    return pt[3] / fmax(eps, sqrt(dot(v, v)));
}

static float ew_line_k(__global const float *ln, float3 P, float eps)
{
    float3 v = P - ew_load3(ln);
    float along = dot(v, ew_load3(ln + 4));
    return ln[3] / fmax(eps, sqrt(fmax(dot(v, v) - along * along, 0.0f)));
}

/* P in the torus frame: P_local = Rᵀ(P − centre), axis = local z.
 * digest 000 §8 #20: the thesis fixes the torus at the origin; this is the pose. */
static float3 ew_torus_local(__global const float *to, float3 P)
{
    float3 v = P - ew_load3(to);
    return (float3)(dot(v, ew_load3(to + 4)), dot(v, ew_load3(to + 8)), dot(v, ew_load3(to + 12)));
}

/* (3.6): distance to the centre circle of radius R. */
static float ew_torus_dist(float3 l, float R)
{
    float dr = sqrt(l.x * l.x + l.y * l.y) - R;
    return sqrt(dr * dr + l.z * l.z);
}

static float ew_torus_k(__global const float *to, float3 P, float eps)
{
    return to[7] / fmax(eps, ew_torus_dist(ew_torus_local(to, P), to[3]));
}

static float3 ew_curve_at(__global const float *cv, float t)
{
    return (ew_load3(cv + 8) * t + ew_load3(cv + 4)) * t + ew_load3(cv);
}

/* Nearest point of C(t) = C₂t² + C₁t + C₀, t in [0,1], to P: (distance, t*).
 * digest 000 §8 #4: thesis eq. 3.12 lacks −2C₂·P in the t coefficient (and flips the
 * sign); the cubic is 2|C₂|²t³ + 3(C₁·C₂)t² + (2C₂·(C₀−P) + |C₁|²)t + C₁·(C₀−P) = 0,
 * normalised by 2|C₂|² (§8 #6), with the straight case C₂ ≈ 0 solved linearly. */
static float2 ew_curve_nearest(__global const float *cv, float3 P)
{
    float3 D = ew_load3(cv) - P, C1 = ew_load3(cv + 4), C2 = ew_load3(cv + 8);
    float c2sq = cv[7], c12 = cv[11], c1sq = cv[12];
    float cand[5] = {0.0f, 1.0f, 0.0f, 0.0f, 0.0f};
    int n = 2;
    if (c2sq <= 1e-6f * c1sq) {
        cand[n++] = c1sq > 0.0f ? clamp(-dot(C1, D) / c1sq, 0.0f, 1.0f) : 0.0f;
    } else {
        float inv = 0.5f / c2sq, r[3];
        int nr = ew_cubic(3.0f * c12 * inv, (2.0f * dot(C2, D) + c1sq) * inv, dot(C1, D) * inv, r);
        for (int k = 0; k < nr; k++) cand[n++] = clamp(r[k], 0.0f, 1.0f);
    }
    float3 v0 = ew_curve_at(cv, cand[0]) - P;
    float best = dot(v0, v0), bt = cand[0];
    for (int k = 1; k < n; k++) {
        float3 v = ew_curve_at(cv, cand[k]) - P;
        float d2 = dot(v, v);
        if (d2 < best) {
            best = d2;
            bt = cand[k];
        }
    }
    return (float2)(sqrt(best), bt);
}

/* (3.27): coef · S(t*) / max(ε, L(P, curve)). */
static float ew_curve_k(const ew_scene *sc, __global const float *cv, float3 P)
{
    float2 dt = ew_curve_nearest(cv, P);
    float s = ew_bspline(sc->wts + (cv - sc->cur) / EW_CV_STRIDE * EW_MAX_W, (int)cv[13], dt.y);
    return cv[3] * s / fmax(sc->eps, dt.x);
}

/* (3.28): ψ(P), the sum over every source. */
static float ew_psi(const ew_scene *sc, float3 P)
{
    float psi = 0.0f;
    for (int i = 0; i < sc->np; i++) psi += ew_point_k(sc->pts + i * EW_PT_STRIDE, P, sc->eps);
    for (int i = 0; i < sc->nl; i++) psi += ew_line_k(sc->lns + i * EW_LN_STRIDE, P, sc->eps);
    for (int i = 0; i < sc->nt; i++) psi += ew_torus_k(sc->tor + i * EW_TO_STRIDE, P, sc->eps);
    for (int i = 0; i < sc->nc; i++) psi += ew_curve_k(sc, sc->cur + i * EW_CV_STRIDE, P);
    return psi;
}

/* ---- camera ----------------------------------------------------------------------- */

static ew_scene ew_scene_make(__constant const float *cam, __global const float *pts, int np,
                              __global const float *lns, int nl, __global const float *tor, int nt,
                              __global const float *cur, int nc, __global const float *wts)
{
    ew_scene sc = {pts, lns, tor, cur, wts, np, nl, nt, nc, cam[16], cam[17], cam[18]};
    return sc;
}

/* Texel (i, j) → ray start S and Q = E − S, with E = V + ν(S − V).
 * digest 000 §8 #14/#17: translation-invariant E and pixel-centre sampling. */
static void ew_texel_ray(__constant const float *cam, int i, int j, int width, int height, float3 *S, float3 *Q)
{
    float x = ((float)i + 0.5f) / (float)width - 0.5f;
    float y = 0.5f - ((float)j + 0.5f) / (float)height;
    float3 V = (float3)(cam[12], cam[13], cam[14]);
    *S = (float3)(cam[0], cam[1], cam[2]) + x * (float3)(cam[4], cam[5], cam[6]) + y * (float3)(cam[8], cam[9], cam[10]);
    *Q = (cam[15] - 1.0f) * (*S - V);
}

/* ---- Simpson (thesis §3.5.3, §4) --------------------------------------------------- */

/* digest 000 §8 #16: the thesis samples k = 0…d−1 and reuses A^{d−1} as f(1); here
 * n+1 samples k = 0…n with weights 1,4,2,…,4,1. */
__kernel void ew_render_simpson(__global float *out, __constant const float *cam, __global const float *pts,
                                int np, __global const float *lns, int nl, __global const float *tor, int nt,
                                __global const float *cur, int nc, __global const float *wts, int width,
                                int height, int divisions)
{
    int i = get_global_id(0), j = get_global_id(1);
    if (i >= width || j >= height) return;
    ew_scene sc = ew_scene_make(cam, pts, np, lns, nl, tor, nt, cur, nc, wts);
    float3 S, Q;
    ew_texel_ray(cam, i, j, width, height, &S, &Q);
    float inv_n = 1.0f / (float)divisions, acc = 0.0f;
    for (int k = 0; k <= divisions; k++) {
        float s = (float)k * inv_n;
        float wk = (k == 0 || k == divisions) ? 1.0f : ((k & 1) ? 4.0f : 2.0f);
        acc += wk * ew_psi(&sc, S + s * Q) * ew_zeta(&sc, s);
    }
    out[j * width + i] = acc * inv_n / 3.0f;
}

/* ---- closed forms for points and lines (digest §2.6) ------------------------------ */

/* asinh(z1/k) − asinh(z0/k) for k = √k2; when z0, z1 share a sign it is a log ratio,
 * exact even when k → 0 (a ray through the source). */
static float ew_asinh_diff(float z0, float z1, float k2)
{
    if (z0 * z1 > 0.0f) {
        float a0 = fabs(z0), a1 = fabs(z1);
        float l = log((a1 + sqrt(a1 * a1 + k2)) / (a0 + sqrt(a0 * a0 + k2)));
        return z1 > 0.0f ? l : -l;
    }
    float k = sqrt(fmax(k2, 1e-30f));
    return asinh(z1 / k) - asinh(z0 / k);
}

/* ∫_{s0}^{s1} α ds / ((s+β)² √(As² + 2Bs + C)), k2 = AC − B² (computed as a cross
 * product by the caller). With y = 1/(s+β), a' = U(−β), b' = B − Aβ it is
 * α[G(y0) − G(y1)], G(y) = √(a'y²+2b'y+A)/a' − b'a'^{−3/2} asinh((a'y+b')/√k2).
 * digest 000 §8 #2: the thesis's (2.8) lacks the square root in the asinh argument. */
static float ew_quad_piece(const ew_scene *sc, float A, float B, float C, float k2, float s0, float s1)
{
    if (s1 <= s0) return 0.0f;
    float be = sc->beta;
    float ap = (A * be - 2.0f * B) * be + C, bp = B - A * be;
    float y0 = 1.0f / (s0 + be), y1 = 1.0f / (s1 + be);
    float u0 = fmax((A * s0 + 2.0f * B) * s0 + C, 0.0f), u1 = fmax((A * s1 + 2.0f * B) * s1 + C, 0.0f);
    float t1 = (y0 * sqrt(u0) - y1 * sqrt(u1)) / ap;
    float t2 = bp / (ap * sqrt(ap)) * ew_asinh_diff(ap * y1 + bp, ap * y0 + bp, k2);
    return sc->alpha * (t1 - t2);
}

/* ∫₀¹ ζ(s) / max(ε, √(As² + 2Bs + C)) ds: inside the ε-ball the kernel is 1/ε. */
static float ew_quad_int(const ew_scene *sc, float A, float B, float C, float k2)
{
    float e2 = sc->eps * sc->eps, h2 = k2 / A, sstar = -B / A;
    if (h2 >= e2) return ew_quad_piece(sc, A, B, C, k2, 0.0f, 1.0f);
    float delta = sqrt((e2 - h2) / A);
    float lo = clamp(sstar - delta, 0.0f, 1.0f), hi = clamp(sstar + delta, 0.0f, 1.0f);
    float core = sc->alpha / sc->eps * (1.0f / (lo + sc->beta) - 1.0f / (hi + sc->beta));
    return ew_quad_piece(sc, A, B, C, k2, 0.0f, lo) + core + ew_quad_piece(sc, A, B, C, k2, hi, 1.0f);
}

static float ew_point_int(const ew_scene *sc, __global const float *pt, float3 S, float3 Q)
{
    float3 v = S - ew_load3(pt), x = cross(Q, v);
    return pt[3] * ew_quad_int(sc, dot(Q, Q), dot(Q, v), dot(v, v), dot(x, x));
}

/* The line kernel is the point kernel in the plane normal to the line (2.14)–(2.16). */
static float ew_line_int(const ew_scene *sc, __global const float *ln, float3 S, float3 Q)
{
    float3 D = ew_load3(ln + 4), v = S - ew_load3(ln);
    float3 qp = Q - dot(Q, D) * D, vp = v - dot(v, D) * D, x = cross(qp, vp);
    float A = dot(qp, qp), C = dot(vp, vp);
    if (A <= 1e-10f * dot(Q, Q)) /* ray parallel to the line: constant distance */
        return ln[3] * sc->alpha * (1.0f / sc->beta - 1.0f / (1.0f + sc->beta)) / fmax(sc->eps, sqrt(C));
    return ln[3] * ew_quad_int(sc, A, dot(qp, vp), C, dot(x, x));
}

/* ---- peak-adapted quadrature for tori and curves ---------------------------------- */

/* kind 0: torus, 1: curve. */
static float ew_prim_k(const ew_scene *sc, int kind, __global const float *prim, float3 P)
{
    return kind == 0 ? ew_torus_k(prim, P, sc->eps) : ew_curve_k(sc, prim, P);
}

/* ∫ between s0 (a peak of half-width w) and s1 of ψ_prim ζ ds, with s = s0 ± w·sinh(u). */
static float ew_side(const ew_scene *sc, int kind, __global const float *prim, float3 S, float3 Q, float s0,
                     float w, float s1)
{
    float len = fabs(s1 - s0);
    if (len < 1e-7f) return 0.0f;
    float U = asinh(len / w), dir = s1 > s0 ? w : -w, acc = 0.0f;
    for (int k = 0; k < EW_GL_N; k++) {
        float e = exp(U * ew_gl_x[k]), ie = 1.0f / e;
        float s = s0 + dir * 0.5f * (e - ie);
        acc += ew_gl_w[k] * (e + ie) * ew_prim_k(sc, kind, prim, S + s * Q) * ew_zeta(sc, s);
    }
    return acc * 0.5f * U * w;
}

/* Half-width to use when anchoring the sinh map at x: the nearest peak's, widened by
 * the distance to it (the ray is at distance ≈ k·√(w² + (x − s*)²) there). */
static float ew_anchor_w(const ew_peaks *pk, float x)
{
    float best = INFINITY;
    for (int m = 0; m < pk->n; m++) {
        float d = x - pk->s[m];
        best = fmin(best, pk->w[m] * pk->w[m] + d * d);
    }
    return sqrt(best);
}

/* ∫ over [a, b] where a or b may be a peak (pa, pb: peak index or −1). */
static float ew_piece(const ew_scene *sc, int kind, __global const float *prim, float3 S, float3 Q,
                      const ew_peaks *pk, float a, int pa, float b, int pb)
{
    if (pa >= 0 && pb >= 0) {
        float mid = 0.5f * (a + b);
        return ew_side(sc, kind, prim, S, Q, a, pk->w[pa], mid) + ew_side(sc, kind, prim, S, Q, b, pk->w[pb], mid);
    }
    if (pa >= 0) return ew_side(sc, kind, prim, S, Q, a, pk->w[pa], b);
    if (pb >= 0) return ew_side(sc, kind, prim, S, Q, b, pk->w[pb], a);
    float wa = ew_anchor_w(pk, a), wb = ew_anchor_w(pk, b);
    return wa <= wb ? ew_side(sc, kind, prim, S, Q, a, wa, b) : ew_side(sc, kind, prim, S, Q, b, wb, a);
}

/* Splits [0,1] at the peaks and the jump and integrates every piece. */
static float ew_peaks_int(const ew_scene *sc, int kind, __global const float *prim, float3 S, float3 Q,
                          const ew_peaks *pk)
{
    float x[4];
    int peak[4], n = 0;
    for (int m = 0; m < pk->n; m++) {
        x[n] = pk->s[m];
        peak[n++] = m;
    }
    if (pk->split > 0.0f && pk->split < 1.0f) {
        int k = n++;
        for (; k > 0 && x[k - 1] > pk->split; k--) {
            x[k] = x[k - 1];
            peak[k] = peak[k - 1];
        }
        x[k] = pk->split;
        peak[k] = -1;
    }
    float acc = 0.0f, a = 0.0f;
    int pa = -1;
    for (int k = 0; k < n; k++) {
        acc += ew_piece(sc, kind, prim, S, Q, pk, a, pa, x[k], peak[k]);
        a = x[k];
        pa = peak[k];
    }
    return acc + ew_piece(sc, kind, prim, S, Q, pk, a, pa, 1.0f, -1);
}

/* Adds the approach to point X (tangent T, or T = 0 at a curve end) to pk. The peak
 * half-width is h / k with k the ray's speed across the primitive: |Q| past a point,
 * |Q × T̂| past a curve. */
static void ew_peak_add(ew_peaks *pk, float eps, float3 S, float3 Q, float3 X, float3 T)
{
    float qq = dot(Q, Q), tt = dot(T, T);
    float s = clamp(dot(X - S, Q) / qq, 0.0f, 1.0f);
    float3 d = S + s * Q - X;
    float along = tt > 0.0f ? dot(Q, T) * dot(Q, T) / tt : 0.0f;
    float w = fmax(sqrt(dot(d, d)), eps) / sqrt(fmax(qq - along, 1e-4f * qq));
    int n = pk->n++;
    if (n == 1 && s < pk->s[0]) {
        pk->s[1] = pk->s[0];
        pk->w[1] = pk->w[0];
        n = 0;
    }
    pk->s[n] = s;
    pk->w[n] = w;
}

/* Squared distance from the ray line to the circle point at φ, in the expanded form
 * f = aa c² + bb s² + 2ab cs − 2ac c − 2bc s + cc (c = cos φ, s = sin φ). */
static float ew_circle_f(const float *K, float phi)
{
    float c = cos(phi), s = sin(phi);
    return K[0] * c * c + K[1] * s * s + 2.0f * K[2] * c * s - 2.0f * K[3] * c - 2.0f * K[4] * s + K[5];
}

/* Newton on f'(φ) = 0 from a coarse minimum. */
static float ew_circle_refine(const float *K, float phi)
{
    for (int it = 0; it < 3; it++) {
        float c = cos(phi), s = sin(phi);
        float g = (K[1] - K[0]) * s * c + K[2] * (c * c - s * s) + K[3] * s - K[4] * c;
        float h = (K[1] - K[0]) * (c * c - s * s) - 4.0f * K[2] * s * c + K[3] * c + K[4] * s;
        if (h <= 0.0f) break;
        phi -= clamp(g / h, -0.4f, 0.4f);
    }
    return phi;
}

/* Closest approaches of the ray line to the torus centre circle (at most two local
 * minima of the distance): 16-point search around the circle, then Newton. */
static void ew_torus_peaks(__global const float *to, float eps, float3 S, float3 Q, ew_peaks *pk)
{
    float3 e1 = ew_load3(to + 4), e2 = ew_load3(to + 8), e3 = ew_load3(to + 12);
    float3 Sl = ew_torus_local(to, S), Ql = (float3)(dot(Q, e1), dot(Q, e2), dot(Q, e3));
    float R = to[3];
    float3 qn = normalize(Ql);
    float3 a = R * ((float3)(1.0f, 0.0f, 0.0f) - qn.x * qn), b = R * ((float3)(0.0f, 1.0f, 0.0f) - qn.y * qn);
    float3 c = Sl - dot(Sl, qn) * qn;
    float K[6] = {dot(a, a), dot(b, b), dot(a, b), dot(a, c), dot(b, c), dot(c, c)};
    float f[16];
    for (int k = 0; k < 16; k++) f[k] = ew_circle_f(K, (float)k * (M_PI_F / 8.0f));
    int best[2] = {-1, -1};
    for (int k = 0; k < 16; k++) {
        float fk = f[k];
        if (!(fk <= f[(k + 15) & 15] && fk < f[(k + 1) & 15])) continue;
        if (best[0] < 0 || fk < f[best[0]]) {
            best[1] = best[0];
            best[0] = k;
        } else if (best[1] < 0 || fk < f[best[1]]) {
            best[1] = k;
        }
    }
    if (best[0] < 0) best[0] = 0; /* ray along the axis: every circle point is a minimum */
    pk->n = 0;
    pk->split = -1.0f;
    for (int m = 0; m < 2 && best[m] >= 0; m++) {
        float phi = ew_circle_refine(K, (float)best[m] * (M_PI_F / 8.0f));
        float3 X = (float3)(R * cos(phi), R * sin(phi), 0.0f), T = (float3)(-sin(phi), cos(phi), 0.0f);
        ew_peak_add(pk, eps, Sl, Ql, X, T);
    }
}

/* Where the ray crosses the curve's medial plane: the nearest point jumps between the
 * two arms there, and so may S(t*). For a parabola it is the symmetry plane (through
 * the vertex C(t_v), normal to C'(t_v)) beyond the vertex's centre of curvature;
 * returns its ray parameter, or −1 when the ray does not cross it. */
static float ew_curve_medial(__global const float *cv, float3 S, float3 Q)
{
    float c2sq = cv[7], tv = -cv[11] / (2.0f * c2sq);
    if (c2sq <= 1e-6f * cv[12] || tv <= 0.0f || tv >= 1.0f) return -1.0f;
    float3 C2 = ew_load3(cv + 8), Tv = 2.0f * tv * C2 + ew_load3(cv + 4), Xv = ew_curve_at(cv, tv);
    float den = dot(Q, Tv);
    if (fabs(den) <= 1e-6f * sqrt(dot(Q, Q) * dot(Tv, Tv))) return -1.0f;
    float sm = dot(Xv - S, Tv) / den;
    return dot(S + sm * Q - Xv, C2) > 0.5f * dot(Tv, Tv) ? sm : -1.0f;
}

/* Closest approaches of the ray line to the lit part [t_lo, t_hi] of a curve (where
 * S(t) > 0): the local minima over t of the squared distance f(t) = |p(t)|², p = the
 * curve projected on the plane normal to the ray (relative to S). f'/2 is the
 * nearest-point cubic of the projected curve, so the same solver finds them; the ends
 * of the range count when f rises away from them. At most two minima. */
static void ew_curve_peaks(__global const float *cv, float eps, float3 S, float3 Q, ew_peaks *pk)
{
    float3 qn = normalize(Q);
    float3 C1 = ew_load3(cv + 4), C2 = ew_load3(cv + 8), D = ew_load3(cv) - S;
    float3 C1p = C1 - dot(C1, qn) * qn, C2p = C2 - dot(C2, qn) * qn, Dp = D - dot(D, qn) * qn;
    float c2 = dot(C2p, C2p), c12 = dot(C1p, C2p), c1 = dot(C1p, C1p), c2d = dot(C2p, Dp), c1d = dot(C1p, Dp);
    float lo = cv[14], hi = cv[15], cand[3], r[3];
    int n = 0;
    if (c2 <= 1e-6f * c1) {
        cand[n++] = c1 > 0.0f ? clamp(-c1d / c1, lo, hi) : 0.5f * (lo + hi);
    } else {
        float inv = 0.5f / c2;
        int nr = ew_cubic(3.0f * c12 * inv, (2.0f * c2d + c1) * inv, c1d * inv, r);
        if (((2.0f * c2 * lo + 3.0f * c12) * lo + 2.0f * c2d + c1) * lo + c1d > 0.0f) cand[n++] = lo;
        for (int k = 0; k < nr && n < 2; k++)
            if (r[k] > lo && r[k] < hi && (6.0f * c2 * r[k] + 6.0f * c12) * r[k] + 2.0f * c2d + c1 > 0.0f)
                cand[n++] = r[k];
        if (n < 2 && ((2.0f * c2 * hi + 3.0f * c12) * hi + 2.0f * c2d + c1) * hi + c1d < 0.0f) cand[n++] = hi;
        if (n == 0) cand[n++] = 0.5f * (lo + hi); /* rounding hid every minimum */
    }
    pk->n = 0;
    pk->split = ew_curve_medial(cv, S, Q);
    for (int k = 0; k < n; k++) {
        float t = cand[k];
        float3 T = (t > 0.0f && t < 1.0f) ? 2.0f * t * C2 + C1 : (float3)(0.0f);
        ew_peak_add(pk, eps, S, Q, ew_curve_at(cv, t), T);
    }
}

__kernel void ew_render_adaptive(__global float *out, __constant const float *cam, __global const float *pts,
                                 int np, __global const float *lns, int nl, __global const float *tor, int nt,
                                 __global const float *cur, int nc, __global const float *wts, int width,
                                 int height)
{
    int i = get_global_id(0), j = get_global_id(1);
    if (i >= width || j >= height) return;
    ew_scene sc = ew_scene_make(cam, pts, np, lns, nl, tor, nt, cur, nc, wts);
    float3 S, Q;
    ew_texel_ray(cam, i, j, width, height, &S, &Q);
    ew_peaks pk;
    float acc = 0.0f;
    for (int k = 0; k < np; k++) acc += ew_point_int(&sc, pts + k * EW_PT_STRIDE, S, Q);
    for (int k = 0; k < nl; k++) acc += ew_line_int(&sc, lns + k * EW_LN_STRIDE, S, Q);
    for (int k = 0; k < nt; k++) {
        ew_torus_peaks(tor + k * EW_TO_STRIDE, sc.eps, S, Q, &pk);
        acc += ew_peaks_int(&sc, 0, tor + k * EW_TO_STRIDE, S, Q, &pk);
    }
    for (int k = 0; k < nc; k++) {
        ew_curve_peaks(cur + k * EW_CV_STRIDE, sc.eps, S, Q, &pk);
        acc += ew_peaks_int(&sc, 1, cur + k * EW_CV_STRIDE, S, Q, &pk);
    }
    out[j * width + i] = acc;
}

/* ---- test entry points (energy_wave_dev_*) ---------------------------------------- */

__kernel void ew_test_cubic(__global const float *abc, __global float *roots, __global int *nroots)
{
    int i = get_global_id(0);
    float r[3] = {0.0f, 0.0f, 0.0f};
    nroots[i] = ew_cubic(abc[3 * i], abc[3 * i + 1], abc[3 * i + 2], r);
    for (int k = 0; k < 3; k++) roots[3 * i + k] = k < nroots[i] ? r[k] : 0.0f;
}

__kernel void ew_test_bspline(__global const float *w, int nw, __global const float *t, __global float *out)
{
    int i = get_global_id(0);
    out[i] = ew_bspline(w, nw, t[i]);
}

__kernel void ew_test_curve_nearest(__global const float *cv, __global const float *p, __global float *dist,
                                    __global float *tparam)
{
    int i = get_global_id(0);
    float2 dt = ew_curve_nearest(cv, (float3)(p[3 * i], p[3 * i + 1], p[3 * i + 2]));
    dist[i] = dt.x;
    tparam[i] = dt.y;
}
