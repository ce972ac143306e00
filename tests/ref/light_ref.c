/* light_ref.c — see light_ref.h. */
#include "light_ref.h"

#include <math.h>
#include <string.h>

#include "vec3.h"

void light_ref_nearest(const struct fxs_rig_seg *s, const double M[3], double E[3])
{
    double v[3] = {M[0] - s->c[0], M[1] - s->c[1], M[2] - s->c[2]};
    double a = vec3_dot(v, s->d); /* eq. 2.1 */
    if (a < s->a_lo) a = s->a_lo; /* eq. 2.2 (a ≤ 0 → E = C for the thesis's half-line) */
    if (a > s->a_hi) a = s->a_hi;
    for (int k = 0; k < 3; k++) E[k] = s->c[k] + a * s->d[k];
}

int light_ref_point_light(const struct fxs_rig *rig, const double M[3], double E[3])
{
    int best = -1;
    double best_score = 0;
    for (int i = 0; i < rig->n_seg; i++) {
        const struct fxs_rig_seg *s = &rig->seg[i];
        if (!(s->strength > 0)) continue;
        double e[3];
        light_ref_nearest(s, M, e);
        double d[3] = {e[0] - M[0], e[1] - M[1], e[2] - M[2]};
        double dist = sqrt(vec3_dot(d, d));
        double score = s->strength / (dist > 1e-6 ? dist : 1e-6);
        if (best < 0 || score > best_score) {
            best = i;
            best_score = score;
            memcpy(E, e, sizeof e);
        }
    }
    return best;
}

double light_ref_m(const double E[3], const double M[3], const double N[3])
{
    double L[3] = {E[0] - M[0], E[1] - M[1], E[2] - M[2]};
    if (vec3_normalize(L) < 1e-9) return 1.0; /* M on the centre line (digest gap 11) */
    double m = vec3_dot(N, L); /* eq. 2.4, deliberately not clamped at 0 */
    return m < -1 ? -1 : (m > 1 ? 1 : m);
}

void light_ref_ramp(const struct fxs_rig_consts *k, double m, double rgb[3])
{
    int pick = 0;
    for (int i = 0; i < k->n_bands; i++)
        if (m >= k->bands[i].m_min) pick = i; /* bands ascend by m_min (checked by light_rig_check) */
    for (int c = 0; c < 3; c++) rgb[c] = k->n_bands ? k->bands[pick].rgb[c] : 1.0;
}

int light_ref_shadow_dir(const struct fxs_rig_consts *k, const double e_in[3], double prev_i[3], double out[3],
                         double *lambda)
{
    const double *Y = k->plane_y, *X = k->plane_x, *Z = k->plane_z;
    double e[3] = {e_in[0], e_in[1], e_in[2]};
    if (vec3_normalize(e) < 1e-12) { /* B on the axis: straight down (digest gap 11) */
        for (int c = 0; c < 3; c++) e[c] = -Y[c];
    }
    double cl = -vec3_dot(e, Y); /* eq. 2.13: cos λ = e·(−Y) */
    double lam = acos(cl < -1 ? -1 : (cl > 1 ? 1 : cl));
    if (lambda) *lambda = lam;
    double theta = k->shadow_theta;
    if (lam <= theta) {
        memcpy(out, e, sizeof e);
        return 0;
    }
    /* eqs. 2.15-2.16: i = the in-plane direction of e, away from the light */
    double f[3], ex = vec3_dot(e, X), ez = vec3_dot(e, Z);
    for (int c = 0; c < 3; c++) f[c] = ex * X[c] + ez * Z[c];
    double i[3] = {1, 0, 0};
    if (vec3_normalize(f) > 1e-9) {
        memcpy(i, f, sizeof i);
        if (prev_i) memcpy(prev_i, f, sizeof f);
    } else if (prev_i && vec3_dot(prev_i, prev_i) > 0.5) {
        memcpy(i, prev_i, sizeof i); /* light straight below: the previous frame's i (gap 11) */
    } else {
        memcpy(i, X, sizeof i);
    }
    /* Sign fix, digest 003 §6 gap 1: the thesis's eqs. 2.17/2.22 (j = i × Y, q = cos φ/2 +
     * j sin φ/2) rotate i towards +Y, giving k = cos φ·i + sin φ·Y at angle π − θ from −Y, so
     * every shadow vertex above the plane gets t < 0 and eq. 2.32 hides the whole shadow. The
     * rotation must go the other way (by −φ, or j = Y × i): k = sin θ·i − cos θ·Y. */
    for (int c = 0; c < 3; c++) out[c] = sin(theta) * i[c] - cos(theta) * Y[c];
    return 1;
}
