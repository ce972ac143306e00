/* light_ref.h — C references of the client's shading with a light rig (digest 003 §2, §7
 * "client shader"), which the page's shader and JS implement: the light position, m = N·L,
 * the toon ramp and the clamped shadow direction. tests/unit/test_light_rig.c checks them
 * against the digest's golden values; the daemon never shades, so they live with the tests. */
#ifndef FX_LIGHT_REF_H
#define FX_LIGHT_REF_H

#include "fxs_rig.h"

/* Nearest point E on one segment to M. */
void light_ref_nearest(const struct fxs_rig_seg *s, const double M[3], double E[3]);
/* The light position of M: the nearest point of the segment with the largest
 * strength / max(distance, 1e-6) among segments with strength > 0 (the dominant term of
 * the 1/distance field; for equal strengths simply the nearest segment, digest gap 12).
 * Returns the segment index, or -1 (E untouched) when no segment lights. */
int light_ref_point_light(const struct fxs_rig *rig, const double M[3], double E[3]);
/* m = N · normalize(E − M), not clamped (eq. 2.4); M on the centre line gives m = 1 (gap 11). */
double light_ref_m(const double E[3], const double M[3], const double N[3]);
/* The toon colour of m: the band with the largest m_min ≤ m (the first band below it). */
void light_ref_ramp(const struct fxs_rig_consts *k, double m, double rgb[3]);
/* The shadow projection direction k of a caster whose light direction is e = (B − W)/|B − W|
 * (eq. 2.8), clamped to at most θ from the plane's downward normal (eqs. 2.13-2.22 with the
 * sign fixed: digest 003 §6 gap 1). prev_i: the previous frame's in-plane direction for the
 * degenerate f = 0 case (may be NULL; updated when f ≠ 0). *lambda gets λ. Returns 1 when
 * clamped. */
int light_ref_shadow_dir(const struct fxs_rig_consts *k, const double e[3], double prev_i[3], double out[3],
                         double *lambda);

#endif
