/* fxload_conn.c — see fxload_conn.h. */
#include "fxload_conn.h"

#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "fxload_plan.h"
#include "fxload_state.h"
#include "fxws.h"

#define LD_CLOSE_WAIT_US 2000000

int ld_conns_create(struct ld *ld)
{
    long n = ld->o->connections;
    int maxg = 1;
    for (int g = 0; g < ld->ngroups; g++)
        if (ld->groups[g].n > maxg) maxg = ld->groups[g].n;
    ld->conns = calloc((size_t)n, sizeof *ld->conns);
    ld->subs = calloc((size_t)n * (size_t)maxg, sizeof *ld->subs);
    if (!ld->conns || !ld->subs) return -1;
    for (long i = 0; i < n; i++) {
        struct ld_conn *lc = &ld->conns[i];
        lc->ld = ld;
        lc->subs = ld->subs + i * maxg;
        lc->group = ld->o->mode == LD_SUBSCRIBE ? ld_plan_next_group(ld) : -1;
    }
    return 0;
}

struct ld_conn *ld_open_conn(struct ld *ld)
{
    for (long i = 0; i < ld->o->connections; i++)
        if (ld->conns[i].state == LDC_OPEN) return &ld->conns[i];
    return NULL;
}

int ld_send_control(struct ld_conn *lc, const char *op, const char *prefix, int index, const cJSON *params)
{
    struct ld *ld = lc->ld;
    char id[32];
    cJSON *req = cJSON_CreateObject();
    int r;
    snprintf(id, sizeof id, "%s%d", prefix, index);
    cJSON_AddStringToObject(req, "op", op);
    cJSON_AddStringToObject(req, "id", id);
    cJSON_AddStringToObject(req, "stream", ld->streams[index].name);
    if (params) cJSON_AddItemToObject(req, "params", cJSON_Duplicate(params, 1));
    r = fxp_send_json(lc->c, req);
    cJSON_Delete(req);
    return r;
}

void ld_service_until(struct ld *ld, int (*done)(const struct ld *ld), int64_t wait_us)
{
    int64_t deadline = fxws_now_us(CLOCK_MONOTONIC) + wait_us;
    while (!done(ld) && fxp_live(ld->pool) > 0 && fxws_now_us(CLOCK_MONOTONIC) < deadline)
        if (fxp_service(ld->pool, 10) < 0) break;
}

static int ld_all_closed(const struct ld *ld) { return fxp_live(ld->pool) == 0; }

void ld_close_all(struct ld *ld)
{
    for (long i = 0; i < ld->o->connections; i++)
        if (ld->conns[i].c) fxp_close(ld->conns[i].c);
    ld_service_until(ld, ld_all_closed, LD_CLOSE_WAIT_US);
}
