/* png.h — a minimal PNG writer (RGBA8, no compression) for fxctl's output files.
 *
 * fxctl writes look-up-table products as PNG so a person can open them; the deflate
 * stream uses stored blocks only, so no compression library is needed and the writer
 * stays small. */
#ifndef FX_PNG_H
#define FX_PNG_H

#include <stdint.h>

/* Writes w x h RGBA8 pixels (row 0 first) to path. Returns 0, or -1 (errno set). */
int png_write_rgba8(const char *path, const uint8_t *rgba, uint32_t w, uint32_t h);

#endif
