/* histogram.c — see histogram.h. */
#include <stdio.h>
#include <string.h>

#include "histogram.h"

const double hist_step_bounds[] = {0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.033, 0.05, 0.1, 0.2, 0.5, 1};
const int hist_step_nb = sizeof hist_step_bounds / sizeof hist_step_bounds[0];
const double hist_age_bounds[] = {0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2, 5};
const int hist_age_nb = sizeof hist_age_bounds / sizeof hist_age_bounds[0];

void hist_init(struct histogram *h, const double *bounds, int nb)
{
    h->bounds = bounds;
    h->nb = nb < HIST_MAX_BUCKETS ? nb : HIST_MAX_BUCKETS;
    for (int i = 0; i <= HIST_MAX_BUCKETS; i++) atomic_init(&h->counts[i], 0);
    atomic_init(&h->sum_ns, 0);
}

void hist_observe(struct histogram *h, double seconds)
{
    if (!(seconds >= 0)) seconds = 0; /* NaN or a clock step back */
    int i = 0;
    while (i < h->nb && seconds > h->bounds[i]) i++;
    atomic_fetch_add(&h->counts[i], 1);
    atomic_fetch_add(&h->sum_ns, (uint64_t)(seconds * 1e9));
}

static void hist_line(struct fx_buf *out, const char *text)
{
    fx_buf_append(out, text, strlen(text));
}

void hist_render(struct fx_buf *out, const struct histogram *h, const char *name, const char *labels)
{
    char line[512];
    uint64_t cum = 0;
    for (int i = 0; i <= h->nb; i++) {
        cum += atomic_load(&h->counts[i]);
        if (i < h->nb) snprintf(line, sizeof line, "%s_bucket{%s,le=\"%g\"} %llu\n", name, labels, h->bounds[i],
                                (unsigned long long)cum);
        else snprintf(line, sizeof line, "%s_bucket{%s,le=\"+Inf\"} %llu\n", name, labels, (unsigned long long)cum);
        hist_line(out, line);
    }
    snprintf(line, sizeof line, "%s_sum{%s} %.9g\n%s_count{%s} %llu\n", name, labels,
             (double)atomic_load(&h->sum_ns) * 1e-9, name, labels, (unsigned long long)cum);
    hist_line(out, line);
}
