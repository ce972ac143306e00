/* replica.c — see replica.h. */
#include <string.h>

#include "clock.h"
#include "cluster.h"
#include "effect.h"
#include "log.h"
#include "replica.h"
#include "session.h"
#include "store.h"

#define REPLICA_RETRY_S 1.0 /* after a failed reload, the next try waits this long */

/* Adds a stream from Redis, validated as a stored stream is at start: one this daemon cannot
 * serve (an effect or a value its version does not know) is left out, with a log line. */
static void replica_create(struct server *srv, const char *name, const char *effect, uint64_t rev, const cJSON *params)
{
    struct fx_err err = {0};
    const struct effect_ops *ops = effect_find(effect);
    cJSON *doc = ops ? effect_params(ops, NULL, params, &err) : NULL;
    if (!ops) fx_fail(&err, "unknown_effect", "effect", "no effect named \"%s\"", effect);
    if (!doc || hub_create(&srv->hub, ops, name, doc, rev, &err)) {
        cJSON_Delete(doc);
        log_error("cluster: cannot serve stream %s here: %s", name, err.message);
        return;
    }
    struct stream *s = hub_find(&srv->hub, name);
    session_event_created(srv, NULL, s, rev);
    stream_unref(s);
}

static void replica_update(struct server *srv, struct stream *s, uint64_t rev, const cJSON *params)
{
    struct fx_err err = {0};
    cJSON *doc = effect_params(s->effect, NULL, params, &err);
    if (!doc) {
        log_error("cluster: cannot take parameters rev %llu of stream %s here: %s", (unsigned long long)rev, s->name,
                  err.message);
        return;
    }
    hub_set_params(&srv->hub, s, cJSON_Duplicate(doc, 1), rev);
    session_event_params(srv, NULL, s, rev, doc);
    cJSON_Delete(doc);
}

static void replica_destroy(struct server *srv, const char *name)
{
    struct stream *s = hub_destroy(&srv->hub, name, &(struct fx_err){0});
    if (!s) return;
    session_event_destroyed(srv, NULL, s);
    stream_unref(s);
}

/* Makes the stream `name` what Redis holds: of `effect` at rev with params, or absent when
 * effect is NULL; each difference goes to the clients as its event. */
static void replica_put(struct server *srv, const char *name, const char *effect, uint64_t rev, const cJSON *params)
{
    struct stream *s = hub_find(&srv->hub, name);
    if (s && (!effect || strcmp(s->effect->name, effect))) {
        stream_unref(s);
        s = NULL;
        replica_destroy(srv, name);
    }
    if (!effect) return;
    if (!s) {
        replica_create(srv, name, effect, rev, params);
        return;
    }
    uint64_t have;
    cJSON *cur = hub_get_params(&srv->hub, s, &have);
    if (have != rev || !cJSON_Compare(cur, params, true)) replica_update(srv, s, rev, params);
    cJSON_Delete(cur);
    stream_unref(s);
}

static const char *replica_str(const cJSON *o, const char *name)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, name);
    return cJSON_IsString(v) ? v->valuestring : NULL;
}

/* A stream definition's revision, or 0 when it is not one. */
static uint64_t replica_rev(const cJSON *o) { return hub_rev_from_json(cJSON_GetObjectItemCaseSensitive(o, "rev")); }

/* Another daemon's change ({op, node, stream[, effect, rev, params]}, cluster.h). One that
 * does not read as a change leaves the copy stale, so the state is reloaded. */
static void replica_event(struct server *srv, const cJSON *ev)
{
    const char *op = replica_str(ev, "op"), *name = replica_str(ev, "stream"), *node = replica_str(ev, "node");
    const char *effect = replica_str(ev, "effect");
    const cJSON *params = cJSON_GetObjectItemCaseSensitive(ev, "params");
    uint64_t rev = replica_rev(ev);
    bool def = effect && rev && cJSON_IsObject(params);
    if (!op || !name || !node) op = "";
    if ((!strcmp(op, "created") || !strcmp(op, "params")) && def) {
        if (!strcmp(op, "created")) log_info("stream %s created (effect %s) on %s", name, effect, node);
        replica_put(srv, name, effect, rev, params);
    } else if (!strcmp(op, "destroyed")) {
        log_info("stream %s destroyed on %s", name, node);
        replica_put(srv, name, NULL, 0, NULL);
    } else if (!strcmp(op, "reset")) {
        struct stream *s = hub_find(&srv->hub, name);
        if (s) hub_request_reset(&srv->hub, s);
        stream_unref(s);
    } else { /* unreadable */
        cluster_stale(srv->cluster);
        return;
    }
    atomic_fetch_add(&srv->counters.cluster_applied, 1);
}

static bool replica_listed(const cJSON *all, const char *name)
{
    for (const cJSON *e = all->child; e; e = e->next)
        if (!strcmp(replica_str(e, "stream"), name)) return true;
    return false;
}

/* Sets each revision of `all` that did not read as one (bad_rev) to the one this daemon has
 * + 1 (1 for a stream it has not): the number of repairs sent, or -1 with err. */
static int replica_repair(struct server *srv, const cJSON *all, struct fx_err *err)
{
    int made = 0;
    for (const cJSON *e = all->child; e; e = e->next) {
        const char *bad = replica_str(e, "bad_rev"), *name = replica_str(e, "stream");
        if (!bad) continue;
        struct stream *s = hub_find(&srv->hub, name);
        struct stream_status st = {.rev = 0};
        if (s) hub_status(&srv->hub, s, &st);
        stream_unref(s);
        uint64_t rev = (double)st.rev + 1 < HUB_REV_MAX ? st.rev + 1 : 1;
        if (cluster_repair_rev(srv->cluster, name, replica_str(e, "effect"), bad, rev,
                               cJSON_GetObjectItemCaseSensitive(e, "params"), err))
            return -1;
        made++;
    }
    return made;
}

/* Redis's state and the number of its last change: a database never seeded (or that lost its
 * data) is seeded with this daemon's streams first, and revisions that do not read are
 * repaired, then the state is loaded again (a third load keeps what still does not read). */
static int replica_fetch(struct server *srv, cJSON **all, uint64_t *seq, struct fx_err *err)
{
    struct cluster *cl = srv->cluster;
    cJSON *mine = store_streams(srv);
    int rc = 1;
    for (int pass = 0; rc > 0 && pass < 3; pass++) {
        cJSON_Delete(*all);
        *all = NULL;
        rc = cluster_seed(cl, mine, err) ? -1 : cluster_load(cl, all, seq, err);
        if (!rc && pass < 2) rc = replica_repair(srv, *all, err);
    }
    cJSON_Delete(mine);
    if (rc > 0) rc = fx_fail(err, "unavailable", NULL, "cluster: %s lost its data again while being seeded",
                             srv->cfg.cluster.url);
    return rc;
}

/* Makes the copy Redis's state (replica_fetch). A stream whose revision still does not read is
 * left here as it is. */
static int replica_reload(struct server *srv, struct fx_err *err)
{
    cJSON *all = NULL;
    uint64_t seq;
    if (replica_fetch(srv, &all, &seq, err)) {
        cJSON_Delete(all);
        return -1;
    }
    int n;
    struct stream **local = hub_snapshot(&srv->hub, &n);
    for (int i = 0; i < n; i++)
        if (!replica_listed(all, local[i]->name)) replica_destroy(srv, local[i]->name);
    hub_release_all(local, n);
    for (const cJSON *e = all->child; e; e = e->next)
        if (replica_rev(e))
            replica_put(srv, replica_str(e, "stream"), replica_str(e, "effect"), replica_rev(e),
                        cJSON_GetObjectItemCaseSensitive(e, "params"));
        else
            log_warn("cluster: stream %s left as it is here: its revision in %s still does not read",
                     replica_str(e, "stream"), srv->cfg.cluster.url);
    log_info("cluster: %d streams loaded from %s (change %llu)", cJSON_GetArraySize(all), srv->cfg.cluster.url,
             (unsigned long long)seq);
    cJSON_Delete(all);
    cluster_loaded(srv->cluster, seq);
    atomic_fetch_add(&srv->counters.cluster_reloads, 1);
    return 0;
}

int replica_poll(struct server *srv, struct fx_err *err)
{
    struct cluster *cl = srv->cluster;
    if (!cl) return 0;
    struct cluster_item *it;
    while ((it = cluster_next(cl))) {
        const char *op = it->doc ? replica_str(it->doc, "op") : NULL;
        if (it->kind == CLUSTER_EVENT && (!op || !strcmp(op, "seeded"))) /* unreadable, or Redis was emptied: reload */
            cluster_stale(cl);
        else if (it->kind == CLUSTER_EVENT && cluster_fit(cl, it->seq) == CLUSTER_APPLY) replica_event(srv, it->doc);
        cluster_item_free(it);
    }
    double now = clock_now();
    if (cluster_in_sync(cl) || !cluster_link_up(cl) || now < srv->cluster_retry_at) return 0;
    if (!replica_reload(srv, err)) return 0;
    srv->cluster_retry_at = now + REPLICA_RETRY_S;
    log_warn("cluster: cannot load the state from %s: %s (retrying)", srv->cfg.cluster.url, err->message);
    return -1;
}
