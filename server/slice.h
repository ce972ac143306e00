/* slice.h — how much of a long piece of work fits into one slice of a step (effect.h: a step
 * stops at slice_end and goes on at its next turn).
 *
 * A meter learns the seconds one unit of a kind of work takes (a work-item of a kernel, a row
 * of an atlas, a megabyte to compress) from the launches it timed, and sizes the next launch to
 * end by the slice's deadline. The first launch is a small probe, and no launch is more than
 * SLICE_GROWTH times the largest one timed, so a cost the probe misjudged (work is uneven across
 * a picture) makes one slice somewhat longer, never seconds long. */
#ifndef FX_SLICE_H
#define FX_SLICE_H

#include <stddef.h>

#define SLICE_GROWTH 4

struct slice_meter {
    size_t probe;    /* units of the first launch; set by the owner */
    double per_unit; /* seconds per unit, smoothed; 0 until a launch was timed */
    size_t largest;  /* units of the largest launch timed */
};

/* Units to launch next, 1 to left: all of them when end is INFINITY (no slicing), otherwise as
 * many as the meter expects to finish between now and end (at least one). */
size_t slice_units(const struct slice_meter *m, size_t left, double now, double end);
/* Records that `units` took `seconds`. */
void slice_record(struct slice_meter *m, size_t units, double seconds);

#endif
