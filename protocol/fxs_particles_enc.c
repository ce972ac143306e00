/* fxs_particles_enc.c — the particle codec's encoder: fxs_particles_encode (fxs_particles.h),
 * run by the daemon on every flame frame.
 *
 * One block (PROTOCOL.md §7.5) in three passes over the frame:
 *   - positions: quantised on one step for all three axes, sorted into the kd-tree's
 *     depth-first order by Morton key (radix sort), and the tree coded level by level as
 *     each node's count in its lower half (a stable partition instead for axes over 21
 *     bits), then the leaves' remaining bits;
 *   - attributes: flags, T and F in tree order, in the mode a static estimate of both
 *     costs picks per frame (0: residuals against the nearest recent particle; 1: values
 *     in contexts of the neighbours' values), after one neighbour search for both
 *     (fxs_particles_near.c);
 *   - velocities, when the frame has them: per axis a residual against the same neighbour.
 * Both sections are written as they go and assembled behind the header at the end. A frame
 * of many particles may be cut into slabs coded in parallel as blocks on a common grid
 * (codec 3, §7.5.8). */
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "fxs_particles.h"
#include "fxs_particles_format.h"
#include "fxs_particles_near.h"
#include "fxs_rangecoder.h"

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
    struct fxs_rc_enc w;
    struct fxs_rc_buf rb, bb;    /* range-coder and raw-bits sections */
    struct fxs_pt_models m;
};

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

/* A node of the tree being coded: its first point in tree order and its count (a leaf: its
 * depth). */
struct fxs_pt_node {
    uint32_t at, c;
};

/* The count of a node's lower half: the first of its c sorted keys with bit kb set, by a
 * branchless binary search. */
static uint32_t fxs_pt_lower_sorted(const uint64_t *key, uint32_t c, int kb)
{
    const uint64_t *base = key;
    uint32_t len = c;
    while (len > 1) {
        uint32_t half = len >> 1;
        base += half & ((uint32_t)(base[half] >> kb & 1u) - 1u);
        len -= half;
    }
    return (uint32_t)(base - key) + (uint32_t)(~*base >> kb & 1u);
}

/* The count of a node's lower half: its c points stably partitioned by bit sh of axis a
 * (through tmp). */
static uint32_t fxs_pt_lower_part(struct fxs_pt_pt *p, struct fxs_pt_pt *tmp, uint32_t c, int a, int sh)
{
    uint32_t lo = 0, hi = 0;
    for (uint32_t i = 0; i < c; i++)
        if (!((p[i].q[a] >> sh) & 1u)) p[lo++] = p[i];
        else tmp[hi++] = p[i];
    memcpy(p + lo, tmp, hi * sizeof *p);
    return lo;
}

/* The tree level by level (§7.5.3): each node's count in its lower half, the nodes of a
 * level in order; then each leaf's remaining bits (x, then y and z together: <= 48 bits),
 * in the order the leaves appeared. The points are in tree order: key and q sorted (pts
 * NULL), or pts, partitioned here node by node (frames with an axis over 21 bits). -1 when
 * out of memory. */
static int fxs_pt_enc_tree(struct fxs_pt_enc *e, const uint64_t *key, const uint32_t *q, struct fxs_pt_pt *pts,
                           struct fxs_pt_pt *tmp)
{
    const struct fxs_pt_frame *f = &e->f;
    struct fxs_rc_enc w = e->w;
    uint32_t n = f->n, ncur = 0, nl = 0;
    /* two level lists (a level has at most n / 2 nodes), then the leaves (at, depth) */
    struct fxs_pt_node *mem = malloc((2 * (n / 2 + 1) + n) * sizeof *mem), *cur = mem, *nxt = cur + n / 2 + 1;
    struct fxs_pt_node *lf = nxt + n / 2 + 1;
    int r = 0;
    if (!mem) return -1;
    if (n == 1) lf[nl++] = (struct fxs_pt_node){ 0, 0 };
    else cur[ncur++] = (struct fxs_pt_node){ 0, n };
    for (int d = 0; d < f->depth && ncur && !r; d++) {
        int a = f->axis[d], sh = f->left[d][a] - 1;
        uint32_t nn = 0;
        for (uint32_t i = 0; i < ncur; i++) {
            uint32_t at = cur[i].at, c = cur[i].c;
            uint32_t lo = pts ? fxs_pt_lower_part(pts + at, tmp, c, a, sh) : fxs_pt_lower_sorted(key + at, c, 3 * sh + 2 - a);
            if ((r = fxs_rc_room(&e->rb, &e->bb, &w))) break;
            fxs_rc_put_small(&w, e->m.cnt[fxs_pt_cclass(c) * 3 + a], fxs_pt_zigzag((int32_t)lo - (int32_t)(c >> 1)));
            struct fxs_pt_node ch[2] = { { at, lo }, { at + lo, c - lo } };
            for (int k = 0; k < 2; k++)
                if (ch[k].c >= 2) nxt[nn++] = ch[k];
                else if (ch[k].c == 1) lf[nl++] = (struct fxs_pt_node){ ch[k].at, (uint32_t)d + 1 };
        }
        struct fxs_pt_node *t = cur;
        cur = nxt, nxt = t, ncur = nn;
    }
    for (uint32_t k = 0; k < nl && !r; k++) {
        const uint32_t *qa = pts ? pts[lf[k].at].q : q + 3 * (size_t)lf[k].at;
        const uint8_t *l = f->left[lf[k].c];
        if ((r = fxs_rc_room(&e->rb, &e->bb, &w))) break;
        fxs_rc_bits_put64(&w, qa[0], l[0]);
        fxs_rc_bits_put64(&w, (qa[1] & ((1u << l[1]) - 1u)) | (uint64_t)qa[2] << l[1], l[1] + l[2]);
    }
    e->w = w;
    free(mem);
    return r;
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
    /* q into tree order by gathering from a copy (in pd, free until the neighbour search),
     * cheaper than decoding the keys. */
    memcpy(q0, q, 12 * (size_t)n);
    for (uint32_t j = 0; j < n; j++) {
        const uint32_t *qi = q0 + 3 * (size_t)ix[c][j];
        q[3 * (size_t)j] = qi[0], q[3 * (size_t)j + 1] = qi[1], q[3 * (size_t)j + 2] = qi[2];
    }
    e->order = ix[c];
    return fxs_pt_enc_tree(e, k[c], q, NULL, NULL);
}

/* The tree of a frame with an axis of more than 21 bits (partitioning), then e->q in tree
 * order and e->order: the same order as the Morton path, ties in input order. -1 when out
 * of memory. */
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
        r = fxs_pt_enc_tree(e, NULL, NULL, pts, pts + n);
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
    struct fxs_rc_enc w = e->w;
    uint32_t zt = 0, zf = 0, n = e->f.n;
    for (uint32_t j = 0; j < n; j++) {
        int32_t nb = nbs[j];
        uint32_t nt = nb < 0 ? 0 : qt[nb], nf = nb < 0 ? 0 : qf[nb];
        unsigned nfl = nb < 0 ? 0 : fl[nb], v = fl[j];
        int f0 = nf == 0;
        fxs_rc_prob *pt = m->t[(fxs_pt_rclass(zt) * 8 + (int)(v & 7u)) * 2 + f0];
        fxs_rc_prob *pf = m->f[(fxs_pt_rclass(zf) * 2 + f0) * 2 + (int)(v >> 2 & 1u)];
        if (fxs_rc_room(&e->rb, &e->bb, &w)) return -1;
        fxs_rc_bit(&w, &m->same[(nfl & 7u) * 2 + (unsigned)f0], v != nfl);
        if (v != nfl) fxs_rc_put_tree(&w, m->tree, v, 8);
        zt = fxs_pt_zigzag((int32_t)qt[j] - (int32_t)nt);
        zf = fxs_pt_zigzag((int32_t)qf[j] - (int32_t)nf);
        fxs_rc_put_int(&w, pt, FXS_PT_T_U, zt);
        fxs_rc_put_int(&w, pf, FXS_PT_F_U, zf);
    }
    e->w = w;
    return 0;
}

static int fxs_pt_enc_attrs1(struct fxs_pt_enc *e, const uint32_t *qt, const uint32_t *qf, const uint8_t *fl,
                             const int32_t *nbs, const uint8_t *sk)
{
    const struct fxs_pt_frame *f = &e->f;
    struct fxs_pt_models *m = &e->m;
    struct fxs_rc_enc w = e->w;
    const int tbits = f->temp_bits, fbits = f->fuel_bits;
    const int t3 = tbits > 3 ? tbits - 3 : 0, t4 = tbits > 4 ? tbits - 4 : 0;
    int32_t last[256];
    for (int i = 0; i < 256; i++) last[i] = -1;
    for (uint32_t j = 0; j < f->n; j++) {
        unsigned v = fl[j], c = v & 7u, t = qt[j], fu = qf[j];
        int32_t nb = nbs[j], sb = sk[j] ? (int32_t)(j - sk[j]) : last[v];
        unsigned nf0 = nb < 0 || qf[nb] == 0;
        unsigned nfl = nb < 0 ? 0 : fl[nb], nc = nb < 0 ? 8 : nfl & 7u;
        if (fxs_rc_room(&e->rb, &e->bb, &w)) return -1;
        fxs_rc_bit(&w, &m->vsame[nc * 2 + nf0], v != nfl);
        if (v != nfl) fxs_rc_put_tree(&w, m->vfl[nc], v, 8);
        fxs_rc_put_tree(&w, m->vt[c * 9 + (sb < 0 ? 8u : qt[sb] >> t3)], t, tbits);
        fxs_rc_bit(&w, &m->vf0[(c * 16 + (t >> t4)) * 2 + nf0], fu != 0);
        if (fu) fxs_rc_put_tree(&w, m->vf[c * 8 + (t >> t3)], fu - 1, fbits);
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
     * mostly land in the same bucket, and one copy would make every increment wait on the
     * one before (and a double sum on its add); F = 0 by flags follows from the totals of
     * the two histograms. All exact integers, so the estimate does not depend on the
     * order of the additions. */
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
    double *xd = e->pd, *yd = xd + n, *zd = yd + n, *fd = zd + n;
    for (uint32_t j = 0; j < n; j++) {
        uint32_t i = e->order[j];
        qt[j] = fxs_pt_quant(p->temp[i], f->lo[3], ts, tmax);
        qf[j] = fxs_pt_quant(p->fuel[i], f->lo[4], fs, fmax);
        fl[j] = p->flags[i];
        xd[j] = q[3 * (size_t)j], yd[j] = q[3 * (size_t)j + 1], zd[j] = q[3 * (size_t)j + 2], fd[j] = fl[j];
    }
    fxs_pt_near_same(n, f->abits[0] <= 23 && f->abits[1] <= 23 && f->abits[2] <= 23, xd, yd, zd, fd, nbs, sk);
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
    struct fxs_rc_enc w;
    if (!qv) return -1;
    for (int a = 0; a < 3; a++) scale[a] = f->vstep[a] > 0 ? 1.0 / f->vstep[a] : 0;
    for (uint32_t j = 0; j < n; j++)
        for (int a = 0; a < 3; a++) qv[3 * (size_t)j + a] = fxs_pt_vquant(p->vel[3 * (size_t)e->order[j] + a], scale[a], qmax);
    w = e->w;
    for (uint32_t j = 0; j < n; j++) {
        const int32_t *c = qv + 3 * (size_t)j, *o = nbs[j] < 0 ? NULL : qv + 3 * (size_t)nbs[j];
        unsigned fl = p->flags[e->order[j]];
        if (fxs_rc_room(&e->rb, &e->bb, &w)) {
            free(qv);
            return -1;
        }
        uint32_t zb = zx; /* the residual before: the previous particle's x, then this one's x, y */
        for (int a = 0; a < 3; a++) {
            uint32_t z = fxs_pt_zigzag(c[a] - (o ? o[a] : 0));
            fxs_rc_put_int(&w, e->m.v[fxs_pt_vctx(a, zb, fl)], FXS_PT_V_U, z);
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
    struct fxs_rc_enc *w = &e->w;
    uint8_t *s;
    fxs_pt_steps(&e->f);
    fxs_rc_enc_init(w);
    if (!(w->rp = fxs_rc_grow(&e->rb, NULL, hb + nn + 4096))) return -1;
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
        if (!(w->bp = fxs_rc_grow(&e->bb, NULL, nn + 4096))) return -1;
        if (e->f.abits[0] <= 21 && e->f.abits[1] <= 21 && e->f.abits[2] <= 21) {
            if (fxs_pt_enc_morton(e)) return -1;
        } else if (fxs_pt_enc_wide(e)) {
            return -1;
        }
        if (fxs_pt_enc_attrs(e, p) || (e->f.vel && fxs_pt_enc_vel(e, p)) || fxs_rc_room(&e->rb, &e->bb, w)) return -1;
        fxs_rc_enc_flush(w);
        rl = (size_t)(w->rp - e->rb.p) - hb;
        bl = (size_t)(w->bp - e->bb.p);
        if (rl > UINT32_MAX || bl > UINT32_MAX) return -1;
        if (!(w->rp = fxs_rc_grow(&e->rb, w->rp, bl))) return -1;
        if (bl) memcpy(w->rp, e->bb.p, bl);
    }
    fxs_pt_header_put(&e->f, e->rb.p, (uint32_t)rl, (uint32_t)bl);
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
