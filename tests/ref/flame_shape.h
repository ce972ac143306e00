/* flame_shape.h — the flame's shape figures (H90, W90, share below the source, flicker,
 * centroid), measured on particle states the way a client measures them on the stream's
 * frames (tests and benches only).
 *
 * "Burning" = a gas particle with T >= T_ign. Heights run along `up` from the sources' plane
 * (through the mean of the enabled sources' centres: the source's centre when there is one),
 * lateral distances from the vertical line through that centre. Frames are added one at a time; the figures pool every added frame. Simulated time,
 * not wall time: the stream's frames are these states whenever it keeps real time. */
#ifndef FX_FLAME_SHAPE_H
#define FX_FLAME_SHAPE_H

#include "effects/flame.h"
#include "params.h"

struct flame_shape_acc {
    double c[3], up[3], T_ign;
    double *h, *w;    /* heights and lateral distances of every burning particle added */
    size_t n, cap;
    double *p99;      /* per frame: 99th percentile height of its burning particles */
    double lat[3];    /* sum of the burning particles' lateral offsets (centroid) */
    double height_sum;
    int frames;
    double particles; /* sum over frames of all particles */
};

struct flame_shape {
    double H90, W90;      /* 90th percentiles of height and lateral distance, m */
    double below;         /* share of burning particles below the source plane */
    double flicker;       /* standard deviation / mean of the per-frame 99th percentile height */
    double centroid_h;    /* mean height of burning particles, m */
    double centroid_lat[3]; /* mean lateral offset of burning particles (a vector normal to up), m */
    double burning, particles; /* mean per frame */
};

/* Runs the scene of the complete document doc: warm_s simulated seconds, then one state every
 * 1/30 s of simulated time for `seconds`, measured from the sources' centre. 0 or -1 (err). */
int flame_shape_run(struct ocl *ocl, const cJSON *doc, double warm_s, double seconds, struct flame_shape *out,
                    struct fx_err *err);

/* What flame_shape_run does with each state it measures: acc is the run's accumulator, set up for
 * the scene (its sources' centre, up and T_ign; flame_shape_run's adds p to it). */
typedef void (*flame_shape_each)(void *ctx, struct flame_shape_acc *acc, const struct flame_particles *p);
/* flame_shape_run with each(ctx, acc, p) called for every state (p as flame_read gives it, ids
 * included); out: the run's accumulator's figures. 0 or -1 (err). */
int flame_shape_frames(struct ocl *ocl, const cJSON *doc, double warm_s, double seconds, flame_shape_each each,
                       void *ctx, struct flame_shape *out, struct fx_err *err);

/* The JSON overrides of the flame's built-in preset `name`, or NULL. */
const char *flame_shape_preset(const char *name);

void flame_shape_init(struct flame_shape_acc *a, const double c[3], const double up[3], double T_ign);
void flame_shape_add(struct flame_shape_acc *a, const struct flame_particles *p);
void flame_shape_result(struct flame_shape_acc *a, struct flame_shape *out);
void flame_shape_free(struct flame_shape_acc *a);

#endif
