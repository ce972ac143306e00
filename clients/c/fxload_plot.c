/* fxload_plot.c — fxload's --plot: writes the per-second rows and the gnuplot commands
 * into a gnuplot process (popen), which draws FILE.svg or FILE.png. gnuplot is a separate
 * program (Debian gnuplot-nox); fxload.c checks that it is there before the run.
 *
 * Panels, time on x: latency percentiles with the open connections on a second axis (so a
 * latency rise can be read against the load); then one line per stream: frames/s (with the
 * total MB/s on a second axis) and skipped/s on an axis of its own, where a few skipped
 * frames are not flattened by thousands of frames/s (subscribe mode), or sets/s (set mode). */
#include "fxload_plot.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <sys/wait.h>

#include "fxload_opts.h"
#include "fxload_state.h"

/* Columns of the data block: the row's totals, then LD_GP_PER_STREAM per stream. */
enum {
    LD_GP_T = 1, LD_GP_CONNS, LD_GP_FPS, LD_GP_MBPS, LD_GP_SETS, LD_GP_P50, LD_GP_P95, LD_GP_P99, LD_GP_MAX,
    LD_GP_SKIPPED, LD_GP_STREAMS /* first per-stream column */
};
enum { LD_GP_S_FPS, LD_GP_S_SKIPPED, LD_GP_S_SETS, LD_GP_PER_STREAM };

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

/* The value of column col (1-based, as gnuplot counts) of row i. */
static double ld_gp_value(const struct ld *ld, int i, int col)
{
    const struct ld_row *r = &ld->rows[i];
    double dt = r->dt > 0 ? r->dt : 1;
    const struct ld_row_stream *rs;
    switch (col) {
    case LD_GP_T: return r->t;
    case LD_GP_CONNS: return r->conns;
    case LD_GP_FPS: return (double)r->d.frames / dt;
    case LD_GP_MBPS: return (double)r->d.bytes / dt / 1e6;
    case LD_GP_SETS: return (double)r->d.sets_ok / dt;
    case LD_GP_P50: return r->p50;
    case LD_GP_P95: return r->p95;
    case LD_GP_P99: return r->p99;
    case LD_GP_MAX: return r->max;
    case LD_GP_SKIPPED: return (double)r->d.skipped / dt;
    default: break;
    }
    rs = &ld->row_streams[i * ld->nstreams + (col - LD_GP_STREAMS) / LD_GP_PER_STREAM];
    switch ((col - LD_GP_STREAMS) % LD_GP_PER_STREAM) {
    case LD_GP_S_FPS: return (double)rs->frames / dt;
    case LD_GP_S_SKIPPED: return (double)rs->skipped / dt;
    default: return (double)rs->sets / dt;
    }
}

static int ld_gp_columns(const struct ld *ld) { return LD_GP_STREAMS - 1 + ld->nstreams * LD_GP_PER_STREAM; }

static void ld_gp_data(FILE *gp, const struct ld *ld)
{
    fputs("$d << EOD\n", gp);
    for (int i = 0; i < ld->nrows; i++)
        for (int col = 1; col <= ld_gp_columns(ld); col++)
            fprintf(gp, "%.7g%c", ld_gp_value(ld, i, col), col < ld_gp_columns(ld) ? ' ' : '\n');
    fputs("EOD\n", gp);
}

/* The top of an axis showing columns from..to, step apart: their maximum and a margin, 1
 * when they are all 0 (gnuplot would warn about an empty range). */
static double ld_gp_top(const struct ld *ld, int from, int to, int step)
{
    double max = 0;
    for (int i = 0; i < ld->nrows; i++)
        for (int col = from; col <= to; col += step) {
            double v = ld_gp_value(ld, i, col);
            if (v > max) max = v;
        }
    return max > 0 ? max * 1.08 : 1;
}

/* The top of an axis showing per-stream column col of every stream. */
static double ld_gp_stream_top(const struct ld *ld, int col)
{
    return ld_gp_top(ld, LD_GP_STREAMS + col, ld_gp_columns(ld), LD_GP_PER_STREAM);
}

static void ld_gp_setup(FILE *gp, const struct ld *ld)
{
    const char *path = ld->o->plot_path;
    int height = ld->o->mode == LD_SET ? 760 : 1080;
    if (!strcmp(path + strlen(path) - 4, ".png"))
        fprintf(gp, "set terminal pngcairo size 1000,%d noenhanced font 'sans,10'\n", height);
    else
        fprintf(gp, "set terminal svg size 1000,%d dynamic noenhanced font 'sans,11' background '#ffffff'\n", height);
    fputs("set output ", gp);
    ld_gp_quoted(gp, path);
    fputc('\n', gp);
}

/* A panel's axes: y from 0 to ytop; y2 from 0 to y2top when y2label is not NULL. */
static void ld_gp_axes(FILE *gp, const char *ylabel, double ytop, const char *y2label, double y2top)
{
    fputs("set ylabel ", gp);
    ld_gp_quoted(gp, ylabel);
    fprintf(gp, "\nset yrange [0:%.6g]\n", ytop);
    if (!y2label) {
        fputs("unset y2label\nunset y2tics\nset ytics mirror\n", gp);
        return;
    }
    fputs("set y2label ", gp);
    ld_gp_quoted(gp, y2label);
    fprintf(gp, "\nset y2tics\nset ytics nomirror\nset y2range [0:%.6g]\n", y2top);
}

/* Latency percentiles, and the open connections on y2. */
static void ld_gp_latency(FILE *gp, const struct ld *ld)
{
    ld_gp_axes(gp, ld->o->mode == LD_SET ? "set round trip latency (ms)" : "frame latency (ms)",
               ld_gp_top(ld, LD_GP_P50, LD_GP_MAX, 1), "connections", ld_gp_top(ld, LD_GP_CONNS, LD_GP_CONNS, 1));
    fprintf(gp,
            "plot $d using 1:%d with linespoints title 'p50', $d using 1:%d with linespoints title 'p95', "
            "$d using 1:%d with linespoints title 'p99', $d using 1:%d with linespoints title 'max', "
            "$d using 1:%d with steps lw 2 dt 2 lc rgb '#606060' title 'connections' axes x1y2\n",
            LD_GP_P50, LD_GP_P95, LD_GP_P99, LD_GP_MAX, LD_GP_CONNS);
}

/* One line per stream of per-stream column `col`; `extra` (may be NULL) adds plot items. */
static void ld_gp_per_stream(FILE *gp, const struct ld *ld, int col, const char *extra)
{
    fputs("plot ", gp);
    for (int s = 0; s < ld->nstreams; s++) {
        fprintf(gp, "%s$d using 1:%d with linespoints title ", s ? ", " : "",
                LD_GP_STREAMS + s * LD_GP_PER_STREAM + col);
        ld_gp_quoted(gp, ld->streams[s].name);
    }
    fprintf(gp, "%s%s\n", extra ? ", " : "", extra ? extra : "");
}

static void ld_gp_subscribe(FILE *gp, const struct ld *ld)
{
    char mbps[128];
    snprintf(mbps, sizeof mbps, "$d using 1:%d with lines dt 3 lc rgb '#404040' title 'MB/s (all)' axes x1y2",
             LD_GP_MBPS);
    ld_gp_axes(gp, "frames/s", ld_gp_stream_top(ld, LD_GP_S_FPS), "MB/s", ld_gp_top(ld, LD_GP_MBPS, LD_GP_MBPS, 1));
    ld_gp_per_stream(gp, ld, LD_GP_S_FPS, mbps);
    ld_gp_axes(gp, "skipped/s", ld_gp_stream_top(ld, LD_GP_S_SKIPPED), NULL, 0);
    ld_gp_per_stream(gp, ld, LD_GP_S_SKIPPED, NULL);
}

static void ld_gp_plots(FILE *gp, const struct ld *ld)
{
    const struct ld_opts *o = ld->o;
    char title[1280], urls[1024];
    ld_urls_text(o, urls, sizeof urls);
    snprintf(title, sizeof title, "fxload %s: %ld connections to %s, %.1f s", o->mode == LD_SET ? "set" : "subscribe",
             o->connections, urls, ld->elapsed);
    fprintf(gp, "set multiplot layout %d,1 title ", o->mode == LD_SET ? 2 : 3);
    ld_gp_quoted(gp, title);
    fputs("\nset grid\nset key top left\nset xlabel 'time (s)'\n", gp);
    ld_gp_latency(gp, ld);
    if (o->mode == LD_SET) {
        ld_gp_axes(gp, "sets/s", ld_gp_stream_top(ld, LD_GP_S_SETS), NULL, 0);
        ld_gp_per_stream(gp, ld, LD_GP_S_SETS, NULL);
    } else {
        ld_gp_subscribe(gp, ld);
    }
    fputs("unset multiplot\nset output\n", gp);
}

int ld_plot(const struct ld *ld)
{
    const char *path = ld->o->plot_path;
    int st;
    FILE *gp = popen("gnuplot", "w");
    if (!gp) {
        fprintf(stderr, "fxload: cannot run gnuplot: %s\n", strerror(errno));
        return -1;
    }
    ld_gp_setup(gp, ld);
    ld_gp_data(gp, ld);
    ld_gp_plots(gp, ld);
    st = pclose(gp);
    if (st == -1 || !WIFEXITED(st) || WEXITSTATUS(st) != 0) {
        fprintf(stderr, "fxload: gnuplot failed (%s %d) writing %s; is it installed (Debian gnuplot-nox)?\n",
                st != -1 && WIFEXITED(st) ? "exit status" : "status", st != -1 && WIFEXITED(st) ? WEXITSTATUS(st) : st,
                path);
        return -1;
    }
    return 0;
}
