/* test_exr.c — exr_write_mem checked by reading its files back with OpenEXRCore.
 *
 * Every file is parsed from memory (custom read_fn, no temporary files) and decoded
 * to raw half bits with the exr_decoding_* pipeline, so the checks see exactly what
 * any EXR reader sees: header (channels, windows, line order, compression), chunk
 * order, and pixels. Expected halves come from an independent float->half reference
 * written here with double arithmetic (round to nearest even, overflow to inf).
 * Lossless codecs (none, rle, zips, zip, piz, and pxr24, which only rounds 32-bit
 * floats) must match bit for bit; b44/b44a must stay within the error their 4x4
 * block quantisation allows. exr_rle.c's compressor must give a plain reference's bytes
 * (OpenEXR's RLE written here step by step). Last, `exrheader` must accept the files. */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <openexr.h>

#include "check.h"
#include "exr.h"
#include "exr_rle.h"

#define TEST_NCODECS (EXR_CODEC_B44A + 1)

/* ---- independent half reference ---- */

static uint16_t test_half_bits_of_value(double v) /* v >= 0, exactly representable */
{
    if (v < 0x1p-14) return (uint16_t)(v * 0x1p24); /* subnormal (or zero) */
    int e;
    double m = frexp(v, &e); /* v = m * 2^e, m in [0.5, 1) */
    return (uint16_t)(((e - 1 + 15) << 10) | ((int)(m * 2048.0) - 1024));
}

/* Float to half bits: round to nearest even, overflow to inf, NaN stays NaN. */
static uint16_t test_half(float f)
{
    uint16_t sign = signbit(f) ? 0x8000 : 0;
    double a = fabs((double)f);
    if (isnan(f)) return 0x7e00;
    if (a < 0x1p-14) return sign | test_half_bits_of_value(rint(a * 0x1p24) * 0x1p-24);
    int e;
    frexp(a, &e);
    double ulp = ldexp(1.0, e - 11), r = rint(a / ulp) * ulp;
    if (r > 65504.0) return sign | 0x7c00;
    return sign | test_half_bits_of_value(r);
}

static double test_half_value(uint16_t h)
{
    int e = (h >> 10) & 0x1f, m = h & 0x3ff;
    double v = e == 0 ? ldexp(m, -24) : e == 31 ? (m ? NAN : INFINITY) : ldexp(1024 + m, e - 25);
    return (h & 0x8000) ? -v : v;
}

static int test_half_is_nan(uint16_t h) { return (h & 0x7c00) == 0x7c00 && (h & 0x3ff); }

/* ---- reading a file back ---- */

struct test_src {
    const uint8_t *data;
    size_t len;
};

static int64_t test_read(exr_const_context_t ctxt, void *userdata, void *buffer, uint64_t sz, uint64_t offset,
                         exr_stream_error_func_ptr_t error_cb)
{
    const struct test_src *src = userdata;
    (void)ctxt, (void)error_cb;
    if (offset >= src->len) return 0;
    size_t n = sz < src->len - offset ? (size_t)sz : src->len - (size_t)offset;
    memcpy(buffer, src->data + offset, n);
    return (int64_t)n;
}

static int64_t test_size(exr_const_context_t ctxt, void *userdata)
{
    (void)ctxt;
    return (int64_t)((const struct test_src *)userdata)->len;
}

static exr_context_t test_open(struct test_src *src)
{
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.user_data = src;
    init.read_fn = test_read;
    init.size_fn = test_size;
    exr_context_t ctxt = NULL;
    exr_result_t rv = exr_start_read(&ctxt, "memory.exr", &init);
    CHECK(rv == EXR_ERR_SUCCESS, "exr_start_read: %s", exr_get_default_error_message(rv));
    return rv == EXR_ERR_SUCCESS ? ctxt : NULL;
}

static int test_channel_offset(const char *name)
{
    return name[0] == 'G' ? 1 : name[0] == 'B' ? 2 : name[0] == 'A' ? 3 : 0;
}

static void test_bind_decode(exr_decode_pipeline_t *d, uint16_t *out, int width, int channels, int y)
{
    size_t row = (size_t)width * (size_t)channels;
    for (int c = 0; c < d->channel_count; c++) {
        exr_coding_channel_info_t *ch = &d->channels[c];
        ch->user_data_type = EXR_PIXEL_HALF;
        ch->user_bytes_per_element = 2;
        ch->user_pixel_stride = 2 * channels;
        ch->user_line_stride = (int32_t)(2 * row);
        ch->decode_to_ptr = (uint8_t *)(out + (size_t)y * row + test_channel_offset(ch->channel_name));
    }
}

static exr_result_t test_decode_chunk(exr_context_t ctxt, exr_decode_pipeline_t *d, uint16_t *out, int width,
                                      int channels, int y)
{
    exr_chunk_info_t ci;
    int first = d->channels == NULL;
    exr_result_t rv = exr_read_scanline_chunk_info(ctxt, 0, y, &ci);
    if (rv == EXR_ERR_SUCCESS)
        rv = first ? exr_decoding_initialize(ctxt, 0, &ci, d) : exr_decoding_update(ctxt, 0, &ci, d);
    if (rv != EXR_ERR_SUCCESS) return rv;
    test_bind_decode(d, out, width, channels, y);
    if (first) rv = exr_decoding_choose_default_routines(ctxt, 0, d);
    return rv == EXR_ERR_SUCCESS ? exr_decoding_run(ctxt, 0, d) : rv;
}

/* Decodes the whole image into interleaved half bits (R,G,B,A or Y per texel). */
static int test_decode(exr_context_t ctxt, uint16_t *out, int width, int height, int channels)
{
    exr_decode_pipeline_t d = EXR_DECODE_PIPELINE_INITIALIZER;
    int32_t lines = 0;
    exr_result_t rv = exr_get_scanlines_per_chunk(ctxt, 0, &lines);
    for (int y = 0; rv == EXR_ERR_SUCCESS && y < height; y += lines)
        rv = test_decode_chunk(ctxt, &d, out, width, channels, y);
    if (d.channels) exr_decoding_destroy(ctxt, &d);
    CHECK(rv == EXR_ERR_SUCCESS, "decode: %s", exr_get_default_error_message(rv));
    return rv == EXR_ERR_SUCCESS ? 0 : -1;
}

/* ---- images ---- */

static uint32_t test_rng = 12345;

static double test_uniform(void)
{
    test_rng = test_rng * 1664525u + 1013904223u;
    return (test_rng >> 8) * 0x1p-24;
}

/* Values across the whole half range: signs, subnormals, HDR, some overflow to inf. */
static float *test_noise_image(int width, int height, int channels)
{
    size_t n = (size_t)width * height * channels;
    float *px = malloc(sizeof(float) * n);
    for (size_t i = 0; i < n; i++) {
        double mag = ldexp(1.0 + test_uniform(), (int)floor(test_uniform() * 42.0) - 26);
        px[i] = (float)(test_uniform() < 0.2 ? -mag : mag);
    }
    return px;
}

/* A smooth HDR glow (0 .. ~8) like the effects produce; channel c is scaled by 1+c/3. */
static float *test_smooth_image(int width, int height, int channels)
{
    float *px = malloc(sizeof(float) * (size_t)width * height * channels);
    for (int y = 0; y < height; y++)
        for (int x = 0; x < width; x++) {
            double u = (x + 0.5) / width, v = (y + 0.5) / height;
            double g = 0.05 / (fabs(v - 0.5 - 0.2 * sin(6.0 * u)) + 0.01) + 0.1 * u;
            for (int c = 0; c < channels; c++)
                px[((size_t)y * width + x) * channels + c] = (float)(g * (1.0 + c / 3.0));
        }
    return px;
}

static int test_write(const float *px, int width, int height, int channels, int codec, struct fx_buf *out)
{
    struct exr_image img = {width, height, channels, px, codec};
    struct fx_err err = {0};
    out->len = 0;
    int rc = exr_write_mem(&img, out, &err);
    CHECK(rc == 0, "exr_write_mem %dx%d c%d %s: %s", width, height, channels, exr_codec_names[codec], err.message);
    return rc;
}

/* Writes, reads back and decodes; returns the decoded halves (caller frees) or NULL. */
static uint16_t *test_round_trip(const float *px, int width, int height, int channels, int codec)
{
    struct fx_buf out = {0};
    uint16_t *dec = NULL;
    if (test_write(px, width, height, channels, codec, &out) == 0) {
        struct test_src src = {out.data, out.len};
        exr_context_t ctxt = test_open(&src);
        dec = calloc((size_t)width * height * channels, sizeof *dec);
        if (!ctxt || test_decode(ctxt, dec, width, height, channels)) {
            free(dec);
            dec = NULL;
        }
        if (ctxt) exr_finish(&ctxt);
    }
    fx_buf_free(&out);
    return dec;
}

/* Number of texels whose decoded half differs from the reference conversion. */
static size_t test_exact_mismatches(const float *px, const uint16_t *dec, size_t n)
{
    size_t bad = 0;
    for (size_t i = 0; i < n; i++) {
        uint16_t want = test_half(px[i]);
        int same = test_half_is_nan(want) ? test_half_is_nan(dec[i]) : dec[i] == want;
        if (!same && bad++ < 3)
            fprintf(stderr, "  texel value %d: %.9g -> %#06x, want %#06x\n", (int)i, px[i], dec[i], want);
    }
    return bad;
}

static int test_lossless(int codec) { return codec != EXR_CODEC_B44 && codec != EXR_CODEC_B44A; }

/* ---- tests ---- */

static void test_codec_names(void)
{
    static const char *const want[] = {"none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a"};
    for (int c = 0; c < TEST_NCODECS; c++)
        CHECK(exr_codec_names[c] && strcmp(exr_codec_names[c], want[c]) == 0, "name %d", c);
    CHECK(exr_codec_names[TEST_NCODECS] == NULL, "names end with NULL");
    static const int lib[][2] = {
        {EXR_CODEC_NONE, EXR_COMPRESSION_NONE}, {EXR_CODEC_RLE, EXR_COMPRESSION_RLE},
        {EXR_CODEC_ZIPS, EXR_COMPRESSION_ZIPS}, {EXR_CODEC_ZIP, EXR_COMPRESSION_ZIP},
        {EXR_CODEC_PIZ, EXR_COMPRESSION_PIZ},   {EXR_CODEC_PXR24, EXR_COMPRESSION_PXR24},
        {EXR_CODEC_B44, EXR_COMPRESSION_B44},   {EXR_CODEC_B44A, EXR_COMPRESSION_B44A},
    };
    for (int c = 0; c < TEST_NCODECS; c++) CHECK(lib[c][0] == lib[c][1], "%s numbered as OpenEXR", want[c]);
}

static void test_check_header(exr_context_t ctxt, int width, int height, int channels, int codec)
{
    const exr_attr_chlist_t *cl = NULL;
    exr_attr_box2i_t dw, disp;
    exr_lineorder_t lo = EXR_LINEORDER_LAST_TYPE;
    exr_compression_t comp = EXR_COMPRESSION_LAST_TYPE;
    exr_storage_t st = EXR_STORAGE_LAST_TYPE;
    int parts = 0;
    CHECK(exr_get_count(ctxt, &parts) == EXR_ERR_SUCCESS && parts == 1, "parts %d", parts);
    CHECK(exr_get_storage(ctxt, 0, &st) == EXR_ERR_SUCCESS && st == EXR_STORAGE_SCANLINE, "storage %d", st);
    CHECK(exr_get_channels(ctxt, 0, &cl) == EXR_ERR_SUCCESS && cl->num_channels == channels, "channel count");
    const char *names = channels == 4 ? "ABGR" : "Y";
    for (int c = 0; cl && c < cl->num_channels && c < channels; c++) {
        const exr_attr_chlist_entry_t *e = &cl->entries[c];
        CHECK(strlen(e->name.str) == 1 && e->name.str[0] == names[c], "channel %d is %s", c, e->name.str);
        CHECK(e->pixel_type == EXR_PIXEL_HALF && e->x_sampling == 1 && e->y_sampling == 1, "channel %s", e->name.str);
    }
    CHECK(exr_get_data_window(ctxt, 0, &dw) == EXR_ERR_SUCCESS && dw.min.x == 0 && dw.min.y == 0 &&
              dw.max.x == width - 1 && dw.max.y == height - 1,
          "data window (%d %d)-(%d %d)", dw.min.x, dw.min.y, dw.max.x, dw.max.y);
    CHECK(exr_get_display_window(ctxt, 0, &disp) == EXR_ERR_SUCCESS && memcmp(&disp, &dw, sizeof dw) == 0,
          "display window = data window");
    CHECK(exr_get_lineorder(ctxt, 0, &lo) == EXR_ERR_SUCCESS && lo == EXR_LINEORDER_INCREASING_Y, "line order %d", lo);
    CHECK(exr_get_compression(ctxt, 0, &comp) == EXR_ERR_SUCCESS && (int)comp == codec, "compression %d", comp);
}

static void test_headers(void)
{
    float *px = test_smooth_image(37, 19, 4);
    struct fx_buf out = {0};
    for (int codec = 0; codec < TEST_NCODECS; codec++)
        for (int channels = 1; channels <= 4; channels += 3) {
            if (test_write(px, 37, 19, channels, codec, &out)) continue;
            struct test_src src = {out.data, out.len};
            CHECK(out.len > 4 && memcmp(out.data, "\x76\x2f\x31\x01", 4) == 0, "EXR magic");
            exr_context_t ctxt = test_open(&src);
            if (ctxt) test_check_header(ctxt, 37, 19, channels, codec);
            if (ctxt) exr_finish(&ctxt);
        }
    fx_buf_free(&out);
    free(px);
}

/* Every lossless codec reproduces the reference halves bit for bit. */
static void test_lossless_exact_size(int width, int height)
{
    for (int channels = 1; channels <= 4; channels += 3) {
        float *px = test_noise_image(width, height, channels);
        size_t n = (size_t)width * height * channels;
        for (int codec = 0; codec < TEST_NCODECS; codec++) {
            if (!test_lossless(codec)) continue;
            uint16_t *dec = test_round_trip(px, width, height, channels, codec);
            CHECK(dec && test_exact_mismatches(px, dec, n) == 0, "%dx%d c%d %s exact", width, height, channels,
                  exr_codec_names[codec]);
            free(dec);
        }
        free(px);
    }
}

static void test_lossless_exact(void)
{
    test_lossless_exact_size(37, 19);
    test_lossless_exact_size(1, 1);
    test_lossless_exact_size(64, 48);
    test_lossless_exact_size(3, 130);
}

/* The float->half conversion: rounding, overflow, NaN, subnormals, HDR kept unclamped. */
static void test_special_values(void)
{
    static const float v[] = {0.0f, -0.0f, 1.0f, 1.5f, 5.0f, 100.0f, 1000.0f, 60000.0f, 65504.0f,
                              65519.0f, 65520.0f, 1e6f, -1e6f, INFINITY, -INFINITY, NAN,
                              1.0f + 0x1p-11f, 1.0f + 3 * 0x1p-11f, 0x1p-24f, 0x1p-25f, 0x1.8p-25f, 1e-9f,
                              -2.5f, 0.1f, 3.14159265f, 0x1p-14f};
    enum { N = sizeof v / sizeof v[0] };
    static const uint16_t want[N] = {0x0000, 0x8000, 0x3c00, 0x3e00, 0x4500, 0x5640, 0x63d0, 0x7b53,
                                     0x7bff, 0x7bff, 0x7c00, 0x7c00, 0xfc00, 0x7c00, 0xfc00, 0x7e00,
                                     0x3c00, 0x3c02, 0x0001, 0x0000, 0x0001, 0x0000,
                                     0xc100, 0x2e66, 0x4248, 0x0400};
    for (int i = 0; i < N; i++)
        CHECK(test_half(v[i]) == want[i], "reference half(%.9g) = %#06x, want %#06x", v[i], test_half(v[i]), want[i]);
    for (int codec = 0; codec < TEST_NCODECS; codec++) {
        if (!test_lossless(codec)) continue;
        uint16_t *dec = test_round_trip(v, N, 1, 1, codec);
        for (int i = 0; dec && i < N; i++)
            CHECK(test_half_is_nan(want[i]) ? test_half_is_nan(dec[i]) : dec[i] == want[i],
                  "%s: %.9g -> %#06x, want %#06x", exr_codec_names[codec], v[i], dec[i], want[i]);
        CHECK(dec && test_half_value(dec[7]) > 59000.0, "%s keeps HDR 60000", exr_codec_names[codec]);
        free(dec);
    }
}

/* Half bits as a monotonic integer (B44's own ordering). */
static int test_ordered(uint16_t h) { return (h & 0x8000) ? (~h & 0xffff) : (h | 0x8000); }

/* B44 rounds each value of a 4x4 block to a multiple of 2^s in ordered-half units, with
 * the smallest s that keeps neighbour differences within 6 bits; so the error is at
 * most max(1, range/15) ordered units, range being the block's max - min. */
static int test_b44_block_ok(const float *px, const uint16_t *dec, int width, int height, int channels, int bx,
                             int by, int c)
{
    int lo = 1 << 17, hi = -1, worst = 0;
    for (int y = by; y < by + 4 && y < height; y++)
        for (int x = bx; x < bx + 4 && x < width; x++) {
            int t = test_ordered(test_half(px[((size_t)y * width + x) * channels + c]));
            lo = t < lo ? t : lo;
            hi = t > hi ? t : hi;
        }
    for (int y = by; y < by + 4 && y < height; y++)
        for (int x = bx; x < bx + 4 && x < width; x++) {
            size_t i = ((size_t)y * width + x) * channels + c;
            int e = abs(test_ordered(dec[i]) - test_ordered(test_half(px[i])));
            worst = e > worst ? e : worst;
        }
    int ok = 15 * worst <= (hi - lo > 15 ? hi - lo : 15);
    if (!ok) fprintf(stderr, "  block (%d,%d) c%d: error %d units, range %d\n", bx, by, c, worst, hi - lo);
    return ok;
}

static int test_b44_bad_blocks(const float *px, const uint16_t *dec, int width, int height, int channels)
{
    int bad = 0;
    for (int by = 0; by < height; by += 4)
        for (int bx = 0; bx < width; bx += 4)
            for (int c = 0; c < channels; c++)
                bad += !test_b44_block_ok(px, dec, width, height, channels, bx, by, c);
    return bad;
}

static double test_max_rel_error(const float *px, const uint16_t *dec, size_t n)
{
    double worst = 0;
    for (size_t i = 0; i < n; i++) {
        double e = fabs(test_half_value(dec[i]) - px[i]) / fabs(px[i]);
        worst = e > worst ? e : worst;
    }
    return worst;
}

static void test_b44_bounded_size(int width, int height)
{
    for (int channels = 1; channels <= 4; channels += 3) {
        float *px = test_smooth_image(width, height, channels);
        size_t n = (size_t)width * height * channels;
        for (int codec = EXR_CODEC_B44; codec <= EXR_CODEC_B44A; codec++) {
            uint16_t *dec = test_round_trip(px, width, height, channels, codec);
            CHECK(dec && test_b44_bad_blocks(px, dec, width, height, channels) == 0, "%dx%d c%d %s bound",
                  width, height, channels, exr_codec_names[codec]);
            /* and, on these smooth frames, a few percent at most (peaks are steep at 37x19) */
            CHECK(dec && test_max_rel_error(px, dec, n) < 0.04, "%dx%d c%d %s: rel error %.4f", width, height,
                  channels, exr_codec_names[codec], dec ? test_max_rel_error(px, dec, n) : -1.0);
            free(dec);
        }
        free(px);
    }
}

static void test_b44_bounded(void)
{
    test_b44_bounded_size(37, 19);
    test_b44_bounded_size(1, 1);
    test_b44_bounded_size(128, 64);
}

/* b44a stores flat blocks exactly and in fewer bytes than b44. */
static void test_b44a_flat(void)
{
    float *px = malloc(sizeof(float) * 64 * 64);
    for (int i = 0; i < 64 * 64; i++) px[i] = i < 64 * 32 ? 2.75f : 7.5f;
    struct fx_buf b44 = {0}, b44a = {0};
    test_write(px, 64, 64, 1, EXR_CODEC_B44, &b44);
    test_write(px, 64, 64, 1, EXR_CODEC_B44A, &b44a);
    CHECK(b44a.len < b44.len, "b44a %zu bytes, b44 %zu", b44a.len, b44.len);
    uint16_t *dec = test_round_trip(px, 64, 64, 1, EXR_CODEC_B44A);
    CHECK(dec && test_exact_mismatches(px, dec, 64 * 64) == 0, "flat blocks exact");
    free(dec);
    fx_buf_free(&b44);
    fx_buf_free(&b44a);
    free(px);
}

/* Input row 0 is y 0, the first (top) scanline, stored first in the file. */
static void test_row0_top(void)
{
    enum { W = 5, H = 70 };
    float px[W * H * 4];
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++)
            for (int c = 0; c < 4; c++) px[(y * W + x) * 4 + c] = (float)(100 * c + y) + 0.25f * x;
    for (int codec = 0; codec < TEST_NCODECS; codec++) {
        if (!test_lossless(codec)) continue;
        uint16_t *dec = test_round_trip(px, W, H, 4, codec);
        CHECK(dec && test_half_value(dec[0]) == 0.0 && test_half_value(dec[3]) == 300.0, "%s top-left RGBA",
              exr_codec_names[codec]);
        CHECK(dec && test_half_value(dec[(H - 1) * W * 4 + 1]) == 100.0 + H - 1, "%s bottom row G",
              exr_codec_names[codec]);
        CHECK(dec && test_half_value(dec[1 * 4 + 2]) == 200.25, "%s (1,0) B", exr_codec_names[codec]);
        free(dec);
    }
}

/* Chunks appear in the file in increasing y, the first one holding y 0. */
static void test_chunk_order(void)
{
    float *px = test_smooth_image(16, 100, 1);
    struct fx_buf out = {0};
    for (int codec = 0; codec < TEST_NCODECS && test_write(px, 16, 100, 1, codec, &out) == 0; codec++) {
        struct test_src src = {out.data, out.len};
        exr_context_t ctxt = test_open(&src);
        int32_t lines = 0;
        uint64_t prev = 0;
        if (ctxt) exr_get_scanlines_per_chunk(ctxt, 0, &lines);
        for (int y = 0; ctxt && lines > 0 && y < 100; y += lines) {
            exr_chunk_info_t ci;
            CHECK(exr_read_scanline_chunk_info(ctxt, 0, y, &ci) == EXR_ERR_SUCCESS && ci.start_y == y &&
                      ci.data_offset > prev,
                  "%s chunk at y %d", exr_codec_names[codec], y);
            prev = ci.data_offset;
        }
        if (ctxt) exr_finish(&ctxt);
    }
    fx_buf_free(&out);
    free(px);
}

static void test_large_one(int channels, int codec)
{
    enum { S = 2048 };
    float *px = test_smooth_image(S, S, channels);
    uint16_t *dec = test_round_trip(px, S, S, channels, codec);
    CHECK(dec && test_exact_mismatches(px, dec, (size_t)S * S * channels) == 0, "2048x2048 c%d %s", channels,
          exr_codec_names[codec]);
    free(dec);
    free(px);
}

static void test_large(void)
{
    test_large_one(1, EXR_CODEC_ZIP);
    test_large_one(4, EXR_CODEC_PIZ);
}

/* The file is appended after what out already holds, which is left intact. */
static void test_append_and_reuse(void)
{
    float *px = test_smooth_image(37, 19, 4);
    struct exr_image img = {37, 19, 4, px, EXR_CODEC_ZIP};
    struct fx_buf out = {0}, again = {0};
    struct fx_err err;
    fx_buf_append(&out, "prefix", 6);
    CHECK(exr_write_mem(&img, &out, &err) == 0, "%s", err.message);
    CHECK(memcmp(out.data, "prefix", 6) == 0, "prefix kept");
    test_write(px, 37, 19, 4, EXR_CODEC_ZIP, &again);
    CHECK(out.len == again.len + 6 && memcmp(out.data + 6, again.data, again.len) == 0, "same file after prefix");
    size_t first = again.len;
    test_write(px, 37, 19, 4, EXR_CODEC_ZIP, &again); /* reused buffer, len reset */
    CHECK(again.len == first && memcmp(out.data + 6, again.data, first) == 0, "deterministic on reuse");
    fx_buf_free(&out);
    fx_buf_free(&again);
    free(px);
}

static void test_bad_input(void)
{
    float px[16] = {0};
    struct exr_image bad[] = {
        {4, 4, 3, px, EXR_CODEC_ZIP}, {4, 4, 1, px, 8},  {4, 4, 1, px, -1},
        {0, 4, 1, px, EXR_CODEC_ZIP}, {4, -1, 1, px, 0}, {4, 4, 1, NULL, 0},
    };
    struct fx_buf out = {0};
    fx_buf_append(&out, "xy", 2);
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        struct fx_err err = {0};
        CHECK(exr_write_mem(&bad[i], &out, &err) == -1, "bad image %zu rejected", i);
        CHECK(strcmp(err.code, "internal") == 0 && err.message[0], "bad image %zu: code '%s'", i, err.code);
        CHECK(out.len == 2, "bad image %zu leaves out alone", i);
    }
    fx_buf_free(&out);
}

/* ---- exrheader ---- */

static int test_have_exrheader(void)
{
    const char *path = getenv("PATH");
    char dir[4096], full[4200];
    snprintf(dir, sizeof dir, "%s", path ? path : "/usr/bin:/bin");
    for (char *save = NULL, *d = strtok_r(dir, ":", &save); d; d = strtok_r(NULL, ":", &save)) {
        snprintf(full, sizeof full, "%s/exrheader", d);
        if (access(full, X_OK) == 0) return 1;
    }
    return 0;
}

/* Runs exrheader on data; returns its exit status and keeps its output in text. */
static int test_exrheader_run(const struct fx_buf *file, char *text, size_t cap)
{
    char path[] = "/tmp/test_exr_XXXXXX", cmd[128];
    int fd = mkstemp(path);
    if (fd < 0) return -1;
    ssize_t w = write(fd, file->data, file->len);
    close(fd);
    snprintf(cmd, sizeof cmd, "exrheader %s 2>&1", path);
    FILE *p = w == (ssize_t)file->len ? popen(cmd, "r") : NULL;
    size_t n = p ? fread(text, 1, cap - 1, p) : 0;
    text[n] = 0;
    int status = p ? pclose(p) : -1;
    unlink(path);
    return status;
}

static void test_exrheader(void)
{
    if (!test_have_exrheader()) {
        printf("note: exrheader not installed (Debian package openexr), skipping its check\n");
        return;
    }
    float *px = test_smooth_image(37, 19, 4);
    struct fx_buf out = {0};
    static char text[8192];
    for (int codec = 0; codec < TEST_NCODECS; codec++) {
        if (test_write(px, 37, 19, 4, codec, &out)) continue;
        int status = test_exrheader_run(&out, text, sizeof text);
        CHECK(status == 0, "exrheader %s exit %d: %s", exr_codec_names[codec], status, text);
        CHECK(strstr(text, "dataWindow (type box2i): (0 0) - (36 18)"), "%s: %s", exr_codec_names[codec], text);
        CHECK(strstr(text, "increasing y") && strstr(text, "R, 16-bit floating-point"), "%s: %s",
              exr_codec_names[codec], text);
    }
    fx_buf_free(&out);
    free(px);
}

/* ---- RLE against a plain reference ---- */

/* OpenEXR's RLE of src[0..n) into out, step by step: even bytes then odd bytes; each but the
 * first minus the one before plus 128; runs of 3 to 128 equal bytes as (length - 1, byte),
 * else literals of up to 127 bytes, each ending where 3 equal bytes begin; the raw bytes when
 * that is not smaller. */
static size_t test_rle_ref(const uint8_t *src, size_t n, uint8_t *out)
{
    uint8_t *t = malloc(n + 1);
    size_t h = (n + 1) / 2, o = 0;
    for (size_t i = 0; i < n; i++) t[i % 2 ? h + i / 2 : i / 2] = src[i];
    for (size_t i = n; i-- > 1;) t[i] = (uint8_t)(t[i] - t[i - 1] + 128);
    for (size_t i = 0; i < n;) {
        size_t run = 1;
        while (i + run < n && run < 128 && t[i + run] == t[i]) run++;
        if (run >= 3) {
            out[o++] = (uint8_t)(run - 1);
            out[o++] = t[i];
            i += run;
            continue;
        }
        size_t j = i + run;
        while (j < n && j - i < 127 && !(j + 2 < n && t[j] == t[j + 1] && t[j + 1] == t[j + 2])) j++;
        out[o++] = (uint8_t)-(int)(j - i);
        memcpy(out + o, t + i, j - i);
        o += j - i;
        i = j;
    }
    free(t);
    if (o < n) return o;
    memcpy(out, src, n);
    return n;
}

/* n bytes of runs of random lengths (1 to 300, mostly short) over a small alphabet, so that
 * runs, pairs and literals of every length meet, and their differences repeat too. */
static void test_rle_bytes(uint8_t *b, size_t n, unsigned *seed)
{
    for (size_t i = 0; i < n;) {
        unsigned r = (unsigned)rand_r(seed);
        size_t len = r % 8 == 0 ? 1 + (size_t)(r >> 8) % 300 : 1 + (size_t)(r >> 8) % 4;
        uint8_t v = (uint8_t)(r % 3 == 0 ? (r >> 16) : (r >> 16) % 4);
        for (; len-- && i < n; i++) b[i] = v;
    }
}

static void test_rle_reference(void)
{
    enum { N = 4096 };
    static uint8_t src[N], scratch[N], got[EXR_RLE_OUT(N)], want[EXR_RLE_OUT(N)];
    unsigned seed = 7;
    int bad = 0, compressed = 0, raw = 0;
    for (int k = 0; k < 3000; k++) {
        size_t n = k < 40 ? (size_t)k : 1 + (size_t)rand_r(&seed) % N;
        test_rle_bytes(src, n, &seed);
        if (k % 5 == 4) /* incompressible */
            for (size_t i = 0; i < n; i++) src[i] = (uint8_t)rand_r(&seed);
        size_t g = exr_rle_compress(src, n, scratch, got), w = test_rle_ref(src, n, want);
        bad += g != w || memcmp(got, want, w);
        compressed += n && w < n;
        raw += n && w == n;
    }
    CHECK(bad == 0, "exr_rle_compress differs from the reference on %d of 3000 inputs", bad);
    CHECK(compressed > 1000 && raw > 500, "inputs: %d compressed, %d stored raw", compressed, raw);
}

int main(void)
{
    RUN(test_codec_names);
    RUN(test_headers);
    RUN(test_lossless_exact);
    RUN(test_special_values);
    RUN(test_b44_bounded);
    RUN(test_b44a_flat);
    RUN(test_row0_top);
    RUN(test_chunk_order);
    RUN(test_rle_reference);
    RUN(test_large);
    RUN(test_append_and_reuse);
    RUN(test_bad_input);
    RUN(test_exrheader);
    return CHECK_DONE();
}
