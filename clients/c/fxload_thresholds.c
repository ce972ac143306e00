/* fxload_thresholds.c — fxload's thresholds, as k6 has them: --max-p99 MS (p99 latency of
 * frames, or of set round trips in set mode), --min-delivered PCT (each stream's delivered
 * percentage: frames per subscriber against its fps) and --max-skipped PCT (skipped frames
 * over the frames the subscriptions should have seen: received + skipped). Each given
 * threshold is judged once after the run, printed with its measured value and pass/FAIL in
 * the summary (a failure also on stderr) and listed in the JSON report; any failure makes
 * the exit status 4. A threshold without data (nothing timed, a stream's fps unknown, no
 * frames) fails: a run that measured nothing does not pass. */
#include "fxload_thresholds.h"

#include <math.h>
#include <string.h>

#include "fxload_state.h"
#include "fxload_stats.h"

static struct ld_check *ld_check_add(struct ld_thresholds *t, const char *option, const char *what, const char *stream,
                                     double limit, const char *unit)
{
    struct ld_check *c = &t->checks[t->n++];
    c->at_most = !strncmp(option, "--max-", 6);
    c->option = option;
    c->what = what;
    c->stream = stream;
    c->limit = limit;
    c->unit = unit;
    c->has_data = 0;
    c->passed = 0;
    return c;
}

static void ld_check_max_p99(struct ld_thresholds *t, const struct ld *ld)
{
    const struct fxp_hist *h = ld->o->mode == LD_SET ? &ld->set_lat : &ld->lat;
    struct ld_check *c = ld_check_add(t, "--max-p99", ld->o->mode == LD_SET ? "set round trip p99" : "frame latency p99",
                                      NULL, ld->o->max_p99_ms, "ms");
    c->has_data = h->count > 0;
    c->measured = fxp_hist_quantile(h, 0.99) / 1000;
    c->passed = c->has_data && c->measured <= c->limit;
}

static void ld_check_min_delivered(struct ld_thresholds *t, const struct ld *ld)
{
    for (int i = 0; i < ld->nstreams; i++) {
        const struct ld_stream *st = &ld->streams[i];
        struct ld_delivery d = ld_delivered(st, ld_stream_steps(st));
        struct ld_check *c = ld_check_add(t, "--min-delivered", "delivered", st->name, ld->o->min_delivered, "%");
        c->has_data = d.known;
        c->measured = d.pct;
        c->passed = d.known && d.pct >= c->limit;
    }
}

static void ld_check_max_skipped(struct ld_thresholds *t, const struct ld *ld)
{
    struct ld_check *c = ld_check_add(t, "--max-skipped", "skipped frames", NULL, ld->o->max_skipped, "%");
    c->has_data = ld->tot.frames + ld->tot.skipped > 0;
    c->measured = ld_skipped_pct(ld);
    c->passed = c->has_data && c->measured <= c->limit;
}

void ld_thresholds_judge(struct ld_thresholds *t, const struct ld *ld)
{
    t->n = 0;
    t->failed = 0;
    if (ld->o->max_p99_ms >= 0) ld_check_max_p99(t, ld);
    if (ld->o->min_delivered >= 0) ld_check_min_delivered(t, ld);
    if (ld->o->max_skipped >= 0) ld_check_max_skipped(t, ld);
    for (int i = 0; i < t->n; i++) t->failed += !t->checks[i].passed;
}

/* A measured value ("14.367 ms", "37.3%") or a limit as given ("0.001 ms", "90%"). */
static void ld_check_value(const struct ld_check *c, double v, int limit, char *buf, size_t len)
{
    int pct = c->unit[0] == '%';
    if (limit) snprintf(buf, len, "%g%s%s", v, pct ? "" : " ", c->unit);
    else snprintf(buf, len, pct ? "%.1f%s%s" : "%.3f%s%s", v, pct ? "" : " ", c->unit);
}

/* What a check measured against its limit, for people: "frame latency p99 14.367 ms >
 * 0.001 ms", "energy delivered 37.3% >= 1%". */
static void ld_check_text(const struct ld_check *c, char *buf, size_t len)
{
    char measured[48], limit[48];
    const char *cmp = c->at_most ? (c->passed ? "<=" : ">") : (c->passed ? ">=" : "<");
    ld_check_value(c, c->measured, 0, measured, sizeof measured);
    ld_check_value(c, c->limit, 1, limit, sizeof limit);
    if (!c->has_data) snprintf(buf, len, "%s%s%s: no data", c->stream ? c->stream : "", c->stream ? " " : "", c->what);
    else snprintf(buf, len, "%s%s%s %s %s %s", c->stream ? c->stream : "", c->stream ? " " : "", c->what, measured, cmp,
                  limit);
}

void ld_thresholds_summary(const struct ld_thresholds *t, FILE *f)
{
    char limit[48], text[160];
    if (!t->n) return;
    fprintf(f, "thresholds: %d of %d failed\n", t->failed, t->n);
    for (int i = 0; i < t->n; i++) {
        const struct ld_check *c = &t->checks[i];
        snprintf(limit, sizeof limit, "%s %g", c->option, c->limit);

        ld_check_text(c, text, sizeof text);
        fprintf(f, "  %-4s  %-22s %s\n", c->passed ? "pass" : "FAIL", limit, text);
        if (!c->passed) fprintf(stderr, "fxload: threshold failed: %s (%s)\n", limit, text);
    }
}

cJSON *ld_thresholds_json(const struct ld_thresholds *t)
{
    cJSON *j = cJSON_CreateObject(), *arr;
    cJSON_AddBoolToObject(j, "passed", t->failed == 0);
    arr = cJSON_AddArrayToObject(j, "checks");
    for (int i = 0; i < t->n; i++) {
        const struct ld_check *c = &t->checks[i];
        cJSON *cj = cJSON_CreateObject();
        cJSON_AddStringToObject(cj, "option", c->option);
        if (c->stream) cJSON_AddStringToObject(cj, "stream", c->stream);
        else cJSON_AddNullToObject(cj, "stream");
        cJSON_AddNumberToObject(cj, "limit", c->limit);
        if (c->has_data) cJSON_AddNumberToObject(cj, "measured", round(c->measured * 1000) / 1000);
        else cJSON_AddNullToObject(cj, "measured");
        cJSON_AddStringToObject(cj, "unit", c->unit);
        cJSON_AddBoolToObject(cj, "passed", c->passed);
        cJSON_AddItemToArray(arr, cj);
    }
    return j;
}
