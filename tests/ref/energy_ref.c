/* energy_ref.c — double-precision reference for the energy_wave effect (see energy_ref.h).
 *
 * Straightforward code over clever code: every formula is the digest's (with its §8
 * corrections), evaluated in double, with no shortcuts shared with the OpenCL kernel.
 * The converged integral splits [0,1] at each primitive's closest approach and at the
 * edges of its core (|distance| along the ray), then runs adaptive Gauss-Kronrod. */
#include "energy_ref.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

/* ---------------------------------------------------------------- vectors */

static double ref_dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static void ref_sub(const double a[3], const double b[3], double out[3])
{
    for (int k = 0; k < 3; k++) out[k] = a[k] - b[k];
}

static void ref_cross(const double a[3], const double b[3], double out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

static void ref_normalize(double v[3])
{
    double n = sqrt(ref_dot(v, v));
    if (n > 0)
        for (int k = 0; k < 3; k++) v[k] /= n;
}

static void ref_lerp(const double S[3], const double E[3], double s, double out[3])
{
    for (int k = 0; k < 3; k++) out[k] = (1.0 - s) * S[k] + s * E[k];
}

/* ---------------------------------------------------------------- JSON scene */

static double ref_num(const cJSON *o, const char *name, double def)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, name);
    return cJSON_IsNumber(v) ? v->valuedouble : def;
}

static void ref_vec(const cJSON *o, const char *name, const double def[3], double out[3])
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, name);
    for (int k = 0; k < 3; k++) out[k] = def[k];
    if (!cJSON_IsArray(v) || cJSON_GetArraySize(v) != 3) return;
    for (int k = 0; k < 3; k++) out[k] = cJSON_GetArrayItem(v, k)->valuedouble;
}

static const cJSON *ref_list(const cJSON *doc, const char *name, int *n, char *msg, size_t len)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(doc, name);
    *n = cJSON_IsArray(v) ? cJSON_GetArraySize(v) : 0;
    if (*n > ENERGY_REF_MAX_PRIMS) {
        snprintf(msg, len, "%s: %d items, reference holds %d", name, *n, ENERGY_REF_MAX_PRIMS);
        return NULL;
    }
    return v;
}

static const double ref_zero[3] = {0, 0, 0};
static const double ref_zaxis[3] = {0, 0, 1};

static int ref_parse_sources(const cJSON *doc, struct energy_ref_scene *sc, char *msg, size_t len)
{
    const cJSON *pl = ref_list(doc, "points", &sc->npoints, msg, len);
    const cJSON *ll = ref_list(doc, "lines", &sc->nlines, msg, len);
    const cJSON *tl = ref_list(doc, "tori", &sc->ntori, msg, len);
    if ((sc->npoints && !pl) || (sc->nlines && !ll) || (sc->ntori && !tl)) return -1;
    for (int i = 0; i < sc->npoints; i++) {
        const cJSON *o = cJSON_GetArrayItem(pl, i);
        ref_vec(o, "pos", ref_zero, sc->points[i].pos);
        sc->points[i].coef = ref_num(o, "coef", 1.0);
    }
    for (int i = 0; i < sc->nlines; i++) {
        const cJSON *o = cJSON_GetArrayItem(ll, i);
        ref_vec(o, "pos", ref_zero, sc->lines[i].pos);
        ref_vec(o, "dir", ref_zaxis, sc->lines[i].dir);
        ref_normalize(sc->lines[i].dir);
        sc->lines[i].coef = ref_num(o, "coef", 1.0);
    }
    for (int i = 0; i < sc->ntori; i++) {
        const cJSON *o = cJSON_GetArrayItem(tl, i);
        ref_vec(o, "center", ref_zero, sc->tori[i].center);
        ref_vec(o, "axis", ref_zaxis, sc->tori[i].axis);
        ref_normalize(sc->tori[i].axis);
        sc->tori[i].R = ref_num(o, "R", 1.0);
        sc->tori[i].coef = ref_num(o, "coef", 1.0);
    }
    return 0;
}

static int ref_parse_curves(const cJSON *doc, double frame, int animate, struct energy_ref_scene *sc,
                            char *msg, size_t len)
{
    const cJSON *cl = ref_list(doc, "curves", &sc->ncurves, msg, len);
    if (sc->ncurves && !cl) return -1;
    for (int i = 0; i < sc->ncurves; i++) {
        struct energy_ref_curve *c = &sc->curves[i];
        const cJSON *o = cJSON_GetArrayItem(cl, i), *w = cJSON_GetObjectItemCaseSensitive(o, "W");
        static const char *names[3] = {"p0", "p1", "p2"};
        for (int k = 0; k < 3; k++) ref_vec(o, names[k], ref_zero, c->b[k]);
        c->coef = ref_num(o, "coef", 1.0);
        c->nw = cJSON_IsArray(w) ? cJSON_GetArraySize(w) : 0;
        if (c->nw < 3 || c->nw > ENERGY_REF_MAX_W) {
            snprintf(msg, len, "curves[%d].W: %d weights (need 3..%d)", i, c->nw, ENERGY_REF_MAX_W);
            return -1;
        }
        double anim[ENERGY_REF_MAX_W];
        energy_ref_loop_weights(frame, c->nw, anim);
        for (int k = 0; k < c->nw; k++)
            c->w[k] = cJSON_GetArrayItem(w, k)->valuedouble * (animate ? anim[k] : 1.0);
    }
    return 0;
}

static void ref_parse_camera(const cJSON *doc, struct energy_ref_camera *cam)
{
    static const double eye[3] = {0, 0, -5}, up[3] = {0, 1, 0};
    ref_vec(doc, "eye", eye, cam->eye);
    ref_vec(doc, "center", ref_zero, cam->center);
    ref_vec(doc, "up", up, cam->up);
    cam->size = ref_num(doc, "size", 4.0);
    cam->nu = ref_num(doc, "nu", 2.0);
    cam->width = (int)ref_num(doc, "width", 32);
    cam->height = (int)ref_num(doc, "height", 32);
}

int energy_ref_scene_from_json(const cJSON *doc, double sim_time, struct energy_ref_scene *sc, char *msg,
                               size_t msg_len)
{
    memset(sc, 0, sizeof *sc);
    if (!cJSON_IsObject(doc)) {
        snprintf(msg, msg_len, "document is not an object");
        return -1;
    }
    double frame = sim_time * ref_num(doc, "anim_rate", 0.0);
    int animate = cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(doc, "animate"));
    if (ref_parse_sources(doc, sc, msg, msg_len) || ref_parse_curves(doc, frame, animate, sc, msg, msg_len))
        return -1;
    sc->epsilon = ref_num(doc, "epsilon", 1e-3);
    sc->alpha = ref_num(doc, "alpha", 1.0);
    sc->beta = ref_num(doc, "beta", 1.0);
    sc->divisions = (int)ref_num(doc, "divisions", 200);
    ref_parse_camera(doc, &sc->cam);
    return 0;
}

void energy_ref_texel_ray(const struct energy_ref_scene *sc, int i, int j, double S[3], double E[3])
{
    const struct energy_ref_camera *c = &sc->cam;
    double f[3], r[3], u[3];
    ref_sub(c->center, c->eye, f);
    ref_normalize(f);
    ref_cross(f, c->up, r);
    ref_normalize(r);
    ref_cross(r, f, u);
    double x = ((i + 0.5) / c->width - 0.5) * c->size;
    double y = (0.5 - (j + 0.5) / c->height) * c->size * ((double)c->height / c->width);
    for (int k = 0; k < 3; k++) {
        S[k] = c->center[k] + x * r[k] + y * u[k];
        E[k] = c->eye[k] + c->nu * (S[k] - c->eye[k]);
    }
}

/* ---------------------------------------------------------------- field */

double energy_ref_point_dist(const struct energy_ref_point *p, const double P[3])
{
    double d[3];
    ref_sub(P, p->pos, d);
    return sqrt(ref_dot(d, d));
}

double energy_ref_line_dist(const struct energy_ref_line *l, const double P[3])
{
    double d[3];
    ref_sub(P, l->pos, d);
    double along = ref_dot(d, l->dir), perp[3];
    for (int k = 0; k < 3; k++) perp[k] = d[k] - along * l->dir[k]; /* no cancellation near the line */
    return sqrt(ref_dot(perp, perp));
}

/* Local frame: z along the axis; rho is rotation invariant, so no x/y basis is needed. */
double energy_ref_torus_dist(const struct energy_ref_torus *t, const double P[3])
{
    double d[3];
    ref_sub(P, t->center, d);
    double z = ref_dot(d, t->axis), perp[3];
    for (int k = 0; k < 3; k++) perp[k] = d[k] - z * t->axis[k];
    double rho = sqrt(ref_dot(perp, perp)) - t->R;
    return sqrt(rho * rho + z * z);
}

double energy_ref_curve_term(const struct energy_ref_curve *c, double eps, const double P[3])
{
    double t, d = energy_ref_curve_nearest(c->b, P, &t);
    return energy_ref_bspline(c->nw, c->w, t) / fmax(eps, d);
}

double energy_ref_psi(const struct energy_ref_scene *sc, const double P[3])
{
    double eps = sc->epsilon, psi = 0;
    for (int i = 0; i < sc->npoints; i++) psi += sc->points[i].coef / fmax(eps, energy_ref_point_dist(&sc->points[i], P));
    for (int i = 0; i < sc->nlines; i++) psi += sc->lines[i].coef / fmax(eps, energy_ref_line_dist(&sc->lines[i], P));
    for (int i = 0; i < sc->ntori; i++) psi += sc->tori[i].coef / fmax(eps, energy_ref_torus_dist(&sc->tori[i], P));
    for (int i = 0; i < sc->ncurves; i++) psi += sc->curves[i].coef * energy_ref_curve_term(&sc->curves[i], eps, P);
    return psi;
}

double energy_ref_zeta(const struct energy_ref_scene *sc, double s)
{
    if (sc->no_attenuation) return 1.0;
    return sc->alpha / ((s + sc->beta) * (s + sc->beta));
}

/* ---------------------------------------------------------------- cubic */

static double ref_cubic_value(double a, double b, double c, double x) { return ((x + a) * x + b) * x + c; }

static double ref_cubic_polish(double a, double b, double c, double x)
{
    double f = ref_cubic_value(a, b, c, x), d = (3 * x + 2 * a) * x + b;
    if (d == 0) return x;
    double y = x - f / d;
    return fabs(ref_cubic_value(a, b, c, y)) < fabs(f) ? y : x;
}

static void ref_sort3(double *r, int n)
{
    for (int i = 1; i < n; i++)
        for (int k = i; k > 0 && r[k] < r[k - 1]; k--) {
            double t = r[k];
            r[k] = r[k - 1];
            r[k - 1] = t;
        }
}

int energy_ref_cubic(double a, double b, double c, double roots[3])
{
    double p = -a * a / 9 + b / 3, q = a * a * a / 27 - a * b / 6 + c / 2, r = p * p * p + q * q;
    double scale = q * q + fabs(p * p * p);
    int n;
    if (scale == 0) { /* p = q = 0: triple root */
        roots[0] = -a / 3;
        n = 1;
    } else if (r > 16 * 2.2e-16 * scale || p >= 0) { /* one real root */
        double sr = sqrt(fmax(r, 0));
        roots[0] = cbrt(-q + sr) + cbrt(-q - sr) - a / 3;
        n = 1;
    } else { /* three real roots (r <= 0, up to rounding; includes the double root) */
        double m = 2 * sqrt(-p), arg = -q / sqrt(-p * p * p);
        double phi = acos(arg > 1 ? 1 : (arg < -1 ? -1 : arg));
        for (int k = 0; k < 3; k++) roots[k] = m * cos((phi + 2 * M_PI * k) / 3) - a / 3;
        n = 3;
    }
    for (int k = 0; k < n; k++) roots[k] = ref_cubic_polish(a, b, c, ref_cubic_polish(a, b, c, roots[k]));
    ref_sort3(roots, n);
    return n;
}

/* ---------------------------------------------------------------- nearest point */

void energy_ref_curve_eval(const double b[3][3], double t, double out[3])
{
    double u = 1 - t;
    for (int k = 0; k < 3; k++) out[k] = u * u * b[0][k] + 2 * t * u * b[1][k] + t * t * b[2][k];
}

static double ref_curve_dist_at(const double b[3][3], const double P[3], double t)
{
    double C[3], d[3];
    energy_ref_curve_eval(b, t, C);
    ref_sub(C, P, d);
    return sqrt(ref_dot(d, d));
}

/* Newton on g(t) = C'(t).(C(t) - P) from t, kept in [0,1]. */
static double ref_nearest_polish(const double C0P[3], const double C1[3], const double C2[3], double t)
{
    for (int it = 0; it < 2; it++) {
        double Ct[3], dC[3];
        for (int k = 0; k < 3; k++) {
            Ct[k] = C0P[k] + (C1[k] + C2[k] * t) * t;
            dC[k] = C1[k] + 2 * C2[k] * t;
        }
        double g = ref_dot(dC, Ct), dg = ref_dot(dC, dC) + 2 * ref_dot(C2, Ct);
        if (dg <= 0) break;
        t -= g / dg;
        t = t < 0 ? 0 : (t > 1 ? 1 : t);
    }
    return t;
}

double energy_ref_curve_nearest(const double b[3][3], const double P[3], double *t_out)
{
    double C0P[3], C1[3], C2[3], cand[5];
    int n = 0;
    for (int k = 0; k < 3; k++) {
        C0P[k] = b[0][k] - P[k];
        C1[k] = 2 * (b[1][k] - b[0][k]);
        C2[k] = b[0][k] - 2 * b[1][k] + b[2][k];
    }
    double c22 = ref_dot(C2, C2), c11 = ref_dot(C1, C1);
    cand[n++] = 0;
    cand[n++] = 1;
    if (c22 <= 1e-14 * c11) { /* straight (C2 ~ 0): linear case */
        if (c11 > 0) cand[n++] = fmin(1, fmax(0, -ref_dot(C1, C0P) / c11));
    } else {
        double r[3], k2 = 2 * c22;
        int nr = energy_ref_cubic(3 * ref_dot(C1, C2) / k2, (2 * ref_dot(C2, C0P) + c11) / k2,
                                  ref_dot(C1, C0P) / k2, r);
        for (int k = 0; k < nr; k++) cand[n++] = fmin(1, fmax(0, r[k]));
    }
    double best = INFINITY, bt = 0;
    for (int k = 0; k < n; k++) {
        double tk = (k >= 2) ? ref_nearest_polish(C0P, C1, C2, cand[k]) : cand[k];
        double d = ref_curve_dist_at(b, P, tk);
        if (d < best) {
            best = d;
            bt = tk;
        }
    }
    if (t_out) *t_out = bt;
    return best;
}

double energy_ref_curve_nearest_brute(const double b[3][3], const double P[3], int samples, double *t_out)
{
    double best = INFINITY, bt = 0;
    for (int k = 0; k <= samples; k++) {
        double t = (double)k / samples, d = ref_curve_dist_at(b, P, t);
        if (d < best) {
            best = d;
            bt = t;
        }
    }
    double lo = fmax(0, bt - 1.0 / samples), hi = fmin(1, bt + 1.0 / samples), g = (sqrt(5) - 1) / 2;
    for (int it = 0; it < 60; it++) { /* golden section inside the best sample's bracket */
        double x1 = hi - g * (hi - lo), x2 = lo + g * (hi - lo);
        if (ref_curve_dist_at(b, P, x1) < ref_curve_dist_at(b, P, x2)) hi = x2; else lo = x1;
    }
    double tm = 0.5 * (lo + hi), dm = ref_curve_dist_at(b, P, tm);
    if (dm < best) {
        best = dm;
        bt = tm;
    }
    if (t_out) *t_out = bt;
    return best;
}

/* ---------------------------------------------------------------- B-spline */

int energy_ref_knots(int nw, double *U)
{
    int m = nw + 3;
    for (int i = 0; i < 3; i++) {
        U[i] = 0;
        U[m - 1 - i] = 1;
    }
    for (int i = 1; i <= nw - 3; i++) U[2 + i] = (double)i / (nw - 2);
    return m;
}

static double ref_ratio(double num, double den) { return den == 0 ? 0 : num / den; }

/* Cox-de Boor (3.24) to degree 2, 0/0 := 0, the last non-empty span closed at t = 1. */
static void ref_basis_all(int nw, double t, double *N2)
{
    double U[ENERGY_REF_MAX_W + 3], N[ENERGY_REF_MAX_W + 3];
    int m = energy_ref_knots(nw, U);
    t = t < 0 ? 0 : (t > 1 ? 1 : t);
    for (int i = 0; i < m - 1; i++) N[i] = (U[i] <= t && t < U[i + 1]) ? 1 : 0;
    if (t >= 1) N[nw - 1] = 1; /* span [u_{n-1}, u_n) = [(n-3)/(n-2), 1] closed */
    for (int k = 1; k <= 2; k++)
        for (int i = 0; i < m - 1 - k; i++)
            N[i] = ref_ratio(t - U[i], U[i + k] - U[i]) * N[i] +
                   ref_ratio(U[i + k + 1] - t, U[i + k + 1] - U[i + 1]) * N[i + 1];
    for (int i = 0; i < nw; i++) N2[i] = N[i];
}

double energy_ref_bspline_basis(int nw, int i, double t)
{
    double N[ENERGY_REF_MAX_W + 3];
    ref_basis_all(nw, t, N);
    return (i >= 0 && i < nw) ? N[i] : 0;
}

double energy_ref_bspline(int nw, const double *w, double t)
{
    double N[ENERGY_REF_MAX_W + 3], s = 0;
    ref_basis_all(nw, t, N);
    for (int i = 0; i < nw; i++) s += w[i] * N[i];
    return s;
}

void energy_ref_anim_weights(double frame, int n, double *w)
{
    for (int i = 0; i < n; i++) {
        double th = (frame - 7.0 * i) * M_PI / 25.0;
        if (th < 0 || th > 2 * M_PI) th = 0;
        double v = (-cos(th) + 0.8) / 1.5;
        w[i] = v < 0 ? 0 : (v > 1 ? 1 : v);
    }
}

void energy_ref_loop_weights(double frame, int n, double *w)
{
    double P = 7.0 * n + 10, life = 7.0 * (n - 1) + 50, one[ENERGY_REF_MAX_W];
    for (int i = 0; i < n; i++) w[i] = 0;
    for (double m = ceil((frame - life) / P); m * P <= frame; m++) {
        energy_ref_anim_weights(frame - m * P, n, one);
        for (int i = 0; i < n; i++) w[i] += one[i];
    }
    for (int i = 0; i < n; i++) w[i] = w[i] > 1 ? 1 : w[i];
}

/* ---------------------------------------------------------------- integrators */

double energy_ref_simpson(energy_ref_fn f, void *ctx, double a, double b, int n)
{
    double h = (b - a) / n, sum = f(a, ctx) + f(b, ctx);
    for (int k = 1; k < n; k++) sum += (k % 2 ? 4.0 : 2.0) * f(a + k * h, ctx);
    return sum * h / 3.0;
}

static const double ref_xgk[8] = {0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
                                  0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
                                  0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
                                  0.207784955007898467600689403773245, 0.0};
static const double ref_wgk[8] = {0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
                                  0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
                                  0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
                                  0.204432940075298892414161999234649, 0.209482141084727828012999174891714};
static const double ref_wg[4] = {0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
                                 0.381830050505118944950369775488975, 0.417959183673469387755102040816327};

/* Kronrod 15-point value on [a, b]; *err = |K15 - G7|. */
static double ref_gk15(energy_ref_fn f, void *ctx, double a, double b, double *err, double *absval)
{
    double c = 0.5 * (a + b), h = 0.5 * (b - a), fc = f(c, ctx);
    double k = fc * ref_wgk[7], g = fc * ref_wg[3], ab = fabs(fc) * ref_wgk[7];
    for (int j = 0; j < 7; j++) {
        double f1 = f(c - h * ref_xgk[j], ctx), f2 = f(c + h * ref_xgk[j], ctx);
        k += ref_wgk[j] * (f1 + f2);
        ab += ref_wgk[j] * (fabs(f1) + fabs(f2));
        if (j % 2) g += ref_wg[j / 2] * (f1 + f2);
    }
    *err = fabs((k - g) * h);
    if (absval) *absval = ab * h;
    return k * h;
}

static double ref_adapt(energy_ref_fn f, void *ctx, double a, double b, double tol, int depth)
{
    double err, v = ref_gk15(f, ctx, a, b, &err, NULL);
    if (err <= tol * (b - a) || depth >= 60 || b - a < 1e-10) return v;
    double m = 0.5 * (a + b);
    return ref_adapt(f, ctx, a, m, tol, depth + 1) + ref_adapt(f, ctx, m, b, tol, depth + 1);
}

/* Integrates over the sorted cut points; tolerance is rel times the integral of |f|. */
static double ref_adaptive_cuts(energy_ref_fn f, void *ctx, const double *cut, int n, double rel)
{
    double mag = 0, err, ab, sum = 0;
    for (int i = 0; i + 1 < n; i++) {
        ref_gk15(f, ctx, cut[i], cut[i + 1], &err, &ab);
        mag += ab;
    }
    double tol = rel * (mag > 0 ? mag : 1e-300) / (cut[n - 1] - cut[0]);
    for (int i = 0; i + 1 < n; i++) sum += ref_adapt(f, ctx, cut[i], cut[i + 1], tol, 0);
    return sum;
}

double energy_ref_adaptive(energy_ref_fn f, void *ctx, double a, double b, double rel)
{
    double cut[2] = {a, b};
    return ref_adaptive_cuts(f, ctx, cut, 2, rel);
}

/* ---------------------------------------------------------------- ray integrals */

struct ref_ray {
    const struct energy_ref_scene *sc;
    double S[3], E[3];
};

static double ref_ray_integrand(double s, void *ctx)
{
    const struct ref_ray *r = ctx;
    double P[3];
    ref_lerp(r->S, r->E, s, P);
    return energy_ref_psi(r->sc, P) * energy_ref_zeta(r->sc, s);
}

double energy_ref_ray_simpson(const struct energy_ref_scene *sc, const double S[3], const double E[3], int n)
{
    struct ref_ray r = {.sc = sc};
    memcpy(r.S, S, sizeof r.S);
    memcpy(r.E, E, sizeof r.E);
    return energy_ref_simpson(ref_ray_integrand, &r, 0, 1, n);
}

#define REF_MAX_CUTS (4 * ENERGY_REF_MAX_PRIMS * 4 * 3 + 64)

struct ref_cuts {
    double v[REF_MAX_CUTS];
    int n;
};

static void ref_cut_add(struct ref_cuts *c, double s)
{
    if (c->n < REF_MAX_CUTS && s > 0 && s < 1) c->v[c->n++] = s;
}

/* Closest approach s* with core half-width w (both in s units): cut at s*, s* +- w, s* +- 4w. */
static void ref_cut_peak(struct ref_cuts *c, double s, double w)
{
    ref_cut_add(c, s);
    ref_cut_add(c, s - w);
    ref_cut_add(c, s + w);
    ref_cut_add(c, s - 4 * w);
    ref_cut_add(c, s + 4 * w);
}

typedef double (*ref_dist_fn)(const void *prim, const double P[3]);

static double ref_dist_along(ref_dist_fn d, const void *prim, const double S[3], const double E[3], double s)
{
    double P[3];
    ref_lerp(S, E, s, P);
    return d(prim, P);
}

/* Local minima of a primitive's distance along the ray: coarse scan, golden refinement. */
static void ref_cut_search(struct ref_cuts *c, ref_dist_fn d, const void *prim, const double S[3],
                           const double E[3], double len)
{
    enum { N = 96 };
    double v[N + 1], g = (sqrt(5) - 1) / 2;
    for (int k = 0; k <= N; k++) v[k] = ref_dist_along(d, prim, S, E, (double)k / N);
    for (int k = 0; k <= N; k++) {
        if ((k > 0 && v[k] > v[k - 1]) || (k < N && v[k] > v[k + 1])) continue;
        double lo = fmax(0, (k - 1.0) / N), hi = fmin(1, (k + 1.0) / N);
        for (int it = 0; it < 50; it++) {
            double x1 = hi - g * (hi - lo), x2 = lo + g * (hi - lo);
            if (ref_dist_along(d, prim, S, E, x1) < ref_dist_along(d, prim, S, E, x2)) hi = x2; else lo = x1;
        }
        double sm = 0.5 * (lo + hi);
        ref_cut_peak(c, sm, ref_dist_along(d, prim, S, E, sm) / len);
    }
}

static double ref_d_torus(const void *p, const double P[3]) { return energy_ref_torus_dist(p, P); }
static double ref_d_curve(const void *p, const double P[3])
{
    return energy_ref_curve_nearest(((const struct energy_ref_curve *)p)->b, P, NULL);
}

static void ref_cut_analytic(struct ref_cuts *c, const double q[3], double len)
{
    if (q[0] <= 0) return;
    double s = -q[1] / q[0], h2 = q[2] - q[1] * q[1] / q[0];
    ref_cut_peak(c, s, sqrt(h2 > 0 ? h2 : 0) / len);
}

static int ref_cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static void ref_collect_cuts(const struct energy_ref_scene *sc, const double S[3], const double E[3],
                             struct ref_cuts *c)
{
    double Q[3], q[3];
    ref_sub(E, S, Q);
    double len = sqrt(ref_dot(Q, Q));
    c->n = 0;
    for (int k = 0; k <= 16; k++) c->v[c->n++] = k / 16.0;
    for (int i = 0; i < sc->npoints; i++) {
        energy_ref_point_quad(sc->points[i].pos, S, E, q);
        ref_cut_analytic(c, q, len);
    }
    for (int i = 0; i < sc->nlines; i++) {
        energy_ref_line_quad(sc->lines[i].pos, sc->lines[i].dir, S, E, q);
        ref_cut_analytic(c, q, len);
    }
    for (int i = 0; i < sc->ntori; i++) ref_cut_search(c, ref_d_torus, &sc->tori[i], S, E, len);
    for (int i = 0; i < sc->ncurves; i++) ref_cut_search(c, ref_d_curve, &sc->curves[i], S, E, len);
    qsort(c->v, c->n, sizeof c->v[0], ref_cmp);
    int m = 0;
    for (int k = 0; k < c->n; k++)
        if (m == 0 || c->v[k] - c->v[m - 1] > 1e-12) c->v[m++] = c->v[k];
    c->v[m - 1] = 1; /* the last cut is 1 (dedupe may have dropped it for a neighbour) */
    c->n = m;
}

double energy_ref_ray_converged(const struct energy_ref_scene *sc, const double S[3], const double E[3])
{
    struct ref_ray r = {.sc = sc};
    memcpy(r.S, S, sizeof r.S);
    memcpy(r.E, E, sizeof r.E);
    struct ref_cuts cuts;
    ref_collect_cuts(sc, S, E, &cuts);
    return ref_adaptive_cuts(ref_ray_integrand, &r, cuts.v, cuts.n, 1e-10);
}

double energy_ref_texel_simpson(const struct energy_ref_scene *sc, int i, int j, int n)
{
    double S[3], E[3];
    energy_ref_texel_ray(sc, i, j, S, E);
    return energy_ref_ray_simpson(sc, S, E, n);
}

double energy_ref_texel_converged(const struct energy_ref_scene *sc, int i, int j)
{
    double S[3], E[3];
    energy_ref_texel_ray(sc, i, j, S, E);
    return energy_ref_ray_converged(sc, S, E);
}

/* ---------------------------------------------------------------- closed forms */

void energy_ref_point_quad(const double M[3], const double S[3], const double E[3], double q[3])
{
    double Q[3], SM[3];
    ref_sub(E, S, Q);
    ref_sub(S, M, SM);
    q[0] = ref_dot(Q, Q);
    q[1] = ref_dot(Q, SM);
    q[2] = ref_dot(SM, SM);
}

void energy_ref_line_quad(const double M[3], const double D[3], const double S[3], const double E[3],
                          double q[3])
{
    double Q[3], SM[3];
    ref_sub(E, S, Q);
    ref_sub(S, M, SM);
    double qd = ref_dot(Q, D), sd = ref_dot(SM, D);
    q[0] = ref_dot(Q, Q) - qd * qd;
    q[1] = ref_dot(Q, SM) - qd * sd;
    q[2] = ref_dot(SM, SM) - sd * sd;
}

double energy_ref_abe_integral(double A, double B, double C)
{
    double k = sqrt(A * C - B * B);
    return (asinh((A + B) / k) - asinh(B / k)) / sqrt(A);
}

double energy_ref_zeta_integral(double A, double B, double C, double alpha, double beta)
{
    double a = A * beta * beta - 2 * B * beta + C, b = B - A * beta, c = A;
    double k = sqrt(a * c - b * b);
    double y1 = 1 / beta, y0 = 1 / (1 + beta);
    double g1 = sqrt(a * y1 * y1 + 2 * b * y1 + c) / a - (b / a) / sqrt(a) * asinh((a * y1 + b) / k);
    double g0 = sqrt(a * y0 * y0 + 2 * b * y0 + c) / a - (b / a) / sqrt(a) * asinh((a * y0 + b) / k);
    return alpha * (g1 - g0);
}
