/* bench_page.c — the page's default: streams energy, flame and eye together on one daemon.
 *
 * Owns: a daemon of its own (trial.h) with deploy/fxstreamd.json's three streams at their
 * default parameters, one client connection subscribed to all three as the page
 * (clients/web/src/main.js) subscribes: max_fps starting at 2 steps/s, every 2 s doubled while
 * frames arrive within 50 ms of the stream's best latency, raised by 30% within 100 ms, halved
 * beyond 250 ms, up to the stream's fps. After a 12 s ramp, a window of SECONDS (the argument;
 * 20 by default, 300 for the target's five minutes) in which /metrics is read every second:
 * per stream the frames delivered per second (fxs_stream_delivered_fps of its most frequent
 * kind: energy's texture, the flame's particles) and the flame's real-time factor
 * (fxs_stream_realtime_factor, simulated seconds per wall second over the last second),
 * printed as min / median / mean of
 * the samples with the targets beside them: energy and flame each >= 29 fps delivered and the
 * flame's real-time factor >= 0.98. The eye at its defaults is static: it sends its look-up
 * table once and again only when its parameters change, so it has a frame count, no rate
 * target. The client's own count of frames per stream (its most frequent kind) is printed too.
 *
 * The client only counts frames (a browser would decode and draw them, on its own machine);
 * the daemon, its PoCL workers and this process share the cores. */
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include "fxclient.h"
#include "trial.h"

#define BP_STREAMS 3
#define BP_RAMP_S 12.0
#define BP_DEFAULT_S 20.0
#define BP_MAX_SAMPLES 4000
#define BP_FPS_TARGET 29.0
#define BP_RTF_TARGET 0.98

static const char *const bp_names[BP_STREAMS] = {"energy", "flame", "eye"};
static const int bp_animated[BP_STREAMS] = {1, 1, 0}; /* streaming at their fps: the rate target applies */

struct bp_stream {
    double max_fps, best_lat_ms, lat_sum_ms;
    int lat_n;
    uint64_t frames, frames_window[FXS_KIND_MAX + 1]; /* all, and in the window per kind */
    double fps[BP_MAX_SAMPLES];
    int nfps;
};

static struct bp_stream bp_st[BP_STREAMS];
static double bp_rtf[BP_MAX_SAMPLES];
static int bp_nrtf;

static int bp_index(const char *stream)
{
    for (int i = 0; stream && i < BP_STREAMS; i++)
        if (!strcmp(stream, bp_names[i])) return i;
    return -1;
}

/* GET /metrics into buf (NUL-terminated body and headers); 0 or -1. */
static int bp_metrics(int port, char *buf, size_t len)
{
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons((uint16_t)port)};
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    struct timeval tv = {5, 0};
    size_t got = 0;
    ssize_t r;
    if (fd < 0) return -1;
    setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    const char req[] = "GET /metrics HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n";
    if (connect(fd, (struct sockaddr *)&a, sizeof a) || send(fd, req, sizeof req - 1, 0) != (ssize_t)sizeof req - 1) {
        close(fd);
        return -1;
    }
    while (got + 1 < len && (r = recv(fd, buf + got, len - 1 - got, 0)) > 0) got += (size_t)r;
    close(fd);
    buf[got] = 0;
    return strstr(buf, " 200 ") ? 0 : -1;
}

/* The value of metric `name` for stream `stream` in a scrape, the largest over its kinds; NaN
 * when absent. */
static double bp_metric(const char *text, const char *name, const char *stream)
{
    char key[160];
    double best = NAN;
    snprintf(key, sizeof key, "%s{stream=\"%s\"", name, stream);
    for (const char *p = strstr(text, key); p; p = strstr(p + 1, key)) {
        if (p != text && p[-1] != '\n') continue;
        const char *v = strchr(p, '}');
        double x;
        if (v && sscanf(v + 1, "%lf", &x) == 1) best = isnan(best) ? x : fmax(best, x);
    }
    return best;
}

static void bp_sample(const char *text)
{
    for (int i = 0; i < BP_STREAMS; i++) {
        double f = bp_metric(text, "fxs_stream_delivered_fps", bp_names[i]);
        if (!isnan(f) && bp_st[i].nfps < BP_MAX_SAMPLES) bp_st[i].fps[bp_st[i].nfps++] = f;
    }
    double r = bp_metric(text, "fxs_stream_realtime_factor", "flame");
    if (!isnan(r) && bp_nrtf < BP_MAX_SAMPLES) bp_rtf[bp_nrtf++] = r;
}

/* The page's pacing, every 2 s: latency above the best seen decides the next max_fps. */
static void bp_pace(struct fxc_client *c)
{
    char err[256];
    for (int i = 0; i < BP_STREAMS; i++) {
        struct bp_stream *s = &bp_st[i];
        if (!s->lat_n) continue;
        double excess = s->lat_sum_ms / s->lat_n - s->best_lat_ms, cap = s->max_fps;
        s->lat_sum_ms = 0;
        s->lat_n = 0;
        if (excess > 250) cap = fmax(0.5, cap * 0.5);
        else if (excess < 100) cap = fmin(30, cap * (excess < 50 ? 2 : 1.3));
        if (fabs(cap - s->max_fps) < 0.1 * s->max_fps) continue;
        s->max_fps = round(cap * 10) / 10;
        if (fxc_subscribe(c, bp_names[i], s->max_fps, err, sizeof err) < 0)
            fprintf(stderr, "bench_page: re-subscribing %s: %s\n", bp_names[i], err);
    }
}

static int bp_cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* min / median / mean of n samples (sorted in place); 0 when n == 0. */
static void bp_summary(double *v, int n, double *mn, double *med, double *mean)
{
    double s = 0;
    qsort(v, (size_t)n, sizeof *v, bp_cmp);
    for (int i = 0; i < n; i++) s += v[i];
    *mn = n ? v[0] : 0;
    *med = n ? v[n / 2] : 0;
    *mean = n ? s / n : 0;
}

static int bp_run(int port, double seconds)
{
    char url[64], err[256];
    static char text[1 << 20];
    struct fxc_client *c;
    snprintf(url, sizeof url, "ws://127.0.0.1:%d/v1/ws", port);
    if (fxc_connect(&c, url, NULL, 10000, err, sizeof err)) {
        printf("bench_page: cannot connect: %s\n", err);
        return 1;
    }
    for (int i = 0; i < BP_STREAMS; i++) {
        bp_st[i].max_fps = 2;
        bp_st[i].best_lat_ms = INFINITY;
        if (fxc_subscribe(c, bp_names[i], bp_st[i].max_fps, err, sizeof err) < 0) {
            printf("bench_page: cannot subscribe to %s: %s\n", bp_names[i], err);
            fxc_close(c);
            return 1;
        }
    }
    double t0 = trial_now(), start = t0 + BP_RAMP_S, end = start + seconds, pace = t0 + 2, scrape = start;
    int failed = 0;
    while (!failed) {
        double now = trial_now();
        if (now >= end) {
            if (bp_metrics(port, text, sizeof text) == 0) bp_sample(text); /* the window's last second */
            break;
        }
        if (now >= pace) {
            bp_pace(c);
            pace += 2;
        }
        if (now >= scrape) {
            if (bp_metrics(port, text, sizeof text)) {
                printf("bench_page: cannot read /metrics\n");
                failed = 1;
            } else if (scrape > start) {
                bp_sample(text); /* the first scrape only starts the window's rates */
            }
            scrape += 1;
        }
        struct fxc_event ev;
        int r = fxc_poll(c, &ev, 20, err, sizeof err);
        if (r < 0) {
            printf("bench_page: connection lost: %s\n", err);
            failed = 1;
        } else if (r == 1) {
            int i = bp_index(ev.stream);
            if (ev.type == FXC_EVENT_FRAME && i >= 0) {
                double lat = ((double)ev.recv_time_us - (double)ev.header.server_time_us) * 1e-3;
                bp_st[i].best_lat_ms = fmin(bp_st[i].best_lat_ms, lat);
                bp_st[i].lat_sum_ms += lat;
                bp_st[i].lat_n++;
                bp_st[i].frames++;
                if (now >= start && ev.header.kind <= FXS_KIND_MAX) bp_st[i].frames_window[ev.header.kind]++;
            } else if (ev.type == FXC_EVENT_TEXT && ev.code) {
                printf("bench_page: %s: %s %s\n", ev.stream ? ev.stream : "server", ev.code, ev.message ? ev.message : "");
            }
            fxc_event_free(&ev);
        }
    }
    fxc_close(c);
    return failed;
}

static void bp_report(double seconds)
{
    double mn, med, mean;
    for (int i = 0; i < BP_STREAMS; i++) {
        uint64_t most = 0;
        for (int k = 0; k <= FXS_KIND_MAX; k++)
            if (bp_st[i].frames_window[k] > most) most = bp_st[i].frames_window[k];
        if (!bp_animated[i]) {
            printf("bench_page: %-6s %llu frames in all (static at its defaults: no rate target)\n", bp_names[i],
                   (unsigned long long)bp_st[i].frames);
            continue;
        }
        bp_summary(bp_st[i].fps, bp_st[i].nfps, &mn, &med, &mean);
        printf("bench_page: %-6s delivered %.1f / %.1f / %.1f fps (min / median / mean of %d one-second samples of "
               "/metrics; the client counted %.1f fps; max_fps reached %.1f): %s (target >= %.0f fps)\n",
               bp_names[i], mn, med, mean, bp_st[i].nfps, most / seconds, bp_st[i].max_fps,
               mean >= BP_FPS_TARGET ? "met" : "not met", BP_FPS_TARGET);
    }
    bp_summary(bp_rtf, bp_nrtf, &mn, &med, &mean);
    printf("bench_page: flame real-time factor %.3f / %.3f / %.3f (min / median / mean of %d samples): %s (target >= "
           "%.2f)\n", mn, med, mean, bp_nrtf, mean >= BP_RTF_TARGET ? "met" : "not met", BP_RTF_TARGET);
}

int main(int argc, char **argv)
{
    double seconds = argc > 1 ? atof(argv[1]) : BP_DEFAULT_S;
    if (argc > 2 || !(seconds >= 1 && seconds <= 3600)) {
        fprintf(stderr, "usage: bench_page [SECONDS]   (the measured window, 1 to 3600; default %.0f)\n", BP_DEFAULT_S);
        return 2;
    }
    char dir[] = "/tmp/bench_page_XXXXXX", cfg[128];
    int port;
    signal(SIGPIPE, SIG_IGN);
    fxc_set_log(0, NULL);
    if (!mkdtemp(dir)) return 1;
    snprintf(cfg, sizeof cfg, "%s/config.json", dir);
    FILE *f = fopen(cfg, "w");
    if (!f) return 1;
    fprintf(f, "{\"pause_idle\":true,\"streams\":[{\"stream\":\"energy\",\"effect\":\"energy_wave\",\"params\":{}},"
               "{\"stream\":\"flame\",\"effect\":\"flame\",\"params\":{}},"
               "{\"stream\":\"eye\",\"effect\":\"compound_eye\",\"params\":{}}]}\n");
    fclose(f);
    pid_t pid = trial_daemon(cfg, NULL, &port);
    if (pid < 0) {
        printf("bench_page: cannot start build/fxstreamd (run make all)\n");
        return 1;
    }
    printf("bench_page: streams energy, flame and eye at their defaults, subscribed together as the page does; "
           "%.0f s ramp, then %.0f s measured\n", BP_RAMP_S, seconds);
    int rc = bp_run(port, seconds);
    trial_stop(pid);
    unlink(cfg);
    rmdir(dir);
    if (!rc) bp_report(seconds);
    return rc;
}
