/* server.h — the daemon's shared context: configuration, limits and the parts that
 * every module reaches (hub, engine, sessions, counters). One instance, built by
 * main.c; modules take a pointer to it instead of using globals. */
#ifndef FX_SERVER_H
#define FX_SERVER_H

#include <limits.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

#include "access.h"
#include "cluster.h"
#include "engine.h"
#include "hub.h"
#include "presets.h"

#define FX_VERSION "0.1.0"

struct limits {
    int max_connections;
    int max_streams;
    int max_subscriptions;   /* per connection */
    int max_message_bytes;   /* control message size */
    int max_json_depth;
    int max_control_per_sec; /* per connection, token bucket with a burst of this size */
    int max_queued_messages; /* text replies/events queued per connection before it is closed */
    int max_queued_bytes;    /* ... and their bytes: a client that asks for large replies and does not read */
    int stall_timeout_s;     /* a connection whose socket stays full this long is closed */
    int max_buffered_bytes;  /* unread bytes per connection beyond which no new frame starts */
};

struct config {
    char listen[64];
    int port;
    char state_dir[PATH_MAX];
    char device[64];
    char web_root[PATH_MAX];
    char assets_dir[PATH_MAX]; /* handed to the effects at start (effect_env) */
    int log_level;
    bool pause_idle;
    struct limits limits;
    struct access access;  /* tokens and allowed origins (access.h) */
    char tls_cert[PATH_MAX]; /* PEM files; both set: the daemon speaks only TLS (https, wss) */
    char tls_key[PATH_MAX];
    struct cJSON *streams; /* streams to create at start ([{effect, stream, params}]), NULL = built-in */
    struct cluster_config cluster; /* --cluster, --node-id (cluster.h); url "" = single node */
};

struct counters {
    atomic_uint_fast64_t connections_total, messages_in, errors_out, frames_sent, frames_skipped, bytes_sent;
    atomic_uint_fast64_t stalled_closed; /* connections closed for not reading (stall_timeout_s) */
    atomic_uint_fast64_t state_writes;   /* streams.json writes tried (one per accepted change, store.h) */
    atomic_uint_fast64_t state_write_failures; /* state writes the disk refused (streams.json, presets.json) */
    atomic_uint_fast64_t handshakes_evicted; /* pending connections dropped for newer ones (net.c) */
    /* Cluster mode (store.c, replica.c): changes this daemon made in Redis, and those refused
     * there (unavailable, or Redis's state said no); sets re-made on a newer document; other
     * daemons' changes applied here; reloads of the whole state from Redis. */
    atomic_uint_fast64_t cluster_changes, cluster_failures, cluster_rebases, cluster_applied, cluster_reloads;
    /* Cluster mode (lease.c, relay.c): leases taken and lost; frames published through Redis,
     * refused there (fenced), and relayed from other daemons to subscribers here. */
    atomic_uint_fast64_t cluster_leases_taken, cluster_leases_lost;
    atomic_uint_fast64_t cluster_frames_published, cluster_frames_fenced, cluster_frames_relayed;
};

struct session;
struct ocl;

struct server {
    struct config cfg;
    struct hub hub;
    struct presets presets;   /* network thread only (presets.h) */
    struct engine engine;
    struct ocl *ocl;
    struct cluster *cluster;  /* cluster mode's Redis link (cluster.h), NULL on a single node */
    struct lease *lease;      /* cluster mode: leases and frame publishing (lease.h) */
    struct relay *relay;      /* cluster mode: frames computed elsewhere (relay.h) */
    struct counters counters;
    struct session *sessions; /* network thread only */
    int nsessions;
    int quarantined;          /* stored streams moved to streams.quarantine.json at start */
    char state_error[320];    /* network thread only: why the last state write failed, "" once one succeeds */
    double cluster_retry_at;  /* network thread only (replica.c): no reload from Redis before this */
    double start_time;        /* CLOCK_MONOTONIC seconds */
    /* Called by the session layer when a session has output queued (net.c asks the
     * socket for a writable callback). */
    void (*wake)(struct session *s);
};

#endif
