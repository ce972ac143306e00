/* test_particles.c — the kind 1 particle codec 2 (protocol/fxs_particles_*.c, PROTOCOL.md §7.5).
 *
 * Round trips of random, SPH-like and real flame sets (n = 0, 1, 2, 1e6, all particles
 * identical, degenerate and extreme bounds, every pos_bits 8..24, every T/F width) checked
 * particle by particle against the order the spec prescribes (Morton order, ties in
 * input order), within the documented quantisation bounds; the optional velocities
 * (§7.5.7: every vel_bits 2..16 within half a step, empty frames, all-zero and extreme
 * magnitudes, the other attributes unchanged by them, off = no velocity block); corrupt,
 * truncated and codec 1 payloads are rejected without reading out of bounds (build with
 * -fsanitize=address,undefined or run under valgrind too).
 * Test vectors: tests/data/particles/NAME.bin with NAME.json (what decoding gives) are
 * checked here and by the JavaScript decoder; `test_particles --write-vectors`
 * regenerates them after a deliberate format change. FXS_TEST_QUICK=1 skips the 1e6 set. */
#include <float.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "fxs_particles.h"
#include "particles_gen.h"

#define VEC_DIR "tests/data/particles"

static void free_set(struct fxs_particles *p) { fxs_particles_free(p); }

/* ---- the order of the spec ------------------------------------------------------------ */

static float getf(const uint8_t *b)
{
    float f;
    uint32_t v = (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
    memcpy(&f, &v, 4);
    return f;
}

/* Position step of a payload: largest extent / (2^B - 1), one for all axes. */
static double pos_step(const uint8_t *enc)
{
    double r = 0;
    for (int a = 0; a < 3; a++) r = fmax(r, (double)getf(enc + 28 + 4 * a) - (double)getf(enc + 16 + 4 * a));
    return r / (double)((1u << enc[5]) - 1u);
}

static uint32_t quant_pos(float v, float lo, double step, int bits)
{
    uint32_t qmax = (1u << bits) - 1u;
    double s = step > 0 ? 1.0 / step : 0, q = ((double)v - lo) * s + 0.5;
    uint32_t u = q <= 0 ? 0 : (uint32_t)q;
    return u > qmax ? qmax : u;
}

struct ord128 {
    unsigned __int128 key;
    uint32_t i;
};
static int ord128_cmp(const void *a, const void *b)
{
    const struct ord128 *x = a, *y = b;
    return x->key < y->key ? -1 : x->key > y->key ? 1 : (x->i > y->i) - (x->i < y->i);
}

/* Input index of each decoded particle: by Morton key (at each bit from the top, x
 * above y above z), ties in input order. */
static uint32_t *spec_order(const struct fxs_particles *p, const uint8_t *enc)
{
    int b = enc[5];
    double step = pos_step(enc);
    struct ord128 *o = malloc((p->n ? p->n : 1) * sizeof *o);
    uint32_t *idx = malloc((p->n ? p->n : 1) * sizeof *idx);
    for (uint32_t i = 0; i < p->n && o; i++) {
        uint32_t q[3];
        for (int a = 0; a < 3; a++) q[a] = quant_pos(p->xyz[3 * i + a], getf(enc + 16 + 4 * a), step, b);
        o[i].key = 0;
        for (int bit = 23; bit >= 0; bit--)
            for (int a = 0; a < 3; a++) o[i].key = o[i].key << 1 | ((q[a] >> bit) & 1u);
        o[i].i = i;
    }
    if (o) qsort(o, p->n, sizeof *o, ord128_cmp);
    for (uint32_t j = 0; j < p->n && o && idx; j++) idx[j] = o[j].i;
    free(o);
    return idx;
}

/* 600 particles of a real flame frame (fxctl subscribe flame --out, the first 600 in the
 * file), the input of the real_flame600 vectors. */
#define REAL_PLY VEC_DIR "/real_flame600.ply"
/* 600 particles of a real flame frame with velocities (fxctl subscribe flame --out with the
 * stream's velocities on), the input of the real_vel600 vector. */
#define REAL_VEL_PLY VEC_DIR "/real_vel600.ply"

/* ---- round trips ------------------------------------------------------------------------ */

static double tol(float lo, float hi, int bits)
{
    double step = ((double)hi - lo) / ((1u << bits) - 1u), mag = fmax(fabs(lo), fabs(hi));
    return step / 2 * (1 + 1e-9) + mag * FLT_EPSILON;
}

/* Velocity bound of axis a of a payload with velocities: half a step (largest |v| of the
 * axis / (2^(vel_bits-1) - 1)) plus float32 rounding. */
static double vel_tol(const uint8_t *enc, int a)
{
    double vmax = getf(enc + 64 + 4 + 4 * a);
    return vmax / ((1u << (enc[64] - 1)) - 1u) / 2 * (1 + 1e-9) + vmax * FLT_EPSILON;
}

/* Counts particles whose velocity is outside the bounds (in: input order, out: decoded). */
static int compare_vel(const struct fxs_particles *in, const struct fxs_particles *out, const uint8_t *enc,
                       const uint32_t *idx)
{
    int bad = 0;
    if (!in->vel || !out->vel) return in->vel || out->vel ? (int)in->n + 1 : 0;
    if (!(enc[11] & 0x10)) return (int)in->n + 1;
    for (uint32_t j = 0; j < in->n; j++)
        for (int a = 0; a < 3; a++) {
            double e = (double)in->vel[3 * idx[j] + a] - out->vel[3 * j + a];
            if (fabs(e) <= vel_tol(enc, a)) continue;
            if (bad++ < 3) fprintf(stderr, "  particle %u (input %u): velocity %d error %g\n", j, idx[j], a, e);
        }
    return bad;
}

/* Counts particles outside the bounds; prints the first few. */
static int compare(const struct fxs_particles *in, const struct fxs_particles *out, const uint8_t *enc)
{
    uint32_t *idx = spec_order(in, enc);
    int bad = 0, bits[5] = { enc[5], enc[5], enc[5], enc[6], enc[7] };
    double t[5];
    for (int c = 0; c < 5; c++) t[c] = tol(getf(enc + (c < 3 ? 16 + 4 * c : 40 + 8 * (c - 3))), getf(enc + (c < 3 ? 28 + 4 * c : 44 + 8 * (c - 3))), bits[c]);
    for (int c = 0; c < 3; c++) /* one step for all axes */
        t[c] = pos_step(enc) / 2 * (1 + 1e-9) + fmax(fabs(getf(enc + 16 + 4 * c)), fabs(getf(enc + 28 + 4 * c))) * FLT_EPSILON;
    for (uint32_t j = 0; j < in->n && idx; j++) {
        uint32_t i = idx[j];
        double e[5] = { in->xyz[3 * i] - out->xyz[3 * j], in->xyz[3 * i + 1] - out->xyz[3 * j + 1],
                        in->xyz[3 * i + 2] - out->xyz[3 * j + 2], in->temp[i] - out->temp[j], in->fuel[i] - out->fuel[j] };
        int ok = in->flags[i] == out->flags[j];
        for (int c = 0; c < 5; c++) ok = ok && fabs(e[c]) <= t[c];
        if (!ok && bad++ < 3)
            fprintf(stderr, "  particle %u (input %u): errors %g %g %g T %g F %g flags %u/%u\n", j, i, e[0], e[1], e[2],
                    e[3], e[4], in->flags[i], out->flags[j]);
    }
    if (idx) bad += compare_vel(in, out, enc, idx);
    free(idx);
    return idx ? bad : -1;
}

/* Encodes with o, decodes and compares; returns the payload size or -1. */
static long round_trip_opts(const struct fxs_particles *in, const struct fxs_particles_opts *o)
{
    struct fxs_particles out;
    uint8_t *enc = NULL;
    size_t len = 0;
    char err[200] = "";
    long r = -1;
    int bad;
    CHECK(fxs_particles_encode(in, o, &enc, &len, err, sizeof err) == 0, "encode: %s", err);
    if (!enc) return -1;
    CHECK(fxs_particles_decode(enc, len, &out, err, sizeof err) == 0, "decode: %s", err);
    CHECK(out.n == in->n, "n %u vs %u", out.n, in->n);
    if (out.n == in->n) {
        bad = compare(in, &out, enc);
        CHECK(bad == 0, "%d of %u particles outside the bounds (pos_bits %d, vel_bits %d)", bad, in->n, o->pos_bits,
              o->vel_bits);
        r = (long)len;
    }
    free(enc);
    fxs_particles_free(&out);
    return r;
}

static long round_trip(const struct fxs_particles *in, int pos_bits, int temp_bits, int fuel_bits)
{
    struct fxs_particles_opts o = { .pos_bits = pos_bits, .temp_bits = temp_bits, .fuel_bits = fuel_bits, .vel_bits = 0 };
    return round_trip_opts(in, &o);
}

static void test_empty_and_tiny(void)
{
    struct fxs_particles p = { 0 };
    for (uint32_t n = 0; n <= 2; n++) {
        pgen_random(&p, n, 1.0);
        CHECK(round_trip(&p, 16, 0, 0) >= 64, "n=%u", n);
        free_set(&p);
    }
}

static void test_every_pos_bits(void)
{
    struct fxs_particles p = { 0 }, f = { 0 };
    pgen_random(&p, 3000, 2.0);
    pgen_flame(&f, 3000);
    for (int b = 8; b <= 24; b++) {
        CHECK(round_trip(&p, b, 0, 0) > 0, "random, pos_bits %d", b);
        CHECK(round_trip(&f, b, 0, 0) > 0, "flame, pos_bits %d", b);
    }
    free_set(&p);
    free_set(&f);
}

static void test_temp_fuel_bits(void)
{
    struct fxs_particles p = { 0 };
    pgen_flame(&p, 5000);
    for (int b = 2; b <= 16; b++) CHECK(round_trip(&p, 16, b, 18 - b) > 0, "temp_bits %d, fuel_bits %d", b, 18 - b);
    free_set(&p);
}

/* Synthetic flame: 4.80 B/particle at 16 bits, 3.30 at 12, 4.56 with T and F at 8 bits
 * (bench_particles; Draco: 4.80 at 16 bits with T and F at 8); guards regressions. */
static void test_flame_size(void)
{
    struct fxs_particles p = { 0 };
    long len;
    pgen_flame(&p, 50000);
    len = round_trip(&p, 16, 0, 0);
    CHECK(len > 0 && (double)len / p.n < 4.9, "%.2f bytes/particle", (double)len / p.n);
    len = round_trip(&p, 12, 0, 0);
    CHECK(len > 0 && (double)len / p.n < 3.4, "%.2f bytes/particle at 12 bits", (double)len / p.n);
    len = round_trip(&p, 16, 8, 8);
    CHECK(len > 0 && (double)len / p.n < 4.7, "%.2f bytes/particle with T and F at 8 bits", (double)len / p.n);
    free_set(&p);
}

static void test_degenerate(void)
{
    struct fxs_particles p = { 0 };
    pgen_random(&p, 1000, 1.0);
    for (uint32_t i = 0; i < p.n; i++) {
        p.xyz[3 * i] = p.xyz[3 * i + 1] = p.xyz[3 * i + 2] = 0.25f;
        p.temp[i] = 300;
        p.fuel[i] = 0;
        p.flags[i] = 4;
    }
    CHECK(round_trip(&p, 16, 0, 0) > 0, "one point");
    for (uint32_t i = 0; i < p.n; i++) p.xyz[3 * i] = (float)i; /* one axis spread */
    CHECK(round_trip(&p, 24, 0, 0) > 0, "a line");
    for (uint32_t i = 0; i < p.n; i++) p.xyz[3 * i] = 1e6f + (float)(i % 7) * 0.0625f; /* far from 0 */
    CHECK(round_trip(&p, 24, 16, 16) > 0, "far from the origin");
    for (uint32_t i = 0; i < p.n; i++) { /* extreme bounds: spans near FLT_MAX */
        for (int a = 0; a < 3; a++) p.xyz[3 * i + a] = (float)((pgen_rand() - 0.5) * 6e38);
        p.temp[i] = (float)((pgen_rand() - 0.5) * 6e38);
        p.fuel[i] = i % 2 ? -FLT_MAX : FLT_MAX;
        p.flags[i] = (uint8_t)(pgen_rand() * 256);
    }
    for (int b = 8; b <= 24; b += 8) CHECK(round_trip(&p, b, 16, 2) > 0, "extreme bounds, pos_bits %d", b);
    free_set(&p);
    for (uint32_t n = 1; n <= 3; n++) { /* identical particles, tiny n */
        pgen_random(&p, n, 1.0);
        for (uint32_t i = 1; i < n; i++) {
            memcpy(p.xyz + 3 * i, p.xyz, 3 * sizeof *p.xyz);
            p.temp[i] = p.temp[0], p.fuel[i] = p.fuel[0], p.flags[i] = p.flags[0];
        }
        CHECK(round_trip(&p, 16, 0, 0) > 0, "%u identical", n);
        free_set(&p);
    }
}

static void test_real_frame(void)
{
    struct fxs_particles p = { 0 };
    if (pgen_read_ply(REAL_PLY, &p)) {
        CHECK(0, "read %s", REAL_PLY);
        return;
    }
    for (int b = 8; b <= 24; b += 4) CHECK(round_trip(&p, b, 0, 0) > 0, "real frame, pos_bits %d", b);
    CHECK(round_trip(&p, 16, 8, 8) > 0, "real frame, T and F 8 bits");
    {   /* mixed burning and cold particles: the encoder picks attribute mode 1 (values) */
        struct fxs_particles_opts o = { .pos_bits = 16, .temp_bits = 8, .fuel_bits = 8, .vel_bits = 0 };
        uint8_t *enc = NULL;
        size_t len = 0;
        char err[200];
        CHECK(!fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) && len > 11 && enc[11] == 1,
              "real frame: attribute mode %d, expected 1", enc && len > 11 ? enc[11] : -1);
        free(enc);
    }
    free_set(&p);
    {   /* a smooth synthetic flame: mode 0 (residuals) */
        struct fxs_particles_opts o = { .pos_bits = 16, .temp_bits = 8, .fuel_bits = 8, .vel_bits = 0 };
        uint8_t *enc = NULL;
        size_t len = 0;
        char err[200];
        pgen_flame(&p, 20000);
        CHECK(!fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) && len > 11 && enc[11] == 0,
              "synthetic frame: attribute mode %d, expected 0", enc && len > 11 ? enc[11] : -1);
        free(enc);
        free_set(&p);
    }
}

static void test_large(void)
{
    struct fxs_particles p = { 0 };
    const char *quick = getenv("FXS_TEST_QUICK");
    if (quick && *quick == '1') return;
    pgen_random(&p, 1000000, 10.0);
    CHECK(round_trip(&p, 16, 0, 0) > 0, "1e6 random");
    free_set(&p);
    pgen_flame(&p, 1000000);
    CHECK(round_trip(&p, 20, 0, 0) > 0, "1e6-ish flame");
    free_set(&p);
}

/* ---- velocities (§7.5.7) ---------------------------------------------------------------- */

/* Encodes p with o into *enc (the caller frees it); the payload length, 0 on failure. */
static size_t encode(const struct fxs_particles *p, const struct fxs_particles_opts *o, uint8_t **enc)
{
    size_t len = 0;
    char err[200] = "";
    *enc = NULL;
    CHECK(fxs_particles_encode(p, o, enc, &len, err, sizeof err) == 0, "encode: %s", err);
    return *enc ? len : 0;
}

static void test_vel_bits(void)
{
    struct fxs_particles p = { 0 };
    pgen_flame(&p, 5000);
    pgen_velocities(&p);
    for (int b = 2; b <= 16; b++) {
        struct fxs_particles_opts o = { .pos_bits = 16, .temp_bits = 0, .fuel_bits = 0, .vel_bits = b };
        CHECK(round_trip_opts(&p, &o) > 0, "vel_bits %d", b);
    }
    for (int b = 8; b <= 24; b += 8) {
        struct fxs_particles_opts o = { .pos_bits = b, .temp_bits = 16, .fuel_bits = 2, .vel_bits = 8 };
        CHECK(round_trip_opts(&p, &o) > 0, "pos_bits %d with velocities", b);
    }
    free_set(&p);
    pgen_random(&p, 3000, 1.0); /* random velocities: nothing to predict */
    pgen_velocities(&p);
    for (uint32_t i = 0; i < 3 * p.n; i++) p.vel[i] = (float)((pgen_rand() - 0.5) * 10);
    for (int b = 4; b <= 12; b += 4) {
        struct fxs_particles_opts o = { .pos_bits = 16, .temp_bits = 0, .fuel_bits = 0, .vel_bits = b };
        CHECK(round_trip_opts(&p, &o) > 0, "random velocities, vel_bits %d", b);
    }
    free_set(&p);
}

/* Off: no velocity block, and vel_bits has no effect; on: the other attributes decode to
 * exactly what they decode to without velocities, and the payload grows by the block. */
static void test_vel_off_on(void)
{
    struct fxs_particles p = { 0 }, a, b;
    struct fxs_particles_opts o8 = { .pos_bits = 16, .vel_bits = 8 }, o12 = { .pos_bits = 16, .vel_bits = 12 },
                              o0 = { .pos_bits = 16 };
    uint8_t *e0, *e1, *ev;
    char err[200];
    pgen_flame(&p, 3000);
    size_t l0 = encode(&p, &o0, &e0), l1 = encode(&p, &o12, &e1);
    CHECK(l0 && l0 == l1 && !memcmp(e0, e1, l0) && !(e0[11] & 0x10), "without velocities vel_bits changes the payload");
    pgen_velocities(&p);
    size_t lv = encode(&p, &o8, &ev);
    CHECK(lv > l0 + 16 && ev && (ev[11] & 0x10) && (ev[11] & 0x0f) == (e0[11] & 0x0f), "with velocities: %zu vs %zu bytes", lv, l0);
    if (e0 && ev && !fxs_particles_decode(e0, l0, &a, err, sizeof err)) {
        if (!fxs_particles_decode(ev, lv, &b, err, sizeof err)) {
            CHECK(a.vel == NULL && b.vel != NULL, "vel pointer set only with velocities");
            CHECK(a.n == b.n && !memcmp(a.xyz, b.xyz, 12 * (size_t)a.n) && !memcmp(a.temp, b.temp, 4 * (size_t)a.n) &&
                  !memcmp(a.fuel, b.fuel, 4 * (size_t)a.n) && !memcmp(a.flags, b.flags, a.n),
                  "velocities change the other attributes");
            CHECK(!memcmp(e0 + 12, ev + 12, 44), "header fields differ");
            fxs_particles_free(&b);
        } else {
            CHECK(0, "decode with velocities: %s", err);
        }
        fxs_particles_free(&a);
    }
    printf("  3k synthetic flame: %.3f B/particle, %.3f with velocities at 8 bits\n", (double)l0 / p.n, (double)lv / p.n);
    free(e0), free(e1), free(ev);
    free_set(&p);
}

static void test_vel_empty_zero(void)
{
    struct fxs_particles p = { 0 }, d;
    struct fxs_particles_opts o = { .pos_bits = 16, .temp_bits = 0, .fuel_bits = 0, .vel_bits = 8 };
    uint8_t *enc;
    char err[200];
    size_t len, l0;
    pgen_random(&p, 0, 1.0);
    pgen_velocities(&p);
    len = encode(&p, &o, &enc);
    CHECK(len == 80 && (enc[11] & 0x10), "empty frame with velocities: %zu bytes", len);
    CHECK(enc && !fxs_particles_decode(enc, len, &d, err, sizeof err) && d.n == 0 && d.vel != NULL, "empty: %s", err);
    if (enc && d.vel) fxs_particles_free(&d);
    free(enc);
    free_set(&p);
    /* all zero: decoded exactly, at almost no cost */
    pgen_flame(&p, 5000);
    l0 = encode(&p, &o, &enc);
    free(enc);
    p.vel = calloc(3 * (size_t)p.n, sizeof *p.vel);
    len = encode(&p, &o, &enc);
    CHECK(len > l0 && len < l0 + 16 + p.n / 40, "all-zero velocities cost %zu bytes over %zu", len - l0, l0);
    if (enc && !fxs_particles_decode(enc, len, &d, err, sizeof err)) {
        int nz = 0;
        for (uint32_t i = 0; i < 3 * d.n; i++) nz += d.vel[i] != 0 || signbit(d.vel[i]);
        CHECK(nz == 0, "%d non-zero components", nz);
        for (int a = 0; a < 3; a++) CHECK(getf(enc + 68 + 4 * a) == 0, "vmax %d", a);
        fxs_particles_free(&d);
    } else {
        CHECK(0, "decode all-zero: %s", err);
    }
    free(enc);
    free_set(&p);
}

/* The largest magnitudes: components at +-vmax (exact), near FLT_MAX, one axis zero. */
static void test_vel_extremes(void)
{
    struct fxs_particles p = { 0 }, d;
    struct fxs_particles_opts o = { .pos_bits = 16, .temp_bits = 0, .fuel_bits = 0, .vel_bits = 8 };
    uint8_t *enc;
    char err[200];
    size_t len;
    pgen_flame(&p, 2000);
    pgen_velocities(&p);
    for (uint32_t i = 0; i < p.n; i++) {
        p.vel[3 * i] = i % 3 == 0 ? 2.5f : i % 3 == 1 ? -2.5f : p.vel[3 * i];
        p.vel[3 * i + 1] = 0;
    }
    len = encode(&p, &o, &enc);
    if (enc && !fxs_particles_decode(enc, len, &d, err, sizeof err)) {
        int exact = 0, zero = 0;
        for (uint32_t i = 0; i < d.n; i++) {
            exact += fabsf(d.vel[3 * i]) == 2.5f;
            zero += d.vel[3 * i + 1] == 0;
        }
        CHECK(exact >= (int)(2 * d.n / 3), "only %d of %u at +-vmax decode exactly", exact, d.n);
        CHECK(zero == (int)d.n && getf(enc + 68) == 2.5f && getf(enc + 72) == 0, "zero axis, vmax");
        fxs_particles_free(&d);
    } else {
        CHECK(0, "decode: %s", err);
    }
    free(enc);
    CHECK(round_trip_opts(&p, &o) > 0, "+-vmax");
    for (uint32_t i = 0; i < 3 * p.n; i++) p.vel[i] = (float)((pgen_rand() - 0.5) * 6.8e38);
    p.vel[5] = FLT_MAX, p.vel[7] = -FLT_MAX;
    for (int b = 2; b <= 16; b += 7) {
        o.vel_bits = b;
        CHECK(round_trip_opts(&p, &o) > 0, "magnitudes near FLT_MAX, vel_bits %d", b);
    }
    p.vel[3] = INFINITY;
    CHECK(fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) == -1 && strstr(err, "non-finite"), "inf velocity");
    p.vel[3] = NAN;
    CHECK(fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) == -1, "NaN velocity");
    p.vel[3] = 0;
    o.vel_bits = 1;
    CHECK(fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) == -1, "vel_bits 1");
    o.vel_bits = 17;
    CHECK(fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) == -1, "vel_bits 17");
    free_set(&p);
}

static void test_bad_input(void)
{
    struct fxs_particles p = { 0 };
    struct fxs_particles_opts o = { .pos_bits = 7, .temp_bits = 0, .fuel_bits = 0, .vel_bits = 0 };
    uint8_t *enc = NULL;
    size_t len;
    char err[200];
    pgen_random(&p, 10, 1.0);
    CHECK(fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) == -1, "pos_bits 7");
    o.pos_bits = 25;
    CHECK(fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) == -1, "pos_bits 25");
    o.pos_bits = 16;
    o.temp_bits = 17;
    CHECK(fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) == -1, "temp_bits 17");
    o.temp_bits = 0;
    p.temp[3] = NAN;
    CHECK(fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) == -1, "NaN");
    CHECK(strstr(err, "non-finite") != NULL, "message: %s", err);
    p.temp[3] = 300;
    p.xyz[4] = INFINITY;
    CHECK(fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) == -1, "inf");
    p.n = FXS_PARTICLES_MAX_N + 1;
    CHECK(fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) == -1, "too many");
    p.n = 10;
    free_set(&p);
}

/* Encodes the first n particles of a small flame, with velocities if vel; the caller frees *enc. */
static size_t small_payload(uint8_t **enc, uint32_t n, int vel)
{
    struct fxs_particles p = { 0 };
    size_t len = 0;
    char err[200];
    pgen_flame(&p, 3000);
    if (vel) pgen_velocities(&p);
    if (p.n > n) p.n = n;
    if (fxs_particles_encode(&p, NULL, enc, &len, err, sizeof err)) *enc = NULL;
    free_set(&p);
    return len;
}

static int try_decode(const uint8_t *buf, size_t len)
{
    struct fxs_particles out;
    char err[200];
    uint8_t *copy = malloc(len ? len : 1); /* exact size, so valgrind sees overreads */
    int r;
    memcpy(copy, buf, len);
    r = fxs_particles_decode(copy, len, &out, err, sizeof err);
    if (!r) fxs_particles_free(&out);
    else CHECK(strncmp(err, "particles: ", 11) == 0 && out.xyz == NULL, "error state: %s", err);
    free(copy);
    return r;
}

static void test_truncated(void)
{
    for (int vel = 0; vel <= 1; vel++) {
        uint8_t *enc;
        size_t len = small_payload(&enc, 200, vel);
        CHECK(enc && try_decode(enc, len) == 0, "intact payload decodes");
        for (size_t l = 0; enc && l < len; l++)
            CHECK(try_decode(enc, l) == -1, "truncated to %zu of %zu decodes (velocities %d)", l, len, vel);
        free(enc);
    }
}

static void test_corrupt_one(int vel)
{
    uint8_t *enc, *bad;
    size_t len = small_payload(&enc, 200, vel);
    int rejected = 0, trials = 3000;
    if (!enc) {
        CHECK(0, "encode");
        return;
    }
    bad = malloc(len);
    for (int t = 0; t < trials; t++) {
        memcpy(bad, enc, len);
        size_t at = (size_t)(pgen_rand() * len);
        bad[at] ^= (uint8_t)(1 + pgen_rand() * 255);
        if (pgen_rand() < 0.3) bad[(size_t)(pgen_rand() * len)] = (uint8_t)(pgen_rand() * 256);
        rejected += try_decode(bad, len) == -1;
    }
    printf("  corrupt%s: %d of %d rejected, the rest decode to other valid particles\n", vel ? " (velocities)" : "",
           rejected, trials);
    CHECK(rejected > trials / 2, "only %d rejected", rejected);
    free(bad);
    free(enc);
}

static void test_corrupt(void)
{
    test_corrupt_one(0);
    test_corrupt_one(1);
}

static void put32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static void test_header_limits(void)
{
    uint8_t *enc, *bad;
    size_t len = small_payload(&enc, 50, 0);
    static const struct { int at; uint8_t v; } byte_cases[] = {
        { 0, 'X' }, { 3, '1' }, { 4, 1 }, { 5, 7 }, { 5, 25 }, { 6, 1 }, { 7, 17 }, { 8, 17 }, { 10, 25 }, { 11, 2 }, { 11, 255 },
        { 11, 0x20 }, { 11, 0x80 }, { 11, 0x10 }, { 11, 0x11 },
    };
    /* with velocities: mode bits, vel_bits, reserved bytes (64 + ...) */
    static const struct { int at; uint8_t v; } vel_cases[] = {
        { 11, 0x30 }, { 11, 0x00 }, { 11, 0x01 }, { 64, 1 }, { 64, 17 }, { 64, 0 }, { 65, 1 }, { 67, 0x80 },
    };
    if (!enc) {
        CHECK(0, "encode");
        return;
    }
    bad = malloc(len);
    for (size_t c = 0; c < sizeof byte_cases / sizeof byte_cases[0]; c++) {
        memcpy(bad, enc, len);
        bad[byte_cases[c].at] = byte_cases[c].v;
        CHECK(try_decode(bad, len) == -1, "byte %d = %u accepted", byte_cases[c].at, byte_cases[c].v);
    }
    memcpy(bad, enc, len);
    put32(bad + 12, FXS_PARTICLES_MAX_N + 1);
    CHECK(try_decode(bad, len) == -1, "n over the limit");
    memcpy(bad, enc, len);
    put32(bad + 16, 0x7fc00000u); /* NaN bound */
    CHECK(try_decode(bad, len) == -1, "NaN bound");
    memcpy(bad, enc, len);
    put32(bad + 56, 0xffffffffu);
    CHECK(try_decode(bad, len) == -1, "huge rans_bytes");
    free(bad);
    free(enc);
    len = small_payload(&enc, 50, 1);
    if (!enc) {
        CHECK(0, "encode");
        return;
    }
    bad = malloc(len);
    CHECK(try_decode(enc, len) == 0, "intact velocity payload");
    for (size_t c = 0; c < sizeof vel_cases / sizeof vel_cases[0]; c++) {
        memcpy(bad, enc, len);
        bad[vel_cases[c].at] = vel_cases[c].v;
        CHECK(try_decode(bad, len) == -1, "velocity payload: byte %d = %u accepted", vel_cases[c].at, vel_cases[c].v);
    }
    static const uint32_t vmax_bad[] = { 0x7fc00000u, 0x7f800000u, 0xbf800000u }; /* NaN, inf, -1 */
    for (int a = 0; a < 3; a++)
        for (int k = 0; k < 3; k++) {
            memcpy(bad, enc, len);
            put32(bad + 68 + 4 * a, vmax_bad[k]);
            CHECK(try_decode(bad, len) == -1, "vmax[%d] = %08x accepted", a, vmax_bad[k]);
        }
    free(bad);
    free(enc);
}

/* ---- blocks (§7.5.8) --------------------------------------------------------------------- */

/* Blocks in a payload, by their headers' section sizes (0 if they do not add up). */
static int count_blocks(const uint8_t *enc, size_t len)
{
    int k = 0;
    for (size_t at = 0; at < len; k++) {
        if (len - at < 64) return 0;
        const uint8_t *b = enc + at;
        size_t hb = 64 + ((b[11] & 0x10) ? 16 : 0);
        at += hb + (b[56] | b[57] << 8 | (uint32_t)b[58] << 16 | (uint32_t)b[59] << 24) +
              (b[60] | b[61] << 8 | (uint32_t)b[62] << 16 | (uint32_t)b[63] << 24);
        if (at > len) return 0;
    }
    return k;
}

/* Decoded particles as sortable records: x y z T F flags vx vy vz. */
static int rec_cmp(const void *a, const void *b) { return memcmp(a, b, 9 * sizeof(float)); }
static float *records(const struct fxs_particles *d)
{
    float *r = calloc((size_t)d->n * 9 + 1, sizeof *r);
    for (uint32_t i = 0; r && i < d->n; i++) {
        memcpy(r + 9 * i, d->xyz + 3 * i, 12);
        r[9 * i + 3] = d->temp[i], r[9 * i + 4] = d->fuel[i], r[9 * i + 5] = d->flags[i];
        if (d->vel) memcpy(r + 9 * i + 6, d->vel + 3 * i, 12);
    }
    if (r) qsort(r, d->n, 9 * sizeof *r, rec_cmp);
    return r;
}

/* Threads cut a frame into blocks on the frame's common grid: the decoded set is the one
 * block's, particle for particle, for 1-2% more bytes; small frames stay one block (codec 2),
 * byte for byte. */
static void test_blocks(void)
{
    for (int vel = 0; vel < 2; vel++) {
        struct fxs_particles p = { 0 }, d1, dk;
        pgen_flame(&p, 20000);
        if (vel) pgen_velocities(&p);
        struct fxs_particles_opts o1 = { .threads = 1 };
        uint8_t *e1 = NULL;
        size_t l1 = encode(&p, &o1, &e1);
        char err[200] = "";
        CHECK(e1 && fxs_particles_codec(e1, l1) == FXS_CODEC_PARTICLES && count_blocks(e1, l1) == 1, "one block");
        CHECK(e1 && !fxs_particles_decode(e1, l1, &d1, err, sizeof err), "decode one block: %s", err);
        float *r1 = e1 ? records(&d1) : NULL;
        const int threads[3] = { 2, 3, 8 }, want[3] = { 2, 3, 4 }; /* 8 threads: n / 4096 = 4 blocks */
        for (int t = 0; t < 3 && r1; t++) {
            struct fxs_particles_opts ok = { .threads = threads[t] };
            uint8_t *ek = NULL;
            size_t lk = encode(&p, &ok, &ek);
            CHECK(ek && fxs_particles_codec(ek, lk) == FXS_CODEC_PARTICLES_BLOCKS && count_blocks(ek, lk) == want[t],
                  "vel %d, %d threads: %d blocks (want %d)", vel, threads[t], ek ? count_blocks(ek, lk) : -1, want[t]);
            CHECK(lk <= l1 * 1.03, "vel %d, %d threads: %zu bytes against %zu in one block", vel, threads[t], lk, l1);
            if (ek && !fxs_particles_decode(ek, lk, &dk, err, sizeof err)) {
                float *rk = records(&dk);
                CHECK(dk.n == d1.n && !dk.vel == !d1.vel && rk && !memcmp(rk, r1, (size_t)d1.n * 9 * sizeof *rk),
                      "vel %d, %d threads: the decoded set differs from the one block's", vel, threads[t]);
                free(rk);
                fxs_particles_free(&dk);
            } else {
                CHECK(0, "decode %d blocks: %s", want[t], err);
            }
            free(ek);
        }
        if (r1) fxs_particles_free(&d1);
        free(r1), free(e1);
        p.n = 2 * FXS_PARTICLES_BLOCK_MIN - 1; /* too few for two blocks */
        struct fxs_particles_opts o8 = { .threads = 8 };
        uint8_t *a = NULL, *b = NULL;
        size_t la = encode(&p, &o1, &a), lb = encode(&p, &o8, &b);
        CHECK(a && b && la == lb && !memcmp(a, b, la), "vel %d: %u particles, 8 threads: the one-block payload", vel, p.n);
        free(a), free(b);
        free_set(&p);
    }
}

static void expect_reject(const uint8_t *buf, size_t len, const char *want, const char *what)
{
    struct fxs_particles d;
    char err[200] = "";
    int r = fxs_particles_decode(buf, len, &d, err, sizeof err);
    CHECK(r == -1 && strstr(err, want), "%s: rejected with \"%s\" (got %d, \"%s\")", what, want, r, err);
    if (!r) fxs_particles_free(&d);
}

static void test_blocks_reject(void)
{
    struct fxs_particles p = { 0 }, e = { 0 };
    pgen_flame(&p, 20000);
    struct fxs_particles_opts o2 = { .threads = 2 }, o1 = { .threads = 1 };
    uint8_t *two = NULL, *plain = NULL, *withv = NULL;
    size_t l2 = encode(&p, &o2, &two), lp = encode(&p, &o1, &plain);
    pgen_velocities(&p);
    size_t lv = encode(&p, &o1, &withv);
    if (!two || !plain || !withv) goto out;
    expect_reject(two, l2 - 1, "section sizes do not match", "two blocks, the last byte cut");
    uint8_t *buf = malloc(lp + lv + 64 * 65 + 16);
    memcpy(buf, plain, lp), memcpy(buf + lp, withv, lv);
    expect_reject(buf, lp + lv, "blocks disagree on velocities", "a block without velocities, then one with them");
    memcpy(buf + lp, "garbage!", 8);
    expect_reject(buf, lp + 8, "not a codec 2 payload", "a block, then 8 bytes of garbage");
    uint8_t *empty = NULL;
    size_t le = encode(&e, &o1, &empty); /* 64 bytes, n = 0 */
    for (int i = 0; empty && i < 65; i++) memcpy(buf + le * (size_t)i, empty, le);
    struct fxs_particles d;
    char err[200] = "";
    CHECK(empty && !fxs_particles_decode(buf, le * 64, &d, err, sizeof err) && d.n == 0, "64 empty blocks: %s", err);
    if (empty && !err[0]) fxs_particles_free(&d);
    if (empty) expect_reject(buf, le * 65, "more blocks than allowed", "65 empty blocks");
    memcpy(buf, empty, le), memcpy(buf + le, empty, le); /* two header-only blocks claiming 2^21 + 1 each */
    for (int k = 0; k < 2; k++) buf[le * (size_t)k + 12] = 1, buf[le * (size_t)k + 14] = 0x20;
    expect_reject(buf, 2 * le, "particle count over the limit", "two blocks of 2^21 + 1 particles");
    free(buf), free(empty);
out:
    free(two), free(plain), free(withv);
    free_set(&p);
}

/* ---- test vectors ------------------------------------------------------------------------ */

static void vec_input(int v, struct fxs_particles *p, struct fxs_particles_opts *o)
{
    pgen_rng = 12345 + (uint64_t)v;
    *o = (struct fxs_particles_opts){ .pos_bits = 16, .temp_bits = 0, .fuel_bits = 0, .vel_bits = 0 };
    if (v == 0) pgen_random(p, 0, 1.0);
    if (v == 1) pgen_random(p, 1, 1.0);
    if (v == 2) pgen_random(p, 7, 3.0), o->pos_bits = 8;
    if (v == 3 || v == 4) {
        pgen_flame(p, 3000);
        p->n = 64;
        if (v == 4) *o = (struct fxs_particles_opts){ .pos_bits = 24, .temp_bits = 16, .fuel_bits = 16, .vel_bits = 0 };
    }
    if (v == 5) {
        pgen_random(p, 5, 1.0);
        for (int i = 0; i < 5; i++) p->xyz[3 * i + 1] = 2.5f; /* flat in y */
    }
    if (v == 6 || v == 7) {
        CHECK(pgen_read_ply(REAL_PLY, p) == 0, "read %s", REAL_PLY);
        if (v == 7) *o = (struct fxs_particles_opts){ .pos_bits = 12, .temp_bits = 8, .fuel_bits = 8, .vel_bits = 0 };
    }
    if (v == 8) { /* all identical */
        pgen_random(p, 9, 1.0);
        for (int i = 1; i < 9; i++) {
            memcpy(p->xyz + 3 * i, p->xyz, 3 * sizeof *p->xyz);
            p->temp[i] = p->temp[0], p->fuel[i] = p->fuel[0], p->flags[i] = p->flags[0];
        }
    }
    if (v == 9) { /* velocities, default 8 bits */
        pgen_flame(p, 3000);
        p->n = 64;
        pgen_velocities(p);
    }
    if (v == 10) { /* velocities at 4 bits, one axis at rest, random set */
        pgen_random(p, 7, 3.0);
        pgen_velocities(p);
        for (int i = 0; i < 7; i++) p->vel[3 * i] = (float)(pgen_rand() - 0.5), p->vel[3 * i + 1] = 0;
        o->vel_bits = 4;
    }
    if (v == 11) { /* empty, with velocities */
        pgen_random(p, 0, 1.0);
        pgen_velocities(p);
    }
    if (v == 12) { /* a real frame with velocities, 12-bit */
        CHECK(pgen_read_ply(REAL_VEL_PLY, p) == 0 && p->vel, "read %s", REAL_VEL_PLY);
        o->vel_bits = 12;
    }
}

static const char *const vec_names[] = { "empty", "one", "seven_8bit", "flame64", "flame64_24bit", "flat_y",
                                         "real_flame600", "real_flame600_12bit", "identical9", "flame64_vel",
                                         "seven_vel_4bit", "empty_vel", "real_vel600_12bit" };
#define NVEC 13

/* The JSON the decoder must produce: floats as %.9g (float32 round trips exactly). */
static char *vec_json(const struct fxs_particles *d)
{
    size_t cap = 256 + (size_t)d->n * 150, o = 0;
    char *s = malloc(cap);
    const float *arr[3] = { d->xyz, d->temp, d->fuel };
    const char *names[3] = { "xyz", "temp", "fuel" };
    o += (size_t)snprintf(s + o, cap - o, "{\"n\":%u", d->n);
    for (int a = 0; a < 3; a++) {
        uint32_t cnt = a ? d->n : 3 * d->n;
        o += (size_t)snprintf(s + o, cap - o, ",\n\"%s\":[", names[a]);
        for (uint32_t i = 0; i < cnt; i++) o += (size_t)snprintf(s + o, cap - o, "%s%.9g", i ? "," : "", arr[a][i]);
        o += (size_t)snprintf(s + o, cap - o, "]");
    }
    o += (size_t)snprintf(s + o, cap - o, ",\n\"flags\":[");
    for (uint32_t i = 0; i < d->n; i++) o += (size_t)snprintf(s + o, cap - o, "%s%u", i ? "," : "", d->flags[i]);
    o += (size_t)snprintf(s + o, cap - o, "]");
    if (d->vel) {
        o += (size_t)snprintf(s + o, cap - o, ",\n\"vel\":[");
        for (uint32_t i = 0; i < 3 * d->n; i++) o += (size_t)snprintf(s + o, cap - o, "%s%.9g", i ? "," : "", d->vel[i]);
        o += (size_t)snprintf(s + o, cap - o, "]");
    }
    snprintf(s + o, cap - o, "}\n");
    return s;
}

static char *read_file(const char *path, size_t *len)
{
    FILE *f = fopen(path, "rb");
    char *buf = NULL;
    long n;
    if (!f) return NULL;
    if (fseek(f, 0, SEEK_END) == 0 && (n = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0 && (buf = malloc((size_t)n + 1))) {
        *len = fread(buf, 1, (size_t)n, f);
        buf[*len] = 0;
    }
    fclose(f);
    return buf;
}

static int write_file(const char *path, const void *data, size_t len)
{
    FILE *f = fopen(path, "wb");
    int ok = f && fwrite(data, 1, len, f) == len;
    if (f && fclose(f)) ok = 0;
    return ok ? 0 : -1;
}

/* A payload of version 2, which version 3 replaced (PROTOCOL.md §7.5.1: the tree's order and
 * counts changed): flame64 as the version 2 encoder wrote it. Rejected, naming the version. */
static void test_version2(void)
{
    size_t len;
    char err[200] = "", *buf = read_file(VEC_DIR "/replaced/flame64_version2.bin", &len);
    struct fxs_particles out;
    if (!buf) {
        CHECK(0, "read " VEC_DIR "/replaced/flame64_version2.bin");
        return;
    }
    CHECK(len > 4 && buf[4] == 2, "the file is a version 2 payload");
    int r = fxs_particles_decode((const uint8_t *)buf, len, &out, err, sizeof err);
    CHECK(r == -1, "version 2 payload decoded");
    if (!r) fxs_particles_free(&out);
    CHECK(!strcmp(err, "particles: unsupported version (this decoder reads version 3)"), "message: %s", err);
    free(buf);
}

/* Encodes vector v; writes it (write) or compares it with the committed files. */
static void vec_one(int v, int write)
{
    struct fxs_particles p = { 0 }, d;
    struct fxs_particles_opts o;
    uint8_t *enc = NULL;
    size_t len = 0, flen = 0, jlen = 0;
    char err[200], path[256], *file, *json, *fjson;
    vec_input(v, &p, &o);
    CHECK(fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err) == 0, "%s", err);
    CHECK(enc && fxs_particles_decode(enc, len, &d, err, sizeof err) == 0, "%s", err);
    json = vec_json(&d);
    snprintf(path, sizeof path, VEC_DIR "/%s.bin", vec_names[v]);
    if (write) CHECK(write_file(path, enc, len) == 0, "write %s", path);
    file = read_file(path, &flen);
    CHECK(file && flen == len && !memcmp(file, enc, len), "%s differs from the encoder's output (format change? rerun with --write-vectors)", path);
    snprintf(path, sizeof path, VEC_DIR "/%s.json", vec_names[v]);
    if (write) CHECK(write_file(path, json, strlen(json)) == 0, "write %s", path);
    fjson = read_file(path, &jlen);
    CHECK(fjson && !strcmp(fjson, json), "%s differs from what the decoder gives", path);
    free(file), free(fjson), free(json), free(enc);
    fxs_particles_free(&d);
    free_set(&p);
}

static int vec_write;
static void test_vectors(void)
{
    for (int v = 0; v < NVEC; v++) vec_one(v, vec_write);
}

int main(int argc, char **argv)
{
    vec_write = argc > 1 && !strcmp(argv[1], "--write-vectors");
    RUN(test_vectors);
    RUN(test_empty_and_tiny);
    RUN(test_every_pos_bits);
    RUN(test_temp_fuel_bits);
    RUN(test_flame_size);
    RUN(test_degenerate);
    RUN(test_real_frame);
    RUN(test_large);
    RUN(test_vel_bits);
    RUN(test_vel_off_on);
    RUN(test_vel_empty_zero);
    RUN(test_vel_extremes);
    RUN(test_blocks);
    RUN(test_blocks_reject);
    RUN(test_bad_input);
    RUN(test_truncated);
    RUN(test_corrupt);
    RUN(test_header_limits);
    RUN(test_version2);
    return CHECK_DONE();
}
