/* fxload_set.c — fxload's set mode: the `set` messages at --rate (values drawn from each
 * --set spec in turn, one outstanding per connection), and leaving the streams as they were:
 * before the first set, the `get` of each stream (fxload_run.c) gives the values of the
 * parameters the run changes; after the run, once the sets in flight are answered, one `set`
 * per stream puts them back (unless --keep) and waits for its answer. A parameter --set
 * names that the stream does not have ends the run at once (exit 2). */
#include "fxload_set.h"

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "fxload_conn.h"
#include "fxload_errors.h"
#include "fxload_plan.h"
#include "fxload_state.h"
#include "fxws.h"

#define LD_SET_BURST_MAX 10000     /* set messages one loop turn may send to catch up */
#define LD_DRAIN_WAIT_US 2000000   /* for the answers of the sets in flight at the end */
#define LD_RESTORE_WAIT_US 5000000 /* for the answers of the restoring sets */

/* ---- the values before the run ------------------------------------------------------------ */

/* Keeps, from a `get` reply of st, the value of each parameter a --set changes on st. */
void ld_set_take_before(struct ld *ld, struct ld_stream *st, const cJSON *reply)
{
    const cJSON *params = cJSON_GetObjectItemCaseSensitive(reply, "params");
    cJSON *before = cJSON_CreateObject();
    for (int i = 0; i < ld->o->nsets; i++) {
        const struct ld_setspec *sp = &ld->o->sets[i];
        const cJSON *v = cJSON_GetObjectItemCaseSensitive(params, sp->param);
        if (strcmp(sp->stream, st->name) || cJSON_GetObjectItemCaseSensitive(before, sp->param)) continue;
        if (!v) {
            ld_fatal(ld, LD_USAGE, "--set %s.%s: stream %s has no parameter \"%s\"", sp->stream, sp->param, st->name,
                     sp->param);
            cJSON_Delete(before);
            return;
        }
        cJSON_AddItemToObject(before, sp->param, cJSON_Duplicate(v, 1));
    }
    cJSON_Delete(st->before);
    st->before = before;
}

/* Every stream's values are known: the sets may start. */
static int ld_sets_ready(struct ld *ld)
{
    for (int i = 0; !ld->sets_ready && i < ld->nstreams; i++)
        if (!ld->streams[i].before) return 0;
    ld->sets_ready = 1;
    return 1;
}

/* ---- the set messages ---------------------------------------------------------------------- */

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
        ld_stream_find(ld, sp->stream)->sets_sent++;
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
void ld_send_due_sets(struct ld *ld, double now)
{
    int burst = 0;
    if (!ld_sets_ready(ld)) {
        ld->next_set = now; /* the rate starts with the values known */
        return;
    }
    while (ld->next_set <= now && burst++ < LD_SET_BURST_MAX) {
        if (ld->open && ld_send_set(ld)) ld->sets_skipped++; /* none open yet: not due */
        ld->next_set += 1.0 / ld->o->rate;
    }
    if (ld->next_set < now) ld->next_set = now; /* fell behind: do not catch up later */
}


/* ---- after the run ------------------------------------------------------------------------ */

static int ld_sets_drained(const struct ld *ld)
{
    for (long i = 0; i < ld->o->connections; i++)
        if (ld->conns[i].state == LDC_OPEN && ld->conns[i].set_busy) return 0;
    return 1;
}

static int ld_restores_answered(const struct ld *ld)
{
    for (int i = 0; i < ld->nstreams; i++)
        if (ld->streams[i].restore == LDR_SENT) return 0;
    return 1;
}

static void ld_restore_failed(struct ld_stream *st, const char *why)
{
    st->restore = LDR_FAILED;
    snprintf(st->restore_err, sizeof st->restore_err, "%s", why);
}

/* Sends the restoring `set` of every stream with values from before the run. */
static void ld_send_restores(struct ld *ld)
{
    for (int i = 0; i < ld->nstreams; i++) {
        struct ld_stream *st = &ld->streams[i];
        struct ld_conn *lc = ld_open_conn(ld);
        if (!st->before || !st->sets_sent) continue;
        if (!lc) ld_restore_failed(st, "no connection open");
        else if (ld_send_control(lc, "set", LD_RESTORE_ID, i, st->before)) ld_restore_failed(st, "cannot queue the set");
        else st->restore = LDR_SENT;
    }
}

void ld_set_on_restore_reply(struct ld *ld, int index, const cJSON *m, const char *op)
{
    struct ld_stream *st;
    const cJSON *rev = cJSON_GetObjectItemCaseSensitive(m, "rev");
    char text[200];
    if (index < 0 || index >= ld->nstreams || ld->streams[index].restore != LDR_SENT) return;
    st = &ld->streams[index];
    if (!strcmp(op, "params")) {
        st->restore = LDR_DONE;
        st->restored_rev = cJSON_IsNumber(rev) ? (uint32_t)rev->valuedouble : 0;
        return;
    }
    ld_error_text(m, text, sizeof text);
    ld_restore_failed(st, text);
}

void ld_set_finish(struct ld *ld)
{
    ld_service_until(ld, ld_sets_drained, LD_DRAIN_WAIT_US);
    if (ld->o->keep) return;
    ld_send_restores(ld);
    ld_service_until(ld, ld_restores_answered, LD_RESTORE_WAIT_US);
    for (int i = 0; i < ld->nstreams; i++) {
        struct ld_stream *st = &ld->streams[i];
        if (st->restore == LDR_SENT) ld_restore_failed(st, fxp_live(ld->pool) ? "no answer within 5 s" : "connection lost");
        if (st->restore == LDR_FAILED) ld->restore_failed++;
    }
}
