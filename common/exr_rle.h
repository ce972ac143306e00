/* exr_rle.h — OpenEXR's RLE compression of one chunk's packed bytes (exr_rle.c). */
#ifndef FX_EXR_RLE_H
#define FX_EXR_RLE_H

#include <stddef.h>
#include <stdint.h>

/* Bytes of output exr_rle_compress needs for n packed bytes (a token may end past n before
 * the copy replaces it); its scratch takes n. */
#define EXR_RLE_OUT(n) ((n) + 128)

/* Compresses src[0..n) as OpenEXR's RLE codec does (the bytes split into even and odd halves,
 * each byte replaced by its difference to the one before plus 128, then runs and literals):
 * the same bytes as OpenEXRCore's own. Returns the compressed size, or n with out holding a
 * copy of src where the compression would not be smaller (as OpenEXR stores such a chunk). */
size_t exr_rle_compress(const uint8_t *src, size_t n, uint8_t *scratch, uint8_t *out);

#endif
