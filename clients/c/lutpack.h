/* lutpack.h — reading the kind 4 codec 1 container ("FXL1", PROTOCOL.md §7.6) on the
 * client side: the directory and each product's decompressed RGBA8 texels. */
#ifndef FX_LUTPACK_H
#define FX_LUTPACK_H

#include <stddef.h>
#include <stdint.h>

struct lutpack_product {
    char name[5];
    uint32_t format, codec, width, height, offset, stored, raw;
};

/* Reads entry i of the container (0..count-1). Returns the entry count (>= 0), or -1
 * with msg when the container is malformed or i is out of range. */
int lutpack_entry(const uint8_t *p, size_t len, int i, struct lutpack_product *out, char *msg, size_t cap);

/* Decompresses a product into a malloc'ed buffer of raw bytes; NULL with msg on error. */
uint8_t *lutpack_texels(const uint8_t *p, size_t len, const struct lutpack_product *e, char *msg, size_t cap);

#endif
