/* fxs_particles_near.c — the particle codec's neighbour searches (fxs_particles_near.h).
 *
 * A candidate's key is its squared distance * 32 + k (k: how many particles back), so the
 * smallest key is the nearest candidate and, on ties, the latest. With axes of <= 23 bits
 * the keys are exact in doubles (distance < 3 * 2^46, key < 3 * 2^51 < 2^53), so minima of
 * keys find the nearest exactly and without a branch; candidates with other flags get
 * key + inf, and the 4 nearest are kept sorted by a min/max exchange per candidate. The
 * vector paths take two particles at a time in the lanes (SSE2 on x86-64, SIMD128 in
 * WebAssembly: one body, written with the V2 operations below; four with AVX2 where the CPU
 * has it), every operation vertical (no shuffles, no blends); the remaining particles take
 * the same keys one at a time. Frames with a 24-bit axis, and the first 8 or 16 particles,
 * compare distance, then k. The bodies are instantiated per search so that each inner loop
 * has constant bounds and no tests. */
#include "fxs_particles_near.h"

#include <math.h>
#include <stddef.h>
#if defined(__SSE2__) && !defined(FXS_PT_SCALAR)
#include <emmintrin.h>
#define FXS_PT_V2 1
typedef __m128d fxs_pt_v2;
#define V2_SPLAT(a) _mm_set1_pd(a)
#define V2_LOAD(p) _mm_loadu_pd(p)
#define V2_STORE(p, v) _mm_storeu_pd(p, v)
#define V2_ADD(a, b) _mm_add_pd(a, b)
#define V2_SUB(a, b) _mm_sub_pd(a, b)
#define V2_MUL(a, b) _mm_mul_pd(a, b)
#define V2_MIN(a, b) _mm_min_pd(a, b)
#define V2_MAX(a, b) _mm_max_pd(a, b)
#define V2_NE_INF(a, b, inf) _mm_and_pd(_mm_cmpneq_pd(a, b), inf) /* inf where a != b, else 0 */
#elif defined(__wasm_simd128__) && !defined(FXS_PT_SCALAR)
#include <wasm_simd128.h>
#define FXS_PT_V2 1
typedef v128_t fxs_pt_v2;
#define V2_SPLAT(a) wasm_f64x2_splat(a)
#define V2_LOAD(p) wasm_v128_load(p)
#define V2_STORE(p, v) wasm_v128_store(p, v)
#define V2_ADD(a, b) wasm_f64x2_add(a, b)
#define V2_SUB(a, b) wasm_f64x2_sub(a, b)
#define V2_MUL(a, b) wasm_f64x2_mul(a, b)
#define V2_MIN(a, b) wasm_f64x2_pmin(a, b) /* b < a ? b : a: minpd, where min would also order NaNs and zeros */
#define V2_MAX(a, b) wasm_f64x2_pmax(a, b)
#define V2_NE_INF(a, b, inf) wasm_v128_and(wasm_f64x2_ne(a, b), inf)
#endif
#if defined(__x86_64__) && defined(__GNUC__) && !defined(FXS_PT_SCALAR)
#include <immintrin.h>
#define FXS_PT_AVX2 1
#endif

#include "fxs_particles_format.h"

enum fxs_pt_search { FXS_PT_S_NEAR, FXS_PT_S_SAME, FXS_PT_S_NEAR4 };
#define FXS_PT_KMAX(s) ((s) == FXS_PT_S_NEAR ? FXS_PT_NEAR : FXS_PT_SAME)

struct fxs_pt_out {
    int32_t *nbs;
    uint8_t *sk;
    uint32_t *near4;
};

/* The k of a key, 0 for none (inf). */
static inline uint32_t fxs_pt_key_k(double key) { return key < INFINITY ? (uint32_t)((int64_t)key & 31) : 0; }

/* The results of particle j from its minima of keys: bn (nearest of 8), bs (same flags),
 * b4 (the 4 nearest). */
static inline void fxs_pt_put(struct fxs_pt_out *o, enum fxs_pt_search s, uint32_t j, double bn, double bs,
                              const double *b4)
{
    o->nbs[j] = (int32_t)(j - fxs_pt_key_k(bn));
    if (s == FXS_PT_S_SAME) o->sk[j] = (uint8_t)fxs_pt_key_k(bs);
    if (s == FXS_PT_S_NEAR4)
        o->near4[j] = fxs_pt_key_k(b4[0]) | fxs_pt_key_k(b4[1]) << 8 | fxs_pt_key_k(b4[2]) << 16 | fxs_pt_key_k(b4[3]) << 24;
}

/* Particle j against its first kmax candidates, distance then k, one at a time: for the
 * first particles and for frames whose keys are not exact. */
static void fxs_pt_near_one(const double *x, const double *y, const double *z, const double *fl, uint32_t j,
                            uint32_t kmax, enum fxs_pt_search s, struct fxs_pt_out *o)
{
    double bn = INFINITY, bs = INFINITY, bd[4] = { INFINITY, INFINITY, INFINITY, INFINITY };
    uint32_t kn = 0, ks = 0, k4[4] = { 0, 0, 0, 0 };
    for (uint32_t k = 1; k <= kmax; k++) {
        double dx = x[j] - x[j - k], dy = y[j] - y[j - k], dz = z[j] - z[j - k], d = dx * dx + dy * dy + dz * dz;
        if (k <= FXS_PT_NEAR && d < bn) bn = d, kn = k;
        if (s == FXS_PT_S_SAME && fl[j - k] == fl[j] && d < bs) bs = d, ks = k;
        for (int r = 0; s == FXS_PT_S_NEAR4 && r < 4; r++)
            if (d < bd[r]) { /* insert, the later ones one place down */
                for (int t = 3; t > r; t--) bd[t] = bd[t - 1], k4[t] = k4[t - 1];
                bd[r] = d, k4[r] = k;
                break;
            }
    }
    o->nbs[j] = kn ? (int32_t)(j - kn) : -1;
    if (s == FXS_PT_S_SAME) o->sk[j] = (uint8_t)ks;
    if (s == FXS_PT_S_NEAR4) o->near4[j] = k4[0] | k4[1] << 8 | k4[2] << 16 | k4[3] << 24;
}

/* The smaller and the larger of two keys as selects (fmin would be a library call where
 * NaNs matter). */
static inline double fxs_pt_min(double a, double b) { return b < a ? b : a; }
static inline double fxs_pt_max(double a, double b) { return b < a ? a : b; }

/* Particles j ... n - 1 with exact keys, one at a time without a branch. */
__attribute__((always_inline)) static inline void fxs_pt_near_keys_body(const double *x, const double *y,
                                                                       const double *z, const double *fl, uint32_t j,
                                                                       uint32_t n, const enum fxs_pt_search s,
                                                                       struct fxs_pt_out *o)
{
    for (; j < n; j++) {
        double bn = INFINITY, bs = INFINITY, b4[4] = { INFINITY, INFINITY, INFINITY, INFINITY };
#pragma GCC unroll 16
        for (uint32_t k = 1; k <= FXS_PT_SAME; k++) {
            if (k > FXS_PT_KMAX(s)) break;
            double key = fxs_pt_near_key(x, y, z, j, k);
            if (k <= FXS_PT_NEAR) bn = fxs_pt_min(bn, key);
            if (s == FXS_PT_S_SAME) bs = fxs_pt_min(bs, fl[j - k] == fl[j] ? key : INFINITY);
#pragma GCC unroll 4
            for (int r = 0; s == FXS_PT_S_NEAR4 && r < 4; r++) { /* insert into the sorted four */
                double lo = fxs_pt_min(b4[r], key);
                key = fxs_pt_max(b4[r], key);
                b4[r] = lo;
            }
        }
        fxs_pt_put(o, s, j, bn, bs, b4);
    }
}

#if defined(FXS_PT_AVX2)
__attribute__((target("avx2"), always_inline)) static inline uint32_t
fxs_pt_near_avx2_body(const double *x, const double *y, const double *z, const double *fl, uint32_t j, uint32_t n,
                      const enum fxs_pt_search s, struct fxs_pt_out *o)
{
    const __m256d inf = _mm256_set1_pd(INFINITY), k32 = _mm256_set1_pd(32.0);
    for (; j + 4 <= n; j += 4) {
        const __m256d cx = _mm256_loadu_pd(x + j), cy = _mm256_loadu_pd(y + j), cz = _mm256_loadu_pd(z + j);
        const __m256d cf = s == FXS_PT_S_SAME ? _mm256_loadu_pd(fl + j) : inf;
        __m256d bn = inf, bs = inf, b[4] = { inf, inf, inf, inf };
        double kn[4], ks[4], k4[4][4];
#pragma GCC unroll 16
        for (uint32_t k = 1; k <= FXS_PT_SAME; k++) {
            if (k > FXS_PT_KMAX(s)) break;
            __m256d dx = _mm256_sub_pd(cx, _mm256_loadu_pd(x + j - k));
            __m256d dy = _mm256_sub_pd(cy, _mm256_loadu_pd(y + j - k));
            __m256d dz = _mm256_sub_pd(cz, _mm256_loadu_pd(z + j - k));
            __m256d d = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)), _mm256_mul_pd(dz, dz));
            __m256d key = _mm256_add_pd(_mm256_mul_pd(d, k32), _mm256_set1_pd((double)k));
            if (k <= FXS_PT_NEAR) bn = _mm256_min_pd(bn, key);
            if (s == FXS_PT_S_SAME) {
                __m256d other = _mm256_and_pd(_mm256_cmp_pd(cf, _mm256_loadu_pd(fl + j - k), _CMP_NEQ_UQ), inf);
                bs = _mm256_min_pd(bs, _mm256_add_pd(key, other));
            }
#pragma GCC unroll 4
            for (int r = 0; s == FXS_PT_S_NEAR4 && r < 4; r++) { /* insert into the sorted four */
                __m256d lo = _mm256_min_pd(b[r], key);
                key = _mm256_max_pd(b[r], key);
                b[r] = lo;
            }
        }
        _mm256_storeu_pd(kn, bn);
        _mm256_storeu_pd(ks, bs);
        for (int r = 0; s == FXS_PT_S_NEAR4 && r < 4; r++) _mm256_storeu_pd(k4[r], b[r]);
        for (uint32_t l = 0; l < 4; l++)
            fxs_pt_put(o, s, j + l, kn[l], ks[l], (double[4]){ k4[0][l], k4[1][l], k4[2][l], k4[3][l] });
    }
    return j;
}

__attribute__((target("avx2"))) static uint32_t fxs_pt_near_avx2(const double *x, const double *y, const double *z,
                                                                const double *fl, uint32_t j, uint32_t n,
                                                                enum fxs_pt_search s, struct fxs_pt_out *o)
{
    if (s == FXS_PT_S_NEAR) return fxs_pt_near_avx2_body(x, y, z, fl, j, n, FXS_PT_S_NEAR, o);
    if (s == FXS_PT_S_SAME) return fxs_pt_near_avx2_body(x, y, z, fl, j, n, FXS_PT_S_SAME, o);
    return fxs_pt_near_avx2_body(x, y, z, fl, j, n, FXS_PT_S_NEAR4, o);
}
#endif

#if defined(FXS_PT_V2)
__attribute__((always_inline)) static inline uint32_t fxs_pt_near_v2_body(const double *x, const double *y,
                                                                         const double *z, const double *fl,
                                                                         uint32_t j, uint32_t n,
                                                                         const enum fxs_pt_search s,
                                                                         struct fxs_pt_out *o)
{
    const fxs_pt_v2 inf = V2_SPLAT(INFINITY), k32 = V2_SPLAT(32.0);
    for (; j + 2 <= n; j += 2) {
        const fxs_pt_v2 cx = V2_LOAD(x + j), cy = V2_LOAD(y + j), cz = V2_LOAD(z + j);
        const fxs_pt_v2 cf = s == FXS_PT_S_SAME ? V2_LOAD(fl + j) : inf;
        fxs_pt_v2 bn = inf, bs = inf, b[4] = { inf, inf, inf, inf };
        double kn[2], ks[2], k4[4][2];
#pragma GCC unroll 16
        for (uint32_t k = 1; k <= FXS_PT_SAME; k++) {
            if (k > FXS_PT_KMAX(s)) break;
            fxs_pt_v2 dx = V2_SUB(cx, V2_LOAD(x + j - k)), dy = V2_SUB(cy, V2_LOAD(y + j - k));
            fxs_pt_v2 dz = V2_SUB(cz, V2_LOAD(z + j - k));
            fxs_pt_v2 d = V2_ADD(V2_ADD(V2_MUL(dx, dx), V2_MUL(dy, dy)), V2_MUL(dz, dz));
            fxs_pt_v2 key = V2_ADD(V2_MUL(d, k32), V2_SPLAT((double)k));
            if (k <= FXS_PT_NEAR) bn = V2_MIN(bn, key);
            if (s == FXS_PT_S_SAME) bs = V2_MIN(bs, V2_ADD(key, V2_NE_INF(cf, V2_LOAD(fl + j - k), inf)));
#pragma GCC unroll 4
            for (int r = 0; s == FXS_PT_S_NEAR4 && r < 4; r++) {
                fxs_pt_v2 lo = V2_MIN(b[r], key);
                key = V2_MAX(b[r], key);
                b[r] = lo;
            }
        }
        V2_STORE(kn, bn);
        V2_STORE(ks, bs);
        for (int r = 0; s == FXS_PT_S_NEAR4 && r < 4; r++) V2_STORE(k4[r], b[r]);
        for (uint32_t l = 0; l < 2; l++)
            fxs_pt_put(o, s, j + l, kn[l], ks[l], (double[4]){ k4[0][l], k4[1][l], k4[2][l], k4[3][l] });
    }
    return j;
}
#endif

/* Particles j ... n - 1 with exact keys on the widest path this build and CPU have. */
__attribute__((always_inline)) static inline void fxs_pt_near_fast(const double *x, const double *y, const double *z,
                                                                  const double *fl, uint32_t j, uint32_t n,
                                                                  const enum fxs_pt_search s, struct fxs_pt_out *o)
{
#if defined(FXS_PT_AVX2)
    if (__builtin_cpu_supports("avx2")) j = fxs_pt_near_avx2(x, y, z, fl, j, n, s, o);
#endif
#if defined(FXS_PT_V2)
    j = fxs_pt_near_v2_body(x, y, z, fl, j, n, s, o);
#endif
    fxs_pt_near_keys_body(x, y, z, fl, j, n, s, o);
}

static void fxs_pt_search(uint32_t n, int keys_exact, const double *x, const double *y, const double *z,
                          const double *fl, enum fxs_pt_search s, struct fxs_pt_out *o)
{
    uint32_t kmax = FXS_PT_KMAX(s), j = 0;
    for (; j < n && j < kmax; j++) fxs_pt_near_one(x, y, z, fl, j, j, s, o);
    if (!keys_exact)
        for (; j < n; j++) fxs_pt_near_one(x, y, z, fl, j, kmax, s, o);
    else if (s == FXS_PT_S_NEAR)
        fxs_pt_near_fast(x, y, z, fl, j, n, FXS_PT_S_NEAR, o);
    else if (s == FXS_PT_S_SAME)
        fxs_pt_near_fast(x, y, z, fl, j, n, FXS_PT_S_SAME, o);
    else
        fxs_pt_near_fast(x, y, z, fl, j, n, FXS_PT_S_NEAR4, o);
}

void fxs_pt_near(uint32_t n, int keys_exact, const double *x, const double *y, const double *z, int32_t *nbs)
{
    struct fxs_pt_out o = { nbs, NULL, NULL };
    fxs_pt_search(n, keys_exact, x, y, z, NULL, FXS_PT_S_NEAR, &o);
}

void fxs_pt_near_same(uint32_t n, int keys_exact, const double *x, const double *y, const double *z, const double *fl,
                      int32_t *nbs, uint8_t *sk)
{
    struct fxs_pt_out o = { nbs, sk, NULL };
    fxs_pt_search(n, keys_exact, x, y, z, fl, FXS_PT_S_SAME, &o);
}

void fxs_pt_near4(uint32_t n, int keys_exact, const double *x, const double *y, const double *z, int32_t *nbs,
                  uint32_t *near4)
{
    struct fxs_pt_out o = { nbs, NULL, near4 };
    fxs_pt_search(n, keys_exact, x, y, z, NULL, FXS_PT_S_NEAR4, &o);
}
