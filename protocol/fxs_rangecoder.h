/* fxs_rangecoder.h — the entropy stage of the particle codec (PROTOCOL.md §7.5.4), both
 * directions: an adaptive binary range coder (LZMA's: 12-bit probabilities that adapt by
 * 1/32 of the distance to 0 or 4096, 32-bit range, carry propagated through a cache byte)
 * for every modelled decision, a raw LSB-first bit section for the incompressible bits, and
 * the three shapes built on them: integers (unary prefix, Exp-Golomb class, top mantissa bit
 * modelled, the rest raw), values as bit trees, and small counts (a 3-level bit tree with an
 * escape, all in the range coder: three decisions without a branch in the common case).
 *
 * Everything is static inline: the codec's hot loops call these once per decision, and the
 * compiler keeps the coder's state in registers only when it sees the whole loop. Only the
 * encoder's buffer growth is out of line (fxs_rangecoder.c). */
#ifndef FXS_RANGECODER_H
#define FXS_RANGECODER_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "fxs_bytes.h"

#define FXS_RC_PROB_BITS 12
#define FXS_RC_PROB_INIT (1u << (FXS_RC_PROB_BITS - 1))
#define FXS_RC_ADAPT 5
#define FXS_RC_TOP (1u << 24)
#define FXS_RC_MAXK 24 /* Exp-Golomb classes 0..23 */
/* Probabilities of an integer model with u unary decisions: the u decisions, the class in
 * unary (FXS_RC_MAXK), then the top mantissa bit by class (FXS_RC_MAXK). */
#define FXS_RC_IPROBS(u) ((u) + 2 * FXS_RC_MAXK)
/* Probabilities of a small-count model: the 3-level tree's 7 (p[1 ... 7]; p[0] unused), then
 * the escape's Exp-Golomb class in unary. */
#define FXS_RC_SMALL_ESC 7u
#define FXS_RC_SPROBS (8 + FXS_RC_MAXK)
/* The probability of an equiprobable decision ("direct bit"), never adapted. */
#define FXS_RC_HALF FXS_RC_PROB_INIT

typedef uint16_t fxs_rc_prob;

/* The decoder's functions are inlined whatever the compiler's estimate: called out of line
 * they would keep the decoder's state in memory, on the decisions' dependency chain. */
#if defined(__GNUC__)
#define FXS_RC_INLINE static inline __attribute__((always_inline))
#else
#define FXS_RC_INLINE static inline
#endif

/* ---- decoder: range decoder and raw bits reader ----------------------------------------- */

/* Zero bytes after each section in the decoder's copy of it: the hot loops read ahead
 * without checking and test the positions (fxs_rc_past) once per particle or tree node,
 * which takes at most 81 decisions (a byte each at most) and 72 raw bits, and the raw bits
 * are loaded 8 bytes at a time. Past its end a section reads as zeros, as LZMA's decoder
 * shifts in; a payload that gets there is rejected at the next test. */
#define FXS_RC_PAD 256u

/* The decoder of both sections. The hot loops copy it into a local (the compiler keeps the
 * fields in registers) and write it back at the end. */
struct fxs_rc_dec {
    const uint8_t *p;        /* next byte of the range-coder section */
    const uint8_t *bp;       /* next byte of the raw bits not yet loaded into acc */
    uint64_t acc;            /* raw bits loaded, next first; the low cnt are valid */
    uint32_t range, code;
    int cnt;
};

/* The sections rc (rl bytes: a zero byte, then the first four bytes of code) and bits, each
 * followed by FXS_RC_PAD zero bytes. -1 when the range coder cannot start so. */
static inline int fxs_rc_dec_init(struct fxs_rc_dec *d, const uint8_t *rc, size_t rl, const uint8_t *bits)
{
    if (rl < 5 || rc[0] != 0) return -1;
    d->p = rc + 5;
    d->range = 0xFFFFFFFFu;
    d->code = (uint32_t)rc[1] << 24 | (uint32_t)rc[2] << 16 | (uint32_t)rc[3] << 8 | rc[4]; /* big endian */
    d->bp = bits;
    d->acc = 0;
    d->cnt = 0;
    return d->code == 0xFFFFFFFFu ? -1 : 0;
}

/* One decision with probability *p (of a 0), which then adapts as the encoder's
 * fxs_rc_bit does. For decisions the caller branches on: the compiler may decode with a
 * branch, which costs least when the bit is predictable. */
FXS_RC_INLINE unsigned fxs_rc_get(struct fxs_rc_dec *d, fxs_rc_prob *p)
{
    uint32_t pv = *p, bound = (d->range >> FXS_RC_PROB_BITS) * pv;
    unsigned bit = d->code >= bound;
    uint32_t mask = 0u - bit;
    d->code -= bound & mask;
    d->range = bit ? d->range - bound : bound;
    *p = (fxs_rc_prob)(pv - (uint32_t)((int32_t)(pv - (((1u << FXS_RC_PROB_BITS) - 31u) & ~mask)) >> FXS_RC_ADAPT));
    if (d->range < FXS_RC_TOP) {
        d->range <<= 8;
        d->code = d->code << 8 | *d->p++;
    }
    return bit;
}

/* fxs_rc_get with the probability's value pv loaded by the caller, without a branch on the
 * bit: for decisions whose bit only feeds arithmetic (a tree's next node). *next becomes
 * p0 after a 0, p1 after a 1 (the next node's probability, loaded by the caller before the
 * bit is known). On x86-64 the subtraction code - bound sets the carry flag that picks the
 * new range, the new code and *next: cmovs on one flag, no setcc/test on the range's chain
 * (and GCC, left to itself, turns these selects into branches on the bit, which mispredict
 * on every other decision of a value tree). Elsewhere (WebAssembly: Clang) plain selects. */
FXS_RC_INLINE unsigned fxs_rc_get_next(struct fxs_rc_dec *d, fxs_rc_prob *p, uint32_t pv, uint32_t p0, uint32_t p1,
                                       uint32_t *next)
{
    uint32_t bound = (d->range >> FXS_RC_PROB_BITS) * pv, range = bound, code = d->code, bit;
#if defined(__GNUC__) && defined(__x86_64__)
    uint32_t rhi = d->range - bound, chi;
    bit = 0;
    __asm__("movl %[code], %[chi]\n\t"
            "subl %[bound], %[chi]\n\t"
            "cmovnc %[rhi], %[range]\n\t"
            "cmovnc %[chi], %[code]\n\t"
            "cmovnc %[p1], %[p0]\n\t"
            "setnc %b[bit]"
            : [chi] "=&r"(chi), [range] "+r"(range), [code] "+r"(code), [bit] "+q"(bit), [p0] "+r"(p0)
            : [bound] "r"(bound), [rhi] "r"(rhi), [p1] "r"(p1)
            : "cc");
#else
    bit = code >= bound;
    range = bit ? d->range - bound : range;
    p0 = bit ? p1 : p0;
    code -= bound & (0u - bit);
#endif
    *next = p0;
    *p = (fxs_rc_prob)(pv - (uint32_t)((int32_t)(pv - (((1u << FXS_RC_PROB_BITS) - 31u) & (bit - 1u))) >> FXS_RC_ADAPT));
    d->range = range, d->code = code;
    if (d->range < FXS_RC_TOP) {
        d->range <<= 8;
        d->code = d->code << 8 | *d->p++;
    }
    return bit;
}

/* fxs_rc_get_next for a tree's last decision (no next node). */
FXS_RC_INLINE unsigned fxs_rc_get_pv(struct fxs_rc_dec *d, fxs_rc_prob *p, uint32_t pv)
{
    uint32_t unused;
    return fxs_rc_get_next(d, p, pv, 0, 0, &unused);
}

/* n raw bits (n <= 56), LSB first. The buffer is refilled to at least 56 bits on every
 * read, without a branch: the bytes at bp land at bit cnt (bits already there past cnt are
 * the same stream bits, loaded before). */
FXS_RC_INLINE uint64_t fxs_rc_raw(struct fxs_rc_dec *d, int n)
{
    uint64_t v, next;
    memcpy(&next, d->bp, 8); /* one load; the bytes are little-endian */
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
    next = __builtin_bswap64(next);
#endif
    d->acc |= next << d->cnt;
    d->bp += (63 - d->cnt) >> 3;
    d->cnt |= 56;
    v = d->acc & ((1ull << n) - 1u);
    d->acc >>= n;
    d->cnt -= n;
    return v;
}

/* Whether d has read past the range-coder section ending at rc_end or taken raw bits past
 * bits_end. */
FXS_RC_INLINE int fxs_rc_past(const struct fxs_rc_dec *d, const uint8_t *rc_end, const uint8_t *bits_end)
{
    return d->p > rc_end || (d->bp - bits_end) * 8 > (ptrdiff_t)d->cnt;
}

/* Whether d has consumed both sections exactly: every range-coder byte, and the raw bits
 * up to the last byte's zero padding. */
static inline int fxs_rc_exact_rc(const struct fxs_rc_dec *d, const uint8_t *rc_end) { return d->p == rc_end; }
static inline int fxs_rc_exact_bits(const struct fxs_rc_dec *d, const uint8_t *bits_end)
{
    ptrdiff_t left = (ptrdiff_t)d->cnt - (d->bp - bits_end) * 8; /* bits of the section not taken */
    return left >= 0 && left < 8 && !(d->acc & ((1ull << left) - 1u));
}

/* An integer z >= 0 with the model p (FXS_RC_IPROBS(u) probabilities). Returns 0, or -1 for
 * a class beyond the limit. */
FXS_RC_INLINE int fxs_rc_get_int(struct fxs_rc_dec *d, fxs_rc_prob *p, int u, uint32_t *z)
{
    uint32_t e;
    int k = 0;
    for (int i = 0; i < u; i++)
        if (!fxs_rc_get(d, p + i)) {
            *z = (uint32_t)i;
            return 0;
        }
    while (fxs_rc_get(d, p + u + k))
        if (++k == FXS_RC_MAXK) return -1;
    e = 1;
    if (k) {
        e = 2u | fxs_rc_get(d, p + u + FXS_RC_MAXK + k);
        e = e << (k - 1) | (uint32_t)fxs_rc_raw(d, k - 1);
    }
    *z = e + (uint32_t)u - 1u;
    return 0;
}

/* A value of `bits` bits as a bit tree: the top min(bits, 8) bits high first with p[m]
 * (m = 1, then 2m + bit), then the low bits - 8 bits raw. With 8 or more bits, the tree's
 * 8 levels are unrolled and both children's probabilities loaded before the bit that picks
 * one is known, so the load is off the decisions' dependency chain. */
FXS_RC_INLINE uint32_t fxs_rc_get_tree(struct fxs_rc_dec *d, fxs_rc_prob *p, int bits)
{
    uint32_t m = 1;
    if (bits >= 8) {
        uint32_t pv = p[1];
        for (int i = 0; i < 7; i++) m = 2 * m + fxs_rc_get_next(d, p + m, pv, p[2 * m], p[2 * m + 1], &pv);
        m = 2 * m + fxs_rc_get_pv(d, p + m, pv);
        return (m - 256u) << (bits - 8) | (uint32_t)fxs_rc_raw(d, bits - 8);
    }
    while (m < 1u << bits) m = 2 * m + fxs_rc_get(d, p + m);
    return m - (1u << bits);
}

/* A small count z >= 0 with the model p (FXS_RC_SPROBS probabilities): three decisions
 * down a bit tree give s = 0 ... 7 without a branch (the next node's probability loaded
 * before the bit is known); s < 7 is z. s = 7 is an escape: e = z - 6 >= 1, its class
 * k = floor(log2 e) in unary with p[8 + i], then its low k bits as direct bits, high first.
 * Only the range coder is read. Returns 0, or -1 for a class beyond the limit. */
FXS_RC_INLINE int fxs_rc_get_small(struct fxs_rc_dec *d, fxs_rc_prob *p, uint32_t *z)
{
    uint32_t pv = p[1], m = 2 + fxs_rc_get_next(d, p + 1, pv, p[2], p[3], &pv), e = 1;
    m = 2 * m + fxs_rc_get_next(d, p + m, pv, p[2 * m], p[2 * m + 1], &pv);
    m = 2 * m + fxs_rc_get_pv(d, p + m, pv);
    *z = m - 8u;
    if (*z < FXS_RC_SMALL_ESC) return 0;
    int k = 0;
    while (fxs_rc_get(d, p + 8 + k))
        if (++k == FXS_RC_MAXK) return -1;
    for (int i = 0; i < k; i++) {
        fxs_rc_prob half = FXS_RC_HALF;
        e = 2 * e + fxs_rc_get(d, &half);
    }
    *z = e + FXS_RC_SMALL_ESC - 1u;
    return 0;
}

/* ---- encoder: range coder and raw bits writer --------------------------------------------- */

/* The encoder's whole output state. The hot loops copy it into a local (the compiler keeps
 * the fields in registers) and write it back at the end; they make room for the next
 * particle or node up front (fxs_rc_room), so that coding a decision or raw bits never
 * checks for space. */
struct fxs_rc_enc {
    uint8_t *rp, *bp;        /* next byte of the range-coder and of the raw-bits section */
    uint64_t low, acc;       /* range coder low (33 bits); raw bits not yet written */
    uint64_t pending;        /* bytes waiting on a carry: the cache byte and pending - 1 0xFFs */
    uint32_t range;
    int cnt;                 /* bits in acc */
    uint8_t cache;
};

/* A growing output section. */
struct fxs_rc_buf {
    uint8_t *p;
    size_t cap;
};

/* At most this many bytes per particle or tree node go to either section beyond the
 * pending carry run: every decision shifts out at most one byte (a range >= 2^24 times
 * the smallest probability 31/4096 is still >= 2^16), a node or particle codes at most
 * 60 decisions, and sends at most 3 x 24 raw bits. */
#define FXS_RC_SLACK 96u

/* Grows b so that at + need fits; returns the (moved) at, or NULL when out of memory. */
uint8_t *fxs_rc_grow(struct fxs_rc_buf *b, uint8_t *at, size_t need);

/* Makes room for one more particle or node in both sections; -1 when out of memory. */
static inline int fxs_rc_room(struct fxs_rc_buf *rb, struct fxs_rc_buf *bb, struct fxs_rc_enc *w)
{
    if ((size_t)(rb->p + rb->cap - w->rp) < FXS_RC_SLACK + w->pending && !(w->rp = fxs_rc_grow(rb, w->rp, FXS_RC_SLACK + w->pending)))
        return -1;
    if ((size_t)(bb->p + bb->cap - w->bp) < FXS_RC_SLACK && !(w->bp = fxs_rc_grow(bb, w->bp, FXS_RC_SLACK))) return -1;
    return 0;
}

/* Raw bits, LSB first (nbits <= 32). */
static inline void fxs_rc_bits_put(struct fxs_rc_enc *w, uint32_t v, int nbits)
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

/* Raw bits without a branch, for the kd-tree's leaves (fxs_rc_bits_put's flush every 32
 * bits is taken about once per leaf, irregularly: a misprediction). Needs
 * w->cnt + nbits <= 63; leaves w->cnt < 8, which fxs_rc_bits_put takes as is. Stores 8
 * bytes at w->bp (within FXS_RC_SLACK); those past the whole bytes are written again
 * later. */
static inline void fxs_rc_bits_put64(struct fxs_rc_enc *w, uint64_t v, int nbits)
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
static inline void fxs_rc_shift(struct fxs_rc_enc *w)
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
 * cmov: one cycle less on the range's dependency chain than and/andn/or of a mask). */
static inline void fxs_rc_bit(struct fxs_rc_enc *w, fxs_rc_prob *p, uint32_t bit)
{
    uint32_t pv = *p, bound = (w->range >> FXS_RC_PROB_BITS) * pv, mask = 0u - bit;
    w->low += bound & mask;
    w->range = bit ? w->range - bound : bound;
    *p = (fxs_rc_prob)(pv - (uint32_t)((int32_t)(pv - (((1u << FXS_RC_PROB_BITS) - 31u) & ~mask)) >> FXS_RC_ADAPT));
    if (w->range < FXS_RC_TOP) {
        w->range <<= 8;
        fxs_rc_shift(w);
    }
}

static inline void fxs_rc_enc_init(struct fxs_rc_enc *w)
{
    memset(w, 0, sizeof *w);
    w->range = 0xFFFFFFFFu;
    w->pending = 1;
}

/* Ends both sections: the range coder's last bytes, the raw bits' last partial byte. */
static inline void fxs_rc_enc_flush(struct fxs_rc_enc *w)
{
    for (int i = 0; i < 5; i++) fxs_rc_shift(w);
    for (; w->cnt > 0; w->cnt -= 8, w->acc >>= 8) *w->bp++ = (uint8_t)w->acc;
}

/* An integer z >= 0 with the model p (FXS_RC_IPROBS(u) probabilities): unary prefix of u
 * decisions, Exp-Golomb class in unary, the top mantissa bit modelled, the other mantissa
 * bits raw. */
static inline void fxs_rc_put_int(struct fxs_rc_enc *w, fxs_rc_prob *p, int u, uint32_t z)
{
    uint32_t e;
    int k;
    for (int i = 0; i < u; i++) {
        fxs_rc_bit(w, p + i, z > (uint32_t)i);
        if (z == (uint32_t)i) return;
    }
    e = z - (uint32_t)u + 1u;
    k = 31 - __builtin_clz(e);
    for (int i = 0; i < k; i++) fxs_rc_bit(w, p + u + i, 1);
    fxs_rc_bit(w, p + u + k, 0);
    if (k) {
        fxs_rc_bit(w, p + u + FXS_RC_MAXK + k, e >> (k - 1) & 1u);
        fxs_rc_bits_put(w, e, k - 1);
    }
}

/* A value tree: the top min(bits, 8) bits of v, high bit first, with p[m] (m = 1, then
 * 2m + bit); the low bits - 8 bits raw. */
static inline void fxs_rc_put_tree(struct fxs_rc_enc *w, fxs_rc_prob *p, uint32_t v, int bits)
{
    int low = bits > 8 ? bits - 8 : 0, b = bits - low;
    uint32_t top = v >> low | 1u << b;
    while (b-- > 0) fxs_rc_bit(w, p + (top >> (b + 1)), top >> b & 1u);
    fxs_rc_bits_put(w, v, low);
}

/* A small count z >= 0 with the model p (FXS_RC_SPROBS probabilities): min(z, 7) as a
 * 3-level bit tree, and for 7 the escape (fxs_rc_get_small), all in the range coder. */
static inline void fxs_rc_put_small(struct fxs_rc_enc *w, fxs_rc_prob *p, uint32_t z)
{
    uint32_t s = z < FXS_RC_SMALL_ESC ? z : FXS_RC_SMALL_ESC, e = z - FXS_RC_SMALL_ESC + 1u;
    fxs_rc_put_tree(w, p, s, 3);
    if (s < FXS_RC_SMALL_ESC) return;
    int k = 31 - __builtin_clz(e);
    for (int i = 0; i < k; i++) fxs_rc_bit(w, p + 8 + i, 1);
    fxs_rc_bit(w, p + 8 + k, 0);
    for (int i = k - 1; i >= 0; i--) {
        fxs_rc_prob half = FXS_RC_HALF;
        fxs_rc_bit(w, &half, e >> i & 1u);
    }
}

#endif
