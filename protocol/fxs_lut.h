/* fxs_lut.h — the kind 4 codec 1 payload ("FXL1" container, PROTOCOL.md §7.6): a 64-byte
 * header with the compound eye's optics, a directory of 64-byte entries, and each product's
 * RGBA8 texels as one zstd frame, 8-byte aligned.
 *
 * Shared by the daemon (server/effects/eye_lut.c lays out the products and encodes them
 * here) and libfxclient (fxctl, the fuzz target), as fxs_particles.h is. Depends on libc
 * and libzstd only. */
#ifndef FXS_LUT_H
#define FXS_LUT_H

#include <stddef.h>
#include <stdint.h>

#define FXS_LUT_MAGIC "FXL1"
#define FXS_LUT_VERSION 1
#define FXS_LUT_HEADER_BYTES 64
#define FXS_LUT_ENTRY_BYTES 64
#define FXS_LUT_FORMAT_RGBA8 1
#define FXS_LUT_CODEC_ZSTD 1
/* Most texels of one product a decoder inflates (the largest table, lut_dirs 64 x (lut_cells
 * 64 + 2) squared, is 71 MB): a few kB of zstd could otherwise ask for gigabytes. */
#define FXS_LUT_MAX_RAW (256u << 20)

/* The container header's fields after the directory sizes. */
struct fxs_lut_info {
    uint32_t lattice; /* 0 square, 1 hexagonal */
    float tile_h, lens_radius, refractive_index, pigment_depth;
    uint32_t max_passes, cells, dirs, gutter, supersample;
};

/* A directory entry. offset/stored/raw are the encoder's output and the decoder's input;
 * rgba (width x height x 4 bytes) is the encoder's input only. */
struct fxs_lut_product {
    char name[5];
    uint32_t format, codec, width, height, offset, stored, raw;
    uint32_t tile, tiles_x, tiles_y, inner;
    const uint8_t *rgba;
};

/* Bytes the encoder may need for these products (directory, alignment, zstd bounds). */
size_t fxs_lut_bound(const struct fxs_lut_product *products, int count);

/* The encoder writes the container into out (cap bytes, at least fxs_lut_bound) a piece at a
 * time, so that a big table can be encoded between other work: begin writes the header, each
 * fxs_lut_encode_some compresses up to `bytes` more of the products' texels, in order (one zstd
 * frame per product, its size in the frame header), filling each product's offset, stored and
 * raw as it completes. */
struct fxs_lut_encoder {
    struct fxs_lut_product *products;
    int count, level;
    int cur;         /* the product being compressed */
    size_t done;     /* its texel bytes compressed so far */
    uint8_t *out;
    size_t cap, len; /* len: the container's bytes so far */
    void *zstd;      /* ZSTD_CCtx */
};
/* 0, or -1 with msg (out of memory). */
int fxs_lut_encode_begin(struct fxs_lut_encoder *e, const struct fxs_lut_info *info, struct fxs_lut_product *products,
                         int count, int zstd_level, uint8_t *out, size_t cap, char *msg, size_t msgcap);
/* 1 while texels are left, 0 once the container is complete (e->len bytes), -1 with msg. */
int fxs_lut_encode_some(struct fxs_lut_encoder *e, size_t bytes, char *msg, size_t msgcap);
void fxs_lut_encode_free(struct fxs_lut_encoder *e);

/* Reads entry i of a container (0..count-1). Returns the entry count (>= 0), or -1 with msg
 * when the container is malformed or i is out of range. */
int fxs_lut_entry(const uint8_t *p, size_t len, int i, struct fxs_lut_product *out, char *msg, size_t cap);
/* Reads the container header into info. Returns the entry count (>= 0), or -1 with msg when
 * the container is malformed or of another version. */
int fxs_lut_header(const uint8_t *p, size_t len, struct fxs_lut_info *info, char *msg, size_t cap);
/* Decompresses a product into out (cap bytes). Returns 0; 1 when out is NULL or smaller than
 * e->raw (nothing written); -1 with msg when the entry or its data is malformed. */
int fxs_lut_texels_into(const uint8_t *p, size_t len, const struct fxs_lut_product *e, uint8_t *out, size_t cap,
                        char *msg, size_t msgcap);
/* Decompresses a product into a malloc'ed buffer of raw texels; NULL with msg on error. */
uint8_t *fxs_lut_texels(const uint8_t *p, size_t len, const struct fxs_lut_product *e, char *msg, size_t cap);

#endif
