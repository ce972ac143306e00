/* fxs_particles.c — kind 1 particle payloads, codec 1 (PROTOCOL.md §7.5).
 *
 * Owns quantisation, ordering and entropy coding of particle frames, shared by the
 * daemon (encode) and libfxclient (decode). Shape, chosen by measurement
 * (tests/bench/bench_particles.c):
 *   - positions quantised to pos_bits per axis relative to the frame's bounds, T and F
 *     to temp_bits / fuel_bits relative to their [min, max];
 *   - particles re-ordered by a coarse grid of 2^k cells per axis (cell id linear,
 *     x fastest), inside a cell by x: the set costs little more than its entropy and
 *     neighbours follow each other (clients must not rely on particle order anyway);
 *   - per particle 7 values (cell gap, x offset or its delta in the cell, y and z
 *     offsets, zigzag deltas of T and F, flags) mapped to tokens (small values direct,
 *     large ones as bit length + next bit, with raw extra bits);
 *   - tokens coded with one static-table rANS (12-bit probabilities, byte-wise
 *     renormalisation, one table per value kind), extra bits packed LSB first.
 * Both sides are a few hundred lines of integer code, so the browser decoder
 * (clients/web/fxs_particles.js) needs no dependency. The decoder validates every
 * length, table and value and checks that rANS ends in its initial state. */
#include "fxs_particles.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define FXS_PT_MAGIC "FXP1"
#define FXS_PT_VERSION 1u
#define FXS_PT_PROB_BITS 12
#define FXS_PT_PROB_SCALE (1u << FXS_PT_PROB_BITS)
#define FXS_PT_RANS_L (1u << 23)
#define FXS_PT_NTOK 72
#define FXS_PT_SLOTS 7
#define FXS_PT_MAX_CELL_BITS 10

/* Value kinds, each with its own frequency table, in table order. */
enum fxs_pt_stream { FXS_PT_CELL, FXS_PT_XSAME, FXS_PT_XNEW, FXS_PT_Y, FXS_PT_Z, FXS_PT_T, FXS_PT_F, FXS_PT_FLAGS, FXS_PT_NSTREAMS };

struct fxs_pt_table {
    int nsym;                       /* tokens 0..nsym-1 may occur */
    uint32_t freq[FXS_PT_NTOK];     /* sums to FXS_PT_PROB_SCALE (or all 0) */
    uint32_t start[FXS_PT_NTOK];
};

static int fxs_pt_fail(char *err, size_t errlen, const char *msg)
{
    if (err && errlen) snprintf(err, errlen, "particles: %s", msg);
    return -1;
}

/* ---- little-endian helpers ---------------------------------------------------------- */

static void fxs_pt_put32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}
static uint32_t fxs_pt_get32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}
static void fxs_pt_putf(uint8_t *p, float f)
{
    uint32_t v;
    memcpy(&v, &f, 4);
    fxs_pt_put32(p, v);
}
static float fxs_pt_getf(const uint8_t *p)
{
    uint32_t v = fxs_pt_get32(p);
    float f;
    memcpy(&f, &v, 4);
    return f;
}

/* ---- tokens ------------------------------------------------------------------------------ */

/* v < 16 is its own token; otherwise the token carries the bit length (5..32) and the
 * bit below the top one, and the len-2 lower bits go out raw. */
static inline unsigned fxs_pt_token(uint32_t v, uint32_t *extra, int *nbits)
{
    int len;
    if (v < 16) {
        *nbits = 0;
        *extra = 0;
        return v;
    }
    len = 32 - __builtin_clz(v);
    *nbits = len - 2;
    *extra = v & ((1u << (len - 2)) - 1u);
    return 16u + 2u * (unsigned)(len - 5) + ((v >> (len - 2)) & 1u);
}

static inline int fxs_pt_token_bits(unsigned tok) { return tok < 16 ? 0 : 5 + (int)(tok - 16) / 2 - 2; }

static inline uint32_t fxs_pt_untoken(unsigned tok, uint32_t extra)
{
    int nb;
    if (tok < 16) return tok;
    nb = fxs_pt_token_bits(tok);
    return ((2u | ((tok - 16) & 1u)) << nb) | extra;
}

static inline uint32_t fxs_pt_zigzag(int32_t d) { return ((uint32_t)d << 1) ^ (uint32_t)(d >> 31); }
static inline int32_t fxs_pt_unzigzag(uint32_t z) { return (int32_t)(z >> 1) ^ -(int32_t)(z & 1); }

/* ---- raw bits ------------------------------------------------------------------------------ */

struct fxs_pt_bitw {
    uint8_t *buf;
    size_t len;
    uint64_t acc;
    int cnt;
};

static inline void fxs_pt_bits_put(struct fxs_pt_bitw *w, uint32_t v, int nbits)
{
    w->acc |= (uint64_t)v << w->cnt;
    w->cnt += nbits;
    while (w->cnt >= 8) {
        w->buf[w->len++] = (uint8_t)w->acc;
        w->acc >>= 8;
        w->cnt -= 8;
    }
}

static void fxs_pt_bits_flush(struct fxs_pt_bitw *w)
{
    if (w->cnt > 0) w->buf[w->len++] = (uint8_t)w->acc;
    w->acc = 0;
    w->cnt = 0;
}

struct fxs_pt_bitr {
    const uint8_t *p, *end;
    uint64_t acc;
    int cnt;
};

/* Reads nbits (<= 30); returns -1 past the end. */
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

/* ---- frequency tables ----------------------------------------------------------------------- */

/* Scales counts to freqs summing to the probability scale, every used token >= 1. */
static void fxs_pt_normalize(const uint32_t *count, struct fxs_pt_table *t)
{
    uint64_t total = 0;
    uint32_t sum = 0;
    int best = 0;
    memset(t, 0, sizeof *t);
    for (int s = 0; s < FXS_PT_NTOK; s++) total += count[s];
    if (!total) return;
    for (int s = 0; s < FXS_PT_NTOK; s++) {
        if (!count[s]) continue;
        t->freq[s] = (uint32_t)((uint64_t)count[s] * FXS_PT_PROB_SCALE / total);
        if (!t->freq[s]) t->freq[s] = 1;
        sum += t->freq[s];
        if (count[s] > count[best]) best = s;
        t->nsym = s + 1;
    }
    if (sum < FXS_PT_PROB_SCALE) t->freq[best] += FXS_PT_PROB_SCALE - sum;
    while (sum > FXS_PT_PROB_SCALE) { /* take from the largest until it fits */
        int big = 0;
        for (int s = 1; s < t->nsym; s++)
            if (t->freq[s] > t->freq[big]) big = s;
        t->freq[big]--;
        sum--;
    }
    for (int s = 1; s < FXS_PT_NTOK; s++) t->start[s] = t->start[s - 1] + t->freq[s - 1];
}

/* Table bytes: nsym, then nsym frequencies as LEB128 (1 or 2 bytes each). */
static size_t fxs_pt_table_write(const struct fxs_pt_table *t, uint8_t *out)
{
    size_t o = 0;
    out[o++] = (uint8_t)t->nsym;
    for (int s = 0; s < t->nsym; s++) {
        uint32_t f = t->freq[s];
        if (f >= 128) {
            out[o++] = (uint8_t)(0x80u | (f & 0x7fu));
            out[o++] = (uint8_t)(f >> 7);
        } else {
            out[o++] = (uint8_t)f;
        }
    }
    return o;
}

static int fxs_pt_table_read(const uint8_t *p, size_t len, size_t *pos, struct fxs_pt_table *t)
{
    uint32_t sum = 0;
    memset(t, 0, sizeof *t);
    if (*pos >= len) return -1;
    t->nsym = p[(*pos)++];
    if (t->nsym > FXS_PT_NTOK) return -1;
    for (int s = 0; s < t->nsym; s++) {
        uint32_t f;
        if (*pos >= len) return -1;
        f = p[(*pos)++];
        if (f & 0x80u) {
            if (*pos >= len || p[*pos] & 0x80u) return -1;
            f = (f & 0x7fu) | (uint32_t)p[(*pos)++] << 7;
        }
        if (f > FXS_PT_PROB_SCALE) return -1;
        t->freq[s] = f;
        sum += f;
    }
    if (sum != FXS_PT_PROB_SCALE && sum != 0) return -1;
    for (int s = 1; s < FXS_PT_NTOK; s++) t->start[s] = t->start[s - 1] + t->freq[s - 1];
    return 0;
}

/* ---- quantisation ---------------------------------------------------------------------------- */

struct fxs_pt_frame {
    uint32_t n;
    int pos_bits, temp_bits, fuel_bits, cell_bits;
    float lo[5], hi[5]; /* x, y, z, T, F */
};

static inline uint32_t fxs_pt_quant(float v, float lo, double scale, uint32_t qmax)
{
    double q = ((double)v - (double)lo) * scale + 0.5;
    uint32_t u = q <= 0 ? 0u : (uint32_t)q;
    return u > qmax ? qmax : u;
}

/* Reconstruction shared with the JavaScript decoder: float32(lo + q * step) in double. */
static inline double fxs_pt_step(float lo, float hi, int bits)
{
    return ((double)hi - (double)lo) / (double)((1u << bits) - 1u);
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
    return 0;
}

/* Cells per axis 2^k: about one cell per particle over the box. */
static int fxs_pt_cell_bits(uint32_t n, int pos_bits)
{
    int k = 0;
    while (k < FXS_PT_MAX_CELL_BITS && k < pos_bits && (1ull << (3 * (k + 1))) <= (uint64_t)n) k++;
    return k;
}

/* ---- sorting --------------------------------------------------------------------------------- */

/* LSD radix sort of idx by key (11-bit digits, constant digits skipped). */
static int fxs_pt_radix(uint64_t *key, uint32_t *idx, uint64_t *key2, uint32_t *idx2, uint32_t n, int keybits)
{
    static const int D = 11;
    uint32_t *count;
    if (n < 2) return 0;
    if (!(count = malloc(sizeof(uint32_t) << D))) return -1;
    for (int shift = 0; shift < keybits; shift += D) {
        uint32_t sum = 0, mask = (1u << D) - 1u;
        memset(count, 0, sizeof(uint32_t) << D);
        for (uint32_t i = 0; i < n; i++) count[(key[i] >> shift) & mask]++;
        if (count[(key[0] >> shift) & mask] == n) continue;
        for (uint32_t d = 0; d <= mask; d++) {
            uint32_t c = count[d];
            count[d] = sum;
            sum += c;
        }
        for (uint32_t i = 0; i < n; i++) {
            uint32_t d = (uint32_t)(key[i] >> shift) & mask, o = count[d]++;
            key2[o] = key[i];
            idx2[o] = idx[i];
        }
        memcpy(key, key2, n * sizeof *key);
        memcpy(idx, idx2, n * sizeof *idx);
    }
    free(count);
    return 0;
}

/* Division-free encoder symbol (ryg_rans): x / freq as a multiply and shift, bit-exact. */
struct fxs_pt_esym {
    uint32_t xmax, rcp, bias;
    uint16_t cmpl;
    uint16_t shift;
};

/* ---- encoder --------------------------------------------------------------------------------- */

struct fxs_pt_enc {
    struct fxs_pt_frame f;
    uint64_t *key;
    uint32_t *idx;
    uint8_t *tok;   /* 7 per particle */
    uint32_t count[FXS_PT_NSTREAMS][FXS_PT_NTOK];
    struct fxs_pt_table tab[FXS_PT_NSTREAMS];
    struct fxs_pt_esym sym[FXS_PT_NSTREAMS][FXS_PT_NTOK];
    struct fxs_pt_bitw bits;
    uint8_t *rans;  /* written backwards from rans + rans_cap */
    size_t rans_cap, rans_len;
};

static int fxs_pt_opts(const struct fxs_particles_opts *o, struct fxs_pt_frame *f)
{
    f->pos_bits = o && o->pos_bits ? o->pos_bits : FXS_PARTICLES_DEFAULT_POS_BITS;
    f->temp_bits = o && o->temp_bits ? o->temp_bits : FXS_PARTICLES_DEFAULT_TEMP_BITS;
    f->fuel_bits = o && o->fuel_bits ? o->fuel_bits : FXS_PARTICLES_DEFAULT_FUEL_BITS;
    if (f->pos_bits < 8 || f->pos_bits > 24) return -1;
    if (f->temp_bits < 2 || f->temp_bits > 16 || f->fuel_bits < 2 || f->fuel_bits > 16) return -1;
    return 0;
}

/* Sort keys: (cell id << m) | x offset, m = pos_bits - k. */
static void fxs_pt_keys(const struct fxs_particles *p, struct fxs_pt_enc *e, uint32_t *q)
{
    const struct fxs_pt_frame *f = &e->f;
    int m = f->pos_bits - f->cell_bits, k = f->cell_bits;
    uint32_t qmax = (1u << f->pos_bits) - 1u;
    double scale[3];
    for (int c = 0; c < 3; c++) scale[c] = f->hi[c] > f->lo[c] ? (double)qmax / ((double)f->hi[c] - (double)f->lo[c]) : 0;
    for (uint32_t i = 0; i < p->n; i++) {
        uint32_t qx = fxs_pt_quant(p->xyz[3 * i], f->lo[0], scale[0], qmax);
        uint32_t qy = fxs_pt_quant(p->xyz[3 * i + 1], f->lo[1], scale[1], qmax);
        uint32_t qz = fxs_pt_quant(p->xyz[3 * i + 2], f->lo[2], scale[2], qmax);
        uint64_t cell = (uint64_t)(qz >> m) << (2 * k) | (uint64_t)(qy >> m) << k | (qx >> m);
        e->key[i] = cell << m | (qx & ((1u << m) - 1u));
        e->idx[i] = i;
        q[3 * i] = qx;
        q[3 * i + 1] = qy;
        q[3 * i + 2] = qz;
    }
}

static inline void fxs_pt_emit(struct fxs_pt_enc *e, uint8_t *slot, int stream, uint32_t v)
{
    uint32_t extra;
    int nb;
    unsigned t = fxs_pt_token(v, &extra, &nb);
    *slot = (uint8_t)t;
    e->count[stream][t]++;
    if (nb) fxs_pt_bits_put(&e->bits, extra, nb);
}

/* Forward pass in sorted order: tokens, counts and raw bits. */
static void fxs_pt_tokens(const struct fxs_particles *p, struct fxs_pt_enc *e, const uint32_t *q)
{
    const struct fxs_pt_frame *f = &e->f;
    int m = f->pos_bits - f->cell_bits;
    uint32_t omask = (1u << m) - 1u, tmax = (1u << f->temp_bits) - 1u, fmax = (1u << f->fuel_bits) - 1u;
    double ts = f->hi[3] > f->lo[3] ? (double)tmax / ((double)f->hi[3] - (double)f->lo[3]) : 0;
    double fs = f->hi[4] > f->lo[4] ? (double)fmax / ((double)f->hi[4] - (double)f->lo[4]) : 0;
    uint64_t prev_cell = 0;
    uint32_t prev_x = 0, prev_t = 0, prev_f = 0;
    for (uint32_t j = 0; j < p->n; j++) {
        uint32_t i = e->idx[j];
        uint8_t *s = e->tok + (size_t)FXS_PT_SLOTS * j;
        uint64_t cell = e->key[j] >> m;
        uint32_t ox = q[3 * i] & omask;
        uint32_t qt = fxs_pt_quant(p->temp[i], f->lo[3], ts, tmax), qf = fxs_pt_quant(p->fuel[i], f->lo[4], fs, fmax);
        fxs_pt_emit(e, s, FXS_PT_CELL, (uint32_t)(cell - prev_cell));
        if (cell == prev_cell && j) fxs_pt_emit(e, s + 1, FXS_PT_XSAME, ox - prev_x);
        else fxs_pt_emit(e, s + 1, FXS_PT_XNEW, ox);
        fxs_pt_emit(e, s + 2, FXS_PT_Y, q[3 * i + 1] & omask);
        fxs_pt_emit(e, s + 3, FXS_PT_Z, q[3 * i + 2] & omask);
        fxs_pt_emit(e, s + 4, FXS_PT_T, fxs_pt_zigzag((int32_t)qt - (int32_t)prev_t));
        fxs_pt_emit(e, s + 5, FXS_PT_F, fxs_pt_zigzag((int32_t)qf - (int32_t)prev_f));
        fxs_pt_emit(e, s + 6, FXS_PT_FLAGS, p->flags[i]);
        prev_cell = cell;
        prev_x = ox;
        prev_t = qt;
        prev_f = qf;
    }
    fxs_pt_bits_flush(&e->bits);
}

static void fxs_pt_esym_init(struct fxs_pt_esym *e, uint32_t start, uint32_t freq)
{
    e->xmax = ((FXS_PT_RANS_L >> FXS_PT_PROB_BITS) << 8) * freq;
    e->cmpl = (uint16_t)(FXS_PT_PROB_SCALE - freq);
    if (freq < 2) {
        e->rcp = ~0u;
        e->shift = 0;
        e->bias = start + FXS_PT_PROB_SCALE - 1u;
    } else {
        uint32_t shift = 0;
        while (freq > (1u << shift)) shift++;
        e->rcp = (uint32_t)(((1ull << (shift + 31)) + freq - 1) / freq);
        e->shift = (uint16_t)(shift - 1);
        e->bias = start;
    }
}

static inline void fxs_pt_rans_put(struct fxs_pt_enc *e, uint32_t *x, const struct fxs_pt_esym *sym)
{
    uint32_t q;
    while (*x >= sym->xmax) {
        e->rans[e->rans_cap - ++e->rans_len] = (uint8_t)*x;
        *x >>= 8;
    }
    q = (uint32_t)(((uint64_t)*x * sym->rcp) >> 32) >> sym->shift;
    *x += sym->bias + q * sym->cmpl;
}

/* Backward rANS pass; the decoder reads the bytes forward. */
static void fxs_pt_rans(struct fxs_pt_enc *e)
{
    static const int slot_stream[FXS_PT_SLOTS] = { FXS_PT_CELL, -1, FXS_PT_Y, FXS_PT_Z, FXS_PT_T, FXS_PT_F, FXS_PT_FLAGS };
    struct fxs_pt_esym (*sym)[FXS_PT_NTOK] = e->sym;
    uint32_t x = FXS_PT_RANS_L;
    if (!e->f.n) return;
    for (int st = 0; st < FXS_PT_NSTREAMS; st++)
        for (int t = 0; t < e->tab[st].nsym; t++) fxs_pt_esym_init(&sym[st][t], e->tab[st].start[t], e->tab[st].freq[t]);
    for (uint32_t j = e->f.n; j-- > 0;) {
        const uint8_t *s = e->tok + (size_t)FXS_PT_SLOTS * j;
        for (int k = FXS_PT_SLOTS - 1; k >= 0; k--) {
            int st = k == 1 ? (s[0] == 0 && j ? FXS_PT_XSAME : FXS_PT_XNEW) : slot_stream[k];
            fxs_pt_rans_put(e, &x, &sym[st][s[k]]);
        }
    }
    for (int i = 0; i < 4; i++) e->rans[e->rans_cap - ++e->rans_len] = (uint8_t)(x >> (8 * (3 - i)));
}

static void fxs_pt_header(const struct fxs_pt_frame *f, uint8_t *out, uint32_t rans_len, uint32_t bits_len)
{
    memset(out, 0, FXS_PARTICLES_HEADER_BYTES);
    memcpy(out, FXS_PT_MAGIC, 4);
    out[4] = FXS_PT_VERSION;
    out[5] = (uint8_t)f->pos_bits;
    out[6] = (uint8_t)f->temp_bits;
    out[7] = (uint8_t)f->fuel_bits;
    out[8] = (uint8_t)f->cell_bits;
    fxs_pt_put32(out + 12, f->n);
    for (int c = 0; c < 3; c++) {
        fxs_pt_putf(out + 16 + 4 * c, f->lo[c]);
        fxs_pt_putf(out + 28 + 4 * c, f->hi[c]);
    }
    fxs_pt_putf(out + 40, f->lo[3]);
    fxs_pt_putf(out + 44, f->hi[3]);
    fxs_pt_putf(out + 48, f->lo[4]);
    fxs_pt_putf(out + 52, f->hi[4]);
    fxs_pt_put32(out + 56, rans_len);
    fxs_pt_put32(out + 60, bits_len);
}

static int fxs_pt_assemble(struct fxs_pt_enc *e, uint8_t **out, size_t *out_len)
{
    uint8_t tables[FXS_PT_NSTREAMS * (1 + 2 * FXS_PT_NTOK)];
    size_t tl = 0, total;
    uint8_t *buf;
    if (e->f.n)
        for (int s = 0; s < FXS_PT_NSTREAMS; s++) tl += fxs_pt_table_write(&e->tab[s], tables + tl);
    total = FXS_PARTICLES_HEADER_BYTES + tl + e->rans_len + e->bits.len;
    if (!(buf = malloc(total ? total : 1))) return -1;
    fxs_pt_header(&e->f, buf, (uint32_t)e->rans_len, (uint32_t)e->bits.len);
    memcpy(buf + FXS_PARTICLES_HEADER_BYTES, tables, tl);
    if (e->rans_len) memcpy(buf + FXS_PARTICLES_HEADER_BYTES + tl, e->rans + e->rans_cap - e->rans_len, e->rans_len);
    if (e->bits.len) memcpy(buf + FXS_PARTICLES_HEADER_BYTES + tl + e->rans_len, e->bits.buf, e->bits.len);
    *out = buf;
    *out_len = total;
    return 0;
}

static void fxs_pt_enc_free(struct fxs_pt_enc *e)
{
    free(e->key);
    free(e->idx);
    free(e->tok);
    free(e->bits.buf);
    free(e->rans);
}

/* Allocates the work arrays; the sort scratch (key2, idx2) reuses q's neighbours. */
static int fxs_pt_enc_alloc(struct fxs_pt_enc *e, uint32_t n)
{
    size_t m = n ? n : 1;
    e->key = malloc(2 * m * sizeof *e->key);
    e->idx = malloc(2 * m * sizeof *e->idx);
    e->tok = malloc(m * FXS_PT_SLOTS);
    e->bits.buf = malloc(m * FXS_PT_SLOTS * 4 + 8);
    e->rans_cap = m * FXS_PT_SLOTS * 2 + 16;
    e->rans = malloc(e->rans_cap);
    return e->key && e->idx && e->tok && e->bits.buf && e->rans ? 0 : -1;
}

static int fxs_pt_check_input(const struct fxs_particles *p, char *err, size_t errlen)
{
    if (!p) return fxs_pt_fail(err, errlen, "no particles given");
    if (p->n > FXS_PARTICLES_MAX_N) return fxs_pt_fail(err, errlen, "too many particles");
    if (p->n && (!p->xyz || !p->temp || !p->fuel || !p->flags))
        return fxs_pt_fail(err, errlen, "missing particle array");
    return 0;
}

int fxs_particles_encode(const struct fxs_particles *p, const struct fxs_particles_opts *opts, uint8_t **out,
                         size_t *out_len, char *err, size_t errlen)
{
    struct fxs_pt_enc *e;
    uint32_t *q;
    int r = -1;
    if (fxs_pt_check_input(p, err, errlen)) return -1;
    if (!(e = calloc(1, sizeof *e))) return fxs_pt_fail(err, errlen, "out of memory");
    if (fxs_pt_opts(opts, &e->f)) {
        free(e);
        return fxs_pt_fail(err, errlen, "pos_bits must be 8..24, temp_bits and fuel_bits 2..16");
    }
    e->f.n = p->n;
    e->f.cell_bits = fxs_pt_cell_bits(p->n, e->f.pos_bits);
    q = malloc(3 * (size_t)(p->n ? p->n : 1) * sizeof *q);
    if (fxs_pt_bounds(p, &e->f)) {
        fxs_pt_fail(err, errlen, "non-finite position, temperature or fuel");
    } else if (!q || fxs_pt_enc_alloc(e, p->n) || (fxs_pt_keys(p, e, q), 0) ||
               fxs_pt_radix(e->key, e->idx, e->key + p->n, e->idx + p->n, p->n,
                            2 * e->f.cell_bits + e->f.pos_bits)) {
        fxs_pt_fail(err, errlen, "out of memory");
    } else {
        fxs_pt_tokens(p, e, q);
        for (int s = 0; s < FXS_PT_NSTREAMS; s++) fxs_pt_normalize(e->count[s], &e->tab[s]);
        fxs_pt_rans(e);
        r = fxs_pt_assemble(e, out, out_len);
        if (r) fxs_pt_fail(err, errlen, "out of memory");
    }
    free(q);
    fxs_pt_enc_free(e);
    free(e);
    return r;
}

/* ---- decoder --------------------------------------------------------------------------------- */

struct fxs_pt_dec {
    struct fxs_pt_frame f;
    struct fxs_pt_table tab[FXS_PT_NSTREAMS];
    uint8_t lookup[FXS_PT_NSTREAMS][FXS_PT_PROB_SCALE];
    const uint8_t *rp, *rend;
    uint32_t x;
    struct fxs_pt_bitr bits;
};

static void fxs_pt_lookup(const struct fxs_pt_table *t, uint8_t *lookup)
{
    for (int s = 0; s < t->nsym; s++) memset(lookup + t->start[s], s, t->freq[s]);
}

/* Decodes one value of a stream: token by rANS, then its raw bits. */
static inline int fxs_pt_get(struct fxs_pt_dec *d, int stream, uint32_t *v)
{
    const struct fxs_pt_table *t = &d->tab[stream];
    uint32_t extra = 0, slot = d->x & (FXS_PT_PROB_SCALE - 1u);
    unsigned s;
    if (!t->nsym) return -1;
    s = d->lookup[stream][slot];
    d->x = t->freq[s] * (d->x >> FXS_PT_PROB_BITS) + slot - t->start[s];
    while (d->x < FXS_PT_RANS_L) {
        if (d->rp >= d->rend) return -1;
        d->x = d->x << 8 | *d->rp++;
    }
    if (s >= 16 && fxs_pt_bits_get(&d->bits, fxs_pt_token_bits(s), &extra)) return -1;
    *v = fxs_pt_untoken(s, extra);
    return 0;
}

static int fxs_pt_parse_header(const uint8_t *buf, size_t len, struct fxs_pt_frame *f, uint32_t *rl, uint32_t *bl)
{
    if (len < FXS_PARTICLES_HEADER_BYTES || memcmp(buf, FXS_PT_MAGIC, 4)) return -1;
    if (buf[4] != FXS_PT_VERSION) return -2;
    f->pos_bits = buf[5];
    f->temp_bits = buf[6];
    f->fuel_bits = buf[7];
    f->cell_bits = buf[8];
    f->n = fxs_pt_get32(buf + 12);
    for (int c = 0; c < 3; c++) {
        f->lo[c] = fxs_pt_getf(buf + 16 + 4 * c);
        f->hi[c] = fxs_pt_getf(buf + 28 + 4 * c);
    }
    f->lo[3] = fxs_pt_getf(buf + 40);
    f->hi[3] = fxs_pt_getf(buf + 44);
    f->lo[4] = fxs_pt_getf(buf + 48);
    f->hi[4] = fxs_pt_getf(buf + 52);
    *rl = fxs_pt_get32(buf + 56);
    *bl = fxs_pt_get32(buf + 60);
    return 0;
}

static const char *fxs_pt_check_frame(const struct fxs_pt_frame *f)
{
    if (f->pos_bits < 8 || f->pos_bits > 24 || f->temp_bits < 2 || f->temp_bits > 16 || f->fuel_bits < 2 ||
        f->fuel_bits > 16)
        return "bad bit widths";
    if (f->cell_bits > FXS_PT_MAX_CELL_BITS || f->cell_bits > f->pos_bits) return "bad cell_bits";
    if (f->n > FXS_PARTICLES_MAX_N) return "particle count over the limit";
    for (int c = 0; c < 5; c++)
        if (!isfinite(f->lo[c]) || !isfinite(f->hi[c]) || f->lo[c] > f->hi[c]) return "bad bounds";
    return NULL;
}

struct fxs_pt_state {
    uint64_t cell;
    uint32_t x, t, f;
};

/* Decodes particle j into p. Returns 0 or -1 (corrupt). */
static int fxs_pt_decode_one(struct fxs_pt_dec *d, struct fxs_pt_state *st, uint32_t j, struct fxs_particles *p,
                             const double *step)
{
    const struct fxs_pt_frame *f = &d->f;
    int m = f->pos_bits - f->cell_bits, k = f->cell_bits;
    uint32_t v[FXS_PT_SLOTS], omask = (1u << m) - 1u;
    if (fxs_pt_get(d, FXS_PT_CELL, &v[0])) return -1;
    if (fxs_pt_get(d, v[0] == 0 && j ? FXS_PT_XSAME : FXS_PT_XNEW, &v[1]) || v[1] > omask) return -1;
    for (int s = 2; s < FXS_PT_SLOTS; s++)
        if (fxs_pt_get(d, FXS_PT_Y + s - 2, &v[s])) return -1;
    st->cell += v[0];
    st->x = v[0] == 0 && j ? st->x + v[1] : v[1];
    st->t = (uint32_t)((int32_t)st->t + fxs_pt_unzigzag(v[4]));
    st->f = (uint32_t)((int32_t)st->f + fxs_pt_unzigzag(v[5]));
    if (st->cell >> (3 * k) || st->x > omask || v[2] > omask || v[3] > omask) return -1;
    if (st->t >> f->temp_bits || st->f >> f->fuel_bits || v[6] > 255) return -1;
    {
        uint32_t cm = (1u << k) - 1u, c = (uint32_t)st->cell;
        uint32_t q[3] = { (c & cm) << m | st->x, ((c >> k) & cm) << m | v[2], (c >> (2 * k)) << m | v[3] };
        for (int a = 0; a < 3; a++) p->xyz[3 * j + a] = (float)(f->lo[a] + q[a] * step[a]);
    }
    p->temp[j] = (float)(f->lo[3] + st->t * step[3]);
    p->fuel[j] = (float)(f->lo[4] + st->f * step[4]);
    p->flags[j] = (uint8_t)v[6];
    return 0;
}

static int fxs_pt_decode_all(struct fxs_pt_dec *d, struct fxs_particles *p)
{
    const struct fxs_pt_frame *f = &d->f;
    struct fxs_pt_state st = { 0, 0, 0, 0 };
    double step[5];
    for (int c = 0; c < 5; c++) step[c] = fxs_pt_step(f->lo[c], f->hi[c], c < 3 ? f->pos_bits : c == 3 ? f->temp_bits : f->fuel_bits);
    if (d->rend - d->rp < 4) return -1;
    d->x = fxs_pt_get32(d->rp);
    d->rp += 4;
    for (uint32_t j = 0; j < f->n; j++)
        if (fxs_pt_decode_one(d, &st, j, p, step)) return -1;
    if (d->rp != d->rend || d->x != FXS_PT_RANS_L) return -1;
    if (d->bits.p != d->bits.end || d->bits.acc) return -1;
    return 0;
}

static int fxs_pt_alloc_out(struct fxs_particles *p, uint32_t n)
{
    size_t m = n ? n : 1;
    p->n = n;
    p->xyz = malloc(3 * m * sizeof *p->xyz);
    p->temp = malloc(m * sizeof *p->temp);
    p->fuel = malloc(m * sizeof *p->fuel);
    p->flags = malloc(m);
    if (p->xyz && p->temp && p->fuel && p->flags) return 0;
    fxs_particles_free(p);
    return -1;
}

/* Reads the tables and sets up both streams; checks the sizes add up to len. */
static const char *fxs_pt_setup(struct fxs_pt_dec *d, const uint8_t *buf, size_t len, uint32_t rl, uint32_t bl)
{
    size_t pos = FXS_PARTICLES_HEADER_BYTES;
    if (!d->f.n) return rl || bl || len != FXS_PARTICLES_HEADER_BYTES ? "bad sizes" : NULL;
    for (int s = 0; s < FXS_PT_NSTREAMS; s++) {
        if (fxs_pt_table_read(buf, len, &pos, &d->tab[s])) return "corrupt frequency table";
        fxs_pt_lookup(&d->tab[s], d->lookup[s]);
    }
    if ((uint64_t)pos + rl + bl != len) return "section sizes do not match the payload length";
    d->rp = buf + pos;
    d->rend = d->rp + rl;
    d->bits.p = d->rend;
    d->bits.end = d->rend + bl;
    return NULL;
}

int fxs_particles_decode(const uint8_t *buf, size_t len, struct fxs_particles *p, char *err, size_t errlen)
{
    struct fxs_pt_dec *d;
    uint32_t rl, bl;
    const char *why;
    int r;
    if (!p) return fxs_pt_fail(err, errlen, "no output given");
    memset(p, 0, sizeof *p);
    if (!buf) return fxs_pt_fail(err, errlen, "no input");
    if (!(d = calloc(1, sizeof *d))) return fxs_pt_fail(err, errlen, "out of memory");
    r = fxs_pt_parse_header(buf, len, &d->f, &rl, &bl);
    why = r == -1 ? "not a codec 1 payload (short or bad magic)" : r == -2 ? "unsupported version" : NULL;
    if (!why) why = fxs_pt_check_frame(&d->f);
    if (!why) why = fxs_pt_setup(d, buf, len, rl, bl);
    if (!why && fxs_pt_alloc_out(p, d->f.n)) why = "out of memory";
    if (!why && d->f.n && fxs_pt_decode_all(d, p)) {
        fxs_particles_free(p);
        why = "corrupt particle data";
    }
    free(d);
    return why ? fxs_pt_fail(err, errlen, why) : 0;
}

void fxs_particles_free(struct fxs_particles *p)
{
    if (!p) return;
    free(p->xyz);
    free(p->temp);
    free(p->fuel);
    free(p->flags);
    memset(p, 0, sizeof *p);
}
