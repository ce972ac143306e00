/* buf.h — a growable byte buffer.
 *
 * Used wherever output size is not known up front (EXR files written to memory,
 * JSON text, metrics pages). Header-only: three small functions. */
#ifndef FX_BUF_H
#define FX_BUF_H

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

struct fx_buf {
    uint8_t *data;
    size_t len;
    size_t cap;
};

/* Makes room for at least `extra` more bytes. Returns 0, or -1 when out of memory. */
static inline int fx_buf_reserve(struct fx_buf *b, size_t extra)
{
    if (b->len + extra <= b->cap) return 0;
    size_t cap = b->cap ? b->cap : 256;
    while (cap < b->len + extra) cap *= 2;
    uint8_t *p = realloc(b->data, cap);
    if (!p) return -1;
    b->data = p;
    b->cap = cap;
    return 0;
}

static inline int fx_buf_append(struct fx_buf *b, const void *src, size_t n)
{
    if (n == 0) return 0; /* b->data may still be NULL (and src too) */
    if (fx_buf_reserve(b, n)) return -1;
    memcpy(b->data + b->len, src, n);
    b->len += n;
    return 0;
}

static inline void fx_buf_free(struct fx_buf *b)
{
    free(b->data);
    b->data = NULL;
    b->len = b->cap = 0;
}

#endif
