/* fxload.c — the load generator of fxstreamd, built on libfxclient's pool (fxpool.h).
 *
 * Owns option parsing (fxctl's conventions: one-line errors, exit 2 for usage), the
 * plan of a run (which connection subscribes to which streams, when each connection
 * opens during the ramp, when each `set` goes out), the measurements (frames, bytes,
 * latency histograms, seq gaps per connection, channel and kind, errors, disconnects)
 * and the three reports: a per-second table and a summary on the terminal, a JSON
 * document, and a gnuplot plot (SVG or PNG) of latency and throughput over time.
 *
 * Everything runs in one thread around fxp_service(); the run ends by itself after
 * --duration seconds (or earlier when every connection is gone or on SIGINT/SIGTERM).
 * It never targets anything but the default loopback URL or the one given with --url. */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>
#include <sys/wait.h>

#include <libwebsockets.h>

#include "fxpool.h"
#include "fxws.h"

#define LD_DEFAULT_URL "ws://127.0.0.1:7681/v1/ws"
#define LD_MAX_CONNECTIONS 10000
#define LD_MAX_STREAMS 64     /* distinct stream names in --streams */
#define LD_MAX_GROUP 16       /* streams one connection subscribes to (server default limit) */
#define LD_MAX_GROUPS 64
#define LD_MAX_SETS 16
#define LD_MAX_ERRS 32        /* distinct error messages kept */
#define LD_CLOSE_WAIT_US 2000000
#define LD_SERVICE_MAX_MS 10

enum { LD_OK = 0, LD_FAIL = 1, LD_USAGE = 2, LD_DEGRADED = 3 };
enum { LD_SUBSCRIBE = 0, LD_SET = 1 };

static const char ld_help[] =
    "usage: fxload [options]\n"
    "\n"
    "Load generator for fxstreamd: opens N WebSocket connections (one thread, one\n"
    "event loop), ramping up at a steady rate, and for a fixed time either subscribes\n"
    "each to streams or sends parameter changes; then closes them and reports.\n"
    "\n"
    "options (also as --opt=VALUE):\n"
    "  --url URL          server (default " LD_DEFAULT_URL "); fxload targets\n"
    "                     only this loopback default or the URL given here (ws://, wss://)\n"
    "  --token T          access token for every connection (default $FXSTREAM_TOKEN)\n"
    "  --ca-file F        PEM bundle for a wss:// server (default $FXSTREAM_CA_FILE)\n"
    "  --connections N    connections, 1..10000 (default 10)\n"
    "  --mode M           subscribe (default) or set\n"
    "  --streams LIST     subscribe mode: comma-separated groups GROUP[:WEIGHT]; a group\n"
    "                     is STREAM or STREAM+STREAM+... (a connection subscribes to\n"
    "                     every stream of its group); connections are shared among the\n"
    "                     groups in proportion to WEIGHT (default 1).\n"
    "                     Default energy,flame (half each). E.g. flame:3,energy:1\n"
    "  --max-fps F        subscribe mode: max_fps of each subscription, (0, 1000]\n"
    "  --set SPEC         set mode: STREAM.PARAM=LO..HI (uniform random number; integers\n"
    "                     when LO and HI are) or STREAM.PARAM=JSON (fixed value); may be\n"
    "                     repeated, each set message uses the next SPEC in turn.\n"
    "                     Default energy.alpha=0.5..2\n"
    "  --rate R           set mode: set messages per second over all connections, each\n"
    "                     from the next connection without one outstanding (default 10)\n"
    "  --duration S       length of the run in seconds, ramp included (default 10)\n"
    "  --ramp S           open the connections evenly over the first S seconds\n"
    "                     (default 1; 0 opens them all at once; must be < duration)\n"
    "  --json FILE        write the report as JSON to FILE ('-': stdout; the table and\n"
    "                     summary then go to stderr)\n"
    "  --plot FILE        plot latency and throughput over time with gnuplot into\n"
    "                     FILE.svg or FILE.png (needs gnuplot: Debian gnuplot-nox)\n"
    "  --payloads         reassemble whole frames (default: keep only headers, count\n"
    "                     bytes; cheaper, so the load generator disturbs less)\n"
    "  --seed N           random seed for --set values (default 1)\n"
    "  --quiet            no per-second table (the summary is still printed)\n"
    "  --help, -h         this text\n"
    "\n"
    "measures: frames and bytes received per stream and kind; latency = arrival time -\n"
    "server_time_us of the frame header (same host or synchronised clocks; the first\n"
    "frame of each subscription is counted but not timed: it is the stream's newest\n"
    "frame, possibly older than the subscription); skipped frames = gaps in seq per\n"
    "connection, channel and kind; in set mode the set -> params round trip; errors\n"
    "(server error messages, failed connections) and disconnects (connections the\n"
    "server or network closed during the run).\n"
    "\n"
    "output: one table line per second (t, connections, frames/s, MB/s, skipped/s,\n"
    "sets/s, latency p50 p95 p99 max in ms, errors, disconnects), then a summary per\n"
    "stream. Errors go to stderr as \"fxload: WHAT\".\n"
    "exit status: 0 run completed cleanly; 1 nothing could connect, or a failure\n"
    "(libwebsockets, writing the report, gnuplot); 2 usage error; 3 run completed with\n"
    "failed connections, disconnects or errors (the report says which).\n";

/* ---- options ------------------------------------------------------------------ */

struct ld_setspec {
    char stream[64];
    char param[64];
    int range, integer; /* LO..HI */
    double lo, hi;
    cJSON *value;       /* fixed JSON value */
};

struct ld_group {
    int n;
    int stream[LD_MAX_GROUP];
    double weight, current; /* smooth weighted round-robin */
};

struct ld_opts {
    const char *url;
    const char *token, *ca_file; /* --token / $FXSTREAM_TOKEN, --ca-file / $FXSTREAM_CA_FILE */
    long connections;
    int mode;
    const char *streams_spec;
    double max_fps;      /* < 0: not given */
    struct ld_setspec sets[LD_MAX_SETS];
    int nsets;
    double rate;         /* < 0: not given */
    double duration, ramp;
    int ramp_given;
    const char *json_path, *plot_path;
    int quiet, payloads;
    unsigned long seed;
    const char *mode_name;
};

/* ---- state -------------------------------------------------------------------- */

struct ld_kind {
    uint64_t frames, bytes, skipped;
};

struct ld_stream {
    char name[64];
    struct ld_kind kind[FXS_KIND_MAX + 1]; /* [0]: unknown kinds */
    uint64_t frames, bytes, skipped;
    struct fxp_hist lat;
    int subscribers;     /* `subscribed` replies */
    int sub_errors;
    uint32_t max_rev;    /* set mode: highest rev in `params` replies */
    uint64_t sets_ok, sets_err;
};

struct ld_sub {
    uint32_t channel;    /* 0 until `subscribed` */
    uint64_t last_seq[FXS_KIND_MAX + 1];
};

enum { LDC_IDLE, LDC_CONNECTING, LDC_OPEN, LDC_DONE };

struct ld;

struct ld_conn {
    struct ld *ld;
    struct fxp_conn *c;
    int state;
    int group;
    struct ld_sub *subs;     /* group's n entries */
    /* set mode */
    int set_busy;
    double set_id;
    int64_t set_sent_us;
    int set_spec;
};

struct ld_counters {
    uint64_t frames, bytes, skipped, errors, disconnects, failed, sets_ok, sets_err;
};

struct ld_row {
    double t, dt;
    int conns;
    struct ld_counters d; /* deltas over the row */
    double p50, p95, p99, max; /* ms, frames (subscribe) or set round trips (set) */
    uint64_t timed;
};

struct ld_err {
    char msg[200];
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
    int stopping;
    int64_t t0;              /* CLOCK_MONOTONIC µs */
    struct ld_counters tot, row_base;
    struct fxp_hist lat, row_lat, set_lat;
    struct ld_row *rows;
    int nrows, rows_cap;
    double row_start;
    struct ld_err errs[LD_MAX_ERRS];
    int nerrs;
    uint64_t other_errs;
    uint64_t unknown_channel, seq_backwards, sets_skipped, events;
    double next_set;         /* seconds since t0 */
    int set_rr;
    unsigned next_spec;
    unsigned long rng;
    double elapsed;
    const char *end_reason;
    FILE *tout;              /* table and summary */
    FILE *json;
};

static volatile sig_atomic_t ld_signalled;

static void ld_on_signal(int sig) { ld_signalled = sig; }

static int ld_usage(const char *why, const char *arg)
{
    fprintf(stderr, "fxload: %s%s%s\nTry 'fxload --help'.\n", why, arg ? ": " : "", arg ? arg : "");
    return LD_USAGE;
}

static int ld_parse_double(const char *s, double *out)
{
    char *end;
    double v;
    errno = 0;
    v = strtod(s, &end);
    if (errno || end == s || *end || !isfinite(v)) return -1;
    *out = v;
    return 0;
}

static int ld_parse_long(const char *s, long *out)
{
    char *end;
    long v;
    errno = 0;
    v = strtol(s, &end, 10);
    if (errno || end == s || *end) return -1;
    *out = v;
    return 0;
}

static int ld_valid_stream_name(const char *s, size_t n)
{
    if (n < 1 || n > 63) return 0;
    for (size_t i = 0; i < n; i++) {
        char c = s[i];
        if (!((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '.' ||
              c == '-'))
            return 0;
    }
    return 1;
}

static int ld_valid_param_name(const char *s)
{
    if (!*s || strlen(s) > 63) return 0;
    for (; *s; s++)
        if (!((*s >= 'A' && *s <= 'Z') || (*s >= 'a' && *s <= 'z') || (*s >= '0' && *s <= '9') || *s == '_'))
            return 0;
    return 1;
}

static int ld_is_integer_text(const char *s, size_t n)
{
    size_t i = (n && (s[0] == '-' || s[0] == '+')) ? 1 : 0;
    if (i == n) return 0;
    for (; i < n; i++)
        if (s[i] < '0' || s[i] > '9') return 0;
    return 1;
}

/* Parses --set STREAM.PARAM=LO..HI or STREAM.PARAM=JSON. */
static int ld_parse_set(struct ld_setspec *sp, const char *arg)
{
    const char *eq = strchr(arg, '='), *dot, *val, *dd;
    char lhs[160], lo[64], hi[64];
    if (!eq || eq == arg || (size_t)(eq - arg) >= sizeof lhs)
        return ld_usage("--set needs STREAM.PARAM=LO..HI or STREAM.PARAM=JSON", arg);
    memcpy(lhs, arg, (size_t)(eq - arg));
    lhs[eq - arg] = 0;
    dot = strrchr(lhs, '.');
    if (!dot || !ld_valid_stream_name(lhs, (size_t)(dot - lhs)) || !ld_valid_param_name(dot + 1))
        return ld_usage("--set needs STREAM.PARAM (a stream name, a dot, a top-level parameter name)", arg);
    snprintf(sp->stream, sizeof sp->stream, "%.*s", (int)(dot - lhs), lhs);
    snprintf(sp->param, sizeof sp->param, "%s", dot + 1);
    val = eq + 1;
    if ((dd = strstr(val, "..")) && (size_t)(dd - val) < sizeof lo && strlen(dd + 2) < sizeof hi) {
        snprintf(lo, sizeof lo, "%.*s", (int)(dd - val), val);
        snprintf(hi, sizeof hi, "%s", dd + 2);
        if (ld_parse_double(lo, &sp->lo) || ld_parse_double(hi, &sp->hi) || sp->lo > sp->hi)
            return ld_usage("--set range needs numbers LO..HI with LO <= HI", arg);
        sp->range = 1;
        sp->integer = ld_is_integer_text(lo, strlen(lo)) && ld_is_integer_text(hi, strlen(hi));
        return 0;
    }
    if (!*val || !(sp->value = cJSON_ParseWithOpts(val, NULL, 1)))
        return ld_usage("--set value must be LO..HI or a JSON value (strings in quotes)", arg);
    return 0;
}

static const char *const ld_value_opts[] = { "--url", "--connections", "--mode", "--streams", "--max-fps", "--set",
                                              "--rate", "--duration", "--ramp", "--json", "--plot", "--seed",
                                              "--token", "--ca-file", NULL };

static int ld_set_opt(struct ld_opts *o, const char *name, const char *val)
{
    int known = 0;
    for (int i = 0; ld_value_opts[i]; i++) known |= !strcmp(name, ld_value_opts[i]);
    if (!strcmp(name, "--quiet") || !strcmp(name, "--payloads")) {
        if (val) return ld_usage("option takes no value", name);
        if (name[2] == 'q') o->quiet = 1;
        else o->payloads = 1;
        return 0;
    }
    if (!known) return ld_usage("unknown option", name);
    if (!val) return ld_usage("option needs a value", name);
    if (!strcmp(name, "--url")) {
        o->url = val;
    } else if (!strcmp(name, "--token")) {
        o->token = val;
    } else if (!strcmp(name, "--ca-file")) {
        o->ca_file = val;
    } else if (!strcmp(name, "--connections")) {
        if (ld_parse_long(val, &o->connections) || o->connections < 1 || o->connections > LD_MAX_CONNECTIONS)
            return ld_usage("--connections needs an integer from 1 to 10000", val);
    } else if (!strcmp(name, "--mode")) {
        if (!strcmp(val, "subscribe")) o->mode = LD_SUBSCRIBE;
        else if (!strcmp(val, "set")) o->mode = LD_SET;
        else return ld_usage("--mode must be subscribe or set", val);
        o->mode_name = val;
    } else if (!strcmp(name, "--streams")) {
        o->streams_spec = val;
    } else if (!strcmp(name, "--max-fps")) {
        if (ld_parse_double(val, &o->max_fps) || !(o->max_fps > 0) || o->max_fps > 1000)
            return ld_usage("--max-fps needs a number in (0, 1000]", val);
    } else if (!strcmp(name, "--set")) {
        if (o->nsets >= LD_MAX_SETS) return ld_usage("too many --set options (at most 16)", val);
        return ld_parse_set(&o->sets[o->nsets++], val);
    } else if (!strcmp(name, "--rate")) {
        if (ld_parse_double(val, &o->rate) || !(o->rate > 0) || o->rate > 100000)
            return ld_usage("--rate needs messages per second in (0, 100000]", val);
    } else if (!strcmp(name, "--duration")) {
        if (ld_parse_double(val, &o->duration) || !(o->duration > 0) || o->duration > 86400)
            return ld_usage("--duration needs seconds in (0, 86400]", val);
    } else if (!strcmp(name, "--ramp")) {
        if (ld_parse_double(val, &o->ramp) || o->ramp < 0 || o->ramp > 86400)
            return ld_usage("--ramp needs seconds, 0 or more", val);
        o->ramp_given = 1;
    } else if (!strcmp(name, "--json")) {
        if (!*val) return ld_usage("--json needs a file name", NULL);
        o->json_path = val;
    } else if (!strcmp(name, "--plot")) {
        size_t n = strlen(val);
        if (n < 5 || (strcmp(val + n - 4, ".svg") && strcmp(val + n - 4, ".png")))
            return ld_usage("--plot needs a file name ending in .svg or .png", val);
        o->plot_path = val;
    } else if (!strcmp(name, "--seed")) {
        long s;
        if (ld_parse_long(val, &s) || s < 0) return ld_usage("--seed needs a non-negative integer", val);
        o->seed = (unsigned long)s;
    } else {
        return ld_usage("unknown option", name);
    }
    return 0;
}

/* Fills o from argv. Returns 0, LD_USAGE, or -1 after printing --help. */
static int ld_parse_args(struct ld_opts *o, int argc, char **argv)
{
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *eq;
        char name[32];
        int r;
        if (!strcmp(a, "-h") || !strcmp(a, "--help")) {
            fputs(ld_help, stdout);
            return -1;
        }
        if (strncmp(a, "--", 2) != 0 || !a[2]) return ld_usage("unexpected argument", a);
        if ((eq = strchr(a, '='))) {
            if ((size_t)(eq - a) >= sizeof name) return ld_usage("unknown option", a);
            snprintf(name, sizeof name, "%.*s", (int)(eq - a), a);
            r = ld_set_opt(o, name, eq + 1);
        } else if (!strcmp(a, "--quiet") || !strcmp(a, "--payloads")) {
            r = ld_set_opt(o, a, NULL);
        } else {
            r = ld_set_opt(o, a, i + 1 < argc ? argv[++i] : NULL);
        }
        if (r) return r;
    }
    return 0;
}

/* ---- plan ----------------------------------------------------------------------- */

static int ld_stream_index(struct ld *ld, const char *name, size_t n)
{
    for (int i = 0; i < ld->nstreams; i++)
        if (strlen(ld->streams[i].name) == n && !strncmp(ld->streams[i].name, name, n)) return i;
    if (ld->nstreams >= LD_MAX_STREAMS) return -1;
    snprintf(ld->streams[ld->nstreams].name, sizeof ld->streams[0].name, "%.*s", (int)n, name);
    return ld->nstreams++;
}

/* Parses --streams: GROUP[:WEIGHT],... with GROUP = STREAM[+STREAM...]. */
static int ld_parse_streams(struct ld *ld, const char *spec)
{
    const char *p = spec;
    if (!*spec) return ld_usage("--streams needs at least one stream", NULL);
    while (*p) {
        const char *end = strchr(p, ','), *colon;
        size_t len = end ? (size_t)(end - p) : strlen(p);
        struct ld_group *g;
        char item[1024], *s, *w;
        if (!len || len >= sizeof item) return ld_usage("--streams: empty or too long item", spec);
        if (ld->ngroups >= LD_MAX_GROUPS) return ld_usage("--streams: at most 64 groups", spec);
        memcpy(item, p, len);
        item[len] = 0;
        g = &ld->groups[ld->ngroups++];
        g->weight = 1;
        if ((colon = strchr(item, ':'))) {
            w = item + (colon - item);
            *w++ = 0;
            if (ld_parse_double(w, &g->weight) || !(g->weight > 0) || g->weight > 1e6)
                return ld_usage("--streams: WEIGHT must be a positive number", item[0] ? w : spec);
        }
        for (s = item; s && *s;) {
            char *plus = strchr(s, '+');
            size_t n = plus ? (size_t)(plus - s) : strlen(s);
            int idx;
            if (!ld_valid_stream_name(s, n)) return ld_usage("--streams: invalid stream name (A-Z a-z 0-9 _ . -, 1-63)", p);
            if (g->n >= LD_MAX_GROUP) return ld_usage("--streams: at most 16 streams in one group", p);
            if ((idx = ld_stream_index(ld, s, n)) < 0) return ld_usage("--streams: at most 64 distinct streams", spec);
            for (int k = 0; k < g->n; k++)
                if (g->stream[k] == idx) return ld_usage("--streams: a stream twice in one group", p);
            g->stream[g->n++] = idx;
            s = plus ? plus + 1 : NULL;
            if (plus && !*s) return ld_usage("--streams: empty stream name after +", p);
        }
        if (!g->n) return ld_usage("--streams: empty group", spec);
        p += len;
        if (*p == ',') {
            p++;
            if (!*p) return ld_usage("--streams: empty item at the end", spec);
        }
    }
    return 0;
}

/* Checks combinations and fills defaults. */
static int ld_validate(struct ld *ld, struct ld_opts *o)
{
    int r;
    if (!o->ramp_given) o->ramp = o->duration > 2 ? 1 : o->duration / 2;
    if (o->ramp >= o->duration) return ld_usage("--ramp must be shorter than --duration", NULL);
    if (o->mode == LD_SUBSCRIBE) {
        if (o->nsets) return ld_usage("--set goes with --mode set", NULL);
        if (o->rate >= 0) return ld_usage("--rate goes with --mode set", NULL);
        if ((r = ld_parse_streams(ld, o->streams_spec ? o->streams_spec : "energy,flame"))) return r;
    } else {
        if (o->streams_spec) return ld_usage("--streams goes with --mode subscribe (set mode uses --set)", NULL);
        if (o->max_fps >= 0) return ld_usage("--max-fps goes with --mode subscribe", NULL);
        if (o->rate < 0) o->rate = 10;
        if (!o->nsets && (r = ld_parse_set(&o->sets[o->nsets++], "energy.alpha=0.5..2"))) return r;
        for (int i = 0; i < o->nsets; i++)
            if (ld_stream_index(ld, o->sets[i].stream, strlen(o->sets[i].stream)) < 0)
                return ld_usage("too many streams", NULL);
    }
    return 0;
}

/* Smooth weighted round-robin: the group of the next connection. */
static int ld_next_group(struct ld *ld)
{
    double total = 0;
    int best = 0;
    for (int g = 0; g < ld->ngroups; g++) {
        ld->groups[g].current += ld->groups[g].weight;
        total += ld->groups[g].weight;
        if (ld->groups[g].current > ld->groups[best].current) best = g;
    }
    ld->groups[best].current -= total;
    return best;
}

static int ld_plan(struct ld *ld)
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
        lc->group = ld->o->mode == LD_SUBSCRIBE ? ld_next_group(ld) : -1;
    }
    return 0;
}

/* ---- measurements ------------------------------------------------------------------- */

static double ld_now(const struct ld *ld) { return (double)(fxws_now_us(CLOCK_MONOTONIC) - ld->t0) / 1e6; }

/* Records msg among the distinct messages shown at the end (not counted as an error). */
static void ld_note(struct ld *ld, const char *msg)
{
    for (int i = 0; i < ld->nerrs; i++)
        if (!strcmp(ld->errs[i].msg, msg)) {
            ld->errs[i].count++;
            return;
        }
    if (ld->nerrs < LD_MAX_ERRS) {
        snprintf(ld->errs[ld->nerrs].msg, sizeof ld->errs[0].msg, "%s", msg);
        ld->errs[ld->nerrs++].count = 1;
    } else {
        ld->other_errs++;
    }
}

static void ld_error(struct ld *ld, const char *msg)
{
    ld->tot.errors++;
    ld_note(ld, msg);
}

/* "code: message" of an error message from the server, prefixed by what it answered. */
static void ld_server_error(struct ld *ld, const char *what, const cJSON *m)
{
    const cJSON *code = cJSON_GetObjectItemCaseSensitive(m, "code");
    const cJSON *msg = cJSON_GetObjectItemCaseSensitive(m, "message");
    char line[200];
    snprintf(line, sizeof line, "%s%s%s: %s", what, *what ? ": " : "", cJSON_IsString(code) ? code->valuestring : "error",
             cJSON_IsString(msg) ? msg->valuestring : "(no message)");
    ld_error(ld, line);
}

static void ld_on_open(struct fxp_conn *c, const cJSON *hello, void *user)
{
    struct ld_conn *lc = user;
    struct ld *ld = lc->ld;
    (void)hello;
    lc->state = LDC_OPEN;
    ld->ever_open++;
    if (++ld->open > ld->peak) ld->peak = ld->open;
    if (ld->o->mode != LD_SUBSCRIBE) return;
    const struct ld_group *g = &ld->groups[lc->group];
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

static void ld_on_set_reply(struct ld *ld, struct ld_conn *lc, const cJSON *m, const char *op, uint64_t now)
{
    struct ld_stream *st = &ld->streams[ld_stream_index(ld, ld->o->sets[lc->set_spec].stream,
                                                        strlen(ld->o->sets[lc->set_spec].stream))];
    lc->set_busy = 0;
    if (!strcmp(op, "params")) {
        const cJSON *rev = cJSON_GetObjectItemCaseSensitive(m, "rev");
        int64_t rtt = (int64_t)now - lc->set_sent_us;
        ld->tot.sets_ok++;
        st->sets_ok++;
        if (cJSON_IsNumber(rev) && rev->valuedouble > st->max_rev) st->max_rev = (uint32_t)rev->valuedouble;
        if (!ld->stopping) {
            fxp_hist_add(&ld->set_lat, rtt);
            fxp_hist_add(&ld->row_lat, rtt);
        }
    } else {
        char what[160];
        ld->tot.sets_err++;
        st->sets_err++;
        snprintf(what, sizeof what, "set %s.%s", st->name, ld->o->sets[lc->set_spec].param);
        ld_server_error(ld, what, m);
    }
}

static void ld_on_text(struct fxp_conn *c, const cJSON *m, uint64_t now, void *user)
{
    struct ld_conn *lc = user;
    struct ld *ld = lc->ld;
    const char *op = cJSON_GetObjectItemCaseSensitive(m, "op")->valuestring;
    const cJSON *id = cJSON_GetObjectItemCaseSensitive(m, "id");
    const cJSON *stream = cJSON_GetObjectItemCaseSensitive(m, "stream");
    (void)c;
    if (ld->o->mode == LD_SET && cJSON_IsNumber(id)) {
        if (lc->set_busy && id->valuedouble == lc->set_id) ld_on_set_reply(ld, lc, m, op, now);
        return;
    }
    if (ld->o->mode == LD_SUBSCRIBE && cJSON_IsNumber(id)) {
        const struct ld_group *g = &ld->groups[lc->group];
        int k = (int)id->valuedouble - 1;
        if (k < 0 || k >= g->n) return;
        struct ld_stream *st = &ld->streams[g->stream[k]];
        if (!strcmp(op, "subscribed")) {
            const cJSON *ch = cJSON_GetObjectItemCaseSensitive(m, "channel");
            if (!lc->subs[k].channel) st->subscribers++;
            lc->subs[k].channel = cJSON_IsNumber(ch) ? (uint32_t)ch->valuedouble : 0;
        } else if (!strcmp(op, "error")) {
            char what[120];
            st->sub_errors++;
            snprintf(what, sizeof what, "subscribe %s", st->name);
            ld_server_error(ld, what, m);
        }
        return;
    }
    ld->events++;
    if (!strcmp(op, "error")) {
        char what[120];
        snprintf(what, sizeof what, "%s%s", cJSON_IsString(stream) ? "stream " : "server",
                 cJSON_IsString(stream) ? stream->valuestring : "");
        ld_server_error(ld, what, m);
    } else if (!strcmp(op, "unsubscribed")) {
        char line[160];
        const cJSON *why = cJSON_GetObjectItemCaseSensitive(m, "reason");
        snprintf(line, sizeof line, "unsubscribed from %s (%s)", cJSON_IsString(stream) ? stream->valuestring : "?",
                 cJSON_IsString(why) ? why->valuestring : "no reason");
        ld_error(ld, line);
    }
}

static void ld_on_frame(struct fxp_conn *c, const struct fxs_header *h, const uint8_t *payload, size_t bytes,
                        uint64_t now, void *user)
{
    struct ld_conn *lc = user;
    struct ld *ld = lc->ld;
    unsigned kind = h->kind <= FXS_KIND_MAX ? h->kind : 0;
    struct ld_sub *sub = NULL;
    struct ld_stream *st = NULL;
    (void)c;
    (void)payload;
    if (ld->stopping) return;
    ld->tot.frames++;
    ld->tot.bytes += bytes;
    if (lc->group >= 0) {
        const struct ld_group *g = &ld->groups[lc->group];
        for (int k = 0; k < g->n; k++)
            if (lc->subs[k].channel == h->channel) {
                sub = &lc->subs[k];
                st = &ld->streams[g->stream[k]];
                break;
            }
    }
    if (!sub) {
        ld->unknown_channel++;
        return;
    }
    st->frames++;
    st->bytes += bytes;
    st->kind[kind].frames++;
    st->kind[kind].bytes += bytes;
    if (sub->last_seq[kind]) {
        if (h->seq > sub->last_seq[kind] + 1) {
            uint64_t gap = h->seq - sub->last_seq[kind] - 1;
            ld->tot.skipped += gap;
            st->skipped += gap;
            st->kind[kind].skipped += gap;
        } else if (h->seq <= sub->last_seq[kind]) {
            ld->seq_backwards++;
        }
        int64_t lat = (int64_t)now - (int64_t)h->server_time_us;
        fxp_hist_add(&ld->lat, lat);
        fxp_hist_add(&ld->row_lat, lat);
        fxp_hist_add(&st->lat, lat);
    }
    sub->last_seq[kind] = h->seq;
}

static void ld_on_close(struct fxp_conn *c, const struct fxp_close_info *info, void *user)
{
    struct ld_conn *lc = user;
    struct ld *ld = lc->ld;
    (void)c;
    if (lc->state == LDC_OPEN) ld->open--;
    lc->c = NULL;
    if (info->by_client) {
        lc->state = LDC_DONE;
        return;
    }
    if (lc->state == LDC_OPEN) ld->tot.disconnects++;
    else ld->tot.failed++;
    lc->state = LDC_DONE;
    ld_note(ld, info->reason);
}

/* ---- the run ---------------------------------------------------------------------- */

static double ld_rand(struct ld *ld)
{
    ld->rng = ld->rng * 6364136223846793005ULL + 1442695040888963407ULL;
    return (double)(ld->rng >> 11) / 9007199254740992.0;
}

/* Sends one set from the next idle open connection. Returns 0, or -1 when none is idle. */
static int ld_send_set(struct ld *ld)
{
    long n = ld->o->connections;
    for (long tries = 0; tries < n; tries++) {
        struct ld_conn *lc = &ld->conns[ld->set_rr];
        ld->set_rr = (int)((ld->set_rr + 1) % n);
        if (lc->state != LDC_OPEN || lc->set_busy) continue;
        int spec = (int)(ld->next_spec++ % (unsigned)ld->o->nsets);
        const struct ld_setspec *sp = &ld->o->sets[spec];
        cJSON *req = cJSON_CreateObject(), *params;
        cJSON_AddStringToObject(req, "op", "set");
        cJSON_AddNumberToObject(req, "id", ++lc->set_id);
        cJSON_AddStringToObject(req, "stream", sp->stream);
        params = cJSON_AddObjectToObject(req, "params");
        if (sp->range) {
            double v = sp->lo + (sp->hi - sp->lo) * ld_rand(ld);
            if (sp->integer) v = floor(sp->lo + (sp->hi - sp->lo + 1) * ld_rand(ld));
            if (v > sp->hi) v = sp->hi;
            cJSON_AddNumberToObject(params, sp->param, v);
        } else {
            cJSON_AddItemToObject(params, sp->param, cJSON_Duplicate(sp->value, 1));
        }
        if (fxp_send_json(lc->c, req) == 0) {
            lc->set_busy = 1;
            lc->set_spec = spec;
            lc->set_sent_us = fxws_now_us(CLOCK_REALTIME);
        }
        cJSON_Delete(req);
        return 0;
    }
    return -1;
}

static void ld_row_end(struct ld *ld, double now)
{
    struct ld_row *r;
    if (ld->nrows == ld->rows_cap) {
        int cap = ld->rows_cap ? 2 * ld->rows_cap : 64;
        struct ld_row *p = realloc(ld->rows, (size_t)cap * sizeof *p);
        if (!p) return;
        ld->rows = p;
        ld->rows_cap = cap;
    }
    r = &ld->rows[ld->nrows++];
    r->t = now;
    r->dt = now - ld->row_start;
    r->conns = ld->open;
    r->d.frames = ld->tot.frames - ld->row_base.frames;
    r->d.bytes = ld->tot.bytes - ld->row_base.bytes;
    r->d.skipped = ld->tot.skipped - ld->row_base.skipped;
    r->d.errors = ld->tot.errors - ld->row_base.errors;
    r->d.disconnects = ld->tot.disconnects - ld->row_base.disconnects;
    r->d.failed = ld->tot.failed - ld->row_base.failed;
    r->d.sets_ok = ld->tot.sets_ok - ld->row_base.sets_ok;
    r->d.sets_err = ld->tot.sets_err - ld->row_base.sets_err;
    r->p50 = fxp_hist_quantile(&ld->row_lat, 0.50) / 1000;
    r->p95 = fxp_hist_quantile(&ld->row_lat, 0.95) / 1000;
    r->p99 = fxp_hist_quantile(&ld->row_lat, 0.99) / 1000;
    r->max = fxp_hist_quantile(&ld->row_lat, 1.0) / 1000;
    r->timed = ld->row_lat.count;
    ld->row_base = ld->tot;
    ld->row_start = now;
    fxp_hist_reset(&ld->row_lat);
    if (!ld->o->quiet) {
        double dt = r->dt > 0 ? r->dt : 1;
        fprintf(ld->tout, "%6.1f %6d %9.0f %8.2f %7.0f %7.0f %8.3f %8.3f %8.3f %8.3f %5" PRIu64 " %5" PRIu64 "\n", r->t,
                r->conns, (double)r->d.frames / dt, (double)r->d.bytes / dt / 1e6, (double)r->d.skipped / dt,
                (double)r->d.sets_ok / dt, r->p50, r->p95, r->p99, r->max, r->d.errors + r->d.failed,
                r->d.disconnects);
        fflush(ld->tout);
    }
}

static void ld_table_header(struct ld *ld)
{
    if (ld->o->quiet) return;
    fprintf(ld->tout, "%6s %6s %9s %8s %7s %7s %8s %8s %8s %8s %5s %5s\n", "t", "conns", "frames/s", "MB/s", "skip/s",
            "sets/s", "p50_ms", "p95_ms", "p99_ms", "max_ms", "err", "disc");
    fflush(ld->tout);
}

/* Starts the connections due by `now` (ramp). Returns -1 on a fatal error. */
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
            return -2;
        }
        if (r) {
            lc->state = LDC_DONE;
            ld->tot.failed++;
            ld_note(ld, err);
        }
    }
    return 0;
}

/* The run: ramp, measure, stop, close. Returns 0, or an exit status on fatal errors. */
static int ld_run(struct ld *ld)
{
    struct fxp_callbacks cb = { ld_on_open, ld_on_text, ld_on_frame, ld_on_close };
    struct fxp_options po = { .max_connections = (int)ld->o->connections, .payloads = ld->o->payloads,
                              .token = ld->o->token, .ca_file = ld->o->ca_file };
    char err[300];
    double next_row = 1, now = 0;
    if (fxp_pool_create(&ld->pool, &cb, &po, err, sizeof err)) {
        fprintf(stderr, "fxload: %s\n", err);
        return LD_FAIL;
    }
    ld->t0 = fxws_now_us(CLOCK_MONOTONIC);
    ld_table_header(ld);
    for (;;) {
        double wait;
        int r;
        now = ld_now(ld);
        if ((r = ld_start_due(ld, now))) return r == -2 ? LD_USAGE : LD_FAIL;
        if (ld->o->mode == LD_SET) {
            int burst = 0;
            while (ld->next_set <= now && burst++ < 10000) {
                if (ld->open && ld_send_set(ld)) ld->sets_skipped++; /* none open yet: not due */
                ld->next_set += 1.0 / ld->o->rate;
            }
            if (ld->next_set < now) ld->next_set = now; /* fell behind: do not catch up later */
        }
        while (now >= next_row && next_row <= ld->o->duration) {
            ld_row_end(ld, next_row);
            next_row += 1;
        }
        if (ld_signalled) { ld->end_reason = "interrupted"; break; }
        if (now >= ld->o->duration) { ld->end_reason = "duration reached"; break; }
        if (ld->started == ld->o->connections && fxp_live(ld->pool) == 0) {
            ld->end_reason = ld->ever_open ? "every connection closed" : "no connection could be established";
            break;
        }
        wait = fmin(next_row, ld->o->duration) - now;
        if (ld->started < ld->o->connections)
            wait = fmin(wait, ld->o->ramp * (double)ld->started / (double)ld->o->connections - now);
        if (ld->o->mode == LD_SET) wait = fmin(wait, ld->next_set - now);
        wait = fmin(fmax(wait, 0), LD_SERVICE_MAX_MS / 1000.0);
        if (fxp_service(ld->pool, (int)ceil(wait * 1000)) < 0) {
            fprintf(stderr, "fxload: libwebsockets service failed\n");
            return LD_FAIL;
        }
    }
    /* The last partial second, then stop measuring and close politely. */
    if (now - ld->row_start > 0.05 || ld->nrows == 0) ld_row_end(ld, now);
    ld->elapsed = now;
    ld->stopping = 1;
    for (long i = 0; i < ld->o->connections; i++)
        if (ld->conns[i].c) fxp_close(ld->conns[i].c);
    int64_t deadline = fxws_now_us(CLOCK_MONOTONIC) + LD_CLOSE_WAIT_US;
    while (fxp_live(ld->pool) > 0 && fxws_now_us(CLOCK_MONOTONIC) < deadline)
        if (fxp_service(ld->pool, 10) < 0) break;
    fxp_pool_destroy(ld->pool);
    ld->pool = NULL;
    return 0;
}

/* ---- reports ----------------------------------------------------------------------------- */

static double ld_ms(double us) { return round(us) / 1000.0; }

static cJSON *ld_latency_json(const struct fxp_hist *h)
{
    cJSON *j = cJSON_CreateObject();
    cJSON_AddNumberToObject(j, "count", (double)h->count);
    cJSON_AddNumberToObject(j, "p50", ld_ms(fxp_hist_quantile(h, 0.50)));
    cJSON_AddNumberToObject(j, "p95", ld_ms(fxp_hist_quantile(h, 0.95)));
    cJSON_AddNumberToObject(j, "p99", ld_ms(fxp_hist_quantile(h, 0.99)));
    cJSON_AddNumberToObject(j, "max", ld_ms(fxp_hist_quantile(h, 1.0)));
    cJSON_AddNumberToObject(j, "mean", h->count ? ld_ms(h->sum_us / (double)h->count) : 0);
    return j;
}

static cJSON *ld_report_json(const struct ld *ld)
{
    const struct ld_opts *o = ld->o;
    cJSON *j = cJSON_CreateObject(), *opt, *con, *tot, *arr, *e;
    cJSON_AddStringToObject(j, "tool", "fxload");
    opt = cJSON_AddObjectToObject(j, "options");
    cJSON_AddStringToObject(opt, "url", o->url);
    cJSON_AddStringToObject(opt, "mode", o->mode == LD_SET ? "set" : "subscribe");
    cJSON_AddNumberToObject(opt, "connections", (double)o->connections);
    cJSON_AddNumberToObject(opt, "duration_s", o->duration);
    cJSON_AddNumberToObject(opt, "ramp_s", o->ramp);
    if (o->mode == LD_SUBSCRIBE) cJSON_AddStringToObject(opt, "streams", o->streams_spec ? o->streams_spec : "energy,flame");
    if (o->max_fps > 0) cJSON_AddNumberToObject(opt, "max_fps", o->max_fps);
    if (o->mode == LD_SET) cJSON_AddNumberToObject(opt, "rate", o->rate);
    cJSON_AddBoolToObject(opt, "payloads", o->payloads);
    cJSON_AddNumberToObject(j, "elapsed_s", round(ld->elapsed * 1000) / 1000);
    cJSON_AddStringToObject(j, "end", ld->end_reason ? ld->end_reason : "");
    con = cJSON_AddObjectToObject(j, "connections");
    cJSON_AddNumberToObject(con, "requested", (double)o->connections);
    cJSON_AddNumberToObject(con, "connected", ld->ever_open);
    cJSON_AddNumberToObject(con, "peak", ld->peak);
    cJSON_AddNumberToObject(con, "open_at_end", ld->open);
    cJSON_AddNumberToObject(con, "failed", (double)ld->tot.failed);
    cJSON_AddNumberToObject(con, "disconnects", (double)ld->tot.disconnects);
    tot = cJSON_AddObjectToObject(j, "totals");
    cJSON_AddNumberToObject(tot, "frames", (double)ld->tot.frames);
    cJSON_AddNumberToObject(tot, "bytes", (double)ld->tot.bytes);
    cJSON_AddNumberToObject(tot, "skipped", (double)ld->tot.skipped);
    cJSON_AddNumberToObject(tot, "frames_per_s", ld->elapsed > 0 ? round((double)ld->tot.frames / ld->elapsed) : 0);
    cJSON_AddNumberToObject(tot, "mbytes_per_s", ld->elapsed > 0 ? round((double)ld->tot.bytes / ld->elapsed / 1e3) / 1e3 : 0);
    cJSON_AddNumberToObject(tot, "errors", (double)ld->tot.errors);
    cJSON_AddNumberToObject(tot, "unknown_channel", (double)ld->unknown_channel);
    cJSON_AddNumberToObject(tot, "seq_backwards", (double)ld->seq_backwards);
    cJSON_AddNumberToObject(tot, "events", (double)ld->events);
    cJSON_AddItemToObject(tot, "latency_ms", ld_latency_json(&ld->lat));
    arr = cJSON_AddArrayToObject(j, "streams");
    for (int i = 0; i < ld->nstreams; i++) {
        const struct ld_stream *st = &ld->streams[i];
        cJSON *s = cJSON_CreateObject(), *kinds;
        cJSON_AddStringToObject(s, "stream", st->name);
        if (o->mode == LD_SUBSCRIBE) {
            cJSON_AddNumberToObject(s, "subscribers", st->subscribers);
            cJSON_AddNumberToObject(s, "subscribe_errors", st->sub_errors);
            cJSON_AddNumberToObject(s, "frames", (double)st->frames);
            cJSON_AddNumberToObject(s, "bytes", (double)st->bytes);
            cJSON_AddNumberToObject(s, "skipped", (double)st->skipped);
            cJSON_AddItemToObject(s, "latency_ms", ld_latency_json(&st->lat));
            kinds = cJSON_AddObjectToObject(s, "kinds");
            for (int k = 0; k <= FXS_KIND_MAX; k++) {
                char key[8];
                cJSON *kj;
                if (!st->kind[k].frames) continue;
                snprintf(key, sizeof key, "%d", k);
                kj = cJSON_AddObjectToObject(kinds, key);
                cJSON_AddNumberToObject(kj, "frames", (double)st->kind[k].frames);
                cJSON_AddNumberToObject(kj, "bytes", (double)st->kind[k].bytes);
                cJSON_AddNumberToObject(kj, "skipped", (double)st->kind[k].skipped);
            }
        } else {
            cJSON_AddNumberToObject(s, "sets_ok", (double)st->sets_ok);
            cJSON_AddNumberToObject(s, "sets_failed", (double)st->sets_err);
            cJSON_AddNumberToObject(s, "max_rev", st->max_rev);
        }
        cJSON_AddItemToArray(arr, s);
    }
    if (o->mode == LD_SET) {
        cJSON *sj = cJSON_AddObjectToObject(j, "sets");
        cJSON_AddNumberToObject(sj, "ok", (double)ld->tot.sets_ok);
        cJSON_AddNumberToObject(sj, "failed", (double)ld->tot.sets_err);
        cJSON_AddNumberToObject(sj, "not_sent", (double)ld->sets_skipped);
        cJSON_AddItemToObject(sj, "latency_ms", ld_latency_json(&ld->set_lat));
    }
    arr = cJSON_AddArrayToObject(j, "errors");
    for (int i = 0; i < ld->nerrs; i++) {
        e = cJSON_CreateObject();
        cJSON_AddStringToObject(e, "message", ld->errs[i].msg);
        cJSON_AddNumberToObject(e, "count", (double)ld->errs[i].count);
        cJSON_AddItemToArray(arr, e);
    }
    if (ld->other_errs) {
        e = cJSON_CreateObject();
        cJSON_AddStringToObject(e, "message", "(other messages)");
        cJSON_AddNumberToObject(e, "count", (double)ld->other_errs);
        cJSON_AddItemToArray(arr, e);
    }
    arr = cJSON_AddArrayToObject(j, "seconds");
    for (int i = 0; i < ld->nrows; i++) {
        const struct ld_row *r = &ld->rows[i];
        cJSON *s = cJSON_CreateObject();
        cJSON_AddNumberToObject(s, "t", round(r->t * 1000) / 1000);
        cJSON_AddNumberToObject(s, "dt", round(r->dt * 1000) / 1000);
        cJSON_AddNumberToObject(s, "connections", r->conns);
        cJSON_AddNumberToObject(s, "frames", (double)r->d.frames);
        cJSON_AddNumberToObject(s, "bytes", (double)r->d.bytes);
        cJSON_AddNumberToObject(s, "skipped", (double)r->d.skipped);
        cJSON_AddNumberToObject(s, "sets", (double)r->d.sets_ok);
        cJSON_AddNumberToObject(s, "errors", (double)(r->d.errors + r->d.failed));
        cJSON_AddNumberToObject(s, "disconnects", (double)r->d.disconnects);
        cJSON_AddNumberToObject(s, "p50_ms", round(r->p50 * 1000) / 1000);
        cJSON_AddNumberToObject(s, "p95_ms", round(r->p95 * 1000) / 1000);
        cJSON_AddNumberToObject(s, "p99_ms", round(r->p99 * 1000) / 1000);
        cJSON_AddNumberToObject(s, "max_ms", round(r->max * 1000) / 1000);
        cJSON_AddItemToArray(arr, s);
    }
    return j;
}

static void ld_summary_line(FILE *f, const char *name, int subs, uint64_t frames, uint64_t bytes, uint64_t skipped,
                            const struct fxp_hist *h)
{
    fprintf(f, "%-20s %6d %10" PRIu64 " %10.2f %8" PRIu64 " %8.3f %8.3f %8.3f %8.3f\n", name, subs, frames,
            (double)bytes / 1e6, skipped, fxp_hist_quantile(h, 0.5) / 1000, fxp_hist_quantile(h, 0.95) / 1000,
            fxp_hist_quantile(h, 0.99) / 1000, fxp_hist_quantile(h, 1.0) / 1000);
}

static void ld_summary(const struct ld *ld)
{
    FILE *f = ld->tout;
    const struct ld_opts *o = ld->o;
    fprintf(f, "fxload: %s, %d of %ld connections (peak %d, failed %" PRIu64 ", disconnects %" PRIu64
               ") to %s, %.2f s (%s)\n",
            o->mode == LD_SET ? "set" : "subscribe", ld->ever_open, o->connections, ld->peak, ld->tot.failed,
            ld->tot.disconnects, o->url, ld->elapsed, ld->end_reason ? ld->end_reason : "");
    if (o->mode == LD_SUBSCRIBE) {
        int subs = 0;
        fprintf(f, "%-20s %6s %10s %10s %8s %8s %8s %8s %8s\n", "stream", "subs", "frames", "MB", "skipped", "p50_ms",
                "p95_ms", "p99_ms", "max_ms");
        for (int i = 0; i < ld->nstreams; i++) {
            const struct ld_stream *st = &ld->streams[i];
            subs += st->subscribers;
            ld_summary_line(f, st->name, st->subscribers, st->frames, st->bytes, st->skipped, &st->lat);
        }
        ld_summary_line(f, "total", subs, ld->tot.frames, ld->tot.bytes, ld->tot.skipped, &ld->lat);
        fprintf(f, "throughput: %.0f frames/s, %.2f MB/s\n", ld->elapsed > 0 ? (double)ld->tot.frames / ld->elapsed : 0,
                ld->elapsed > 0 ? (double)ld->tot.bytes / ld->elapsed / 1e6 : 0);
    } else {
        fprintf(f, "sets: %" PRIu64 " ok, %" PRIu64 " failed, %" PRIu64 " not sent (no idle connection); round trip ms "
                   "p50 %.3f p95 %.3f p99 %.3f max %.3f\n",
                ld->tot.sets_ok, ld->tot.sets_err, ld->sets_skipped, fxp_hist_quantile(&ld->set_lat, 0.5) / 1000,
                fxp_hist_quantile(&ld->set_lat, 0.95) / 1000, fxp_hist_quantile(&ld->set_lat, 0.99) / 1000,
                fxp_hist_quantile(&ld->set_lat, 1.0) / 1000);
        for (int i = 0; i < ld->nstreams; i++)
            fprintf(f, "  %s: %" PRIu64 " ok, %" PRIu64 " failed, rev now %" PRIu32 "\n", ld->streams[i].name,
                    ld->streams[i].sets_ok, ld->streams[i].sets_err, ld->streams[i].max_rev);
    }
    fflush(f);
    for (int i = 0; i < ld->nerrs; i++)
        fprintf(stderr, "fxload: %" PRIu64 " x %s\n", ld->errs[i].count, ld->errs[i].msg);
    if (ld->other_errs) fprintf(stderr, "fxload: %" PRIu64 " x other errors\n", ld->other_errs);
}

/* Writes s for a single-quoted gnuplot string ('' is a quote). */
static void ld_gp_quoted(FILE *f, const char *s)
{
    fputc('\'', f);
    for (; *s; s++) {
        if (*s == '\'') fputc('\'', f);
        if (*s != '\n') fputc(*s, f);
    }
    fputc('\'', f);
}

static int ld_plot(const struct ld *ld)
{
    const struct ld_opts *o = ld->o;
    const char *path = o->plot_path;
    int png = !strcmp(path + strlen(path) - 4, ".png"), set = o->mode == LD_SET, st;
    char title[512];
    FILE *gp = popen("gnuplot", "w");
    if (!gp) {
        fprintf(stderr, "fxload: cannot run gnuplot: %s\n", strerror(errno));
        return -1;
    }
    if (png) fputs("set terminal pngcairo size 1000,760 noenhanced font 'sans,10'\n", gp);
    else fputs("set terminal svg size 1000,760 dynamic noenhanced font 'sans,11' background '#ffffff'\n", gp);
    fputs("set output ", gp);
    ld_gp_quoted(gp, path);
    fputs("\n$d << EOD\n", gp);
    for (int i = 0; i < ld->nrows; i++) {
        const struct ld_row *r = &ld->rows[i];
        double dt = r->dt > 0 ? r->dt : 1;
        fprintf(gp, "%.3f %d %.3f %.6f %.3f %.3f %.3f %.3f %.3f %.3f\n", r->t, r->conns, (double)r->d.frames / dt,
                (double)r->d.bytes / dt / 1e6, (double)r->d.sets_ok / dt, r->p50, r->p95, r->p99, r->max,
                (double)r->d.skipped / dt);
    }
    fputs("EOD\n", gp);
    snprintf(title, sizeof title, "fxload %s: %ld connections to %s, %.1f s", set ? "set" : "subscribe",
             o->connections, o->url, ld->elapsed);
    fputs("set multiplot layout 2,1 title ", gp);
    ld_gp_quoted(gp, title);
    fputs("\nset grid\nset key top left\nset xlabel 'time (s)'\nset yrange [0:*]\n", gp);
    fprintf(gp, "set ylabel '%s latency (ms)'\n", set ? "set round trip" : "frame");
    fputs("plot $d using 1:6 with linespoints title 'p50', $d using 1:7 with linespoints title 'p95', "
          "$d using 1:8 with linespoints title 'p99', $d using 1:9 with linespoints title 'max'\n", gp);
    if (set) {
        fputs("set ylabel 'sets/s'\nset y2label 'connections'\nset y2tics\nset ytics nomirror\nset y2range [0:*]\n"
              "plot $d using 1:5 with linespoints title 'sets/s' axes x1y1, "
              "$d using 1:2 with lines title 'connections' axes x1y2\n", gp);
    } else {
        fputs("set ylabel 'frames/s'\nset y2label 'MB/s'\nset y2tics\nset ytics nomirror\nset y2range [0:*]\n"
              "plot $d using 1:3 with linespoints title 'frames/s' axes x1y1, "
              "$d using 1:4 with linespoints title 'MB/s' axes x1y2, "
              "$d using 1:10 with lines title 'skipped/s' axes x1y1\n", gp);
    }
    fputs("unset multiplot\nset output\n", gp);
    st = pclose(gp);
    if (st == -1 || !WIFEXITED(st) || WEXITSTATUS(st) != 0) {
        fprintf(stderr, "fxload: gnuplot failed (%s %d) writing %s; is it installed (Debian gnuplot-nox)?\n",
                st != -1 && WIFEXITED(st) ? "exit status" : "status", st != -1 && WIFEXITED(st) ? WEXITSTATUS(st) : st,
                path);
        return -1;
    }
    return 0;
}

/* Opens the output files before the run so a bad path fails early. */
static int ld_open_outputs(struct ld *ld)
{
    const struct ld_opts *o = ld->o;
    ld->tout = stdout;
    if (o->json_path && !strcmp(o->json_path, "-")) {
        ld->json = stdout;
        ld->tout = stderr;
    } else if (o->json_path && !(ld->json = fopen(o->json_path, "w"))) {
        fprintf(stderr, "fxload: cannot write %s: %s\n", o->json_path, strerror(errno));
        return LD_FAIL;
    }
    if (o->plot_path) {
        FILE *f = fopen(o->plot_path, "w");
        if (!f) {
            fprintf(stderr, "fxload: cannot write %s: %s\n", o->plot_path, strerror(errno));
            return LD_FAIL;
        }
        fclose(f);
        if (system("command -v gnuplot >/dev/null 2>&1") != 0) {
            fprintf(stderr, "fxload: --plot needs gnuplot (Debian package gnuplot-nox; deploy/install-deps.sh)\n");
            return LD_FAIL;
        }
    }
    return 0;
}

static int ld_write_json(struct ld *ld)
{
    cJSON *j = ld_report_json(ld);
    char *text = cJSON_Print(j);
    int ok = text && fprintf(ld->json, "%s\n", text) > 0;
    free(text);
    cJSON_Delete(j);
    if (ld->json == stdout) ok = fflush(stdout) == 0 && ok;
    else if (fclose(ld->json)) ok = 0;
    ld->json = NULL;
    if (!ok) fprintf(stderr, "fxload: cannot write %s: %s\n", ld->o->json_path, strerror(errno));
    return ok ? 0 : -1;
}

static void ld_free(struct ld *ld)
{
    if (ld->pool) fxp_pool_destroy(ld->pool);
    if (ld->json && ld->json != stdout) fclose(ld->json);
    free(ld->conns);
    free(ld->subs);
    free(ld->rows);
    for (int i = 0; i < ld->o->nsets; i++) cJSON_Delete(ld->o->sets[i].value);
}

int main(int argc, char **argv)
{
    static struct ld ld; /* large (histograms): not on the stack */
    struct ld_opts o = { .url = LD_DEFAULT_URL, .connections = 10, .max_fps = -1, .rate = -1, .duration = 10,
                         .seed = 1 };
    struct fxws_url u;
    char err[300];
    struct sigaction sa;
    int r;
    const char *log = getenv("FXLOAD_LWS_LOG");
    o.token = getenv("FXSTREAM_TOKEN");
    o.ca_file = getenv("FXSTREAM_CA_FILE");
    lws_set_log_level(log ? atoi(log) : 0, NULL);
    ld.o = &o;
    r = ld_parse_args(&o, argc, argv);
    if (r == 0) r = ld_validate(&ld, &o);
    if (r == 0 && fxws_url_parse(&u, o.url, err, sizeof err)) r = ld_usage(err, NULL);
    if (r == 0 && ld_plan(&ld)) {
        fprintf(stderr, "fxload: out of memory\n");
        r = LD_FAIL;
    }
    if (r == 0) r = ld_open_outputs(&ld);
    if (r) {
        ld_free(&ld);
        return r < 0 ? LD_OK : r;
    }
    ld.rng = o.seed * 2654435761UL + 1;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = ld_on_signal;
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
    signal(SIGPIPE, SIG_IGN);
    r = ld_run(&ld);
    if (r) {
        ld_free(&ld);
        return r;
    }
    ld_summary(&ld);
    if (ld.json && ld_write_json(&ld)) r = LD_FAIL;
    if (o.plot_path && ld_plot(&ld)) r = LD_FAIL;
    if (!r && !ld.ever_open) {
        fprintf(stderr, "fxload: no connection could be established to %s\n", o.url);
        r = LD_FAIL;
    } else if (!r && (ld.tot.failed || ld.tot.disconnects || ld.tot.errors)) {
        r = LD_DEGRADED;
    }
    ld_free(&ld);
    return r;
}
