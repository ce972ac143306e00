/* fxload_stats.c — see fxload_stats.h.
 *
 * Delivered rate: every subscription open for t seconds of a stream at F fps (or --max-fps
 * when lower) should see F * t frames of each kind the stream sends every step; what it saw
 * over that is the delivered percentage. fps may change during the run (a `params`
 * broadcast): the promise follows it. The subscriber-time before the first `get` reply is
 * kept apart and promised at the first fps known. */
#include "fxload_stats.h"

#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fxload_conn.h"
#include "fxload_errors.h"
#include "fxload_plan.h"
#include "fxload_state.h"
#include "fxws.h"

double ld_now(const struct ld *ld) { return (double)(fxws_now_us(CLOCK_MONOTONIC) - ld->t0) / 1e6; }

/* The subscription of lc that channel belongs to, and its stream; NULL when none. */
static struct ld_sub *ld_find_sub(struct ld *ld, struct ld_conn *lc, uint32_t channel, struct ld_stream **st)
{
    const struct ld_group *g;
    if (lc->group < 0) return NULL;
    g = &ld->groups[lc->group];
    for (int k = 0; k < g->n; k++)
        if (lc->subs[k].channel == channel) {
            *st = &ld->streams[g->stream[k]];
            return &lc->subs[k];
        }
    return NULL;
}

/* Seq gap and latency of a frame after the first of its subscription and kind. */
static void ld_count_gap_and_latency(struct ld *ld, struct ld_stream *st, unsigned kind, uint64_t last_seq,
                                     const struct fxs_header *h, uint64_t now)
{
    int64_t lat = (int64_t)now - (int64_t)h->server_time_us;
    if (h->seq > last_seq + 1) {
        uint64_t gap = h->seq - last_seq - 1;
        ld->tot.skipped += gap;
        st->skipped += gap;
        st->row.skipped += gap;
        st->kind[kind].skipped += gap;
    } else if (h->seq <= last_seq) {
        ld->seq_backwards++;
    }
    fxp_hist_add(&ld->lat, lat);
    fxp_hist_add(&ld->row_lat, lat);
    fxp_hist_add(&st->lat, lat);
    fxp_hist_add(&st->kind[kind].lat, lat);
}

void ld_count_frame(struct ld *ld, struct ld_conn *lc, const struct fxs_header *h, size_t bytes, uint64_t now)
{
    unsigned kind = h->kind <= FXS_KIND_MAX ? h->kind : 0;
    struct ld_stream *st = NULL;
    struct ld_sub *sub;
    if (ld->stopping) return;
    ld->tot.frames++;
    ld->tot.bytes += bytes;
    if (!(sub = ld_find_sub(ld, lc, h->channel, &st))) {
        ld->unknown_channel++;
        return;
    }
    st->frames++;
    st->row.frames++;
    st->bytes += bytes;
    st->kind[kind].frames++;
    st->kind[kind].bytes += bytes;
    /* the first frame of a subscription is the stream's newest, possibly older than it */
    if (sub->last_seq[kind]) ld_count_gap_and_latency(ld, st, kind, sub->last_seq[kind], h, now);
    sub->last_seq[kind] = h->seq;
}

void ld_count_set_reply(struct ld *ld, struct ld_conn *lc, const cJSON *m, const char *op, uint64_t now)
{
    const struct ld_setspec *sp = &ld->o->sets[lc->set_spec];
    struct ld_stream *st = ld_stream_find(ld, sp->stream);
    lc->set_busy = 0;
    if (!strcmp(op, "params")) {
        const cJSON *rev = cJSON_GetObjectItemCaseSensitive(m, "rev");
        int64_t rtt = (int64_t)now - lc->set_sent_us;
        ld->tot.sets_ok++;
        st->sets_ok++;
        st->row.sets++;
        if (cJSON_IsNumber(rev) && rev->valuedouble > st->max_rev) st->max_rev = (uint32_t)rev->valuedouble;
        if (!ld->stopping) {
            fxp_hist_add(&ld->set_lat, rtt);
            fxp_hist_add(&ld->row_lat, rtt);
        }
    } else {
        char what[160];
        ld->tot.sets_err++;
        st->sets_err++;
        snprintf(what, sizeof what, "set %s.%s", st->name, sp->param);
        ld_server_error(ld, what, m);
    }
}

/* Room for one more row; -1 out of memory. */
static int ld_rows_grow(struct ld *ld)
{
    int cap;
    struct ld_row *p;
    struct ld_row_stream *q;
    if (ld->nrows < ld->rows_cap) return 0;
    cap = ld->rows_cap ? 2 * ld->rows_cap : 64;
    if (!(p = realloc(ld->rows, (size_t)cap * sizeof *p))) return -1;
    ld->rows = p;
    if (!(q = realloc(ld->row_streams, (size_t)cap * (size_t)ld->nstreams * sizeof *q))) return -1;
    ld->row_streams = q;
    ld->rows_cap = cap;
    return 0;
}

/* Moves each stream's counts of the row being measured into row r. */
static void ld_row_streams_end(struct ld *ld, int r)
{
    for (int i = 0; i < ld->nstreams; i++) {
        ld->row_streams[r * ld->nstreams + i] = ld->streams[i].row;
        memset(&ld->streams[i].row, 0, sizeof ld->streams[i].row);
    }
}

static void ld_counters_sub(struct ld_counters *d, const struct ld_counters *a, const struct ld_counters *b)
{
    d->frames = a->frames - b->frames;
    d->bytes = a->bytes - b->bytes;
    d->skipped = a->skipped - b->skipped;
    d->errors = a->errors - b->errors;
    d->disconnects = a->disconnects - b->disconnects;
    d->failed = a->failed - b->failed;
    d->sets_ok = a->sets_ok - b->sets_ok;
    d->sets_err = a->sets_err - b->sets_err;
}

const struct ld_row *ld_row_end(struct ld *ld, double now)
{
    struct ld_row *r;
    if (ld_rows_grow(ld)) {
        ld_error(ld, "out of memory: a second of the per-second table is missing");
        return NULL;
    }
    ld_row_streams_end(ld, ld->nrows);
    r = &ld->rows[ld->nrows++];
    r->t = now;
    r->dt = now - ld->row_start;
    r->conns = ld->open;
    ld_counters_sub(&r->d, &ld->tot, &ld->row_base);
    r->p50 = fxp_hist_quantile(&ld->row_lat, 0.50) / 1000;
    r->p95 = fxp_hist_quantile(&ld->row_lat, 0.95) / 1000;
    r->p99 = fxp_hist_quantile(&ld->row_lat, 0.99) / 1000;
    r->max = fxp_hist_quantile(&ld->row_lat, 1.0) / 1000;
    ld->row_base = ld->tot;
    ld->row_start = now;
    fxp_hist_reset(&ld->row_lat);
    return r;
}

/* ---- delivered rate --------------------------------------------------------------------- */

static double ld_target_fps(const struct ld *ld, double fps)
{
    return ld->o->max_fps > 0 && ld->o->max_fps < fps ? ld->o->max_fps : fps;
}

void ld_stats_advance(struct ld *ld, double now)
{
    double dt = now - ld->advanced;
    if (ld->stopping || dt <= 0) return;
    ld->advanced = now;
    for (int i = 0; i < ld->nstreams; i++) {
        struct ld_stream *st = &ld->streams[i];
        double s = st->active * dt;
        st->sub_seconds += s;
        if (st->fps > 0) st->expected += ld_target_fps(ld, st->fps) * s;
        else st->unknown_seconds += s;
    }
}

void ld_stats_sub_start(struct ld *ld, struct ld_stream *st)
{
    ld_stats_advance(ld, ld_now(ld));
    st->active++;
}

void ld_stats_sub_end(struct ld *ld, struct ld_stream *st)
{
    ld_stats_advance(ld, ld_now(ld));
    st->active--;
}

void ld_stats_set_fps(struct ld *ld, struct ld_stream *st, double fps)
{
    if (!(fps > 0) || fps == st->fps) return;
    ld_stats_advance(ld, ld_now(ld));
    if (!(st->fps > 0)) {
        st->expected += ld_target_fps(ld, fps) * st->unknown_seconds;
        st->unknown_seconds = 0;
    }
    st->fps = fps;
}

double ld_skipped_pct(const struct ld *ld)
{
    uint64_t due = ld->tot.frames + ld->tot.skipped;
    return due ? 100.0 * (double)ld->tot.skipped / (double)due : 0;
}

uint64_t ld_stream_steps(const struct ld_stream *st)
{
    uint64_t best = 0;
    for (int k = 0; k <= FXS_KIND_MAX; k++)
        if (st->kind[k].frames > best) best = st->kind[k].frames;
    return best;
}

struct ld_delivery ld_delivered(const struct ld_stream *st, uint64_t frames)
{
    struct ld_delivery d = { 0, 0, 0, 0 };
    if (!(st->sub_seconds > 0) || !(st->expected > 0)) return d;
    d.known = 1;
    d.fps = (double)frames / st->sub_seconds;
    d.target = st->expected / st->sub_seconds;
    d.pct = 100.0 * (double)frames / st->expected;
    return d;
}

const char *ld_kind_name(int kind)
{
    static const char *const names[FXS_KIND_MAX + 1] = { "unknown", "particles", "texture", "light_rig", "lut" };
    return kind >= 0 && kind <= FXS_KIND_MAX ? names[kind] : names[0];
}
