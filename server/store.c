/* store.c — see store.h. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cluster.h"
#include "jsonfile.h"
#include "log.h"
#include "store.h"

/* Cluster mode: a set re-made on a newer document this many times before giving up. */
#define STORE_REBASE_TRIES 8

static cJSON *store_entry(const char *stream, const char *effect, uint64_t rev, cJSON *params)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "stream", stream);
    cJSON_AddStringToObject(o, "effect", effect);
    cJSON_AddNumberToObject(o, "rev", (double)rev);
    cJSON_AddItemToObject(o, "params", params);
    return o;
}

/* Every stream in creation order, with `change` applied at revision new_rev (change may be NULL). */
static cJSON *store_snapshot(struct server *srv, const struct store_change *change, uint64_t new_rev)
{
    cJSON *arr = cJSON_CreateArray();
    bool seen = false;
    int n;
    struct stream **all = hub_snapshot(&srv->hub, &n);
    for (int i = 0; i < n; i++) {
        uint64_t rev;
        if (change && !strcmp(all[i]->name, change->stream)) {
            seen = true;
            if (change->op != STORE_DESTROY)
                cJSON_AddItemToArray(arr, store_entry(change->stream, change->effect, new_rev,
                                                      cJSON_Duplicate(change->params, 1)));
            continue;
        }
        cJSON *params = hub_get_params(&srv->hub, all[i], &rev);
        cJSON_AddItemToArray(arr, store_entry(all[i]->name, all[i]->effect->name, rev, params));
    }
    hub_release_all(all, n);
    if (change && !seen && change->op != STORE_DESTROY)
        cJSON_AddItemToArray(arr, store_entry(change->stream, change->effect, new_rev, cJSON_Duplicate(change->params, 1)));
    return arr;
}

cJSON *store_streams(struct server *srv) { return store_snapshot(srv, NULL, 0); }

void store_note(struct server *srv, const char *why)
{
    if (!why) {
        if (srv->state_error[0]) log_info("state directory writable again");
        srv->state_error[0] = 0;
        return;
    }
    atomic_fetch_add(&srv->counters.state_write_failures, 1);
    snprintf(srv->state_error, sizeof srv->state_error, "%s", why);
    log_error("%s", why);
}

/* A SET in Redis, re-made on the current document (change->rebase) while another daemon's
 * change got there first. */
static int store_cluster_set(struct server *srv, struct store_change *c, struct fx_err *err)
{
    uint64_t base = c->rev;
    int rc = 0;
    for (int i = 0; i < STORE_REBASE_TRIES && !rc; i++) {
        struct cluster_current cur = {0};
        rc = cluster_set(srv->cluster, c->stream, c->effect, base, c->rebased ? c->rebased : c->params, &cur, err);
        if (rc == 0) {
            c->rev = base + 1;
            return 0;
        }
        if (rc < 0) break;
        cJSON *next = NULL;
        if (strcmp(cur.effect, c->effect))
            rc = fx_fail(err, "unknown_stream", "stream", "stream %s was destroyed and made again (effect %s) on "
                         "another daemon; nothing changed", c->stream, cur.effect);
        else if (hub_rev_check(c->stream, cur.rev, err))
            rc = -1;
        else if (c->rebase && !(next = c->rebase(c->rebase_ctx, cur.params, err)))
            rc = -1;
        else
            rc = 0; /* try again on cur */
        cJSON_Delete(cur.params);
        if (next) {
            cJSON_Delete(c->rebased);
            c->rebased = next;
        }
        base = cur.rev;
        if (!rc) atomic_fetch_add(&srv->counters.cluster_rebases, 1);
    }
    cJSON_Delete(c->rebased);
    c->rebased = NULL;
    if (rc) return -1;
    return fx_fail(err, "unavailable", NULL, "stream %s kept changing on other daemons (%d tries); nothing changed",
                   c->stream, STORE_REBASE_TRIES);
}

static int store_cluster(struct server *srv, struct store_change *c, struct fx_err *err)
{
    int rc;
    switch (c->op) {
    case STORE_CREATE:
        rc = cluster_create(srv->cluster, c->stream, c->effect, c->params, srv->cfg.limits.max_streams, err);
        c->rev = 1;
        break;
    case STORE_SET: rc = store_cluster_set(srv, c, err); break;
    case STORE_DESTROY: rc = cluster_destroy(srv->cluster, c->stream, err); break;
    default: rc = cluster_reset(srv->cluster, c->stream, err); break;
    }
    atomic_fetch_add(rc ? &srv->counters.cluster_failures : &srv->counters.cluster_changes, 1);
    return rc;
}

int store_commit(struct server *srv, struct store_change *change, struct fx_err *err)
{
    change->rebased = NULL;
    if (srv->cluster) return store_cluster(srv, change, err);
    uint64_t rev = change->op == STORE_SET ? change->rev + 1 : 1;
    if (!srv->cfg.state_dir[0] || change->op == STORE_RESET) {
        change->rev = rev;
        return 0;
    }
    cJSON *doc = store_snapshot(srv, change, rev);
    char *text = cJSON_Print(doc);
    cJSON_Delete(doc);
    int rc = text ? jsonfile_write(srv->cfg.state_dir, "streams.json", text) : -1;
    int e = text ? errno : ENOMEM;
    cJSON_free(text);
    atomic_fetch_add(&srv->counters.state_writes, 1);
    if (!rc) {
        change->rev = rev;
        store_note(srv, NULL);
        return 0;
    }
    fx_fail(err, "unavailable", NULL, "cannot save %s/streams.json: %s (nothing changed)", srv->cfg.state_dir, strerror(e));
    store_note(srv, err->message);
    return -1;
}

/* Far above any real state (max_streams documents), small enough to refuse a runaway file. */
#define STORE_MAX_BYTES (256L << 20)

int store_load(const struct server *srv, cJSON **streams, struct fx_err *err)
{
    *streams = NULL;
    if (!srv->cfg.state_dir[0] || srv->cfg.cluster.url[0]) return 0;
    char path[PATH_MAX + 32];
    snprintf(path, sizeof path, "%s/streams.json", srv->cfg.state_dir);
    char why[128] = "";
    if (jsonfile_read(path, STORE_MAX_BYTES, streams, why, sizeof why)) {
        if (errno == ENOENT) return 0;
        return fx_fail(err, "internal", NULL, "cannot read %s: %s", path, strerror(errno));
    }
    if (!cJSON_IsArray(*streams)) {
        cJSON_Delete(*streams);
        *streams = NULL;
        return fx_fail(err, "internal", NULL, "%s: %s (left as it is)", path, why[0] ? why : "not a JSON array of streams");
    }
    return 0;
}

int store_quarantine(const struct server *srv, const cJSON *entries)
{
    char path[PATH_MAX + 64], why[128] = "";
    snprintf(path, sizeof path, "%s/streams.quarantine.json", srv->cfg.state_dir);
    cJSON *all = NULL;
    if (jsonfile_read(path, STORE_MAX_BYTES, &all, why, sizeof why) || !cJSON_IsArray(all)) {
        cJSON_Delete(all); /* none yet (or unreadable: a new file keeps at least these) */
        all = cJSON_CreateArray();
    }
    for (const cJSON *e = entries->child; e; e = e->next) cJSON_AddItemToArray(all, cJSON_Duplicate(e, 1));
    char *text = cJSON_Print(all);
    cJSON_Delete(all);
    int rc = text ? jsonfile_write(srv->cfg.state_dir, "streams.quarantine.json", text) : -1;
    free(text);
    return rc;
}
