/* bench_load.c — fan-out capacity of fxstreamd, measured with libfxclient's pool (fxload's engine).
 *
 * Owns: the config build/fxstreamd is started with (trial.h starts it), which defines two
 * dedicated streams (a ~20k-particle flame and a 256x256 texture without its light rig,
 * both at 30 fps) and lifts max_connections; a raw loopback TCP throughput measurement in the same run
 * (one sender thread, one receiver); and, per stream, an upward search for the largest
 * number of subscribers that still receive >= 95% of the frames the stream produced
 * with p99 latency <= 100 ms (the trial and the search: trial.h, shared with bench_cluster).
 * One line per figure on stdout. Total time bounded (~2.5 min).
 *
 * The client shares the machine with the daemon, so every figure is a property of
 * "daemon + load generator on the same cores", not of the daemon alone. */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/resource.h>
#include <sys/socket.h>

#include <libwebsockets.h>

#include "trial.h"

#define BL_BUDGET_S 150.0      /* whole benchmark */
#define BL_STREAM_BUDGET_S 70.0
#define BL_DRAIN_N 3072 /* send capacity: 3072 x 30 fps x ~82 kB offers ~7.6 GB/s, above raw loopback (4-6 GB/s) */

static double bl_t0;

/* ---- send capacity: subscribers that only drain their sockets -------------------- */

/* A plain TCP connection that completes the WebSocket handshake and subscribes to
 * `stream`, then only reads (no WebSocket parsing: what is measured is the daemon's
 * sending, not a client's parsing). Returns the fd, or -1. */
static int bl_drain_open(int port, const char *stream)
{
    struct sockaddr_in a = { .sin_family = AF_INET, .sin_port = htons((uint16_t)port) };
    char req[512], head[1024], msg[128];
    uint8_t frame[160];
    size_t got = 0;
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    struct timeval tv = { 5, 0 };
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (fd < 0) return -1;
    setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    int n = snprintf(req, sizeof req, "GET /v1/ws HTTP/1.1\r\nHost: 127.0.0.1:%d\r\nUpgrade: websocket\r\n"
                     "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                     "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Protocol: fxstream.v1\r\n\r\n", port);
    if (connect(fd, (struct sockaddr *)&a, sizeof a) || send(fd, req, (size_t)n, 0) != n) goto fail;
    while (got < sizeof head - 1 && !(got >= 4 && !memcmp(head + got - 4, "\r\n\r\n", 4)))
        if (recv(fd, head + got++, 1, 0) != 1) goto fail; /* byte by byte: nothing after the headers */
    head[got] = 0;
    if (!strstr(head, " 101 ")) goto fail;
    n = snprintf(msg, sizeof msg, "{\"op\":\"subscribe\",\"stream\":\"%s\"}", stream);
    frame[0] = 0x81; /* FIN, text; masked with a zero key (the mask is mandatory, its value is not) */
    frame[1] = (uint8_t)(0x80 | n);
    memset(frame + 2, 0, 4);
    memcpy(frame + 6, msg, (size_t)n);
    if (send(fd, frame, (size_t)n + 6, 0) != n + 6) goto fail;
    return fd;
fail:
    close(fd);
    return -1;
}

/* MB/s the daemon sends to n subscribers of stream that read as fast as they can. */
static double bl_drain(int port, const char *stream, int n, double seconds, int *opened)
{
    struct pollfd *p = calloc((size_t)n, sizeof *p);
    static uint8_t buf[1 << 18];
    uint64_t bytes = 0;
    *opened = 0;
    for (int i = 0; p && i < n; i++)
        if ((p[*opened].fd = bl_drain_open(port, stream)) >= 0) p[(*opened)++].events = POLLIN;
    double start = trial_now() + TRIAL_WARMUP_S, end = start + seconds;
    for (double now = trial_now(); now < end; now = trial_now()) {
        if (poll(p, (nfds_t)*opened, 100) <= 0) continue;
        for (int i = 0; i < *opened; i++) {
            if (!(p[i].revents & POLLIN)) continue;
            ssize_t r = recv(p[i].fd, buf, sizeof buf, MSG_DONTWAIT);
            if (r > 0 && now >= start) bytes += (uint64_t)r;
        }
    }
    for (int i = 0; i < *opened; i++) close(p[i].fd);
    free(p);
    return (double)bytes / seconds / 1e6;
}

/* ---- raw loopback TCP ---------------------------------------------------------- */

struct bl_raw {
    struct sockaddr_in addr;
    double seconds;
};

static void *bl_raw_writer(void *arg)
{
    struct bl_raw *r = arg;
    static char buf[65536];
    int s = socket(AF_INET, SOCK_STREAM, 0);
    double end;
    if (s < 0 || connect(s, (struct sockaddr *)&r->addr, sizeof r->addr)) {
        if (s >= 0) close(s);
        return NULL;
    }
    end = trial_now() + r->seconds;
    while (trial_now() < end)
        if (write(s, buf, sizeof buf) < 0) break;
    close(s);
    return NULL;
}

/* MB/s through one loopback TCP connection, one writer thread, one reader. */
static double bl_raw_loopback(double seconds)
{
    struct bl_raw r;
    socklen_t len = sizeof r.addr;
    pthread_t th;
    static char buf[262144];
    uint64_t total = 0;
    double t0, t1;
    ssize_t n;
    int ls = socket(AF_INET, SOCK_STREAM, 0), cs;
    memset(&r, 0, sizeof r);
    r.addr.sin_family = AF_INET;
    r.addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    r.seconds = seconds;
    if (ls < 0 || bind(ls, (struct sockaddr *)&r.addr, sizeof r.addr) || listen(ls, 1) ||
        getsockname(ls, (struct sockaddr *)&r.addr, &len))
        return 0;
    if (pthread_create(&th, NULL, bl_raw_writer, &r)) return 0;
    cs = accept(ls, NULL, NULL);
    t0 = trial_now();
    while (cs >= 0 && (n = read(cs, buf, sizeof buf)) > 0) total += (uint64_t)n;
    t1 = trial_now();
    pthread_join(th, NULL);
    if (cs >= 0) close(cs);
    close(ls);
    return t1 > t0 ? (double)total / (t1 - t0) / 1e6 : 0;
}

static void bl_report_stream(const char *what, const struct trial_result *b, const struct trial_result *f)
{
    if (b->n)
        printf("bench_load: %s: max subscribers with >= 95%% of frames and p99 <= 100 ms: %d "
               "(%.1f%% delivered, p50 %.1f ms, p99 %.1f ms, %.1f MB/s, stream at %.1f fps, %" PRIu64 " B/frame)",
               what, b->n, 100 * b->ratio, b->p50, b->p99, b->mbps, b->fps_produced, b->frame_bytes);
    else
        printf("bench_load: %s: max subscribers with >= 95%% of frames and p99 <= 100 ms: none passed", what);
    if (f->n)
        printf("; %d failed (%.1f%% delivered, p99 %.1f ms)\n", f->n, 100 * f->ratio, f->p99);
    else
        printf("\n");
}

/* Server CPU per delivered subscriber-frame: all of it (the engine's stepping and
 * encoding included) at the largest passing load, and the marginal cost between the
 * smallest and the largest passing loads (what one more subscriber-frame costs). */
static void bl_report_cpu(const char *what, const struct trial_result *a, const struct trial_result *b)
{
    if (!b->frames) return;
    printf("bench_load: server CPU per subscriber-frame, %s: %.0f us all-in at %d subscribers", what,
           1e6 * b->cpu_s / (double)b->frames, b->n);
    if (a->n && b->n > a->n && b->frames > a->frames)
        printf("; marginal %.0f us (%d -> %d subscribers)\n", 1e6 * (b->cpu_s - a->cpu_s) / (double)(b->frames - a->frames),
               a->n, b->n);
    else
        printf("\n");
}

/* The searches' figures: subscribers per stream, CPU per subscriber-frame, best send rate. */
static void bl_report_searches(const struct trial_search *fl, const struct trial_search *tx, double raw)
{
    const struct trial_result *fastest = tx->fastest.mbps > fl->fastest.mbps ? &tx->fastest : &fl->fastest;
    char what[128];
    snprintf(what, sizeof what, "flame %" PRIu64 " particles at 30 fps",
             fl->best.count ? fl->best.count : fl->fail.count);
    bl_report_stream(what, &fl->best, &fl->fail);
    bl_report_stream("texture 256x256 (EXR) at 30 fps", &tx->best, &tx->fail);
    bl_report_cpu("flame", &fl->first, &fl->best);
    bl_report_cpu("texture", &tx->first, &tx->best);
    printf("bench_load: server aggregate send rate at the best passing trial (%s, %d subscribers): %.1f MB/s = %.1f%% "
           "of raw loopback\n",
           fastest->stream ? fastest->stream : "none", fastest->n, fastest->mbps, raw > 0 ? 100 * fastest->mbps / raw : 0);
}

/* Both searches, after a 1-subscriber trial that lets the flame develop to its ~20k particles. */
static void bl_searches(struct trial_target *tg, struct trial_search *fl, struct trial_search *tx)
{
    struct trial_result warm;
    tg->stream = "bench_flame";
    trial_run(tg, 1, &warm);
    trial_search(tg, fmin(trial_now() + BL_STREAM_BUDGET_S, bl_t0 + BL_BUDGET_S), fl);
    tg->stream = "bench_tex";
    trial_search(tg, fmin(trial_now() + BL_STREAM_BUDGET_S, bl_t0 + BL_BUDGET_S), tx);
}

int main(void)
{
    char dir[] = "/tmp/bench_load_XXXXXX", cfg[128], url[64];
    struct rlimit rl;
    struct trial_search fl, tx;
    struct trial_target tg = { .urls = { url }, .nurls = 1, .npids = 1 };
    int port;
    double raw;
    FILE *f;
    bl_t0 = trial_now();
    lws_set_log_level(0, NULL);
    signal(SIGPIPE, SIG_IGN);
    if (!getrlimit(RLIMIT_NOFILE, &rl) && rl.rlim_cur < rl.rlim_max) {
        rl.rlim_cur = rl.rlim_max; /* inherited by the daemon too */
        setrlimit(RLIMIT_NOFILE, &rl);
    }
    if (!mkdtemp(dir)) return 1;
    snprintf(cfg, sizeof cfg, "%s/config.json", dir);
    if (!(f = fopen(cfg, "w"))) return 1;
    fprintf(f, "{\"limits\":{\"max_connections\":%d},\"pause_idle\":true,\"streams\":["
               /* Table 3.1's h and no base plate: the same ~20k-particle flame as before the finer default h */
               "{\"stream\":\"bench_flame\",\"effect\":\"flame\",\"params\":{\"sources\":[{\"radius\":0.08}],"
               "\"h\":0.01125,\"obstacles\":[],\"fps\":30}},"
               "{\"stream\":\"bench_tex\",\"effect\":\"energy_wave\",\"params\":{\"width\":256,\"height\":256,\"fps\":30,"
               "\"light_rig\":false,"
               "\"curves\":[],\"tori\":[{\"center\":[0,0,18],\"axis\":[0,0,1],\"R\":6,\"coef\":5}]}}]}\n",
            TRIAL_MAX_N + 100);
    fclose(f);
    if ((tg.pids[0] = trial_daemon(cfg, NULL, &port)) < 0) {
        printf("bench_load: cannot start build/fxstreamd (run make all)\n");
        return 1;
    }
    snprintf(url, sizeof url, "ws://127.0.0.1:%d/v1/ws", port);
    raw = bl_raw_loopback(1.0);
    /* BENCH_LOAD_ONLY=capacity: raw loopback and send capacity only (~10 s), for experiments */
    const char *only = getenv("BENCH_LOAD_ONLY");
    int searches = !only || strcmp(only, "capacity") != 0;
    if (searches) bl_searches(&tg, &fl, &tx);
    int drained;
    double cap = bl_drain(port, "bench_tex", BL_DRAIN_N, TRIAL_WINDOW_S, &drained);
    trial_stop(tg.pids[0]);
    unlink(cfg);
    rmdir(dir);

    printf("bench_load: raw loopback TCP, 1 writer + 1 reader thread: %.0f MB/s\n", raw);
    if (searches) bl_report_searches(&fl, &tx, raw);
    printf("bench_load: server send capacity, %d subscribers of bench_tex that only drain their sockets: %.0f MB/s = "
           "%.1f%% of raw loopback (target >= 50%%)\n", drained, cap, raw > 0 ? 100 * cap / raw : 0);
    printf("bench_load: total %.0f s on %ld CPUs (daemon, its engine and the load generator share them)\n", trial_now() - bl_t0,
           sysconf(_SC_NPROCESSORS_ONLN));
    return 0;
}
