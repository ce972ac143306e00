/* fxload.c — the load generator of fxstreamd, built on libfxclient's pool (fxpool.h): its
 * help text and main, which runs the phases in order (options, plan, output files, the run,
 * the reports) and turns their outcome into the exit status.
 *
 * The run ends by itself after --duration seconds (or earlier when every connection is
 * gone or on SIGINT/SIGTERM). It never targets anything but the default loopback URL or the
 * ones given with --url.
 *
 * fxload's files, one noun each with its header; a file includes only those listed above it:
 *   fxload_opts       options, their checks and defaults, exit statuses
 *   fxload_state.h    the record of one run (struct ld): streams, groups, counters, rows
 *   fxload_errors     error messages kept for the end, fatal errors
 *   fxload_plan       the run's streams (--streams groups, --set streams), each connection's group
 *   fxload_conn       the connections: their table, control requests, servicing, closing
 *   fxload_stats      measurements: frames, bytes, seq gaps, latency, delivered rate, rows
 *   fxload_set        set mode: the set messages, the values before the run, restoring them
 *   fxload_thresholds --max-p99, --min-delivered, --max-skipped: pass or fail
 *   fxload_report     the per-second table, the summary, the JSON report
 *   fxload_plot       the gnuplot plot
 *   fxload_run        the run on libfxclient's pool: ramp, requests, callbacks, the end
 * Not a library: the Makefile links these files into build/fxload only. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fxclient.h"
#include "fxload_conn.h"
#include "fxload_opts.h"
#include "fxload_plot.h"
#include "fxload_plan.h"
#include "fxload_report.h"
#include "fxload_run.h"
#include "fxload_state.h"
#include "fxload_thresholds.h"
#include "fxws.h"

static const char ld_help[] =
    "usage: fxload [options]\n"
    "\n"
    "Load generator for fxstreamd: opens N WebSocket connections (one thread, one\n"
    "event loop), ramping up at a steady rate, and for a fixed time either subscribes\n"
    "each to streams or sends parameter changes; then closes them and reports.\n"
    "\n"
    "options (also as --opt=VALUE):\n"
    "  --url URL          server (default " LD_DEFAULT_URL "); fxload targets\n"
    "                     only this loopback default or the URLs given here (ws://, wss://).\n"
    "                     Repeat it (up to 16) to spread the connections round robin over\n"
    "                     the daemons of a cluster (README \"Cluster mode\")\n"
    "  --token T          access token for every connection (default $FXSTREAM_TOKEN)\n"
    "  --ca-file F        PEM bundle for a wss:// server (default $FXSTREAM_CA_FILE)\n"
    "  --connections N    connections, 1..10000 (default 10)\n"
    "  --mode M           subscribe (default) or set\n"
    "  --streams LIST     subscribe mode: comma-separated groups GROUP[:WEIGHT]; a group\n"
    "                     is STREAM or STREAM+STREAM+... (a connection subscribes to\n"
    "                     every stream of its group); connections are shared among the\n"
    "                     groups in proportion to WEIGHT (default 1).\n"
    "                     Default energy,flame (half each). E.g. flame:3,energy:1\n"
    "  --max-fps F        subscribe mode: max_fps of each subscription, [0.01, 1000]\n"
    "  --max-particles P  subscribe mode: max_particles of each subscription, at most P\n"
    "                     particles a particle frame, [1000, 4194304]: the server\n"
    "                     serves the largest of its steps 1000, 2000, 5000, ...\n"
    "                     2000000 at most P, one subset per stream and step, so the\n"
    "                     run measures what budgeted subscribers cost\n"
    "  --set SPEC         set mode: STREAM.PARAM=LO..HI (uniform random number; integers\n"
    "                     when LO and HI are) or STREAM.PARAM=JSON (fixed value); may be\n"
    "                     repeated, each set message uses the next SPEC in turn.\n"
    "                     Default energy.alpha=0.5..2\n"
    "  --rate R           set mode: set messages per second over all connections, each\n"
    "                     from the next connection without one outstanding (default 10)\n"    "                     Before the first set, fxload reads (get) the values of the\n"
    "                     parameters it changes; after the run it sets them back\n"
    "  --keep             set mode: leave the last values set instead\n"
    "  --duration S       length of the run in seconds, ramp included (default 10)\n"
    "  --ramp S           open the connections evenly over the first S seconds\n"
    "                     (default 1; 0 opens them all at once; must be < duration)\n"
    "  --json FILE        write the report as JSON to FILE ('-': stdout; the table and\n"
    "                     summary then go to stderr)\n"
    "  --plot FILE        plot over time with gnuplot into FILE.svg or FILE.png (needs\n"
    "                     gnuplot: Debian gnuplot-nox): latency percentiles with the\n"
    "                     open connections; per stream frames/s (and MB/s) and\n"
    "                     skipped/s on its own axis, or sets/s in set mode\n"
    "  --payloads         reassemble whole frames (default: keep only headers, count\n"
    "                     bytes; cheaper, so the load generator disturbs less)\n"
    "  --seed N           random seed for --set values (default 1)\n"
    "  --max-p99 MS       threshold: p99 latency (of frames; of set round trips in set\n"
    "                     mode) at most MS milliseconds\n"
    "  --min-delivered PCT  threshold, subscribe mode: each stream delivers at least\n"
    "                     PCT% of its fps to its subscribers (see delivered below)\n"
    "  --max-skipped PCT  threshold, subscribe mode: at most PCT% of the frames due\n"
    "                     (received + skipped) were skipped\n"
    "                     Thresholds are judged after the run and listed in the summary\n"
    "                     and the JSON report with the measured value and pass/FAIL; one\n"
    "                     without data (nothing timed, fps unknown) fails.\n"
    "  --quiet            no per-second table (the summary is still printed)\n"
    "  --help, -h         this text\n"
    "\n"
    "measures: frames and bytes received per stream and kind; latency = arrival time -\n"
    "server_time_us of the frame header (same host or synchronised clocks; the first\n"
    "frame of each subscription is counted but not timed: it is the stream's newest\n"
    "frame, possibly older than the subscription); skipped frames = gaps in seq per\n"
    "connection, channel and kind; delivered = frames per subscriber per second against\n"
    "the stream's fps parameter (read with `get`, followed through `params` broadcasts;\n"
    "--max-fps when lower), e.g. \"15.0 of 30 fps (50%)\", per stream (its most\n"
    "delivered kind: one stream step) and per kind; in set mode the set -> params round\n"
    "trip; errors (server error messages, failed connections) and disconnects\n"
    "(connections the server or network closed during the run).\n"
    "\n"
    "output: one table line per second (t, connections, frames/s, MB/s, skipped/s,\n"
    "sets/s, latency p50 p95 p99 max in ms, errors, disconnects), then a summary: a line\n"
    "per stream and under it one per kind (1 particles, 2 texture, 3 light_rig, 4 lut).\n"
    "Errors go to stderr as \"fxload: WHAT\".\n"
    "exit status: 0 run completed cleanly; 1 nothing could connect, or a failure\n"
    "(libwebsockets, writing the report, gnuplot, restoring the values in set mode);\n"
    "2 usage error, or a stream or parameter that does not exist (the run stops at the\n"
    "server's answer, no report); 3 run completed with failed connections, disconnects\n"
    "or errors (the report says which); 4 a threshold failed (also when 3 would apply).\n";

/* Opens the output files before the run so a bad path fails early. */
static int ld_open_outputs(struct ld *ld)
{
    const struct ld_opts *o = ld->o;
    FILE *f;
    ld->tout = stdout;
    if (o->json_path && !strcmp(o->json_path, "-")) {
        ld->json = stdout;
        ld->tout = stderr;
    } else if (o->json_path) {
        if (!(ld->json = fopen(o->json_path, "w"))) {
            fprintf(stderr, "fxload: cannot write %s: %s\n", o->json_path, strerror(errno));
            return LD_FAIL;
        }
        ld->json_created = 1;
    }
    if (!o->plot_path) return 0;
    if (!(f = fopen(o->plot_path, "w"))) {
        fprintf(stderr, "fxload: cannot write %s: %s\n", o->plot_path, strerror(errno));
        return LD_FAIL;
    }
    fclose(f);
    ld->plot_created = 1;
    if (system("command -v gnuplot >/dev/null 2>&1") != 0) {
        fprintf(stderr, "fxload: --plot needs gnuplot (Debian package gnuplot-nox; deploy/install-deps.sh)\n");
        return LD_FAIL;
    }
    return 0;
}

/* A run that ended without reports leaves no empty report files behind. */
static void ld_discard_outputs(struct ld *ld)
{
    if (ld->json && ld->json != stdout) fclose(ld->json);
    ld->json = NULL;
    if (ld->json_created) unlink(ld->o->json_path);
    if (ld->plot_created) unlink(ld->o->plot_path);
}

static void ld_free(struct ld *ld)
{
    if (ld->pool) fxp_pool_destroy(ld->pool);
    if (ld->json && ld->json != stdout) fclose(ld->json);
    free(ld->conns);
    free(ld->subs);
    free(ld->rows);
    free(ld->row_streams);
    for (int i = 0; i < ld->o->nsets; i++) cJSON_Delete(ld->o->sets[i].value);
    for (int i = 0; i < ld->nstreams; i++) cJSON_Delete(ld->streams[i].before);
}

/* Everything before the run: options, plan, output files. Returns 0, -1 after --help, or an
 * exit status. */
static int ld_prepare(struct ld *ld, struct ld_opts *o, int argc, char **argv)
{
    struct fxws_url u;
    char err[300];
    int r = ld_parse_args(o, argc, argv, ld_help);
    if (r) return r;
    if ((r = ld_opts_check(o)) || (r = ld_plan_streams(ld))) return r;
    for (int i = 0; i < (o->nurls ? o->nurls : 1); i++)
        if (fxws_url_parse(&u, ld_url_for(o, i), err, sizeof err)) return ld_usage(err, NULL);
    if (ld_conns_create(ld)) {
        fprintf(stderr, "fxload: out of memory\n");
        return LD_FAIL;
    }
    return ld_open_outputs(ld);
}

/* The reports of a finished run, then its exit status. */
static int ld_finish(struct ld *ld)
{
    struct ld_thresholds th;
    int r = LD_OK;
    ld_thresholds_judge(&th, ld);
    ld_summary(ld, &th);
    if (ld->json && ld_write_json(ld, &th)) r = LD_FAIL;
    if (ld->o->plot_path && ld_plot(ld)) r = LD_FAIL;
    if (r) return r;
    if (!ld->ever_open) {
        char urls[1024];
        ld_urls_text(ld->o, urls, sizeof urls);
        fprintf(stderr, "fxload: no connection could be established to %s\n", urls);
        return LD_FAIL;
    }
    if (ld->restore_failed) return LD_FAIL;
    if (th.failed) return LD_THRESHOLD;
    if (ld->tot.failed || ld->tot.disconnects || ld->tot.errors) return LD_DEGRADED;
    return LD_OK;
}

int main(int argc, char **argv)
{
    static struct ld ld; /* large (histograms): not on the stack */
    struct ld_opts o = { .url = LD_DEFAULT_URL, .connections = 10, .max_fps = -1, .rate = -1, .duration = 10,
                         .seed = 1, .max_p99_ms = -1, .min_delivered = -1, .max_skipped = -1 };
    const char *log = getenv("FXLOAD_LWS_LOG");
    int r;
    o.token = getenv("FXSTREAM_TOKEN");
    o.ca_file = getenv("FXSTREAM_CA_FILE");
    if (log) fxc_set_log(atoi(log), NULL);
    ld.o = &o;
    r = ld_prepare(&ld, &o, argc, argv);
    if (!r) r = ld_run(&ld);
    if (!r) r = ld_finish(&ld);
    else if (r > 0) ld_discard_outputs(&ld);
    ld_free(&ld);
    return r < 0 ? LD_OK : r;
}
