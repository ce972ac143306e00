/* light_rig.c — the energy wave's light rig (seed 003; digest 003 §7, PROTOCOL.md §7.7).
 *
 * Owns the derivation of the rig from energy_wave's parameters (centre-line segments and
 * their strength at a frame's time, and the constants), its byte encoding, and the C
 * references of the client-side shading used by tests/unit/test_light_rig.c. It keeps no
 * state: energy_wave calls it once per frame (a few hundred floats, microseconds). */
#include "light_rig.h"

#include <math.h>
#include <string.h>

#include "../params.h"
#include "energy_wave.h"

#define LR_MAX_W 32

static double lr_dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static void lr_cross(const double a[3], const double b[3], double out[3])
{
    double r[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
    memcpy(out, r, sizeof r);
}

static double lr_normalize(double v[3])
{
    double n = sqrt(lr_dot(v, v));
    if (n > 0)
        for (int k = 0; k < 3; k++) v[k] /= n;
    return n;
}

/* ---- B-spline strength (seed 000 eqs. 3.24-3.26) ----------------------------------- */

double light_rig_bspline(int nw, const double *w, double t)
{
    if (nw < 3) return nw > 0 ? w[0] : 0.0;
    int m = nw + 3; /* knots U = [0,0,0, 1/(n-2), ..., (n-3)/(n-2), 1,1,1] */
    double U[LR_MAX_W + 3];
    for (int i = 0; i < m; i++) {
        double u = (i - 2.0) / (nw - 2.0);
        U[i] = u < 0 ? 0 : (u > 1 ? 1 : u);
    }
    if (t < 0) t = 0;
    if (t > 1) t = 1;
    /* degree 0: the span holding t; the last non-empty span is closed at t = 1 */
    double N[LR_MAX_W + 3] = {0};
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

/* ---- the rig from energy_wave's parameters ----------------------------------------- */

static struct light_seg *lr_add(struct light_rig *rig, int source, int index)
{
    if (rig->n_seg >= LIGHT_RIG_MAX_SEG) return NULL; /* extra segments are dropped (§7.7) */
    struct light_seg *s = &rig->seg[rig->n_seg++];
    memset(s, 0, sizeof *s);
    s->source = source;
    s->index = index;
    return s;
}

/* A chord from a to b as a capsule segment. */
static void lr_chord(struct light_seg *s, const double a[3], const double b[3], double strength)
{
    double d[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]};
    double len = lr_normalize(d);
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

static void lr_segments(const cJSON *p, double sim_time, struct light_rig *rig)
{
    const cJSON *it;
    int i = 0;
    cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(p, "points")) {
        struct light_seg *s = lr_add(rig, LR_SRC_POINT, i++);
        if (!s) return;
        params_vec3(it, "pos", s->c);
        s->d[2] = 1.0; /* any unit vector: a_lo = a_hi = 0 */
        s->strength = params_num(it, "coef");
    }
    i = 0;
    cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(p, "lines")) {
        struct light_seg *s = lr_add(rig, LR_SRC_LINE, i++);
        if (!s) return;
        params_vec3(it, "pos", s->c);
        params_vec3(it, "dir", s->d);
        lr_normalize(s->d);
        s->a_lo = -INFINITY;
        s->a_hi = INFINITY;
        s->strength = params_num(it, "coef");
    }
    int nt = (int)params_num(p, "torus_segments"), ncs = (int)params_num(p, "curve_segments");
    i = 0;
    cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(p, "tori")) {
        double c[3], e1[3], e2[3], e3[3], R = params_num(it, "R"), coef = params_num(it, "coef");
        params_vec3(it, "center", c);
        params_vec3(it, "axis", e3);
        lr_normalize(e3);
        double helper[3] = {fabs(e3[0]) < 0.9 ? 1.0 : 0.0, fabs(e3[0]) < 0.9 ? 0.0 : 1.0, 0.0};
        lr_cross(helper, e3, e1);
        lr_normalize(e1);
        lr_cross(e3, e1, e2);
        for (int j = 0; j < nt; j++) {
            double a[3], b[3], t0 = 2 * M_PI * j / nt, t1 = 2 * M_PI * (j + 1) / nt;
            for (int k = 0; k < 3; k++) {
                a[k] = c[k] + R * (cos(t0) * e1[k] + sin(t0) * e2[k]);
                b[k] = c[k] + R * (cos(t1) * e1[k] + sin(t1) * e2[k]);
            }
            struct light_seg *s = lr_add(rig, LR_SRC_TORUS, i);
            if (!s) return;
            lr_chord(s, a, b, coef);
        }
        i++;
    }
    int animate = params_bool(p, "animate");
    double rate = params_num(p, "anim_rate");
    i = 0;
    cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(p, "curves")) {
        static const char *const names[3] = {"p0", "p1", "p2"};
        double b[3][3], w[LR_MAX_W], anim[LR_MAX_W], coef = params_num(it, "coef");
        int nw = 0;
        for (int k = 0; k < 3; k++) params_vec3(it, names[k], b[k]);
        const cJSON *x;
        cJSON_ArrayForEach(x, cJSON_GetObjectItemCaseSensitive(it, "W")) if (nw < LR_MAX_W) w[nw++] = x->valuedouble;
        if (animate && nw > 0) { /* the same pulses as the texture (energy_wave.c ew_pack_curves) */
            energy_wave_loop_weights(sim_time * rate, nw, anim);
            for (int k = 0; k < nw; k++) w[k] *= anim[k];
        }
        for (int j = 0; j < ncs; j++) {
            double a[3], e[3];
            lr_bezier(b, (double)j / ncs, a);
            lr_bezier(b, (double)(j + 1) / ncs, e);
            struct light_seg *s = lr_add(rig, LR_SRC_CURVE, i);
            if (!s) return;
            lr_chord(s, a, e, coef * light_rig_bspline(nw, w, (j + 0.5) / ncs));
        }
        i++;
    }
}

/* The default ramp (an empty `ramp`): three bands of eq. 2.5's shape tinted by the wave's own
 * colour C_e, so changing color_energy changes the light the wave casts (issue 14). */
static void lr_ramp_from_energy(const cJSON *p, struct light_consts *k)
{
    static const double m_min[3] = {-1, -0.3, 0}, base[3] = {0, 0.2, 0.75}, gain[3] = {0.4, 0.7, 0.25};
    double ce[3];
    params_vec3(p, "color_energy", ce);
    for (int i = 0; i < 3; i++) {
        k->bands[i].m_min = m_min[i];
        for (int c = 0; c < 3; c++) k->bands[i].rgb[c] = fmin(1.0, base[i] + gain[i] * ce[c]);
    }
    k->n_bands = 3;
}

static void lr_constants(const cJSON *p, struct light_consts *k)
{
    memset(k, 0, sizeof *k);
    k->flags = (params_bool(p, "features") ? LR_FEATURES : 0) | (params_bool(p, "outline") ? LR_OUTLINE : 0) |
               (params_bool(p, "shadow") ? LR_SHADOW : 0);
    k->strength = params_num(p, "light_strength");
    k->outline_width = params_num(p, "outline_width");
    params_vec3(p, "outline_color", k->outline_rgb);
    k->shadow_theta = params_num(p, "shadow_theta") * M_PI / 180.0;
    k->shadow_opacity = params_num(p, "shadow_opacity");
    params_vec3(p, "shadow_color", k->shadow_rgb);
    params_vec3(p, "shadow_plane_point", k->plane_i);
    params_vec3(p, "shadow_plane_normal", k->plane_y);
    lr_normalize(k->plane_y);
    /* An orthonormal in-plane pair (digest gap 3: the plane is (I, Y); X, Z derived). */
    const double *Y = k->plane_y;
    double helper[3] = {0, 0, 0};
    helper[fabs(Y[0]) < 0.9 ? 0 : 2] = 1.0;
    double dxy = lr_dot(helper, Y);
    for (int c = 0; c < 3; c++) k->plane_x[c] = helper[c] - dxy * Y[c];
    lr_normalize(k->plane_x);
    lr_cross(k->plane_x, Y, k->plane_z); /* X, Y, Z right-handed: Z = X × Y (eq. 2.12) */
    const cJSON *it;
    cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(p, "ramp")) {
        if (k->n_bands >= LIGHT_RIG_MAX_BANDS) break;
        struct light_band *b = &k->bands[k->n_bands++];
        b->m_min = params_num(it, "m_min");
        params_vec3(it, "color", b->rgb);
    }
    if (!k->n_bands) lr_ramp_from_energy(p, k);
}

void light_rig_from_params(const cJSON *params, double sim_time, struct light_rig *rig)
{
    rig->n_seg = 0;
    lr_segments(params, sim_time, rig);
    lr_constants(params, &rig->k);
}

/* ---- encoding ------------------------------------------------------------------------ */

static void lr_put_f32(uint8_t *p, double v)
{
    float f = (float)v;
    uint32_t u;
    memcpy(&u, &f, 4);
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(u >> (8 * i));
}

static double lr_get_f32(const uint8_t *p)
{
    uint32_t u = (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
    float f;
    memcpy(&f, &u, 4);
    return f;
}

static void lr_put_u16(uint8_t *p, unsigned v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }
static void lr_put_u32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}
static unsigned lr_get_u16(const uint8_t *p) { return p[0] | p[1] << 8; }
static uint32_t lr_get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static void lr_put3(uint8_t *p, const double v[3])
{
    for (int i = 0; i < 3; i++) lr_put_f32(p + 4 * i, v[i]);
}

static void lr_get3(const uint8_t *p, double v[3])
{
    for (int i = 0; i < 3; i++) v[i] = lr_get_f32(p + 4 * i);
}

static size_t lr_constants_bytes(const struct light_consts *k)
{
    return LIGHT_RIG_CONST_FIXED + (size_t)k->n_bands * LIGHT_RIG_BAND_BYTES;
}

static size_t lr_encode_constants(const struct light_consts *k, uint8_t *o)
{
    size_t n = lr_constants_bytes(k);
    memset(o, 0, n);
    lr_put_u16(o, (unsigned)k->n_bands);
    lr_put_u16(o + 2, k->flags);
    lr_put_f32(o + 4, k->strength);
    lr_put_f32(o + 8, k->outline_width);
    lr_put3(o + 12, k->outline_rgb);
    lr_put_f32(o + 24, k->shadow_theta);
    lr_put_f32(o + 28, k->shadow_opacity);
    lr_put3(o + 32, k->shadow_rgb);
    lr_put3(o + 44, k->plane_i);
    lr_put3(o + 56, k->plane_y);
    lr_put3(o + 68, k->plane_x);
    lr_put3(o + 80, k->plane_z);
    for (int i = 0; i < k->n_bands; i++) {
        uint8_t *b = o + LIGHT_RIG_CONST_FIXED + (size_t)i * LIGHT_RIG_BAND_BYTES;
        lr_put_f32(b, k->bands[i].m_min);
        lr_put3(b + 4, k->bands[i].rgb);
    }
    return n;
}

static uint32_t lr_fnv1a(const uint8_t *p, size_t n)
{
    uint32_t h = 2166136261u;
    for (size_t i = 0; i < n; i++) h = (h ^ p[i]) * 16777619u;
    return h;
}

uint32_t light_rig_constants_id(const struct light_consts *k)
{
    uint8_t buf[LIGHT_RIG_CONST_FIXED + LIGHT_RIG_MAX_BANDS * LIGHT_RIG_BAND_BYTES];
    return lr_fnv1a(buf, lr_encode_constants(k, buf));
}

size_t light_rig_encode(const struct light_rig *rig, int with_constants, uint8_t *out)
{
    uint8_t *o = out;
    memset(o, 0, LIGHT_RIG_HEADER_BYTES);
    memcpy(o, LIGHT_RIG_MAGIC, 4);
    lr_put_u16(o + 4, LIGHT_RIG_VERSION);
    lr_put_u16(o + 6, LIGHT_RIG_HEADER_BYTES);
    lr_put_u16(o + 8, (unsigned)rig->n_seg);
    lr_put_u16(o + 10, LIGHT_RIG_SEG_BYTES);
    lr_put_u32(o + 12, with_constants ? LIGHT_RIG_FLAG_CONSTANTS : 0);
    lr_put_u32(o + 16, light_rig_constants_id(&rig->k));
    size_t n = LIGHT_RIG_HEADER_BYTES;
    for (int i = 0; i < rig->n_seg; i++, n += LIGHT_RIG_SEG_BYTES) {
        const struct light_seg *s = &rig->seg[i];
        lr_put3(out + n, s->c);
        lr_put3(out + n + 12, s->d);
        lr_put_f32(out + n + 24, s->a_lo);
        lr_put_f32(out + n + 28, s->a_hi);
        lr_put_f32(out + n + 32, s->strength);
        lr_put_u16(out + n + 36, (unsigned)s->source);
        lr_put_u16(out + n + 38, (unsigned)s->index);
    }
    size_t cb = with_constants ? lr_encode_constants(&rig->k, out + n) : 0;
    lr_put_u32(o + 20, (uint32_t)cb);
    return n + cb;
}

int light_rig_decode(const uint8_t *p, size_t len, struct light_rig *rig, uint32_t *constants_id, int *has_constants)
{
    if (len < LIGHT_RIG_HEADER_BYTES || memcmp(p, LIGHT_RIG_MAGIC, 4) || lr_get_u16(p + 4) != LIGHT_RIG_VERSION)
        return -1;
    size_t hb = lr_get_u16(p + 6), ns = lr_get_u16(p + 8), sb = lr_get_u16(p + 10);
    uint32_t flags = lr_get_u32(p + 12), cb = lr_get_u32(p + 20);
    if (hb < LIGHT_RIG_HEADER_BYTES || sb < LIGHT_RIG_SEG_BYTES || ns > LIGHT_RIG_MAX_SEG) return -1;
    int hc = (flags & LIGHT_RIG_FLAG_CONSTANTS) != 0;
    if ((!hc && cb) || (hc && cb < LIGHT_RIG_CONST_FIXED) || hb + ns * sb + cb != len) return -1;
    rig->n_seg = (int)ns;
    for (size_t i = 0; i < ns; i++) {
        const uint8_t *q = p + hb + i * sb;
        struct light_seg *s = &rig->seg[i];
        lr_get3(q, s->c);
        lr_get3(q + 12, s->d);
        s->a_lo = lr_get_f32(q + 24);
        s->a_hi = lr_get_f32(q + 28);
        s->strength = lr_get_f32(q + 32);
        s->source = (int)lr_get_u16(q + 36);
        s->index = (int)lr_get_u16(q + 38);
    }
    *constants_id = lr_get_u32(p + 16);
    *has_constants = hc;
    if (hc) {
        const uint8_t *c = p + hb + ns * sb;
        struct light_consts *k = &rig->k;
        unsigned nb = lr_get_u16(c);
        if (nb > LIGHT_RIG_MAX_BANDS || cb < LIGHT_RIG_CONST_FIXED + nb * LIGHT_RIG_BAND_BYTES) return -1;
        k->n_bands = (int)nb;
        k->flags = lr_get_u16(c + 2);
        k->strength = lr_get_f32(c + 4);
        k->outline_width = lr_get_f32(c + 8);
        lr_get3(c + 12, k->outline_rgb);
        k->shadow_theta = lr_get_f32(c + 24);
        k->shadow_opacity = lr_get_f32(c + 28);
        lr_get3(c + 32, k->shadow_rgb);
        lr_get3(c + 44, k->plane_i);
        lr_get3(c + 56, k->plane_y);
        lr_get3(c + 68, k->plane_x);
        lr_get3(c + 80, k->plane_z);
        for (unsigned i = 0; i < nb; i++) {
            const uint8_t *b = c + LIGHT_RIG_CONST_FIXED + i * LIGHT_RIG_BAND_BYTES;
            k->bands[i].m_min = lr_get_f32(b);
            lr_get3(b + 4, k->bands[i].rgb);
        }
    }
    return 0;
}

/* ---- references of the client's shading ----------------------------------------------- */

void light_rig_nearest(const struct light_seg *s, const double M[3], double E[3])
{
    double v[3] = {M[0] - s->c[0], M[1] - s->c[1], M[2] - s->c[2]};
    double a = lr_dot(v, s->d); /* eq. 2.1 */
    if (a < s->a_lo) a = s->a_lo; /* eq. 2.2 (a ≤ 0 → E = C for the thesis's half-line) */
    if (a > s->a_hi) a = s->a_hi;
    for (int k = 0; k < 3; k++) E[k] = s->c[k] + a * s->d[k];
}

int light_rig_point_light(const struct light_rig *rig, const double M[3], double E[3])
{
    int best = -1;
    double best_score = 0;
    for (int i = 0; i < rig->n_seg; i++) {
        const struct light_seg *s = &rig->seg[i];
        if (!(s->strength > 0)) continue;
        double e[3];
        light_rig_nearest(s, M, e);
        double d[3] = {e[0] - M[0], e[1] - M[1], e[2] - M[2]};
        double dist = sqrt(lr_dot(d, d));
        double score = s->strength / (dist > 1e-6 ? dist : 1e-6);
        if (best < 0 || score > best_score) {
            best = i;
            best_score = score;
            memcpy(E, e, sizeof e);
        }
    }
    return best;
}

double light_rig_m(const double E[3], const double M[3], const double N[3])
{
    double L[3] = {E[0] - M[0], E[1] - M[1], E[2] - M[2]};
    if (lr_normalize(L) < 1e-9) return 1.0; /* M on the centre line (digest gap 11) */
    double m = lr_dot(N, L); /* eq. 2.4, deliberately not clamped at 0 */
    return m < -1 ? -1 : (m > 1 ? 1 : m);
}

void light_rig_ramp(const struct light_consts *k, double m, double rgb[3])
{
    int pick = 0;
    for (int i = 0; i < k->n_bands; i++)
        if (m >= k->bands[i].m_min) pick = i; /* bands ascend by m_min (checked by energy_wave) */
    for (int c = 0; c < 3; c++) rgb[c] = k->n_bands ? k->bands[pick].rgb[c] : 1.0;
}

int light_rig_shadow_dir(const struct light_consts *k, const double e_in[3], double prev_i[3], double out[3],
                         double *lambda)
{
    const double *Y = k->plane_y, *X = k->plane_x, *Z = k->plane_z;
    double e[3] = {e_in[0], e_in[1], e_in[2]};
    if (lr_normalize(e) < 1e-12) { /* B on the axis: straight down (digest gap 11) */
        for (int c = 0; c < 3; c++) e[c] = -Y[c];
    }
    double cl = -lr_dot(e, Y); /* eq. 2.13: cos λ = e·(−Y) */
    double lam = acos(cl < -1 ? -1 : (cl > 1 ? 1 : cl));
    if (lambda) *lambda = lam;
    double theta = k->shadow_theta;
    if (lam <= theta) {
        memcpy(out, e, sizeof e);
        return 0;
    }
    /* eqs. 2.15-2.16: i = the in-plane direction of e, away from the light */
    double f[3], ex = lr_dot(e, X), ez = lr_dot(e, Z);
    for (int c = 0; c < 3; c++) f[c] = ex * X[c] + ez * Z[c];
    double i[3] = {1, 0, 0};
    if (lr_normalize(f) > 1e-9) {
        memcpy(i, f, sizeof i);
        if (prev_i) memcpy(prev_i, f, sizeof f);
    } else if (prev_i && lr_dot(prev_i, prev_i) > 0.5) {
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
