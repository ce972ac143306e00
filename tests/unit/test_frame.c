/* test_frame.c — the 64-byte binary frame header of fxstream.v1 (protocol/fxs_frame.h).
 *
 * The header is the one thing every client parses (and the daemon's frames, server/frame.h,
 * carry a subset's total at offset 60), so the tests pin it to the
 * PROTOCOL.md §7.1 table byte by byte (not only pack/unpack agreeing
 * with each other), round-trip every field at its extremes (sim_time by its bits),
 * and check that malformed frames are rejected while a longer header from a future
 * version is accepted with the payload found after it. Buffers are allocated to
 * their exact length so that ASan/valgrind catch any read past the end. */
#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "frame.h"
#include "fxs_frame.h"

static struct fxs_header test_sample(void)
{
    struct fxs_header h = {0};
    h.kind = 0x0102;
    h.channel = 0x0a0b0c0d;
    h.param_rev = 0x11223344;
    h.seq = 0x0102030405060708ull;
    h.sim_time = 1.5; /* bits 0x3ff8000000000000 */
    h.server_time_us = 0xf1e2d3c4b5a69788ull;
    h.codec = 0x21222324;
    h.payload_bytes = 5;
    h.count_or_width = 0x31323334;
    h.height = 0x41424344;
    h.flags = 0x51525354;
    return h;
}

/* A frame of exactly 64 + payload_bytes bytes on the heap; payload bytes are 0xa5. */
static uint8_t *test_frame(const struct fxs_header *h, size_t *len)
{
    *len = FXS_HEADER_BYTES + h->payload_bytes;
    uint8_t *buf = malloc(*len);
    fxs_header_pack(h, buf);
    memset(buf + FXS_HEADER_BYTES, 0xa5, h->payload_bytes);
    return buf;
}

/* Little-endian value of n bytes at p, read independently of fxs_get_*. */
static uint64_t test_le(const uint8_t *p, int n)
{
    uint64_t v = 0;
    for (int i = 0; i < n; i++) v |= (uint64_t)p[i] << (8 * i);
    return v;
}

static void test_offsets(void)
{
    struct fxs_header h = test_sample();
    uint8_t b[FXS_HEADER_BYTES];
    memset(b, 0xee, sizeof b);
    h.header_bytes = 0; /* ignored by pack: v1 always writes 64 */
    fxs_header_pack(&h, b);
    CHECK(memcmp(b, "FXS1", 4) == 0, "magic");
    CHECK(b[4] == 64 && b[5] == 0, "header_bytes at 4..5: %02x %02x", b[4], b[5]);
    CHECK(b[6] == 0x02 && b[7] == 0x01, "kind at 6..7 little-endian: %02x %02x", b[6], b[7]);
    CHECK(b[8] == 0x0d && b[11] == 0x0a && test_le(b + 8, 4) == h.channel, "channel at 8");
    CHECK(test_le(b + 12, 4) == h.param_rev, "param_rev at 12");
    CHECK(b[16] == 0x08 && b[23] == 0x01 && test_le(b + 16, 8) == h.seq, "seq at 16");
    CHECK(test_le(b + 24, 8) == 0x3ff8000000000000ull, "sim_time bits at 24");
    CHECK(b[32] == 0x88 && test_le(b + 32, 8) == h.server_time_us, "server_time_us at 32");
    CHECK(test_le(b + 40, 4) == h.codec, "codec at 40");
    CHECK(test_le(b + 44, 4) == h.payload_bytes, "payload_bytes at 44");
    CHECK(test_le(b + 48, 4) == h.count_or_width, "count_or_width at 48");
    CHECK(test_le(b + 52, 4) == h.height, "height at 52");
    CHECK(test_le(b + 56, 4) == h.flags, "flags at 56");
    CHECK(test_le(b + 60, 4) == 0, "total at 60 is 0 unless set");
    fxs_header_set_total(b, 0x01020304u);
    CHECK(test_le(b + 60, 4) == 0x01020304u && fxs_header_total(b) == 0x01020304u, "total at 60");
    CHECK(test_le(b + 56, 4) == h.flags, "total leaves flags alone");
}

static int test_same_bits(double a, double b) { return memcmp(&a, &b, sizeof a) == 0; }

static void test_round_trip_one(const struct fxs_header *h)
{
    size_t len;
    uint8_t *buf = test_frame(h, &len);
    struct fxs_header g;
    memset(&g, 0x5a, sizeof g);
    CHECK(fxs_header_unpack(buf, len, &g) == 0, "unpack");
    CHECK(g.header_bytes == FXS_HEADER_BYTES, "header_bytes %u", g.header_bytes);
    CHECK(g.kind == h->kind && g.channel == h->channel && g.param_rev == h->param_rev, "kind/channel/rev");
    CHECK(g.seq == h->seq && g.server_time_us == h->server_time_us, "seq %llu time %llu",
          (unsigned long long)g.seq, (unsigned long long)g.server_time_us);
    CHECK(test_same_bits(g.sim_time, h->sim_time), "sim_time %.17g vs %.17g", g.sim_time, h->sim_time);
    CHECK(g.codec == h->codec && g.payload_bytes == h->payload_bytes, "codec/payload_bytes");
    CHECK(g.count_or_width == h->count_or_width && g.height == h->height && g.flags == h->flags, "size/flags");
    free(buf);
}

static void test_round_trip(void)
{
    struct fxs_header h = test_sample();
    test_round_trip_one(&h);

    h.seq = UINT64_MAX, h.server_time_us = UINT64_MAX, h.kind = UINT16_MAX;
    h.channel = h.param_rev = h.codec = h.count_or_width = h.height = h.flags = UINT32_MAX;
    test_round_trip_one(&h);

    memset(&h, 0, sizeof h);
    test_round_trip_one(&h); /* all zero, empty payload */

    uint64_t nan_bits = 0x7ff4000000000123ull; /* a NaN payload survives as bits */
    double nan_with_payload;
    memcpy(&nan_with_payload, &nan_bits, 8);
    const double times[] = {-0.0, DBL_MAX, -DBL_MAX, DBL_MIN, 4.9406564584124654e-324, INFINITY,
                            -INFINITY, nan_with_payload, 1e-300, 123456.789012345678};
    h = test_sample();
    for (size_t i = 0; i < sizeof times / sizeof times[0]; i++) {
        h.sim_time = times[i];
        test_round_trip_one(&h);
    }
}

static int test_unpack_copy(const uint8_t *src, size_t len)
{
    uint8_t *copy = malloc(len ? len : 1); /* exact size, so over-reads are caught */
    memcpy(copy, src, len);
    struct fxs_header g;
    int rc = fxs_header_unpack(copy, len, &g);
    free(copy);
    return rc;
}

static void test_reject_short(void)
{
    struct fxs_header h = test_sample();
    h.payload_bytes = 0;
    size_t len;
    uint8_t *buf = test_frame(&h, &len);
    const size_t shorter[] = {0, 1, 4, 6, 32, 63};
    for (size_t i = 0; i < sizeof shorter / sizeof shorter[0]; i++)
        CHECK(test_unpack_copy(buf, shorter[i]) == -1, "%zu bytes accepted", shorter[i]);
    CHECK(test_unpack_copy(buf, 64) == 0, "64 bytes with empty payload rejected");
    free(buf);
}

static void test_reject_magic(void)
{
    struct fxs_header h = test_sample();
    size_t len;
    uint8_t *buf = test_frame(&h, &len);
    for (int i = 0; i < 4; i++) {
        uint8_t saved = buf[i];
        buf[i] ^= 0x20; /* "fXS1", "FxS1", "FXs1", "FX\x111" */
        CHECK(test_unpack_copy(buf, len) == -1, "magic byte %d altered accepted", i);
        buf[i] = saved;
    }
    memcpy(buf, "FXS2", 4);
    CHECK(test_unpack_copy(buf, len) == -1, "FXS2 accepted");
    free(buf);
}

static void test_reject_header_bytes(void)
{
    struct fxs_header h = test_sample();
    size_t len; /* 69: 64 + 5 payload */
    uint8_t *buf = test_frame(&h, &len);
    const uint16_t bad[] = {0, 1, 32, 63, 70, 1000, UINT16_MAX};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        fxs_put_u16(buf + 4, bad[i]);
        CHECK(test_unpack_copy(buf, len) == -1, "header_bytes %u accepted", bad[i]);
    }
    for (uint16_t hb = 0; hb < 64; hb += 4) { /* payload_bytes consistent with the short header */
        fxs_put_u16(buf + 4, hb);
        fxs_put_u32(buf + 44, (uint32_t)(len - hb));
        CHECK(test_unpack_copy(buf, len) == -1, "header_bytes %u with matching payload accepted", hb);
    }
    fxs_put_u32(buf + 44, 5);
    fxs_put_u16(buf + 4, 69); /* whole frame is header: payload_bytes 5 no longer fits */
    CHECK(test_unpack_copy(buf, len) == -1, "header_bytes 69 with payload 5 accepted");
    free(buf);
}

static void test_reject_payload_mismatch(void)
{
    struct fxs_header h = test_sample();
    size_t len;
    uint8_t *buf = test_frame(&h, &len);
    const uint32_t bad[] = {0, 4, 6, 69, UINT32_MAX};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        fxs_put_u32(buf + 44, bad[i]);
        CHECK(test_unpack_copy(buf, len) == -1, "payload_bytes %u for 5 accepted", bad[i]);
    }
    fxs_put_u32(buf + 44, 5);
    CHECK(test_unpack_copy(buf, len) == 0, "payload_bytes 5 rejected");
    free(buf);
}

/* A future version with 16 more header bytes: accepted, payload after byte 80. */
/* The daemon's frames carry a subset's total at offset 60 (0 for the others). */
static void test_frame_total(void)
{
    struct fxs_header h = test_sample();
    const uint8_t payload[3] = {1, 2, 3};
    struct frame *f = frame_new(&h, 123456, payload, sizeof payload), *g = frame_new(&h, 0, payload, sizeof payload);
    CHECK(f && test_le(f->bytes + 60, 4) == 123456 && fxs_header_total(f->bytes) == 123456, "total packed");
    CHECK(g && test_le(g->bytes + 60, 4) == 0, "no total: 0");
    struct fxs_header u;
    CHECK(f && fxs_header_unpack(f->bytes, f->len, &u) == 0 && u.payload_bytes == 3, "still a valid frame");
    frame_unref(f);
    frame_unref(g);
}

static void test_longer_header(void)
{
    struct fxs_header h = test_sample(), g;
    const size_t len = 80 + 5;
    uint8_t *buf = malloc(len);
    fxs_header_pack(&h, buf);
    memset(buf + 64, 0xcc, 16); /* fields this reader does not know */
    memcpy(buf + 80, "hello", 5);
    fxs_put_u16(buf + 4, 80);
    int rc = fxs_header_unpack(buf, len, &g);
    CHECK(rc == 0, "80-byte header rejected");
    CHECK(rc == 0 && g.header_bytes == 80 && g.payload_bytes == 5, "header_bytes %u payload %u", g.header_bytes,
          g.payload_bytes);
    CHECK(rc == 0 && memcmp(buf + g.header_bytes, "hello", 5) == 0, "payload after header_bytes");
    CHECK(rc == 0 && g.seq == h.seq && g.flags == h.flags, "known fields still read");
    fxs_put_u32(buf + 44, 21); /* payload counted from 64 would be wrong */
    CHECK(test_unpack_copy(buf, len) == -1, "payload_bytes counted from byte 64 accepted");
    free(buf);
}

int main(void)
{
    RUN(test_offsets);
    RUN(test_round_trip);
    RUN(test_reject_short);
    RUN(test_reject_magic);
    RUN(test_reject_header_bytes);
    RUN(test_reject_payload_mismatch);
    RUN(test_longer_header);
    RUN(test_frame_total);
    return CHECK_DONE();
}
