/* fxs_rig.h — the kind 3 codec 1 payload ("FXR1", PROTOCOL.md §7.7): the energy wave's light
 * rig as centre-line capsule segments with a strength each, plus the constants a client needs
 * to shade its own scene (toon ramp, outline, shadow angle clamp and plane).
 *
 * Shared by the daemon (server/effects/light_rig.c derives a rig and encodes it) and
 * libfxclient (decodes it), as fxs_particles.h is; no dependencies beyond libc. */
#ifndef FXS_RIG_H
#define FXS_RIG_H

#include <stddef.h>
#include <stdint.h>

#define FXS_RIG_MAGIC "FXR1"
#define FXS_RIG_VERSION 1
#define FXS_RIG_MAX_SEG 64
#define FXS_RIG_MAX_BANDS 8
#define FXS_RIG_HEADER_BYTES 32
#define FXS_RIG_SEG_BYTES 40
#define FXS_RIG_CONST_FIXED 96
#define FXS_RIG_BAND_BYTES 16
#define FXS_RIG_FLAG_CONSTANTS 1u /* payload flag: the constants block follows the segments */
#define FXS_RIG_MAX_PAYLOAD                                                                                  \
    (FXS_RIG_HEADER_BYTES + FXS_RIG_MAX_SEG * FXS_RIG_SEG_BYTES + FXS_RIG_CONST_FIXED +                        \
     FXS_RIG_MAX_BANDS * FXS_RIG_BAND_BYTES)

enum fxs_rig_source { FXS_RIG_POINT = 1, FXS_RIG_LINE = 2, FXS_RIG_TORUS = 3, FXS_RIG_CURVE = 4 };
enum fxs_rig_const_flag { FXS_RIG_FEATURES = 1, FXS_RIG_OUTLINE = 2, FXS_RIG_SHADOW = 4 };

/* A capsule segment of the centre line: the nearest point of M is C + a·D with
 * a = clamp((M − C)·D, a_lo, a_hi) (digest 003 eqs. 2.1-2.2 with gap 5's capsule; a point
 * source has a_lo = a_hi = 0, an infinite line −∞ … +∞, the thesis's half-line 0 … +∞). */
struct fxs_rig_seg {
    double c[3], d[3], a_lo, a_hi;
    double strength; /* coef · S(t) at the segment (≤ 0: does not light) */
    int source, index; /* enum fxs_rig_source, and the source's index in its list */
};

struct fxs_rig_band {
    double m_min, rgb[3];
};

struct fxs_rig_consts {
    unsigned flags; /* enum fxs_rig_const_flag */
    double strength; /* mix of the toon colour over the client's own shading */
    double outline_width, outline_rgb[3];
    double shadow_theta, shadow_opacity, shadow_rgb[3]; /* θ in radians */
    double plane_i[3], plane_y[3], plane_x[3], plane_z[3]; /* I; unit normal Y; unit X, Z in the plane */
    int n_bands;
    struct fxs_rig_band bands[FXS_RIG_MAX_BANDS];
};

struct fxs_rig {
    int n_seg;
    struct fxs_rig_seg seg[FXS_RIG_MAX_SEG];
    struct fxs_rig_consts k;
};

/* Encodes the payload into out (at least FXS_RIG_MAX_PAYLOAD bytes); with_constants adds the
 * constants block. Returns the payload size. */
size_t fxs_rig_encode(const struct fxs_rig *rig, int with_constants, uint8_t *out);
/* FNV-1a 32 of the encoded constants block: the payload's constants_id. */
uint32_t fxs_rig_constants_id(const struct fxs_rig_consts *k);
/* Parses a payload; 0 on success (has_constants says whether rig->k was filled), -1 when
 * malformed (bad magic/version, sizes that do not add up, too many segments or bands). */
int fxs_rig_decode(const uint8_t *p, size_t len, struct fxs_rig *rig, uint32_t *constants_id, int *has_constants);

#endif
