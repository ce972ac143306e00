/* eye_order.c — see eye_order.h.
 *
 * The sort is a stable counting sort on the costs (one byte each), so rays of equal cost keep
 * their order, near their neighbours; the padding goes last. A new order costs an upload (and
 * the bake lays its geometry out again, about a tenth of a view), so it is taken only when it
 * saves EYE_ORDER_GAIN of the lane-slots; a run in the order it already uses changes nothing. */
#include "eye_order.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "compound_eye_layout.h"

#define EYE_ORDER_GAIN 0.05

void eye_order_free(struct eye_order *o)
{
    if (o->d_order) clReleaseMemObject(o->d_order);
    if (o->d_cost) clReleaseMemObject(o->d_cost);
    free(o->order);
    free(o->sorted);
    free(o->cost);
    memset(o, 0, sizeof *o);
}

static int eye_order_upload(struct eye_order *o, struct ocl *ocl, struct fx_err *err)
{
    cl_int rc = clEnqueueWriteBuffer(ocl_queue(ocl), o->d_order, CL_TRUE, 0, o->npad * sizeof *o->order, o->order, 0,
                                     NULL, NULL);
    return rc == CL_SUCCESS ? 0 : fx_fail(err, "internal", "", "upload of the rays' order: %s", ocl_errstr(rc));
}

int eye_order_reset(struct eye_order *o, struct ocl *ocl, size_t n, size_t npad, int lanes, struct fx_err *err)
{
    cl_int rc = CL_SUCCESS, rc2 = CL_SUCCESS;
    eye_order_free(o);
    *o = (struct eye_order){.n = n, .npad = npad, .lanes = lanes, .sorting = ocl_is_cpu(ocl), .lane_use = NAN};
    o->order = malloc(npad * sizeof *o->order);
    o->sorted = malloc(npad * sizeof *o->sorted);
    o->cost = malloc(n ? n : 1);
    if (!o->order || !o->sorted || !o->cost) return fx_fail(err, "internal", "", "out of memory for %zu rays' order", n);
    for (size_t k = 0; k < npad; k++) o->order[k] = (int)k;
    o->d_order = clCreateBuffer(ocl_context(ocl), CL_MEM_READ_ONLY, npad * sizeof *o->order, NULL, &rc);
    o->d_cost = clCreateBuffer(ocl_context(ocl), CL_MEM_WRITE_ONLY, n ? n : 1, NULL, &rc2);
    if (rc != CL_SUCCESS || rc2 != CL_SUCCESS)
        return fx_fail(err, "internal", "", "clCreateBuffer for %zu rays' order: %s", n, ocl_errstr(rc ? rc : rc2));
    return eye_order_upload(o, ocl, err);
}

/* Lane-slots the order keeps busy: each work-item as long as its costliest ray. */
static double eye_order_work(const struct eye_order *o, const int *order)
{
    double work = 0;
    for (size_t k0 = 0; k0 < o->npad; k0 += (size_t)o->lanes) {
        int most = 0;
        for (size_t l = 0; l < (size_t)o->lanes; l++) {
            size_t t = (size_t)order[k0 + l];
            most = t < o->n && o->cost[t] > most ? o->cost[t] : most;
        }
        work += (double)most * o->lanes;
    }
    return work;
}

int eye_order_update(struct eye_order *o, struct ocl *ocl, struct fx_err *err)
{
    size_t at[EYE_COST_MAX + 2] = {0};
    double total = 0;
    if (!o->sorting) return 0;
    cl_int rc = clEnqueueReadBuffer(ocl_queue(ocl), o->d_cost, CL_TRUE, 0, o->n, o->cost, 0, NULL, NULL);
    if (rc != CL_SUCCESS) return fx_fail(err, "internal", "", "read-back of the rays' costs: %s", ocl_errstr(rc));
    for (size_t k = 0; k < o->n; k++) at[o->cost[k] + 1]++;
    for (int c = 1; c <= EYE_COST_MAX + 1; c++) {
        total += (double)(c - 1) * (double)at[c];
        at[c] += at[c - 1];
    }
    for (size_t k = 0; k < o->n; k++) o->sorted[at[o->cost[k]]++] = (int)k;
    for (size_t k = o->n; k < o->npad; k++) o->sorted[k] = (int)k;
    double now = eye_order_work(o, o->order), best = eye_order_work(o, o->sorted);
    o->lane_use = now > 0 ? total / now : 1.0;
    if (now <= best * (1.0 + EYE_ORDER_GAIN)) return 0;
    int *t = o->order;
    o->order = o->sorted;
    o->sorted = t;
    return eye_order_upload(o, ocl, err) ? -1 : 1;
}
