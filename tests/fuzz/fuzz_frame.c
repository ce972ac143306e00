/* fuzz_frame.c — libFuzzer target: what a client does with a binary message: the 64-byte
 * frame header (fxs_header_unpack), then the payload decoders of its kind and codec, both the
 * codecs' own (fxs_particles for codecs 2 and 3, fxs_engine for the engine encoding's 16,
 * fxs_lut) and libfxclient's public ones into caller-sized arrays (fxc_decode_particles,
 * fxc_decode_texture, fxc_decode_rig, fxc_decode_lut, sized from the counts they report, as a
 * game plugin does). A header that parses must describe exactly the bytes given; decoders must
 * reject or decode without reading or writing out of bounds. */
#include <stdint.h>
#include <stdlib.h>

#include "fxclient.h"
#include "fxs_engine.h"
#include "fxs_frame.h"
#include "fxs_particles.h"
#include "fxs_lut.h"

#define FUZZ_MAX_TEXELS (1u << 24) /* bytes of look-up-table texels the target allocates */

static void fuzz_public_particles(const struct fxs_header *h, const uint8_t *payload)
{
    char msg[256];
    struct fxc_particles p = { 0 };
    if (fxc_decode_particles(h, payload, &p, msg, sizeof msg) != 1) return;
    p.capacity = p.count;
    p.xyz = malloc(12 * (size_t)p.count + 1);
    p.temperature = malloc(4 * (size_t)p.count + 1);
    p.flags = malloc(p.count + 1);
    p.velocity = malloc(12 * (size_t)p.count + 1);
    if (p.xyz && p.temperature && p.flags && p.velocity && fxc_decode_particles(h, payload, &p, msg, sizeof msg) == 1)
        abort(); /* room for the count it reported, yet too small */
    free(p.xyz);
    free(p.temperature);
    free(p.flags);
    free(p.velocity);
}

static void fuzz_public_texture(const struct fxs_header *h, const uint8_t *payload)
{
    char msg[256];
    struct fxc_texture t = { 0 };
    if (fxc_decode_texture(h, payload, &t, msg, sizeof msg) != 1) return;
    t.capacity = (size_t)t.width * t.height * t.channels;
    t.texels = malloc(4 * t.capacity + 1);
    if (t.texels && fxc_decode_texture(h, payload, &t, msg, sizeof msg) == 1)
        abort(); /* room for the size it reported, yet too small */
    free(t.texels);
}

static void fuzz_public_lut(const struct fxs_header *h, const uint8_t *payload)
{
    char msg[256];
    struct fxc_lut lut = { 0 };
    struct fxc_lut_product prods[8] = { 0 };
    size_t total = 0;
    if (fxc_decode_lut(h, payload, &lut, msg, sizeof msg) != 1 || lut.count > 8) return;
    lut.products = prods;
    lut.capacity = lut.count;
    if (fxc_decode_lut(h, payload, &lut, msg, sizeof msg) != 1) return;
    for (int i = 0; i < lut.count; i++) total += (size_t)prods[i].width * prods[i].height * 4;
    for (int i = 0; i < lut.count && total <= FUZZ_MAX_TEXELS; i++) {
        prods[i].rgba_capacity = (size_t)prods[i].width * prods[i].height * 4;
        prods[i].rgba = malloc(prods[i].rgba_capacity + 1);
    }
    if (total <= FUZZ_MAX_TEXELS) fxc_decode_lut(h, payload, &lut, msg, sizeof msg);
    for (int i = 0; i < lut.count; i++) free(prods[i].rgba);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    struct fxs_header h;
    if (fxs_header_unpack(data, size, &h)) return 0;
    if (h.header_bytes + (size_t)h.payload_bytes != size) abort();
    const uint8_t *payload = data + h.header_bytes;
    char msg[256];
    if (h.codec == FXS_CODEC_ENGINE && h.kind == FXS_KIND_PARTICLES) {
        struct fxs_particles p;
        if (!fxs_engine_decode_particles(payload, h.payload_bytes, &p, msg, sizeof msg)) fxs_particles_free(&p);
        fuzz_public_particles(&h, payload);
    } else if (h.codec == FXS_CODEC_ENGINE && h.kind == FXS_KIND_TEXTURE) {
        struct fxs_engine_info info;
        float *texels;
        if (!fxs_engine_decode_texture(payload, h.payload_bytes, &info, &texels, msg, sizeof msg)) free(texels);
        fuzz_public_texture(&h, payload);
    } else if (h.kind == FXS_KIND_PARTICLES) {
        struct fxs_particles p;
        if (!fxs_particles_decode(payload, h.payload_bytes, &p, msg, sizeof msg)) fxs_particles_free(&p);
        fuzz_public_particles(&h, payload);
    } else if (h.kind == FXS_KIND_LUT) {
        struct fxs_lut_product prod;
        for (int i = 0; i < 8 && fxs_lut_entry(payload, h.payload_bytes, i, &prod, msg, sizeof msg) > i; i++)
            free(fxs_lut_texels(payload, h.payload_bytes, &prod, msg, sizeof msg));
        fuzz_public_lut(&h, payload);
    } else if (h.kind == FXS_KIND_LIGHT_RIG) {
        struct fxc_rig_segment segs[FXC_RIG_MAX_SEGMENTS];
        struct fxc_rig rig = { .capacity = FXC_RIG_MAX_SEGMENTS, .segments = segs };
        fxc_decode_rig(&h, payload, &rig, msg, sizeof msg);
    }
    return 0;
}
