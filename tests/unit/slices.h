/* slices.h — for the kernel tests: one step of an effect run to its end in slices of a given
 * budget (effect.h: slice_end), keeping the default payload of one kind of frame (made by its
 * encode callback when the effect defers it), so that a test can compare a frame stepped in
 * pieces with the same frame stepped whole. */
#ifndef FX_TEST_SLICES_H
#define FX_TEST_SLICES_H

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "clock.h"
#include "effect.h"

struct slices_frame {
    uint16_t kind;     /* the kind kept */
    uint8_t *payload;  /* its payload (malloc'ed), NULL when none was emitted */
    size_t len;
    int calls;         /* step calls the frame took */
};

static int slices_emit(void *ctx, const struct effect_frame *ef)
{
    struct slices_frame *out = ctx;
    struct effect_frame f = *ef;
    struct fx_err err = {0};
    if (f.kind != out->kind) return 0;
    if (effect_frame_encode(&f, &err)) return -1;
    free(out->payload);
    out->payload = malloc(f.payload_bytes ? f.payload_bytes : 1);
    if (!out->payload) return -1;
    memcpy(out->payload, f.payload, f.payload_bytes);
    out->len = f.payload_bytes;
    return 0;
}

/* Steps state to sim_time until the step completes, each call given budget seconds (INFINITY:
 * one call; 0: one piece per call). 0, or the step's -1 with err. */
static int slices_step(const struct effect_ops *ops, void *state, double sim_time, double budget,
                       struct slices_frame *out, struct fx_err *err)
{
    int rc;
    out->calls = 0;
    do {
        double end = isinf(budget) ? INFINITY : clock_now() + budget;
        rc = ops->step(state, sim_time, out->calls ? 0.0 : 1.0 / 30, end, slices_emit, out, err);
        out->calls++;
    } while (rc == EFFECT_MORE);
    return rc;
}

static void slices_free(struct slices_frame *f)
{
    free(f->payload);
    f->payload = NULL;
}

#endif
