/* bench_cluster.c — fan-out of one 256x256 texture stream at 30 fps: one daemon against a
 * cluster of one compute daemon and two edges on the same machine, and what Redis adds to the
 * latency.
 *
 * Owns: the run, in this order, bounded to ~4 min:
 *   1. single: build/fxstreamd alone (no cluster);
 *   2. edges2: a redis-server of its own (free loopback port, no persistence) and three daemons
 *      on it, all with the same config: `--role compute` (started first, it seeds Redis with
 *      the config's stream) and two `--role edge` (no OpenCL) that relay its frames; subscribers
 *      split evenly over the two edges (the compute daemon takes the lease only after a TTL in
 *      Redis, so frames are awaited at both edges before anything is measured).
 * In each: a fixed trial of CL_LAT_N subscribers, whose client-measured latency (receive time
 * minus the header's server_time_us, which stays the owner's frame time through Redis; one
 * machine, one clock) gives p50/p99 and, between the two setups, Redis's added latency; then
 * the search of trial.h for the largest number of subscribers with >= 95% of the frames and
 * p99 <= 100 ms. Around each fixed trial, the serving daemons' /metrics are read before and
 * after (the difference is that trial's, summed over the daemons): fxs_stream_frame_age_seconds
 * (frame time to the start of its sending: on an edge, the owner's publish to the edge's send)
 * and, on the edges, fxs_cluster_relay_latency_seconds (the owner's frame time to arrival at
 * the edge); their p50/p99 are interpolated linearly inside the histograms' buckets (1, 2,
 * 5, 10, 20, 50 ms...: coarse). The stream computes all the time (pause_idle false), in both
 * setups alike, so subscribers never wait for a paused stream to start.
 * Every process started here is stopped at exit (atexit, failures included) and is killed when
 * this one dies otherwise (PR_SET_PDEATHSIG).
 * One line per figure on stdout ("cluster.NAME VALUE"), progress on stderr.
 *
 * All daemons, Redis and the load generator share the machine's cores: on a small machine the
 * cluster's figures say what the extra hops cost there, not what edges on machines of their
 * own would carry. */
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>

#include <libwebsockets.h>

#include "trial.h"

#define CL_BUDGET_S 235.0       /* whole benchmark */
#define CL_SEARCH_BUDGET_S 80.0 /* per setup */
#define CL_LAT_N 20             /* subscribers of the fixed latency trial */
#define CL_AWAIT_S 20.0         /* first frames at every daemon, lease TTL included */
#define CL_EDGES 2
#define CL_MAX_PROCS 4
#define CL_HIST_MAX 16
#define CL_STREAM "bench_tex"
#define CL_AGE_METRIC "fxs_stream_frame_age_seconds_bucket{stream=\"" CL_STREAM "\","
#define CL_RELAY_METRIC "fxs_cluster_relay_latency_seconds_bucket{"

/* A Prometheus histogram as /metrics renders it: cumulative counts per upper bound. */
struct cl_hist {
    int nb;
    double le[CL_HIST_MAX];
    double cum[CL_HIST_MAX];
};

/* One setup's figures; the histograms over the fixed trial, summed over the serving daemons. */
struct cl_setup {
    struct trial_result lat;
    struct trial_search search;
    struct cl_hist age;   /* fxs_stream_frame_age_seconds: frame time to the start of its sending */
    struct cl_hist relay; /* fxs_cluster_relay_latency_seconds (edges only): frame time to arrival */
};

static double cl_t0;
static char cl_dir[] = "/tmp/bench_cluster_XXXXXX", cl_cfg[128];
static pid_t cl_procs[CL_MAX_PROCS];
static int cl_nprocs;

/* ---- processes ---------------------------------------------------------------------- */

static pid_t cl_track(pid_t pid)
{
    if (pid > 0 && cl_nprocs < CL_MAX_PROCS) cl_procs[cl_nprocs++] = pid;
    return pid;
}

/* Stops what was started, the latest first (edges before the compute daemon, Redis last). */
static void cl_stop_all(void)
{
    while (cl_nprocs > 0) trial_stop(cl_procs[--cl_nprocs]);
}

/* atexit: every process stopped, the temporary directory removed. */
static void cl_cleanup(void)
{
    char path[192];
    cl_stop_all();
    unlink(cl_cfg);
    snprintf(path, sizeof path, "%s/redis", cl_dir);
    rmdir(path);
    rmdir(cl_dir);
}

static int cl_free_port(void)
{
    struct sockaddr_in a = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
    socklen_t len = sizeof a;
    int fd = socket(AF_INET, SOCK_STREAM, 0), port = 0;
    if (fd >= 0 && !bind(fd, (struct sockaddr *)&a, sizeof a) && !getsockname(fd, (struct sockaddr *)&a, &len))
        port = ntohs(a.sin_port);
    if (fd >= 0) close(fd);
    return port;
}

/* A loopback TCP connection to port with a 2 s receive timeout, or -1. */
static int cl_connect(int port)
{
    struct sockaddr_in a = { .sin_family = AF_INET, .sin_port = htons((uint16_t)port),
                             .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
    struct timeval tv = { 2, 0 };
    int fd = socket(AF_INET, SOCK_STREAM, 0);
    if (fd < 0) return -1;
    setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    if (!connect(fd, (struct sockaddr *)&a, sizeof a)) return fd;
    close(fd);
    return -1;
}

/* Sends req, reads the whole answer (until the peer closes, or out is full) into out. */
static int cl_request(int port, const char *req, char *out, size_t len)
{
    size_t got = 0;
    ssize_t r;
    int fd = cl_connect(port);
    if (fd < 0) return -1;
    if (send(fd, req, strlen(req), 0) == (ssize_t)strlen(req))
        while (got < len - 1 && (r = recv(fd, out + got, len - 1 - got, 0)) > 0) got += (size_t)r;
    out[got] = 0;
    close(fd);
    return got ? 0 : -1;
}

static int cl_redis_ping(int port)
{
    char ans[64];
    return cl_request(port, "PING\r\nQUIT\r\n", ans, sizeof ans) || strncmp(ans, "+PONG", 5) ? -1 : 0;
}

/* redis-server on a free loopback port, no persistence, data in cl_dir/redis. */
static pid_t cl_redis_start(int *port)
{
    char dir[160], ps[16];
    pid_t pid;
    snprintf(dir, sizeof dir, "%s/redis", cl_dir);
    if (mkdir(dir, 0700) || !(*port = cl_free_port())) return -1;
    snprintf(ps, sizeof ps, "%d", *port);
    if ((pid = fork()) < 0) return -1;
    if (pid == 0) {
        int null = open("/dev/null", O_WRONLY);
        dup2(null, 1);
        dup2(null, 2);
        prctl(PR_SET_PDEATHSIG, SIGKILL);
        execl("/usr/bin/redis-server", "redis-server", "--port", ps, "--bind", "127.0.0.1", "--save", "",
              "--appendonly", "no", "--dir", dir, "--daemonize", "no", (char *)NULL);
        _exit(127);
    }
    cl_track(pid);
    for (double end = trial_now() + 10; trial_now() < end; usleep(50000))
        if (!cl_redis_ping(*port)) return pid;
    return -1;
}

/* ---- histograms from /metrics ------------------------------------------------------------ */

/* Adds the daemon's buckets of the series whose lines start with prefix to h (the same
 * bounds everywhere); a daemon without the series adds nothing. */
static int cl_hist_add(int port, const char *prefix, struct cl_hist *h)
{
    static char body[1 << 20];
    int i = 0;
    if (cl_request(port, "GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n", body, sizeof body))
        return -1;
    for (char *p = strstr(body, prefix); p && i < CL_HIST_MAX; p = strstr(p + 1, prefix), i++) {
        char *le = strstr(p, "le=\""), *val = strchr(p, ' ');
        if (!le || !val) return -1;
        h->le[i] = strncmp(le + 4, "+Inf", 4) ? strtod(le + 4, NULL) : INFINITY;
        h->cum[i] += strtod(val + 1, NULL);
    }
    if (i) h->nb = i;
    return 0;
}

/* The series summed over the daemons at ports; -1 when one cannot be read. */
static int cl_hist_read(const int *ports, int nports, const char *prefix, struct cl_hist *h)
{
    memset(h, 0, sizeof *h);
    for (int i = 0; i < nports; i++)
        if (cl_hist_add(ports[i], prefix, h)) return -1;
    return 0;
}

/* What was observed between two readings: after - before, into after. */
static void cl_hist_since(struct cl_hist *after, const struct cl_hist *before)
{
    for (int i = 0; i < after->nb && i < before->nb; i++) after->cum[i] -= before->cum[i];
}

static double cl_hist_count(const struct cl_hist *h) { return h->nb ? h->cum[h->nb - 1] : 0; }

/* The q-quantile in seconds: linear inside the bucket holding rank q * count (Prometheus's
 * histogram_quantile); a rank in the +Inf bucket gives the highest finite bound. */
static double cl_hist_quantile(const struct cl_hist *h, double q)
{
    double rank = q * cl_hist_count(h), lo = 0, below = 0;
    if (rank <= 0) return 0;
    for (int i = 0; i < h->nb; i++) {
        if (h->cum[i] >= rank) {
            if (isinf(h->le[i])) return lo;
            return lo + (h->le[i] - lo) * (h->cum[i] > below ? (rank - below) / (h->cum[i] - below) : 1);
        }
        lo = h->le[i];
        below = h->cum[i];
    }
    return lo;
}

/* ---- the two setups ------------------------------------------------------------------- */

static void cl_write_config(void)
{
    FILE *f = fopen(cl_cfg, "w");
    if (!f) return;
    fprintf(f, "{\"limits\":{\"max_connections\":%d},\"pause_idle\":false,\"streams\":["
               "{\"stream\":\"" CL_STREAM "\",\"effect\":\"energy_wave\",\"params\":{\"width\":256,\"height\":256,"
               "\"fps\":30,\"light_rig\":false,"
               "\"curves\":[],\"tori\":[{\"center\":[0,0,18],\"axis\":[0,0,1],\"R\":6,\"coef\":5}]}}]}\n",
            TRIAL_MAX_N + 100);
    fclose(f);
}

/* The fixed trial, with the serving daemons' histograms read before and after it. */
static int cl_fixed_trial(const struct trial_target *tg, const int *ports, int nports, struct cl_setup *s)
{
    struct cl_hist age, relay;
    if (cl_hist_read(ports, nports, CL_AGE_METRIC, &age) || cl_hist_read(ports, nports, CL_RELAY_METRIC, &relay))
        return -1;
    trial_run(tg, CL_LAT_N, &s->lat);
    if (cl_hist_read(ports, nports, CL_AGE_METRIC, &s->age) || cl_hist_read(ports, nports, CL_RELAY_METRIC, &s->relay))
        return -1;
    cl_hist_since(&s->age, &age);
    cl_hist_since(&s->relay, &relay);
    return 0;
}

/* The search, ending after CL_SEARCH_BUDGET_S or at the end of the whole budget. */
static void cl_search(const struct trial_target *tg, struct cl_setup *s)
{
    trial_search(tg, fmin(trial_now() + CL_SEARCH_BUDGET_S, cl_t0 + CL_BUDGET_S), &s->search);
}

static int cl_single(struct cl_setup *s)
{
    static char url[64];
    struct trial_target tg = { .stream = CL_STREAM, .urls = { url }, .nurls = 1, .npids = 1 };
    int port;
    if ((tg.pids[0] = cl_track(trial_daemon(cl_cfg, NULL, &port))) < 0) return -1;
    snprintf(url, sizeof url, "ws://127.0.0.1:%d/v1/ws", port);
    if (trial_await_frames(&tg, 1, CL_AWAIT_S) || cl_fixed_trial(&tg, &port, 1, s)) return -1;
    cl_search(&tg, s);
    cl_stop_all();
    return 0;
}

/* Starts a daemon of the cluster on redis_url: its pid, with *port. */
static pid_t cl_node(const char *redis_url, const char *node, const char *role, int *port)
{
    const char *args[] = { "--cluster", redis_url, "--node-id", node, "--role", role, NULL };
    return cl_track(trial_daemon(cl_cfg, args, port));
}

/* Redis, the compute daemon (first: it seeds Redis), the edges; the target: both edges. */
static int cl_cluster_start(struct trial_target *tg, int *edge_ports)
{
    static char redis_url[64], urls[CL_EDGES][64];
    char node[16];
    int port;
    if ((tg->pids[tg->npids++] = cl_redis_start(&port)) < 0) return -1;
    snprintf(redis_url, sizeof redis_url, "redis://127.0.0.1:%d", port);
    if ((tg->pids[tg->npids++] = cl_node(redis_url, "compute", "compute", &port)) < 0) return -1;
    for (int i = 0; i < CL_EDGES; i++) {
        snprintf(node, sizeof node, "edge%d", i + 1);
        if ((tg->pids[tg->npids++] = cl_node(redis_url, node, "edge", &edge_ports[i])) < 0) return -1;
        snprintf(urls[i], sizeof urls[i], "ws://127.0.0.1:%d/v1/ws", edge_ports[i]);
        tg->urls[tg->nurls++] = urls[i];
    }
    return 0;
}

static int cl_cluster(struct cl_setup *s)
{
    struct trial_target tg = { .stream = CL_STREAM };
    int edge_ports[CL_EDGES];
    if (cl_cluster_start(&tg, edge_ports) || trial_await_frames(&tg, CL_EDGES, CL_AWAIT_S) ||
        cl_fixed_trial(&tg, edge_ports, CL_EDGES, s))
        return -1;
    cl_search(&tg, s);
    cl_stop_all();
    return 0;
}

/* ---- report ------------------------------------------------------------------------- */

static void cl_report_search(const char *name, const struct trial_search *s)
{
    printf("cluster.%s.max_subscribers %d\n", name, s->best.n);
    printf("cluster.%s.failed_at %d\n", name, s->fail.n);
}

/* A histogram's count and interpolated p50/p99 in ms. */
static void cl_report_hist(const char *name, const struct cl_hist *h)
{
    printf("cluster.%s.observed %.0f\n", name, cl_hist_count(h));
    printf("cluster.%s.bucket_interp_p50_ms %.1f\n", name, 1e3 * cl_hist_quantile(h, 0.5));
    printf("cluster.%s.bucket_interp_p99_ms %.1f\n", name, 1e3 * cl_hist_quantile(h, 0.99));
}

static void cl_report(const struct cl_setup *one, const struct cl_setup *two)
{
    cl_report_search("single", &one->search);
    cl_report_search("edges2", &two->search);
    printf("cluster.latency.subscribers %d\n", CL_LAT_N);
    printf("cluster.latency.single.p50_ms %.1f\ncluster.latency.single.p99_ms %.1f\n", one->lat.p50, one->lat.p99);
    printf("cluster.latency.edges2.p50_ms %.1f\ncluster.latency.edges2.p99_ms %.1f\n", two->lat.p50, two->lat.p99);
    printf("cluster.latency.added.p50_ms %.1f\ncluster.latency.added.p99_ms %.1f\n", two->lat.p50 - one->lat.p50,
           two->lat.p99 - one->lat.p99);
    cl_report_hist("frame_age.single", &one->age);
    cl_report_hist("frame_age.edges2", &two->age);
    cl_report_hist("relay_latency.edges2", &two->relay);
    printf("cluster.total_s %.0f\ncluster.cpus %ld\n", trial_now() - cl_t0, sysconf(_SC_NPROCESSORS_ONLN));
}

static int cl_setup_run(void)
{
    struct rlimit rl;
    lws_set_log_level(0, NULL);
    signal(SIGPIPE, SIG_IGN);
    if (!getrlimit(RLIMIT_NOFILE, &rl) && rl.rlim_cur < rl.rlim_max) {
        rl.rlim_cur = rl.rlim_max; /* inherited by the daemons too */
        setrlimit(RLIMIT_NOFILE, &rl);
    }
    if (!mkdtemp(cl_dir)) return -1;
    snprintf(cl_cfg, sizeof cl_cfg, "%s/config.json", cl_dir);
    atexit(cl_cleanup);
    cl_write_config();
    return 0;
}

int main(void)
{
    struct cl_setup one, two;
    cl_t0 = trial_now();
    if (cl_setup_run()) return 1;
    if (cl_single(&one)) {
        printf("cluster.error cannot start build/fxstreamd or get frames from it (run make all)\n");
        return 1;
    }
    if (cl_cluster(&two)) {
        printf("cluster.error the cluster (redis-server, 1 compute, %d edges) did not start or relay frames\n", CL_EDGES);
        return 1;
    }
    cl_report(&one, &two);
    return 0;
}
