/* fxload_thresholds.h — fxload's thresholds (--max-p99, --min-delivered, --max-skipped;
 * fxload_thresholds.c says what each measures): the checks judged after a run, each a limit
 * against what the run measured, and their part of the summary and of the JSON report. */
#ifndef FXLOAD_THRESHOLDS_H
#define FXLOAD_THRESHOLDS_H

#include <stdio.h>

#include <cjson/cJSON.h>

#include "fxload_state.h"

/* One threshold judged: a limit against what the run measured. */
struct ld_check {
    const char *option;        /* "--max-p99", "--min-delivered", "--max-skipped" */
    const char *what;          /* what was measured, for people: "frame latency p99" */
    const char *stream;        /* --min-delivered: the stream judged; else NULL (the whole run) */
    double limit, measured;
    const char *unit;          /* "ms" or "%" */
    int at_most;               /* the measure must stay <= limit (--max-*), else >= limit */
    int has_data, passed;      /* without data (nothing timed, fps unknown) it fails */
};

#define LD_MAX_CHECKS (2 + LD_MAX_STREAMS)

/* The thresholds given, judged. */
struct ld_thresholds {
    struct ld_check checks[LD_MAX_CHECKS];
    int n, failed;
};

/* Judges the thresholds the options of the finished run ld give. */
void ld_thresholds_judge(struct ld_thresholds *t, const struct ld *ld);
/* "thresholds: F of N failed" and a line per check to f (nothing when none was given); each
 * failure also on stderr. */
void ld_thresholds_summary(const struct ld_thresholds *t, FILE *f);
/* {"passed":..., "checks":[...]} */
cJSON *ld_thresholds_json(const struct ld_thresholds *t);

#endif
