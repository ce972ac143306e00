/* fxload_state.h — the record of one fxload run (struct ld) and the records it holds by
 * value: the streams the run uses (their measurements, the `get` of their parameters, set
 * mode's values to restore), the groups of streams connections subscribe to, the run's
 * counters, the per-second rows and the distinct error messages. Types only: the functions
 * that fill each part live with their noun (fxload.c lists the files) and take the whole
 * record, as everything runs in one thread around fxp_service(). The options
 * (fxload_opts.h) and the connections (fxload_conn.h) are reached through pointers, so this
 * header includes no other of fxload's but the options. */
#ifndef FXLOAD_STATE_H
#define FXLOAD_STATE_H

#include <stdint.h>
#include <stdio.h>

#include <cjson/cJSON.h>

#include "fxload_opts.h"
#include "fxpool.h"

#define LD_MAX_STREAMS 64 /* distinct stream names in --streams */
#define LD_MAX_GROUP 16   /* streams one connection subscribes to (server default limit) */
#define LD_MAX_GROUPS 64
#define LD_MAX_ERRS 32    /* distinct error messages kept */
#define LD_ERR_MSG_MAX 200 /* bytes of one, longer ones are cut */

struct ld_conn;
struct ld_sub;

struct ld_kind {
    uint64_t frames, bytes, skipped;
    struct fxp_hist lat;
};

/* Where the `get` of a stream's parameters stands (its fps, set mode's values to restore). */
enum ld_get_state { LDG_NONE, LDG_ASKED, LDG_DONE };
/* Set mode: where putting the values of before the run back stands. */
enum ld_restore_state { LDR_NONE, LDR_SENT, LDR_DONE, LDR_FAILED };

/* A stream's counts over one row of the per-second table (for the plot's line per stream). */
struct ld_row_stream {
    uint64_t frames, skipped, sets;
};

struct ld_stream {
    char name[LD_NAME_MAX];
    struct ld_kind kind[FXS_KIND_MAX + 1]; /* [0]: kinds this fxload does not know */
    uint64_t frames, bytes, skipped;
    struct fxp_hist lat;
    int subscribers;        /* `subscribed` replies */
    int sub_errors;
    int active;             /* subscriptions open now */
    enum ld_get_state get;
    const struct ld_conn *get_conn; /* where the `get` went (LDG_ASKED) */
    double fps;             /* the stream's fps parameter; 0 until known */
    /* delivered rate: subscriber-seconds, and frames of one kind a subscriber would have had
       at the target rate (fps, or --max-fps when lower) over them */
    double sub_seconds, unknown_seconds, expected;
    uint32_t max_rev;       /* set mode: highest rev in `params` replies */
    uint64_t sets_sent, sets_ok, sets_err;
    struct ld_row_stream row; /* counts of the row being measured */
    cJSON *before;          /* set mode: the values of the parameters --set changes, before the run */
    enum ld_restore_state restore;
    char restore_err[LD_ERR_MSG_MAX]; /* LDR_FAILED: why */
    uint32_t restored_rev;  /* LDR_DONE: the rev of the restoring set */
};

struct ld_group {
    int n;
    int stream[LD_MAX_GROUP]; /* indexes into ld.streams */
    double weight, current;   /* smooth weighted round-robin */
};

struct ld_counters {
    uint64_t frames, bytes, skipped, errors, disconnects, failed, sets_ok, sets_err;
};

/* One line of the per-second table. */
struct ld_row {
    double t, dt;
    int conns;
    struct ld_counters d;      /* deltas over the row */
    double p50, p95, p99, max; /* ms: frames (subscribe) or set round trips (set) */
};

struct ld_err {
    char msg[LD_ERR_MSG_MAX];
    uint64_t count;
};

struct ld {
    struct ld_opts *o;
    struct fxp_pool *pool;
    struct ld_stream streams[LD_MAX_STREAMS];
    int nstreams;
    struct ld_group groups[LD_MAX_GROUPS];
    int ngroups;
    struct ld_conn *conns;   /* o->connections of them (fxload_conn.h) */
    struct ld_sub *subs;     /* each connection's subscriptions, one block */
    int started;             /* connections started so far */
    int open, peak, ever_open;
    int stopping;            /* the run is over: nothing more is measured */
    int fatal;               /* an exit status that ends the run at once (a misspelled name) */
    int64_t t0;              /* CLOCK_MONOTONIC µs */
    double advanced;         /* seconds: delivered-rate counters accumulated up to here */
    struct ld_counters tot, row_base;
    struct fxp_hist lat, row_lat, set_lat;
    struct ld_row *rows;
    struct ld_row_stream *row_streams; /* nstreams per row: row r's at [r * nstreams] */
    int nrows, rows_cap;
    double row_start;
    struct ld_err errs[LD_MAX_ERRS];
    int nerrs;
    uint64_t other_errs;
    uint64_t unknown_channel, seq_backwards, sets_skipped, events;
    double next_set;         /* seconds since t0 */
    int sets_ready;          /* every stream's values before the run are known */
    int restore_failed;      /* streams whose values could not be put back */
    int set_rr;
    unsigned next_spec;
    unsigned long rng;
    double elapsed;
    const char *end_reason;
    FILE *tout;              /* table and summary */
    FILE *json;
    int json_created, plot_created; /* files this run created (removed when it fails) */
};

#endif
