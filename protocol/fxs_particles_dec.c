/* fxs_particles_dec.c — the particle codec's decoder: fxs_particles_decode, _decode_into,
 * _info, _codec and _free (fxs_particles.h), run by libfxclient (fxctl, fxload, a game's
 * plugin) on every particle frame, and by the tests.
 *
 * Reads a payload of one or more blocks (PROTOCOL.md §7.5, §7.5.8): every header is checked
 * before anything is decoded, each block then decodes into its slice of the output, in the
 * encoder's order: the kd-tree's positions, the attributes, the velocities. Every length
 * and value is validated and both sections must be consumed exactly, so truncated,
 * corrupt or oversized input is rejected without reading out of bounds. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fxs_particles.h"
#include "fxs_particles_format.h"
#include "fxs_rangecoder.h"

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

struct fxs_pt_dec {
    struct fxs_pt_frame f;
    struct fxs_rc_io io;
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
        if (fxs_rc_get_int(&d->io, d->m.cnt[fxs_pt_cclass(c) * 3 + a], FXS_PT_CNT_U, &z)) return -1;
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
            if (fxs_rc_bits_get(&d->io.bits, f->left[depth][a], &v)) return -1;
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
        if (fxs_rc_get(&d->io.rc, &d->m.same[(nfl & 7u) * 2 + (unsigned)f0])) {
            unsigned m = 1;
            while (m < 256) m = 2 * m + (unsigned)fxs_rc_get(&d->io.rc, &d->m.tree[m]);
            v = m - 256;
            if (v == nfl) return -1;
        }
        fxs_rc_prob *pt = d->m.t[(fxs_pt_rclass(zt) * 8 + (int)(v & 7u)) * 2 + f0];
        fxs_rc_prob *pf = d->m.f[(fxs_pt_rclass(zf) * 2 + f0) * 2 + (int)(v >> 2 & 1u)];
        if (fxs_rc_get_int(&d->io, pt, FXS_PT_T_U, &zt) || fxs_rc_get_int(&d->io, pf, FXS_PT_F_U, &zf)) return -1;
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
        if (fxs_rc_get(&d->io.rc, &d->m.vsame[nc * 2 + (unsigned)nf0])) {
            if (fxs_rc_get_tree(&d->io, d->m.vfl[nc], 8, &v)) return -1;
            if (v == nfl) return -1;
        }
        c = v & 7u;
        fl[j] = (uint8_t)v;
        sb = fxs_pt_same(fl, j, dist, v, last);
        tb = sb < 0 ? 8 : fxs_pt_top(qt[sb], f->temp_bits, 3);
        if (fxs_rc_get_tree(&d->io, d->m.vt[c * 9 + (unsigned)tb], f->temp_bits, &t)) return -1;
        if (fxs_rc_get(&d->io.rc, &d->m.vf0[(c * 16 + (unsigned)fxs_pt_top(t, f->temp_bits, 4)) * 2 + (unsigned)nf0])) {
            if (fxs_rc_get_tree(&d->io, d->m.vf[c * 8 + (unsigned)fxs_pt_top(t, f->temp_bits, 3)], f->fuel_bits, &fu))
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
            if (fxs_rc_get_int(&d->io, d->m.v[fxs_pt_vctx(a, zb, p->flags[j])], FXS_PT_V_U, &z)) return -1;
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
    if (fxs_rc_dec_init(&d->io.rc, body, rl)) return "corrupt particle data";
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
    int r = fxs_pt_header_get(buf, len, f, rl, bl);
    const char *why = r == -1   ? "not a codec 2 payload (short or bad magic)"
                      : r == -2 ? "unsupported version"
                      : r == -3 ? "unknown attribute mode"
                      : r == -4 ? "non-zero reserved bytes in the velocity block"
                                : fxs_pt_header_check(f);
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
