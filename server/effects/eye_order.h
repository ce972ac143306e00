/* eye_order.h — the order a compound-eye kernel traces its rays in (eye_order.c).
 *
 * A work-item traces EYE_LANES neighbouring rays as the lanes of one vector and runs until the
 * slowest of them is done, and neighbouring rays differ widely in how many lenses they pass
 * through. So the kernels take ray order[slot] in each slot and write what each ray cost
 * (EYE_COST_*, kernels/compound_eye_layout.h); after a run the host sorts the rays by that
 * cost, and the next run (the next view, or table, of the same size) traces them in that order:
 * a work-item's lanes then run alike. A ray's result does not depend on its lanes' neighbours,
 * so the products are the same in any order. Only on a CPU device: on a GPU the kernels take a
 * fraction of a millisecond and the host's sort costs more than the lanes save (an H200 with a
 * 16-core host: the 512² view 4.1 -> 4.9 ms a frame sorted, the 1024² view 11.6 -> 18.3 ms). */
#ifndef FX_EYE_ORDER_H
#define FX_EYE_ORDER_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "err.h"
#include "../ocl.h"

struct eye_order {
    size_t n, npad;          /* rays; slots (n rounded up to whole work-groups: the rest padding) */
    int lanes;               /* rays a work-item traces */
    bool sorting;            /* a CPU device: the order follows the costs; else index order */
    cl_mem d_order, d_cost;  /* the slots' rays (npad ints); each ray's cost (n bytes) */
    int *order, *sorted;     /* the order in use; the last run's costs sorted */
    uint8_t *cost;           /* the last run's costs, read back */
    double lane_use;         /* the last run: its costs' sum over the lane-slots its order kept busy
                              * (NAN when not sorting: the costs are not read) */
};

/* The order of n rays in npad slots (identity), uploaded; frees o first. 0, or -1 with err. */
int eye_order_reset(struct eye_order *o, struct ocl *ocl, size_t n, size_t npad, int lanes, struct fx_err *err);
void eye_order_free(struct eye_order *o);

/* After a run, when sorting: reads the rays' costs back, sets lane_use, and takes the sorted
 * order (uploaded) when it keeps fewer lane-slots busy by more than EYE_ORDER_GAIN. 1 when the
 * order changed, 0 when it did not, -1 with err. */
int eye_order_update(struct eye_order *o, struct ocl *ocl, struct fx_err *err);

#endif
