/* fxs_lut.c — see fxs_lut.h. Every size and offset is checked against the payload on decode. */
#include "fxs_lut.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zstd.h>

#include "fxs_bytes.h"

static size_t lut_raw(const struct fxs_lut_product *p) { return (size_t)p->width * p->height * 4; }

size_t fxs_lut_bound(const struct fxs_lut_product *products, int count)
{
    size_t n = FXS_LUT_HEADER_BYTES + (size_t)count * FXS_LUT_ENTRY_BYTES;
    for (int i = 0; i < count; i++) n += 8 + ZSTD_compressBound(lut_raw(&products[i]));
    return n;
}

static void lut_header(const struct fxs_lut_info *in, int count, uint8_t *h)
{
    memset(h, 0, FXS_LUT_HEADER_BYTES);
    memcpy(h, FXS_LUT_MAGIC, 4);
    fxs_put_u16(h + 4, FXS_LUT_VERSION);
    fxs_put_u16(h + 6, FXS_LUT_HEADER_BYTES);
    fxs_put_u16(h + 8, (uint16_t)count);
    fxs_put_u16(h + 10, FXS_LUT_ENTRY_BYTES);
    fxs_put_u32(h + 12, in->lattice);
    fxs_put_f32(h + 16, in->tile_h);
    fxs_put_f32(h + 20, in->lens_radius);
    fxs_put_f32(h + 24, in->refractive_index);
    fxs_put_f32(h + 28, in->pigment_depth);
    fxs_put_u32(h + 32, in->max_passes);
    fxs_put_u32(h + 36, in->cells);
    fxs_put_u32(h + 40, in->dirs);
    fxs_put_u32(h + 44, in->gutter);
    fxs_put_u32(h + 48, in->supersample);
}

static void lut_entry(const struct fxs_lut_product *p, uint8_t *e)
{
    memset(e, 0, FXS_LUT_ENTRY_BYTES);
    memcpy(e, p->name, 4);
    fxs_put_u32(e + 4, p->format);
    fxs_put_u32(e + 8, p->codec);
    fxs_put_u32(e + 12, p->width);
    fxs_put_u32(e + 16, p->height);
    fxs_put_u32(e + 20, p->offset);
    fxs_put_u32(e + 24, p->stored);
    fxs_put_u32(e + 28, p->raw);
    fxs_put_u32(e + 32, p->tile);
    fxs_put_u32(e + 36, p->tiles_x);
    fxs_put_u32(e + 40, p->tiles_y);
    fxs_put_u32(e + 44, p->inner);
}

int fxs_lut_encode_begin(struct fxs_lut_encoder *e, const struct fxs_lut_info *info, struct fxs_lut_product *products,
                         int count, int zstd_level, uint8_t *out, size_t cap, char *msg, size_t msgcap)
{
    *e = (struct fxs_lut_encoder){.products = products, .count = count, .level = zstd_level, .out = out, .cap = cap};
    e->zstd = ZSTD_createCCtx();
    if (!e->zstd) return snprintf(msg, msgcap, "zstd: out of memory"), -1;
    lut_header(info, count, out);
    e->len = FXS_LUT_HEADER_BYTES + (size_t)count * FXS_LUT_ENTRY_BYTES;
    return 0;
}

/* Starts product cur's zstd frame, 8-aligned, with its size pledged (it goes into the frame header). */
static int lut_product_begin(struct fxs_lut_encoder *e, struct fxs_lut_product *p, char *msg, size_t msgcap)
{
    while (e->len % 8) e->out[e->len++] = 0;
    p->offset = (uint32_t)e->len;
    size_t z = ZSTD_CCtx_reset(e->zstd, ZSTD_reset_session_and_parameters);
    if (!ZSTD_isError(z)) z = ZSTD_CCtx_setParameter(e->zstd, ZSTD_c_compressionLevel, e->level);
    if (!ZSTD_isError(z)) z = ZSTD_CCtx_setPledgedSrcSize(e->zstd, lut_raw(p));
    return ZSTD_isError(z) ? snprintf(msg, msgcap, "zstd (%s): %s", p->name, ZSTD_getErrorName(z)), -1 : 0;
}

int fxs_lut_encode_some(struct fxs_lut_encoder *e, size_t bytes, char *msg, size_t msgcap)
{
    while (e->cur < e->count) {
        struct fxs_lut_product *p = &e->products[e->cur];
        size_t raw = lut_raw(p), take = raw - e->done < bytes ? raw - e->done : bytes;
        if (e->done == 0 && lut_product_begin(e, p, msg, msgcap)) return -1;
        ZSTD_EndDirective mode = e->done + take == raw ? ZSTD_e_end : ZSTD_e_continue;
        ZSTD_inBuffer in = {p->rgba + e->done, take, 0};
        ZSTD_outBuffer zout = {e->out + e->len, e->cap - e->len, 0};
        size_t left;
        do { /* until the input is taken, and with e_end the frame is flushed */
            left = ZSTD_compressStream2(e->zstd, &zout, &in, mode);
            if (ZSTD_isError(left)) return snprintf(msg, msgcap, "zstd (%s): %s", p->name, ZSTD_getErrorName(left)), -1;
            if (zout.pos == zout.size && (in.pos < in.size || (mode == ZSTD_e_end && left)))
                return snprintf(msg, msgcap, "zstd (%s): the output is full", p->name), -1;
        } while (in.pos < in.size || (mode == ZSTD_e_end && left));
        e->len += zout.pos;
        e->done += take;
        bytes -= take;
        if (e->done < raw) return 1;
        p->format = FXS_LUT_FORMAT_RGBA8;
        p->codec = FXS_LUT_CODEC_ZSTD;
        p->stored = (uint32_t)(e->len - p->offset);
        p->raw = (uint32_t)raw;
        lut_entry(p, e->out + FXS_LUT_HEADER_BYTES + (size_t)e->cur * FXS_LUT_ENTRY_BYTES);
        e->cur++;
        e->done = 0;
        if (!bytes && e->cur < e->count) return 1;
    }
    return 0;
}

void fxs_lut_encode_free(struct fxs_lut_encoder *e)
{
    ZSTD_freeCCtx(e->zstd);
    e->zstd = NULL;
}

/* Checks the container's magic and that its directory lies inside the payload: the directory's
 * offset, entry count and entry size, or -1 with msg. */
static int lut_directory(const uint8_t *p, size_t len, uint32_t *hb, uint32_t *count, uint32_t *eb, char *msg,
                         size_t cap)
{
    if (len < 12 || memcmp(p, FXS_LUT_MAGIC, 4)) return snprintf(msg, cap, "not an FXL1 container"), -1;
    *hb = fxs_get_u16(p + 6);
    *count = fxs_get_u16(p + 8);
    *eb = fxs_get_u16(p + 10);
    if (*hb < FXS_LUT_HEADER_BYTES || *eb < 48 || *hb + (size_t)*count * *eb > len)
        return snprintf(msg, cap, "container directory runs past the payload"), -1;
    return 0;
}

int fxs_lut_entry(const uint8_t *p, size_t len, int i, struct fxs_lut_product *out, char *msg, size_t cap)
{
    uint32_t hb, count, eb;
    if (lut_directory(p, len, &hb, &count, &eb, msg, cap)) return -1;
    if (i < 0 || (uint32_t)i >= count) return snprintf(msg, cap, "no product %d", i), -1;
    const uint8_t *e = p + hb + (size_t)i * eb;
    memset(out, 0, sizeof *out);
    memcpy(out->name, e, 4);
    out->format = fxs_get_u32(e + 4);
    out->codec = fxs_get_u32(e + 8);
    out->width = fxs_get_u32(e + 12);
    out->height = fxs_get_u32(e + 16);
    out->offset = fxs_get_u32(e + 20);
    out->stored = fxs_get_u32(e + 24);
    out->raw = fxs_get_u32(e + 28);
    out->tile = fxs_get_u32(e + 32);
    out->tiles_x = fxs_get_u32(e + 36);
    out->tiles_y = fxs_get_u32(e + 40);
    out->inner = fxs_get_u32(e + 44);
    if ((size_t)out->offset + out->stored > len) return snprintf(msg, cap, "product %s runs past the payload", out->name), -1;
    return (int)count;
}

int fxs_lut_header(const uint8_t *p, size_t len, struct fxs_lut_info *info, char *msg, size_t cap)
{
    uint32_t hb, count, eb;
    if (lut_directory(p, len, &hb, &count, &eb, msg, cap)) return -1;
    if (fxs_get_u16(p + 4) != FXS_LUT_VERSION)
        return snprintf(msg, cap, "unsupported FXL1 version %u", (unsigned)fxs_get_u16(p + 4)), -1;
    info->lattice = fxs_get_u32(p + 12);
    info->tile_h = fxs_get_f32(p + 16);
    info->lens_radius = fxs_get_f32(p + 20);
    info->refractive_index = fxs_get_f32(p + 24);
    info->pigment_depth = fxs_get_f32(p + 28);
    info->max_passes = fxs_get_u32(p + 32);
    info->cells = fxs_get_u32(p + 36);
    info->dirs = fxs_get_u32(p + 40);
    info->gutter = fxs_get_u32(p + 44);
    info->supersample = fxs_get_u32(p + 48);
    return (int)count;
}

int fxs_lut_texels_into(const uint8_t *p, size_t len, const struct fxs_lut_product *e, uint8_t *out, size_t cap,
                        char *msg, size_t msgcap)
{
    if (e->format != FXS_LUT_FORMAT_RGBA8 || e->codec != FXS_LUT_CODEC_ZSTD || (uint64_t)e->width * e->height * 4 != e->raw) {
        snprintf(msg, msgcap, "product %s: unsupported format %u / codec %u", e->name, e->format, e->codec);
        return -1;
    }
    if (e->raw > FXS_LUT_MAX_RAW) {
        snprintf(msg, msgcap, "product %s: %u bytes of texels, over the limit of %u", e->name, e->raw, FXS_LUT_MAX_RAW);
        return -1;
    }
    if ((size_t)e->offset + e->stored > len) {
        snprintf(msg, msgcap, "product %s runs past the payload", e->name);
        return -1;
    }
    unsigned long long content = ZSTD_getFrameContentSize(p + e->offset, e->stored);
    if (content == ZSTD_CONTENTSIZE_ERROR || (content != ZSTD_CONTENTSIZE_UNKNOWN && content != e->raw)) {
        snprintf(msg, msgcap, "product %s: %s", e->name, content == ZSTD_CONTENTSIZE_ERROR ? "not a zstd frame"
                                                                                          : "zstd frame of another size");
        return -1;
    }
    if (!out || cap < e->raw) return 1;
    size_t n = ZSTD_decompress(out, e->raw, p + e->offset, e->stored);
    if (ZSTD_isError(n) || n != e->raw) {
        snprintf(msg, msgcap, "product %s: %s", e->name, ZSTD_isError(n) ? ZSTD_getErrorName(n) : "size mismatch");
        return -1;
    }
    return 0;
}

uint8_t *fxs_lut_texels(const uint8_t *p, size_t len, const struct fxs_lut_product *e, char *msg, size_t cap)
{
    uint8_t *out = NULL;
    if (fxs_lut_texels_into(p, len, e, NULL, 0, msg, cap) < 0) return NULL; /* checked before allocating */
    if (!(out = malloc(e->raw ? e->raw : 1))) snprintf(msg, cap, "product %s: out of memory", e->name);
    if (out && fxs_lut_texels_into(p, len, e, out, e->raw ? e->raw : 1, msg, cap)) {
        free(out);
        return NULL;
    }
    return out;
}
