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
#include "fxs_particles_near.h"
#include "fxs_rangecoder.h"

/* One block being decoded. */
struct fxs_pt_dec {
    struct fxs_pt_frame f;
    struct fxs_rc_dec rc;
    const uint8_t *rc_end, *bits_end; /* ends of the two sections in the padded copy */
    struct fxs_pt_models m;
    /* scratch, one allocation: the sections' padded copy; x, y, z (quantised coordinates
     * in tree order, as doubles for the neighbour search); quantised T and F; each
     * particle's nearest recent neighbour (-1: none) and, in mode 1, the k of its 4 nearest
     * of the 16 before (fxs_pt_near4); the quantised velocities; the tree's two level
     * lists and its leaves */
    void *scratch;
    double *x, *y, *z;
    uint32_t *qt, *qf, *near4;
    int32_t *nbs, *qv;
    struct fxs_pt_dnode *lists, *leaves;
};

/* A node of the tree being decoded: its count (a leaf: its depth), its first particle, and
 * its coordinates' bits above its depth. */
struct fxs_pt_dnode {
    uint32_t c, at, b[3];
};

/* Node nd with the count models cnt of its split's axis: its children, the upper one's
 * base with the split's bit (ux, uy, uz: the bit on its axis, 0 on the others), go to the
 * next level's list (nxt, nn) or to the leaves (lf, nl, with their depth d), or nowhere when
 * empty, without a branch: each is written to both and kept where its count says. -1 for a
 * count outside 0 ... c. */
static inline __attribute__((always_inline)) int fxs_pt_dec_node(struct fxs_rc_dec *rc, fxs_rc_prob (*cnt)[FXS_RC_SPROBS],
                                                                 const struct fxs_pt_dnode *nd, uint32_t ux, uint32_t uy,
                                                                 uint32_t uz, uint32_t d, struct fxs_pt_dnode *nxt,
                                                                 uint32_t *nn, struct fxs_pt_dnode *lf, uint32_t *nl)
{
    uint32_t c = nd->c, at = nd->at, bx = nd->b[0], by = nd->b[1], bz = nd->b[2], z;
    if (fxs_rc_get_small(rc, cnt[fxs_pt_cclass(c) * 3], &z)) return -1;
    uint32_t lo = (c >> 1) + (uint32_t)fxs_pt_unzigzag(z), hi = c - lo;
    if (lo > c) return -1; /* negative or over c */
    nxt[*nn] = (struct fxs_pt_dnode){ lo, at, { bx, by, bz } };
    lf[*nl] = (struct fxs_pt_dnode){ d, at, { bx, by, bz } };
    *nn += lo >= 2;
    *nl += lo == 1;
    nxt[*nn] = (struct fxs_pt_dnode){ hi, at + lo, { bx | ux, by | uy, bz | uz } };
    lf[*nl] = (struct fxs_pt_dnode){ d, at + lo, { bx | ux, by | uy, bz | uz } };
    *nn += hi >= 2;
    *nl += hi == 1;
    return 0;
}

/* The kd-tree (§7.5.3) level by level, each level a flat loop over its nodes; the leaves
 * are listed with their depth, and their remaining bits read after the whole tree (x, then
 * y and z together); each point's coordinates go to x, y, z in tree order. 0, or -1 for a
 * corrupt tree. */
static int fxs_pt_dec_tree(struct fxs_pt_dec *d)
{
    const struct fxs_pt_frame *f = &d->f;
    struct fxs_rc_dec rc = d->rc;
    const uint8_t *rc_end = d->rc_end, *bits_end = d->bits_end;
    uint32_t n = f->n, ncur = 0, nl = 0;
    struct fxs_pt_dnode *cur = d->lists, *nxt = cur + n / 2 + 2, *lf = d->leaves;
    double *x = d->x, *y = d->y, *z = d->z;
    if (n == 1) lf[nl++] = (struct fxs_pt_dnode){ 0, 0, { 0, 0, 0 } };
    else cur[ncur++] = (struct fxs_pt_dnode){ n, 0, { 0, 0, 0 } };
    for (int depth = 0; depth < f->depth && ncur; depth++) {
        int a = f->axis[depth];
        uint32_t bit = 1u << (f->left[depth][a] - 1), ux = a == 0 ? bit : 0, uy = a == 1 ? bit : 0, uz = a == 2 ? bit : 0;
        uint32_t nn = 0;
        fxs_rc_prob (*cnt)[FXS_RC_SPROBS] = d->m.cnt + a;
        for (uint32_t i = 0; i < ncur; i++)
            if (fxs_pt_dec_node(&rc, cnt, cur + i, ux, uy, uz, (uint32_t)depth + 1, nxt, &nn, lf, &nl) ||
                fxs_rc_past(&rc, rc_end, bits_end))
                return -1;
        struct fxs_pt_dnode *t = cur;
        cur = nxt, nxt = t, ncur = nn;
    }
    for (uint32_t i = 0; i < ncur; i++) /* identical points at full depth */
        for (uint32_t j = cur[i].at; j < cur[i].at + cur[i].c; j++) x[j] = cur[i].b[0], y[j] = cur[i].b[1], z[j] = cur[i].b[2];
    for (uint32_t k = 0; k < nl; k++) {
        const struct fxs_pt_dnode *e = lf + k;
        const uint8_t *l = f->left[e->c];
        x[e->at] = e->b[0] | (uint32_t)fxs_rc_raw(&rc, l[0]);
        uint64_t yz = fxs_rc_raw(&rc, l[1] + l[2]);
        y[e->at] = e->b[1] | ((uint32_t)yz & ((1u << l[1]) - 1u));
        z[e->at] = e->b[2] | (uint32_t)(yz >> l[1]);
        if (fxs_rc_past(&rc, rc_end, bits_end)) return -1;
    }
    d->rc = rc;
    return 0;
}

/* Mode 0: flags, T and F predicted from the nearest recent neighbour nbs[j]. The loops
 * keep every pointer in a local: a store through fl (bytes) could otherwise alias d's
 * fields and make the compiler reload them per particle. */
static int fxs_pt_dec_attrs0(struct fxs_pt_dec *d, uint8_t *fl)
{
    const struct fxs_pt_frame *f = &d->f;
    struct fxs_pt_models *m = &d->m;
    struct fxs_rc_dec rc = d->rc;
    const uint8_t *rc_end = d->rc_end, *bits_end = d->bits_end;
    const int32_t *nbs = d->nbs;
    uint32_t *qt = d->qt, *qf = d->qf, zt = 0, zf = 0, n = f->n, tlim = 1u << f->temp_bits, flim = 1u << f->fuel_bits;
    for (uint32_t j = 0; j < n; j++) {
        int32_t nb = nbs[j];
        uint32_t nt = nb < 0 ? 0 : qt[nb], nf = nb < 0 ? 0 : qf[nb];
        unsigned nfl = nb < 0 ? 0 : fl[nb], v = nfl, f0 = nf == 0;
        if (fxs_rc_get(&rc, &m->same[(nfl & 7u) * 2 + f0])) {
            v = fxs_rc_get_tree(&rc, m->tree, 8);
            if (v == nfl) return -1;
        }
        fxs_rc_prob *pt = m->t[(fxs_pt_rclass(zt) * 8 + (int)(v & 7u)) * 2 + (int)f0];
        fxs_rc_prob *pf = m->f[(fxs_pt_rclass(zf) * 2 + (int)f0) * 2 + (int)(v >> 2 & 1u)];
        if (fxs_rc_get_int(&rc, pt, FXS_PT_T_U, &zt) || fxs_rc_get_int(&rc, pf, FXS_PT_F_U, &zf)) return -1;
        uint32_t t = nt + (uint32_t)fxs_pt_unzigzag(zt), fu = nf + (uint32_t)fxs_pt_unzigzag(zf);
        if (t >= tlim || fu >= flim || fxs_rc_past(&rc, rc_end, bits_end)) return -1;
        qt[j] = t;
        qf[j] = fu;
        fl[j] = (uint8_t)v;
    }
    d->rc = rc;
    return 0;
}

/* Mode 1: the nearest of j - 1 ... j - FXS_PT_SAME with flags v (the latest on ties), for
 * when the nearest of them all (near4's first) has other flags: the next of the 4 nearest
 * with v, else the whole search; -1 when none has v. */
static int32_t fxs_pt_dec_same(const struct fxs_pt_dec *d, const uint8_t *fl, uint32_t j, unsigned v, uint32_t near4)
{
    const double *x = d->x, *y = d->y, *z = d->z;
    uint32_t kmax = j < FXS_PT_SAME ? j : FXS_PT_SAME;
    int32_t best = -1;
    double bd = INFINITY;
    for (uint32_t k = near4 >> 8; k & 0xFFu; k >>= 8)
        if (fl[j - (k & 0xFFu)] == v) return (int32_t)(j - (k & 0xFFu));
    for (uint32_t k = 1; k <= kmax; k++) {
        double dx = x[j] - x[j - k], dy = y[j] - y[j - k], dz = z[j] - z[j - k], dd = dx * dx + dy * dy + dz * dz;
        if (fl[j - k] == v && dd < bd) bd = dd, best = (int32_t)(j - k);
    }
    return best;
}

/* Mode 1: flags, T and F as values (bit trees) in contexts of the neighbours' values. */
static int fxs_pt_dec_attrs1(struct fxs_pt_dec *d, uint8_t *fl)
{
    const struct fxs_pt_frame *f = &d->f;
    struct fxs_pt_models *m = &d->m;
    struct fxs_rc_dec rc = d->rc;
    const uint8_t *rc_end = d->rc_end, *bits_end = d->bits_end;
    const int32_t *nbs = d->nbs;
    const uint32_t *near4 = d->near4;
    const int tbits = f->temp_bits, fbits = f->fuel_bits;
    const int t3 = tbits > 3 ? tbits - 3 : 0, t4 = tbits > 4 ? tbits - 4 : 0;
    uint32_t *qt = d->qt, *qf = d->qf, n = f->n, flim = 1u << fbits;
    int32_t last[256];
    for (int i = 0; i < 256; i++) last[i] = -1;
    for (uint32_t j = 0; j < n; j++) {
        int32_t nb = nbs[j], sb;
        unsigned nf0 = nb < 0 || qf[nb] == 0, nfl = nb < 0 ? 0 : fl[nb], nc = nb < 0 ? 8 : nfl & 7u, v = nfl, c;
        uint32_t t, fu = 0, k0 = near4[j] & 0xFFu;
        if (fxs_rc_get(&rc, &m->vsame[nc * 2 + nf0])) {
            v = fxs_rc_get_tree(&rc, m->vfl[nc], 8);
            if (v == nfl) return -1;
        }
        c = v & 7u;
        fl[j] = (uint8_t)v;
        /* the same-flags neighbour: usually the nearest of all 16 */
        sb = k0 && fl[j - k0] == v ? (int32_t)(j - k0) : fxs_pt_dec_same(d, fl, j, v, near4[j]);
        if (sb < 0) sb = last[v];
        t = fxs_rc_get_tree(&rc, m->vt[c * 9 + (sb < 0 ? 8u : qt[sb] >> t3)], tbits);
        if (fxs_rc_get(&rc, &m->vf0[(c * 16 + (t >> t4)) * 2 + nf0])) {
            fu = fxs_rc_get_tree(&rc, m->vf[c * 8 + (t >> t3)], fbits) + 1;
            if (fu >= flim) return -1;
        }
        if (fxs_rc_past(&rc, rc_end, bits_end)) return -1;
        qt[j] = t;
        qf[j] = fu;
        last[v] = (int32_t)j;
    }
    d->rc = rc;
    return 0;
}

/* Velocities (§7.5.7) of every particle in tree order, after the attributes: per axis the
 * residual against the neighbour nbs[j]'s. */
static int fxs_pt_dec_vel(struct fxs_pt_dec *d, const uint8_t *fl)
{
    const struct fxs_pt_frame *f = &d->f;
    struct fxs_rc_dec rc = d->rc;
    const uint8_t *rc_end = d->rc_end, *bits_end = d->bits_end;
    const int32_t *nbs = d->nbs;
    int32_t qmax = fxs_pt_vqmax(f->vel_bits), *qv = d->qv;
    uint32_t zx = 0, n = f->n;
    for (uint32_t j = 0; j < n; j++) {
        int32_t nb = nbs[j];
        uint32_t zb = zx, z;
        for (int a = 0; a < 3; a++) {
            if (fxs_rc_get_int(&rc, d->m.v[fxs_pt_vctx(a, zb, fl[j])], FXS_PT_V_U, &z)) return -1;
            int64_t v = (int64_t)(nb < 0 ? 0 : qv[3 * (size_t)nb + a]) + fxs_pt_unzigzag(z);
            if (v < -qmax || v > qmax) return -1;
            qv[3 * (size_t)j + a] = (int32_t)v;
            zb = z;
            if (!a) zx = z;
        }
        if (fxs_rc_past(&rc, rc_end, bits_end)) return -1;
    }
    d->rc = rc;
    return 0;
}

/* The decoded block's values into p: float32(lo + q * step) computed in double (what the
 * JavaScript decoder computes too), velocities float32(q * step). */
static void fxs_pt_dec_out(const struct fxs_pt_dec *d, struct fxs_particles *p)
{
    const struct fxs_pt_frame *f = &d->f;
    const double lx = f->lo[0], ly = f->lo[1], lz = f->lo[2], sx = f->step[0], sy = f->step[1], sz = f->step[2];
    for (uint32_t j = 0; j < f->n; j++) {
        p->xyz[3 * (size_t)j] = (float)(lx + d->x[j] * sx);
        p->xyz[3 * (size_t)j + 1] = (float)(ly + d->y[j] * sy);
        p->xyz[3 * (size_t)j + 2] = (float)(lz + d->z[j] * sz);
    }
    for (uint32_t j = 0; j < f->n; j++) p->temp[j] = (float)(f->lo[3] + d->qt[j] * f->step[3]);
    if (p->fuel)
        for (uint32_t j = 0; j < f->n; j++) p->fuel[j] = (float)(f->lo[4] + d->qf[j] * f->step[4]);
    if (p->vel && f->vel)
        for (size_t i = 0; i < 3 * (size_t)f->n; i++) p->vel[i] = (float)(d->qv[i] * f->vstep[i % 3]);
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

/* Scratch of a block of nn particles (fxs_pt_dec's layout) and the sections' padded copy;
 * -1 when out of memory. */
static int fxs_pt_dec_scratch(struct fxs_pt_dec *d, const uint8_t *body, uint32_t rl, uint32_t bl)
{
    /* the level lists: at most n / 2 nodes each, + 2 for the branchless writes past the end */
    size_t nn = d->f.n, sections = (size_t)rl + bl + 2 * FXS_RC_PAD, nodes = 2 * (nn / 2 + 2) + nn + 2;
    uint8_t *s = d->scratch = malloc(24 * nn + 16 * nn + (d->f.vel ? 12 * nn : 0) + nodes * sizeof *d->lists + sections);
    if (!s) return -1;
    d->x = (double *)s, d->y = d->x + nn, d->z = d->y + nn;
    d->qt = (uint32_t *)(d->z + nn), d->qf = d->qt + nn, d->near4 = d->qf + nn;
    d->nbs = (int32_t *)(d->near4 + nn);
    d->qv = d->nbs + nn;
    d->lists = (struct fxs_pt_dnode *)(d->qv + (d->f.vel ? 3 * nn : 0));
    d->leaves = d->lists + 2 * (nn / 2 + 2);
    uint8_t *rc = (uint8_t *)(d->leaves + nn + 2), *bits = rc + rl + FXS_RC_PAD;
    memcpy(rc, body, rl);
    memset(rc + rl, 0, FXS_RC_PAD);
    memcpy(bits, body + rl, bl);
    memset(bits + bl, 0, FXS_RC_PAD);
    d->rc_end = rc + rl;
    d->bits_end = bits + bl;
    return fxs_rc_dec_init(&d->rc, rc, rl, bits) ? 1 : 0;
}

/* Decodes both sections after the header: the tree, the neighbours, the attributes, the
 * velocities, then the values. NULL or the reason for rejecting. */
static const char *fxs_pt_dec_body(struct fxs_pt_dec *d, const uint8_t *buf, size_t len, uint32_t rl, uint32_t bl,
                                   struct fxs_particles *p)
{
    const struct fxs_pt_frame *f = &d->f;
    size_t hb = fxs_pt_hdr_bytes(f);
    const char *why = NULL;
    int r;
    if ((uint64_t)hb + rl + bl != len) return "section sizes do not match the payload length";
    if (!f->n) return rl || bl ? "bad sizes" : NULL;
    if ((r = fxs_pt_dec_scratch(d, buf + hb, rl, bl))) return r < 0 ? "out of memory" : "corrupt particle data";
    fxs_pt_steps(&d->f);
    fxs_pt_schedule(&d->f);
    fxs_pt_models_init(&d->m);
    if (fxs_pt_dec_tree(d)) return "corrupt particle data";
    int exact = f->abits[0] <= 23 && f->abits[1] <= 23 && f->abits[2] <= 23;
    if (f->mode) fxs_pt_near4(f->n, exact, d->x, d->y, d->z, d->nbs, d->near4);
    else fxs_pt_near(f->n, exact, d->x, d->y, d->z, d->nbs);
    if ((f->mode ? fxs_pt_dec_attrs1 : fxs_pt_dec_attrs0)(d, p->flags) || (f->vel && fxs_pt_dec_vel(d, p->flags)))
        why = "corrupt particle data";
    else if (!fxs_rc_exact_rc(&d->rc, d->rc_end))
        why = "corrupt particle data (range coder section not consumed exactly)";
    else if (!fxs_rc_exact_bits(&d->rc, d->bits_end))
        why = "corrupt particle data (raw bits not consumed exactly)";
    else
        fxs_pt_dec_out(d, p);
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
                      : r == -2 ? "unsupported version (this decoder reads version 3)"
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
        free(d->scratch);
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
