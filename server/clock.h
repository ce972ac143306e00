/* clock.h — the daemon's two clocks, in one place: monotonic seconds for every interval and
 * deadline (steps, rates, timeouts, uptime), and wall-clock microseconds for the frame header's
 * server_time_us (clients compare it with their own clocks). */
#ifndef FX_CLOCK_H
#define FX_CLOCK_H

#include <stdint.h>
#include <time.h>

/* CLOCK_MONOTONIC seconds. */
static inline double clock_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* CLOCK_REALTIME microseconds since the epoch. */
static inline uint64_t clock_wall_us(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    return (uint64_t)ts.tv_sec * 1000000u + (uint64_t)ts.tv_nsec / 1000u;
}

#endif
