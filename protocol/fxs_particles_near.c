/* fxs_particles_near.c — the particle codec's neighbour search (fxs_particles_near.h).
 *
 * A candidate's key is its squared distance * 32 + k (k: how many particles back), so the
 * smallest key is the nearest candidate and, on ties, the latest. With SSE2 (all x86-64)
 * and axes of <= 23 bits the keys are exact in doubles (distance < 3 * 2^46, key
 * < 3 * 2^51 < 2^53), so minpd finds the same minimum as 64-bit integer keys; candidates
 * with other flags get key + inf. Two particles at a time in the lanes (four with AVX2
 * where the CPU has it), x, y, z and flags converted to doubles once, every operation
 * vertical (no shuffles, no blends). Other frames, and the first 16 particles, take the
 * 64-bit integer keys one particle at a time. */
#include "fxs_particles_near.h"

#include <math.h>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define FXS_PT_AVX2 1
#endif

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

void fxs_pt_neighbours(const struct fxs_pt_frame *f, const uint32_t *q, const uint8_t *fl, int32_t *nbs, uint8_t *sk,
                       double *pd)
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

