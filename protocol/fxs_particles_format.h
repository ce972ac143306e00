/* fxs_particles_format.h — what the particle encoder and decoder share about one codec 2
 * block (PROTOCOL.md §7.5): the block header, the quantisation grid, the kd-tree's split
 * schedule, the context models and how contexts are formed. Internal to protocol/
 * (fxs_particles.h is the codec's interface); fxs_particles_enc.c and fxs_particles_dec.c
 * both include it, so the two sides cannot disagree on a constant or a context.
 *
 * The block's shape, chosen by measurement (tests/bench/bench_particles.c, table in
 * PROTOCOL.md §7.5.6):
 *   - positions quantised with one step for all axes (largest extent / (2^B - 1), as
 *     Draco's -qp), T and F to temp_bits / fuel_bits relative to their [min, max];
 *   - positions as a kd-tree of point counts (split x, y, z alternately, top bit first):
 *     each node with c >= 2 points sends how many lie in its lower half, a lone point
 *     sends its remaining bits raw. The set is unordered, so this costs close to the
 *     set's entropy, and the adaptive count models learn the particles' even spacing.
 *     The tree goes level by level and a count is a 3-decision bit tree (an escape for
 *     large ones), so a decoder walks a level as a flat loop without data-dependent
 *     branches; the leaves' bits follow the whole tree;
 *   - particles are sent in the tree's depth-first order; their flags, T and F in one of
 *     two modes picked per frame: mode 0 predicts each from the nearest of the 8 particles
 *     before it and codes the residual with contexts (smooth fields); mode 1 codes the
 *     values as bit trees in contexts of the neighbours' values (the nearest's flags, the
 *     nearest same-flags particle's T, own T for F: real flames, where burning and cold
 *     particles mix and residuals cost more than values);
 *   - optional velocities (§7.5.7, flagged in attr_mode, a 16-byte block after the header):
 *     per axis on a symmetric grid of vel_bits, each component a residual against the same
 *     neighbour's, after the attributes; without them the payload is what it always was;
 *   - one adaptive binary range coder for every modelled decision, and a raw LSB-first bit
 *     section for the incompressible bits (fxs_rangecoder.h).
 * Both sides are a few hundred lines of integer code, so the browser decoder
 * (clients/web/fxs_particles.js) needs no dependency. */
#ifndef FXS_PARTICLES_FORMAT_H
#define FXS_PARTICLES_FORMAT_H

#include <stddef.h>
#include <stdint.h>

#include "fxs_particles.h"
#include "fxs_rangecoder.h"

#define FXS_PT_MAGIC "FXP2"
#define FXS_PT_VERSION 3u
#define FXS_PT_NEAR 8           /* neighbours searched for the attribute prediction */
#define FXS_PT_SAME 16          /* mode 1: neighbours searched for one with the same flags */
#define FXS_PT_MAXD 72          /* kd-tree depth: bits of x + y + z */
#define FXS_PT_HAS_VEL 0x10u    /* attr_mode byte: a velocity block follows the header (§7.5.7) */

/* Integer models (fxs_rc_put_int): U unary decisions, then the Exp-Golomb class in unary,
 * then the top mantissa bit by class; the other mantissa bits go out raw. (The tree's counts
 * are small counts, fxs_rc_put_small.) */
#define FXS_PT_T_U 2
#define FXS_PT_F_U 2
#define FXS_PT_V_U 2
#define FXS_PT_CNT_CTX (14 * 3)   /* count class x axis */
#define FXS_PT_T_CTX (7 * 8 * 2)  /* previous residual class x own flags & 7 x neighbour F == 0 */
#define FXS_PT_F_CTX (7 * 2 * 2)  /* previous residual class x neighbour F == 0 x own flame bit */
#define FXS_PT_FL_CTX 16          /* neighbour flags & 7 x neighbour F == 0 */
#define FXS_PT_V_CTX (3 * 7 * 4)  /* axis x class of the residual before (§7.5.7) x own flags & 3 */

/* Every adaptive probability of a block, all starting at 1/2. */
struct fxs_pt_models {
    fxs_rc_prob cnt[FXS_PT_CNT_CTX][FXS_RC_SPROBS];
    fxs_rc_prob t[FXS_PT_T_CTX][FXS_RC_IPROBS(FXS_PT_T_U)];
    fxs_rc_prob f[FXS_PT_F_CTX][FXS_RC_IPROBS(FXS_PT_F_U)];
    fxs_rc_prob same[FXS_PT_FL_CTX];
    fxs_rc_prob tree[256];
    /* attribute mode 1 (direct values, §7.5.4) */
    fxs_rc_prob vsame[9 * 2];       /* flags differ from the neighbour's, by its flags & 7 (8: none) x its F == 0 */
    fxs_rc_prob vfl[9][256];        /* flags by the neighbour's flags & 7 (8: none) */
    fxs_rc_prob vt[8 * 9][256];     /* T by own flags & 7 x the same-flags neighbour's T / 8 (8: none) */
    fxs_rc_prob vf0[8 * 16 * 2];    /* F = 0 by own flags & 7 x T / 16 x neighbour F == 0 */
    fxs_rc_prob vf[8 * 8][256];     /* F - 1 by own flags & 7 x T / 8 */
    fxs_rc_prob v[FXS_PT_V_CTX][FXS_RC_IPROBS(FXS_PT_V_U)]; /* velocity residuals (§7.5.7) */
};

/* One block as both sides see it: the header's fields and what follows from them. */
struct fxs_pt_frame {
    uint32_t n;
    int pos_bits, temp_bits, fuel_bits;
    int mode;                /* attribute mode 0 or 1 (§7.5.4) */
    int vel, vel_bits;       /* velocities present (§7.5.7), bits per component */
    float vmax[3];           /* largest |v| of each axis */
    double vstep[3];
    int abits[3];            /* bits of each axis' quantised coordinate */
    float lo[5], hi[5];      /* x, y, z, T, F */
    double step[5];
    /* kd-tree schedule: axis split at depth d, and bits of each axis left below depth d */
    int depth;
    uint8_t axis[FXS_PT_MAXD];
    uint8_t left[FXS_PT_MAXD + 1][3];
};

/* class(c) of §7.5.3 for a node's count c = 2 ... 256 (class 13 above). */
extern const uint8_t fxs_pt_cclass_tab[257];

static inline uint32_t fxs_pt_zigzag(int32_t d) { return ((uint32_t)d << 1) ^ (uint32_t)(d >> 31); }
static inline int32_t fxs_pt_unzigzag(uint32_t z) { return (int32_t)(z >> 1) ^ -(int32_t)(z & 1); }

/* Class of a previous residual: 0, 1, 2-3, 4-7, 8-15, 16-31, 32+. */
static inline int fxs_pt_rclass(uint32_t z) { return z < 2 ? (int)z : z >= 32 ? 6 : 32 - __builtin_clz(z); }

/* Class of a node's count c >= 2: 2..8 alone, then 9-12, 13-16, 17-32, ... 257+. */
static inline int fxs_pt_cclass(uint32_t c) { return c <= 256 ? fxs_pt_cclass_tab[c] : 13; }

/* Largest quantised velocity magnitude: 2^(bits - 1) - 1. */
static inline int32_t fxs_pt_vqmax(int bits) { return (int32_t)(1u << (bits - 1)) - 1; }

/* Header bytes before the range-coder section: 64, + the velocity block (§7.5.7). */
static inline size_t fxs_pt_hdr_bytes(const struct fxs_pt_frame *f)
{
    return FXS_PARTICLES_HEADER_BYTES + (f->vel ? FXS_PARTICLES_VEL_BLOCK_BYTES : 0u);
}

/* Context of a velocity residual: axis, class of the residual coded before it (x: the
 * previous particle's x, y and z: this particle's x and y), own type (flags & 3). */
static inline int fxs_pt_vctx(int a, uint32_t zbefore, unsigned flags)
{
    return (a * 7 + fxs_pt_rclass(zbefore)) * 4 + (int)(flags & 3u);
}

void fxs_pt_models_init(struct fxs_pt_models *m);
/* Quantisation steps of f's bounds and bit widths (positions, T, F, velocities). */
void fxs_pt_steps(struct fxs_pt_frame *f);
/* The kd-tree's split schedule from f->abits. */
void fxs_pt_schedule(struct fxs_pt_frame *f);
/* Writes f's header (and velocity block) to out with the two section sizes. */
void fxs_pt_header_put(const struct fxs_pt_frame *f, uint8_t *out, uint32_t rc_len, uint32_t bits_len);
/* Reads a header from buf (len bytes): 0; -1 short or bad magic, -2 unsupported version,
 * -3 unknown attribute mode, -4 non-zero reserved bytes in the velocity block. */
int fxs_pt_header_get(const uint8_t *buf, size_t len, struct fxs_pt_frame *f, uint32_t *rl, uint32_t *bl);
/* NULL when f's fields are in range, else what is wrong. */
const char *fxs_pt_header_check(const struct fxs_pt_frame *f);
/* "particles: msg" into err; returns -1. */
int fxs_pt_fail(char *err, size_t errlen, const char *msg);

#endif
