/* flame_count.c — a game loop fed by libfxclient: connects to fxstreamd without waiting,
 * subscribes to the `flame` stream and, once per 60 Hz tick, drains what arrived with a poll
 * that never blocks, decodes each particle frame into arrays it owns and prints the counts.
 * A native engine plugin does the same in its process callback.
 *
 *   cc flame_count.c -o flame_count $(pkg-config --cflags --libs fxclient)
 *   ./flame_count [URL [FRAMES]]     (ws://127.0.0.1:7681/v1/ws, 10 frames)
 *
 * Prints one line per particle frame, then the longest fxc_poll call of the run; exits 0
 * after FRAMES frames, 1 when the connection fails, the server refuses the subscription or
 * no frame comes for 15 s. */
#define _POSIX_C_SOURCE 200809L /* clock_gettime, nanosleep */

#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include <fxclient.h>

#define TICK_NS 16666667L     /* 60 Hz */
#define PATIENCE_TICKS (15 * 60)

struct particles {
    struct fxc_particles p;
    float *buf;  /* xyz and temperature of `capacity` particles */
    uint8_t *flags;
};

/* Makes room for n particles (the header's count) and points p's arrays there. */
static int grow(struct particles *a, uint32_t n)
{
    if (n <= a->p.capacity && a->buf) return 0;
    free(a->buf);
    free(a->flags);
    a->buf = malloc((size_t)(n ? n : 1) * 4 * sizeof *a->buf);
    a->flags = malloc(n ? n : 1);
    a->p = (struct fxc_particles){ .capacity = n, .xyz = a->buf, .temperature = a->buf ? a->buf + 3 * (size_t)n : NULL,
                                   .flags = a->flags };
    return a->buf && a->flags ? 0 : -1;
}

/* Decodes one particle frame and prints its counts. */
static int on_frame(const struct fxc_event *ev, struct particles *a)
{
    char err[256];
    uint32_t burning = 0;
    double sum_t = 0;
    if (ev->header.kind != FXS_KIND_PARTICLES) return 0; /* another kind: not ours to draw */
    if (grow(a, ev->header.count_or_width) || fxc_decode_particles(&ev->header, ev->payload, &a->p, err, sizeof err)) {
        fprintf(stderr, "flame_count: frame %" PRIu64 ": %s\n", ev->header.seq, a->buf ? err : "out of memory");
        return -1;
    }
    for (uint32_t i = 0; i < a->p.count; i++) {
        burning += (a->p.flags[i] >> 2) & 1u;
        sum_t += a->p.temperature[i];
    }
    printf("%s frame %" PRIu64 ": %" PRIu32 " particles (header count %" PRIu32 "), %" PRIu32 " burning, mean %.0f K\n",
           ev->stream ? ev->stream : "?", ev->header.seq, a->p.count, ev->header.count_or_width, burning,
           a->p.count ? sum_t / a->p.count : 0.0);
    return 0;
}

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

int main(int argc, char **argv)
{
    const char *url = argc > 1 ? argv[1] : "ws://127.0.0.1:7681/v1/ws";
    long want = argc > 2 ? atol(argv[2]) : 10, got = 0, idle = 0;
    struct particles a = { 0 };
    struct fxc_client *c;
    char err[256];
    double longest = 0;
    int64_t sub;
    int r = 0;
    if (fxc_open(&c, url, NULL, err, sizeof err)) {
        fprintf(stderr, "flame_count: %s\n", err);
        return 1;
    }
    if ((sub = fxc_subscribe(c, "flame", 30, err, sizeof err)) < 0) { /* goes out once connected */
        fprintf(stderr, "flame_count: %s\n", err);
        fxc_close(c);
        return 1;
    }
    while (!r && got < want && idle++ < PATIENCE_TICKS) {
        for (;;) { /* everything that arrived since the last tick */
            struct fxc_event ev;
            double t0 = now_ms();
            int n = fxc_poll(c, &ev, 0, err, sizeof err);
            if (now_ms() - t0 > longest) longest = now_ms() - t0;
            if (n < 0) {
                fprintf(stderr, "flame_count: %s\n", err);
                r = -1;
            }
            if (n != 1) break;
            if (ev.type == FXC_EVENT_FRAME) {
                r = on_frame(&ev, &a);
                got += ev.header.kind == FXS_KIND_PARTICLES;
                idle = 0;
            } else if (ev.id == sub && ev.code) {
                fprintf(stderr, "flame_count: subscribe: %s: %s\n", ev.code, ev.message);
                r = -1;
            }
            fxc_event_free(&ev);
            if (r || got == want) break;
        }
        nanosleep(&(struct timespec){ 0, TICK_NS }, NULL); /* the rest of the game's frame */
    }
    if (!r && got < want) {
        fprintf(stderr, "flame_count: no frame for 15 s (%ld of %ld)\n", got, want);
        r = -1;
    }
    if (!r) printf("longest fxc_poll call: %.3f ms\n", longest);
    fxc_close(c);
    free(a.buf);
    free(a.flags);
    return r ? 1 : 0;
}
