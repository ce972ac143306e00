/* fxload_run.c — drives a run of fxload on libfxclient's pool (fxpool.h): opens the
 * connections along the ramp, sends the subscribe requests and the `get` of each stream's
 * parameters (its fps; in set mode the values to restore), lets fxload_set.c send the set
 * messages, routes what arrives through the pool's callbacks to the measurements
 * (fxload_stats.c), decides when the run ends (duration, every connection gone, SIGINT or
 * SIGTERM, or at once on a misspelled stream or parameter) and closes the connections
 * politely. One thread: everything happens inside fxp_service().
 *
 * Request ids: subscribe requests carry 1 + the stream's place in the connection's group,
 * set messages a number per connection, fxload's own requests a string ("get:3"). */
#include "fxload_run.h"

#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fxload_conn.h"
#include "fxload_errors.h"
#include "fxload_opts.h"
#include "fxload_plan.h"
#include "fxload_report.h"
#include "fxload_set.h"
#include "fxload_state.h"
#include "fxload_stats.h"
#include "fxws.h"

#define LD_SERVICE_MAX_MS 10

static volatile sig_atomic_t ld_signalled;

static void ld_on_signal(int sig) { ld_signalled = sig; }

static void ld_send_subscribes(struct ld *ld, struct fxp_conn *c, const struct ld_group *g)
{
    for (int k = 0; k < g->n; k++) {
        cJSON *req = cJSON_CreateObject();
        cJSON_AddStringToObject(req, "op", "subscribe");
        cJSON_AddNumberToObject(req, "id", k + 1);
        cJSON_AddStringToObject(req, "stream", ld->streams[g->stream[k]].name);
        if (ld->o->max_fps > 0) cJSON_AddNumberToObject(req, "max_fps", ld->o->max_fps);
        if (ld->o->max_particles) cJSON_AddNumberToObject(req, "max_particles", (double)ld->o->max_particles);
        if (fxp_send_json(c, req)) ld_error(ld, "cannot queue a subscribe request");
        cJSON_Delete(req);
    }
}

static void ld_on_open(struct fxp_conn *c, const cJSON *hello, void *user)
{
    struct ld_conn *lc = user;
    struct ld *ld = lc->ld;
    (void)hello;
    lc->state = LDC_OPEN;
    ld->ever_open++;
    if (++ld->open > ld->peak) ld->peak = ld->open;
    if (ld->o->mode == LD_SUBSCRIBE) ld_send_subscribes(ld, c, &ld->groups[lc->group]);
}

/* The reply to subscribe request id (1 + the stream's place in the connection's group). */
static void ld_on_subscribe_reply(struct ld *ld, struct ld_conn *lc, int id, const cJSON *m, const char *op)
{
    const struct ld_group *g = &ld->groups[lc->group];
    struct ld_stream *st;
    int k = id - 1;
    if (k < 0 || k >= g->n) return;
    st = &ld->streams[g->stream[k]];
    if (!strcmp(op, "subscribed")) {
        const cJSON *ch = cJSON_GetObjectItemCaseSensitive(m, "channel");
        if (!cJSON_IsNumber(ch) || ch->valuedouble < 1 || lc->subs[k].channel) return;
        st->subscribers++;
        lc->subs[k].channel = (uint32_t)ch->valuedouble;
        ld_stats_sub_start(ld, st);
    } else if (!strcmp(op, "error")) {
        char what[120];
        st->sub_errors++;
        snprintf(what, sizeof what, "subscribe %s", st->name);
        if (ld_is_error_code(m, "unknown_stream")) ld_fatal_reply(ld, LD_USAGE, what, m);
        else ld_server_error(ld, what, m);
    }
}

/* The fps in a `params` message (reply or broadcast) of stream st. */
static void ld_take_fps(struct ld *ld, struct ld_stream *st, const cJSON *m)
{
    const cJSON *fps = cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(m, "params"), "fps");
    if (cJSON_IsNumber(fps)) ld_stats_set_fps(ld, st, fps->valuedouble);
}

/* The server ended lc's subscription of the stream called name (it was destroyed). */
static void ld_sub_ended(struct ld *ld, struct ld_conn *lc, const char *name)
{
    const struct ld_group *g;
    if (lc->group < 0) return;
    g = &ld->groups[lc->group];
    for (int k = 0; k < g->n; k++)
        if (lc->subs[k].channel && !strcmp(ld->streams[g->stream[k]].name, name)) {
            lc->subs[k].channel = 0;
            ld_stats_sub_end(ld, &ld->streams[g->stream[k]]);
        }
}

/* A message without id: errors and unsubscriptions count, a `params` broadcast may change
 * the stream's fps, other events are only counted. */
static void ld_on_event(struct ld *ld, struct ld_conn *lc, const cJSON *m, const char *op)
{
    const cJSON *stream = cJSON_GetObjectItemCaseSensitive(m, "stream");
    const char *sname = cJSON_IsString(stream) ? stream->valuestring : NULL;
    struct ld_stream *st = sname ? ld_stream_find(ld, sname) : NULL;
    ld->events++;
    if (!strcmp(op, "error")) {
        char what[120];
        snprintf(what, sizeof what, "%s%s", sname ? "stream " : "server", sname ? sname : "");
        ld_server_error(ld, what, m);
    } else if (!strcmp(op, "unsubscribed")) {
        char line[160];
        const cJSON *why = cJSON_GetObjectItemCaseSensitive(m, "reason");
        snprintf(line, sizeof line, "unsubscribed from %s (%s)", sname ? sname : "?",
                 cJSON_IsString(why) ? why->valuestring : "no reason");
        ld_error(ld, line);
        if (sname) ld_sub_ended(ld, lc, sname);
    } else if (!strcmp(op, "params") && st) {
        ld_take_fps(ld, st, m);
    }
}

/* ---- the `get` of each stream's parameters ------------------------------------------------ */

/* Asks for the parameters of each stream that needs them and has not asked yet: in
 * subscribe mode once it has a subscriber (for its fps), in set mode at once (the values
 * to restore after the run). */
static void ld_send_gets(struct ld *ld)
{
    struct ld_conn *lc = NULL;
    for (int i = 0; i < ld->nstreams; i++) {
        struct ld_stream *st = &ld->streams[i];
        if (st->get != LDG_NONE || (ld->o->mode == LD_SUBSCRIBE && !st->active)) continue;
        if (!lc && !(lc = ld_open_conn(ld))) return;
        if (ld_send_control(lc, "get", LD_GET_ID, i, NULL) == 0) {
            st->get = LDG_ASKED;
            st->get_conn = lc;
        }
    }
}

/* A `get` failed. In set mode it is the first message about the stream (a misspelled --set
 * stream), and without the values the run could not restore them: the run ends. */
static void ld_on_get_error(struct ld *ld, struct ld_stream *st, const cJSON *m)
{
    char what[120];
    snprintf(what, sizeof what, "get %s", st->name);
    if (ld->o->mode == LD_SUBSCRIBE) ld_server_error(ld, what, m);
    else if (ld_is_error_code(m, "unknown_stream")) ld_fatal_reply(ld, LD_USAGE, what, m);
    else ld_fatal_reply(ld, LD_FAIL, what, m);
}

/* The reply to a `get` (id "get:INDEX"). */
static void ld_on_get_reply(struct ld *ld, int index, const cJSON *m, const char *op)
{
    struct ld_stream *st;
    if (index < 0 || index >= ld->nstreams || ld->streams[index].get != LDG_ASKED) return;
    st = &ld->streams[index];
    st->get = LDG_DONE;
    if (strcmp(op, "params")) ld_on_get_error(ld, st, m);
    else if (ld->o->mode == LD_SET) ld_set_take_before(ld, st, m);
    else ld_take_fps(ld, st, m);
}

/* A reply to one of fxload's own requests (a string id "PREFIX" "INDEX"). */
static void ld_on_control_reply(struct ld *ld, const char *id, const cJSON *m, const char *op)
{
    size_t get = strlen(LD_GET_ID), restore = strlen(LD_RESTORE_ID);
    if (!strncmp(id, LD_GET_ID, get)) ld_on_get_reply(ld, atoi(id + get), m, op);
    else if (!strncmp(id, LD_RESTORE_ID, restore)) ld_set_on_restore_reply(ld, atoi(id + restore), m, op);
}

static void ld_on_text(struct fxp_conn *c, const cJSON *m, uint64_t now, void *user)
{
    struct ld_conn *lc = user;
    struct ld *ld = lc->ld;
    const char *op = cJSON_GetObjectItemCaseSensitive(m, "op")->valuestring;
    const cJSON *id = cJSON_GetObjectItemCaseSensitive(m, "id");
    (void)c;
    if (cJSON_IsString(id)) ld_on_control_reply(ld, id->valuestring, m, op);
    else if (!cJSON_IsNumber(id)) ld_on_event(ld, lc, m, op);
    else if (ld->o->mode == LD_SUBSCRIBE) ld_on_subscribe_reply(ld, lc, (int)id->valuedouble, m, op);
    else if (lc->set_busy && id->valuedouble == lc->set_id) ld_count_set_reply(ld, lc, m, op, now);
}

static void ld_on_frame(struct fxp_conn *c, const struct fxs_header *h, const uint8_t *payload, size_t bytes,
                        uint64_t now, void *user)
{
    (void)c;
    (void)payload;
    ld_count_frame(((struct ld_conn *)user)->ld, user, h, bytes, now);
}

/* A closed connection's subscriptions end; a `get` it carried is asked again elsewhere. */
static void ld_conn_gone(struct ld *ld, struct ld_conn *lc)
{
    const struct ld_group *g = lc->group >= 0 ? &ld->groups[lc->group] : NULL;
    for (int k = 0; g && k < g->n; k++)
        if (lc->subs[k].channel) ld_stats_sub_end(ld, &ld->streams[g->stream[k]]);
    for (int i = 0; i < ld->nstreams; i++)
        if (ld->streams[i].get == LDG_ASKED && ld->streams[i].get_conn == lc) ld->streams[i].get = LDG_NONE;
}

static void ld_on_close(struct fxp_conn *c, const struct fxp_close_info *info, void *user)
{
    struct ld_conn *lc = user;
    struct ld *ld = lc->ld;
    int was_open = lc->state == LDC_OPEN;
    (void)c;
    if (was_open) ld->open--;
    lc->c = NULL;
    lc->state = LDC_DONE;
    ld_conn_gone(ld, lc);
    if (info->by_client) return;
    if (was_open) ld->tot.disconnects++;
    else ld->tot.failed++;
    ld_note(ld, info->reason);
}

/* ---- the loop -------------------------------------------------------------------------- */

/* Starts the connections due by `now` (ramp). Returns 0, or LD_USAGE for a bad URL. */
static int ld_start_due(struct ld *ld, double now)
{
    long n = ld->o->connections;
    while (ld->started < n) {
        double due = ld->o->ramp > 0 ? ld->o->ramp * (double)ld->started / (double)n : 0;
        struct ld_conn *lc = &ld->conns[ld->started];
        char err[300];
        int r;
        if (due > now) break;
        ld->started++;
        lc->state = LDC_CONNECTING;
        r = fxp_connect(ld->pool, ld_url_for(ld->o, ld->started - 1), lc, &lc->c, err, sizeof err);
        if (r == -2) {
            fprintf(stderr, "fxload: %s\n", err);
            return LD_USAGE;
        }
        if (r) {
            lc->state = LDC_DONE;
            ld->tot.failed++;
            ld_note(ld, err);
        }
    }
    return 0;
}

/* Why the run ends now, or NULL when it goes on. */
static const char *ld_end_reason(const struct ld *ld, double now)
{
    if (ld_signalled) return "interrupted";
    if (now >= ld->o->duration) return "duration reached";
    if (ld->started == ld->o->connections && fxp_live(ld->pool) == 0)
        return ld->ever_open ? "every connection closed" : "no connection could be established";
    return NULL;
}

/* How long fxp_service may wait: until the next row, connection or set is due. */
static int ld_wait_ms(const struct ld *ld, double now, double next_row)
{
    double wait = fmin(next_row, ld->o->duration) - now;
    if (ld->started < ld->o->connections)
        wait = fmin(wait, ld->o->ramp * (double)ld->started / (double)ld->o->connections - now);
    if (ld->o->mode == LD_SET && ld->sets_ready) wait = fmin(wait, ld->next_set - now);
    wait = fmin(fmax(wait, 0), LD_SERVICE_MAX_MS / 1000.0);
    return (int)ceil(wait * 1000);
}

/* Ends the per-second row at t (seconds since t0) and prints its line of the table. */
static void ld_row_cut(struct ld *ld, double t)
{
    const struct ld_row *r = ld_row_end(ld, t);
    if (r) ld_table_line(ld, r);
}

/* Ramp, measure, until the end. Returns 0, or an exit status on a fatal error. */
static int ld_loop(struct ld *ld)
{
    double next_row = 1, now;
    for (;;) {
        int r;
        now = ld_now(ld);
        if (ld->fatal) return ld->fatal;
        if ((r = ld_start_due(ld, now))) return r;
        ld_stats_advance(ld, now);
        ld_send_gets(ld);
        if (ld->o->mode == LD_SET) ld_send_due_sets(ld, now);
        for (; now >= next_row && next_row <= ld->o->duration; next_row += 1) ld_row_cut(ld, next_row);
        if ((ld->end_reason = ld_end_reason(ld, now))) break;
        if (fxp_service(ld->pool, ld_wait_ms(ld, now, next_row)) < 0) {
            fprintf(stderr, "fxload: libwebsockets service failed\n");
            return LD_FAIL;
        }
    }
    /* the last partial second */
    if (now - ld->row_start > 0.05 || ld->nrows == 0) ld_row_cut(ld, now);
    ld->elapsed = now;
    return 0;
}

static void ld_catch_signals(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = ld_on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
}

int ld_run(struct ld *ld)
{
    struct fxp_callbacks cb = { ld_on_open, ld_on_text, ld_on_frame, ld_on_close };
    struct fxp_options po = { .max_connections = (int)ld->o->connections, .payloads = ld->o->payloads,
                              .token = ld->o->token, .ca_file = ld->o->ca_file };
    char err[300];
    int r;
    if (fxp_pool_create(&ld->pool, &cb, &po, err, sizeof err)) {
        fprintf(stderr, "fxload: %s\n", err);
        return LD_FAIL;
    }
    ld_catch_signals();
    ld->rng = ld->o->seed * 2654435761UL + 1;
    ld->t0 = fxws_now_us(CLOCK_MONOTONIC);
    ld_table_header(ld);
    r = ld_loop(ld);
    ld->stopping = 1; /* nothing more is measured */
    if (!r && ld->o->mode == LD_SET) ld_set_finish(ld);
    ld_close_all(ld);
    fxp_pool_destroy(ld->pool);
    ld->pool = NULL;
    return r;
}
