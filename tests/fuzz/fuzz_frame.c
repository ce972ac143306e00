/* fuzz_frame.c — libFuzzer target: what a client does with a binary message: the 64-byte
 * frame header (fxs_header_unpack), then the payload decoder of its kind and codec: particle
 * frames (codecs 2 and 3), the engine encoding of particles and textures (codec 16, fxs_engine)
 * and the compound-eye product container (fxs_lut). A header that parses must
 * describe exactly the bytes given; decoders must reject or decode without reading out of
 * bounds. */
#include <stdint.h>
#include <stdlib.h>

#include "fxs_engine.h"
#include "fxs_frame.h"
#include "fxs_particles.h"
#include "fxs_lut.h"

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
    } else if (h.codec == FXS_CODEC_ENGINE && h.kind == FXS_KIND_TEXTURE) {
        struct fxs_engine_info info;
        float *texels;
        if (!fxs_engine_decode_texture(payload, h.payload_bytes, &info, &texels, msg, sizeof msg)) free(texels);
    } else if (h.kind == FXS_KIND_PARTICLES) {
        struct fxs_particles p;
        if (!fxs_particles_decode(payload, h.payload_bytes, &p, msg, sizeof msg)) fxs_particles_free(&p);
    } else if (h.kind == FXS_KIND_LUT) {
        struct fxs_lut_product prod;
        for (int i = 0; i < 8 && fxs_lut_entry(payload, h.payload_bytes, i, &prod, msg, sizeof msg) > i; i++)
            free(fxs_lut_texels(payload, h.payload_bytes, &prod, msg, sizeof msg));
    }
    return 0;
}
