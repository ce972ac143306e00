/* trial.c — the fan-out trial that bench_load and bench_cluster share (what it owns: trial.h). */
#include "trial.h"

#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <sys/prctl.h>
#include <sys/wait.h>

#include "fxpool.h"
#include "fxws.h"

#define TRIAL_RATIO 0.95
#define TRIAL_P99_MS 100.0
#define TRIAL_GRACE_S 0.5
#define TRIAL_MAX_ARGS 24

struct trial_conn {
    int subscribed;
    uint64_t last_seq;
};

struct trial_state {
    const char *stream;
    struct trial_conn *conns;
    int subscribed, receiving, closed_early, errors;
    int measuring;               /* 1: in the window; 2: grace period after it */
    uint64_t frames, bytes, max_seq, max_seq_start, max_seq_end;
    uint64_t payload_bytes_last, count_last;
    struct fxp_hist lat;
};

double trial_now(void) { return (double)fxws_now_us(CLOCK_MONOTONIC) / 1e6; }

/* ---- daemons ------------------------------------------------------------------------ */

static void trial_exec(const char *cfg, const char *const *extra)
{
    const char *argv[TRIAL_MAX_ARGS] = { "fxstreamd", "--config", cfg, "--port", "0", "--log-level", "error" };
    int n = 7;
    for (; extra && *extra && n < TRIAL_MAX_ARGS - 1; extra++) argv[n++] = *extra;
    prctl(PR_SET_PDEATHSIG, SIGKILL); /* never outlives the benchmark, whatever ends it */
    execv("build/fxstreamd", (char *const *)argv);
    _exit(127);
}

pid_t trial_daemon(const char *cfg, const char *const *extra, int *port)
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
        trial_exec(cfg, extra);
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
    if (*port) return pid;
    trial_stop(pid);
    return -1;
}

void trial_stop(pid_t pid)
{
    int status;
    kill(pid, SIGTERM);
    waitpid(pid, &status, 0);
}

/* CPU seconds of process pid, or with thread set of its main thread alone (fxstreamd's network
 * thread: libwebsockets' service loop, which sends the frames; the engine and PoCL's workers
 * run in other threads). */
static double trial_proc_cpu(pid_t pid, int thread)
{
    char path[64], buf[1024], *p;
    unsigned long ut = 0, st = 0;
    FILE *f;
    if (thread) snprintf(path, sizeof path, "/proc/%d/task/%d/stat", (int)pid, (int)pid);
    else snprintf(path, sizeof path, "/proc/%d/stat", (int)pid);
    if (!(f = fopen(path, "r"))) return 0;
    if (!fgets(buf, sizeof buf, f)) buf[0] = 0;
    fclose(f);
    if (!(p = strrchr(buf, ')'))) return 0;
    /* fields after ")": state(3) ... utime(14) stime(15) */
    if (sscanf(p + 2, "%*c %*d %*d %*d %*d %*d %*u %*u %*u %*u %*u %lu %lu", &ut, &st) != 2) return 0;
    return (double)(ut + st) / (double)sysconf(_SC_CLK_TCK);
}

static double trial_cpu(const struct trial_target *tg, int thread)
{
    double s = 0;
    for (int i = 0; i < tg->npids; i++) s += trial_proc_cpu(tg->pids[i], thread);
    return s;
}

/* ---- the pool's callbacks ------------------------------------------------------------- */

/* The pool's callbacks get the conn's user pointer; the trial is reached through a
 * file-scope pointer (one trial at a time). */
static struct trial_state *trial_cur;

static void trial_on_open(struct fxp_conn *c, const cJSON *hello, void *user)
{
    char req[160];
    (void)hello;
    (void)user;
    snprintf(req, sizeof req, "{\"op\":\"subscribe\",\"id\":1,\"stream\":\"%s\"}", trial_cur->stream);
    if (fxp_send_text(c, req, strlen(req))) trial_cur->errors++;
}

static void trial_on_text(struct fxp_conn *c, const cJSON *m, uint64_t now, void *user)
{
    struct trial_conn *tc = user;
    const char *op = cJSON_GetObjectItemCaseSensitive(m, "op")->valuestring;
    (void)c;
    (void)now;
    if (!strcmp(op, "subscribed") && !tc->subscribed) {
        tc->subscribed = 1;
        trial_cur->subscribed++;
    } else if (!strcmp(op, "error")) {
        trial_cur->errors++;
    }
}

static void trial_on_frame(struct fxp_conn *c, const struct fxs_header *h, const uint8_t *payload, size_t bytes,
                           uint64_t now, void *user)
{
    struct trial_conn *tc = user;
    struct trial_state *t = trial_cur;
    (void)c;
    (void)payload;
    if (h->seq > t->max_seq) t->max_seq = h->seq;
    t->payload_bytes_last = bytes;
    t->count_last = h->count_or_width;
    if (t->measuring == 1) {
        t->bytes += bytes;
        if (tc->last_seq) fxp_hist_add(&t->lat, (int64_t)now - (int64_t)h->server_time_us);
    }
    /* delivery: frames produced inside the window, wherever they arrive (grace included) */
    if (t->measuring && h->seq > t->max_seq_start && (t->measuring == 1 || h->seq <= t->max_seq_end)) t->frames++;
    if (!tc->last_seq) t->receiving++;
    tc->last_seq = h->seq;
}

static void trial_on_close(struct fxp_conn *c, const struct fxp_close_info *info, void *user)
{
    (void)c;
    (void)user;
    if (!info->by_client) trial_cur->closed_early++;
}

/* ---- one trial ------------------------------------------------------------------------ */

static void trial_service_until(struct fxp_pool *p, double until)
{
    while (trial_now() < until) fxp_service(p, 5);
}

/* Resets t, makes the pool and opens n subscribers in a ramp, waiting until all are
 * subscribed (or closed, or 10 s after the ramp). Returns the pool, or NULL. */
static struct fxp_pool *trial_open(const struct trial_target *tg, int n, struct trial_state *t)
{
    struct fxp_callbacks cb = { trial_on_open, trial_on_text, trial_on_frame, trial_on_close };
    struct fxp_options po = { .max_connections = n };
    struct fxp_pool *pool;
    char err[256];
    double start, ramp = fmax(0.2, n / 3000.0), deadline;
    int started = 0;
    memset(t, 0, sizeof *t);
    t->stream = tg->stream;
    trial_cur = t;
    if (!(t->conns = calloc((size_t)n, sizeof *t->conns))) return NULL;
    if (fxp_pool_create(&pool, &cb, &po, err, sizeof err)) {
        fprintf(stderr, "trial: %s\n", err);
        free(t->conns);
        return NULL;
    }
    start = trial_now();
    deadline = start + ramp + 10;
    while ((t->subscribed + t->closed_early < n) && trial_now() < deadline) {
        double el = trial_now() - start;
        while (started < n && el >= ramp * started / n) {
            if (fxp_connect(pool, tg->urls[started % tg->nurls], &t->conns[started], NULL, err, sizeof err))
                t->closed_early++;
            started++;
        }
        fxp_service(pool, 2);
    }
    return pool;
}

static void trial_close(struct fxp_pool *pool, struct trial_state *t)
{
    fxp_pool_destroy(pool); /* drops every connection at once */
    free(t->conns);
    trial_cur = NULL;
    usleep(300000); /* let the daemons drop the closed sessions */
}

int trial_await_frames(const struct trial_target *tg, int n, double timeout_s)
{
    static struct trial_state t;
    double deadline = trial_now() + timeout_s;
    struct fxp_pool *pool = trial_open(tg, n, &t);
    if (!pool) return -1;
    while (t.receiving < n && trial_now() < deadline) fxp_service(pool, 5);
    int ok = t.receiving == n;
    trial_close(pool, &t);
    return ok ? 0 : -1;
}

/* The window: delivery counted from the frames produced inside it, latency inside it. */
static void trial_measure(const struct trial_target *tg, struct fxp_pool *pool, struct trial_state *t,
                          struct trial_result *res)
{
    double w0, w1, cpu0, cpu1, net0, net1;
    trial_service_until(pool, trial_now() + TRIAL_WARMUP_S);
    t->max_seq_start = t->max_seq;
    fxp_hist_reset(&t->lat);
    cpu0 = trial_cpu(tg, 0);
    net0 = trial_cpu(tg, 1);
    w0 = trial_now();
    t->measuring = 1;
    trial_service_until(pool, w0 + TRIAL_WINDOW_S);
    w1 = trial_now();
    cpu1 = trial_cpu(tg, 0);
    net1 = trial_cpu(tg, 1);
    t->max_seq_end = t->max_seq;
    t->measuring = 2;
    trial_service_until(pool, w1 + TRIAL_GRACE_S);
    t->measuring = 0;
    uint64_t produced = t->max_seq_end > t->max_seq_start ? t->max_seq_end - t->max_seq_start : 0;
    double expected = (double)produced * t->subscribed;
    res->ratio = expected > 0 ? (double)t->frames / expected : 0;
    res->p50 = fxp_hist_quantile(&t->lat, 0.5) / 1000;
    res->p99 = fxp_hist_quantile(&t->lat, 0.99) / 1000;
    res->mbps = (double)t->bytes / (w1 - w0) / 1e6;
    res->cpu_s = cpu1 - cpu0;
    res->net_cpu_s = net1 - net0;
    res->frames = t->frames;
    res->fps_produced = (double)produced / (w1 - w0);
    res->frame_bytes = t->payload_bytes_last;
    res->count = t->count_last;
    res->ok = res->all_subscribed && !t->closed_early && res->ratio >= TRIAL_RATIO && res->p99 <= TRIAL_P99_MS &&
              t->lat.count > 0;
}

int trial_run(const struct trial_target *tg, int n, struct trial_result *res)
{
    static struct trial_state t;
    struct fxp_pool *pool;
    memset(res, 0, sizeof *res);
    if (!(pool = trial_open(tg, n, &t))) return -1;
    res->n = n;
    res->stream = tg->stream;
    res->all_subscribed = t.subscribed == n;
    trial_measure(tg, pool, &t, res);
    fprintf(stderr, "  %s n=%d: %s subscribed %d, ratio %.3f, p50 %.1f ms, p99 %.1f ms, %.1f MB/s, produced %.1f fps, cpu %.2f s\n",
            tg->stream, n, res->ok ? "PASS" : "fail", t.subscribed, res->ratio, res->p50, res->p99, res->mbps,
            res->fps_produced, res->cpu_s);
    trial_close(pool, &t);
    return 0;
}

/* ---- the search ------------------------------------------------------------------------ */

static void trial_note_pass(struct trial_search *s, const struct trial_result *r)
{
    if (r->mbps > s->fastest.mbps) s->fastest = *r;
    if (!s->first.n || r->n < s->first.n) s->first = *r;
    s->best = *r;
}

/* Doubling from 25 while trials pass, then bisection. */
void trial_search(const struct trial_target *tg, double t_end, struct trial_search *s)
{
    int lo = 0, hi = 0, n = 25;
    struct trial_result r;
    memset(s, 0, sizeof *s);
    while (n <= TRIAL_MAX_N && trial_now() < t_end) {
        if (trial_run(tg, n, &r)) break;
        if (!r.ok) {
            s->fail = r;
            hi = n;
            break;
        }
        trial_note_pass(s, &r);
        lo = n;
        if (n == TRIAL_MAX_N) break;
        n = n * 2 > TRIAL_MAX_N ? TRIAL_MAX_N : n * 2;
    }
    while (hi && hi - lo > (lo > 0 ? lo / 8 : 3) && trial_now() + 6 < t_end) {
        n = lo ? (lo + hi) / 2 : hi / 2;
        if (n < 1 || n == lo) break;
        if (trial_run(tg, n, &r)) break;
        if (r.ok) {
            trial_note_pass(s, &r);
            lo = n;
        } else {
            s->fail = r;
            hi = n;
        }
    }
}
