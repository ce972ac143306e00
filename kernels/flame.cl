/* flame.cl — the SPH flame (seed 002, Mabuchi 2012; spec: digest 002) on the device.
 *
 * One substep (digest §2.10, §5.3):
 *   fl_hash           cell key per particle (cells 2h in y and z, h/2 along x by default; linear
 *                     hash, power-of-two table)
 *   fl_radix_hist/scan/scatter   stable LSD radix sort of (key, index), 8 bits a pass
 *   fl_reorder        gathers the state into sorted order (double buffer)
 *   fl_cell_start     cs[k] = number of particles with key < k (so a run of keys is one range)
 *   fl_density        rho (poly6, eq 3.10), p (eq 3.11), neighbour and flame-neighbour counts,
 *                     and the neighbour list (up to FL_LIST = FL_NL - 8 indices per particle)
 *   fl_forces         walks that list (or the grid again for a particle that overflowed it):
 *                     pressure (sign fixed, §2.5/§9 #1), viscosity (3.13), heat/fuel diffusion
 *                     (3.20/3.21, stabilised §9 #4), chemistry (3.17-3.19), buoyancy (3.16),
 *                     wind (§9 #15; §2.14's drag toward the air's velocity), symplectic Euler
 *                     (3.14/3.15), solids (§2.13, §9 #16),
 *                     resampling decisions (§2.12, §9 #9-11) and the runaway flag
 *   fl_count/fl_scan_blocks/fl_compact   every resample_interval steps: survivors in order,
 *                     then inserted particles appended in parent order with fresh ids
 * On a GPU the sort and the compaction run wide, one work item per element (fl_key_*, fl_scan_*,
 * fl_compact_wide: a counting sort whose scan is the cell-start table, and scanned flags), in the
 * same order as the serial-per-block passes above, which suit a CPU's few cores.
 *
 * Neighbour gather (§2.11): cells have edge c = h / FL_CELLS_PER_H (flame_params.h; 2h by default) and
 * key(cx,cy,cz) = (cx + P1 cy + P2 cz) mod M, so the cells of one (cy,cz) row with consecutive cx
 * have consecutive keys and, after the sort, consecutive particles: a particle visits at most 4
 * rows (9 with cells of h, 25 with h/2), each one contiguous
 * range [cs[k0], cs[k0+len]), trimmed to the part of the row the sphere of radius h reaches.
 * A candidate is accepted when r <= h and (the FL_FOR_NEIGHBOURS walk, and fl_density when two
 * of its rows' ranges overlap) its own (cy,cz) is the row's, which filters hash collisions and
 * makes overlapping rows (tiny tables) count each neighbour once. The candidate loop (about 6
 * candidates per neighbour) costs far more than the pair arithmetic, so it runs once a step:
 * fl_density records the accepted j != i in gather order and fl_forces reads them back
 * (bench_flame: the forces pass 3.5x faster), 8 neighbours at a time as float8 lanes (another
 * 1.6x), the last group masked.
 * Parameters live in one __constant float array; its indices FP_*, the particle flags FL_* and
 * the error bits come from flame_layout.h, which the build prepends and flame.c includes. */

#define FL_HP1 0x9E3779B1u
#define FL_HP2 0x85EBCA77u

typedef __constant const float *prm_t;

inline int3 fl_cell(float4 p, prm_t P)
{
    return convert_int3_rtn(p.xyz * (float3)(P[FP_INV_CELLX], P[FP_INV_CELL], P[FP_INV_CELL]));
}

/* floor(x) as an int: truncation, one less below a negative non-integer (floor() and
 * convert_int_rtn cost several times more on PoCL) */
inline int fl_floor(float x)
{
    int t = convert_int(x);
    return t - ((float)t > x ? 1 : 0);
}

inline uint fl_row_base(int cy, int cz) { return (uint)cy * FL_HP1 + (uint)cz * FL_HP2; }

inline uint fl_key(int3 c, uint mask) { return ((uint)c.x + fl_row_base(c.y, c.z)) & mask; }

inline int fl_is_flame(float4 p, float4 v, prm_t P) { return p.w > P[FP_TIGN] && v.w > P[FP_FEPS]; }

/* ---- sort -------------------------------------------------------------------------- */

__kernel void fl_hash(__global const float4 *pos, __global uint *key, __global uint *val, int n, uint mask,
                      prm_t P)
{
    int i = get_global_id(0);
    if (i >= n) return;
    key[i] = fl_key(fl_cell(pos[i], P), mask);
    val[i] = (uint)i;
}

inline void fl_block(int b, int nb, int n, int *lo, int *hi)
{
    int bs = (n + nb - 1) / nb;
    *lo = min(n, b * bs);
    *hi = min(n, *lo + bs);
}

/* Per block: counts of each 8-bit digit, stored digit-major (hist[d * nb + b]). */
__kernel void fl_radix_hist(__global const uint *key, int n, int shift, __global uint *hist)
{
    int b = get_global_id(0), nb = get_global_size(0), lo, hi;
    uint c[256];
    for (int d = 0; d < 256; d++) c[d] = 0;
    fl_block(b, nb, n, &lo, &hi);
    for (int i = lo; i < hi; i++) c[(key[i] >> shift) & 255u]++;
    for (int d = 0; d < 256; d++) hist[d * nb + b] = c[d];
}

/* Exclusive scan of `len` counts in place (one work item: len = 256 * blocks is small). */
__kernel void fl_scan_serial(__global uint *a, int len)
{
    uint s = 0;
    for (int i = 0; i < len; i++) {
        uint v = a[i];
        a[i] = s;
        s += v;
    }
}

/* Stable scatter of one block, in index order, to its digits' offsets. */
__kernel void fl_radix_scatter(__global const uint *kin, __global const uint *vin, __global uint *kout,
                               __global uint *vout, int n, int shift, __global const uint *hist)
{
    int b = get_global_id(0), nb = get_global_size(0), lo, hi;
    uint off[256];
    for (int d = 0; d < 256; d++) off[d] = hist[d * nb + b];
    fl_block(b, nb, n, &lo, &hi);
    for (int i = lo; i < hi; i++) {
        uint k = kin[i], o = off[(k >> shift) & 255u]++;
        kout[o] = k;
        vout[o] = vin[i];
    }
}

__kernel void fl_reorder(__global const uint *val, int n, __global const float4 *pos, __global const float4 *vel,
                         __global const uint *flags, __global const uint *id, __global float4 *pos2,
                         __global float4 *vel2, __global uint *flags2, __global uint *id2, __global float *sxyz,
                         int stride)
{
    int i = get_global_id(0);
    if (i >= n) return;
    uint s = val[i];
    float4 p = pos[s];
    pos2[i] = p;
    sxyz[i] = p.x; /* x, y, z again as three arrays for the 8-wide loads of fl_density */
    sxyz[stride + i] = p.y;
    sxyz[2 * stride + i] = p.z;
    vel2[i] = vel[s];
    flags2[i] = flags[s];
    id2[i] = id[s];
}

/* cs[q] = p for key[p-1] < q <= key[p]; work item n fills the tail up to cs[M] = n. */
__kernel void fl_cell_start(__global const uint *key, int n, uint m, __global uint *cs)
{
    int p = get_global_id(0);
    if (p > n) return;
    uint from = p > 0 ? key[p - 1] + 1u : 0u, to = p < n ? key[p] : m;
    for (uint q = from; q <= to; q++) cs[q] = (uint)p;
}

/* ---- the sort and the compaction one work item per element (wide passes, GPU devices) ------
 *
 * The serial-per-block passes above suit a CPU's few cores; a GPU needs every element on its own
 * work item. The sort becomes a counting sort: fl_key_count counts the particles of each key
 * (an atomic increment, which also gives each particle a slot in its key's run), a scan of the
 * counts is the cell-start table itself, fl_key_scatter places each particle's index in its run,
 * and fl_key_rank puts each run in index order (the atomics' order is arbitrary): the result is
 * the radix sort's, (key, index) ascending, bit for bit. A run holds one cell's particles (and
 * those of cells hashed to the same key), a few dozen at most, so the rank's O(run^2) is small. */

__kernel void fl_key_count(__global const uint *key, int n, __global uint *cnt, __global uint *slot)
{
    int i = get_global_id(0);
    if (i < n) slot[i] = atomic_inc(&cnt[key[i]]);
}

__kernel void fl_key_scatter(__global const uint *key, __global const uint *slot, int n, __global const uint *cs,
                             __global uint *run)
{
    int i = get_global_id(0);
    if (i < n) run[cs[key[i]] + slot[i]] = (uint)i;
}

__kernel void fl_key_rank(__global const uint *key, __global const uint *run, int n, __global const uint *cs,
                          __global uint *sorted)
{
    int p = get_global_id(0);
    if (p >= n) return;
    uint i = run[p], k = key[i], a = cs[k], b = cs[k + 1], r = 0;
    for (uint q = a; q < b; q++) r += run[q] < i;
    sorted[a + r] = i;
}

/* Exclusive scan of in[e * stride + off] for e < len into out[0 .. len) (sum of the first e),
 * in three launches: fl_scan_reduce sums each tile of FL_SCAN_TILE elements, fl_scan_top scans
 * the tile sums in one work-group (and stores the grand total in tot[tot_i]), fl_scan_down scans
 * each tile from its offset. Work item l of a group takes the tile's elements l*E .. l*E+E-1. */
/* FL_SCAN_WG, FL_SCAN_E, FL_SCAN_TILE: flame_layout.h */

/* The work-group's exclusive prefix of v (Hillis-Steele in local memory) and its total. */
inline uint fl_group_scan(__local uint *s, uint v, uint *total)
{
    int l = get_local_id(0);
    s[l] = v;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int o = 1; o < FL_SCAN_WG; o <<= 1) {
        uint t = l >= o ? s[l - o] : 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
        s[l] += t;
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    uint r = s[l] - v;
    *total = s[FL_SCAN_WG - 1];
    barrier(CLK_LOCAL_MEM_FENCE);
    return r;
}

inline void fl_scan_load(__global const uint *in, int stride, int off, int len, uint *x)
{
    int e0 = get_group_id(0) * FL_SCAN_TILE + get_local_id(0) * FL_SCAN_E;
    for (int e = 0; e < FL_SCAN_E; e++) x[e] = e0 + e < len ? in[(e0 + e) * stride + off] : 0u;
}

__kernel __attribute__((reqd_work_group_size(FL_SCAN_WG, 1, 1)))
void fl_scan_reduce(__global const uint *in, int stride, int off, int len, __global uint *sums)
{
    __local uint s[FL_SCAN_WG];
    uint x[FL_SCAN_E], v = 0, total;
    fl_scan_load(in, stride, off, len, x);
    for (int e = 0; e < FL_SCAN_E; e++) v += x[e];
    fl_group_scan(s, v, &total);
    if (get_local_id(0) == 0) sums[get_group_id(0)] = total;
}

/* One work-group: work item l scans its share of the `tiles` sums serially around the group scan. */
__kernel __attribute__((reqd_work_group_size(FL_SCAN_WG, 1, 1)))
void fl_scan_top(__global uint *sums, int tiles, __global uint *tot, int tot_i)
{
    __local uint s[FL_SCAN_WG];
    int l = get_local_id(0), per = (tiles + FL_SCAN_WG - 1) / FL_SCAN_WG;
    int lo = min(tiles, l * per), hi = min(tiles, lo + per);
    uint v = 0, all;
    for (int t = lo; t < hi; t++) v += sums[t];
    uint run = fl_group_scan(s, v, &all);
    for (int t = lo; t < hi; t++) {
        uint x = sums[t];
        sums[t] = run;
        run += x;
    }
    if (l == 0) tot[tot_i] = all;
}

__kernel __attribute__((reqd_work_group_size(FL_SCAN_WG, 1, 1)))
void fl_scan_down(__global const uint *in, int stride, int off, int len, __global const uint *sums,
                  __global uint *out)
{
    __local uint s[FL_SCAN_WG];
    uint x[FL_SCAN_E], v = 0, total;
    fl_scan_load(in, stride, off, len, x);
    for (int e = 0; e < FL_SCAN_E; e++) v += x[e];
    uint run = sums[get_group_id(0)] + fl_group_scan(s, v, &total);
    int e0 = get_group_id(0) * FL_SCAN_TILE + get_local_id(0) * FL_SCAN_E;
    for (int e = 0; e < FL_SCAN_E; e++) {
        if (e0 + e < len) out[e0 + e] = run;
        run += x[e];
    }
}

/* ---- neighbour gather ---------------------------------------------------------------- */

/* Iterates the neighbours j (including i itself) of position `pi`; BODY sees j, dx = r_i - r_j,
 * r2 = |dx|^2 and pj. Rows are trimmed to the sphere of radius h; collisions are filtered. */
#define FL_FOR_NEIGHBOURS(pos, cs, mask, P, pi, BODY)                                                       \
    {                                                                                                       \
        const float h_ = P[FP_H] * 1.0001f, h2_ = P[FP_H2], ic_ = P[FP_INV_CELL], c_ = 1.0f / ic_, icx_ = P[FP_INV_CELLX];                    \
        const uint m_ = mask + 1u;                                                                          \
        const int ylo_ = (int)floor((pi.y - h_) * ic_), yhi_ = (int)floor((pi.y + h_) * ic_);               \
        const int zlo_ = (int)floor((pi.z - h_) * ic_), zhi_ = (int)floor((pi.z + h_) * ic_);               \
        for (int cz_ = zlo_; cz_ <= zhi_; cz_++) {                                                          \
            float ez_ = fmax(0.0f, fmax(cz_ * c_ - pi.z, pi.z - (cz_ + 1) * c_));                           \
            for (int cy_ = ylo_; cy_ <= yhi_; cy_++) {                                                      \
                float ey_ = fmax(0.0f, fmax(cy_ * c_ - pi.y, pi.y - (cy_ + 1) * c_));                       \
                float rr_ = h_ * h_ - ey_ * ey_ - ez_ * ez_;                                                    \
                if (rr_ < 0.0f) continue;                                                                   \
                float rx_ = sqrt(rr_) * 1.0001f;                                                                      \
                int xlo_ = (int)floor((pi.x - rx_) * icx_), xhi_ = (int)floor((pi.x + rx_) * icx_);           \
                uint k0_ = ((uint)xlo_ + fl_row_base(cy_, cz_)) & mask;                                     \
                uint k1_ = k0_ + (uint)(xhi_ - xlo_ + 1);                                                   \
                for (int part_ = 0; part_ < 2; part_++) {                                                   \
                    uint a_, b_;                                                                            \
                    if (part_ == 0) { a_ = cs[k0_]; b_ = cs[min(k1_, m_)]; }                                \
                    else if (k1_ > m_) { a_ = cs[0]; b_ = cs[k1_ - m_]; }                                   \
                    else break;                                                                             \
                    for (uint j = a_; j < b_; j++) {                                                        \
                        float4 pj = pos[j];                                                                 \
                        float3 dx = pi.xyz - pj.xyz;                                                        \
                        float r2 = dot(dx, dx);                                                             \
                        if (r2 > h2_) continue;                                                             \
                        if ((int)floor(pj.y * ic_) != cy_ || (int)floor(pj.z * ic_) != cz_) continue;       \
                        BODY                                                                                \
                    }                                                                                       \
                }                                                                                           \
            }                                                                                               \
        }                                                                                                   \
    }

/* fl_pack8[m]: the positions of the set bits of the 8-bit mask m in increasing order, one per
 * 4-bit nibble from the lowest (unused nibbles 0): fl_density's compaction of accepted lanes. */
#define FL_POP8(m) (((m) & 1) + ((m) >> 1 & 1) + ((m) >> 2 & 1) + ((m) >> 3 & 1) + ((m) >> 4 & 1) + \
                    ((m) >> 5 & 1) + ((m) >> 6 & 1) + ((m) >> 7 & 1))
#define FL_PB(m, b) (((m) >> (b) & 1) ? (uint)(b) << (4 * FL_POP8((m) & ((1 << (b)) - 1))) : 0u)
#define FL_P1(m) (FL_PB(m, 0) | FL_PB(m, 1) | FL_PB(m, 2) | FL_PB(m, 3) | FL_PB(m, 4) | FL_PB(m, 5) | \
                  FL_PB(m, 6) | FL_PB(m, 7))
#define FL_P4(m) FL_P1(m), FL_P1(m + 1), FL_P1(m + 2), FL_P1(m + 3)
#define FL_P16(m) FL_P4(m), FL_P4(m + 4), FL_P4(m + 8), FL_P4(m + 12)
#define FL_P64(m) FL_P16(m), FL_P16(m + 16), FL_P16(m + 32), FL_P16(m + 48)
__constant uint fl_pack8[256] = {FL_P64(0), FL_P64(64), FL_P64(128), FL_P64(192)};

#define FL_LIST (FL_NL - 8) /* longest list: fl_density stores 8 slots from slot nb <= FL_LIST */

/* Pass 1: density (eq 3.10, j = i included), pressure (eq 3.11 clamped at 0 in both forms: in the
 * difference form a negative p at the free boundary of a gas with no air around it pushes the
 * boundary outward until the flame burns out; PROTOCOL.md §11.2), neighbour counts j != i
 * (nbr | flame_nbr << 16, digest §2.12), and the neighbour list: nl[i * FL_NL + k] for the nbr neighbours j != i in gather order when nbr <= FL_LIST
 * (slots FL_LIST.. take the overflow writes). fl_forces walks the list instead of the grid; a
 * particle with more neighbours keeps no valid list and both passes gather it from the grid
 * again, so no neighbour is ever dropped. The candidate scan runs 8 candidates at a time as
 * float8 lanes (PoCL emits AVX for it); the row test, needed only when two rows' ranges
 * overlap (below), as float compares (floor(y/c) == cy  <=>  cy <= y/c < cy + 1;
 * convert_int8_rtn is slow on PoCL); x, y, z come from the sorted arrays
 * of fl_reorder (sxyz: three plain vload8 instead of two vload16 and shuffles, 10%). The
 * accepted lanes are appended without a branch: fl_pack8 of their bit mask gives their
 * positions packed to the front, one vstore8 writes all 8 slots from slot nb and nb advances
 * by the popcount (the slots past it are overwritten by the next store or ignored). Appending
 * one set bit at a time instead (a loop with an unpredictable trip count per 8 candidates)
 * makes the density pass about 1.5x slower (docs/performance-log.md). */
__kernel void fl_density(__global const float4 *pos, __global const float4 *vel, __global const uint *cs, uint mask,
                         int n, prm_t P, __global float2 *rho_p, __global uint *counts, __global uint *nl,
                         __global const float *sxyz, int stride)
{
    int i = get_global_id(0);
    if (i >= n) return;
    float4 pi = pos[i];
    float8 w8 = (float8)(0.0f);
    uint nb = 0, fnb = 0;
    const float tign = P[FP_TIGN], feps = P[FP_FEPS];
    __global uint *L = nl + (size_t)i * FL_NL;
    const float h_ = P[FP_H] * 1.0001f, h2_ = P[FP_H2], ic_ = P[FP_INV_CELL], c_ = 1.0f / ic_, icx_ = P[FP_INV_CELLX];
    const uint m_ = mask + 1u;
    const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
    /* the rows the sphere reaches (2 x 2 with cells of 2h; FL_ROWS at most, from flame.c), each
     * one range of sorted particles, or two where its keys wrap past the end of the table */
    uint ra[2 * FL_ROWS], rb[2 * FL_ROWS];
    float rcy[2 * FL_ROWS], rcz[2 * FL_ROWS];
    int nr = 0;
    const int ylo_ = fl_floor((pi.y - h_) * ic_), yhi_ = fl_floor((pi.y + h_) * ic_);
    const int zlo_ = fl_floor((pi.z - h_) * ic_), zhi_ = fl_floor((pi.z + h_) * ic_);
    for (int cz_ = zlo_; cz_ <= zhi_; cz_++) {
        float ez_ = fmax(0.0f, fmax(cz_ * c_ - pi.z, pi.z - (cz_ + 1) * c_));
        for (int cy_ = ylo_; cy_ <= yhi_; cy_++) {
            float ey_ = fmax(0.0f, fmax(cy_ * c_ - pi.y, pi.y - (cy_ + 1) * c_));
            float rr_ = h_ * h_ - ey_ * ey_ - ez_ * ez_;
            if (rr_ < 0.0f) continue;
            float rx_ = sqrt(rr_) * 1.0001f;
            int xlo_ = fl_floor((pi.x - rx_) * icx_), xhi_ = fl_floor((pi.x + rx_) * icx_);
            uint k0_ = ((uint)xlo_ + fl_row_base(cy_, cz_)) & mask;
            uint k1_ = k0_ + (uint)(xhi_ - xlo_ + 1);
            ra[nr] = cs[k0_];
            rb[nr] = cs[min(k1_, m_)];
            rcy[nr] = (float)cy_;
            rcz[nr++] = (float)cz_;
            if (k1_ > m_) {
                ra[nr] = cs[0];
                rb[nr] = cs[k1_ - m_];
                rcy[nr] = (float)cy_;
                rcz[nr++] = (float)cz_;
            }
        }
    }
    /* A candidate within h lies in its own row's range, so with ranges that share no particle
     * the distance test alone accepts each neighbour once; ranges overlap only when the keys
     * of two rows collide (a small table), and then a candidate must be in the row scanned. */
    int overlap = 0;
    for (int u = 0; u < nr; u++)
        for (int v = u + 1; v < nr; v++)
            overlap |= ra[u] < rb[u] && ra[v] < rb[v] && ra[u] < rb[v] && ra[v] < rb[u];
    for (int r_ = 0; r_ < nr; r_++) {
        const uint a_ = ra[r_], b_ = rb[r_];
        const float fcy_ = rcy[r_], fcz_ = rcz[r_];
        /* 8 candidates a step as float8 lanes (sxyz arrays padded by FL_PAD) */
        for (uint j0 = a_; j0 < b_; j0 += 8u) {
            float8 dX = pi.x - vload8(0, sxyz + j0);
            float8 Y = vload8(0, sxyz + stride + j0), Z = vload8(0, sxyz + 2 * stride + j0);
            float8 dY = pi.y - Y, dZ = pi.z - Z;
            float8 r2 = dX * dX + dY * dY + dZ * dZ;
            int8 ok = (r2 <= h2_) & (lane < (int)(b_ - j0));
            if (overlap) {
                float8 yc = Y * ic_, zc = Z * ic_; /* floor(yc) == cy  <=>  cy <= yc < cy + 1 */
                ok &= (yc >= fcy_) & (yc < fcy_ + 1.0f) & (zc >= fcz_) & (zc < fcz_ + 1.0f);
            }
            float8 q = h2_ - r2;
            w8 += select((float8)(0.0f), q * q * q, ok);
            /* accepted lanes as bits (self excluded), stored packed to the front */
            int8 bv = select((int8)(0), (int8)(1, 2, 4, 8, 16, 32, 64, 128), ok);
            int4 b4 = bv.lo | bv.hi;
            uint bits = (uint)(b4.x | b4.y | b4.z | b4.w);
            if ((uint)i - j0 < 8u) bits &= ~(1u << ((uint)i - j0));
            uint8 at = ((uint8)(fl_pack8[bits]) >> (uint8)(0, 4, 8, 12, 16, 20, 24, 28)) & 15u;
            vstore8(j0 + at, 0, L + min(nb, (uint)FL_LIST));
            nb += popcount(bits);
        }
    }
    if (nb > FL_LIST) { /* no list: the flame neighbours from the grid (fl_forces counts them otherwise) */
        FL_FOR_NEIGHBOURS(pos, cs, mask, P, pi, {
            if (j != (uint)i) fnb += (pj.w > tign && vel[j].w > feps) ? 1u : 0u;
        })
    }
    float4 w4 = w8.lo + w8.hi;
    float w = (w4.x + w4.y) + (w4.z + w4.w);
    float rho = w * P[FP_POLY6];
    float p = P[FP_KSTIFF] * (rho - P[FP_RHO0]);
    p = fmax(p, 0.0f);
    rho_p[i] = (float2)(rho, p);
    counts[i] = min(nb, 65535u) | (min(fnb, 65535u) << 16); /* fnb completed by fl_forces for a list */
}

/* Sums of one pass-2 gather. */
struct fl_acc {
    float3 f, visc, nrm;
    float dT, wT, dF, wF, wV;
};

/* Pressure and viscosity force densities, diffusion sums and weights, colour normal. */
inline void fl_pair(struct fl_acc *a, float4 pi, float4 vi, float2 rpi, float4 pj, float4 vj, float2 rpj,
                    float3 dx, float r2, prm_t P)
{
    float r = sqrt(r2), h = P[FP_H], vol = P[FP_MASS] / rpj.x;
    float hr = h - r, lap = P[FP_SPIKY] * hr;          /* eq 3.9 */
    float grad = r > 0.0f ? P[FP_SPIKY] * hr * hr / r : 0.0f;
    float pp = P[FP_SYMMETRIC] != 0.0f ? 0.5f * (rpi.y + rpj.y) : (rpj.y - rpi.y);
    a->f += (vol * pp * grad) * dx;                     /* eq 3.12 pushed away from high p (§2.5) */
    float wv = vol * lap;                               /* eq 3.13, weight per unit k_visc */
    a->visc += wv * (vj.xyz - vi.xyz);
    a->wV += wv;
    a->dT += wv * (pj.w - pi.w);                        /* eq 3.20 per unit k_h */
    a->wT += wv;
    float wf = wv * 0.5f * (pi.w + pj.w);               /* eq 3.21 per unit k_f */
    a->dF += wf * (vj.w - vi.w);
    a->wF += wf;
    float q = P[FP_H2] - r2;
    a->nrm -= (q * q / rpj.x) * dx;                     /* Mueller colour normal / mass: points inward */
}

/* Stabilised explicit diffusion (§9 #4): the weights dt*k*w_ij of one particle sum to W; when
 * W > omega_max all are scaled by omega_max/W, so the update is a convex combination. Returns
 * the time derivative k*sum (scaled). */
inline float fl_diffuse(float sum, float wsum, float k, prm_t P)
{
    float W = P[FP_DT] * k * wsum;
    float s = (P[FP_LITERAL] == 0.0f && W > P[FP_OMEGA]) ? P[FP_OMEGA] / W : 1.0f;
    return s * k * sum;
}

inline float3 fl_random_dir(uint id, prm_t P)
{
    uint s = id * 747796405u + (uint)P[FP_SEED] * 2891336453u + 1u;
    float u[3];
    for (int k = 0; k < 3; k++) {
        s = s * 747796405u + 2891336453u;
        uint x = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
        u[k] = (float)((x >> 22u) ^ x) * (1.0f / 4294967296.0f);
    }
    float z = 2.0f * u[0] - 1.0f, t = 6.2831853f * u[1], r = sqrt(fmax(0.0f, 1.0f - z * z));
    return (float3)(r * cos(t), r * sin(t), z);
}

/* Chemistry (3.17-3.19), cooling (§9 #13), T/F update (3.22/3.23, F >= 0 §9 #12). A step
 * burns at most the fuel the particle has after diffusion, so the invariant T + (k_pt/k_cf) F
 * holds at any dt: clipping F at 0 alone would create heat from fuel that is not there
 * (at dt = 4 ms and 8000 K the Euler step burns 160 units of 100). */
inline float2 fl_burn(float T, float F, float dTdiff, float dFdiff, int flame, prm_t P, float *dT, float *dF)
{
    float S = flame ? P[FP_KRS] * T * F : 0.0f;
    float dt = P[FP_DT];
    float Fd = fmax(0.0f, F + dt * dFdiff), burn = dt * P[FP_KCF] * S;
    if (burn > Fd) S *= Fd / burn;
    *dT = dTdiff + P[FP_KPT] * S;
    *dF = dFdiff - P[FP_KCF] * S;
    float Tn = T + dt * *dT;
    Tn -= fmin(1.0f, dt * P[FP_KCOOL]) * (Tn - P[FP_TAMB]);
    /* all the fuel burned: exactly 0 (F + dt dF rounds to a few 1e-6 with fused multiply-adds) */
    return (float2)(Tn, burn > Fd ? 0.0f : fmax(0.0f, F + dt * *dF));
}

/* fl_forces' sums over the list of fl_density (the same neighbours in the same order), 8
 * neighbours a step as float8 lanes, gathered then transposed; the last group's lanes past the
 * list read particle i itself and weigh nothing. The colour normal only where `normal` (the
 * resampling steps, which alone use it); the callers pass a constant, so each gets its own
 * loop. Returns the flame-neighbour count. */
__attribute__((always_inline)) inline uint fl_list_sums(struct fl_acc *a, __global const uint *L, uint nbl, int i,
                                                        float4 pi, float4 vi, float2 rpi, __global const float4 *pos,
                                                        __global const float4 *vel, __global const float2 *rho_p,
                                                        prm_t P, const int normal)
{
    const float tign = P[FP_TIGN], feps = P[FP_FEPS];
    const float h = P[FP_H], h2 = P[FP_H2], spiky = P[FP_SPIKY], mass = P[FP_MASS];
    const float sym = P[FP_SYMMETRIC] != 0.0f ? 1.0f : 0.0f;
    const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
    float8 fx = 0.0f, fy = 0.0f, fz = 0.0f, ux = 0.0f, uy = 0.0f, uz = 0.0f, nx = 0.0f, ny = 0.0f, nz = 0.0f,
           sT = 0.0f, sV = 0.0f, sF = 0.0f, sWF = 0.0f;
    int8 nfl = 0;
    for (uint k = 0; k < nbl; k += 8u) {
        int8 in = lane < (int)(nbl - k);
        uint8 J = select((uint8)((uint)i), vload8(0, L + k), as_uint8(in));
        float4 p0 = pos[J.s0], p1 = pos[J.s1], p2 = pos[J.s2], p3 = pos[J.s3], p4 = pos[J.s4], p5 = pos[J.s5],
               p6 = pos[J.s6], p7 = pos[J.s7];
        float4 v0 = vel[J.s0], v1 = vel[J.s1], v2 = vel[J.s2], v3 = vel[J.s3], v4 = vel[J.s4], v5 = vel[J.s5],
               v6 = vel[J.s6], v7 = vel[J.s7];
        float2 q0 = rho_p[J.s0], q1 = rho_p[J.s1], q2 = rho_p[J.s2], q3 = rho_p[J.s3], q4 = rho_p[J.s4],
               q5 = rho_p[J.s5], q6 = rho_p[J.s6], q7 = rho_p[J.s7];
        float8 dX = pi.x - (float8)(p0.x, p1.x, p2.x, p3.x, p4.x, p5.x, p6.x, p7.x);
        float8 dY = pi.y - (float8)(p0.y, p1.y, p2.y, p3.y, p4.y, p5.y, p6.y, p7.y);
        float8 dZ = pi.z - (float8)(p0.z, p1.z, p2.z, p3.z, p4.z, p5.z, p6.z, p7.z);
        float8 TJ = (float8)(p0.w, p1.w, p2.w, p3.w, p4.w, p5.w, p6.w, p7.w);
        float8 VX = (float8)(v0.x, v1.x, v2.x, v3.x, v4.x, v5.x, v6.x, v7.x);
        float8 VY = (float8)(v0.y, v1.y, v2.y, v3.y, v4.y, v5.y, v6.y, v7.y);
        float8 VZ = (float8)(v0.z, v1.z, v2.z, v3.z, v4.z, v5.z, v6.z, v7.z);
        float8 FJ = (float8)(v0.w, v1.w, v2.w, v3.w, v4.w, v5.w, v6.w, v7.w);
        nfl -= in & (TJ > tign) & (FJ > feps); /* flame neighbours (true lanes are -1) */
        float8 RJ = (float8)(q0.x, q1.x, q2.x, q3.x, q4.x, q5.x, q6.x, q7.x);
        float8 PJ = (float8)(q0.y, q1.y, q2.y, q3.y, q4.y, q5.y, q6.y, q7.y);
        float8 r2 = dX * dX + dY * dY + dZ * dZ, r = sqrt(r2);
        float8 vol = select((float8)(0.0f), mass / RJ, in);
        float8 hr = h - r, lap = spiky * hr;                                 /* eq 3.9 */
        float8 grad = select((float8)(0.0f), spiky * hr * hr / r, r > 0.0f);
        float8 pp = sym * (0.5f * (rpi.y + PJ)) + (1.0f - sym) * (PJ - rpi.y);
        float8 g = vol * pp * grad;                                          /* eq 3.12 */
        fx += g * dX;
        fy += g * dY;
        fz += g * dZ;
        float8 wv = select((float8)(0.0f), vol * lap, in);                   /* eq 3.13 */
        ux += wv * (VX - vi.x);
        uy += wv * (VY - vi.y);
        uz += wv * (VZ - vi.z);
        sV += wv;
        sT += wv * (TJ - pi.w);                                              /* eq 3.20 */
        float8 wf = wv * 0.5f * (pi.w + TJ);                                 /* eq 3.21 */
        sF += wf * (FJ - vi.w);
        sWF += wf;
        if (normal) {
            float8 q = h2 - r2, c = q * q / RJ;                               /* colour normal / mass */
            nx -= c * dX;                                                   /* dX = 0 on the lanes of i */
            ny -= c * dY;
            nz -= c * dZ;
        }
    }
#define FL_HSUM8(v) ({ float4 t_ = (v).lo + (v).hi; (t_.x + t_.y) + (t_.z + t_.w); })
    a->f = (float3)(FL_HSUM8(fx), FL_HSUM8(fy), FL_HSUM8(fz));
    a->visc = (float3)(FL_HSUM8(ux), FL_HSUM8(uy), FL_HSUM8(uz));
    a->nrm = (float3)(FL_HSUM8(nx), FL_HSUM8(ny), FL_HSUM8(nz));
    a->wV = a->wT = FL_HSUM8(sV);
    a->dT = FL_HSUM8(sT);
    a->dF = FL_HSUM8(sF);
    a->wF = FL_HSUM8(sWF);
#undef FL_HSUM8
    int4 n4 = nfl.lo + nfl.hi;
    return (uint)((n4.x + n4.y) + (n4.z + n4.w));
}

/* Pass 2 + integration: reads the sorted state (pos, vel, flags, id), writes the next state
 * in the same order (pos2..), the derivatives, and when `resample` is set the keep/insert
 * decisions and the outward normal for fl_compact. */
__kernel void fl_forces(__global const float4 *pos, __global const float4 *vel, __global const uint *flags,
                        __global const uint *id, __global const uint *cs, uint mask, int n, prm_t P,
                        __global const float2 *rho_p, __global uint *counts, __global const uint *nl,
                        __global float4 *pos2,
                        __global float4 *vel2, __global uint *flags2, __global uint *id2, __global float4 *force,
                        __global float2 *dTdF, int integrate, int resample, __global uint2 *keep_ins, __global float4 *nrm_out,
                        __global int *errflag)
{
    int i = get_global_id(0);
    if (i >= n) return;
    float4 pi = pos[i], vi = vel[i];
    float2 rpi = rho_p[i];
    uint fl = flags[i], type = fl & FL_TYPE;
    struct fl_acc a = {(float3)(0.0f), (float3)(0.0f), (float3)(0.0f), 0.0f, 0.0f, 0.0f, 0.0f, 0.0f};
    uint nbl = counts[i] & 0xffffu;
    if (nbl <= FL_LIST) { /* the list of fl_density: the same neighbours in the same order */
        __global const uint *L = nl + (size_t)i * FL_NL;
        uint fnb = resample ? fl_list_sums(&a, L, nbl, i, pi, vi, rpi, pos, vel, rho_p, P, 1)
                            : fl_list_sums(&a, L, nbl, i, pi, vi, rpi, pos, vel, rho_p, P, 0);
        counts[i] = nbl | (min(fnb, 65535u) << 16); /* the flame-neighbour count of fl_density's list */
    } else {
        FL_FOR_NEIGHBOURS(pos, cs, mask, P, pi, {
            if (j != (uint)i) fl_pair(&a, pi, vi, rpi, pj, vel[j], rho_p[j], dx, r2, P);
        })
    }
    float dt = P[FP_DT], rho = rpi.x;
    float dTdiff = fl_diffuse(a.dT, a.wT, P[FP_KH], P);
    float dFdiff = fl_diffuse(a.dF, a.wF, P[FP_KF], P);
    float3 fvisc = P[FP_KVISC] * a.visc;
    float wv = dt * P[FP_KVISC] * a.wV / rho; /* viscosity number: the same convex cap (§2.15) */
    if (P[FP_LITERAL] == 0.0f && wv > P[FP_OMEGA]) fvisc *= P[FP_OMEGA] / wv;
    float dT, dF;
    float2 TF = fl_burn(pi.w, vi.w, dTdiff, dFdiff, fl_is_flame(pi, vi, P), P, &dT, &dF);
    float3 up = (float3)(P[FP_UP], P[FP_UP + 1], P[FP_UP + 2]);
    float3 f = a.f + fvisc + (P[FP_KBUO] * (TF.x - P[FP_TAMB])) * up; /* eq 3.16 with the new T */
    float4 pn = pi, vn = vi;
    if (!integrate) {
        /* flame_eval: derivatives only, state unchanged */
    } else if (type == FL_GAS) {
        vn.xyz = vi.xyz + dt * (f / rho + (float3)(P[FP_WIND], P[FP_WIND + 1], P[FP_WIND + 2]));
        /* drag toward the ambient air, digest §2.14's f = rho k_drag (v_wind - v), across `up` only
         * (buoyancy is the net vertical force, §2.6): the velocity relative to the wind relaxes
         * exactly over the step, by the factor exp(-k_drag dt), so any k_drag dt is stable */
        float3 rel = vn.xyz - (float3)(P[FP_WINDV], P[FP_WINDV + 1], P[FP_WINDV + 2]);
        vn.xyz -= P[FP_DRAG] * (rel - dot(rel, up) * up);
        pn.xyz = pi.xyz + dt * vn.xyz;
        pn.w = TF.x;
        vn.w = TF.y;
        if (!(isfinite(pn.x) && isfinite(pn.y) && isfinite(pn.z) && isfinite(pn.w) && isfinite(vn.w)))
            atomic_or(errflag, FL_ERR_NAN);
        else if (dot(vn.xyz, vn.xyz) > P[FP_VMAX] * P[FP_VMAX])
            atomic_or(errflag, FL_ERR_SPEED);
    } else if (type == FL_OBSTACLE) {
        pn.xyz = pi.xyz + dt * vi.xyz; /* prescribed motion (§9 #16) */
    }
    uint isf = integrate ? (fl_is_flame(pn, vn, P) ? FL_FLAME : 0u) : (fl & FL_FLAME);
    pos2[i] = pn;
    vel2[i] = vn;
    flags2[i] = (fl & ~FL_FLAME) | isf;
    id2[i] = id[i];
    force[i] = (float4)(f, 0.0f);
    dTdF[i] = (float2)(dT, dF);
    if (!resample) return;
    uint cnt = counts[i], nbr = cnt & 0xffffu, fnb = cnt >> 16;
    uint keep = (type != FL_GAS || isf || fnb > 0u) ? 1u : 0u;  /* death rule (§2.12, §9 #11) */
    uint ins = (isf && nbr < (uint)P[FP_NBR_INS]) ? 1u : 0u;    /* birth rule (§2.12, §9 #8) */
    keep_ins[i] = (uint2)(keep, ins);
    if (ins) {
        /* The normal is summed without the mass factor m (~1e-8 kg): with it, its squared length
         * (~1e-42) is below float's normal range, and a GPU compiler under -cl-unsafe-math
         * flushes it to 0, so every insertion took the random direction (NVIDIA: a third of
         * the particles, 13% of the burning gas under the source). */
        float ln = length(a.nrm);
        float tiny = 1e-4f * P[FP_H2] * P[FP_H2] * P[FP_H] / rho;
        float3 nh = ln > tiny ? a.nrm / ln : -fl_random_dir(id[i], P); /* §9 #9 */
        nrm_out[i] = (float4)(nh, 0.0f);
    }
}

/* ---- resampling compaction ----------------------------------------------------------- */

/* Per block: number of survivors and of insertions. */
__kernel void fl_count(__global const uint2 *keep_ins, int n, __global uint *bsum)
{
    int b = get_global_id(0), nb = get_global_size(0), lo, hi;
    fl_block(b, nb, n, &lo, &hi);
    uint k = 0, s = 0;
    for (int i = lo; i < hi; i++) {
        uint2 v = keep_ins[i];
        k += v.x;
        s += v.y;
    }
    bsum[b] = k;
    bsum[nb + b] = s;
}

/* Exclusive scans of both rows; tot = (survivors, insertions, resulting n). */
__kernel void fl_scan_blocks(__global uint *bsum, int nb, uint cap, __global uint *tot)
{
    uint s0 = 0, s1 = 0;
    for (int b = 0; b < nb; b++) {
        uint k = bsum[b], s = bsum[nb + b];
        bsum[b] = s0;
        bsum[nb + b] = s1;
        s0 += k;
        s1 += s;
    }
    tot[0] = s0;
    tot[1] = s1;
    tot[2] = min(cap, s0 + s1);
}

/* fl_compact's moves for one particle: a survivor to slot ko, an insertion to slot o (< nmax). */
inline void fl_compact_one(int i, uint2 v, uint ko, uint o, uint nmax, uint id_new, prm_t P,
                           __global const float4 *nrm, __global const float4 *pos, __global const float4 *vel,
                           __global const uint *flags, __global const uint *id, __global const float2 *rho_p,
                           __global const uint *counts, __global const float4 *force, __global const float2 *dTdF,
                           __global float4 *opos, __global float4 *ovel, __global uint *oflags, __global uint *oid,
                           __global float2 *orho_p, __global uint *ocounts, __global float4 *oforce,
                           __global float2 *odTdF)
{
    if (v.x) {
        opos[ko] = pos[i];
        ovel[ko] = vel[i];
        oflags[ko] = flags[i];
        oid[ko] = id[i];
        orho_p[ko] = rho_p[i];
        ocounts[ko] = counts[i];
        oforce[ko] = force[i];
        odTdF[ko] = dTdF[i];
    }
    if (v.y && o < nmax) {
        float4 p = pos[i];
        p.xyz -= P[FP_DIAM] * nrm[i].xyz;
        p.w = P[FP_TAMB];
        float4 w = vel[i];
        w.w = 0.0f;
        opos[o] = p;
        ovel[o] = w;
        oflags[o] = FL_GAS;
        oid[o] = id_new;
        orho_p[o] = (float2)(0.0f);
        ocounts[o] = 0u;
        oforce[o] = (float4)(0.0f);
        odTdF[o] = (float2)(0.0f);
    }
}

/* Survivors keep their order; inserted particles follow them in parent order (§2.12): at
 * r_i - d n_i (§9 #9), T_amb, F = 0, v_i inherited (§9 #10), ids id_base + rank. Derived
 * fields travel with the survivors and are zero for the inserted. */
__kernel void fl_compact(__global const uint2 *keep_ins, int n, __global const uint *bsum,
                         __global const uint *tot, uint id_base, prm_t P, __global const float4 *nrm,
                         __global const float4 *pos, __global const float4 *vel, __global const uint *flags,
                         __global const uint *id, __global const float2 *rho_p, __global const uint *counts,
                         __global const float4 *force, __global const float2 *dTdF, __global float4 *opos,
                         __global float4 *ovel, __global uint *oflags, __global uint *oid, __global float2 *orho_p,
                         __global uint *ocounts, __global float4 *oforce, __global float2 *odTdF)
{
    int b = get_global_id(0), nb = get_global_size(0), lo, hi;
    fl_block(b, nb, n, &lo, &hi);
    uint ko = bsum[b], so = bsum[nb + b], nk = tot[0], nmax = tot[2];
    for (int i = lo; i < hi; i++) {
        uint2 v = keep_ins[i];
        fl_compact_one(i, v, ko, nk + so, nmax, id_base + so, P, nrm, pos, vel, flags, id, rho_p, counts, force, dTdF,
                       opos, ovel, oflags, oid, orho_p, ocounts, oforce, odTdF);
        ko += v.x;
        so += v.y;
    }
}

/* fl_compact one work item per particle (wide passes): ks and is are the exclusive scans of the
 * keep and insert flags, tot[0] and tot[1] their totals; work item 0 stores the new count,
 * min(cap, survivors + insertions), in tot[2] as fl_scan_blocks does. */
__kernel void fl_compact_wide(__global const uint2 *keep_ins, int n, __global const uint *ks, __global const uint *is,
                              __global uint *tot, uint cap, uint id_base, prm_t P, __global const float4 *nrm,
                              __global const float4 *pos, __global const float4 *vel, __global const uint *flags,
                              __global const uint *id, __global const float2 *rho_p, __global const uint *counts,
                              __global const float4 *force, __global const float2 *dTdF, __global float4 *opos,
                              __global float4 *ovel, __global uint *oflags, __global uint *oid, __global float2 *orho_p,
                              __global uint *ocounts, __global float4 *oforce, __global float2 *odTdF)
{
    int i = get_global_id(0);
    if (i >= n) return;
    uint nk = tot[0], so = is[i], nmax = min(cap, nk + tot[1]);
    if (i == 0) tot[2] = nmax;
    fl_compact_one(i, keep_ins[i], ks[i], nk + so, nmax, id_base + so, P, nrm, pos, vel, flags, id,
                   rho_p, counts, force, dTdF, opos, ovel, oflags, oid, orho_p, ocounts, oforce, odTdF);
}
