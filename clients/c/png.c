/* png.c — see png.h. PNG (ISO/IEC 15948): signature, IHDR, one IDAT holding a zlib
 * stream of stored deflate blocks (RFC 1950/1951) over the filtered rows (filter 0), IEND. */
#include "png.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static uint32_t png_crc_table[256];

static void png_crc_init(void)
{
    for (uint32_t n = 0; n < 256; n++) {
        uint32_t c = n;
        for (int k = 0; k < 8; k++) c = c & 1 ? 0xedb88320u ^ (c >> 1) : c >> 1;
        png_crc_table[n] = c;
    }
}

static uint32_t png_crc(uint32_t crc, const uint8_t *p, size_t n)
{
    for (size_t i = 0; i < n; i++) crc = png_crc_table[(crc ^ p[i]) & 0xff] ^ (crc >> 8);
    return crc;
}

static void png_be32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v >> 24), p[1] = (uint8_t)(v >> 16), p[2] = (uint8_t)(v >> 8), p[3] = (uint8_t)v;
}

static int png_chunk(FILE *f, const char *type, const uint8_t *data, size_t n)
{
    uint8_t head[8], tail[4];
    png_be32(head, (uint32_t)n);
    memcpy(head + 4, type, 4);
    uint32_t crc = png_crc(png_crc(0xffffffffu, head + 4, 4), data, n) ^ 0xffffffffu;
    png_be32(tail, crc);
    return fwrite(head, 1, 8, f) == 8 && fwrite(data, 1, n, f) == n && fwrite(tail, 1, 4, f) == 4 ? 0 : -1;
}

/* The zlib stream of the filtered image: 2-byte header, stored blocks, Adler-32. */
static uint8_t *png_zlib(const uint8_t *rgba, uint32_t w, uint32_t h, size_t *len)
{
    size_t row = 1 + 4 * (size_t)w, raw = row * h, blocks = raw / 65535 + 1;
    uint8_t *z = malloc(2 + raw + 5 * blocks + 4);
    if (!z) return NULL;
    size_t o = 0, done = 0;
    uint32_t a = 1, b = 0;
    z[o++] = 0x78;
    z[o++] = 0x01;
    while (done < raw || done == 0) {
        size_t n = raw - done < 65535 ? raw - done : 65535;
        z[o++] = done + n == raw;
        z[o++] = (uint8_t)n, z[o++] = (uint8_t)(n >> 8);
        z[o++] = (uint8_t)~n, z[o++] = (uint8_t)(~n >> 8);
        for (size_t i = 0; i < n; i++, done++) {
            size_t y = done / row, x = done % row;
            uint8_t v = x == 0 ? 0 : rgba[y * 4 * (size_t)w + x - 1];
            z[o++] = v;
            a = (a + v) % 65521u;
            b = (b + a) % 65521u;
        }
        if (raw == 0) break;
    }
    png_be32(z + o, (b << 16) | a);
    *len = o + 4;
    return z;
}

int png_write_rgba8(const char *path, const uint8_t *rgba, uint32_t w, uint32_t h)
{
    static const uint8_t sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    uint8_t ihdr[13];
    size_t zlen;
    if (!png_crc_table[1]) png_crc_init();
    png_be32(ihdr, w);
    png_be32(ihdr + 4, h);
    ihdr[8] = 8, ihdr[9] = 6, ihdr[10] = ihdr[11] = ihdr[12] = 0; /* 8-bit RGBA, deflate, filter 0, no interlace */
    uint8_t *z = png_zlib(rgba, w, h, &zlen);
    FILE *f = z ? fopen(path, "wb") : NULL;
    int rc = f && fwrite(sig, 1, 8, f) == 8 && !png_chunk(f, "IHDR", ihdr, 13) && !png_chunk(f, "IDAT", z, zlen) &&
                     !png_chunk(f, "IEND", NULL, 0)
                 ? 0
                 : -1;
    if (f && fclose(f)) rc = -1;
    if (!z) errno = ENOMEM;
    free(z);
    return rc;
}
