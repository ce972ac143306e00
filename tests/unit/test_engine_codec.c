/* test_engine_codec.c — the engine encoding (protocol/fxs_engine.c, PROTOCOL.md §7.8).
 *
 * Half floats: every half converts to float and back to itself, floats round to the nearest
 * half (ties to even, denormals, overflow to infinity). Particles: round trips of sets of
 * 0 .. 10 000 particles, with and without velocities, near and far from the world's origin,
 * within half a half-float step of each value's offset, inside the header's box; the layout (1024-texel rows, padding,
 * the velocity layer below). Textures: one and four channels, exactly the halves of the
 * input. Malformed payloads are rejected with a message and without reading out of bounds:
 * every cut, wrong sizes, bad magic or version, absurd counts, trailing bytes, unknown
 * format or flags, a non-finite origin or particle. */
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <zstd.h>

#include "check.h"
#include "fxs_bytes.h"
#include "fxs_engine.h"

static uint64_t rng = 88172645463325252ull;
static double rnd(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (double)(rng >> 11) / 9007199254740992.0;
}

/* ---- half floats --------------------------------------------------------------------- */

static void test_half_exhaustive(void)
{
    int bad = 0;
    for (uint32_t h = 0; h < 0x10000; h++) {
        float f = fxs_half_to_float((uint16_t)h);
        uint16_t back = fxs_half_from_float(f);
        bool nan = (h & 0x7c00) == 0x7c00 && (h & 0x3ff);
        if (nan ? !(back & 0x3ff) || (back & 0x7c00) != 0x7c00 : back != h) bad++;
    }
    CHECK(bad == 0, "%d halves do not survive float and back", bad);
    CHECK(fxs_half_to_float(0x3c00) == 1.0f && fxs_half_to_float(0xc000) == -2.0f, "1 and -2");
    CHECK(fxs_half_to_float(0x7bff) == 65504.0f && fxs_half_to_float(0x0001) == ldexpf(1, -24), "max and smallest");
}

/* The nearest half of random floats (ties to even), against a search of the neighbours. */
static void test_half_rounding(void)
{
    int bad = 0;
    for (int i = 0; i < 200000; i++) {
        float f = (float)((rnd() * 2 - 1) * ldexp(1.0, (int)(rnd() * 44) - 28));
        uint16_t h = fxs_half_from_float(f);
        double err = fabs((double)fxs_half_to_float(h) - f);
        for (int d = -1; d <= 1; d += 2) {
            uint16_t o = (uint16_t)(h + d);
            if ((o & 0x7c00) == 0x7c00 || (o ^ h) & 0x8000) continue;
            double e2 = fabs((double)fxs_half_to_float(o) - f);
            if (e2 < err || (e2 == err && (o & 1) == 0)) bad++;
        }
    }
    CHECK(bad == 0, "%d floats not rounded to the nearest half", bad);
    CHECK(fxs_half_from_float(1.0f + ldexpf(1, -11)) == 0x3c00, "a tie goes to the even half (1.0)");
    CHECK(fxs_half_from_float(1.0f + 3 * ldexpf(1, -11)) == 0x3c02, "a tie goes to the even half (1.00195)");
    CHECK(fxs_half_from_float(65519.0f) == 0x7bff && fxs_half_from_float(65520.0f) == 0x7c00, "overflow at 65520");
    CHECK(fxs_half_from_float(-1e9f) == 0xfc00, "-infinity");
    CHECK(fxs_half_from_float(ldexpf(1, -25)) == 0 && fxs_half_from_float(ldexpf(3, -26)) == 1, "denormal rounding");
}

/* ---- particles ----------------------------------------------------------------------- */

static struct fxs_particles make_set(uint32_t n, bool vel, double centre, double extent)
{
    struct fxs_particles p = {n, malloc(12 * (n + 1)), malloc(4 * (n + 1)), malloc(4 * (n + 1)), malloc(n + 1),
                              vel ? malloc(12 * (n + 1)) : NULL};
    for (uint32_t i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++) p.xyz[3 * i + k] = (float)(centre + (rnd() - 0.5) * extent * (k == 1 ? 1 : 0.3));
        p.temp[i] = (float)(300 + 2500 * rnd());
        p.fuel[i] = (float)rnd();
        p.flags[i] = (uint8_t)(rnd() * 8);
        for (int k = 0; k < 3 && vel; k++) p.vel[3 * i + k] = (float)((rnd() - 0.5) * 6);
    }
    return p;
}

/* Half of a half-float step at |v|, plus the float roundings of the offset v and of origin +
 * offset at |x|. */
static double half_tol(double v, double x)
{
    int e;
    frexp(fmax(fabs(v), ldexp(1, -14)), &e);
    return ldexp(1, e - 12) + ldexp(fabs(v), -24) + ldexp(fabs(x), -24);
}

static void round_trip(uint32_t n, bool vel, double centre, double extent)
{
    struct fxs_particles in = make_set(n, vel, centre, extent), out;
    uint8_t *buf = NULL;
    size_t len = 0;
    char err[200] = "";
    CHECK(fxs_engine_encode_particles(&in, FXS_ENGINE_ZSTD_LEVEL, &buf, &len, err, sizeof err) == 0, "encode: %s", err);
    struct fxs_engine_info info;
    CHECK(buf && fxs_engine_info(buf, len, &info, err, sizeof err) == 0, "info: %s", err);
    CHECK(info.count == n && info.width == FXS_ENGINE_PARTICLE_WIDTH && info.height == (n ? (n + 1023) / 1024 : 1) &&
          info.layers == (vel ? 2u : 1u) && info.format == FXS_ENGINE_RGBA16F && info.raw_bytes == info.width * info.height * info.layers * 8,
          "n %u: %u x %u x %u, count %u", n, info.width, info.height, info.layers, info.count);
    if (!buf || fxs_engine_decode_particles(buf, len, &out, err, sizeof err)) {
        CHECK(0, "decode of %u particles: %s", n, err);
        free(buf);
        fxs_particles_free(&in);
        return;
    }
    CHECK(out.n == n && !out.fuel && !out.flags && (out.vel != NULL) == vel, "n %u / %u", out.n, n);
    int bad = 0;
    for (uint32_t i = 0; i < n && out.n == n; i++) {
        for (int k = 0; k < 3; k++) {
            double x = in.xyz[3 * i + k], off = x - info.origin[k];
            bad += fabs(out.xyz[3 * i + k] - x) > half_tol(off, x);
            bad += fabs(off) > info.extent[k]; /* the culling box holds every particle */
            if (vel) bad += fabs(out.vel[3 * i + k] - in.vel[3 * i + k]) > half_tol(in.vel[3 * i + k], 0);
        }
        bad += fabs(out.temp[i] - in.temp[i]) > half_tol(in.temp[i], 0);
    }
    CHECK(bad == 0, "%d values of %u particles (centre %g, extent %g) beyond half precision", bad, n, centre, extent);
    fxs_particles_free(&out);
    fxs_particles_free(&in);
    free(buf);
}

static void test_particles_round_trip(void)
{
    uint32_t ns[] = {0, 1, 2, 1023, 1024, 1025, 10000};
    for (size_t i = 0; i < sizeof ns / sizeof ns[0]; i++) {
        round_trip(ns[i], false, 0.1, 0.3);
        round_trip(ns[i], true, 0.1, 0.3);
    }
    round_trip(5000, true, 1500.0, 0.3); /* far from the origin: precision follows the extent */
    round_trip(5000, false, -20.0, 30.0);
}

/* The layout a shader reads: texel i at (i % 1024, i / 1024), padding zero, velocities below. */
static void test_particles_layout(void)
{
    struct fxs_particles in = make_set(1500, true, 0.0, 0.2);
    uint8_t *buf = NULL;
    size_t len;
    char err[200];
    CHECK(fxs_engine_encode_particles(&in, 3, &buf, &len, err, sizeof err) == 0, "%s", err);
    if (!buf) return;
    struct fxs_engine_info info;
    fxs_engine_info(buf, len, &info, err, sizeof err);
    uint8_t *raw = malloc(info.raw_bytes);
    CHECK(ZSTD_decompress(raw, info.raw_bytes, buf + 64, len - 64) == info.raw_bytes, "decompress");
    size_t layer = 1024 * 2 * 8;
    const uint8_t *t = raw + 8 * 1499, *v = t + layer;
    CHECK_NEAR(fxs_half_to_float(fxs_get_u16(t + 2)) + info.origin[1], in.xyz[3 * 1499 + 1], 1e-4);
    CHECK_NEAR(fxs_half_to_float(fxs_get_u16(t + 6)), in.temp[1499], 2.0);
    CHECK_NEAR(fxs_half_to_float(fxs_get_u16(v + 4)), in.vel[3 * 1499 + 2], 4e-3);
    int nonzero = 0;
    for (size_t i = 8 * 1500; i < layer; i++) nonzero += raw[i] != 0;
    for (size_t i = layer + 8 * 1500; i < 2 * layer; i++) nonzero += raw[i] != 0;
    for (uint32_t i = 0; i < 1500; i++) nonzero += fxs_get_u16(raw + layer + 8 * i + 6) != 0;
    CHECK(nonzero == 0, "%d padding bytes not zero", nonzero);
    free(raw);
    free(buf);
    fxs_particles_free(&in);
}

static void test_particles_encoder_rejects(void)
{
    struct fxs_particles in = make_set(10, true, 0.0, 0.2);
    uint8_t *buf = NULL;
    size_t len;
    char err[200] = "";
    in.xyz[4] = NAN;
    CHECK(fxs_engine_encode_particles(&in, 1, &buf, &len, err, sizeof err) < 0 && strstr(err, "finite"), "NaN: %s", err);
    in.xyz[4] = 0;
    in.vel[7] = 1e6f;
    CHECK(fxs_engine_encode_particles(&in, 1, &buf, &len, err, sizeof err) < 0 && strstr(err, "particle 2"), "1e6 m/s: %s", err);
    in.n = FXS_PARTICLES_MAX_N + 1;
    CHECK(fxs_engine_encode_particles(&in, 1, &buf, &len, err, sizeof err) < 0, "too many");
    in.n = 10;
    fxs_particles_free(&in);
}

/* ---- textures ------------------------------------------------------------------------ */

static void test_texture_round_trip(void)
{
    for (uint32_t ch = 1; ch <= 4; ch += 3) {
        uint32_t w = 37, h = 21;
        float *px = malloc(4 * w * h * ch), *out = NULL;
        for (uint32_t i = 0; i < w * h * ch; i++) px[i] = (float)(rnd() * 4 - 1);
        px[5] = 1e6f;
        uint8_t *buf = NULL;
        size_t len;
        char err[200] = "";
        struct fxs_engine_info info;
        CHECK(fxs_engine_encode_texture(px, w, h, ch, 1, &buf, &len, err, sizeof err) == 0, "%s", err);
        CHECK(buf && fxs_engine_decode_texture(buf, len, &info, &out, err, sizeof err) == 0, "%s", err);
        CHECK(info.width == w && info.height == h && info.format == (ch == 4 ? 1u : 2u) && info.count == 0, "header");
        int bad = 0;
        for (uint32_t i = 0; out && i < w * h * ch; i++) bad += out[i] != fxs_half_to_float(fxs_half_from_float(px[i]));
        CHECK(bad == 0 && out && isinf(out[5]), "%d texels differ from their halves", bad);
        free(out);
        free(buf);
        free(px);
    }
    uint8_t *buf = NULL;
    size_t len;
    char err[200];
    float one = 1;
    CHECK(fxs_engine_encode_texture(&one, 1, 1, 3, 1, &buf, &len, err, sizeof err) < 0, "3 channels");
    CHECK(fxs_engine_encode_texture(&one, 0, 1, 1, 1, &buf, &len, err, sizeof err) < 0, "width 0");
    CHECK(fxs_engine_encode_texture(&one, 8192, 4096, 1, 1, &buf, &len, err, sizeof err) < 0, "2^25 texels");
}

/* ---- malformed payloads -------------------------------------------------------------- */

static int decodes(const uint8_t *buf, size_t len, char *err, size_t cap)
{
    struct fxs_particles p;
    if (fxs_engine_decode_particles(buf, len, &p, err, cap)) return 0;
    fxs_particles_free(&p);
    return 1;
}

/* A copy of the payload with the u32 at off replaced. */
static int decodes_with_u32(const uint8_t *buf, size_t len, size_t off, uint32_t v, char *err, size_t cap)
{
    uint8_t *c = malloc(len);
    memcpy(c, buf, len);
    fxs_put_u32(c + off, v);
    int ok = decodes(c, len, err, cap);
    free(c);
    return ok;
}

static void test_malformed(void)
{
    struct fxs_particles in = make_set(300, true, 0.0, 0.2);
    uint8_t *buf = NULL, *c;
    size_t len;
    char err[200];
    fxs_engine_encode_particles(&in, 1, &buf, &len, err, sizeof err);
    fxs_particles_free(&in);
    if (!buf) return;
    CHECK(decodes(buf, len, err, sizeof err), "the intact payload: %s", err);
    int cut_ok = 0;
    for (size_t n = 0; n < len; n++) {
        c = malloc(n ? n : 1); /* exactly n bytes, so a read past them is a sanitizer error */
        memcpy(c, buf, n);
        cut_ok += decodes(c, n, err, sizeof err);
        free(c);
    }
    CHECK(cut_ok == 0, "%d cut payloads decoded", cut_ok);
    c = malloc(len + 1);
    memcpy(c, buf, len);
    c[len] = 0;
    CHECK(!decodes(c, len + 1, err, sizeof err) && strstr(err, "zstd"), "a trailing byte: %s", err);
    c[0] = 'X';
    CHECK(!decodes(c, len, err, sizeof err) && strstr(err, "magic"), "magic: %s", err);
    c[0] = 'F';
    fxs_put_u16(c + 4, 2);
    CHECK(!decodes(c, len, err, sizeof err) && strstr(err, "version"), "version: %s", err);
    fxs_put_u16(c + 4, 1);
    fxs_put_u16(c + 8, 7);
    CHECK(!decodes(c, len, err, sizeof err) && strstr(err, "format"), "format: %s", err);
    fxs_put_u16(c + 8, FXS_ENGINE_R16F);
    CHECK(!decodes(c, len, err, sizeof err), "R16F particles: %s", err);
    fxs_put_u16(c + 8, 1);
    fxs_put_u16(c + 6, 48);
    CHECK(!decodes(c, len, err, sizeof err) && strstr(err, "header_bytes"), "header_bytes 40: %s", err);
    fxs_put_u16(c + 6, 64);
    fxs_put_u16(c + 10, 1);
    CHECK(!decodes(c, len, err, sizeof err) && strstr(err, "layers"), "one layer with the velocity flag: %s", err);
    free(c);
    CHECK(!decodes_with_u32(buf, len, 12, 65535, err, sizeof err) && strstr(err, "texels"), "absurd width: %s", err);
    CHECK(!decodes_with_u32(buf, len, 16, 0, err, sizeof err), "height 0: %s", err);
    CHECK(!decodes_with_u32(buf, len, 12, 512, err, sizeof err) && strstr(err, "raw_bytes"), "wrong width: %s", err);
    CHECK(!decodes_with_u32(buf, len, 20, 1025, err, sizeof err) && strstr(err, "count"), "count beyond the image: %s", err);
    CHECK(!decodes_with_u32(buf, len, 24, 2 * 1024 * 8 - 2, err, sizeof err), "raw_bytes off by 2: %s", err);
    CHECK(!decodes_with_u32(buf, len, 28, (uint32_t)len, err, sizeof err), "zstd_bytes: %s", err);
    CHECK(!decodes_with_u32(buf, len, 56, 3, err, sizeof err) && strstr(err, "flags"), "unknown flag: %s", err);
    CHECK(!decodes_with_u32(buf, len, 32, 0x7f800000u, err, sizeof err) && strstr(err, "origin"), "infinite origin: %s", err);
    CHECK(!decodes_with_u32(buf, len, 48, 0xbf800000u, err, sizeof err) && strstr(err, "extent"), "negative extent: %s", err);
    free(buf);
}

/* A particle whose half is NaN (hand-made payload) is rejected; a texture may hold infinities. */
static void test_nonfinite_particle(void)
{
    uint8_t raw[1024 * 8] = {0};
    fxs_put_u16(raw + 2, 0x7e00);
    struct fxs_engine_info in = {.format = 1, .layers = 1, .width = 1024, .height = 1, .count = 1, .raw_bytes = sizeof raw};
    uint8_t buf[64 + 512];
    size_t z = ZSTD_compress(buf + 64, sizeof buf - 64, raw, sizeof raw, 1);
    memset(buf, 0, 64);
    memcpy(buf, "FXE1", 4);
    fxs_put_u16(buf + 4, 1);
    fxs_put_u16(buf + 6, 64);
    fxs_put_u16(buf + 8, (uint16_t)in.format);
    fxs_put_u16(buf + 10, 1);
    fxs_put_u32(buf + 12, 1024);
    fxs_put_u32(buf + 16, 1);
    fxs_put_u32(buf + 20, 1);
    fxs_put_u32(buf + 24, sizeof raw);
    fxs_put_u32(buf + 28, (uint32_t)z);
    char err[200] = "";
    CHECK(!ZSTD_isError(z) && !decodes(buf, 64 + z, err, sizeof err) && strstr(err, "not finite"), "NaN particle: %s", err);
    fxs_put_u32(buf + 20, 0); /* count 0: the NaN is padding, never read */
    CHECK(decodes(buf, 64 + z, err, sizeof err), "padding is not read: %s", err);
}

int main(void)
{
    RUN(test_half_exhaustive);
    RUN(test_half_rounding);
    RUN(test_particles_round_trip);
    RUN(test_particles_layout);
    RUN(test_particles_encoder_rejects);
    RUN(test_texture_round_trip);
    RUN(test_malformed);
    RUN(test_nonfinite_particle);
    return CHECK_DONE();
}
