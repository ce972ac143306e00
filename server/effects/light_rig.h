/* light_rig.h — the light rig of the energy wave (seed 003, Nito 2011; spec: digest 003 §7,
 * wire format: PROTOCOL.md §7.7).
 *
 * The server derives a compact rig from the energy_wave parameters at a frame's time:
 * the wave's centre line as capsule segments with a strength each (sources, B-spline
 * strength and the eq. (5.1) pulse), and the constants the client needs to shade its own
 * scene (toon ramp bands, outline, shadow angle clamp θ, plane, colour, opacity). Every
 * per-pixel and per-vertex computation belongs to the client (digest §7); the functions
 * light_rig_point_light, light_rig_ramp and light_rig_shadow_dir are the C references of
 * the client's shader/JS, used by the unit tests against the digest's golden values. */
#ifndef FX_LIGHT_RIG_H
#define FX_LIGHT_RIG_H

#include <stddef.h>
#include <stdint.h>
#include <cjson/cJSON.h>

#define LIGHT_RIG_MAGIC "FXR1"
#define LIGHT_RIG_VERSION 1
#define LIGHT_RIG_MAX_SEG 64
#define LIGHT_RIG_MAX_BANDS 8
#define LIGHT_RIG_HEADER_BYTES 32
#define LIGHT_RIG_SEG_BYTES 40
#define LIGHT_RIG_CONST_FIXED 96
#define LIGHT_RIG_BAND_BYTES 16
#define LIGHT_RIG_FLAG_CONSTANTS 1u /* payload flag: the constants block follows the segments */
#define LIGHT_RIG_MAX_PAYLOAD                                                                          \
    (LIGHT_RIG_HEADER_BYTES + LIGHT_RIG_MAX_SEG * LIGHT_RIG_SEG_BYTES + LIGHT_RIG_CONST_FIXED +        \
     LIGHT_RIG_MAX_BANDS * LIGHT_RIG_BAND_BYTES)

enum light_rig_source { LR_SRC_POINT = 1, LR_SRC_LINE = 2, LR_SRC_TORUS = 3, LR_SRC_CURVE = 4 };
enum light_rig_const_flag { LR_FEATURES = 1, LR_OUTLINE = 2, LR_SHADOW = 4 };

/* A capsule segment of the centre line: the nearest point of M is C + a·D with
 * a = clamp((M − C)·D, a_lo, a_hi) (digest eqs. 2.1-2.2 with gap 5's capsule; a point source
 * has a_lo = a_hi = 0, an infinite line −∞ … +∞, the thesis's half-line 0 … +∞). */
struct light_seg {
    double c[3], d[3], a_lo, a_hi;
    double strength; /* coef · S(t) at the segment (≤ 0: does not light) */
    int source, index;
};

struct light_band {
    double m_min, rgb[3];
};

struct light_consts {
    unsigned flags; /* enum light_rig_const_flag */
    double strength; /* mix of the toon colour over the client's own shading */
    double outline_width, outline_rgb[3];
    double shadow_theta, shadow_opacity, shadow_rgb[3]; /* θ in radians */
    double plane_i[3], plane_y[3], plane_x[3], plane_z[3]; /* I; unit normal Y; unit X, Z in the plane */
    int n_bands;
    struct light_band bands[LIGHT_RIG_MAX_BANDS];
};

struct light_rig {
    int n_seg;
    struct light_seg seg[LIGHT_RIG_MAX_SEG];
    struct light_consts k;
};

/* The rig of a complete validated energy_wave document at stream time sim_time. */
void light_rig_from_params(const cJSON *params, double sim_time, struct light_rig *rig);

/* Quadratic B-spline strength S(t) of weights w[0..nw-1] (seed 000 eqs. 3.24-3.26, the
 * end span closed at t = 1 as in the energy_wave kernel). */
double light_rig_bspline(int nw, const double *w, double t);

/* Encodes the payload (PROTOCOL.md §7.7) into out (at least LIGHT_RIG_MAX_PAYLOAD bytes);
 * with_constants adds the constants block. Returns the payload size. */
size_t light_rig_encode(const struct light_rig *rig, int with_constants, uint8_t *out);
/* FNV-1a 32 of the encoded constants block: the payload's constants_id. */
uint32_t light_rig_constants_id(const struct light_consts *k);
/* Parses a payload; 0 on success (has_constants says whether rig->k was filled), -1 when
 * malformed (bad magic/version, sizes that do not add up, too many segments or bands). */
int light_rig_decode(const uint8_t *p, size_t len, struct light_rig *rig, uint32_t *constants_id,
                     int *has_constants);

/* ---- C references of the client's shading (digest 003 §2, §7 "client shader") ---- */

/* Nearest point E on one segment to M. */
void light_rig_nearest(const struct light_seg *s, const double M[3], double E[3]);
/* The light position of M: the nearest point of the segment with the largest
 * strength / max(distance, 1e-6) among segments with strength > 0 (the dominant term of
 * the 1/distance field; for equal strengths simply the nearest segment, digest gap 12).
 * Returns the segment index, or -1 (E untouched) when no segment lights. */
int light_rig_point_light(const struct light_rig *rig, const double M[3], double E[3]);
/* m = N · normalize(E − M), not clamped (eq. 2.4); M on the centre line gives m = 1 (gap 11). */
double light_rig_m(const double E[3], const double M[3], const double N[3]);
/* The toon colour of m: the band with the largest m_min ≤ m (the first band below it). */
void light_rig_ramp(const struct light_consts *k, double m, double rgb[3]);
/* The shadow projection direction k of a caster whose light direction is e = (B − W)/|B − W|
 * (eq. 2.8), clamped to at most θ from the plane's downward normal (eqs. 2.13-2.22 with the
 * sign fixed: digest 003 §6 gap 1). prev_i: the previous frame's in-plane direction for the
 * degenerate f = 0 case (may be NULL; updated when f ≠ 0). *lambda gets λ. Returns 1 when
 * clamped. */
int light_rig_shadow_dir(const struct light_consts *k, const double e[3], double prev_i[3], double out[3],
                         double *lambda);

#endif
