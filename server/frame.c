/* frame.c — see frame.h. */
#include <stdlib.h>
#include <string.h>

#include "frame.h"

struct frame *frame_new(const struct fxs_header *hdr, uint32_t total, const void *payload, size_t n)
{
    if (n > UINT32_MAX) return NULL;
    struct frame *f = malloc(sizeof *f + FRAME_HEADROOM + FXS_HEADER_BYTES + n);
    if (!f) return NULL;
    atomic_init(&f->refs, 1);
    f->hdr = *hdr;
    f->hdr.header_bytes = FXS_HEADER_BYTES;
    f->hdr.payload_bytes = (uint32_t)n;
    f->bytes = f->storage + FRAME_HEADROOM;
    f->len = FXS_HEADER_BYTES + n;
    fxs_header_pack(&f->hdr, f->bytes);
    fxs_header_set_total(f->bytes, total);
    if (n) memcpy(f->bytes + FXS_HEADER_BYTES, payload, n);
    return f;
}

struct frame *frame_ref(struct frame *f)
{
    atomic_fetch_add(&f->refs, 1);
    return f;
}

void frame_unref(struct frame *f)
{
    if (f && atomic_fetch_sub(&f->refs, 1) == 1) free(f);
}
