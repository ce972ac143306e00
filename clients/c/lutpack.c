/* lutpack.c — see lutpack.h. Every size and offset is checked against the payload. */
#include "lutpack.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <zstd.h>

#include "fxs_frame.h"

int lutpack_entry(const uint8_t *p, size_t len, int i, struct lutpack_product *out, char *msg, size_t cap)
{
    if (len < 12 || memcmp(p, "FXL1", 4)) return snprintf(msg, cap, "not an FXL1 container"), -1;
    uint32_t hb = fxs_get_u16(p + 6), count = fxs_get_u16(p + 8), eb = fxs_get_u16(p + 10);
    if (hb < 64 || eb < 48 || hb + (size_t)count * eb > len)
        return snprintf(msg, cap, "container directory runs past the payload"), -1;
    if (i < 0 || (uint32_t)i >= count) return snprintf(msg, cap, "no product %d", i), -1;
    const uint8_t *e = p + hb + (size_t)i * eb;
    memcpy(out->name, e, 4);
    out->name[4] = 0;
    out->format = fxs_get_u32(e + 4);
    out->codec = fxs_get_u32(e + 8);
    out->width = fxs_get_u32(e + 12);
    out->height = fxs_get_u32(e + 16);
    out->offset = fxs_get_u32(e + 20);
    out->stored = fxs_get_u32(e + 24);
    out->raw = fxs_get_u32(e + 28);
    if ((size_t)out->offset + out->stored > len) return snprintf(msg, cap, "product %s runs past the payload", out->name), -1;
    return (int)count;
}

uint8_t *lutpack_texels(const uint8_t *p, size_t len, const struct lutpack_product *e, char *msg, size_t cap)
{
    (void)len;
    if (e->format != 1 || e->codec != 1 || (uint64_t)e->width * e->height * 4 != e->raw) {
        snprintf(msg, cap, "product %s: unsupported format %u / codec %u", e->name, e->format, e->codec);
        return NULL;
    }
    uint8_t *out = malloc(e->raw ? e->raw : 1);
    size_t n = out ? ZSTD_decompress(out, e->raw, p + e->offset, e->stored) : 0;
    if (!out || ZSTD_isError(n) || n != e->raw) {
        snprintf(msg, cap, "product %s: %s", e->name, out && ZSTD_isError(n) ? ZSTD_getErrorName(n) : "size mismatch");
        free(out);
        return NULL;
    }
    return out;
}
