/* fxs_rangecoder.c — the range coder's out-of-line part: growing the encoder's output
 * sections (fxs_rangecoder.h has the coder itself, inline for the hot loops). */
#include "fxs_rangecoder.h"

#include <stdlib.h>

uint8_t *fxs_rc_grow(struct fxs_rc_buf *b, uint8_t *at, size_t need)
{
    size_t used = at ? (size_t)(at - b->p) : 0, cap = b->cap ? b->cap : 4096;
    uint8_t *p;
    while (cap < used + need) cap *= 2;
    if (cap == b->cap) return at;
    if (!(p = realloc(b->p, cap))) return NULL;
    b->p = p;
    b->cap = cap;
    return p + used;
}
