/* store.c — see store.h. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "jsonfile.h"
#include "log.h"
#include "store.h"

static cJSON *store_snapshot(struct server *srv)
{
    cJSON *arr = cJSON_CreateArray();
    int n;
    struct stream **all = hub_snapshot(&srv->hub, &n);
    for (int i = 0; i < n; i++) {
        uint64_t rev;
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "stream", all[i]->name);
        cJSON_AddStringToObject(o, "effect", all[i]->effect->name);
        cJSON *params = hub_get_params(&srv->hub, all[i], &rev);
        cJSON_AddNumberToObject(o, "rev", rev);
        cJSON_AddItemToObject(o, "params", params);
        cJSON_AddItemToArray(arr, o);
    }
    hub_release_all(all, n);
    return arr;
}

bool store_mark(struct server *srv)
{
    if (srv->cfg.state_dir[0]) srv->store_dirty = true;
    return srv->store_dirty;
}

void store_flush(struct server *srv)
{
    if (!srv->store_dirty) return;
    srv->store_dirty = false;
    atomic_fetch_add(&srv->counters.state_writes, 1);
    cJSON *doc = store_snapshot(srv);
    char *text = cJSON_Print(doc);
    cJSON_Delete(doc);
    if (!text || jsonfile_write(srv->cfg.state_dir, "streams.json", text))
        log_error("cannot save state to %s/streams.json: %s", srv->cfg.state_dir, strerror(errno));
    free(text);
}

/* Far above any real state (max_streams documents), small enough to refuse a runaway file. */
#define STORE_MAX_BYTES (256L << 20)

int store_load(const struct server *srv, cJSON **streams, struct fx_err *err)
{
    *streams = NULL;
    if (!srv->cfg.state_dir[0]) return 0;
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
