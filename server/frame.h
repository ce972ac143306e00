/* frame.h — one encoded frame (64-byte header + payload), immutable and ref-counted.
 *
 * A frame is encoded once per stream step and the same bytes go to every subscriber.
 * FRAME_HEADROOM spare bytes precede the frame so the network layer can put the
 * WebSocket framing in front without copying (libwebsockets' LWS_PRE; net.c checks
 * that it fits). */
#ifndef FX_FRAME_H
#define FX_FRAME_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "fxs_frame.h"

#define FRAME_HEADROOM 32

struct frame {
    atomic_int refs;
    struct fxs_header hdr;
    size_t len;     /* header + payload bytes */
    uint8_t *bytes; /* FRAME_HEADROOM bytes into storage */
    uint8_t storage[];
};

/* A new frame with one reference: hdr (payload_bytes set from n) and total packed, payload copied. */
struct frame *frame_new(const struct fxs_header *hdr, uint32_t total, const void *payload, size_t n);
struct frame *frame_ref(struct frame *f);
void frame_unref(struct frame *f); /* NULL is fine */

#endif
