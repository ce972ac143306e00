/* trial.h — the fan-out trial that bench_load and bench_cluster share.
 *
 * Owns: forking build/fxstreamd on a free loopback port (its arguments after the config, the
 * port parsed from its "listening on" line); one trial: N subscribers of one stream through
 * libfxclient's pool (clients/c/fxpool.h), spread round robin over one or more daemons' URLs,
 * opened in a ramp, then 1 s of warm-up, a 3 s window and 0.5 s of grace; and the upward search
 * (doubling from 25, then bisection) for the largest N whose trial passes: every subscriber
 * subscribed, none closed early, >= 95% of the frames the stream produced inside the window
 * delivered, p99 latency <= 100 ms. Latency is the client's receive time minus the frame
 * header's server_time_us (the computing daemon's frame time; one machine, one clock). The
 * daemons' CPU time comes from /proc/PID/stat, their network threads' from
 * /proc/PID/task/PID/stat. One trial at a time (the pool's callbacks reach it through a
 * file-scope pointer); each prints one progress line on stderr. */
#ifndef BENCH_TRIAL_H
#define BENCH_TRIAL_H

#include <stdint.h>
#include <sys/types.h>

#define TRIAL_MAX_N 10000
#define TRIAL_WARMUP_S 1.0
#define TRIAL_WINDOW_S 3.0
#define TRIAL_MAX_URLS 4
#define TRIAL_MAX_PIDS 4

/* Where a trial's subscribers go, and whose CPU time it counts. */
struct trial_target {
    const char *stream;
    const char *urls[TRIAL_MAX_URLS]; /* subscriber i connects to urls[i % nurls] */
    int nurls;
    pid_t pids[TRIAL_MAX_PIDS];
    int npids;
};

struct trial_result {
    const char *stream;
    int n, ok, all_subscribed;
    double ratio, p50, p99, mbps, fps_produced; /* latencies in ms */
    double cpu_s, net_cpu_s; /* the daemons' CPU seconds in the window: all, and their network (main) threads' */
    uint64_t frames;
    uint64_t frame_bytes, count;
};

/* What a search found: the largest passing trial, the failing one that bounded it, the
 * smallest passing one, and the passing one with the highest send rate (zeroed when none). */
struct trial_search {
    struct trial_result best, fail, first, fastest;
};

/* CLOCK_MONOTONIC in seconds. */
double trial_now(void);
/* Forks build/fxstreamd --config cfg --port 0 --log-level error, then the NULL-terminated
 * extra arguments (extra may be NULL); the child dies with this process. Returns its pid with
 * *port, or -1. */
pid_t trial_daemon(const char *cfg, const char *const *extra, int *port);
/* SIGTERM, then waits for it. */
void trial_stop(pid_t pid);
/* Opens n subscribers and waits until each has received a frame (at most timeout_s).
 * Returns 0, or -1 when some got none in time. */
int trial_await_frames(const struct trial_target *tg, int n, double timeout_s);
/* One trial of n subscribers. Returns 0 (res filled), or -1 when the pool cannot be made. */
int trial_run(const struct trial_target *tg, int n, struct trial_result *res);
/* The upward search, ending by t_end (CLOCK_MONOTONIC seconds). */
void trial_search(const struct trial_target *tg, double t_end, struct trial_search *s);

#endif
