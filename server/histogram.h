/* histogram.h — a fixed-bucket latency histogram that one thread fills and /metrics reads
 * (Prometheus histogram: cumulative `_bucket{le=...}`, `_sum`, `_count`). Counts are atomic, so
 * the reader needs no lock; a scrape may see a count one observation ahead of the sum. */
#ifndef FX_HISTOGRAM_H
#define FX_HISTOGRAM_H

#include <stdatomic.h>
#include <stdint.h>

#include "buf.h"

#define HIST_MAX_BUCKETS 14

struct histogram {
    const double *bounds; /* upper bounds in seconds, ascending; nb of them */
    int nb;
    atomic_uint_fast64_t counts[HIST_MAX_BUCKETS + 1]; /* per bucket (not cumulative); last: +Inf */
    atomic_uint_fast64_t sum_ns;
};

/* Bucket sets: step and encode times (0.5 ms to 1 s), frame ages at send (1 ms to 5 s). */
extern const double hist_step_bounds[], hist_age_bounds[];
extern const int hist_step_nb, hist_age_nb;

void hist_init(struct histogram *h, const double *bounds, int nb);
void hist_observe(struct histogram *h, double seconds);
/* Appends the histogram's lines for series `name` with `labels` (e.g. `stream="a",effect="b"`). */
void hist_render(struct fx_buf *out, const struct histogram *h, const char *name, const char *labels);

#endif
