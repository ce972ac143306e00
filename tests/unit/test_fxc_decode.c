/* test_fxc_decode.c — the payload decoders of libfxclient's public API (fxclient.h):
 * fxc_decode_particles (codecs 2, 3 and the engine encoding's 16), fxc_decode_texture (the
 * engine encoding), fxc_decode_rig and fxc_decode_lut write into the caller's arrays exactly
 * what the protocol/ codecs decode, answer 1 with the counts (and write nothing) when an array
 * is missing or too small, and refuse other kinds, header/payload disagreements and cut
 * payloads with -1 and a message. Frames are built with the daemon's encoders. */
#include <string.h>

#include "check.h"
#include "fxclient.h"
#include "fxs_engine.h"
#include "fxs_lut.h"
#include "fxs_rig.h"
#include "particles_gen.h"

static struct fxs_header header_for(unsigned kind, uint32_t codec, size_t bytes, uint32_t count)
{
    struct fxs_header h = { .header_bytes = 64, .kind = (uint16_t)kind, .channel = 1, .seq = 1, .codec = codec,
                            .payload_bytes = (uint32_t)bytes, .count_or_width = count };
    return h;
}

/* A particle payload of n random particles (with velocities when vel). */
static uint8_t *particle_payload(uint32_t n, int vel, size_t *len, struct fxs_particles *src)
{
    uint8_t *out = NULL;
    char err[128];
    pgen_random(src, n, 0.3);
    if (vel) {
        src->vel = calloc(3 * (size_t)n, sizeof *src->vel);
        for (uint32_t i = 0; i < 3 * n; i++) src->vel[i] = (float)(pgen_rand() - 0.5);
    }
    CHECK(fxs_particles_encode(src, NULL, &out, len, err, sizeof err) == 0, "encode: %s", err);
    return out;
}

static void test_particles(void)
{
    struct fxs_particles src = { 0 }, ref;
    size_t len = 0;
    char err[256];
    uint8_t *payload = particle_payload(3000, 1, &len, &src);
    struct fxs_header h = header_for(FXS_KIND_PARTICLES, FXS_CODEC_PARTICLES, len, 3000);
    static float xyz[3 * 3000], t[3000], fuel[3000], vel[3 * 3000];
    static uint8_t flags[3000];
    struct fxc_particles p = { .capacity = 3000, .xyz = xyz, .temperature = t, .flags = flags, .fuel = fuel,
                               .velocity = vel };
    if (!payload) return;
    CHECK(fxs_particles_decode(payload, len, &ref, err, sizeof err) == 0, "reference decode: %s", err);
    CHECK(fxc_decode_particles(&h, payload, &p, err, sizeof err) == 0, "decode: %s", err);
    CHECK(p.count == 3000 && p.has_velocity && p.has_flags && p.has_fuel, "count %u, velocities %d, flags %d, fuel %d",
          p.count, p.has_velocity, p.has_flags, p.has_fuel);
    CHECK(!memcmp(xyz, ref.xyz, sizeof xyz) && !memcmp(t, ref.temp, sizeof t) && !memcmp(fuel, ref.fuel, sizeof fuel) &&
              !memcmp(flags, ref.flags, sizeof flags) && !memcmp(vel, ref.vel, sizeof vel),
          "the same floats as fxs_particles_decode");

    /* fuel and velocity are optional */
    memset(xyz, 0, sizeof xyz);
    p.fuel = NULL;
    p.velocity = NULL;
    CHECK(fxc_decode_particles(&h, payload, &p, err, sizeof err) == 0 && !memcmp(xyz, ref.xyz, sizeof xyz) &&
              p.has_velocity,
          "without fuel and velocity arrays: %s", err);

    /* too small: the count, nothing written */
    memset(xyz, 0, sizeof xyz);
    p.capacity = 2999;
    p.count = 0;
    CHECK(fxc_decode_particles(&h, payload, &p, err, sizeof err) == 1 && p.count == 3000 && xyz[0] == 0,
          "capacity 2999: 1 with the count, arrays untouched");
    p.capacity = 3000;
    p.flags = NULL;
    CHECK(fxc_decode_particles(&h, payload, &p, err, sizeof err) == 1, "no flags array: 1");
    p.flags = flags;

    /* refused */
    struct fxs_header bad = h;
    bad.count_or_width = 2999;
    CHECK(fxc_decode_particles(&bad, payload, &p, err, sizeof err) == -1 && strstr(err, "header count 2999"),
          "header count disagrees: %s", err);
    bad = h;
    bad.payload_bytes = (uint32_t)len - 1;
    CHECK(fxc_decode_particles(&bad, payload, &p, err, sizeof err) == -1, "a cut payload");
    bad = h;
    bad.kind = FXS_KIND_TEXTURE;
    CHECK(fxc_decode_particles(&bad, payload, &p, err, sizeof err) == -1 && strstr(err, "not a particle frame"),
          "a texture frame: %s", err);
    bad = h;
    bad.codec = 4;
    CHECK(fxc_decode_particles(&bad, payload, &p, err, sizeof err) == -1 && strstr(err, "codec 4"),
          "an unknown codec: %s", err);
    fxs_particles_free(&ref);
    fxs_particles_free(&src);
    free(payload);
}

/* Codec 3 (several blocks) and an empty frame decode alike. */
static void test_particle_blocks(void)
{
    struct fxs_particles src = { 0 }, ref;
    struct fxs_particles_opts o = { .threads = 4 };
    uint8_t *payload = NULL;
    size_t len;
    char err[256];
    pgen_random(&src, 20000, 0.3);
    CHECK(fxs_particles_encode(&src, &o, &payload, &len, err, sizeof err) == 0 &&
              fxs_particles_codec(payload, len) == FXS_CODEC_PARTICLES_BLOCKS,
          "four blocks: %s", err);
    struct fxs_header h = header_for(FXS_KIND_PARTICLES, FXS_CODEC_PARTICLES_BLOCKS, len, 20000);
    static float xyz[3 * 20000], t[20000];
    static uint8_t flags[20000];
    struct fxc_particles p = { .capacity = 20000, .xyz = xyz, .temperature = t, .flags = flags };
    CHECK(fxs_particles_decode(payload, len, &ref, err, sizeof err) == 0, "reference");
    CHECK(fxc_decode_particles(&h, payload, &p, err, sizeof err) == 0 && p.count == 20000 &&
              !memcmp(xyz, ref.xyz, sizeof xyz) && !memcmp(t, ref.temp, sizeof t),
          "codec 3 decodes like the reference: %s", err);
    fxs_particles_free(&ref);
    fxs_particles_free(&src);
    free(payload);

    pgen_random(&src, 0, 0.3);
    CHECK(fxs_particles_encode(&src, NULL, &payload, &len, err, sizeof err) == 0, "an empty frame");
    h = header_for(FXS_KIND_PARTICLES, FXS_CODEC_PARTICLES, len, 0);
    struct fxc_particles none = { 0 };
    CHECK(fxc_decode_particles(&h, payload, &none, err, sizeof err) == 0 && none.count == 0,
          "0 particles need no arrays: %s", err);
    fxs_particles_free(&src);
    free(payload);
}

/* The engine encoding's particles: positions, temperatures and velocities as the protocol's
 * decoder gives them; flags and fuel marked absent and left alone. */
static void test_engine_particles(void)
{
    struct fxs_particles src = { 0 }, ref;
    uint8_t *payload = NULL;
    size_t len = 0;
    char err[256];
    pgen_random(&src, 2500, 0.3);
    src.vel = calloc(3 * 2500, sizeof *src.vel);
    for (uint32_t i = 0; i < 3 * 2500; i++) src.vel[i] = (float)(pgen_rand() - 0.5);
    CHECK(fxs_engine_encode_particles(&src, FXS_ENGINE_ZSTD_LEVEL, &payload, &len, err, sizeof err) == 0, "encode: %s",
          err);
    CHECK(fxs_engine_decode_particles(payload, len, &ref, err, sizeof err) == 0, "reference decode: %s", err);
    struct fxs_header h = header_for(FXS_KIND_PARTICLES, FXS_CODEC_ENGINE, len, 2500);
    static float xyz[3 * 2500], t[2500], fuel[2500], vel[3 * 2500];
    static uint8_t flags[2500];
    memset(fuel, 0x55, sizeof fuel);
    memset(flags, 0x55, sizeof flags);
    struct fxc_particles p = { .capacity = 2500, .xyz = xyz, .temperature = t, .flags = flags, .fuel = fuel,
                               .velocity = vel };
    CHECK(fxc_decode_particles(&h, payload, &p, err, sizeof err) == 0, "decode: %s", err);
    CHECK(p.count == 2500 && p.has_velocity && !p.has_flags && !p.has_fuel, "count %u, velocities %d, flags %d, fuel %d",
          p.count, p.has_velocity, p.has_flags, p.has_fuel);
    CHECK(!memcmp(xyz, ref.xyz, sizeof xyz) && !memcmp(t, ref.temp, sizeof t) && !memcmp(vel, ref.vel, sizeof vel),
          "the same floats as fxs_engine_decode_particles");
    CHECK(fuel[2499] == fuel[0] && flags[2499] == 0x55 && flags[0] == 0x55, "fuel and flags not written");

    /* flags, fuel and velocities are not needed */
    memset(xyz, 0, sizeof xyz);
    struct fxc_particles q = { .capacity = 2500, .xyz = xyz, .temperature = t };
    CHECK(fxc_decode_particles(&h, payload, &q, err, sizeof err) == 0 && !memcmp(xyz, ref.xyz, sizeof xyz) &&
              q.has_velocity,
          "positions and temperatures only: %s", err);
    q.capacity = 2499;
    xyz[0] = 0;
    CHECK(fxc_decode_particles(&h, payload, &q, err, sizeof err) == 1 && q.count == 2500 && xyz[0] == 0,
          "capacity 2499: 1 with the count, arrays untouched");
    q.capacity = 2500;
    q.temperature = NULL;
    CHECK(fxc_decode_particles(&h, payload, &q, err, sizeof err) == 1, "no temperature array: 1");

    /* refused */
    struct fxs_header bad = h;
    bad.count_or_width = 2501;
    CHECK(fxc_decode_particles(&bad, payload, &p, err, sizeof err) == -1 && strstr(err, "header count 2501"),
          "header count disagrees: %s", err);
    bad = h;
    bad.payload_bytes = (uint32_t)len - 1;
    CHECK(fxc_decode_particles(&bad, payload, &p, err, sizeof err) == -1 && strstr(err, "zstd"), "a cut payload: %s",
          err);
    bad = h;
    bad.codec = FXS_CODEC_PARTICLES;
    CHECK(fxc_decode_particles(&bad, payload, &p, err, sizeof err) == -1, "read as codec 2: -1 (%s)", err);
    fxs_particles_free(&ref);
    fxs_particles_free(&src);
    free(payload);
}

/* The engine encoding's textures, one and four channels, as the halves of the input. */
static void test_engine_texture(void)
{
    static float src[4 * 33 * 17], out[4 * 33 * 17];
    char err[256];
    for (int channels = 1; channels <= 4; channels += 3) {
        uint8_t *payload = NULL;
        size_t len = 0, n = (size_t)channels * 33 * 17;
        for (size_t i = 0; i < n; i++) src[i] = (float)(pgen_rand() * 100 - 20);
        CHECK(fxs_engine_encode_texture(src, 33, 17, (uint32_t)channels, FXS_ENGINE_ZSTD_LEVEL, &payload, &len, err,
                                        sizeof err) == 0,
              "encode: %s", err);
        struct fxs_header h = header_for(FXS_KIND_TEXTURE, FXS_CODEC_ENGINE, len, 33);
        h.height = 17;
        struct fxc_texture tex = { 0 };
        CHECK(fxc_decode_texture(&h, payload, &tex, err, sizeof err) == 1 && tex.width == 33 && tex.height == 17 &&
                  tex.channels == (uint32_t)channels,
              "no array: 1 with the size, %u channels", tex.channels);
        tex.texels = out;
        tex.capacity = n - 1;
        out[0] = -1;
        CHECK(fxc_decode_texture(&h, payload, &tex, err, sizeof err) == 1 && out[0] == -1, "one float short: 1, untouched");
        tex.capacity = n;
        int same = fxc_decode_texture(&h, payload, &tex, err, sizeof err) == 0;
        for (size_t i = 0; same && i < n; i++) same = out[i] == fxs_half_to_float(fxs_half_from_float(src[i]));
        CHECK(same, "%d channels: the halves of the input, row 0 first (%s)", channels, err);
        struct fxs_header bad = h;
        bad.height = 16;
        CHECK(fxc_decode_texture(&bad, payload, &tex, err, sizeof err) == -1 && strstr(err, "33x16"),
              "header size disagrees: %s", err);
        bad = h;
        bad.payload_bytes = 63;
        CHECK(fxc_decode_texture(&bad, payload, &tex, err, sizeof err) == -1, "a cut payload: %s", err);
        bad = h;
        bad.codec = FXS_CODEC_EXR;
        CHECK(fxc_decode_texture(&bad, payload, &tex, err, sizeof err) == -1 && strstr(err, "OpenEXR"),
              "an EXR texture: %s", err);
        bad = h;
        bad.kind = FXS_KIND_PARTICLES;
        CHECK(fxc_decode_texture(&bad, payload, &tex, err, sizeof err) == -1 && strstr(err, "not a texture frame"),
              "kind 1: %s", err);
        free(payload);
    }
    /* a particle payload is not a texture */
    struct fxs_particles p = { 0 };
    uint8_t *payload = NULL;
    size_t len = 0;
    pgen_random(&p, 10, 0.3);
    CHECK(fxs_engine_encode_particles(&p, 1, &payload, &len, err, sizeof err) == 0, "encode: %s", err);
    struct fxs_header h = header_for(FXS_KIND_TEXTURE, FXS_CODEC_ENGINE, len, 1024);
    h.height = 1;
    struct fxc_texture tex = { .capacity = sizeof out / sizeof *out, .texels = out };
    CHECK(fxc_decode_texture(&h, payload, &tex, err, sizeof err) == -1 && strstr(err, "count 0"),
          "particles as a texture: %s", err);
    fxs_particles_free(&p);
    free(payload);
}

static void test_rig(void)
{
    static struct fxs_rig rig;
    static uint8_t buf[FXS_RIG_MAX_PAYLOAD];
    struct fxc_rig_segment segs[FXC_RIG_MAX_SEGMENTS];
    struct fxc_rig out = { .capacity = FXC_RIG_MAX_SEGMENTS, .segments = segs };
    char err[256];
    rig.n_seg = 3;
    for (int i = 0; i < 3; i++) {
        rig.seg[i] = (struct fxs_rig_seg){ { i, 1, 2 }, { 0, 1, 0 }, -0.5, 0.25 * i, 0.5 + i, FXS_RIG_CURVE, i };
    }
    rig.k.flags = FXS_RIG_OUTLINE;
    rig.k.strength = 0.75;
    rig.k.shadow_theta = 0.5;
    rig.k.n_bands = 2;
    rig.k.bands[1].m_min = 0.5;
    rig.k.bands[1].rgb[2] = 1;
    size_t n = fxs_rig_encode(&rig, 1, buf);
    struct fxs_header h = header_for(FXS_KIND_LIGHT_RIG, FXS_CODEC_LIGHT_RIG, n, 3);
    CHECK(fxc_decode_rig(&h, buf, &out, err, sizeof err) == 0, "decode: %s", err);
    CHECK(out.count == 3 && out.has_constants && out.constants_id == fxs_rig_constants_id(&rig.k), "count, constants");
    CHECK(segs[2].c[0] == 2 && segs[2].a_hi == 0.5f && segs[2].strength == 2.5f && segs[2].source == FXS_RIG_CURVE &&
              segs[2].index == 2,
          "segment 2");
    CHECK(out.constants.flags == FXS_RIG_OUTLINE && out.constants.strength == 0.75f && out.constants.n_bands == 2 &&
              out.constants.bands[1].m_min == 0.5f && out.constants.bands[1].rgb[2] == 1,
          "constants");
    out.capacity = 2;
    CHECK(fxc_decode_rig(&h, buf, &out, err, sizeof err) == 1 && out.count == 3, "two segments' room: 1");
    CHECK(fxc_decode_rig(&h, buf, &out, err, sizeof err) == 1, "again");
    out.capacity = FXC_RIG_MAX_SEGMENTS;
    h.payload_bytes--;
    CHECK(fxc_decode_rig(&h, buf, &out, err, sizeof err) == -1 && strstr(err, "malformed"), "a cut payload: %s", err);
    h = header_for(FXS_KIND_PARTICLES, FXS_CODEC_PARTICLES, n, 3);
    CHECK(fxc_decode_rig(&h, buf, &out, err, sizeof err) == -1 && strstr(err, "not a light-rig frame"), "kind 1: %s", err);
}

static void test_lut(void)
{
    static uint8_t a[4 * 4 * 4], b[8 * 2 * 4], payload[4096];
    struct fxs_lut_product prods[2] = { { .name = "PIGM", .width = 4, .height = 4, .rgba = a },
                                        { .name = "LLUT", .width = 8, .height = 2, .tile = 4, .tiles_x = 2, .rgba = b } };
    struct fxs_lut_info info = { .lattice = 1, .tile_h = 1.5f, .cells = 7, .dirs = 3 };
    char err[256];
    for (size_t i = 0; i < sizeof a; i++) a[i] = (uint8_t)i;
    for (size_t i = 0; i < sizeof b; i++) b[i] = (uint8_t)(3 * i);
    struct fxs_lut_encoder enc;
    int rc = fxs_lut_encode_begin(&enc, &info, prods, 2, 3, payload, sizeof payload, err, sizeof err);
    while (rc == 0 && (rc = fxs_lut_encode_some(&enc, SIZE_MAX, err, sizeof err)) == 1) {}
    size_t n = rc == 0 ? enc.len : 0;
    fxs_lut_encode_free(&enc);
    CHECK(n > 0, "encode: %s", err);
    struct fxs_header h = header_for(FXS_KIND_LUT, FXS_CODEC_LUT_PACK, n, 8);
    struct fxc_lut lut = { 0 };
    CHECK(fxc_decode_lut(&h, payload, &lut, err, sizeof err) == 1 && lut.count == 2, "no products given: 1, count 2");
    CHECK(lut.lattice == 1 && lut.tile_h == 1.5f && lut.cells == 7 && lut.dirs == 3, "the container header");
    struct fxc_lut_product out[2] = { 0 };
    lut.products = out;
    lut.capacity = 2;
    CHECK(fxc_decode_lut(&h, payload, &lut, err, sizeof err) == 1 && !strcmp(out[1].name, "LLUT") && out[1].width == 8 &&
              out[1].height == 2 && out[1].tiles_x == 2,
          "no texel buffers: 1, the directory");
    static uint8_t ta[sizeof a], tb[sizeof b];
    out[0].rgba = ta;
    out[0].rgba_capacity = sizeof ta;
    out[1].rgba = tb;
    out[1].rgba_capacity = sizeof tb - 1;
    CHECK(fxc_decode_lut(&h, payload, &lut, err, sizeof err) == 1 && ta[5] == 0, "one buffer short: 1, no texels");
    out[1].rgba_capacity = sizeof tb;
    CHECK(fxc_decode_lut(&h, payload, &lut, err, sizeof err) == 0 && !memcmp(ta, a, sizeof a) && !memcmp(tb, b, sizeof b),
          "the texels: %s", err);
    h.payload_bytes = 70;
    CHECK(fxc_decode_lut(&h, payload, &lut, err, sizeof err) == -1, "a cut payload: %s", err);
    payload[0] = 'X';
    h.payload_bytes = (uint32_t)n;
    CHECK(fxc_decode_lut(&h, payload, &lut, err, sizeof err) == -1 && strstr(err, "FXL1"), "bad magic: %s", err);
}

int main(void)
{
    RUN(test_particles);
    RUN(test_particle_blocks);
    RUN(test_engine_particles);
    RUN(test_engine_texture);
    RUN(test_rig);
    RUN(test_lut);
    return CHECK_DONE();
}
