/* fxload_report.c — see fxload_report.h. */
#include "fxload_report.h"

#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "fxload_opts.h"
#include "fxload_state.h"
#include "fxload_stats.h"
#include "fxload_thresholds.h"

/* ---- the per-second table -------------------------------------------------------------- */

void ld_table_header(const struct ld *ld)
{
    if (ld->o->quiet) return;
    fprintf(ld->tout, "%6s %6s %9s %8s %7s %7s %8s %8s %8s %8s %5s %5s\n", "t", "conns", "frames/s", "MB/s", "skip/s",
            "sets/s", "p50_ms", "p95_ms", "p99_ms", "max_ms", "err", "disc");
    fflush(ld->tout);
}

void ld_table_line(const struct ld *ld, const struct ld_row *r)
{
    double dt = r->dt > 0 ? r->dt : 1;
    if (ld->o->quiet) return;
    fprintf(ld->tout, "%6.1f %6d %9.0f %8.2f %7.0f %7.0f %8.3f %8.3f %8.3f %8.3f %5" PRIu64 " %5" PRIu64 "\n", r->t,
            r->conns, (double)r->d.frames / dt, (double)r->d.bytes / dt / 1e6, (double)r->d.skipped / dt,
            (double)r->d.sets_ok / dt, r->p50, r->p95, r->p99, r->max, r->d.errors + r->d.failed, r->d.disconnects);
    fflush(ld->tout);
}

/* ---- the summary ------------------------------------------------------------------------ */

/* "15.0 of 30 fps (50%)": frames per subscriber per second against the target. */
static void ld_delivery_text(char *buf, size_t len, const struct ld_stream *st, uint64_t frames)
{
    struct ld_delivery d = ld_delivered(st, frames);
    if (d.known) snprintf(buf, len, "%.1f of %.4g fps (%.0f%%)", d.fps, d.target, d.pct);
    else snprintf(buf, len, "%s", st->sub_seconds > 0 ? "fps unknown" : "-");
}

static void ld_summary_line(FILE *f, const char *name, const char *subs, uint64_t frames, uint64_t bytes,
                            uint64_t skipped, const struct fxp_hist *h, const char *delivered)
{
    fprintf(f, "%-20s %6s %10" PRIu64 " %10.2f %8" PRIu64 " %8.3f %8.3f %8.3f %8.3f%s%s\n", name, subs, frames,
            (double)bytes / 1e6, skipped, fxp_hist_quantile(h, 0.5) / 1000, fxp_hist_quantile(h, 0.95) / 1000,
            fxp_hist_quantile(h, 0.99) / 1000, fxp_hist_quantile(h, 1.0) / 1000, *delivered ? "  " : "", delivered);
}

/* The stream's line, then one line per kind it sent. */
static void ld_summary_stream(FILE *f, const struct ld_stream *st)
{
    char subs[16], delivered[80], name[32];
    snprintf(subs, sizeof subs, "%d", st->subscribers);
    ld_delivery_text(delivered, sizeof delivered, st, ld_stream_steps(st));
    ld_summary_line(f, st->name, subs, st->frames, st->bytes, st->skipped, &st->lat, delivered);
    for (int k = 0; k <= FXS_KIND_MAX; k++) {
        const struct ld_kind *kd = &st->kind[k];
        if (!kd->frames) continue;
        snprintf(name, sizeof name, "  %d %s", k, ld_kind_name(k));
        ld_delivery_text(delivered, sizeof delivered, st, kd->frames);
        ld_summary_line(f, name, "", kd->frames, kd->bytes, kd->skipped, &kd->lat, delivered);
    }
}

static void ld_summary_subscribe(const struct ld *ld, FILE *f)
{
    int subs = 0;
    char total[16];
    fprintf(f, "%-20s %6s %10s %10s %8s %8s %8s %8s %8s  %s\n", "stream / kind", "subs", "frames", "MB", "skipped",
            "p50_ms", "p95_ms", "p99_ms", "max_ms", "delivered per subscriber");
    for (int i = 0; i < ld->nstreams; i++) {
        subs += ld->streams[i].subscribers;
        ld_summary_stream(f, &ld->streams[i]);
    }
    snprintf(total, sizeof total, "%d", subs);
    ld_summary_line(f, "total", total, ld->tot.frames, ld->tot.bytes, ld->tot.skipped, &ld->lat, "");
    fprintf(f, "throughput: %.0f frames/s, %.2f MB/s\n", ld->elapsed > 0 ? (double)ld->tot.frames / ld->elapsed : 0,
            ld->elapsed > 0 ? (double)ld->tot.bytes / ld->elapsed / 1e6 : 0);
}

/* "alpha=1, beta=[0,1,0]": the values of before the run. */
static void ld_before_text(const struct ld_stream *st, char *buf, size_t len)
{
    size_t n = 0;
    buf[0] = 0;
    for (const cJSON *v = st->before ? st->before->child : NULL; v && n < len; v = v->next) {
        char *text = cJSON_PrintUnformatted(v);
        int w = snprintf(buf + n, len - n, "%s%s=%s", n ? ", " : "", v->string, text ? text : "?");
        free(text);
        if (w < 0) break;
        n += (size_t)w;
    }
}

/* What became of the values of before the run: restored, kept (--keep), failed. */
static void ld_restore_text(const struct ld *ld, const struct ld_stream *st, char *buf, size_t len)
{
    char before[600];
    ld_before_text(st, before, sizeof before);
    if (st->restore == LDR_DONE)
        snprintf(buf, len, "restored %s (rev %" PRIu32 ")", before, st->restored_rev);
    else if (st->restore == LDR_FAILED)
        snprintf(buf, len, "NOT restored (%s): before the run %s", st->restore_err, before);
    else if (st->sets_sent && ld->o->keep)
        snprintf(buf, len, "kept (--keep): before the run %s", before);
    else
        snprintf(buf, len, "unchanged (no set sent)");
}

static void ld_summary_set_stream(const struct ld *ld, FILE *f, const struct ld_stream *st)
{
    char restore[800];
    ld_restore_text(ld, st, restore, sizeof restore);
    fprintf(f, "  %s: %" PRIu64 " ok, %" PRIu64 " failed, rev now %" PRIu32 "; %s\n", st->name, st->sets_ok,
            st->sets_err, st->max_rev, restore);
    if (st->restore == LDR_FAILED) fprintf(stderr, "fxload: cannot restore %s: %s\n", st->name, restore);
}

static void ld_summary_set(const struct ld *ld, FILE *f)
{
    const struct fxp_hist *h = &ld->set_lat;
    fprintf(f, "sets: %" PRIu64 " ok, %" PRIu64 " failed, %" PRIu64 " not sent (no idle connection); round trip ms "
               "p50 %.3f p95 %.3f p99 %.3f max %.3f\n",
            ld->tot.sets_ok, ld->tot.sets_err, ld->sets_skipped, fxp_hist_quantile(h, 0.5) / 1000,
            fxp_hist_quantile(h, 0.95) / 1000, fxp_hist_quantile(h, 0.99) / 1000, fxp_hist_quantile(h, 1.0) / 1000);
    for (int i = 0; i < ld->nstreams; i++) ld_summary_set_stream(ld, f, &ld->streams[i]);
}

void ld_summary(const struct ld *ld, const struct ld_thresholds *t)
{
    FILE *f = ld->tout;
    const struct ld_opts *o = ld->o;
    char urls[1024];
    ld_urls_text(o, urls, sizeof urls);
    fprintf(f, "fxload: %s, %d of %ld connections (peak %d, failed %" PRIu64 ", disconnects %" PRIu64
               ") to %s, %.2f s (%s)\n",
            o->mode == LD_SET ? "set" : "subscribe", ld->ever_open, o->connections, ld->peak, ld->tot.failed,
            ld->tot.disconnects, urls, ld->elapsed, ld->end_reason ? ld->end_reason : "");
    if (o->mode == LD_SUBSCRIBE) ld_summary_subscribe(ld, f);
    else ld_summary_set(ld, f);
    ld_thresholds_summary(t, f);
    fflush(f);
    for (int i = 0; i < ld->nerrs; i++) fprintf(stderr, "fxload: %" PRIu64 " x %s\n", ld->errs[i].count, ld->errs[i].msg);
    if (ld->other_errs) fprintf(stderr, "fxload: %" PRIu64 " x other errors\n", ld->other_errs);
}

/* ---- the JSON report ---------------------------------------------------------------------- */

/* Milliseconds from µs, rounded to the µs. */
static double ld_ms(double us) { return round(us) / 1000.0; }

static double ld_round3(double v) { return round(v * 1000) / 1000; }

static cJSON *ld_latency_json(const struct fxp_hist *h)
{
    cJSON *j = cJSON_CreateObject();
    cJSON_AddNumberToObject(j, "count", (double)h->count);
    cJSON_AddNumberToObject(j, "p50", ld_ms(fxp_hist_quantile(h, 0.50)));
    cJSON_AddNumberToObject(j, "p95", ld_ms(fxp_hist_quantile(h, 0.95)));
    cJSON_AddNumberToObject(j, "p99", ld_ms(fxp_hist_quantile(h, 0.99)));
    cJSON_AddNumberToObject(j, "max", ld_ms(fxp_hist_quantile(h, 1.0)));
    cJSON_AddNumberToObject(j, "mean", h->count ? ld_ms(h->sum_us / (double)h->count) : 0);
    return j;
}

static cJSON *ld_options_json(const struct ld_opts *o)
{
    cJSON *opt = cJSON_CreateObject();
    cJSON_AddStringToObject(opt, "url", o->url);
    cJSON *urls = cJSON_AddArrayToObject(opt, "urls");
    for (int i = 0; i < (o->nurls ? o->nurls : 1); i++) cJSON_AddItemToArray(urls, cJSON_CreateString(ld_url_for(o, i)));
    cJSON_AddStringToObject(opt, "mode", o->mode == LD_SET ? "set" : "subscribe");
    cJSON_AddNumberToObject(opt, "connections", (double)o->connections);
    cJSON_AddNumberToObject(opt, "duration_s", o->duration);
    cJSON_AddNumberToObject(opt, "ramp_s", o->ramp);
    if (o->mode == LD_SUBSCRIBE)
        cJSON_AddStringToObject(opt, "streams", o->streams_spec ? o->streams_spec : LD_DEFAULT_STREAMS);
    if (o->max_fps > 0) cJSON_AddNumberToObject(opt, "max_fps", o->max_fps);
    if (o->max_particles) cJSON_AddNumberToObject(opt, "max_particles", (double)o->max_particles);
    if (o->mode == LD_SET) cJSON_AddNumberToObject(opt, "rate", o->rate);
    if (o->mode == LD_SET) cJSON_AddBoolToObject(opt, "keep", o->keep);
    cJSON_AddBoolToObject(opt, "payloads", o->payloads);
    if (o->max_p99_ms >= 0) cJSON_AddNumberToObject(opt, "max_p99_ms", o->max_p99_ms);
    if (o->min_delivered >= 0) cJSON_AddNumberToObject(opt, "min_delivered_pct", o->min_delivered);
    if (o->max_skipped >= 0) cJSON_AddNumberToObject(opt, "max_skipped_pct", o->max_skipped);
    return opt;
}

static cJSON *ld_connections_json(const struct ld *ld)
{
    cJSON *con = cJSON_CreateObject();
    cJSON_AddNumberToObject(con, "requested", (double)ld->o->connections);
    cJSON_AddNumberToObject(con, "connected", ld->ever_open);
    cJSON_AddNumberToObject(con, "peak", ld->peak);
    cJSON_AddNumberToObject(con, "open_at_end", ld->open);
    cJSON_AddNumberToObject(con, "failed", (double)ld->tot.failed);
    cJSON_AddNumberToObject(con, "disconnects", (double)ld->tot.disconnects);
    return con;
}

static cJSON *ld_totals_json(const struct ld *ld)
{
    cJSON *tot = cJSON_CreateObject();
    double el = ld->elapsed;
    cJSON_AddNumberToObject(tot, "frames", (double)ld->tot.frames);
    cJSON_AddNumberToObject(tot, "bytes", (double)ld->tot.bytes);
    cJSON_AddNumberToObject(tot, "skipped", (double)ld->tot.skipped);
    cJSON_AddNumberToObject(tot, "skipped_pct", ld_round3(ld_skipped_pct(ld)));
    cJSON_AddNumberToObject(tot, "frames_per_s", el > 0 ? round((double)ld->tot.frames / el) : 0);
    cJSON_AddNumberToObject(tot, "mbytes_per_s", el > 0 ? round((double)ld->tot.bytes / el / 1e3) / 1e3 : 0);
    cJSON_AddNumberToObject(tot, "errors", (double)ld->tot.errors);
    cJSON_AddNumberToObject(tot, "unknown_channel", (double)ld->unknown_channel);
    cJSON_AddNumberToObject(tot, "seq_backwards", (double)ld->seq_backwards);
    cJSON_AddNumberToObject(tot, "events", (double)ld->events);
    cJSON_AddItemToObject(tot, "latency_ms", ld_latency_json(&ld->lat));
    return tot;
}

static double ld_round1(double v) { return round(v * 10) / 10; }

/* delivered_fps (per subscriber), target_fps and delivered_pct of `frames`; null when unknown. */
static void ld_add_delivery_json(cJSON *j, const struct ld_stream *st, uint64_t frames)
{
    struct ld_delivery d = ld_delivered(st, frames);
    if (!d.known) {
        cJSON_AddNullToObject(j, "delivered_fps");
        cJSON_AddNullToObject(j, "target_fps");
        cJSON_AddNullToObject(j, "delivered_pct");
        return;
    }
    cJSON_AddNumberToObject(j, "delivered_fps", ld_round3(d.fps));
    cJSON_AddNumberToObject(j, "target_fps", ld_round3(d.target));
    cJSON_AddNumberToObject(j, "delivered_pct", ld_round1(d.pct));
}

/* Per kind the stream sent, keyed by its number ("2"): name, counts, latency, delivery. */
static cJSON *ld_kinds_json(const struct ld_stream *st)
{
    cJSON *kinds = cJSON_CreateObject();
    for (int k = 0; k <= FXS_KIND_MAX; k++) {
        const struct ld_kind *kd = &st->kind[k];
        char key[8];
        cJSON *kj;
        if (!kd->frames) continue;
        snprintf(key, sizeof key, "%d", k);
        kj = cJSON_AddObjectToObject(kinds, key);
        cJSON_AddStringToObject(kj, "name", ld_kind_name(k));
        cJSON_AddNumberToObject(kj, "frames", (double)kd->frames);
        cJSON_AddNumberToObject(kj, "bytes", (double)kd->bytes);
        cJSON_AddNumberToObject(kj, "skipped", (double)kd->skipped);
        cJSON_AddItemToObject(kj, "latency_ms", ld_latency_json(&kd->lat));
        ld_add_delivery_json(kj, st, kd->frames);
    }
    return kinds;
}

static void ld_add_subscribe_json(cJSON *s, const struct ld_stream *st)
{
    cJSON_AddNumberToObject(s, "subscribers", st->subscribers);
    cJSON_AddNumberToObject(s, "subscribe_errors", st->sub_errors);
    if (st->fps > 0) cJSON_AddNumberToObject(s, "fps", st->fps);
    else cJSON_AddNullToObject(s, "fps");
    cJSON_AddNumberToObject(s, "subscriber_seconds", ld_round3(st->sub_seconds));
    cJSON_AddNumberToObject(s, "frames", (double)st->frames);
    cJSON_AddNumberToObject(s, "bytes", (double)st->bytes);
    cJSON_AddNumberToObject(s, "skipped", (double)st->skipped);
    cJSON_AddItemToObject(s, "latency_ms", ld_latency_json(&st->lat));
    ld_add_delivery_json(s, st, ld_stream_steps(st));
    cJSON_AddItemToObject(s, "kinds", ld_kinds_json(st));
}

/* Set mode: "before" (the values before the run), "restore" (done, failed, kept, unchanged),
 * "restored_rev" or "restore_error". */
static void ld_add_restore_json(const struct ld *ld, cJSON *s, const struct ld_stream *st)
{
    static const char *const states[] = { "unchanged", "sent", "done", "failed" };
    const char *state = st->restore == LDR_NONE && st->sets_sent && ld->o->keep ? "kept" : states[st->restore];
    if (st->before) cJSON_AddItemToObject(s, "before", cJSON_Duplicate(st->before, 1));
    else cJSON_AddNullToObject(s, "before");
    cJSON_AddStringToObject(s, "restore", state);
    if (st->restore == LDR_DONE) cJSON_AddNumberToObject(s, "restored_rev", st->restored_rev);
    if (st->restore == LDR_FAILED) cJSON_AddStringToObject(s, "restore_error", st->restore_err);
}

static cJSON *ld_stream_json(const struct ld *ld, const struct ld_stream *st)
{
    cJSON *s = cJSON_CreateObject();
    cJSON_AddStringToObject(s, "stream", st->name);
    if (ld->o->mode == LD_SUBSCRIBE) {
        ld_add_subscribe_json(s, st);
        return s;
    }
    cJSON_AddNumberToObject(s, "sets_ok", (double)st->sets_ok);
    cJSON_AddNumberToObject(s, "sets_failed", (double)st->sets_err);
    cJSON_AddNumberToObject(s, "max_rev", st->max_rev);
    ld_add_restore_json(ld, s, st);
    return s;
}

static cJSON *ld_sets_json(const struct ld *ld)
{
    cJSON *sj = cJSON_CreateObject();
    cJSON_AddNumberToObject(sj, "ok", (double)ld->tot.sets_ok);
    cJSON_AddNumberToObject(sj, "failed", (double)ld->tot.sets_err);
    cJSON_AddNumberToObject(sj, "not_sent", (double)ld->sets_skipped);
    cJSON_AddItemToObject(sj, "latency_ms", ld_latency_json(&ld->set_lat));
    return sj;
}

static void ld_add_error_json(cJSON *arr, const char *msg, uint64_t count)
{
    cJSON *e = cJSON_CreateObject();
    cJSON_AddStringToObject(e, "message", msg);
    cJSON_AddNumberToObject(e, "count", (double)count);
    cJSON_AddItemToArray(arr, e);
}

static cJSON *ld_errors_json(const struct ld *ld)
{
    cJSON *arr = cJSON_CreateArray();
    for (int i = 0; i < ld->nerrs; i++) ld_add_error_json(arr, ld->errs[i].msg, ld->errs[i].count);
    if (ld->other_errs) ld_add_error_json(arr, "(other messages)", ld->other_errs);
    return arr;
}

/* Row i's counts per stream: frames and skipped (subscribe mode) or sets (set mode). */
static cJSON *ld_row_streams_json(const struct ld *ld, int i)
{
    cJSON *j = cJSON_CreateObject();
    for (int k = 0; k < ld->nstreams; k++) {
        const struct ld_row_stream *rs = &ld->row_streams[i * ld->nstreams + k];
        cJSON *sj = cJSON_AddObjectToObject(j, ld->streams[k].name);
        if (ld->o->mode == LD_SET) {
            cJSON_AddNumberToObject(sj, "sets", (double)rs->sets);
            continue;
        }
        cJSON_AddNumberToObject(sj, "frames", (double)rs->frames);
        cJSON_AddNumberToObject(sj, "skipped", (double)rs->skipped);
    }
    return j;
}

static cJSON *ld_row_json(const struct ld *ld, int i)
{
    const struct ld_row *r = &ld->rows[i];
    cJSON *s = cJSON_CreateObject();
    cJSON_AddNumberToObject(s, "t", ld_round3(r->t));
    cJSON_AddNumberToObject(s, "dt", ld_round3(r->dt));
    cJSON_AddNumberToObject(s, "connections", r->conns);
    cJSON_AddNumberToObject(s, "frames", (double)r->d.frames);
    cJSON_AddNumberToObject(s, "bytes", (double)r->d.bytes);
    cJSON_AddNumberToObject(s, "skipped", (double)r->d.skipped);
    cJSON_AddNumberToObject(s, "sets", (double)r->d.sets_ok);
    cJSON_AddNumberToObject(s, "errors", (double)(r->d.errors + r->d.failed));
    cJSON_AddNumberToObject(s, "disconnects", (double)r->d.disconnects);
    cJSON_AddNumberToObject(s, "p50_ms", ld_round3(r->p50));
    cJSON_AddNumberToObject(s, "p95_ms", ld_round3(r->p95));
    cJSON_AddNumberToObject(s, "p99_ms", ld_round3(r->p99));
    cJSON_AddNumberToObject(s, "max_ms", ld_round3(r->max));
    cJSON_AddItemToObject(s, "streams", ld_row_streams_json(ld, i));
    return s;
}

static cJSON *ld_report_json(const struct ld *ld, const struct ld_thresholds *t)
{
    cJSON *j = cJSON_CreateObject(), *arr;
    cJSON_AddStringToObject(j, "tool", "fxload");
    cJSON_AddItemToObject(j, "options", ld_options_json(ld->o));
    cJSON_AddNumberToObject(j, "elapsed_s", ld_round3(ld->elapsed));
    cJSON_AddStringToObject(j, "end", ld->end_reason ? ld->end_reason : "");
    cJSON_AddItemToObject(j, "connections", ld_connections_json(ld));
    cJSON_AddItemToObject(j, "totals", ld_totals_json(ld));
    arr = cJSON_AddArrayToObject(j, "streams");
    for (int i = 0; i < ld->nstreams; i++) cJSON_AddItemToArray(arr, ld_stream_json(ld, &ld->streams[i]));
    if (ld->o->mode == LD_SET) cJSON_AddItemToObject(j, "sets", ld_sets_json(ld));
    cJSON_AddItemToObject(j, "thresholds", ld_thresholds_json(t));
    cJSON_AddItemToObject(j, "errors", ld_errors_json(ld));
    arr = cJSON_AddArrayToObject(j, "seconds");
    for (int i = 0; i < ld->nrows; i++) cJSON_AddItemToArray(arr, ld_row_json(ld, i));
    return j;
}

int ld_write_json(struct ld *ld, const struct ld_thresholds *t)
{
    cJSON *j = ld_report_json(ld, t);
    char *text = cJSON_Print(j);
    int ok = text && fprintf(ld->json, "%s\n", text) > 0;
    free(text);
    cJSON_Delete(j);
    if (ld->json == stdout) ok = fflush(stdout) == 0 && ok;
    else if (fclose(ld->json)) ok = 0;
    ld->json = NULL;
    if (!ok) fprintf(stderr, "fxload: cannot write %s: %s\n", ld->o->json_path, strerror(errno));
    return ok ? 0 : -1;
}
