/* exr_rle.c — OpenEXR's RLE compression of one chunk, the codec of every texture stream by
 * default (`compression` "rle"); exr.c installs it as the encode pipeline's compress_fn.
 *
 * The format (OpenEXR's RLE, as OpenEXRCore 3.1 writes it): the packed bytes split into the
 * even ones then the odd ones, each byte but the first replaced by its difference to the one
 * before plus 128 (mod 256), then tokens: a run of 3 to 128 equal bytes as (length - 1, byte), or
 * a literal of 1 to 127 bytes as (-length, bytes), a literal ending where 3 equal bytes begin.
 * OpenEXRCore does each step a byte at a time; here the split and differences take 16 bytes at
 * a time (SSE2) and runs and literals are found 8 at a time, with the same bytes out
 * (tests/unit/test_exr.c holds it to a plain reference). */
#include "exr_rle.h"

#include <string.h>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#define EXR_RLE_MAX 127 /* the longest literal, and the longest run less one */

static inline uint64_t exr_rle_load(const uint8_t *p)
{
    uint64_t v;
    memcpy(&v, p, sizeof v);
    return v;
}

/* Index of the first zero byte of v (little-endian order), 8 when none: the lowest byte the
 * borrow trick flags is always a true zero. */
static inline int exr_rle_first_zero(uint64_t v)
{
    uint64_t z = (v - 0x0101010101010101ull) & ~v & 0x8080808080808080ull;
    return z ? __builtin_ctzll(z) >> 3 : 8;
}

#if defined(__SSE2__)
/* The even bytes of the 32 at p. */
static inline __m128i exr_rle_evens(const uint8_t *p)
{
    const __m128i lo = _mm_set1_epi16(0x00ff);
    __m128i a = _mm_loadu_si128((const __m128i *)p), b = _mm_loadu_si128((const __m128i *)(p + 16));
    return _mm_packus_epi16(_mm_and_si128(a, lo), _mm_and_si128(b, lo));
}

/* t[i] = s[2i] - s[2i - 2] + 128 for i in [i, m) with 2i + 32 <= end, 16 at a time; the next i. */
static size_t exr_rle_diffs(const uint8_t *s, size_t i, size_t m, size_t end, uint8_t *t)
{
    const __m128i bias = _mm_set1_epi8((char)0x80);
    for (; i + 16 <= m && 2 * i + 32 <= end; i += 16)
        _mm_storeu_si128((__m128i *)(t + i),
                         _mm_add_epi8(_mm_sub_epi8(exr_rle_evens(s + 2 * i), exr_rle_evens(s + 2 * i - 2)), bias));
    return i;
}
#else
static size_t exr_rle_diffs(const uint8_t *s, size_t i, size_t m, size_t end, uint8_t *t)
{
    (void)s, (void)m, (void)end, (void)t;
    return i;
}
#endif

/* The split and differences of src[0..n) into t: the even bytes' from 16 at a time where the
 * CPU has SSE2, then the odd bytes' (the even bytes of src + 1). */
static void exr_rle_predict(const uint8_t *src, size_t n, uint8_t *t)
{
    size_t h = (n + 1) / 2, odd = n / 2;
    t[0] = src[0];
    for (size_t i = exr_rle_diffs(src, 1, h, n, t); i < h; i++) t[i] = (uint8_t)(src[2 * i] - src[2 * i - 2] + 128);
    if (odd) t[h] = (uint8_t)(src[1] - src[2 * h - 2] + 128);
    for (size_t i = exr_rle_diffs(src + 1, 1, odd, n - 1, t + h); i < odd; i++)
        t[h + i] = (uint8_t)(src[2 * i + 1] - src[2 * i - 1] + 128);
}

/* How many bytes after t[at] equal it, at most EXR_RLE_MAX. */
static size_t exr_rle_run(const uint8_t *t, size_t at, size_t n)
{
    size_t end = n - at - 1 < EXR_RLE_MAX ? n - at - 1 : EXR_RLE_MAX, c = 0;
    const uint64_t b = 0x0101010101010101ull * t[at];
    for (; c + 8 <= end; c += 8) {
        uint64_t x = exr_rle_load(t + at + 1 + c) ^ b;
        if (x) return c + (size_t)(__builtin_ctzll(x) >> 3);
    }
    while (c < end && t[at + 1 + c] == t[at]) c++;
    return c;
}

/* The first r' >= r where three equal bytes begin, or limit when none does before it. */
static size_t exr_rle_literal_end(const uint8_t *t, size_t r, size_t n, size_t limit)
{
    for (; r < limit && r + 10 <= n; r += 8) {
        uint64_t x = exr_rle_load(t + r), y = exr_rle_load(t + r + 1), z = exr_rle_load(t + r + 2);
        int k = exr_rle_first_zero((x ^ y) | (y ^ z));
        if (k < 8) return r + (size_t)k < limit ? r + (size_t)k : limit;
    }
    while (r < limit && !(r + 2 < n && t[r] == t[r + 1] && t[r + 1] == t[r + 2])) r++;
    return r < limit ? r : limit;
}

size_t exr_rle_compress(const uint8_t *src, size_t n, uint8_t *scratch, uint8_t *out)
{
    size_t at = 0, o = 0;
    if (!n) return 0;
    exr_rle_predict(src, n, scratch);
    while (at < n && o < n) {
        size_t c = exr_rle_run(scratch, at, n);
        if (c >= 2) {
            out[o++] = (uint8_t)c;
            out[o++] = scratch[at];
            at += c + 1;
        } else {
            size_t limit = n - at < EXR_RLE_MAX ? n : at + EXR_RLE_MAX;
            size_t end = exr_rle_literal_end(scratch, at + c + 1, n, limit);
            out[o++] = (uint8_t)-(int)(end - at);
            memcpy(out + o, scratch + at, end - at);
            o += end - at;
            at = end;
        }
    }
    if (o < n) return o;
    memcpy(out, src, n);
    return n;
}
