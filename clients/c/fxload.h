/* fxload.h — what the files of fxload, the load generator of fxstreamd, share: the options,
 * the state of one run (connections, streams, measurements, per-second rows) and the
 * functions each file offers the others. Not a library: the Makefile links these files into
 * build/fxload only, never into libfxclient.
 *
 *   fxload.c         help, main: output files, the order of the phases, the exit status
 *   fxload_opts.c    options, --streams groups, --set specs, validation, the plan of the run
 *   fxload_run.c     driving libfxclient's pool (fxpool.h): ramp, the callbacks that route
 *                    what arrives, subscribe and get requests, stopping and closing
 *   fxload_set.c     set mode: the set messages, the values before the run, restoring them
 *   fxload_stats.c   measurements: frames, bytes, seq gaps and latency per stream and kind,
 *                    the delivered rate against each stream's fps, per-second rows, error
 *                    messages
 *   fxload_report.c  the per-second table, the summary, the JSON report
 *   fxload_thresholds.c  --max-p99, --min-delivered, --max-skipped: pass or fail, and
 *                    their part of the summary and of the JSON report
 *   fxload_plot.c    the gnuplot plot
 *
 * Everything runs in one thread around fxp_service(); nothing here is shared with another. */
#ifndef FXLOAD_H
#define FXLOAD_H

#include <stdint.h>
#include <stdio.h>

#include <cjson/cJSON.h>

#include "fxpool.h"

#define LD_DEFAULT_URL "ws://127.0.0.1:7681/v1/ws"
#define LD_MAX_CONNECTIONS 10000
#define LD_MAX_URLS 16     /* --url repeated: daemons of a cluster */
#define LD_MAX_STREAMS 64 /* distinct stream names in --streams */
#define LD_MAX_GROUP 16   /* streams one connection subscribes to (server default limit) */
#define LD_MAX_GROUPS 64
#define LD_MAX_SETS 16
#define LD_MAX_ERRS 32    /* distinct error messages kept */
#define LD_ERR_MSG_MAX 200 /* bytes of one, longer ones are cut */
#define LD_NAME_MAX 64    /* stream and parameter names, with the terminating 0 */
#define LD_DEFAULT_STREAMS "energy,flame"
#define LD_DEFAULT_SET "energy.alpha=0.5..2"
#define LD_DEFAULT_RATE 10

/* Exit statuses (README "Load testing with fxload"). */
enum { LD_OK = 0, LD_FAIL = 1, LD_USAGE = 2, LD_DEGRADED = 3, LD_THRESHOLD = 4 };
enum ld_mode { LD_SUBSCRIBE = 0, LD_SET = 1 };

/* ---- options -------------------------------------------------------------------- */

struct ld_setspec {
    char stream[LD_NAME_MAX];
    char param[LD_NAME_MAX];
    int range, integer; /* LO..HI; integers when both are */
    double lo, hi;
    cJSON *value;       /* a fixed JSON value (range 0) */
};

struct ld_group {
    int n;
    int stream[LD_MAX_GROUP]; /* indexes into ld.streams */
    double weight, current;   /* smooth weighted round-robin */
};

struct ld_opts {
    const char *url;             /* the first --url (or the default): for messages */
    const char *urls[LD_MAX_URLS]; /* every --url; connection i goes to urls[i % nurls] */
    int nurls;
    const char *token, *ca_file; /* --token / $FXSTREAM_TOKEN, --ca-file / $FXSTREAM_CA_FILE */
    long connections;
    enum ld_mode mode;
    const char *streams_spec;
    double max_fps;              /* < 0: not given */
    struct ld_setspec sets[LD_MAX_SETS];
    int nsets;
    double rate;                 /* < 0: not given */
    double duration, ramp;
    int ramp_given;
    const char *json_path, *plot_path;
    int quiet, payloads;
    int keep;                    /* set mode: leave the values set at the end of the run */
    double max_p99_ms, min_delivered, max_skipped; /* thresholds; < 0: not given */
    unsigned long seed;
};

/* ---- state of a run ------------------------------------------------------------------ */

struct ld_kind {
    uint64_t frames, bytes, skipped;
    struct fxp_hist lat;
};

/* Where the `get` of a stream's parameters stands (its fps, set mode's values to restore). */
enum ld_get_state { LDG_NONE, LDG_ASKED, LDG_DONE };
/* Set mode: where putting the values of before the run back stands. */
enum ld_restore_state { LDR_NONE, LDR_SENT, LDR_DONE, LDR_FAILED };

/* Ids of fxload's own requests: the prefix, then the stream's index in ld.streams. */
#define LD_GET_ID "get:"
#define LD_RESTORE_ID "restore:"

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

/* Frames delivered per subscriber per second against the target rate. */
struct ld_delivery {
    int known;              /* 0: no subscriber-time or the stream's fps unknown */
    double fps, target, pct;
};

/* One subscription of a connection. */
struct ld_sub {
    uint32_t channel; /* 0 until `subscribed` */
    uint64_t last_seq[FXS_KIND_MAX + 1];
};

enum ld_conn_state { LDC_IDLE, LDC_CONNECTING, LDC_OPEN, LDC_DONE };

struct ld;

struct ld_conn {
    struct ld *ld;
    struct fxp_conn *c;      /* NULL once closed */
    enum ld_conn_state state;
    int group;               /* subscribe mode: index into ld.groups; set mode: -1 */
    struct ld_sub *subs;     /* the group's n subscriptions */
    int set_busy;            /* set mode: a set is outstanding */
    double set_id;
    int64_t set_sent_us;
    int set_spec;
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

/* One threshold judged: a limit against what the run measured. */
struct ld_check {
    const char *option;        /* "--max-p99", "--min-delivered", "--max-skipped" */
    const char *what;          /* what was measured, for people: "frame latency p99" */
    const char *stream;        /* --min-delivered: the stream judged; else NULL (the whole run) */
    double limit, measured;
    const char *unit;          /* "ms" or "%" */
    int at_most;               /* the measure must stay <= limit (--max-*), else >= limit */
    int has_data, passed;      /* without data (nothing timed, fps unknown) it fails */
};

#define LD_MAX_CHECKS (2 + LD_MAX_STREAMS)

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
    struct ld_conn *conns;
    struct ld_sub *subs;
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
    struct ld_check checks[LD_MAX_CHECKS];
    int nchecks, checks_failed;
    int json_created, plot_created; /* files this run created (removed when it fails) */
};

/* fxload_opts.c */
int ld_usage(const char *why, const char *arg);
/* The URL connection i goes to, and all of them as text for messages ("A" or "A, B (2 daemons)"). */
const char *ld_url_for(const struct ld_opts *o, long i);
void ld_urls_text(const struct ld_opts *o, char *out, size_t cap);
/* Fills o from argv. Returns 0, LD_USAGE, or -1 after printing help_text (--help). */
int ld_parse_args(struct ld_opts *o, int argc, char **argv, const char *help_text);
/* Checks combinations, fills defaults and the streams (--streams or --set). */
int ld_validate(struct ld *ld, struct ld_opts *o);
/* Allocates the connections and assigns each its group. Returns 0, or -1 out of memory. */
int ld_plan(struct ld *ld);
/* The stream called name, NULL when it is not one of the run's. */
struct ld_stream *ld_stream_find(struct ld *ld, const char *name);

/* fxload_run.c */
/* The run, from the first connection to the last close. Returns 0 (reports follow), or an
 * exit status when it ended without a report (a fatal error, already on stderr). */
int ld_run(struct ld *ld);
/* Ends the run at once with exit status `status` (the first one given wins), after
 * "fxload: MESSAGE" on stderr. */
void ld_fatal(struct ld *ld, int status, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
/* An open connection, NULL when none is. */
struct ld_conn *ld_open_conn(struct ld *ld);
/* Sends {"op":op,"id":"PREFIX INDEX","stream":...,"params":params} (params may be NULL)
 * about stream ld.streams[index] on lc. Returns 0, or -1 when it cannot be queued. */
int ld_send_control(struct ld_conn *lc, const char *op, const char *prefix, int index, const cJSON *params);
/* Services the pool until done(ld), wait_us passed, or no connection is left. */
void ld_service_until(struct ld *ld, int (*done)(const struct ld *ld), int64_t wait_us);

/* fxload_set.c */
/* Keeps, from a `get` reply of st, the values of the parameters --set changes on st. */
void ld_set_take_before(struct ld *ld, struct ld_stream *st, const cJSON *reply);
/* Sends the sets due by now (seconds since t0), at --rate over the idle connections. */
void ld_send_due_sets(struct ld *ld, double now);
/* The reply to the restoring set of ld.streams[index]. */
void ld_set_on_restore_reply(struct ld *ld, int index, const cJSON *m, const char *op);
/* After the run: waits for the sets in flight, then (unless --keep) restores the values. */
void ld_set_finish(struct ld *ld);

/* fxload_stats.c */
/* Seconds since the run started. */
double ld_now(const struct ld *ld);
/* Records msg among the distinct messages shown at the end (not counted as an error). */
void ld_note(struct ld *ld, const char *msg);
/* ld_note, counted as an error (exit status 3). */
void ld_error(struct ld *ld, const char *msg);
/* "code: message" of the server's error message m. */
void ld_error_text(const cJSON *m, char *buf, size_t len);
int ld_is_error_code(const cJSON *m, const char *code);
/* Counts the server's error message m: "WHAT: code: message" among the errors. */
void ld_server_error(struct ld *ld, const char *what, const cJSON *m);
void ld_count_frame(struct ld *ld, struct ld_conn *lc, const struct fxs_header *h, size_t bytes, uint64_t now);
void ld_count_set_reply(struct ld *ld, struct ld_conn *lc, const cJSON *m, const char *op, uint64_t now);
void ld_row_end(struct ld *ld, double now);
/* Subscriber-time up to now (seconds since t0); called before `active` changes. */
void ld_stats_advance(struct ld *ld, double now);
void ld_stats_sub_start(struct ld *ld, struct ld_stream *st);
void ld_stats_sub_end(struct ld *ld, struct ld_stream *st);
/* The stream's fps as the server reports it (`get` reply, `params` broadcast). */
void ld_stats_set_fps(struct ld *ld, struct ld_stream *st, double fps);
/* Skipped frames in % of the frames due (received + skipped) over the run; 0 when none. */
double ld_skipped_pct(const struct ld *ld);
/* Frames of the stream's most delivered kind: the stream steps a subscriber saw. */
uint64_t ld_stream_steps(const struct ld_stream *st);
struct ld_delivery ld_delivered(const struct ld_stream *st, uint64_t frames);
const char *ld_kind_name(int kind);

/* fxload_report.c */
void ld_table_header(const struct ld *ld);
void ld_table_line(const struct ld *ld, const struct ld_row *r);
void ld_summary(const struct ld *ld);
int ld_write_json(struct ld *ld);

/* fxload_thresholds.c */
/* Judges the thresholds given: fills ld.checks and ld.checks_failed. */
void ld_thresholds_judge(struct ld *ld);
void ld_thresholds_summary(const struct ld *ld, FILE *f);
cJSON *ld_thresholds_json(const struct ld *ld);

/* fxload_plot.c */
int ld_plot(const struct ld *ld);

#endif
