/* main.c — fxstreamd: wires configuration, OpenCL, hub, engine and network together,
 * creates the start-up streams (in cluster mode: takes Redis's, seeding an empty database with
 * them), serves until SIGINT/SIGTERM, then shuts down in order (close WebSockets with 1001,
 * stop the engine, then the cluster's threads: the lease agent gives the leases up, free
 * everything) and exits 0. An edge (--role edge) opens no OpenCL device and starts no engine. */
#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "clock.h"
#include "config.h"
#include "effect.h"
#include "lease.h"
#include "log.h"
#include "net.h"
#include "ocl.h"
#include "relay.h"
#include "replica.h"
#include "store.h"

/* The embedded default: one stream per implemented effect, so `make run` shows something. */
static const char *const main_default_streams =
    "[{\"stream\":\"energy\",\"effect\":\"energy_wave\",\"params\":{}},"
    " {\"stream\":\"flame\",\"effect\":\"flame\",\"params\":{}},"
    " {\"stream\":\"eye\",\"effect\":\"compound_eye\",\"params\":{}}]";

static struct net *main_net;

static void main_on_signal(int sig)
{
    (void)sig;
    if (main_net) net_request_stop(main_net);
}

/* The cluster's stop callback (cluster_node_taken), from any thread. */
static void main_stop(void *net) { net_request_stop(net); }

/* Creates one stream from {stream, effect, params, rev?}; params are re-validated. */
static int main_create_stream(struct server *srv, const cJSON *def, struct fx_err *err)
{
    const cJSON *name = cJSON_GetObjectItemCaseSensitive(def, "stream");
    const cJSON *effect = cJSON_GetObjectItemCaseSensitive(def, "effect");
    const cJSON *params = cJSON_GetObjectItemCaseSensitive(def, "params");
    const cJSON *rev = cJSON_GetObjectItemCaseSensitive(def, "rev");
    if (!cJSON_IsString(name) || !cJSON_IsString(effect))
        return fx_fail(err, "bad_request", NULL, "each stream needs string fields \"stream\" and \"effect\"");
    const struct effect_ops *ops = effect_find(effect->valuestring);
    if (!ops) return fx_fail(err, "unknown_effect", "effect", "stream %s: no effect named \"%s\"", name->valuestring,
                            effect->valuestring);
    cJSON *doc = effect_params(ops, NULL, params, err);
    if (!doc) return -1;
    uint64_t r = rev ? hub_rev_from_json(rev) : 1;
    if (!r) {
        cJSON_Delete(doc);
        return fx_fail(err, "bad_request", "rev", "stream %s: rev must be an integer from 1 to 10^15 - 1",
                       name->valuestring);
    }
    if (hub_create(&srv->hub, ops, name->valuestring, doc, r, err)) {
        cJSON_Delete(doc);
        return -1;
    }
    return 0;
}

static int main_create_streams(struct server *srv, struct fx_err *err)
{
    cJSON *stored = NULL, *builtin = NULL;
    if (store_load(srv, &stored, err)) return -1;
    const cJSON *list = stored ? stored : srv->cfg.streams;
    if (!list) list = builtin = cJSON_Parse(main_default_streams);
    int rc = 0;
    cJSON *quarantine = cJSON_CreateArray();
    for (const cJSON *e = list->child; e && !rc; e = e->next) {
        rc = main_create_stream(srv, e, err);
        if (rc && stored) { /* a stored stream that no longer validates (an upgrade?) is kept aside */
            cJSON *q = cJSON_Duplicate(e, 1);
            if (cJSON_IsObject(q)) cJSON_AddStringToObject(q, "reason", err->message);
            cJSON_AddItemToArray(quarantine, q);
            rc = 0;
        }
    }
    srv->quarantined = cJSON_GetArraySize(quarantine);
    const cJSON *why = srv->quarantined ? cJSON_GetObjectItemCaseSensitive(quarantine->child, "reason") : NULL;
    if (srv->quarantined && store_quarantine(srv, quarantine))
        rc = fx_fail(err, "internal", NULL, "cannot write %s/streams.quarantine.json: %s", srv->cfg.state_dir,
                     strerror(errno));
    else if (srv->quarantined)
        log_warn("%d stored stream(s) no longer valid, moved to %s/streams.quarantine.json (first: %s)",
                 srv->quarantined, srv->cfg.state_dir, cJSON_IsString(why) ? why->valuestring : "?");
    cJSON_Delete(quarantine);
    cJSON_Delete(stored);
    cJSON_Delete(builtin);
    return rc;
}

static int main_prepare_state_dir(const char *dir, struct fx_err *err)
{
    if (!dir[0]) return 0;
    if (mkdir(dir, 0755) && errno != EEXIST)
        return fx_fail(err, "internal", NULL, "cannot create state directory %s: %s", dir, strerror(errno));
    if (access(dir, W_OK))
        return fx_fail(err, "internal", NULL, "state directory %s is not writable: %s", dir, strerror(errno));
    return 0;
}

/* Cluster mode: follows Redis, claims the node id (refused while another daemon runs with it),
 * seeds Redis with the streams just made if it was never seeded, and takes its state
 * (replica.h), before anything is served or computed. */
static int main_join_cluster(struct server *srv, struct fx_err *err)
{
    if (cluster_open(&srv->cluster, &srv->cfg.cluster, err) ||
        cluster_follow(srv->cluster, net_notify, main_stop, main_net, err) || cluster_claim(srv->cluster, err) ||
        replica_poll(srv, err) ||
        lease_start(&srv->lease, srv, err) || relay_start(&srv->relay, srv, err))
        return -1;
    if (srv->cfg.cluster.role != CLUSTER_ROLE_EDGE) {
        srv->engine.export_frame = lease_export;
        srv->engine.export_ctx = srv->lease;
    }
    log_info("cluster: node %s (%s) on %s", srv->cfg.cluster.node_id, cluster_role_name(srv->cfg.cluster.role),
             srv->cfg.cluster.url);
    return 0;
}

static void main_signals(void)
{
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = main_on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
}

static int main_serve(struct server *srv, struct fx_err *err)
{
    srv->start_time = clock_now();
    if (main_prepare_state_dir(srv->cfg.state_dir, err)) return -1;
    bool clustered = srv->cfg.cluster.url[0], edge = clustered && srv->cfg.cluster.role == CLUSTER_ROLE_EDGE;
    if (edge) {
        log_info("cluster edge: no OpenCL device, nothing computed here");
    } else {
        if (ocl_open(&srv->ocl, srv->cfg.device, err)) return -1;
        log_info("OpenCL device: %s (%s)", ocl_device_name(srv->ocl), ocl_platform_name(srv->ocl));
    }
    hub_init(&srv->hub, srv->cfg.limits.max_streams, clustered);
    int rc = presets_load(&srv->presets, srv->cfg.state_dir, err);
    if (!rc) rc = main_create_streams(srv, err);
    if (!rc) rc = net_open(&main_net, srv, err);
    if (!rc && clustered) rc = main_join_cluster(srv, err);
    if (!rc && !edge) rc = engine_start(&srv->engine, &srv->hub, srv->ocl, srv->cfg.pause_idle, err);
    if (!rc) {
        int port = net_port(main_net);
        bool tls = srv->cfg.tls_cert[0];
        printf("fxstreamd: listening on %s://%s:%d/ (WebSocket %s://%s:%d/v1/ws)\n", tls ? "https" : "http",
               srv->cfg.listen, port, tls ? "wss" : "ws", srv->cfg.listen, port);
        if (srv->cfg.access.ntokens) log_info("access: %d tokens; connections start without a role", srv->cfg.access.ntokens);
        else log_info("access: no tokens configured, so every client is admin; listening on loopback only");
        fflush(stdout);
        if (!srv->cfg.web_root[0]) log_warn("no web root: / serves nothing (use --web-root)");
        main_signals();
        net_run(main_net);
        log_info("stopped serving");
        if (srv->cluster && cluster_aborted(srv->cluster, err->message, sizeof err->message)) rc = -1;
    }
    engine_stop(&srv->engine);
    lease_stop(srv->lease); /* after the engine: it gives the leases up */
    relay_stop(srv->relay);
    srv->lease = NULL;
    srv->relay = NULL;
    cluster_close(srv->cluster); /* its follower wakes the network loop: stopped first */
    srv->cluster = NULL;
    net_close(main_net);
    main_net = NULL;
    hub_free(&srv->hub);
    presets_free(&srv->presets);
    ocl_close(srv->ocl);
    return rc;
}

int main(int argc, char **argv)
{
    static struct server srv;
    struct fx_err err = {0};
    switch (config_parse(argc, argv, &srv.cfg, &err)) {
    case CONFIG_HELP: config_usage(stdout); return 0;
    case CONFIG_ERROR: fprintf(stderr, "fxstreamd: %s\n", err.message); return 2;
    case CONFIG_OK: break;
    }
    log_set_level(srv.cfg.log_level);
    if (effects_init(&(struct effect_env){.assets_dir = srv.cfg.assets_dir}, &err)) {
        fprintf(stderr, "fxstreamd: %s\n", err.message);
        config_free(&srv.cfg);
        return 2;
    }
    int rc = main_serve(&srv, &err);
    if (rc) fprintf(stderr, "fxstreamd: %s\n", err.message);
    config_free(&srv.cfg);
    return rc ? 1 : 0;
}
