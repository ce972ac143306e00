/* fxload_run.c — drives a run of fxload on libfxclient's pool (fxpool.h): opens the
 * connections along the ramp, sends the subscribe requests (subscribe mode) or the set
 * messages at --rate (set mode), routes what arrives through the pool's callbacks to the
 * measurements (fxload_stats.c), decides when the run ends (duration, every connection gone,
 * SIGINT/SIGTERM) and closes the connections politely. One thread: everything happens
 * inside fxp_service(). */
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "fxload.h"
#include "fxws.h"

#define LD_CLOSE_WAIT_US 2000000
#define LD_SERVICE_MAX_MS 10
#define LD_SET_BURST_MAX 10000 /* set messages one loop turn may send to catch up */

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

/* Ends the run at once with exit status `status`: "fxload: WHAT: code: message" on stderr. */
static void ld_fatal(struct ld *ld, int status, const char *what, const cJSON *m)
{
    const cJSON *code = cJSON_GetObjectItemCaseSensitive(m, "code");
    const cJSON *msg = cJSON_GetObjectItemCaseSensitive(m, "message");
    fprintf(stderr, "fxload: %s: %s: %s\n", what, cJSON_IsString(code) ? code->valuestring : "error",
            cJSON_IsString(msg) ? msg->valuestring : "(no message)");
    if (!ld->fatal) ld->fatal = status;
}

static int ld_is_error_code(const cJSON *m, const char *code)
{
    const cJSON *c = cJSON_GetObjectItemCaseSensitive(m, "code");
    return cJSON_IsString(c) && !strcmp(c->valuestring, code);
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
        if (!lc->subs[k].channel) st->subscribers++;
        lc->subs[k].channel = cJSON_IsNumber(ch) ? (uint32_t)ch->valuedouble : 0;
    } else if (!strcmp(op, "error")) {
        char what[120];
        st->sub_errors++;
        snprintf(what, sizeof what, "subscribe %s", st->name);
        if (ld_is_error_code(m, "unknown_stream")) ld_fatal(ld, LD_USAGE, what, m);
        else ld_server_error(ld, what, m);
    }
}

/* A message without id: errors and unsubscriptions count, other events are only counted. */
static void ld_on_event(struct ld *ld, const cJSON *m, const char *op)
{
    const cJSON *stream = cJSON_GetObjectItemCaseSensitive(m, "stream");
    const char *sname = cJSON_IsString(stream) ? stream->valuestring : NULL;
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
    }
}

static void ld_on_text(struct fxp_conn *c, const cJSON *m, uint64_t now, void *user)
{
    struct ld_conn *lc = user;
    struct ld *ld = lc->ld;
    const char *op = cJSON_GetObjectItemCaseSensitive(m, "op")->valuestring;
    const cJSON *id = cJSON_GetObjectItemCaseSensitive(m, "id");
    (void)c;
    if (!cJSON_IsNumber(id)) ld_on_event(ld, m, op);
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

static void ld_on_close(struct fxp_conn *c, const struct fxp_close_info *info, void *user)
{
    struct ld_conn *lc = user;
    struct ld *ld = lc->ld;
    int was_open = lc->state == LDC_OPEN;
    (void)c;
    if (was_open) ld->open--;
    lc->c = NULL;
    lc->state = LDC_DONE;
    if (info->by_client) return;
    if (was_open) ld->tot.disconnects++;
    else ld->tot.failed++;
    ld_note(ld, info->reason);
}

/* ---- set mode ------------------------------------------------------------------------ */

static double ld_rand(struct ld *ld)
{
    ld->rng = ld->rng * 6364136223846793005ULL + 1442695040888963407ULL;
    return (double)(ld->rng >> 11) / 9007199254740992.0;
}

/* The value of the next set message of sp: drawn from LO..HI, or the fixed JSON value. */
static cJSON *ld_set_value(struct ld *ld, const struct ld_setspec *sp)
{
    double v;
    if (!sp->range) return cJSON_Duplicate(sp->value, 1);
    v = sp->integer ? floor(sp->lo + (sp->hi - sp->lo + 1) * ld_rand(ld)) : sp->lo + (sp->hi - sp->lo) * ld_rand(ld);
    return cJSON_CreateNumber(v > sp->hi ? sp->hi : v);
}

static void ld_send_set_on(struct ld *ld, struct ld_conn *lc)
{
    int spec = (int)(ld->next_spec++ % (unsigned)ld->o->nsets);
    const struct ld_setspec *sp = &ld->o->sets[spec];
    cJSON *req = cJSON_CreateObject(), *params;
    cJSON_AddStringToObject(req, "op", "set");
    cJSON_AddNumberToObject(req, "id", ++lc->set_id);
    cJSON_AddStringToObject(req, "stream", sp->stream);
    params = cJSON_AddObjectToObject(req, "params");
    cJSON_AddItemToObject(params, sp->param, ld_set_value(ld, sp));
    if (fxp_send_json(lc->c, req) == 0) {
        lc->set_busy = 1;
        lc->set_spec = spec;
        lc->set_sent_us = fxws_now_us(CLOCK_REALTIME);
    }
    cJSON_Delete(req);
}

/* Sends one set from the next idle open connection. Returns 0, or -1 when none is idle. */
static int ld_send_set(struct ld *ld)
{
    long n = ld->o->connections;
    for (long tries = 0; tries < n; tries++) {
        struct ld_conn *lc = &ld->conns[ld->set_rr];
        ld->set_rr = (int)((ld->set_rr + 1) % n);
        if (lc->state != LDC_OPEN || lc->set_busy) continue;
        ld_send_set_on(ld, lc);
        return 0;
    }
    return -1;
}

/* Sends the sets due by now; a set no idle connection can take is counted, not queued. */
static void ld_send_due_sets(struct ld *ld, double now)
{
    int burst = 0;
    while (ld->next_set <= now && burst++ < LD_SET_BURST_MAX) {
        if (ld->open && ld_send_set(ld)) ld->sets_skipped++; /* none open yet: not due */
        ld->next_set += 1.0 / ld->o->rate;
    }
    if (ld->next_set < now) ld->next_set = now; /* fell behind: do not catch up later */
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
        r = fxp_connect(ld->pool, ld->o->url, lc, &lc->c, err, sizeof err);
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
    if (ld->o->mode == LD_SET) wait = fmin(wait, ld->next_set - now);
    wait = fmin(fmax(wait, 0), LD_SERVICE_MAX_MS / 1000.0);
    return (int)ceil(wait * 1000);
}

/* Ramp, measure, until the end. Returns 0, or an exit status on a fatal error. */
static int ld_loop(struct ld *ld)
{
    double next_row = 1, now;
    for (;;) {
        int r;
        now = ld_now(ld);
        if ((r = ld_start_due(ld, now))) return r;
        if (ld->o->mode == LD_SET) ld_send_due_sets(ld, now);
        for (; now >= next_row && next_row <= ld->o->duration; next_row += 1) ld_row_end(ld, next_row);
        if (ld->fatal) return ld->fatal;
        if ((ld->end_reason = ld_end_reason(ld, now))) break;
        if (fxp_service(ld->pool, ld_wait_ms(ld, now, next_row)) < 0) {
            fprintf(stderr, "fxload: libwebsockets service failed\n");
            return LD_FAIL;
        }
    }
    /* the last partial second */
    if (now - ld->row_start > 0.05 || ld->nrows == 0) ld_row_end(ld, now);
    ld->elapsed = now;
    return 0;
}

/* Stops measuring and closes every connection politely (bounded wait). */
static void ld_close_all(struct ld *ld)
{
    int64_t deadline = fxws_now_us(CLOCK_MONOTONIC) + LD_CLOSE_WAIT_US;
    ld->stopping = 1;
    for (long i = 0; i < ld->o->connections; i++)
        if (ld->conns[i].c) fxp_close(ld->conns[i].c);
    while (fxp_live(ld->pool) > 0 && fxws_now_us(CLOCK_MONOTONIC) < deadline)
        if (fxp_service(ld->pool, 10) < 0) break;
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
    ld_close_all(ld);
    fxp_pool_destroy(ld->pool);
    ld->pool = NULL;
    return r;
}
