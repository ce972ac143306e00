/* fxs_particles.c — kind 1 particle payloads, codec 2 (PROTOCOL.md §7.5).
 *
 * Owns quantisation, ordering and entropy coding of particle frames, shared by the
 * daemon (encode) and libfxclient (decode). Shape, chosen by measurement
 * (tests/bench/bench_particles.c, table in PROTOCOL.md §7.5.6):
 *   - positions quantised with one step for all axes (largest extent / (2^B - 1), as
 *     Draco's -qp), T and F to temp_bits / fuel_bits relative to their [min, max];
 *   - positions as a kd-tree of point counts (split x, y, z alternately, top bit first):
 *     each node with c >= 2 points sends how many lie in its lower half, a lone point
 *     sends its remaining bits raw. The set is unordered, so this costs close to the
 *     set's entropy, and the adaptive count models learn the particles' even spacing;
 *   - particles are sent in the tree's depth-first order; their flags, T and F in one of
 *     two modes picked per frame by a static estimate: mode 0 predicts each from the
 *     nearest of the 8 particles before it and codes the residual with contexts (smooth
 *     fields); mode 1 codes the values as bit trees in contexts of the neighbours' values
 *     (the nearest's flags, the nearest same-flags particle's T, own T for F: real flames,
 *     where burning and cold particles mix and residuals cost more than values);
 *   - optional velocities (§7.5.7, flagged in attr_mode, a 16-byte block after the header):
 *     per axis on a symmetric grid of vel_bits, each component a residual against the same
 *     neighbour's, after the attributes; without them the payload is what it always was;
 *   - one adaptive binary range coder (LZMA's, 12-bit probabilities) for every modelled
 *     decision, and a raw LSB-first bit section for the incompressible bits.
 * Both sides are a few hundred lines of integer code, so the browser decoder
 * (clients/web/fxs_particles.js) needs no dependency. The decoder validates every
 * length and value and checks that both sections are consumed exactly. */
#include "fxs_particles.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define FXS_PT_AVX2 1
#endif

#include "fxs_bytes.h"

#define FXS_PT_MAGIC "FXP2"
#define FXS_PT_VERSION 2u
#define FXS_PT_PROB_BITS 12
#define FXS_PT_PROB_INIT (1u << (FXS_PT_PROB_BITS - 1))
#define FXS_PT_ADAPT 5
#define FXS_PT_TOP (1u << 24)
#define FXS_PT_NEAR 8           /* neighbours searched for the attribute prediction */
#define FXS_PT_SAME 16          /* mode 1: neighbours searched for one with the same flags */
#define FXS_PT_MAXK 24          /* Exp-Golomb classes 0..23 */
#define FXS_PT_MAXD 72          /* kd-tree depth: bits of x + y + z */

/* Integer models: U unary decisions, then the Exp-Golomb class in unary, then the top
 * mantissa bit by class; the other mantissa bits go out raw. */
#define FXS_PT_IPROBS(u) ((u) + 2 * FXS_PT_MAXK)
#define FXS_PT_CNT_U 3
#define FXS_PT_T_U 2
#define FXS_PT_F_U 2
#define FXS_PT_CNT_CTX (14 * 3)   /* count class x axis */
#define FXS_PT_T_CTX (7 * 8 * 2)  /* previous residual class x own flags & 7 x neighbour F == 0 */
#define FXS_PT_F_CTX (7 * 2 * 2)  /* previous residual class x neighbour F == 0 x own flame bit */
#define FXS_PT_FL_CTX 16          /* neighbour flags & 7 x neighbour F == 0 */
#define FXS_PT_V_U 2
#define FXS_PT_V_CTX (3 * 7 * 4)  /* axis x class of the residual before (§7.5.7) x own flags & 3 */
#define FXS_PT_HAS_VEL 0x10u      /* attr_mode byte: a velocity block follows the header (§7.5.7) */

typedef uint16_t fxs_pt_prob;

struct fxs_pt_models {
    fxs_pt_prob cnt[FXS_PT_CNT_CTX][FXS_PT_IPROBS(FXS_PT_CNT_U)];
    fxs_pt_prob t[FXS_PT_T_CTX][FXS_PT_IPROBS(FXS_PT_T_U)];
    fxs_pt_prob f[FXS_PT_F_CTX][FXS_PT_IPROBS(FXS_PT_F_U)];
    fxs_pt_prob same[FXS_PT_FL_CTX];
    fxs_pt_prob tree[256];
    /* attribute mode 1 (direct values, §7.5.4) */
    fxs_pt_prob vsame[9 * 2];       /* flags differ from the neighbour's, by its flags & 7 (8: none) x its F == 0 */
    fxs_pt_prob vfl[9][256];        /* flags by the neighbour's flags & 7 (8: none) */
    fxs_pt_prob vt[8 * 9][256];     /* T by own flags & 7 x the same-flags neighbour's T / 8 (8: none) */
    fxs_pt_prob vf0[8 * 16 * 2];    /* F = 0 by own flags & 7 x T / 16 x neighbour F == 0 */
    fxs_pt_prob vf[8 * 8][256];     /* F - 1 by own flags & 7 x T / 8 */
    fxs_pt_prob v[FXS_PT_V_CTX][FXS_PT_IPROBS(FXS_PT_V_U)]; /* velocity residuals (§7.5.7) */
};

static void fxs_pt_models_init(struct fxs_pt_models *m)
{
    fxs_pt_prob *p = (fxs_pt_prob *)m;
    for (size_t i = 0; i < sizeof *m / sizeof *p; i++) p[i] = FXS_PT_PROB_INIT;
}

static int fxs_pt_fail(char *err, size_t errlen, const char *msg)
{
    if (err && errlen) snprintf(err, errlen, "particles: %s", msg);
    return -1;
}

/* ---- zigzag ------------------------------------------------------------------------- */

static inline uint32_t fxs_pt_zigzag(int32_t d) { return ((uint32_t)d << 1) ^ (uint32_t)(d >> 31); }
static inline int32_t fxs_pt_unzigzag(uint32_t z) { return (int32_t)(z >> 1) ^ -(int32_t)(z & 1); }

/* Class of a previous residual: 0, 1, 2-3, 4-7, 8-15, 16-31, 32+. */
static inline int fxs_pt_rclass(uint32_t z) { return z < 2 ? (int)z : z >= 32 ? 6 : 32 - __builtin_clz(z); }

/* Class of a node's count c >= 2: 2..8 alone, then 9-12, 13-16, 17-32, ... 257+. */
static inline int fxs_pt_cclass(uint32_t c)
{
    if (c <= 8) return (int)c - 2;
    if (c <= 12) return 7;
    if (c <= 16) return 8;
    if (c > 256) return 13;
    return 9 + (int)(31 - __builtin_clz(c - 1)) - 4;
}

/* ---- raw bits reader (LSB first) ----------------------------------------------------- */

struct fxs_pt_bitr {
    const uint8_t *p, *end;
    uint64_t acc;
    int cnt;
};

/* Reads nbits (<= 32); returns -1 past the end. */
static inline int fxs_pt_bits_get(struct fxs_pt_bitr *r, int nbits, uint32_t *v)
{
    while (r->cnt < nbits) {
        if (r->p >= r->end) return -1;
        r->acc |= (uint64_t)*r->p++ << r->cnt;
        r->cnt += 8;
    }
    *v = (uint32_t)(r->acc & ((1ull << nbits) - 1u));
    r->acc >>= nbits;
    r->cnt -= nbits;
    return 0;
}

/* ---- adaptive binary range coder (LZMA's) ------------------------------------------ */

struct fxs_pt_rcr {
    const uint8_t *p, *end;
    uint32_t range, code;
    int bad;
};

static int fxs_pt_rcr_init(struct fxs_pt_rcr *d, const uint8_t *p, size_t len)
{
    if (len < 5 || p[0] != 0) return -1;
    d->p = p + 5;
    d->end = p + len;
    d->range = 0xFFFFFFFFu;
    d->code = (uint32_t)p[1] << 24 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 8 | p[4]; /* big endian */
    d->bad = d->code == 0xFFFFFFFFu;
    return d->bad ? -1 : 0;
}

static inline int fxs_pt_rc_get(struct fxs_pt_rcr *d, fxs_pt_prob *p)
{
    uint32_t bound = (d->range >> FXS_PT_PROB_BITS) * *p;
    int bit;
    if (d->code < bound) {
        d->range = bound;
        *p = (fxs_pt_prob)(*p + (((1u << FXS_PT_PROB_BITS) - *p) >> FXS_PT_ADAPT));
        bit = 0;
    } else {
        d->code -= bound;
        d->range -= bound;
        *p = (fxs_pt_prob)(*p - (*p >> FXS_PT_ADAPT));
        bit = 1;
    }
    if (d->range < FXS_PT_TOP) {
        d->range <<= 8;
        if (d->p < d->end) d->code = d->code << 8 | *d->p++;
        else d->bad = 1, d->code <<= 8;
    }
    return bit;
}

/* ---- integers: unary prefix, Exp-Golomb class, top mantissa bit modelled ------------ */

struct fxs_pt_dec_io {
    struct fxs_pt_rcr rc;
    struct fxs_pt_bitr bits;
};

/* Returns 0, or -1 for a class beyond the limit or raw bits past the end. */
static inline int fxs_pt_get_int(struct fxs_pt_dec_io *io, fxs_pt_prob *p, int u, uint32_t *z)
{
    uint32_t e, m;
    int k = 0;
    for (int i = 0; i < u; i++)
        if (!fxs_pt_rc_get(&io->rc, p + i)) {
            *z = (uint32_t)i;
            return 0;
        }
    while (fxs_pt_rc_get(&io->rc, p + u + k))
        if (++k == FXS_PT_MAXK) return -1;
    e = 1;
    if (k) {
        e = 2u | (uint32_t)fxs_pt_rc_get(&io->rc, p + u + FXS_PT_MAXK + k);
        if (fxs_pt_bits_get(&io->bits, k - 1, &m)) return -1;
        e = e << (k - 1) | m;
    }
    *z = e + (uint32_t)u - 1u;
    return 0;
}

/* ---- encoder output: range coder and raw bits ------------------------------------------ */

/* The encoder's whole output state. The hot loops copy it into a local (the compiler keeps
 * the fields in registers) and write it back at the end; they make room for the next
 * particle or node up front (fxs_pt_room), so that coding a decision or raw bits never
 * checks for space. */
struct fxs_pt_ew {
    uint8_t *rp, *bp;        /* next byte of the range-coder and of the raw-bits section */
    uint64_t low, acc;       /* range coder low (33 bits); raw bits not yet written */
    uint64_t pending;        /* bytes waiting on a carry: the cache byte and pending - 1 0xFFs */
    uint32_t range;
    int cnt;                 /* bits in acc */
    uint8_t cache;
};

struct fxs_pt_buf {
    uint8_t *p;
    size_t cap;
};

/* At most this many bytes per particle or tree node go to either section beyond the
 * pending carry run: every decision shifts out at most one byte (a range >= 2^24 times
 * the smallest probability 31/4096 is still >= 2^16), a node or particle codes at most
 * 60 decisions, and sends at most 3 x 24 raw bits. */
#define FXS_PT_SLACK 96u

/* Grows b so that at + need fits; returns the (moved) at, or NULL when out of memory. */
static __attribute__((noinline)) uint8_t *fxs_pt_grow(struct fxs_pt_buf *b, uint8_t *at, size_t need)
{
    size_t used = at ? (size_t)(at - b->p) : 0, cap = b->cap ? b->cap : 4096;
    uint8_t *p;
    while (cap < used + need) cap *= 2;
    if (cap == b->cap) return at;
    if (!(p = realloc(b->p, cap))) return NULL;
    b->p = p;
    b->cap = cap;
    return p + used;
}

/* Makes room for one more particle or node in both sections; -1 when out of memory. */
static inline int fxs_pt_room(struct fxs_pt_buf *rb, struct fxs_pt_buf *bb, struct fxs_pt_ew *w)
{
    if ((size_t)(rb->p + rb->cap - w->rp) < FXS_PT_SLACK + w->pending && !(w->rp = fxs_pt_grow(rb, w->rp, FXS_PT_SLACK + w->pending)))
        return -1;
    if ((size_t)(bb->p + bb->cap - w->bp) < FXS_PT_SLACK && !(w->bp = fxs_pt_grow(bb, w->bp, FXS_PT_SLACK))) return -1;
    return 0;
}

/* Raw bits, LSB first (nbits <= 32). */
static inline void fxs_pt_bits_put(struct fxs_pt_ew *w, uint32_t v, int nbits)
{
    w->acc |= (uint64_t)(v & (uint32_t)((1ull << nbits) - 1u)) << w->cnt;
    w->cnt += nbits;
    if (w->cnt >= 32) {
        fxs_put_u32(w->bp, (uint32_t)w->acc);
        w->bp += 4;
        w->acc >>= 32;
        w->cnt -= 32;
    }
}

/* Raw bits without a branch, for the kd-tree's leaves (fxs_pt_bits_put's flush every 32
 * bits is taken about once per leaf, irregularly: a misprediction; real 10k flame frames:
 * tree walk 29.0 -> 24.5 ns per particle, whole encoder 115.6 -> 111.6 ms/M). Needs
 * w->cnt + nbits <= 63; leaves w->cnt < 8, which fxs_pt_bits_put takes as is. Stores 8
 * bytes at w->bp (within FXS_PT_SLACK); those past the whole bytes are written again
 * later. */
static inline void fxs_pt_bits_put64(struct fxs_pt_ew *w, uint64_t v, int nbits)
{
    w->acc |= (v & ((1ull << nbits) - 1u)) << w->cnt;
    w->cnt += nbits;
    fxs_put_u32(w->bp, (uint32_t)w->acc);
    fxs_put_u32(w->bp + 4, (uint32_t)(w->acc >> 32));
    w->bp += w->cnt >> 3;
    w->acc >>= w->cnt & ~7;
    w->cnt &= 7;
}

/* LZMA's byte output with carry propagation. */
static inline void fxs_pt_rc_shift(struct fxs_pt_ew *w)
{
    if ((uint32_t)w->low < 0xFF000000u || (w->low >> 32) != 0) {
        uint8_t carry = (uint8_t)(w->low >> 32), out = w->cache;
        do {
            *w->rp++ = (uint8_t)(out + carry);
            out = 0xFF;
        } while (--w->pending);
        w->cache = (uint8_t)(w->low >> 24);
    }
    w->pending++;
    w->low = (w->low & 0x00FFFFFFu) << 8;
}

/* One decision, without a branch on the bit: after a 0 the probability moves up by
 * (4096 - p) >> 5, after a 1 down by p >> 5, both as p - ((p - t) >> 5) with t = 4065 or 0
 * (arithmetic shift; p stays in 31..4065). The new range as a select (GCC and Clang emit
 * cmov: one cycle less on the range's dependency chain than and/andn/or of a mask; real
 * 10k flame frames 121-123 -> 117-119 ms/M). */
static inline void fxs_pt_rc_bit(struct fxs_pt_ew *w, fxs_pt_prob *p, uint32_t bit)
{
    uint32_t pv = *p, bound = (w->range >> FXS_PT_PROB_BITS) * pv, mask = 0u - bit;
    w->low += bound & mask;
    w->range = bit ? w->range - bound : bound;
    *p = (fxs_pt_prob)(pv - (uint32_t)((int32_t)(pv - (((1u << FXS_PT_PROB_BITS) - 31u) & ~mask)) >> FXS_PT_ADAPT));
    if (w->range < FXS_PT_TOP) {
        w->range <<= 8;
        fxs_pt_rc_shift(w);
    }
}

static void fxs_pt_ew_init(struct fxs_pt_ew *w)
{
    memset(w, 0, sizeof *w);
    w->range = 0xFFFFFFFFu;
    w->pending = 1;
}

/* Integers: unary prefix of u decisions, Exp-Golomb class in unary, the top mantissa bit
 * modelled, the other mantissa bits raw (§7.5.4). */
static inline void fxs_pt_put_int(struct fxs_pt_ew *w, fxs_pt_prob *p, int u, uint32_t z)
{
    uint32_t e;
    int k;
    for (int i = 0; i < u; i++) {
        fxs_pt_rc_bit(w, p + i, z > (uint32_t)i);
        if (z == (uint32_t)i) return;
    }
    e = z - (uint32_t)u + 1u;
    k = 31 - __builtin_clz(e);
    for (int i = 0; i < k; i++) fxs_pt_rc_bit(w, p + u + i, 1);
    fxs_pt_rc_bit(w, p + u + k, 0);
    if (k) {
        fxs_pt_rc_bit(w, p + u + FXS_PT_MAXK + k, e >> (k - 1) & 1u);
        fxs_pt_bits_put(w, e, k - 1);
    }
}

/* Value tree (attribute mode 1): the top min(bits, 8) bits of v, high bit first, with
 * p[m] (m = 1, then 2m + bit); the low bits - 8 bits raw. */
static inline void fxs_pt_put_tree(struct fxs_pt_ew *w, fxs_pt_prob *p, uint32_t v, int bits)
{
    int low = bits > 8 ? bits - 8 : 0, b = bits - low;
    uint32_t top = v >> low | 1u << b;
    while (b-- > 0) fxs_pt_rc_bit(w, p + (top >> (b + 1)), top >> b & 1u);
    fxs_pt_bits_put(w, v, low);
}

/* ---- values as bit trees (attribute mode 1) ----------------------------------------------- */

static inline int fxs_pt_get_tree(struct fxs_pt_dec_io *io, fxs_pt_prob *p, int bits, uint32_t *v)
{
    int low = bits > 8 ? bits - 8 : 0;
    uint32_t m = 1, end = 1u << (bits - low), r = 0;
    while (m < end) m = 2 * m + (uint32_t)fxs_pt_rc_get(&io->rc, p + m);
    if (low && fxs_pt_bits_get(&io->bits, low, &r)) return -1;
    *v = (m - end) << low | r;
    return 0;
}

/* ---- frame description -------------------------------------------------------------- */

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

static void fxs_pt_steps(struct fxs_pt_frame *f)
{
    double r = 0;
    for (int a = 0; a < 3; a++)
        if ((double)f->hi[a] - (double)f->lo[a] > r) r = (double)f->hi[a] - (double)f->lo[a];
    for (int a = 0; a < 3; a++) f->step[a] = r / (double)((1u << f->pos_bits) - 1u);
    f->step[3] = ((double)f->hi[3] - (double)f->lo[3]) / (double)((1u << f->temp_bits) - 1u);
    f->step[4] = ((double)f->hi[4] - (double)f->lo[4]) / (double)((1u << f->fuel_bits) - 1u);
    for (int a = 0; a < 3 && f->vel; a++) f->vstep[a] = (double)f->vmax[a] / (double)fxs_pt_vqmax(f->vel_bits);
}

/* Splits from the top bit down; at each bit x, then y, then z (axes that have it). */
static void fxs_pt_schedule(struct fxs_pt_frame *f)
{
    int top = 0, d = 0, left[3];
    for (int a = 0; a < 3; a++) {
        left[a] = f->abits[a];
        if (f->abits[a] > top) top = f->abits[a];
    }
    for (int b = top - 1; b >= 0; b--)
        for (int a = 0; a < 3; a++)
            if (b < f->abits[a]) {
                for (int c = 0; c < 3; c++) f->left[d][c] = (uint8_t)left[c];
                f->axis[d++] = (uint8_t)a;
                left[a]--;
            }
    for (int c = 0; c < 3; c++) f->left[d][c] = 0;
    f->depth = d;
}

static inline uint32_t fxs_pt_quant(float v, float lo, double scale, uint32_t qmax)
{
    double q = ((double)v - (double)lo) * scale + 0.5;
    uint32_t u = q <= 0 ? 0u : (uint32_t)q;
    return u > qmax ? qmax : u;
}

static int fxs_pt_bounds(const struct fxs_particles *p, struct fxs_pt_frame *f)
{
    for (int c = 0; c < 5; c++) {
        f->lo[c] = INFINITY;
        f->hi[c] = -INFINITY;
    }
    for (uint32_t i = 0; i < p->n; i++) {
        float v[5] = { p->xyz[3 * i], p->xyz[3 * i + 1], p->xyz[3 * i + 2], p->temp[i], p->fuel[i] };
        for (int c = 0; c < 5; c++) {
            if (!isfinite(v[c])) return -1;
            if (v[c] < f->lo[c]) f->lo[c] = v[c];
            if (v[c] > f->hi[c]) f->hi[c] = v[c];
        }
    }
    if (!p->n)
        for (int c = 0; c < 5; c++) f->lo[c] = f->hi[c] = 0;
    f->vel = p->vel != NULL;
    for (int a = 0; a < 3; a++) f->vmax[a] = 0;
    for (size_t i = 0; f->vel && i < 3 * (size_t)p->n; i++) {
        float m = fabsf(p->vel[i]);
        if (!isfinite(m)) return -1;
        if (m > f->vmax[i % 3]) f->vmax[i % 3] = m;
    }
    return 0;
}

/* Keys (squared distance << 5 | k, exact integers: distances < 2^50) of particle j to
 * j - k for k = 1 ... kmax (those >= 0) into d[k - 1]; returns the index among
 * j - 1 ... j - FXS_PT_NEAR of the nearest (the latest on ties), or -1 for j = 0. */
static inline int64_t fxs_pt_near(const uint32_t *q, uint32_t j, uint64_t *d, uint32_t kmax)
{
    uint64_t best = UINT64_MAX;
    const uint32_t *c = q + 3 * (size_t)j;
    if (j < kmax) kmax = j;
    for (uint32_t k = 1; k <= kmax; k++) {
        const uint32_t *o = c - 3 * (size_t)k;
        int64_t dx = (int64_t)c[0] - o[0], dy = (int64_t)c[1] - o[1], dz = (int64_t)c[2] - o[2];
        d[k - 1] = ((uint64_t)(dx * dx) + (uint64_t)(dy * dy) + (uint64_t)(dz * dz)) << 5 | k;
    }
    for (uint32_t k = 1; k <= FXS_PT_NEAR && k <= kmax; k++) best = d[k - 1] < best ? d[k - 1] : best;
    return best == UINT64_MAX ? -1 : (int64_t)j - (int64_t)(best & 31u);
}

/* Mode 1: the nearest of j - 1 ... j - FXS_PT_SAME with flags v (the latest on ties),
 * else the latest particle before j with flags v (last[v]), else -1. */
static inline int64_t fxs_pt_same(const uint8_t *fl, uint32_t j, const uint64_t *d, unsigned v, const int64_t *last)
{
    uint64_t best = UINT64_MAX;
    uint32_t kmax = j < FXS_PT_SAME ? j : FXS_PT_SAME;
    for (uint32_t k = 1; k <= kmax; k++) {
        uint64_t key = fl[j - k] == v ? d[k - 1] : UINT64_MAX;
        best = key < best ? key : best;
    }
    return best != UINT64_MAX ? (int64_t)j - (int64_t)(best & 31u) : last[v];
}

/* Mode 1 context indices. */
static inline int fxs_pt_top(uint32_t q, int bits, int keep) { return (int)(bits > keep ? q >> (bits - keep) : q); }

/* ---- encoder --------------------------------------------------------------------------- */

struct fxs_pt_pt {
    uint32_t q[3];
    uint32_t i;
};

struct fxs_pt_enc {
    struct fxs_pt_frame f;
    /* scratch, one allocation: q (3n coordinates, input order then tree order; n qT, n qF,
     * n flags), Morton keys and indices (two halves each for the radix sort), nbs (n) and
     * sk (n bytes) of the neighbour search; order: the input index of each particle in
     * tree order */
    void *scratch;
    uint64_t *keys;
    uint32_t *idx, *q, *order;
    int32_t *nbs;
    double *pd;    /* x, y, z and flags as doubles for the neighbour search (4n); before it, a copy of q */
    struct fxs_pt_ew w;
    struct fxs_pt_buf rb, bb;    /* range-coder and raw-bits sections */
    struct fxs_pt_models m;
};

/* class(c) of §7.5.3 for c = 2 ... 256 (class 13 above) */
static uint8_t fxs_pt_cclass_tab[257];

static void fxs_pt_cclass_init(void)
{
    if (fxs_pt_cclass_tab[256]) return;
    for (uint32_t c = 2; c <= 256; c++) fxs_pt_cclass_tab[c] = (uint8_t)fxs_pt_cclass(c);
}

/* Spreads the low 21 bits of v to every third bit. */
static inline uint64_t fxs_pt_spread3(uint64_t v)
{
    v &= 0x1FFFFFu;
    v = (v | v << 32) & 0x1F00000000FFFFull;
    v = (v | v << 16) & 0x1F0000FF0000FFull;
    v = (v | v << 8) & 0x100F00F00F00F00Full;
    v = (v | v << 4) & 0x10C30C30C30C30C3ull;
    v = (v | v << 2) & 0x1249249249249249ull;
    return v;
}

/* The tree over points sorted by Morton key (x above y above z at each bit), depth first
 * without recursion (the upper child of a split waits on a stack of at most one entry per
 * depth): the lower half of a node is found by a branchless binary search. For frames
 * whose axes have <= 21 bits. -1 when out of memory. */
static int fxs_pt_enc_sorted(struct fxs_pt_enc *e, const uint64_t *key, const uint32_t *q)
{
    const struct fxs_pt_frame *f = &e->f;
    struct fxs_pt_ew w = e->w;
    uint32_t st_at[FXS_PT_MAXD + 1], st_c[FXS_PT_MAXD + 1], at = 0, c = f->n;
    int st_d[FXS_PT_MAXD + 1], d = 0, sp = 0;
    for (;;) {
        while (c >= 2 && d < f->depth) {
            int a = f->axis[d], kb = 3 * (f->left[d][a] - 1) + 2 - a;
            const uint64_t *base = key + at;
            uint32_t len = c, lo;
            while (len > 1) { /* first key with bit kb set */
                uint32_t half = len >> 1;
                base += half & ((uint32_t)(base[half] >> kb & 1u) - 1u);
                len -= half;
            }
            lo = (uint32_t)(base - key - at) + (uint32_t)(~*base >> kb & 1u);
            if (fxs_pt_room(&e->rb, &e->bb, &w)) return -1;
            fxs_pt_put_int(&w, e->m.cnt[(c <= 256 ? fxs_pt_cclass_tab[c] : 13) * 3 + a], FXS_PT_CNT_U,
                           fxs_pt_zigzag((int32_t)lo - (int32_t)(c >> 1)));
            d++;
            if (lo && lo < c) {
                st_at[sp] = at + lo, st_c[sp] = c - lo, st_d[sp] = d, sp++;
                c = lo;
            }
        }
        if (c == 1) {
            if (fxs_pt_room(&e->rb, &e->bb, &w)) return -1;
            const uint32_t *qa = q + 3 * (size_t)at; /* x, then y and z together (<= 42 bits) */
            int l1 = f->left[d][1];
            fxs_pt_bits_put64(&w, qa[0], f->left[d][0]);
            fxs_pt_bits_put64(&w, (qa[1] & ((1u << l1) - 1u)) | (uint64_t)qa[2] << l1, l1 + f->left[d][2]);
        }
        if (!sp) break;
        sp--;
        at = st_at[sp], c = st_c[sp], d = st_d[sp];
    }
    e->w = w;
    return 0;
}

/* LSD radix sort by key (12-bit digits, constant digits skipped) of k[0]/ix[0] using
 * k[1]/ix[1] as scratch; returns which of the two holds the result. */
static int fxs_pt_radix(uint64_t *k[2], uint32_t *ix[2], uint32_t n, int keybits)
{
    enum { D = 12 };
    uint32_t count[1u << D];
    int cur = 0;
    for (int shift = 0; n > 1 && shift < keybits; shift += D) {
        const uint64_t *key = k[cur];
        const uint32_t *idx = ix[cur];
        uint64_t *key2 = k[!cur];
        uint32_t *idx2 = ix[!cur];
        uint32_t sum = 0, mask = (1u << D) - 1u;
        memset(count, 0, sizeof count);
        for (uint32_t i = 0; i < n; i++) count[(key[i] >> shift) & mask]++;
        if (count[(key[0] >> shift) & mask] == n) continue;
        for (uint32_t dg = 0; dg <= mask; dg++) {
            uint32_t c = count[dg];
            count[dg] = sum;
            sum += c;
        }
        for (uint32_t i = 0; i < n; i++) {
            uint32_t o = count[(key[i] >> shift) & mask]++;
            key2[o] = key[i];
            idx2[o] = idx[i];
        }
        cur = !cur;
    }
    return cur;
}

/* Sorts the particles by Morton key (e->q becomes tree order, e->order the input index of
 * each) and codes the tree; -1 when out of memory. */
static int fxs_pt_enc_morton(struct fxs_pt_enc *e)
{
    uint32_t n = e->f.n, *q = e->q, *q0 = (uint32_t *)e->pd;
    uint64_t *k[2] = { e->keys, e->keys + n };
    uint32_t *ix[2] = { e->idx, e->idx + n };
    int top = e->f.depth ? e->f.left[0][e->f.axis[0]] : 0, c;
    for (uint32_t i = 0; i < n; i++) {
        const uint32_t *qi = q + 3 * (size_t)i;
        k[0][i] = fxs_pt_spread3(qi[0]) << 2 | fxs_pt_spread3(qi[1]) << 1 | fxs_pt_spread3(qi[2]);
        ix[0][i] = i;
    }
    c = fxs_pt_radix(k, ix, n, 3 * top);
    /* q into tree order by gathering from a copy (in pd, free until the neighbour search)
     * rather than decoding the keys: 1.5-2 ms/M less on real 10k flame frames. */
    memcpy(q0, q, 12 * (size_t)n);
    for (uint32_t j = 0; j < n; j++) {
        const uint32_t *qi = q0 + 3 * (size_t)ix[c][j];
        q[3 * (size_t)j] = qi[0], q[3 * (size_t)j + 1] = qi[1], q[3 * (size_t)j + 2] = qi[2];
    }
    e->order = ix[c];
    return fxs_pt_enc_sorted(e, k[c], q);
}

/* The tree by stable partitioning (through scratch), for frames with an axis of more
 * than 21 bits: the same order as the Morton path, ties in input order. */
static int fxs_pt_enc_node(struct fxs_pt_enc *e, struct fxs_pt_pt *p, struct fxs_pt_pt *tmp, uint32_t c, int d)
{
    const struct fxs_pt_frame *f = &e->f;
    while (c >= 2 && d < f->depth) {
        int a = f->axis[d], sh = f->left[d][a] - 1;
        uint32_t lo = 0, hi = 0;
        for (uint32_t i = 0; i < c; i++)
            if (!((p[i].q[a] >> sh) & 1u)) p[lo++] = p[i];
            else tmp[hi++] = p[i];
        memcpy(p + lo, tmp, hi * sizeof *p);
        if (fxs_pt_room(&e->rb, &e->bb, &e->w)) return -1;
        fxs_pt_put_int(&e->w, e->m.cnt[fxs_pt_cclass(c) * 3 + a], FXS_PT_CNT_U,
                       fxs_pt_zigzag((int32_t)lo - (int32_t)(c >> 1)));
        d++;
        if (lo && lo < c) {
            if (fxs_pt_enc_node(e, p, tmp, lo, d)) return -1;
            p += lo;
            c -= lo;
        }
    }
    if (c == 1) {
        if (fxs_pt_room(&e->rb, &e->bb, &e->w)) return -1;
        for (int a = 0; a < 3; a++) fxs_pt_bits_put(&e->w, p->q[a], f->left[d][a]);
    }
    return 0;
}

/* The tree of a frame with an axis of more than 21 bits (fxs_pt_enc_node), then e->q in
 * tree order and e->order; -1 when out of memory. */
static int fxs_pt_enc_wide(struct fxs_pt_enc *e)
{
    uint32_t n = e->f.n;
    struct fxs_pt_pt *pts = malloc(2 * (size_t)n * sizeof *pts);
    int r = -1;
    if (pts) {
        for (uint32_t i = 0; i < n; i++) {
            memcpy(pts[i].q, e->q + 3 * (size_t)i, sizeof pts[i].q);
            pts[i].i = i;
        }
        r = fxs_pt_enc_node(e, pts, pts + n, n, 0);
        e->order = e->idx;
        for (uint32_t j = 0; j < n; j++) {
            memcpy(e->q + 3 * (size_t)j, pts[j].q, sizeof pts[j].q);
            e->order[j] = pts[j].i;
        }
        free(pts);
    }
    return r;
}

/* Mode 0: flags, T and F predicted from the nearest recent neighbour nb[j]. */
static int fxs_pt_enc_attrs0(struct fxs_pt_enc *e, const uint32_t *qt, const uint32_t *qf, const uint8_t *fl,
                             const int32_t *nbs)
{
    struct fxs_pt_models *m = &e->m;
    struct fxs_pt_ew w = e->w;
    uint32_t zt = 0, zf = 0, n = e->f.n;
    for (uint32_t j = 0; j < n; j++) {
        int32_t nb = nbs[j];
        uint32_t nt = nb < 0 ? 0 : qt[nb], nf = nb < 0 ? 0 : qf[nb];
        unsigned nfl = nb < 0 ? 0 : fl[nb], v = fl[j];
        int f0 = nf == 0;
        fxs_pt_prob *pt = m->t[(fxs_pt_rclass(zt) * 8 + (int)(v & 7u)) * 2 + f0];
        fxs_pt_prob *pf = m->f[(fxs_pt_rclass(zf) * 2 + f0) * 2 + (int)(v >> 2 & 1u)];
        if (fxs_pt_room(&e->rb, &e->bb, &w)) return -1;
        fxs_pt_rc_bit(&w, &m->same[(nfl & 7u) * 2 + (unsigned)f0], v != nfl);
        if (v != nfl) fxs_pt_put_tree(&w, m->tree, v, 8);
        zt = fxs_pt_zigzag((int32_t)qt[j] - (int32_t)nt);
        zf = fxs_pt_zigzag((int32_t)qf[j] - (int32_t)nf);
        fxs_pt_put_int(&w, pt, FXS_PT_T_U, zt);
        fxs_pt_put_int(&w, pf, FXS_PT_F_U, zf);
    }
    e->w = w;
    return 0;
}

/* Key (squared distance << 5 | k, exact: distances < 2^50) of particle c to the one k before. */
static inline uint64_t fxs_pt_key(const uint32_t *c, uint32_t k)
{
    const uint32_t *o = c - 3 * (size_t)k;
    int64_t dx = (int64_t)c[0] - o[0], dy = (int64_t)c[1] - o[1], dz = (int64_t)c[2] - o[2];
    return ((uint64_t)(dx * dx) + (uint64_t)(dy * dy) + (uint64_t)(dz * dz)) << 5 | k;
}

/* Neighbour search of particle j over its first kmax candidates (j - 1 ... j - kmax) with
 * the 64-bit keys, for frames or particles the vector search below does not cover. */
static inline void fxs_pt_nb_one(const uint32_t *q, const uint8_t *fl, uint32_t j, uint32_t kmax, int32_t *nbs,
                                 uint8_t *sk)
{
    const uint32_t *c = q + 3 * (size_t)j;
    uint64_t bn = UINT64_MAX, bs = UINT64_MAX;
    for (uint32_t k = 1; k <= kmax; k++) {
        uint64_t key = fxs_pt_key(c, k), ks = key | ((uint64_t)0 - (uint64_t)(fl[j - k] != fl[j]));
        if (k <= FXS_PT_NEAR) bn = key < bn ? key : bn;
        bs = ks < bs ? ks : bs;
    }
    nbs[j] = bn != UINT64_MAX ? (int32_t)(j - (uint32_t)(bn & 31u)) : -1;
    sk[j] = bs != UINT64_MAX ? (uint8_t)(bs & 31u) : 0;
}

/* The neighbour search of both modes, one pass: nbs[j], the nearest of j - 1 ... j - 8
 * (-1 for j = 0; the latest on ties), and sk[j], the k (1 ... 16) of the nearest of
 * j - 1 ... j - 16 with the flags of j (0: none; the latest on ties), from which mode 1
 * takes the same-flags neighbour (else last[v]); pd: scratch for 4n doubles.
 * With SSE2 (all x86-64) and axes of <= 23 bits, the keys distance * 32 + k are exact in
 * doubles (distance < 3 * 2^46, key < 3 * 2^51 < 2^53), so minpd finds the same minimum
 * as the 64-bit integer keys; candidates with other flags get key + inf. Two particles
 * j at a time in the lanes, x, y, z and flags converted to doubles once, every operation
 * vertical (no shuffles, no blends). Before: 64-bit keys one at a time, and mode 1
 * searched j - 9 ... j - 16 again per particle: real 10k flame frames 131-133
 * -> 119-121 ms/M (whole encoder). */
#if defined(FXS_PT_AVX2) && !defined(FXS_PT_SCALAR)
/* fxs_pt_neighbours' vector search with four particles a step (AVX2, where the CPU has it):
 * the same exact keys and minima, so the same neighbours; returns the next j. */
__attribute__((target("avx2"))) static uint32_t fxs_pt_nb_avx2(const double *xd, const double *yd, const double *zd,
                                                              const double *fd, uint32_t j, uint32_t n, int32_t *nbs,
                                                              uint8_t *sk)
{
    const __m256d inf = _mm256_set1_pd(INFINITY), k32 = _mm256_set1_pd(32.0);
    for (; j + 4 <= n; j += 4) {
        const __m256d cx = _mm256_loadu_pd(xd + j), cy = _mm256_loadu_pd(yd + j), cz = _mm256_loadu_pd(zd + j);
        const __m256d cf = _mm256_loadu_pd(fd + j);
        __m256d bn = inf, bs = inf;
        double kn[4], ks[4];
        for (uint32_t k = 1; k <= FXS_PT_SAME; k++) {
            __m256d dx = _mm256_sub_pd(cx, _mm256_loadu_pd(xd + j - k));
            __m256d dy = _mm256_sub_pd(cy, _mm256_loadu_pd(yd + j - k));
            __m256d dz = _mm256_sub_pd(cz, _mm256_loadu_pd(zd + j - k));
            __m256d d = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)), _mm256_mul_pd(dz, dz));
            __m256d key = _mm256_add_pd(_mm256_mul_pd(d, k32), _mm256_set1_pd((double)k));
            __m256d other = _mm256_and_pd(_mm256_cmp_pd(cf, _mm256_loadu_pd(fd + j - k), _CMP_NEQ_UQ), inf);
            if (k <= FXS_PT_NEAR) bn = _mm256_min_pd(bn, key);
            bs = _mm256_min_pd(bs, _mm256_add_pd(key, other));
        }
        _mm256_storeu_pd(kn, bn);
        _mm256_storeu_pd(ks, bs);
        for (uint32_t l = 0; l < 4; l++) {
            nbs[j + l] = (int32_t)(j + l - (uint32_t)((int64_t)kn[l] & 31));
            sk[j + l] = ks[l] < INFINITY ? (uint8_t)((int64_t)ks[l] & 31) : 0;
        }
    }
    return j;
}
#endif

static void fxs_pt_neighbours(const struct fxs_pt_frame *f, const uint32_t *q, const uint8_t *fl, int32_t *nbs,
                              uint8_t *sk, double *pd)
{
    uint32_t n = f->n, j = 0;
    for (; j < n && j < FXS_PT_SAME; j++) fxs_pt_nb_one(q, fl, j, j, nbs, sk);
#if defined(__SSE2__) && !defined(FXS_PT_SCALAR)
    if (f->abits[0] <= 23 && f->abits[1] <= 23 && f->abits[2] <= 23) {
        double *xd = pd, *yd = pd + n, *zd = pd + 2 * (size_t)n, *fd = pd + 3 * (size_t)n;
        const __m128d inf = _mm_set1_pd(INFINITY), k32 = _mm_set1_pd(32.0);
        for (uint32_t i = 0; i < n; i++) {
            xd[i] = q[3 * (size_t)i], yd[i] = q[3 * (size_t)i + 1], zd[i] = q[3 * (size_t)i + 2];
            fd[i] = fl[i];
        }
#if defined(FXS_PT_AVX2) && !defined(FXS_PT_SCALAR)
        if (__builtin_cpu_supports("avx2")) j = fxs_pt_nb_avx2(xd, yd, zd, fd, j, n, nbs, sk);
#endif
        for (; j + 2 <= n; j += 2) {
            const __m128d cx = _mm_loadu_pd(xd + j), cy = _mm_loadu_pd(yd + j), cz = _mm_loadu_pd(zd + j);
            const __m128d cf = _mm_loadu_pd(fd + j);
            __m128d bn = inf, bs = inf;
            int64_t kn[2], ks[2];
            for (uint32_t k = 1; k <= FXS_PT_SAME; k++) {
                __m128d dx = _mm_sub_pd(cx, _mm_loadu_pd(xd + j - k)), dy = _mm_sub_pd(cy, _mm_loadu_pd(yd + j - k));
                __m128d dz = _mm_sub_pd(cz, _mm_loadu_pd(zd + j - k));
                __m128d d = _mm_add_pd(_mm_add_pd(_mm_mul_pd(dx, dx), _mm_mul_pd(dy, dy)), _mm_mul_pd(dz, dz));
                __m128d key = _mm_add_pd(_mm_mul_pd(d, k32), _mm_set1_pd((double)k));
                __m128d other = _mm_and_pd(_mm_cmpneq_pd(cf, _mm_loadu_pd(fd + j - k)), inf);
                if (k <= FXS_PT_NEAR) bn = _mm_min_pd(bn, key);
                bs = _mm_min_pd(bs, _mm_add_pd(key, other));
            }
            kn[0] = (int64_t)_mm_cvtsd_f64(bn), kn[1] = (int64_t)_mm_cvtsd_f64(_mm_unpackhi_pd(bn, bn));
            nbs[j] = (int32_t)(j - (uint32_t)(kn[0] & 31)), nbs[j + 1] = (int32_t)(j + 1 - (uint32_t)(kn[1] & 31));
            ks[0] = _mm_ucomilt_sd(bs, inf) ? (int64_t)_mm_cvtsd_f64(bs) & 31 : 0;
            bs = _mm_unpackhi_pd(bs, bs);
            ks[1] = _mm_ucomilt_sd(bs, inf) ? (int64_t)_mm_cvtsd_f64(bs) & 31 : 0;
            sk[j] = (uint8_t)ks[0], sk[j + 1] = (uint8_t)ks[1];
        }
    }
#else
    (void)pd;
#endif
    for (; j < n; j++) fxs_pt_nb_one(q, fl, j, FXS_PT_SAME, nbs, sk);
}

/* Mode 1: flags, T and F as values (bit trees) in contexts of the neighbours' values. */
static int fxs_pt_enc_attrs1(struct fxs_pt_enc *e, const uint32_t *qt, const uint32_t *qf, const uint8_t *fl,
                             const int32_t *nbs, const uint8_t *sk)
{
    const struct fxs_pt_frame *f = &e->f;
    struct fxs_pt_models *m = &e->m;
    struct fxs_pt_ew w = e->w;
    const int tbits = f->temp_bits, fbits = f->fuel_bits;
    const int t3 = tbits > 3 ? tbits - 3 : 0, t4 = tbits > 4 ? tbits - 4 : 0;
    int32_t last[256];
    for (int i = 0; i < 256; i++) last[i] = -1;
    for (uint32_t j = 0; j < f->n; j++) {
        unsigned v = fl[j], c = v & 7u, t = qt[j], fu = qf[j];
        int32_t nb = nbs[j], sb = sk[j] ? (int32_t)(j - sk[j]) : last[v];
        unsigned nf0 = nb < 0 || qf[nb] == 0;
        unsigned nfl = nb < 0 ? 0 : fl[nb], nc = nb < 0 ? 8 : nfl & 7u;
        if (fxs_pt_room(&e->rb, &e->bb, &w)) return -1;
        fxs_pt_rc_bit(&w, &m->vsame[nc * 2 + nf0], v != nfl);
        if (v != nfl) fxs_pt_put_tree(&w, m->vfl[nc], v, 8);
        fxs_pt_put_tree(&w, m->vt[c * 9 + (sb < 0 ? 8u : qt[sb] >> t3)], t, tbits);
        fxs_pt_rc_bit(&w, &m->vf0[(c * 16 + (t >> t4)) * 2 + nf0], fu != 0);
        if (fu) fxs_pt_put_tree(&w, m->vf[c * 8 + (t >> t3)], fu - 1, fbits);
        last[v] = (int32_t)j;
    }
    e->w = w;
    return 0;
}

/* Static estimate (bits) of the T and F residuals of mode 0 against their values by flags
 * in mode 1; returns the mode to use. */
static int fxs_pt_choose(const struct fxs_pt_frame *f, const uint32_t *qt, const uint32_t *qf, const uint8_t *fl,
                         const int32_t *nbs)
{
    enum { C = 18, H = 2 * 2048 };
    /* Counts in two copies, by j's parity, and the raw-bit sum as an integer: neighbours
     * mostly land in the same bucket, and one copy made every increment wait on the one
     * before (and the double sum on its add); F = 0 by flags follows from the totals of
     * the two histograms. All exact integers, so the choice is unchanged; real 10k flame
     * frames 109.2-109.4 -> 107.5-108.3 ms/M. */
    uint32_t n = f->n, rc[2][2][C] = { { { 0 } } }, tot[2][8], *h = calloc(2 * H, sizeof *h);
    uint64_t raw = 0;
    double res, dir;
    int low = f->temp_bits > 8 ? f->temp_bits - 8 : 0, lowf = f->fuel_bits > 8 ? f->fuel_bits - 8 : 0;
    if (!h) return 0;
    for (uint32_t j = 0; j < n; j++) {
        int32_t nb = nbs[j];
        uint32_t zt = fxs_pt_zigzag((int32_t)qt[j] - (int32_t)(nb < 0 ? 0 : qt[nb]));
        uint32_t zf = fxs_pt_zigzag((int32_t)qf[j] - (int32_t)(nb < 0 ? 0 : qf[nb]));
        int ct = zt ? 32 - __builtin_clz(zt) : 0, cf = zf ? 32 - __builtin_clz(zf) : 0;
        uint32_t *hj = h + (j & 1u) * H;
        unsigned c = fl[j] & 7u;
        rc[j & 1u][0][ct]++, rc[j & 1u][1][cf]++;
        raw += (uint64_t)((ct > 1 ? ct - 1 : 0) + (cf > 1 ? cf - 1 : 0));
        hj[c * 256 + (qt[j] >> low)]++;
        hj[2048 + c * 256 + (qf[j] ? (qf[j] - 1) >> lowf : 0)] += qf[j] != 0;
    }
    res = (double)raw;
    for (int a = 0; a < 2; a++)
        for (int k = 0; k < C; k++) {
            uint32_t r = rc[0][a][k] + rc[1][a][k];
            if (r) res += r * log2((double)n / r);
        }
    dir = (double)n * (low + lowf);
    for (int g = 0; g < 2; g++) /* T by flags, F - 1 by flags */
        for (unsigned c = 0; c < 8; c++) {
            uint32_t *hh = h + g * 2048 + c * 256;
            tot[g][c] = 0;
            for (int k = 0; k < 256; k++) tot[g][c] += hh[k] += hh[H + k];
            for (int k = 0; k < 256; k++)
                if (hh[k]) dir += hh[k] * log2((double)tot[g][c] / hh[k]) + 6; /* + learning */
        }
    for (unsigned c = 0; c < 8; c++) { /* F = 0 by flags */
        uint32_t a = tot[0][c] - tot[1][c], b = tot[1][c];
        if (a && b) dir += a * log2((double)(a + b) / a) + b * log2((double)(a + b) / b);
    }
    free(h);
    return dir < res;
}

/* Flags, T and F of every particle in tree order, in the mode the estimate picks. */
static int fxs_pt_enc_attrs(struct fxs_pt_enc *e, const struct fxs_particles *p)
{
    const struct fxs_pt_frame *f = &e->f;
    uint32_t n = f->n, tmax = (1u << f->temp_bits) - 1u, fmax = (1u << f->fuel_bits) - 1u;
    double ts = f->hi[3] > f->lo[3] ? (double)tmax / ((double)f->hi[3] - (double)f->lo[3]) : 0;
    double fs = f->hi[4] > f->lo[4] ? (double)fmax / ((double)f->hi[4] - (double)f->lo[4]) : 0;
    uint32_t *q = e->q, *qt = q + 3 * (size_t)n, *qf = qt + n;
    uint8_t *fl = (uint8_t *)(qf + n);
    int32_t *nbs = e->nbs;
    uint8_t *sk = (uint8_t *)(nbs + n);
    for (uint32_t j = 0; j < n; j++) {
        uint32_t i = e->order[j];
        qt[j] = fxs_pt_quant(p->temp[i], f->lo[3], ts, tmax);
        qf[j] = fxs_pt_quant(p->fuel[i], f->lo[4], fs, fmax);
        fl[j] = p->flags[i];
    }
    fxs_pt_neighbours(f, q, fl, nbs, sk, e->pd);
    e->f.mode = fxs_pt_choose(f, qt, qf, fl, nbs);
    return e->f.mode ? fxs_pt_enc_attrs1(e, qt, qf, fl, nbs, sk) : fxs_pt_enc_attrs0(e, qt, qf, fl, nbs);
}

/* Velocity component v on the symmetric grid of step 1 / scale, clamped to +-qmax. */
static inline int32_t fxs_pt_vquant(float v, double scale, int32_t qmax)
{
    double q = fabs((double)v) * scale + 0.5;
    int32_t u = q >= (double)qmax ? qmax : (int32_t)q;
    return v < 0 ? -u : u;
}

/* Velocities of every particle in tree order (§7.5.7): per axis the residual against the
 * nearest recent neighbour's (nbs, as mode 0's), an integer in contexts of the class of the
 * residual coded before it and the particle's type. -1 when out of memory. */
static int fxs_pt_enc_vel(struct fxs_pt_enc *e, const struct fxs_particles *p)
{
    const struct fxs_pt_frame *f = &e->f;
    const int32_t *nbs = e->nbs;
    uint32_t n = f->n, zx = 0;
    int32_t qmax = fxs_pt_vqmax(f->vel_bits), *qv = malloc(12 * (size_t)n);
    double scale[3];
    struct fxs_pt_ew w;
    if (!qv) return -1;
    for (int a = 0; a < 3; a++) scale[a] = f->vstep[a] > 0 ? 1.0 / f->vstep[a] : 0;
    for (uint32_t j = 0; j < n; j++)
        for (int a = 0; a < 3; a++) qv[3 * (size_t)j + a] = fxs_pt_vquant(p->vel[3 * (size_t)e->order[j] + a], scale[a], qmax);
    w = e->w;
    for (uint32_t j = 0; j < n; j++) {
        const int32_t *c = qv + 3 * (size_t)j, *o = nbs[j] < 0 ? NULL : qv + 3 * (size_t)nbs[j];
        unsigned fl = p->flags[e->order[j]];
        if (fxs_pt_room(&e->rb, &e->bb, &w)) {
            free(qv);
            return -1;
        }
        uint32_t zb = zx; /* the residual before: the previous particle's x, then this one's x, y */
        for (int a = 0; a < 3; a++) {
            uint32_t z = fxs_pt_zigzag(c[a] - (o ? o[a] : 0));
            fxs_pt_put_int(&w, e->m.v[fxs_pt_vctx(a, zb, fl)], FXS_PT_V_U, z);
            zb = z;
            if (!a) zx = z;
        }
    }
    e->w = w;
    free(qv);
    return 0;
}

/* Quantises positions into e->q (input order) and sets the axis bits. */
static void fxs_pt_enc_quant(struct fxs_pt_enc *e, const struct fxs_particles *p)
{
    struct fxs_pt_frame *f = &e->f;
    uint32_t qmax = (1u << f->pos_bits) - 1u, all[3] = { 0, 0, 0 };
    double scale = f->step[0] > 0 ? 1.0 / f->step[0] : 0;
    for (uint32_t i = 0; i < p->n; i++) {
        for (int a = 0; a < 3; a++) {
            uint32_t v = fxs_pt_quant(p->xyz[3 * i + a], f->lo[a], scale, qmax);
            e->q[3 * (size_t)i + a] = v;
            all[a] |= v;
        }
    }
    for (int a = 0; a < 3; a++) f->abits[a] = all[a] ? 32 - __builtin_clz(all[a]) : 0;
}

static void fxs_pt_header(const struct fxs_pt_frame *f, uint8_t *out, uint32_t rc_len, uint32_t bits_len)
{
    memset(out, 0, FXS_PARTICLES_HEADER_BYTES);
    memcpy(out, FXS_PT_MAGIC, 4);
    out[4] = FXS_PT_VERSION;
    out[5] = (uint8_t)f->pos_bits;
    out[6] = (uint8_t)f->temp_bits;
    out[7] = (uint8_t)f->fuel_bits;
    for (int a = 0; a < 3; a++) out[8 + a] = (uint8_t)f->abits[a];
    out[11] = (uint8_t)(f->mode | (f->vel ? FXS_PT_HAS_VEL : 0u));
    fxs_put_u32(out + 12, f->n);
    for (int c = 0; c < 3; c++) {
        fxs_put_f32(out + 16 + 4 * c, f->lo[c]);
        fxs_put_f32(out + 28 + 4 * c, f->hi[c]);
    }
    fxs_put_f32(out + 40, f->lo[3]);
    fxs_put_f32(out + 44, f->hi[3]);
    fxs_put_f32(out + 48, f->lo[4]);
    fxs_put_f32(out + 52, f->hi[4]);
    fxs_put_u32(out + 56, rc_len);
    fxs_put_u32(out + 60, bits_len);
    if (f->vel) {
        uint8_t *vb = out + FXS_PARTICLES_HEADER_BYTES;
        memset(vb, 0, FXS_PARTICLES_VEL_BLOCK_BYTES);
        vb[0] = (uint8_t)f->vel_bits;
        for (int a = 0; a < 3; a++) fxs_put_f32(vb + 4 + 4 * a, f->vmax[a]);
    }
}

static int fxs_pt_opts(const struct fxs_particles_opts *o, struct fxs_pt_frame *f)
{
    f->pos_bits = o && o->pos_bits ? o->pos_bits : FXS_PARTICLES_DEFAULT_POS_BITS;
    f->temp_bits = o && o->temp_bits ? o->temp_bits : FXS_PARTICLES_DEFAULT_TEMP_BITS;
    f->fuel_bits = o && o->fuel_bits ? o->fuel_bits : FXS_PARTICLES_DEFAULT_FUEL_BITS;
    f->vel_bits = o && o->vel_bits ? o->vel_bits : FXS_PARTICLES_DEFAULT_VEL_BITS;
    if (f->pos_bits < 8 || f->pos_bits > 24) return -1;
    if (f->temp_bits < 2 || f->temp_bits > 16 || f->fuel_bits < 2 || f->fuel_bits > 16) return -1;
    if (f->vel_bits < 2 || f->vel_bits > 16) return -1;
    return 0;
}

static int fxs_pt_check_input(const struct fxs_particles *p, char *err, size_t errlen)
{
    if (!p) return fxs_pt_fail(err, errlen, "no particles given");
    if (p->n > FXS_PARTICLES_MAX_N) return fxs_pt_fail(err, errlen, "too many particles");
    if (p->n && (!p->xyz || !p->temp || !p->fuel || !p->flags))
        return fxs_pt_fail(err, errlen, "missing particle array");
    return 0;
}

/* Runs both passes and assembles header + range-coder bytes + raw bits (the range-coder
 * section is written after room for the header, the raw bits appended to it). */
static int fxs_pt_enc_run(struct fxs_pt_enc *e, const struct fxs_particles *p, uint8_t **out, size_t *out_len)
{
    uint32_t n = p->n;
    size_t rl = 0, bl = 0, nn = n, hb = fxs_pt_hdr_bytes(&e->f);
    struct fxs_pt_ew *w = &e->w;
    uint8_t *s;
    fxs_pt_steps(&e->f);
    fxs_pt_ew_init(w);
    if (!(w->rp = fxs_pt_grow(&e->rb, NULL, hb + nn + 4096))) return -1;
    w->rp += hb;
    if (n) {
        /* 32n pd, 16n keys, 8n indices, 4n nbs + n sk (in 8n), 12n + 9n q */
        if (!(s = e->scratch = malloc(nn * 85 + 8))) return -1;
        e->pd = (double *)s;
        e->keys = (uint64_t *)(e->pd + 4 * nn);
        e->idx = (uint32_t *)(e->keys + 2 * nn);
        e->nbs = (int32_t *)(e->idx + 2 * nn);
        e->q = (uint32_t *)(e->nbs + 2 * nn);
        fxs_pt_enc_quant(e, p);
        fxs_pt_schedule(&e->f);
        fxs_pt_models_init(&e->m);
        fxs_pt_cclass_init();
        if (!(w->bp = fxs_pt_grow(&e->bb, NULL, nn + 4096))) return -1;
        if (e->f.abits[0] <= 21 && e->f.abits[1] <= 21 && e->f.abits[2] <= 21) {
            if (fxs_pt_enc_morton(e)) return -1;
        } else if (fxs_pt_enc_wide(e)) {
            return -1;
        }
        if (fxs_pt_enc_attrs(e, p) || (e->f.vel && fxs_pt_enc_vel(e, p)) || fxs_pt_room(&e->rb, &e->bb, w)) return -1;
        for (int i = 0; i < 5; i++) fxs_pt_rc_shift(w);
        for (; w->cnt > 0; w->cnt -= 8, w->acc >>= 8) *w->bp++ = (uint8_t)w->acc;
        rl = (size_t)(w->rp - e->rb.p) - hb;
        bl = (size_t)(w->bp - e->bb.p);
        if (rl > UINT32_MAX || bl > UINT32_MAX) return -1;
        if (!(w->rp = fxs_pt_grow(&e->rb, w->rp, bl))) return -1;
        if (bl) memcpy(w->rp, e->bb.p, bl);
    }
    fxs_pt_header(&e->f, e->rb.p, (uint32_t)rl, (uint32_t)bl);
    *out = e->rb.p;
    *out_len = hb + rl + bl;
    e->rb.p = NULL;
    return 0;
}

/* One block of p on the grid of f (its options and bounds set) into *out. 0, or -1 (out of
 * memory). */
static int fxs_pt_encode_block(const struct fxs_particles *p, const struct fxs_pt_frame *f, uint8_t **out,
                               size_t *out_len)
{
    struct fxs_pt_enc *e = calloc(1, sizeof *e);
    if (!e) return -1;
    e->f = *f;
    e->f.n = p->n;
    int r = fxs_pt_enc_run(e, p, out, out_len);
    free(e->scratch);
    free(e->rb.p);
    free(e->bb.p);
    free(e);
    return r;
}

/* ---- blocks (§7.5.8) ------------------------------------------------------------------- */

#define FXS_PT_SLAB_BINS 1024

/* Cuts p into at most k slabs of about n/k particles along the longest axis of f's box (a
 * histogram of FXS_PT_SLAB_BINS bins: a bin goes whole to one slab), copied into one
 * allocation (*mem) that the views b[] point into. Returns the number of non-empty slabs,
 * or -1 (out of memory). */
static int fxs_pt_slabs(const struct fxs_particles *p, const struct fxs_pt_frame *f, int k, struct fxs_particles *b,
                        void **mem)
{
    uint32_t n = p->n, hist[FXS_PT_SLAB_BINS] = {0}, at[FXS_PARTICLES_MAX_BLOCKS + 1] = {0};
    uint8_t slab[FXS_PT_SLAB_BINS];
    int a = 0;
    for (int c = 1; c < 3; c++)
        if ((double)f->hi[c] - f->lo[c] > (double)f->hi[a] - f->lo[a]) a = c;
    double ext = (double)f->hi[a] - f->lo[a], scale = ext > 0 ? FXS_PT_SLAB_BINS / ext : 0;
#define FXS_PT_BIN(i) ((int)fmin(FXS_PT_SLAB_BINS - 1, ((double)p->xyz[3 * (size_t)(i) + a] - f->lo[a]) * scale))
    for (uint32_t i = 0; i < n; i++) hist[FXS_PT_BIN(i)]++;
    uint64_t before = 0;
    for (int i = 0; i < FXS_PT_SLAB_BINS; i++) {
        uint64_t sl = before * (uint64_t)k / n;
        slab[i] = (uint8_t)(sl < (uint64_t)k ? sl : (uint64_t)k - 1);
        at[slab[i] + 1] += hist[i];
        before += hist[i];
    }
    for (int s = 0; s < k; s++) at[s + 1] += at[s];
    size_t per = 12 + 4 + 4 + 1 + (p->vel ? 12 : 0);
    uint8_t *m = *mem = malloc(per * n);
    if (!m) return -1;
    float *xyz = (float *)m, *temp = xyz + 3 * (size_t)n, *fuel = temp + n, *vel = p->vel ? fuel + n : NULL;
    uint8_t *flags = (uint8_t *)(fuel + n + (p->vel ? 3 * (size_t)n : 0));
    uint32_t fill[FXS_PARTICLES_MAX_BLOCKS];
    memcpy(fill, at, sizeof(uint32_t) * (size_t)k);
    for (uint32_t i = 0; i < n; i++) {
        uint32_t j = fill[slab[FXS_PT_BIN(i)]]++;
        memcpy(xyz + 3 * (size_t)j, p->xyz + 3 * (size_t)i, 12);
        temp[j] = p->temp[i];
        fuel[j] = p->fuel[i];
        flags[j] = p->flags[i];
        if (vel) memcpy(vel + 3 * (size_t)j, p->vel + 3 * (size_t)i, 12);
    }
#undef FXS_PT_BIN
    int nb = 0;
    for (int s = 0; s < k; s++)
        if (at[s + 1] > at[s])
            b[nb++] = (struct fxs_particles){at[s + 1] - at[s], xyz + 3 * (size_t)at[s], temp + at[s], fuel + at[s],
                                             flags + at[s], vel ? vel + 3 * (size_t)at[s] : NULL};
    return nb;
}

struct fxs_pt_job {
    struct fxs_particles p;
    const struct fxs_pt_frame *f;
    uint8_t *out;
    size_t len;
    int r;
    pthread_t thread;
    int started;
};

static void *fxs_pt_job_run(void *arg)
{
    struct fxs_pt_job *j = arg;
    j->r = fxs_pt_encode_block(&j->p, j->f, &j->out, &j->len);
    return NULL;
}

/* p as up to k blocks on f's grid, coded in parallel (the calling thread takes the first;
 * a thread that cannot be started is run here), concatenated into *out. 0 or -1. */
static int fxs_pt_encode_blocks(const struct fxs_particles *p, const struct fxs_pt_frame *f, int k, uint8_t **out,
                                size_t *out_len)
{
    struct fxs_particles b[FXS_PARTICLES_MAX_BLOCKS];
    struct fxs_pt_job jobs[FXS_PARTICLES_MAX_BLOCKS];
    void *mem = NULL;
    int nb = fxs_pt_slabs(p, f, k, b, &mem), r = nb < 0 ? -1 : 0;
    fxs_pt_cclass_init(); /* the shared table, before the threads read it */
    for (int i = 0; i < nb; i++) {
        jobs[i] = (struct fxs_pt_job){.p = b[i], .f = f};
        if (i) jobs[i].started = !pthread_create(&jobs[i].thread, NULL, fxs_pt_job_run, &jobs[i]);
    }
    size_t total = 0;
    for (int i = 0; i < nb; i++) {
        if (!i || !jobs[i].started) fxs_pt_job_run(&jobs[i]);
        else pthread_join(jobs[i].thread, NULL);
        r |= jobs[i].r;
        total += jobs[i].r ? 0 : jobs[i].len;
    }
    uint8_t *o = r ? NULL : malloc(total ? total : 1);
    if (!o) r = -1;
    for (size_t i = 0, at = 0; i < (size_t)(nb > 0 ? nb : 0); i++) {
        if (o) memcpy(o + at, jobs[i].out, jobs[i].len);
        at += jobs[i].len;
        free(jobs[i].out);
    }
    free(mem);
    *out = o;
    *out_len = total;
    return r;
}

int fxs_particles_encode(const struct fxs_particles *p, const struct fxs_particles_opts *opts, uint8_t **out,
                         size_t *out_len, char *err, size_t errlen)
{
    struct fxs_pt_frame f;
    memset(&f, 0, sizeof f);
    if (fxs_pt_check_input(p, err, errlen)) return -1;
    if (fxs_pt_opts(opts, &f))
        return fxs_pt_fail(err, errlen, "pos_bits must be 8..24, temp_bits, fuel_bits and vel_bits 2..16");
    if (fxs_pt_bounds(p, &f)) return fxs_pt_fail(err, errlen, "non-finite position, temperature, fuel or velocity");
    uint32_t k = opts && opts->threads > 1 ? (uint32_t)opts->threads : 1u;
    if (k > p->n / FXS_PARTICLES_BLOCK_MIN) k = p->n / FXS_PARTICLES_BLOCK_MIN;
    if (k > FXS_PARTICLES_MAX_BLOCKS) k = FXS_PARTICLES_MAX_BLOCKS;
    int r = k > 1 ? fxs_pt_encode_blocks(p, &f, (int)k, out, out_len) : fxs_pt_encode_block(p, &f, out, out_len);
    return r ? fxs_pt_fail(err, errlen, "out of memory") : 0;
}

/* ---- decoder --------------------------------------------------------------------------- */

struct fxs_pt_dec {
    struct fxs_pt_frame f;
    struct fxs_pt_dec_io io;
    struct fxs_pt_models m;
    uint32_t *q;      /* 3n coordinates in tree order */
    int32_t *nbs;     /* n: each particle's nearest recent neighbour (-1: none), for the velocities */
    uint32_t out;     /* particles placed so far */
};

/* Decodes the subtree of c points at depth d whose coordinates start with base. */
static int fxs_pt_dec_node(struct fxs_pt_dec *d, uint32_t c, int depth, uint32_t bx, uint32_t by, uint32_t bz)
{
    const struct fxs_pt_frame *f = &d->f;
    uint32_t base[3] = { bx, by, bz };
    while (c >= 2 && depth < f->depth) {
        int a = f->axis[depth], sh = f->left[depth][a] - 1;
        uint32_t z;
        int64_t lo;
        if (fxs_pt_get_int(&d->io, d->m.cnt[fxs_pt_cclass(c) * 3 + a], FXS_PT_CNT_U, &z)) return -1;
        lo = (int64_t)(c >> 1) + fxs_pt_unzigzag(z);
        if (lo < 0 || lo > (int64_t)c || d->io.rc.bad) return -1;
        depth++;
        if (lo && lo < (int64_t)c) {
            if (fxs_pt_dec_node(d, (uint32_t)lo, depth, base[0], base[1], base[2])) return -1;
            c -= (uint32_t)lo;
            base[a] |= 1u << sh;
        } else if (!lo) {
            base[a] |= 1u << sh;
        }
    }
    if (c == 1)
        for (int a = 0; a < 3; a++) {
            uint32_t v;
            if (fxs_pt_bits_get(&d->io.bits, f->left[depth][a], &v)) return -1;
            base[a] |= v;
        }
    for (uint32_t k = 0; k < c; k++, d->out++) memcpy(d->q + 3 * (size_t)d->out, base, sizeof base);
    return 0;
}

/* float32(lo + q * step) of every value of particle j. */
static inline void fxs_pt_dec_out(const struct fxs_pt_frame *f, struct fxs_particles *p, const uint32_t *q, uint32_t j,
                                  uint32_t t, uint32_t fu)
{
    for (int a = 0; a < 3; a++) p->xyz[3 * j + a] = (float)(f->lo[a] + q[3 * j + a] * f->step[a]);
    p->temp[j] = (float)(f->lo[3] + t * f->step[3]);
    if (p->fuel) p->fuel[j] = (float)(f->lo[4] + fu * f->step[4]);
}

static int fxs_pt_dec_attrs0(struct fxs_pt_dec *d, struct fxs_particles *p, uint32_t *qt, uint32_t *qf)
{
    const struct fxs_pt_frame *f = &d->f;
    const uint32_t *q = d->q;
    uint32_t zt = 0, zf = 0;
    uint64_t dist[FXS_PT_SAME];
    for (uint32_t j = 0; j < f->n; j++) {
        int64_t nb = fxs_pt_near(q, j, dist, FXS_PT_NEAR);
        uint32_t nt = nb < 0 ? 0 : qt[nb], nf = nb < 0 ? 0 : qf[nb];
        unsigned nfl = nb < 0 ? 0 : p->flags[nb], v = nfl;
        int f0 = nf == 0;
        int64_t t, fu;
        d->nbs[j] = (int32_t)nb;
        if (fxs_pt_rc_get(&d->io.rc, &d->m.same[(nfl & 7u) * 2 + (unsigned)f0])) {
            unsigned m = 1;
            while (m < 256) m = 2 * m + (unsigned)fxs_pt_rc_get(&d->io.rc, &d->m.tree[m]);
            v = m - 256;
            if (v == nfl) return -1;
        }
        fxs_pt_prob *pt = d->m.t[(fxs_pt_rclass(zt) * 8 + (int)(v & 7u)) * 2 + f0];
        fxs_pt_prob *pf = d->m.f[(fxs_pt_rclass(zf) * 2 + f0) * 2 + (int)(v >> 2 & 1u)];
        if (fxs_pt_get_int(&d->io, pt, FXS_PT_T_U, &zt) || fxs_pt_get_int(&d->io, pf, FXS_PT_F_U, &zf)) return -1;
        t = (int64_t)nt + fxs_pt_unzigzag(zt);
        fu = (int64_t)nf + fxs_pt_unzigzag(zf);
        if (t < 0 || t >> f->temp_bits || fu < 0 || fu >> f->fuel_bits || d->io.rc.bad) return -1;
        qt[j] = (uint32_t)t;
        qf[j] = (uint32_t)fu;
        p->flags[j] = (uint8_t)v;
        fxs_pt_dec_out(f, p, q, j, qt[j], qf[j]);
    }
    return 0;
}

static int fxs_pt_dec_attrs1(struct fxs_pt_dec *d, struct fxs_particles *p, uint32_t *qt, uint32_t *qf)
{
    const struct fxs_pt_frame *f = &d->f;
    const uint32_t *q = d->q;
    uint8_t *fl = p->flags;
    int64_t last[256];
    uint64_t dist[FXS_PT_SAME];
    for (int i = 0; i < 256; i++) last[i] = -1;
    for (uint32_t j = 0; j < f->n; j++) {
        int64_t nb = fxs_pt_near(q, j, dist, FXS_PT_SAME), sb;
        uint32_t v, t, fu = 0;
        unsigned c;
        int nf0 = nb < 0 || qf[nb] == 0, tb;
        unsigned nfl = nb < 0 ? 0 : fl[nb], nc = nb < 0 ? 8 : nfl & 7u;
        d->nbs[j] = (int32_t)nb;
        v = nfl;
        if (fxs_pt_rc_get(&d->io.rc, &d->m.vsame[nc * 2 + (unsigned)nf0])) {
            if (fxs_pt_get_tree(&d->io, d->m.vfl[nc], 8, &v)) return -1;
            if (v == nfl) return -1;
        }
        c = v & 7u;
        fl[j] = (uint8_t)v;
        sb = fxs_pt_same(fl, j, dist, v, last);
        tb = sb < 0 ? 8 : fxs_pt_top(qt[sb], f->temp_bits, 3);
        if (fxs_pt_get_tree(&d->io, d->m.vt[c * 9 + (unsigned)tb], f->temp_bits, &t)) return -1;
        if (fxs_pt_rc_get(&d->io.rc, &d->m.vf0[(c * 16 + (unsigned)fxs_pt_top(t, f->temp_bits, 4)) * 2 + (unsigned)nf0])) {
            if (fxs_pt_get_tree(&d->io, d->m.vf[c * 8 + (unsigned)fxs_pt_top(t, f->temp_bits, 3)], f->fuel_bits, &fu))
                return -1;
            if (++fu >> f->fuel_bits) return -1;
        }
        if (d->io.rc.bad) return -1;
        qt[j] = t;
        qf[j] = fu;
        last[v] = j;
        fxs_pt_dec_out(f, p, q, j, t, fu);
    }
    return 0;
}

/* Velocities (§7.5.7) of every particle in tree order, after the attributes; qv: scratch
 * for 3n values. */
static int fxs_pt_dec_vel(struct fxs_pt_dec *d, struct fxs_particles *p, int32_t *qv)
{
    const struct fxs_pt_frame *f = &d->f;
    int32_t qmax = fxs_pt_vqmax(f->vel_bits);
    uint32_t zx = 0;
    for (uint32_t j = 0; j < f->n; j++) {
        int32_t *c = qv + 3 * (size_t)j, nb = d->nbs[j];
        uint32_t zb = zx, z;
        for (int a = 0; a < 3; a++) {
            int64_t v;
            if (fxs_pt_get_int(&d->io, d->m.v[fxs_pt_vctx(a, zb, p->flags[j])], FXS_PT_V_U, &z)) return -1;
            v = (int64_t)(nb < 0 ? 0 : qv[3 * (size_t)nb + a]) + fxs_pt_unzigzag(z);
            if (v < -qmax || v > qmax || d->io.rc.bad) return -1;
            c[a] = (int32_t)v;
            zb = z;
            if (!a) zx = z;
            if (p->vel) p->vel[3 * (size_t)j + a] = (float)(c[a] * f->vstep[a]);
        }
    }
    return 0;
}

static int fxs_pt_parse_header(const uint8_t *buf, size_t len, struct fxs_pt_frame *f, uint32_t *rl, uint32_t *bl)
{
    if (len < FXS_PARTICLES_HEADER_BYTES || memcmp(buf, FXS_PT_MAGIC, 4)) return -1;
    if (buf[4] != FXS_PT_VERSION) return -2;
    f->pos_bits = buf[5];
    f->temp_bits = buf[6];
    f->fuel_bits = buf[7];
    for (int a = 0; a < 3; a++) f->abits[a] = buf[8 + a];
    f->mode = buf[11] & 0x0Fu;
    f->vel = (buf[11] & FXS_PT_HAS_VEL) != 0;
    f->n = fxs_get_u32(buf + 12);
    for (int c = 0; c < 3; c++) {
        f->lo[c] = fxs_get_f32(buf + 16 + 4 * c);
        f->hi[c] = fxs_get_f32(buf + 28 + 4 * c);
    }
    f->lo[3] = fxs_get_f32(buf + 40);
    f->hi[3] = fxs_get_f32(buf + 44);
    f->lo[4] = fxs_get_f32(buf + 48);
    f->hi[4] = fxs_get_f32(buf + 52);
    *rl = fxs_get_u32(buf + 56);
    *bl = fxs_get_u32(buf + 60);
    if ((buf[11] & ~FXS_PT_HAS_VEL) > 1) return -3;
    if (f->vel) {
        const uint8_t *vb = buf + FXS_PARTICLES_HEADER_BYTES;
        if (len < FXS_PARTICLES_HEADER_BYTES + FXS_PARTICLES_VEL_BLOCK_BYTES) return -1;
        if (vb[1] || vb[2] || vb[3]) return -4;
        f->vel_bits = vb[0];
        for (int a = 0; a < 3; a++) f->vmax[a] = fxs_get_f32(vb + 4 + 4 * a);
    }
    return 0;
}

static const char *fxs_pt_check_frame(const struct fxs_pt_frame *f)
{
    if (f->pos_bits < 8 || f->pos_bits > 24 || f->temp_bits < 2 || f->temp_bits > 16 || f->fuel_bits < 2 ||
        f->fuel_bits > 16)
        return "bad bit widths";
    for (int a = 0; a < 3; a++)
        if (f->abits[a] > f->pos_bits) return "bad axis bits";
    if (f->n > FXS_PARTICLES_MAX_N) return "particle count over the limit";
    for (int c = 0; c < 5; c++)
        if (!isfinite(f->lo[c]) || !isfinite(f->hi[c]) || f->lo[c] > f->hi[c]) return "bad bounds";
    if (f->vel && (f->vel_bits < 2 || f->vel_bits > 16)) return "bad velocity bits";
    for (int a = 0; a < 3 && f->vel; a++)
        if (!isfinite(f->vmax[a]) || !(f->vmax[a] >= 0)) return "bad velocity bounds";
    return NULL;
}

static int fxs_pt_alloc_out(struct fxs_particles *p, uint32_t n, int vel)
{
    size_t m = n ? n : 1;
    p->n = n;
    p->xyz = malloc(3 * m * sizeof *p->xyz);
    p->temp = malloc(m * sizeof *p->temp);
    p->fuel = malloc(m * sizeof *p->fuel);
    p->flags = malloc(m);
    p->vel = vel ? malloc(3 * m * sizeof *p->vel) : NULL;
    if (p->xyz && p->temp && p->fuel && p->flags && (p->vel || !vel)) return 0;
    fxs_particles_free(p);
    return -1;
}

/* Decodes both sections after the header; NULL or the reason for rejecting. */
static const char *fxs_pt_dec_body(struct fxs_pt_dec *d, const uint8_t *buf, size_t len, uint32_t rl, uint32_t bl,
                                   struct fxs_particles *p)
{
    size_t hb = fxs_pt_hdr_bytes(&d->f), nn = d->f.n;
    const uint8_t *body = buf + hb;
    uint32_t *qa;
    const char *why = NULL;
    if ((uint64_t)hb + rl + bl != len) return "section sizes do not match the payload length";
    if (!d->f.n) return rl || bl ? "bad sizes" : NULL;
    if (fxs_pt_rcr_init(&d->io.rc, body, rl)) return "corrupt particle data";
    d->io.bits.p = body + rl;
    d->io.bits.end = body + rl + bl;
    fxs_pt_steps(&d->f);
    fxs_pt_schedule(&d->f);
    fxs_pt_models_init(&d->m);
    /* 3n coordinates, n qT, n qF, n neighbours; 3n quantised velocities */
    if (!(qa = malloc(nn * (d->f.vel ? 9 : 6) * sizeof *qa))) return "out of memory";
    d->q = qa;
    d->nbs = (int32_t *)(qa + 5 * nn);
    if (fxs_pt_dec_node(d, d->f.n, 0, 0, 0, 0) || d->out != d->f.n ||
        (d->f.mode ? fxs_pt_dec_attrs1 : fxs_pt_dec_attrs0)(d, p, qa + 3 * nn, qa + 4 * nn) ||
        (d->f.vel && fxs_pt_dec_vel(d, p, (int32_t *)(qa + 6 * nn))))
        why = "corrupt particle data";
    else if (d->io.rc.bad || d->io.rc.p != d->io.rc.end)
        why = "corrupt particle data (range coder section not consumed exactly)";
    else if (d->io.bits.p != d->io.bits.end || d->io.bits.acc)
        why = "corrupt particle data (raw bits not consumed exactly)";
    free(qa);
    return why;
}

/* The block at buf (len bytes left): its frame and section sizes, checked, and its length.
 * NULL or the reason for rejecting. */
static const char *fxs_pt_block(const uint8_t *buf, size_t len, struct fxs_pt_frame *f, uint32_t *rl, uint32_t *bl,
                                size_t *blen)
{
    *rl = *bl = 0;
    int r = fxs_pt_parse_header(buf, len, f, rl, bl);
    const char *why = r == -1   ? "not a codec 2 payload (short or bad magic)"
                      : r == -2 ? "unsupported version"
                      : r == -3 ? "unknown attribute mode"
                      : r == -4 ? "non-zero reserved bytes in the velocity block"
                                : fxs_pt_check_frame(f);
    *blen = fxs_pt_hdr_bytes(f) + (size_t)*rl + *bl;
    if (!why && (uint64_t)fxs_pt_hdr_bytes(f) + *rl + *bl > len) why = "section sizes do not match the payload length";
    return why;
}

/* Every block's header and length (§7.5.8): the total count and whether they carry
 * velocities (all or none). NULL or the reason for rejecting. */
static const char *fxs_pt_blocks(const uint8_t *buf, size_t len, uint32_t *n, int *vel)
{
    struct fxs_pt_frame f;
    uint32_t rl, bl, blocks = 0;
    uint64_t total = 0;
    const char *why = NULL;
    for (size_t at = 0, blen; !why && (at < len || !blocks); at += blen) {
        memset(&f, 0, sizeof f);
        if ((why = fxs_pt_block(buf + at, len - at, &f, &rl, &bl, &blen))) break;
        if (blocks && f.vel != *vel) why = "blocks disagree on velocities";
        else if (++blocks > FXS_PARTICLES_MAX_BLOCKS) why = "more blocks than allowed";
        else if ((total += f.n) > FXS_PARTICLES_MAX_N) why = "particle count over the limit";
        *vel = f.vel;
    }
    *n = (uint32_t)total;
    return why;
}

uint32_t fxs_particles_codec(const uint8_t *payload, size_t len)
{
    struct fxs_pt_frame f;
    uint32_t rl, bl;
    size_t blen;
    memset(&f, 0, sizeof f);
    return !fxs_pt_block(payload, len, &f, &rl, &bl, &blen) && blen < len ? FXS_CODEC_PARTICLES_BLOCKS
                                                                           : FXS_CODEC_PARTICLES;
}

int fxs_particles_info(const uint8_t *buf, size_t len, uint32_t *n, int *vel, char *err, size_t errlen)
{
    const char *why;
    *n = 0;
    *vel = 0;
    if (!buf) return fxs_pt_fail(err, errlen, "no input");
    return (why = fxs_pt_blocks(buf, len, n, vel)) ? fxs_pt_fail(err, errlen, why) : 0;
}

/* The slice of a caller's array from index k, or NULL for no array (no arithmetic on NULL). */
#define FXS_PT_AT(a, k) ((a) ? (a) + (k) : NULL)

int fxs_particles_decode_into(const uint8_t *buf, size_t len, struct fxs_particles *p, uint32_t capacity, char *err,
                              size_t errlen)
{
    struct fxs_pt_dec *d;
    uint32_t n, rl, bl;
    int vel;
    const char *why = NULL;
    if (fxs_particles_info(buf, len, &n, &vel, err, errlen)) return -1;
    if (n > capacity) {
        p->n = n;
        return 1;
    }
    if (n && (!p->xyz || !p->temp || !p->flags)) return fxs_pt_fail(err, errlen, "no output arrays given");
    p->n = n;
    /* each block into its slice of the output, particles in block order */
    for (size_t at = 0, blen, out = 0; !why && at < len; at += blen) {
        if (!(d = calloc(1, sizeof *d))) {
            why = "out of memory";
            break;
        }
        fxs_pt_block(buf + at, len - at, &d->f, &rl, &bl, &blen);
        struct fxs_particles view = {d->f.n, FXS_PT_AT(p->xyz, 3 * out), FXS_PT_AT(p->temp, out),
                                     FXS_PT_AT(p->fuel, out), FXS_PT_AT(p->flags, out),
                                     vel ? FXS_PT_AT(p->vel, 3 * out) : NULL};
        why = fxs_pt_dec_body(d, buf + at, blen, rl, bl, &view);
        out += d->f.n;
        free(d);
    }
    return why ? fxs_pt_fail(err, errlen, why) : 0;
}

int fxs_particles_decode(const uint8_t *buf, size_t len, struct fxs_particles *p, char *err, size_t errlen)
{
    uint32_t n;
    int vel;
    if (!p) return fxs_pt_fail(err, errlen, "no output given");
    memset(p, 0, sizeof *p);
    if (fxs_particles_info(buf, len, &n, &vel, err, errlen)) return -1;
    if (fxs_pt_alloc_out(p, n, vel)) return fxs_pt_fail(err, errlen, "out of memory");
    if (!fxs_particles_decode_into(buf, len, p, n, err, errlen)) return 0;
    fxs_particles_free(p);
    return -1;
}

void fxs_particles_free(struct fxs_particles *p)
{
    if (!p) return;
    free(p->xyz);
    free(p->temp);
    free(p->fuel);
    free(p->flags);
    free(p->vel);
    memset(p, 0, sizeof *p);
}
