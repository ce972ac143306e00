/* bench_load.c — fan-out capacity of fxstreamd, measured with libfxclient's pool (fxload's engine).
 *
 * Owns: starting build/fxstreamd on a free loopback port with a config that defines two
 * dedicated streams (a ~20k-particle flame and a 256x256 texture without its light rig,
 * both at 30 fps) and lifts max_connections; a raw loopback TCP throughput measurement in the same run
 * (one sender thread, one receiver); and, per stream, an upward search for the largest
 * number of subscribers that still receive >= 95% of the frames the stream produced
 * with p99 latency <= 100 ms. A trial opens N connections (ramped), waits until all are
 * subscribed, warms up 1 s and measures 3 s; the daemon's CPU time comes from
 * /proc/PID/stat. One line per figure on stdout. Total time bounded (~2.5 min).
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
#include <sys/wait.h>

#include <libwebsockets.h>

#include "fxpool.h"
#include "fxws.h"

#define BL_BUDGET_S 150.0      /* whole benchmark */
#define BL_STREAM_BUDGET_S 70.0
#define BL_MAX_N 10000
#define BL_WARMUP_S 1.0
#define BL_WINDOW_S 3.0
#define BL_RATIO 0.95
#define BL_P99_MS 100.0
#define BL_DRAIN_N 3072 /* send capacity: 3072 x 30 fps x ~82 kB offers ~7.6 GB/s, above raw loopback (4-6 GB/s) */

struct bl_conn {
    int subscribed;
    uint64_t last_seq;
};

struct bl_trial {
    const char *stream;
    int n;
    struct bl_conn *conns;
    int subscribed, closed_early, errors;
    int measuring;               /* 1: in the window; 2: grace period after it */
    uint64_t frames, bytes, max_seq, max_seq_start, max_seq_end;
    uint64_t payload_bytes_last, count_last;
    struct fxp_hist lat;
};

struct bl_result {
    const char *stream;
    int n, ok, all_subscribed;
    double ratio, p50, p99, mbps, cpu_s, fps_produced;
    uint64_t frames;
    uint64_t frame_bytes, count;
};

static double bl_now(void) { return (double)fxws_now_us(CLOCK_MONOTONIC) / 1e6; }
static double bl_t0;

/* ---- daemon ------------------------------------------------------------------- */

static pid_t bl_daemon(const char *cfg, int *port)
{
    int fd[2];
    pid_t pid;
    char line[512];
    FILE *f;
    if (pipe(fd)) return -1;
    pid = fork();
    if (pid < 0) return -1;
    if (pid == 0) {
        dup2(fd[1], 1);
        close(fd[0]);
        close(fd[1]);
        execl("build/fxstreamd", "fxstreamd", "--config", cfg, "--port", "0", "--log-level", "error", (char *)NULL);
        _exit(127);
    }
    close(fd[1]);
    f = fdopen(fd[0], "r");
    *port = 0;
    while (f && fgets(line, sizeof line, f)) {
        char *p = strstr(line, "listening on http://");
        if (p && (p = strchr(p + 20, ':'))) {
            *port = atoi(p + 1);
            break;
        }
    }
    /* keep the pipe's read end open (the daemon may print more); it is closed at exit */
    return *port ? pid : -1;
}

static double bl_proc_cpu(pid_t pid)
{
    char path[64], buf[1024], *p;
    unsigned long ut = 0, st = 0;
    FILE *f;
    snprintf(path, sizeof path, "/proc/%d/stat", (int)pid);
    if (!(f = fopen(path, "r"))) return 0;
    if (!fgets(buf, sizeof buf, f)) buf[0] = 0;
    fclose(f);
    if (!(p = strrchr(buf, ')'))) return 0;
    /* fields after ")": state(3) ... utime(14) stime(15) */
    if (sscanf(p + 2, "%*c %*d %*d %*d %*d %*d %*u %*u %*u %*u %*u %lu %lu", &ut, &st) != 2) return 0;
    return (double)(ut + st) / (double)sysconf(_SC_CLK_TCK);
}

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
    double start = bl_now() + BL_WARMUP_S, end = start + seconds;
    for (double now = bl_now(); now < end; now = bl_now()) {
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
    end = bl_now() + r->seconds;
    while (bl_now() < end)
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
    t0 = bl_now();
    while (cs >= 0 && (n = read(cs, buf, sizeof buf)) > 0) total += (uint64_t)n;
    t1 = bl_now();
    pthread_join(th, NULL);
    if (cs >= 0) close(cs);
    close(ls);
    return t1 > t0 ? (double)total / (t1 - t0) / 1e6 : 0;
}

/* ---- one trial ------------------------------------------------------------------- */

/* The pool's callbacks get the conn's user pointer; the trial is reached through a
 * file-scope pointer (one trial at a time). */
static struct bl_trial *bl_cur;

static void bl_open(struct fxp_conn *c, const cJSON *hello, void *user)
{
    char req[160];
    (void)hello;
    (void)user;
    snprintf(req, sizeof req, "{\"op\":\"subscribe\",\"id\":1,\"stream\":\"%s\"}", bl_cur->stream);
    if (fxp_send_text(c, req, strlen(req))) bl_cur->errors++;
}

static void bl_text(struct fxp_conn *c, const cJSON *m, uint64_t now, void *user)
{
    struct bl_conn *bc = user;
    const char *op = cJSON_GetObjectItemCaseSensitive(m, "op")->valuestring;
    (void)c;
    (void)now;
    if (!strcmp(op, "subscribed") && !bc->subscribed) {
        bc->subscribed = 1;
        bl_cur->subscribed++;
    } else if (!strcmp(op, "error")) {
        bl_cur->errors++;
    }
}

static void bl_frame(struct fxp_conn *c, const struct fxs_header *h, const uint8_t *payload, size_t bytes,
                     uint64_t now, void *user)
{
    struct bl_conn *bc = user;
    struct bl_trial *t = bl_cur;
    (void)c;
    (void)payload;
    if (h->seq > t->max_seq) t->max_seq = h->seq;
    t->payload_bytes_last = bytes;
    t->count_last = h->count_or_width;
    if (t->measuring == 1) {
        t->bytes += bytes;
        if (bc->last_seq) fxp_hist_add(&t->lat, (int64_t)now - (int64_t)h->server_time_us);
    }
    /* delivery: frames produced inside the window, wherever they arrive (grace included) */
    if (t->measuring && h->seq > t->max_seq_start && (t->measuring == 1 || h->seq <= t->max_seq_end)) t->frames++;
    bc->last_seq = h->seq;
}

static void bl_close(struct fxp_conn *c, const struct fxp_close_info *info, void *user)
{
    (void)c;
    (void)user;
    if (!info->by_client) bl_cur->closed_early++;
}

static void bl_service_until(struct fxp_pool *p, double until)
{
    while (bl_now() < until) fxp_service(p, 5);
}

static int bl_trial(const char *url, pid_t dpid, const char *stream, int n, struct bl_result *res)
{
    static struct bl_trial t;
    struct fxp_callbacks cb = { bl_open, bl_text, bl_frame, bl_close };
    struct fxp_options po = { .max_connections = n };
    struct fxp_pool *pool;
    char err[256];
    double start, ramp = fmax(0.2, n / 3000.0), deadline, w0, w1, cpu0, cpu1;
    int started = 0;
    memset(&t, 0, sizeof t);
    memset(res, 0, sizeof *res);
    t.stream = stream;
    t.n = n;
    bl_cur = &t;
    if (!(t.conns = calloc((size_t)n, sizeof *t.conns))) return -1;
    if (fxp_pool_create(&pool, &cb, &po, err, sizeof err)) {
        fprintf(stderr, "bench_load: %s\n", err);
        free(t.conns);
        return -1;
    }
    start = bl_now();
    deadline = start + ramp + 10;
    while ((t.subscribed + t.closed_early < n) && bl_now() < deadline) {
        double el = bl_now() - start;
        while (started < n && el >= ramp * started / n) {
            if (fxp_connect(pool, url, &t.conns[started], NULL, err, sizeof err)) t.closed_early++;
            started++;
        }
        fxp_service(pool, 2);
    }
    res->n = n;
    res->stream = stream;
    res->all_subscribed = t.subscribed == n;
    bl_service_until(pool, bl_now() + BL_WARMUP_S);
    t.max_seq_start = t.max_seq;
    fxp_hist_reset(&t.lat);
    cpu0 = bl_proc_cpu(dpid);
    w0 = bl_now();
    t.measuring = 1;
    bl_service_until(pool, w0 + BL_WINDOW_S);
    w1 = bl_now();
    cpu1 = bl_proc_cpu(dpid);
    t.max_seq_end = t.max_seq;
    t.measuring = 2;
    bl_service_until(pool, w1 + 0.5);
    t.measuring = 0;
    {
        uint64_t produced = t.max_seq_end > t.max_seq_start ? t.max_seq_end - t.max_seq_start : 0;
        double expected = (double)produced * t.subscribed;
        res->ratio = expected > 0 ? (double)t.frames / expected : 0;
        res->p50 = fxp_hist_quantile(&t.lat, 0.5) / 1000;
        res->p99 = fxp_hist_quantile(&t.lat, 0.99) / 1000;
        res->mbps = (double)t.bytes / (w1 - w0) / 1e6;
        res->cpu_s = cpu1 - cpu0;
        res->frames = t.frames;
        res->fps_produced = (double)produced / (w1 - w0);
        res->frame_bytes = t.payload_bytes_last;
        res->count = t.count_last;
        res->ok = res->all_subscribed && !t.closed_early && res->ratio >= BL_RATIO && res->p99 <= BL_P99_MS &&
                  t.lat.count > 0;
    }
    fxp_pool_destroy(pool); /* drops every connection at once */
    free(t.conns);
    bl_cur = NULL;
    fprintf(stderr, "  %s n=%d: %s subscribed %d, ratio %.3f, p50 %.1f ms, p99 %.1f ms, %.1f MB/s, produced %.1f fps, cpu %.2f s\n",
            stream, n, res->ok ? "PASS" : "fail", t.subscribed, res->ratio, res->p50, res->p99, res->mbps,
            res->fps_produced, res->cpu_s);
    usleep(300000); /* let the daemon drop the closed sessions */
    return 0;
}

/* Upward search: doubling from 25 while trials pass, then bisection. */
static void bl_search(const char *url, pid_t dpid, const char *stream, struct bl_result *best, struct bl_result *fail,
                      struct bl_result *fastest, struct bl_result *first)
{
    double t_end = fmin(bl_now() + BL_STREAM_BUDGET_S, bl_t0 + BL_BUDGET_S);
    int lo = 0, hi = 0, n = 25;
    struct bl_result r;
    memset(best, 0, sizeof *best);
    memset(fail, 0, sizeof *fail);
    while (n <= BL_MAX_N && bl_now() < t_end) {
        if (bl_trial(url, dpid, stream, n, &r)) break;
        if (r.ok && r.mbps > fastest->mbps) *fastest = r;
        if (r.ok) {
            if (!first->n) *first = r;
            *best = r;
            lo = n;
            if (n == BL_MAX_N) break;
            n = n * 2 > BL_MAX_N ? BL_MAX_N : n * 2;
        } else {
            *fail = r;
            hi = n;
            break;
        }
    }
    while (hi && hi - lo > (lo > 0 ? lo / 8 : 3) && bl_now() + 6 < t_end) {
        n = lo ? (lo + hi) / 2 : hi / 2;
        if (n < 1 || n == lo) break;
        if (bl_trial(url, dpid, stream, n, &r)) break;
        if (r.ok && r.mbps > fastest->mbps) *fastest = r;
        if (r.ok) {
            if (!first->n || r.n < first->n) *first = r;
            *best = r;
            lo = n;
        }
        else { *fail = r; hi = n; }
    }
}

static void bl_report_stream(const char *what, const struct bl_result *b, const struct bl_result *f)
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
static void bl_report_cpu(const char *what, const struct bl_result *a, const struct bl_result *b)
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
static void bl_report_searches(const struct bl_result *fb, const struct bl_result *ff, const struct bl_result *tb,
                               const struct bl_result *tf, const struct bl_result *f1, const struct bl_result *t1,
                               const struct bl_result *fastest, double raw)
{
    char what[128];
    snprintf(what, sizeof what, "flame %" PRIu64 " particles at 30 fps", fb->count ? fb->count : ff->count);
    bl_report_stream(what, fb, ff);
    bl_report_stream("texture 256x256 (EXR) at 30 fps", tb, tf);
    bl_report_cpu("flame", f1, fb);
    bl_report_cpu("texture", t1, tb);
    printf("bench_load: server aggregate send rate at the best passing trial (%s, %d subscribers): %.1f MB/s = %.1f%% "
           "of raw loopback\n",
           fastest->stream ? fastest->stream : "none", fastest->n, fastest->mbps, raw > 0 ? 100 * fastest->mbps / raw : 0);
}

int main(void)
{
    char dir[] = "/tmp/bench_load_XXXXXX", cfg[128], url[64];
    struct rlimit rl;
    struct bl_result fb, ff, tb, tf, fastest, f1, t1;
    pid_t dpid;
    int port, status;
    double raw;
    FILE *f;
    bl_t0 = bl_now();
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
            BL_MAX_N + 100);
    fclose(f);
    if ((dpid = bl_daemon(cfg, &port)) < 0) {
        printf("bench_load: cannot start build/fxstreamd (run make all)\n");
        return 1;
    }
    snprintf(url, sizeof url, "ws://127.0.0.1:%d/v1/ws", port);
    raw = bl_raw_loopback(1.0);
    memset(&fastest, 0, sizeof fastest);
    memset(&f1, 0, sizeof f1);
    memset(&t1, 0, sizeof t1);
    /* BENCH_LOAD_ONLY=capacity: raw loopback and send capacity only (~10 s), for experiments */
    const char *only = getenv("BENCH_LOAD_ONLY");
    int searches = !only || strcmp(only, "capacity") != 0;
    if (searches) {
        struct bl_result warm; /* let the flame develop to its ~20k particles before measuring */
        bl_trial(url, dpid, "bench_flame", 1, &warm);
        bl_search(url, dpid, "bench_flame", &fb, &ff, &fastest, &f1);
        bl_search(url, dpid, "bench_tex", &tb, &tf, &fastest, &t1);
    }
    int drained;
    double cap = bl_drain(port, "bench_tex", BL_DRAIN_N, BL_WINDOW_S, &drained);
    kill(dpid, SIGTERM);
    waitpid(dpid, &status, 0);
    unlink(cfg);
    rmdir(dir);

    printf("bench_load: raw loopback TCP, 1 writer + 1 reader thread: %.0f MB/s\n", raw);
    if (searches) bl_report_searches(&fb, &ff, &tb, &tf, &f1, &t1, &fastest, raw);
    printf("bench_load: server send capacity, %d subscribers of bench_tex that only drain their sockets: %.0f MB/s = "
           "%.1f%% of raw loopback (target >= 50%%)\n", drained, cap, raw > 0 ? 100 * cap / raw : 0);
    printf("bench_load: total %.0f s on %ld CPUs (daemon, its engine and the load generator share them)\n", bl_now() - bl_t0,
           sysconf(_SC_NPROCESSORS_ONLN));
    return 0;
}
