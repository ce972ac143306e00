/* fxs_particles_near.c — the particle codec's neighbour searches (fxs_particles_near.h).
 *
 * A candidate's key is its squared distance * 32 + k (k: how many particles back), so the
 * smallest key is the nearest candidate and, on ties, the latest. With SSE2 (all x86-64)
 * and axes of <= 23 bits the keys are exact in doubles (distance < 3 * 2^46, key
 * < 3 * 2^51 < 2^53), so minpd finds the minimum exactly; candidates with other flags get
 * key + inf. Two particles at a time in the lanes (four with AVX2 where the CPU has it),
 * every operation vertical (no shuffles, no blends). Other frames, and the first 8 or 16
 * particles, compare distance, then k, one particle at a time. The three searches share one
 * body, instantiated per search so that each inner loop has constant bounds and no tests. */
#include "fxs_particles_near.h"

#include <math.h>
#include <stddef.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
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

/* Particle j against its first kmax candidates (j - 1 ... j - kmax), one at a time. */
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

/* The k of a key, 0 for none (inf). */
static inline uint32_t fxs_pt_key_k(double key) { return key < INFINITY ? (uint32_t)((int64_t)key & 31) : 0; }

#if defined(FXS_PT_AVX2) && !defined(FXS_PT_SCALAR)
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
        for (uint32_t l = 0; l < 4; l++) {
            o->nbs[j + l] = (int32_t)(j + l - fxs_pt_key_k(kn[l]));
            if (s == FXS_PT_S_SAME) o->sk[j + l] = (uint8_t)fxs_pt_key_k(ks[l]);
            if (s == FXS_PT_S_NEAR4)
                o->near4[j + l] = fxs_pt_key_k(k4[0][l]) | fxs_pt_key_k(k4[1][l]) << 8 | fxs_pt_key_k(k4[2][l]) << 16 |
                                  fxs_pt_key_k(k4[3][l]) << 24;
        }
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

#if defined(__SSE2__) && !defined(FXS_PT_SCALAR)
__attribute__((always_inline)) static inline uint32_t fxs_pt_near_sse2_body(const double *x, const double *y,
                                                                           const double *z, const double *fl,
                                                                           uint32_t j, uint32_t n,
                                                                           const enum fxs_pt_search s,
                                                                           struct fxs_pt_out *o)
{
    const __m128d inf = _mm_set1_pd(INFINITY), k32 = _mm_set1_pd(32.0);
    for (; j + 2 <= n; j += 2) {
        const __m128d cx = _mm_loadu_pd(x + j), cy = _mm_loadu_pd(y + j), cz = _mm_loadu_pd(z + j);
        const __m128d cf = s == FXS_PT_S_SAME ? _mm_loadu_pd(fl + j) : inf;
        __m128d bn = inf, bs = inf, b[4] = { inf, inf, inf, inf };
        double kn[2], ks[2], k4[4][2];
#pragma GCC unroll 16
        for (uint32_t k = 1; k <= FXS_PT_SAME; k++) {
            if (k > FXS_PT_KMAX(s)) break;
            __m128d dx = _mm_sub_pd(cx, _mm_loadu_pd(x + j - k)), dy = _mm_sub_pd(cy, _mm_loadu_pd(y + j - k));
            __m128d dz = _mm_sub_pd(cz, _mm_loadu_pd(z + j - k));
            __m128d d = _mm_add_pd(_mm_add_pd(_mm_mul_pd(dx, dx), _mm_mul_pd(dy, dy)), _mm_mul_pd(dz, dz));
            __m128d key = _mm_add_pd(_mm_mul_pd(d, k32), _mm_set1_pd((double)k));
            if (k <= FXS_PT_NEAR) bn = _mm_min_pd(bn, key);
            if (s == FXS_PT_S_SAME)
                bs = _mm_min_pd(bs, _mm_add_pd(key, _mm_and_pd(_mm_cmpneq_pd(cf, _mm_loadu_pd(fl + j - k)), inf)));
#pragma GCC unroll 4
            for (int r = 0; s == FXS_PT_S_NEAR4 && r < 4; r++) {
                __m128d lo = _mm_min_pd(b[r], key);
                key = _mm_max_pd(b[r], key);
                b[r] = lo;
            }
        }
        _mm_storeu_pd(kn, bn);
        _mm_storeu_pd(ks, bs);
        for (int r = 0; s == FXS_PT_S_NEAR4 && r < 4; r++) _mm_storeu_pd(k4[r], b[r]);
        for (uint32_t l = 0; l < 2; l++) {
            o->nbs[j + l] = (int32_t)(j + l - fxs_pt_key_k(kn[l]));
            if (s == FXS_PT_S_SAME) o->sk[j + l] = (uint8_t)fxs_pt_key_k(ks[l]);
            if (s == FXS_PT_S_NEAR4)
                o->near4[j + l] = fxs_pt_key_k(k4[0][l]) | fxs_pt_key_k(k4[1][l]) << 8 | fxs_pt_key_k(k4[2][l]) << 16 |
                                  fxs_pt_key_k(k4[3][l]) << 24;
        }
    }
    return j;
}

static uint32_t fxs_pt_near_sse2(const double *x, const double *y, const double *z, const double *fl, uint32_t j,
                                 uint32_t n, enum fxs_pt_search s, struct fxs_pt_out *o)
{
    if (s == FXS_PT_S_NEAR) return fxs_pt_near_sse2_body(x, y, z, fl, j, n, FXS_PT_S_NEAR, o);
    if (s == FXS_PT_S_SAME) return fxs_pt_near_sse2_body(x, y, z, fl, j, n, FXS_PT_S_SAME, o);
    return fxs_pt_near_sse2_body(x, y, z, fl, j, n, FXS_PT_S_NEAR4, o);
}
#endif

static void fxs_pt_search(uint32_t n, int keys_exact, const double *x, const double *y, const double *z,
                          const double *fl, enum fxs_pt_search s, struct fxs_pt_out *o)
{
    uint32_t kmax = FXS_PT_KMAX(s), j = 0;
    for (; j < n && j < kmax; j++) fxs_pt_near_one(x, y, z, fl, j, j, s, o);
#if defined(__SSE2__) && !defined(FXS_PT_SCALAR)
    if (keys_exact) {
#if defined(FXS_PT_AVX2)
        if (__builtin_cpu_supports("avx2")) j = fxs_pt_near_avx2(x, y, z, fl, j, n, s, o);
#endif
        j = fxs_pt_near_sse2(x, y, z, fl, j, n, s, o);
    }
#else
    (void)keys_exact;
#endif
    for (; j < n; j++) fxs_pt_near_one(x, y, z, fl, j, kmax, s, o);
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
