/* fxload_plot.c — fxload's --plot: writes the per-second rows and the gnuplot commands
 * into a gnuplot process (popen), which draws latency and throughput over time into
 * FILE.svg or FILE.png. gnuplot is a separate program (Debian gnuplot-nox); fxload.c checks
 * that it is there before the run. */
#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <sys/wait.h>

#include "fxload.h"

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

static void ld_gp_data(FILE *gp, const struct ld *ld)
{
    fputs("$d << EOD\n", gp);
    for (int i = 0; i < ld->nrows; i++) {
        const struct ld_row *r = &ld->rows[i];
        double dt = r->dt > 0 ? r->dt : 1;
        fprintf(gp, "%.3f %d %.3f %.6f %.3f %.3f %.3f %.3f %.3f %.3f\n", r->t, r->conns, (double)r->d.frames / dt,
                (double)r->d.bytes / dt / 1e6, (double)r->d.sets_ok / dt, r->p50, r->p95, r->p99, r->max,
                (double)r->d.skipped / dt);
    }
    fputs("EOD\n", gp);
}

static void ld_gp_setup(FILE *gp, const struct ld *ld)
{
    const char *path = ld->o->plot_path;
    if (!strcmp(path + strlen(path) - 4, ".png"))
        fputs("set terminal pngcairo size 1000,760 noenhanced font 'sans,10'\n", gp);
    else
        fputs("set terminal svg size 1000,760 dynamic noenhanced font 'sans,11' background '#ffffff'\n", gp);
    fputs("set output ", gp);
    ld_gp_quoted(gp, path);
    fputc('\n', gp);
}

static void ld_gp_plots(FILE *gp, const struct ld *ld)
{
    const struct ld_opts *o = ld->o;
    int set = o->mode == LD_SET;
    char title[512];
    snprintf(title, sizeof title, "fxload %s: %ld connections to %s, %.1f s", o->mode == LD_SET ? "set" : "subscribe",
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
