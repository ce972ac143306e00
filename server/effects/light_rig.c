/* light_rig.c — the energy wave's light rig (seed 003; digest 003 §7, PROTOCOL.md §7.7).
 *
 * Owns the rig's parameter checks and settings and the per-frame segments: energy_wave
 * hands over its unpacked sources and this frame's curve weights (a few hundred doubles,
 * microseconds) and encodes the result with protocol/fxs_rig.c. No state of its own. */
#include "light_rig.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "../vec3.h"

/* ---- B-spline strength (seed 000 eqs. 3.24-3.26) ----------------------------------- */

double light_rig_bspline(int nw, const double *w, double t)
{
    if (nw < 3) return nw > 0 ? w[0] : 0.0;
    int m = nw + 3; /* knots U = [0,0,0, 1/(n-2), ..., (n-3)/(n-2), 1,1,1] */
    double U[WAVE_MAX_W + 3];
    for (int i = 0; i < m; i++) {
        double u = (i - 2.0) / (nw - 2.0);
        U[i] = u < 0 ? 0 : (u > 1 ? 1 : u);
    }
    if (t < 0) t = 0;
    if (t > 1) t = 1;
    /* degree 0: the span holding t; the last non-empty span is closed at t = 1 */
    double N[WAVE_MAX_W + 3] = {0};
    int span = -1;
    for (int i = 0; i < m - 1; i++)
        if (U[i] < U[i + 1] && ((t >= U[i] && t < U[i + 1]) || (t == 1.0 && U[i + 1] == 1.0))) span = i;
    if (span < 0) return 0.0;
    N[span] = 1.0;
    for (int k = 1; k <= 2; k++)
        for (int i = 0; i < m - k - 1; i++) {
            double a = U[i + k] > U[i] ? (t - U[i]) / (U[i + k] - U[i]) * N[i] : 0.0;
            double b = U[i + k + 1] > U[i + 1] ? (U[i + k + 1] - t) / (U[i + k + 1] - U[i + 1]) * N[i + 1] : 0.0;
            N[i] = a + b;
        }
    double s = 0;
    for (int i = 0; i < nw; i++) s += w[i] * N[i];
    return s;
}

/* ---- segments ------------------------------------------------------------------------ */

static struct fxs_rig_seg *lr_add(struct fxs_rig *rig, int source, int index)
{
    if (rig->n_seg >= FXS_RIG_MAX_SEG) return NULL; /* extra segments are dropped (§7.7) */
    struct fxs_rig_seg *s = &rig->seg[rig->n_seg++];
    memset(s, 0, sizeof *s);
    s->source = source;
    s->index = index;
    return s;
}

/* A chord from a to b as a capsule segment. */
static void lr_chord(struct fxs_rig_seg *s, const double a[3], const double b[3], double strength)
{
    double d[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    double len = vec3_normalize(d);
    if (len == 0) d[2] = 1.0;
    memcpy(s->c, a, sizeof s->c);
    memcpy(s->d, d, sizeof s->d);
    s->a_lo = 0;
    s->a_hi = len;
    s->strength = strength;
}

static void lr_bezier(const double b[3][3], double t, double out[3])
{
    double u = 1 - t;
    for (int k = 0; k < 3; k++) out[k] = u * u * b[0][k] + 2 * u * t * b[1][k] + t * t * b[2][k];
}

static int lr_points_lines(const struct wave_sources *src, struct fxs_rig *rig)
{
    for (int i = 0; i < src->np; i++) {
        struct fxs_rig_seg *s = lr_add(rig, FXS_RIG_POINT, i);
        if (!s) return -1;
        memcpy(s->c, src->point[i].pos, sizeof s->c);
        s->d[2] = 1.0; /* any unit vector: a_lo = a_hi = 0 */
        s->strength = src->point[i].coef;
    }
    for (int i = 0; i < src->nl; i++) {
        struct fxs_rig_seg *s = lr_add(rig, FXS_RIG_LINE, i);
        if (!s) return -1;
        memcpy(s->c, src->line[i].pos, sizeof s->c);
        memcpy(s->d, src->line[i].dir, sizeof s->d);
        s->a_lo = -INFINITY;
        s->a_hi = INFINITY;
        s->strength = src->line[i].coef;
    }
    return 0;
}

static int lr_tori(const struct wave_sources *src, int nseg, struct fxs_rig *rig)
{
    for (int i = 0; i < src->nt; i++) {
        const struct wave_torus *t = &src->torus[i];
        for (int j = 0; j < nseg; j++) {
            double a[3], b[3], t0 = 2 * M_PI * j / nseg, t1 = 2 * M_PI * (j + 1) / nseg;
            for (int k = 0; k < 3; k++) {
                a[k] = t->c[k] + t->R * (cos(t0) * t->e1[k] + sin(t0) * t->e2[k]);
                b[k] = t->c[k] + t->R * (cos(t1) * t->e1[k] + sin(t1) * t->e2[k]);
            }
            struct fxs_rig_seg *s = lr_add(rig, FXS_RIG_TORUS, i);
            if (!s) return -1;
            lr_chord(s, a, b, t->coef);
        }
    }
    return 0;
}

/* Curve chords, each with coef · S(t) at its middle under this frame's weights (the same
 * pulse as the texture's kernel sees). */
static void lr_curves(const struct wave_sources *src, const double w[][WAVE_MAX_W], int nseg, struct fxs_rig *rig)
{
    for (int i = 0; i < src->nc; i++) {
        const struct wave_curve *c = &src->curve[i];
        for (int j = 0; j < nseg; j++) {
            double a[3], e[3];
            lr_bezier(c->b, (double)j / nseg, a);
            lr_bezier(c->b, (double)(j + 1) / nseg, e);
            struct fxs_rig_seg *s = lr_add(rig, FXS_RIG_CURVE, i);
            if (!s) return;
            lr_chord(s, a, e, c->coef * light_rig_bspline(c->nw, w[i], (j + 0.5) / nseg));
        }
    }
}

void light_rig_build(const struct light_rig *lr, const struct wave_sources *src, const double w[][WAVE_MAX_W],
                     struct fxs_rig *out)
{
    out->n_seg = 0;
    if (lr_points_lines(src, out) == 0 && lr_tori(src, lr->torus_segments, out) == 0)
        lr_curves(src, w, lr->curve_segments, out);
    out->k = lr->k;
}

/* ---- settings ------------------------------------------------------------------------ */

/* The default ramp (an empty `ramp`): three bands of eq. 2.5's shape in the wave's own colour
 * C_e, so changing color_energy changes the light the wave casts and the lit side shows the
 * wave's hue, not a near-white: 0.3 C_e, 0.05 + 0.6 C_e, 0.2 + 0.8 C_e. */
static void lr_ramp_from_energy(const struct energy_wave_config *p, struct fxs_rig_consts *k)
{
    static const double m_min[3] = {-1, -0.3, 0}, base[3] = {0, 0.05, 0.2}, gain[3] = {0.3, 0.6, 0.8};
    const double *ce = p->color_energy;
    for (int i = 0; i < 3; i++) {
        k->bands[i].m_min = m_min[i];
        for (int c = 0; c < 3; c++) k->bands[i].rgb[c] = fmin(1.0, base[i] + gain[i] * ce[c]);
    }
    k->n_bands = 3;
}

/* The shadow plane: I, unit normal Y and an orthonormal in-plane pair (digest gap 3: the
 * plane is (I, Y); X, Z derived). */
static void lr_plane(const struct energy_wave_config *p, struct fxs_rig_consts *k)
{
    memcpy(k->plane_i, p->shadow_plane_point, sizeof k->plane_i);
    memcpy(k->plane_y, p->shadow_plane_normal, sizeof k->plane_y);
    vec3_normalize(k->plane_y);
    const double *Y = k->plane_y;
    double helper[3] = {0, 0, 0};
    helper[fabs(Y[0]) < 0.9 ? 0 : 2] = 1.0;
    double dxy = vec3_dot(helper, Y);
    for (int c = 0; c < 3; c++) k->plane_x[c] = helper[c] - dxy * Y[c];
    vec3_normalize(k->plane_x);
    vec3_cross(k->plane_x, Y, k->plane_z); /* X, Y, Z right-handed: Z = X × Y (eq. 2.12) */
}

static void lr_constants(const struct energy_wave_config *p, struct fxs_rig_consts *k)
{
    memset(k, 0, sizeof *k);
    k->flags = (p->features ? FXS_RIG_FEATURES : 0) | (p->outline ? FXS_RIG_OUTLINE : 0) |
               (p->shadow ? FXS_RIG_SHADOW : 0);
    k->strength = p->light_strength;
    k->outline_width = p->outline_width;
    memcpy(k->outline_rgb, p->outline_color, sizeof k->outline_rgb);
    k->shadow_theta = p->shadow_theta * M_PI / 180.0;
    k->shadow_opacity = p->shadow_opacity;
    memcpy(k->shadow_rgb, p->shadow_color, sizeof k->shadow_rgb);
    lr_plane(p, k);
    for (int i = 0; i < p->n_ramp; i++) {
        struct fxs_rig_band *b = &k->bands[k->n_bands++];
        b->m_min = p->ramp[i].m_min;
        memcpy(b->rgb, p->ramp[i].color, sizeof b->rgb);
    }
    if (!k->n_bands) lr_ramp_from_energy(p, k);
}

void light_rig_read(const struct energy_wave_config *params, struct light_rig *lr)
{
    lr->curve_segments = params->curve_segments;
    lr->torus_segments = params->torus_segments;
    lr_constants(params, &lr->k);
}

int light_rig_check(const struct energy_wave_config *params, struct fx_err *err)
{
    double prev = -INFINITY;
    for (int i = 0; i < params->n_ramp; i++) {
        double m = params->ramp[i].m_min;
        if (m <= prev) {
            char path[32];
            snprintf(path, sizeof path, "ramp[%d].m_min", i);
            return fx_fail(err, "bad_param", path, "ramp bands must ascend: m_min %g after %g", m, prev);
        }
        prev = m;
    }
    return 0;
}
