/* fxs_engine.c — see fxs_engine.h. Every size in a payload is checked against the bytes given
 * and against FXS_ENGINE_MAX_TEXELS before anything is allocated or decompressed. */
#include "fxs_engine.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zstd.h>

#include "fxs_bytes.h"

uint16_t fxs_half_from_float(float f)
{
    /* F. Giesen's float_to_half_fast3_rtne: exact round to nearest even, denormals included */
    const uint32_t f32_inf = 255u << 23, f16_max = (127u + 16) << 23, denorm_magic = ((127u - 15) + (23 - 10) + 1) << 23;
    uint32_t x;
    memcpy(&x, &f, 4);
    uint32_t sign = x & 0x80000000u;
    uint16_t o;
    x ^= sign;
    if (x >= f16_max) {
        o = x > f32_inf ? 0x7e00 : 0x7c00; /* NaN stays NaN; too large for a half: infinity */
    } else if (x < (113u << 23)) {         /* a half denormal (or zero): let the FPU round */
        float xf, dm;
        memcpy(&xf, &x, 4);
        memcpy(&dm, &denorm_magic, 4);
        xf += dm;
        memcpy(&x, &xf, 4);
        o = (uint16_t)(x - denorm_magic);
    } else {
        uint32_t odd = (x >> 13) & 1;
        x += ((uint32_t)(15 - 127) << 23) + 0xfff + odd;
        o = (uint16_t)(x >> 13);
    }
    return (uint16_t)(o | (sign >> 16));
}

float fxs_half_to_float(uint16_t h)
{
    uint32_t sign = (uint32_t)(h & 0x8000u) << 16, e = (h >> 10) & 0x1fu, m = h & 0x3ffu, x;
    if (e == 0) {
        float f = ldexpf((float)m, -24);
        return sign ? -f : f;
    }
    x = sign | (e == 31 ? 0x7f800000u | (m << 13) : ((e + 112) << 23) | (m << 13));
    float f;
    memcpy(&f, &x, 4);
    return f;
}

static uint32_t engine_texel_bytes(uint32_t format) { return format == FXS_ENGINE_RGBA16F ? 8 : 2; }

static void engine_header(const struct fxs_engine_info *in, uint32_t zbytes, uint8_t *h)
{
    memset(h, 0, FXS_ENGINE_HEADER_BYTES);
    memcpy(h, FXS_ENGINE_MAGIC, 4);
    fxs_put_u16(h + 4, FXS_ENGINE_VERSION);
    fxs_put_u16(h + 6, FXS_ENGINE_HEADER_BYTES);
    fxs_put_u16(h + 8, (uint16_t)in->format);
    fxs_put_u16(h + 10, (uint16_t)in->layers);
    fxs_put_u32(h + 12, in->width);
    fxs_put_u32(h + 16, in->height);
    fxs_put_u32(h + 20, in->count);
    fxs_put_u32(h + 24, in->raw_bytes);
    fxs_put_u32(h + 28, zbytes);
    for (int k = 0; k < 3; k++) {
        fxs_put_f32(h + 32 + 4 * k, in->origin[k]);
        fxs_put_f32(h + 44 + 4 * k, in->extent[k]);
    }
    fxs_put_u32(h + 56, in->flags);
}

/* Compresses the raw texels behind the header of `in` into a new payload. */
static int engine_pack(const struct fxs_engine_info *in, const uint8_t *raw, int level, uint8_t **out,
                       size_t *out_len, char *err, size_t errlen)
{
    size_t cap = FXS_ENGINE_HEADER_BYTES + ZSTD_compressBound(in->raw_bytes);
    uint8_t *buf = malloc(cap);
    if (!buf) return snprintf(err, errlen, "out of memory (%zu bytes)", cap), -1;
    size_t z = ZSTD_compress(buf + FXS_ENGINE_HEADER_BYTES, cap - FXS_ENGINE_HEADER_BYTES, raw, in->raw_bytes, level);
    if (ZSTD_isError(z)) {
        free(buf);
        return snprintf(err, errlen, "zstd: %s", ZSTD_getErrorName(z)), -1;
    }
    engine_header(in, (uint32_t)z, buf);
    *out = buf;
    *out_len = FXS_ENGINE_HEADER_BYTES + z;
    return 0;
}

/* Stores v as a half at p; -1 when the half is not finite (v too large, or not finite). */
static int engine_put_half(uint8_t *p, float v)
{
    uint16_t h = fxs_half_from_float(v);
    fxs_put_u16(p, h);
    return (h & 0x7c00u) == 0x7c00u ? -1 : 0;
}

/* The centre of the particles' bounds and half their size (rounded up, so every offset lies
 * within it); -1 when a position is not finite. */
static int engine_bounds(const struct fxs_particles *p, float origin[3], float extent[3])
{
    for (int k = 0; k < 3; k++) {
        float lo = INFINITY, hi = -INFINITY;
        for (uint32_t i = 0; i < p->n; i++) {
            float v = p->xyz[3 * (size_t)i + k];
            if (!isfinite(v)) return -1;
            lo = fminf(lo, v);
            hi = fmaxf(hi, v);
        }
        origin[k] = p->n ? (float)(0.5 * ((double)lo + (double)hi)) : 0.0f;
        extent[k] = p->n ? nextafterf((float)fmax((double)hi - origin[k], (double)origin[k] - lo), INFINITY) : 0.0f;
    }
    return 0;
}

int fxs_engine_encode_particles(const struct fxs_particles *p, int zstd_level, uint8_t **out, size_t *out_len,
                                char *err, size_t errlen)
{
    if (p->n > FXS_PARTICLES_MAX_N) return snprintf(err, errlen, "%u particles: at most %u", p->n, FXS_PARTICLES_MAX_N), -1;
    struct fxs_engine_info in = {.format = FXS_ENGINE_RGBA16F, .layers = p->vel ? 2 : 1,
                                 .width = FXS_ENGINE_PARTICLE_WIDTH, .count = p->n,
                                 .flags = p->vel ? FXS_ENGINE_FLAG_VELOCITIES : 0};
    in.height = p->n ? (p->n + in.width - 1) / in.width : 1;
    size_t layer = (size_t)in.width * in.height * 8;
    in.raw_bytes = (uint32_t)(layer * in.layers);
    if (engine_bounds(p, in.origin, in.extent)) return snprintf(err, errlen, "a particle position is not finite"), -1;
    uint8_t *raw = calloc(in.raw_bytes, 1);
    if (!raw) return snprintf(err, errlen, "out of memory (%u bytes)", in.raw_bytes), -1;
    for (uint32_t i = 0; i < p->n; i++) {
        uint8_t *t = raw + 8 * (size_t)i, *v = t + layer;
        int bad = 0;
        for (int k = 0; k < 3; k++) bad |= engine_put_half(t + 2 * k, (float)((double)p->xyz[3 * (size_t)i + k] - in.origin[k]));
        bad |= engine_put_half(t + 6, p->temp[i]);
        for (int k = 0; k < 3 && p->vel; k++) bad |= engine_put_half(v + 2 * k, p->vel[3 * (size_t)i + k]);
        if (bad) {
            free(raw);
            return snprintf(err, errlen, "particle %u: a value beyond the half-float range (65504) or not finite", i), -1;
        }
    }
    int rc = engine_pack(&in, raw, zstd_level, out, out_len, err, errlen);
    free(raw);
    return rc;
}

int fxs_engine_encode_texture(const float *texels, uint32_t width, uint32_t height, uint32_t channels,
                              int zstd_level, uint8_t **out, size_t *out_len, char *err, size_t errlen)
{
    if (channels != 1 && channels != 4) return snprintf(err, errlen, "%u channels: 1 or 4", channels), -1;
    uint64_t n = (uint64_t)width * height;
    if (!width || !height || n > FXS_ENGINE_MAX_TEXELS)
        return snprintf(err, errlen, "a %ux%u texture: 1 to %u texels", width, height, FXS_ENGINE_MAX_TEXELS), -1;
    struct fxs_engine_info in = {.format = channels == 4 ? FXS_ENGINE_RGBA16F : FXS_ENGINE_R16F, .layers = 1,
                                 .width = width, .height = height, .raw_bytes = (uint32_t)(n * channels * 2)};
    uint8_t *raw = malloc(in.raw_bytes);
    if (!raw) return snprintf(err, errlen, "out of memory (%u bytes)", in.raw_bytes), -1;
    for (size_t i = 0; i < n * channels; i++) fxs_put_u16(raw + 2 * i, fxs_half_from_float(texels[i]));
    int rc = engine_pack(&in, raw, zstd_level, out, out_len, err, errlen);
    free(raw);
    return rc;
}

int fxs_engine_info(const uint8_t *buf, size_t len, struct fxs_engine_info *in, char *err, size_t errlen)
{
    if (len < FXS_ENGINE_HEADER_BYTES)
        return snprintf(err, errlen, "engine payload of %zu bytes: shorter than its %u-byte header", len,
                        FXS_ENGINE_HEADER_BYTES), -1;
    if (memcmp(buf, FXS_ENGINE_MAGIC, 4)) return snprintf(err, errlen, "not an engine payload (magic is not FXE1)"), -1;
    if (fxs_get_u16(buf + 4) != FXS_ENGINE_VERSION)
        return snprintf(err, errlen, "engine payload version %u (this decoder reads %u)", fxs_get_u16(buf + 4), FXS_ENGINE_VERSION), -1;
    memset(in, 0, sizeof *in);
    in->header_bytes = fxs_get_u16(buf + 6);
    in->format = fxs_get_u16(buf + 8);
    in->layers = fxs_get_u16(buf + 10);
    in->width = fxs_get_u32(buf + 12);
    in->height = fxs_get_u32(buf + 16);
    in->count = fxs_get_u32(buf + 20);
    in->raw_bytes = fxs_get_u32(buf + 24);
    uint32_t zbytes = fxs_get_u32(buf + 28);
    for (int k = 0; k < 3; k++) {
        in->origin[k] = fxs_get_f32(buf + 32 + 4 * k);
        in->extent[k] = fxs_get_f32(buf + 44 + 4 * k);
    }
    in->flags = fxs_get_u32(buf + 56);
    uint64_t texels = (uint64_t)in->width * in->height * in->layers;
    if (in->header_bytes < FXS_ENGINE_HEADER_BYTES || in->header_bytes > len)
        return snprintf(err, errlen, "engine header_bytes %u: %u up to the payload's %zu", in->header_bytes,
                        FXS_ENGINE_HEADER_BYTES, len), -1;
    if (in->format != FXS_ENGINE_RGBA16F && in->format != FXS_ENGINE_R16F)
        return snprintf(err, errlen, "engine texel format %u is unknown", in->format), -1;
    if (in->flags & ~FXS_ENGINE_FLAG_VELOCITIES) return snprintf(err, errlen, "engine flags 0x%x: unknown bits", in->flags), -1;
    if (in->layers != ((in->flags & FXS_ENGINE_FLAG_VELOCITIES) ? 2u : 1u))
        return snprintf(err, errlen, "%u layers with flags 0x%x", in->layers, in->flags), -1;
    if (!in->width || !in->height || texels > FXS_ENGINE_MAX_TEXELS)
        return snprintf(err, errlen, "engine image %ux%u x %u layers: 1 to %u texels", in->width, in->height, in->layers,
                        FXS_ENGINE_MAX_TEXELS), -1;
    if (in->raw_bytes != texels * engine_texel_bytes(in->format))
        return snprintf(err, errlen, "raw_bytes %u for %llu texels of %u bytes", in->raw_bytes, (unsigned long long)texels,
                        engine_texel_bytes(in->format)), -1;
    if (in->count > (uint64_t)in->width * in->height)
        return snprintf(err, errlen, "count %u beyond the %ux%u image", in->count, in->width, in->height), -1;
    for (int k = 0; k < 3; k++)
        if (!isfinite(in->origin[k]) || !(in->extent[k] >= 0) || !isfinite(in->extent[k]))
            return snprintf(err, errlen, "engine origin or extent is not finite (or the extent negative)"), -1;
    const uint8_t *z = buf + in->header_bytes;
    size_t zlen = len - in->header_bytes, frame = ZSTD_findFrameCompressedSize(z, zlen);
    if (zbytes != zlen || ZSTD_isError(frame) || frame != zlen)
        return snprintf(err, errlen, "the zstd frame does not fill the payload's %zu bytes after the header (zstd_bytes %u)",
                        zlen, zbytes), -1;
    if (ZSTD_getFrameContentSize(z, zlen) != in->raw_bytes)
        return snprintf(err, errlen, "the zstd frame's content size is not raw_bytes %u", in->raw_bytes), -1;
    return 0;
}

/* The raw texels of a checked payload (malloc'ed, info->raw_bytes), or NULL with a message. */
static uint8_t *engine_unpack(const uint8_t *buf, size_t len, const struct fxs_engine_info *in, char *err, size_t errlen)
{
    uint8_t *raw = malloc(in->raw_bytes);
    if (!raw) return snprintf(err, errlen, "out of memory (%u bytes)", in->raw_bytes), NULL;
    size_t n = ZSTD_decompress(raw, in->raw_bytes, buf + in->header_bytes, len - in->header_bytes);
    if (ZSTD_isError(n) || n != in->raw_bytes) {
        snprintf(err, errlen, "zstd: %s", ZSTD_isError(n) ? ZSTD_getErrorName(n) : "short content");
        free(raw);
        return NULL;
    }
    return raw;
}

static float engine_half_at(const uint8_t *p) { return fxs_half_to_float(fxs_get_u16(p)); }

/* The header of a particle payload, checked for what particles need. 0, or -1 with a message. */
static int engine_particles_check(const uint8_t *buf, size_t len, struct fxs_engine_info *in, char *err, size_t errlen)
{
    if (fxs_engine_info(buf, len, in, err, errlen)) return -1;
    if (in->format != FXS_ENGINE_RGBA16F)
        return snprintf(err, errlen, "particles need texel format 1 (RGBA16F), not %u", in->format), -1;
    if (in->count > FXS_PARTICLES_MAX_N) return snprintf(err, errlen, "%u particles: at most %u", in->count, FXS_PARTICLES_MAX_N), -1;
    return 0;
}

int fxs_engine_particles_info(const uint8_t *buf, size_t len, uint32_t *n, int *vel, char *err, size_t errlen)
{
    struct fxs_engine_info in;
    if (engine_particles_check(buf, len, &in, err, errlen)) return -1;
    *n = in.count;
    *vel = in.layers == 2;
    return 0;
}

int fxs_engine_decode_particles_into(const uint8_t *buf, size_t len, struct fxs_particles *p, uint32_t capacity,
                                     char *err, size_t errlen)
{
    struct fxs_engine_info in;
    if (engine_particles_check(buf, len, &in, err, errlen)) return -1;
    if (in.count > capacity) {
        p->n = in.count;
        return 1;
    }
    if (in.count && (!p->xyz || !p->temp)) return snprintf(err, errlen, "no output arrays given"), -1;
    uint8_t *raw = engine_unpack(buf, len, &in, err, errlen);
    if (!raw) return -1;
    size_t n = in.count, layer = (size_t)in.width * in.height * 8;
    float *vel = in.layers == 2 ? p->vel : NULL;
    p->n = in.count;
    for (size_t i = 0; i < n; i++) {
        const uint8_t *t = raw + 8 * i;
        for (int k = 0; k < 3; k++) p->xyz[3 * i + k] = in.origin[k] + engine_half_at(t + 2 * k);
        p->temp[i] = engine_half_at(t + 6);
        for (int k = 0; k < 3 && vel; k++) vel[3 * i + k] = engine_half_at(t + layer + 2 * k);
        int finite = isfinite(p->xyz[3 * i]) && isfinite(p->xyz[3 * i + 1]) && isfinite(p->xyz[3 * i + 2]) && isfinite(p->temp[i]);
        for (int k = 0; k < 3 && vel; k++) finite = finite && isfinite(vel[3 * i + k]);
        if (!finite) {
            free(raw);
            return snprintf(err, errlen, "particle %zu is not finite", i), -1;
        }
    }
    free(raw);
    return 0;
}

int fxs_engine_decode_particles(const uint8_t *buf, size_t len, struct fxs_particles *p, char *err, size_t errlen)
{
    uint32_t n;
    int vel;
    memset(p, 0, sizeof *p);
    if (fxs_engine_particles_info(buf, len, &n, &vel, err, errlen)) return -1;
    size_t m = n ? n : 1;
    p->xyz = malloc(12 * m);
    p->temp = malloc(4 * m);
    p->vel = vel ? malloc(12 * m) : NULL;
    if (!p->xyz || !p->temp || (vel && !p->vel)) {
        fxs_particles_free(p);
        return snprintf(err, errlen, "out of memory (%u particles)", n), -1;
    }
    if (!fxs_engine_decode_particles_into(buf, len, p, n, err, errlen)) return 0;
    fxs_particles_free(p);
    return -1;
}

/* The header of a texture payload, checked for what textures need. 0, or -1 with a message. */
static int engine_texture_check(const uint8_t *buf, size_t len, struct fxs_engine_info *in, char *err, size_t errlen)
{
    if (fxs_engine_info(buf, len, in, err, errlen)) return -1;
    if (in->layers != 1 || in->count) return snprintf(err, errlen, "a texture has one layer and count 0"), -1;
    return 0;
}

int fxs_engine_decode_texture_into(const uint8_t *buf, size_t len, struct fxs_engine_info *in, float *texels,
                                   size_t capacity, char *err, size_t errlen)
{
    if (engine_texture_check(buf, len, in, err, errlen)) return -1;
    size_t n = in->raw_bytes / 2;
    if (n > capacity || !texels) return 1;
    uint8_t *raw = engine_unpack(buf, len, in, err, errlen);
    if (!raw) return -1;
    for (size_t i = 0; i < n; i++) texels[i] = engine_half_at(raw + 2 * i);
    free(raw);
    return 0;
}

int fxs_engine_decode_texture(const uint8_t *buf, size_t len, struct fxs_engine_info *in, float **texels,
                              char *err, size_t errlen)
{
    *texels = NULL;
    if (engine_texture_check(buf, len, in, err, errlen)) return -1;
    size_t n = in->raw_bytes / 2;
    float *out = malloc(4 * n);
    if (!out) return snprintf(err, errlen, "out of memory (%zu values)", n), -1;
    if (fxs_engine_decode_texture_into(buf, len, in, out, n, err, errlen)) {
        free(out);
        return -1;
    }
    *texels = out;
    return 0;
}
