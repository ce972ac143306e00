/* eye_ref.c — see eye_ref.h. Plain, slow and double: window scans instead of walks. */
#include "eye_ref.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define EYE_REF_SQRT3 1.7320508075688772
#define EYE_REF_MAX_BOUNCES 4

static double eye_ref_dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* Lattice point (i, j): o + i*(1,0) + j*e2 (square: o = (1/2,1/2), e2 = (0,1); hex:
 * o = (1/2, sqrt3/4), e2 = (1/2, sqrt3/2)). */
static void eye_ref_point(int hex, long i, long j, double c[2])
{
    c[0] = 0.5 + (double)i + (hex ? 0.5 * (double)j : 0.0);
    c[1] = (hex ? 0.25 * EYE_REF_SQRT3 + 0.5 * EYE_REF_SQRT3 * (double)j : 0.5 + (double)j);
}

/* Calls fn for every lattice point in the box [x0,x1] x [y0,y1]. */
typedef void (*eye_ref_visit)(const double c[2], void *ctx);
static void eye_ref_box(int hex, double x0, double x1, double y0, double y1, eye_ref_visit fn, void *ctx)
{
    double dy = hex ? 0.5 * EYE_REF_SQRT3 : 1.0, oy = hex ? 0.25 * EYE_REF_SQRT3 : 0.5;
    for (long j = (long)floor((y0 - oy) / dy) - 1; j <= (long)ceil((y1 - oy) / dy) + 1; j++) {
        double shift = hex ? 0.5 * (double)j : 0.0;
        for (long i = (long)floor(x0 - 0.5 - shift) - 1; i <= (long)ceil(x1 - 0.5 - shift) + 1; i++) {
            double c[2];
            eye_ref_point(hex, i, j, c);
            if (c[0] >= x0 && c[0] <= x1 && c[1] >= y0 && c[1] <= y1) fn(c, ctx);
        }
    }
}

void eye_ref_nearest(int hex, double x, double y, double c[2])
{
    double best = INFINITY;
    double dy = hex ? 0.5 * EYE_REF_SQRT3 : 1.0, oy = hex ? 0.25 * EYE_REF_SQRT3 : 0.5;
    long j0 = (long)floor((y - oy) / dy);
    for (long j = j0 - 1; j <= j0 + 2; j++) {
        double shift = hex ? 0.5 * (double)j : 0.0;
        long i0 = (long)floor(x - 0.5 - shift);
        for (long i = i0 - 1; i <= i0 + 2; i++) {
            double p[2];
            eye_ref_point(hex, i, j, p);
            double d2 = (p[0] - x) * (p[0] - x) + (p[1] - y) * (p[1] - y);
            if (d2 < best) best = d2, c[0] = p[0], c[1] = p[1];
        }
    }
}

double eye_ref_cell_centre(double a)
{
    return a >= 0 ? floor(a) + 0.5 : ceil(a) - 0.5; /* (5.17) / (5.19) */
}

int eye_ref_refract(const double d[3], const double m[3], double eta, double out[3])
{
    double c = -eye_ref_dot(m, d), k = 1.0 - eta * eta * (1.0 - c * c);
    if (k < 0.0) return 0;
    for (int i = 0; i < 3; i++) out[i] = eta * d[i] + (eta * c - sqrt(k)) * m[i];
    return 1;
}

/* Roots of |o + t d - c| = r (d unit). */
static int eye_ref_roots(const double o[3], const double d[3], const double c[3], double r, double *t1, double *t2)
{
    double oc[3] = {o[0] - c[0], o[1] - c[1], o[2] - c[2]};
    double b = eye_ref_dot(oc, d), disc = b * b - (eye_ref_dot(oc, oc) - r * r);
    if (disc < 0) return 0;
    *t1 = -b - sqrt(disc);
    *t2 = -b + sqrt(disc);
    return 1;
}

/* ---- entry ---- */

struct eye_ref_entry_scan {
    const struct eye_ref_optics *o;
    double p[3], d[3], best_t, best_c[3];
};

static void eye_ref_entry_visit(const double c[2], void *ctx)
{
    struct eye_ref_entry_scan *s = ctx;
    double c3[3] = {c[0], c[1], -s->o->r}, t1, t2;
    if (eye_ref_roots(s->p, s->d, c3, s->o->r, &t1, &t2) && t2 >= 0 && t1 < s->best_t) {
        s->best_t = t1;
        memcpy(s->best_c, c3, sizeof c3);
    }
}

/* Exact: the smallest first root over every lens near the ray's path down to depth r;
 * a lens is entered only above depth r (digest 004 §2.4: the search ends there). */
static int eye_ref_enter_exact(const struct eye_ref_optics *o, const double p[3], const double d[3], double c[3],
                               double *t)
{
    struct eye_ref_entry_scan s = {o, {p[0], p[1], 0}, {d[0], d[1], d[2]}, INFINITY, {0}};
    double tr = o->r / -d[2], qx = p[0] + d[0] * tr, qy = p[1] + d[1] * tr, m = o->r + 1.0;
    eye_ref_box(o->hex, fmin(p[0], qx) - m, fmax(p[0], qx) + m, fmin(p[1], qy) - m, fmax(p[1], qy) + m,
                eye_ref_entry_visit, &s);
    if (!isfinite(s.best_t)) return 0;
    *t = fmax(s.best_t, 0.0);
    if (*t * -d[2] > o->r) return 0;
    memcpy(c, s.best_c, sizeof s.best_c);
    return 1;
}

/* The thesis's slice planes (5.23-5.27), with the cell of eqs. 5.17-5.22. */
static int eye_ref_enter_slices(const struct eye_ref_optics *o, const double p[3], const double d[3], double c[3],
                                double *t)
{
    for (int s = 0; s <= o->slices; s++) {
        double h = o->r * s / o->slices, ts = h / -d[2], cc[2], t1, t2;
        eye_ref_nearest(o->hex, p[0] + d[0] * ts, p[1] + d[1] * ts, cc);
        double c3[3] = {cc[0], cc[1], -o->r};
        if (eye_ref_roots(p, d, c3, o->r, &t1, &t2) && t2 >= 0) {
            memcpy(c, c3, sizeof c3);
            *t = fmax(t1, 0.0);
            return 1;
        }
    }
    return 0;
}

/* ---- internal pass ---- */

struct eye_ref_pass_scan {
    const struct eye_ref_optics *o;
    double org[3], dir[3], f[3], cur[3], best_t, best_c[3];
};

static int eye_ref_thesis4(int hex, const double dc[2], const double dir[3])
{
    if (hex) return dc[0] * dc[0] + dc[1] * dc[1] < 1.5 && dc[0] * dir[0] + dc[1] * dir[1] > 0;
    long ix = lround(dc[0]), iy = lround(dc[1]);
    if (fabs(dir[0]) >= fabs(dir[1])) return ix == (dir[0] > 0 ? 1 : -1) && labs(iy) <= 1;
    return iy == (dir[1] > 0 ? 1 : -1) && labs(ix) <= 1;
}

static void eye_ref_pass_visit(const double c[2], void *ctx)
{
    struct eye_ref_pass_scan *s = ctx;
    double r = s->o->r, c3[3] = {c[0], c[1], -r}, q[3] = {s->f[0] - c[0], s->f[1] - c[1], s->f[2] + r};
    double dc[2] = {c[0] - s->cur[0], c[1] - s->cur[1]}, t1, t2;
    if (eye_ref_dot(q, q) >= r * r || dc[0] * dc[0] + dc[1] * dc[1] < 1e-8) return;
    if (s->o->thesis4 && !eye_ref_thesis4(s->o->hex, dc, s->dir)) return;
    if (eye_ref_roots(s->org, s->dir, c3, r, &t1, &t2) && t2 > s->best_t) {
        s->best_t = t2;
        memcpy(s->best_c, c3, sizeof c3);
    }
}

/* Digest G5/G6: move to the overlapping lens with the farthest exit on the same ray. */
static double eye_ref_inner_pass(const struct eye_ref_optics *o, const double org[3], const double dir[3], double c[3],
                                 double tf, int *passes)
{
    while (*passes < o->passes) {
        struct eye_ref_pass_scan s = {o, {0}, {0}, {0}, {0}, tf * (1 + 1e-9) + 1e-9, {0}};
        memcpy(s.org, org, sizeof s.org);
        memcpy(s.dir, dir, sizeof s.dir);
        memcpy(s.cur, c, sizeof s.cur);
        for (int k = 0; k < 3; k++) s.f[k] = org[k] + dir[k] * tf;
        double m = o->r + 1.0;
        eye_ref_box(o->hex, s.f[0] - m, s.f[0] + m, s.f[1] - m, s.f[1] + m, eye_ref_pass_visit, &s);
        if (s.best_t <= tf * (1 + 1e-9) + 1e-9) break;
        memcpy(c, s.best_c, sizeof s.best_c);
        tf = s.best_t;
        (*passes)++;
    }
    return tf;
}

/* ---- the tracer ---- */

static void eye_ref_land(const struct eye_ref_optics *o, const double from[3], const double dir[3],
                         struct eye_ref_hit *h)
{
    if (dir[2] >= -1e-12) { /* G9 */
        h->status = EYE_REF_MISSED;
        return;
    }
    double t = (-o->plane - from[2]) / dir[2];
    h->land[0] = from[0] + dir[0] * t;
    h->land[1] = from[1] + dir[1] * t;
    h->status = EYE_REF_LANDED;
}

void eye_ref_trace(const struct eye_ref_optics *o, double px, double py, const double d[3], struct eye_ref_hit *h)
{
    double p[3] = {px, py, 0}, c[3], t, t1, tf;
    memset(h, 0, sizeof *h);
    int in = o->slices > 0 ? eye_ref_enter_slices(o, p, d, c, &t) : eye_ref_enter_exact(o, p, d, c, &t);
    if (!in) {
        eye_ref_land(o, p, d, h);
        return;
    }
    h->entered = 1;
    double org[3], dir[3];
    for (int k = 0; k < 3; k++) {
        org[k] = p[k] + d[k] * t;
        h->entry[k] = org[k];
        h->entry_normal[k] = (org[k] - c[k]) / o->r; /* (5.28) */
    }
    eye_ref_refract(d, h->entry_normal, 1.0 / o->n, dir);
    memcpy(h->r_in, dir, sizeof dir);
    if (!eye_ref_roots(org, dir, c, o->r, &t1, &tf)) tf = 0;
    for (;;) {
        tf = eye_ref_inner_pass(o, org, dir, c, tf, &h->passes);
        double f[3], nf[3], m[3], out[3];
        for (int k = 0; k < 3; k++) {
            f[k] = org[k] + dir[k] * tf;
            nf[k] = (f[k] - c[k]) / o->r;
            m[k] = -nf[k];
        }
        if (eye_ref_refract(dir, m, o->n, out)) {
            memcpy(h->exit, f, sizeof f);
            memcpy(h->exit_normal, nf, sizeof nf);
            memcpy(h->r_out, out, sizeof out);
            eye_ref_land(o, f, out, h);
            return;
        }
        if (o->tir == 2) {
            h->status = EYE_REF_ABSORBED;
            return;
        }
        if (o->tir == 1 || h->bounces == EYE_REF_MAX_BOUNCES) {
            h->status = EYE_REF_MISSED;
            return;
        }
        h->bounces++;
        double cosi = eye_ref_dot(dir, nf);
        for (int k = 0; k < 3; k++) dir[k] -= 2 * cosi * nf[k];
        memcpy(org, f, sizeof f);
        if (!eye_ref_roots(org, dir, c, o->r, &t1, &tf)) tf = 0;
    }
}

/* ---- measurements ---- */

double eye_ref_dark(int hex, double rho, double x, double y)
{
    double c[2];
    eye_ref_nearest(hex, x, y, c);
    return (x - c[0]) * (x - c[0]) + (y - c[1]) * (y - c[1]) < rho * rho ? 1.0 : 0.0;
}

double eye_ref_lens_dark(const struct eye_ref_optics *o, double rho, const double w[3], int m)
{
    double th = o->hex ? EYE_REF_SQRT3 : 1.0, sum = 0, d[3] = {-w[0], -w[1], -w[2]};
    for (int j = 0; j < m; j++)
        for (int i = 0; i < m; i++) {
            struct eye_ref_hit h;
            eye_ref_trace(o, (i + 0.5) / m, (j + 0.5) / m * th, d, &h);
            sum += h.status == EYE_REF_ABSORBED ? 1.0 : h.status == EYE_REF_LANDED ? eye_ref_dark(o->hex, rho, h.land[0], h.land[1]) : 0.0;
        }
    return sum / (m * m);
}

static void eye_ref_flood(const double *dk, int *lab, int g, int start, int id, double *sx, double *sy, double *sw,
                          double tmax, int *stack)
{
    int top = 0;
    stack[top++] = start;
    lab[start] = id;
    while (top) {
        int k = stack[--top], x = k % g, y = k / g;
        double tx = -tmax + 2 * tmax * x / (g - 1), ty = -tmax + 2 * tmax * y / (g - 1);
        *sx += dk[k] * tx;
        *sy += dk[k] * ty;
        *sw += dk[k];
        int nb[4] = {x > 0 ? k - 1 : -1, x < g - 1 ? k + 1 : -1, y > 0 ? k - g : -1, y < g - 1 ? k + g : -1};
        for (int q = 0; q < 4; q++)
            if (nb[q] >= 0 && !lab[nb[q]] && dk[nb[q]] > 0.5) {
                lab[nb[q]] = id;
                stack[top++] = nb[q];
            }
    }
}

int eye_ref_pupils(const struct eye_ref_optics *o, double rho, double tmax, int g, int m, double *cx, double *cy,
                   int max)
{
    double *dk = malloc(sizeof(double) * g * g);
    int *lab = calloc((size_t)g * g, sizeof(int)), *stack = malloc(sizeof(int) * g * g), n = 0;
    if (!dk || !lab || !stack) {
        free(dk);
        free(lab);
        free(stack);
        return -1;
    }
    for (int k = 0; k < g * g; k++) {
        double tx = -tmax + 2 * tmax * (k % g) / (g - 1), ty = -tmax + 2 * tmax * (k / g) / (g - 1);
        double l = sqrt(tx * tx + ty * ty + 1), w[3] = {tx / l, ty / l, 1 / l};
        dk[k] = eye_ref_lens_dark(o, rho, w, m);
    }
    for (int k = 0; k < g * g; k++) {
        if (lab[k] || dk[k] <= 0.5) continue;
        double sx = 0, sy = 0, sw = 0;
        eye_ref_flood(dk, lab, g, k, n + 1, &sx, &sy, &sw, tmax, stack);
        if (n < max) cx[n] = sx / sw, cy[n] = sy / sw;
        n++;
    }
    free(dk);
    free(lab);
    free(stack);
    return n;
}

/* ---- the thesis's frames ---- */

void eye_ref_uv_frame(const double P[3][3], const double T[3][2], double Pc[3], double Du[3], double Dv[3])
{
    double a = T[1][0] - T[0][0], b = T[2][0] - T[0][0], c = T[1][1] - T[0][1], d = T[2][1] - T[0][1];
    double det = a * d - b * c; /* A = [[a, b], [c, d]] = (T10, T20) */
    double inv[2][2] = {{d / det, -b / det}, {-c / det, a / det}};
    /* (5.12)/(5.13): (i, j) = A^-1 (1,0); (k, l) = A^-1 (0,1) */
    double i = inv[0][0], j = inv[1][0], k = inv[0][1], l = inv[1][1];
    for (int q = 0; q < 3; q++) {
        double p10 = P[1][q] - P[0][q], p20 = P[2][q] - P[0][q];
        Du[q] = i * p10 + j * p20;
        Dv[q] = k * p10 + l * p20;
        Pc[q] = P[0][q] - T[0][0] * Du[q] - T[0][1] * Dv[q];
    }
}

void eye_ref_lift(const double Pc[3], const double Du[3], const double Dv[3], const double P[3], double *a, double *b)
{
    double s[3] = {P[0] - Pc[0], P[1] - Pc[1], P[2] - Pc[2]};
    double uu = eye_ref_dot(Du, Du), vv = eye_ref_dot(Dv, Dv), uv = eye_ref_dot(Du, Dv);
    double su = eye_ref_dot(s, Du), sv = eye_ref_dot(s, Dv), den = uu * vv - uv * uv;
    *a = (vv * su - uv * sv) / den; /* (5.26) */
    *b = (uu * sv - uv * su) / den; /* (5.27) */
}
