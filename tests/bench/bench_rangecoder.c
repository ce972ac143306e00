/* bench_rangecoder.c — how much the particle codec's range decoder (protocol/fxs_rangecoder.h)
 * gains from independent decision chains decoded in one loop.
 *
 * The question behind a format with interleaved entropy streams: does the CPU overlap
 * independent decoders? Four streams of 8-bit values are coded as adaptive value trees (as
 * the codec codes T and F: probabilities in memory, 8 decisions a value; values drawn like a
 * flame's temperatures, 9 in 10 from a band of 8, the rest anywhere: ~4 bits a value), then decoded by 1, 2
 * and 4 decoders in one loop, each with its own models, taking a value from each in turn.
 * Prints ns per decision for each, best of RUNS (docs/particle-codec-performance.md has the
 * figures and what they mean for the format). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fxs_rangecoder.h"

#define LANES 4
#define VALUES 20000 /* per stream: a decode of all takes ~3 ms, so the best of RUNS misses preemption */
#define RUNS 41

static double br_now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

/* The streams: values, their coded bytes (each followed by FXS_RC_PAD zeros) and models. */
static uint8_t br_vals[LANES][VALUES];
static uint8_t *br_code[LANES];
static size_t br_len[LANES];
static fxs_rc_prob br_p[LANES][256];
static const uint8_t br_nobits[FXS_RC_PAD];

static int br_encode(void)
{
    uint64_t rng = 88172645463325252ull;
    for (int l = 0; l < LANES; l++) {
        struct fxs_rc_buf rb = { 0 }, bb = { 0 };
        struct fxs_rc_enc w;
        fxs_rc_enc_init(&w);
        if (!(w.rp = fxs_rc_grow(&rb, NULL, VALUES)) || !(w.bp = fxs_rc_grow(&bb, NULL, 64))) return -1;
        for (int i = 0; i < 256; i++) br_p[l][i] = FXS_RC_PROB_INIT;
        for (int i = 0; i < VALUES; i++) {
            rng ^= rng << 13, rng ^= rng >> 7, rng ^= rng << 17;
            br_vals[l][i] = (uint8_t)(rng % 100 < 90 ? 96 + (rng >> 8) % 8 : (rng >> 16) & 255);
            if (fxs_rc_room(&rb, &bb, &w)) return -1;
            fxs_rc_put_tree(&w, br_p[l], br_vals[l][i], 8);
        }
        if (fxs_rc_room(&rb, &bb, &w)) return -1;
        fxs_rc_enc_flush(&w);
        br_len[l] = (size_t)(w.rp - rb.p);
        if (!(br_code[l] = calloc(br_len[l] + FXS_RC_PAD, 1))) return -1;
        memcpy(br_code[l], rb.p, br_len[l]);
        free(rb.p);
        free(bb.p);
    }
    return 0;
}

/* Decodes every stream with k decoders in one loop (k = 1: one stream after another);
 * seconds, or -1 when a value comes out wrong. */
static double br_decode(int k)
{
    struct fxs_rc_dec d[LANES];
    uint32_t bad = 0;
    double t0 = br_now();
    for (int first = 0; first < LANES; first += k) {
        for (int l = first; l < first + k; l++) {
            for (int i = 0; i < 256; i++) br_p[l][i] = FXS_RC_PROB_INIT;
            fxs_rc_dec_init(&d[l], br_code[l], br_len[l], br_nobits);
        }
        if (k == 1)
            for (int i = 0; i < VALUES; i++) bad |= fxs_rc_get_tree(&d[first], br_p[first], 8) ^ br_vals[first][i];
        else if (k == 2)
            for (int i = 0; i < VALUES; i++) {
                bad |= fxs_rc_get_tree(&d[first], br_p[first], 8) ^ br_vals[first][i];
                bad |= fxs_rc_get_tree(&d[first + 1], br_p[first + 1], 8) ^ br_vals[first + 1][i];
            }
        else
            for (int i = 0; i < VALUES; i++) {
                bad |= fxs_rc_get_tree(&d[0], br_p[0], 8) ^ br_vals[0][i];
                bad |= fxs_rc_get_tree(&d[1], br_p[1], 8) ^ br_vals[1][i];
                bad |= fxs_rc_get_tree(&d[2], br_p[2], 8) ^ br_vals[2][i];
                bad |= fxs_rc_get_tree(&d[3], br_p[3], 8) ^ br_vals[3][i];
            }
    }
    return bad ? -1 : br_now() - t0;
}

int main(void)
{
    static const int ks[] = { 1, 2, 4 };
    if (br_encode()) {
        printf("bench_rangecoder: out of memory\n");
        return 1;
    }
    printf("bench_rangecoder: %d streams of %d 8-bit values as adaptive value trees (%.2f bits a value)\n", LANES,
           VALUES, 8.0 * (double)(br_len[0] + br_len[1] + br_len[2] + br_len[3]) / (LANES * (double)VALUES));
    for (int i = 0; i < 3; i++) {
        double best = 1e9;
        for (int r = 0; r < RUNS; r++) {
            double t = br_decode(ks[i]);
            if (t < 0) {
                printf("range decoder, %d in one loop: decoded values differ from the coded ones\n", ks[i]);
                return 1;
            }
            if (t < best) best = t;
        }
        printf("range decoder, %d independent decoder%s in one loop: %.2f ns a decision\n", ks[i], ks[i] > 1 ? "s" : "",
               best * 1e9 / (8.0 * LANES * VALUES));
    }
    for (int l = 0; l < LANES; l++) free(br_code[l]);
    return 0;
}
