/* fxc_api_check.c — libfxclient's public API against a real daemon, built by
 * test_libfxclient.py from the installed files only (pkg-config fxclient), like a program
 * outside the tree: a non-blocking open with requests queued before the handshake, replies
 * matched by id through fxc_poll and fxc_wait, the typed calls, the parameter readers, the
 * server's errors (with its "did you mean"), bad input refused without harm to the
 * connection, a second client's set arriving as an event, frames named by their stream and
 * decoded (particles, light rig, look-up tables; the engine encoding's particles and textures,
 * as a native engine plugin reads them; a particle budget's subsets and their total), events
 * that outlive fxc_close, the end of the connection when the daemon stops, and fxc_set_log.
 *
 * Usage: fxc_api_check URL DAEMON_PID. Prints "ok   what" or "FAIL what" per check and
 * "info ..." lines; exit status 1 on any failure. Every wait is bounded. */
#define _POSIX_C_SOURCE 200809L

#include <inttypes.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <fxclient.h>

static int failed;
static double longest_poll_ms, longest_poll_cpu_ms; /* wall time, and this thread's CPU time */

static void check(int ok, const char *fmt, ...)
{
    va_list ap;
    printf("%s ", ok ? "ok  " : "FAIL");
    va_start(ap, fmt);
    vprintf(fmt, ap);
    va_end(ap);
    printf("\n");
    fflush(stdout);
    failed += !ok;
}

static double clock_ms(clockid_t clk)
{
    struct timespec ts;
    clock_gettime(clk, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

static double now_ms(void) { return clock_ms(CLOCK_MONOTONIC); }

typedef int (*match_fn)(const struct fxc_event *ev, const void *arg);

/* Polls c as a game loop does (timeout 0, a 5 ms tick) for up to ms until an event matches;
 * 1 with it in *ev, 0 on timeout, -1 when the connection ended. Others are dropped. */
static int wait_event(struct fxc_client *c, struct fxc_event *ev, int ms, match_fn match, const void *arg)
{
    char err[256];
    double end = now_ms() + ms;
    while (now_ms() < end) {
        double t0 = now_ms(), c0 = clock_ms(CLOCK_THREAD_CPUTIME_ID);
        int n = fxc_poll(c, ev, 0, err, sizeof err);
        if (now_ms() - t0 > longest_poll_ms) longest_poll_ms = now_ms() - t0;
        if (clock_ms(CLOCK_THREAD_CPUTIME_ID) - c0 > longest_poll_cpu_ms)
            longest_poll_cpu_ms = clock_ms(CLOCK_THREAD_CPUTIME_ID) - c0;
        if (n < 0) return -1;
        if (n == 0) {
            nanosleep(&(struct timespec){ 0, 5000000 }, NULL);
            continue;
        }
        if (match(ev, arg)) return 1;
        fxc_event_free(ev);
    }
    return 0;
}

static int is_op(const struct fxc_event *ev, const void *op)
{
    return ev->type == FXC_EVENT_TEXT && !strcmp(ev->op, op);
}

static int any(const struct fxc_event *ev, const void *arg)
{
    (void)ev;
    (void)arg;
    return 1;
}

static int is_reply(const struct fxc_event *ev, const void *id)
{
    return ev->type == FXC_EVENT_TEXT && ev->id == *(const int64_t *)id;
}

/* A frame of `kind` from `stream`. */
struct want_frame {
    const char *stream;
    unsigned kind;
};
static int is_frame(const struct fxc_event *ev, const void *arg)
{
    const struct want_frame *w = arg;
    return ev->type == FXC_EVENT_FRAME && ev->header.kind == w->kind && ev->stream && !strcmp(ev->stream, w->stream);
}

/* Open without waiting; a get queued before the handshake; the hello first; the reply by id. */
static struct fxc_client *check_open(const char *url, double *alpha, int64_t *rev)
{
    struct fxc_client *c;
    struct fxc_event ev;
    char err[256], json[256];
    double t0 = now_ms();
    int r = fxc_open(&c, url, NULL, err, sizeof err);
    double open_ms = now_ms() - t0;
    check(r == 0 && fxc_state(c) == FXC_CONNECTING && !fxc_hello(c), "fxc_open returns at once, connecting (%s)",
          r ? err : "");
    printf("info fxc_open took %.3f ms\n", open_ms);
    if (r) return NULL;
    int64_t id = fxc_get(c, "energy", err, sizeof err);
    check(id >= 1, "fxc_get before the handshake is queued (id %" PRId64 ")", id);
    r = wait_event(c, &ev, 10000, any, NULL);
    check(r == 1 && !strcmp(ev.op, "hello") && fxc_state(c) == FXC_OPEN && fxc_hello(c) &&
              !strcmp(fxc_hello(c), ev.json),
          "the hello is the first event; the client is open");
    fxc_event_free(&ev);
    r = wait_event(c, &ev, 10000, is_reply, &id);
    check(r == 1 && !strcmp(ev.op, "params") && ev.stream && !strcmp(ev.stream, "energy") && ev.rev >= 1,
          "the get's reply carries its id, op params, stream and rev");
    check(r == 1 && fxc_param_number(&ev, "alpha", alpha) == 0, "fxc_param_number reads alpha (%g)", *alpha);
    check(r == 1 && fxc_param_json(&ev, "color_energy", json, sizeof json) == 0 && json[0] == '[',
          "fxc_param_json writes a value as JSON (%s)", json);
    check(r == 1 && fxc_param_number(&ev, "nope", alpha) == -1 && fxc_param_json(&ev, "color_energy", json, 3) == -1,
          "an absent parameter or a short buffer: -1");
    fxc_param_number(&ev, "alpha", alpha);
    *rev = ev.rev;
    fxc_event_free(&ev);
    return c;
}

/* The typed set, an error reply with the server's suggestion, an unknown op, bad input. */
static void check_requests(struct fxc_client *c, int64_t rev)
{
    struct fxc_event ev;
    char err[256];
    double v = 0;
    int64_t id = fxc_set_number(c, "energy", "alpha", 2.5, err, sizeof err);
    int r = fxc_wait(c, id, &ev, 10000, err, sizeof err);
    check(r == 0 && ev.rev == rev + 1 && fxc_param_number(&ev, "alpha", &v) == 0 && v == 2.5,
          "fxc_set_number: the params reply with the next rev (%" PRId64 ") and the value", ev.rev);
    fxc_event_free(&ev);
    id = fxc_set(c, "energy", "{\"alhpa\":1}", err, sizeof err);
    r = fxc_wait(c, id, &ev, 10000, err, sizeof err);
    check(r == 1 && ev.code && !strcmp(ev.code, "bad_param") && ev.param && !strcmp(ev.param, "alhpa") &&
              strstr(err, "did you mean \"alpha\""),
          "a misspelt parameter: 1, code bad_param, the suggestion in errbuf (%s)", err);
    fxc_event_free(&ev);
    r = fxc_request(c, "{\"op\":\"frobnicate\",\"id\":\"mine\"}", &ev, 10000, err, sizeof err);
    check(r == 1 && !strcmp(ev.code, "unknown_op") && ev.id > 0, "fxc_request of an unknown op: code unknown_op, our id");
    fxc_event_free(&ev);
    check(fxc_send(c, "{\"op\":", err, sizeof err) == -1 && strstr(err, "not valid JSON"), "fxc_send of cut JSON: %s", err);
    check(fxc_send(c, "[1]", err, sizeof err) == -1 && strstr(err, "\"op\""), "fxc_send of an array: %s", err);
    check(fxc_set(c, "energy", "[1]", err, sizeof err) == -1 && strstr(err, "object"), "fxc_set of an array: %s", err);
    check(fxc_subscribe(c, NULL, 0, err, sizeof err) == -1 && strstr(err, "no stream"), "fxc_subscribe(NULL): %s", err);
    check(fxc_wait(c, -1, &ev, 1000, err, sizeof err) == -1 && fxc_wait(c, 1000, &ev, 1000, err, sizeof err) == -1 &&
              strstr(err, "no request has id 1000"),
          "fxc_wait for an id no request got: -1 at once (%s)", err);
    id = fxc_get(c, "energy", err, sizeof err);
    r = fxc_wait(c, id, &ev, 10000, err, sizeof err);
    check(r == 0 && ev.rev == rev + 1, "the connection is still usable after refused input");
    fxc_event_free(&ev);
}

/* A second client's subscription sees the first one's set as an event, then the frames of
 * energy named by stream, its light rig decoded. */
static void check_two_clients(const char *url, struct fxc_client *a)
{
    struct fxc_client *b;
    struct fxc_event ev, reply;
    struct fxc_rig_segment segs[FXC_RIG_MAX_SEGMENTS];
    struct fxc_rig rig = { .capacity = FXC_RIG_MAX_SEGMENTS, .segments = segs };
    struct want_frame rigs = { "energy", FXS_KIND_LIGHT_RIG };
    char err[256];
    int r = fxc_connect(&b, url, NULL, 10000, err, sizeof err);
    check(r == 0 && fxc_state(b) == FXC_OPEN, "fxc_connect: open (%s)", r ? err : "");
    if (r) return;
    int64_t id = fxc_subscribe(b, "energy", 0, err, sizeof err);
    r = fxc_wait(b, id, &ev, 10000, err, sizeof err);
    uint32_t channel = ev.channel;
    check(r == 0 && !strcmp(ev.op, "subscribed") && channel > 0, "subscribed reply with its channel (%u)", channel);
    fxc_event_free(&ev);
    id = fxc_set_number(a, "energy", "alpha", 3, err, sizeof err);
    r = fxc_wait(a, id, &reply, 10000, err, sizeof err);
    check(r == 0, "the other client's set");
    r = wait_event(b, &ev, 10000, is_op, "params");
    check(r == 1 && ev.id == 0 && !strcmp(ev.stream, "energy") && ev.rev == reply.rev,
          "it arrives as a params event without id, rev %" PRId64, ev.rev);
    fxc_event_free(&ev);
    fxc_event_free(&reply);
    r = wait_event(b, &ev, 20000, is_frame, &rigs);
    check(r == 1 && ev.channel == channel, "energy frames come named by their stream, on the subscribed channel");
    r = r == 1 ? fxc_decode_rig(&ev.header, ev.payload, &rig, err, sizeof err) : -1;
    check(r == 0 && rig.count == (int)ev.header.count_or_width && rig.count > 0 && rig.has_constants &&
              rig.constants.n_bands >= 1,
          "fxc_decode_rig: %d segments as the header says, constants (%s)", rig.count, r ? err : "");
    fxc_event_free(&ev);
    fxc_close(b);
}

/* Particle and look-up-table frames decoded into the caller's arrays; a wrong decoder refused. */
static void check_frames(struct fxc_client *c)
{
    struct fxc_event ev;
    struct want_frame flame = { "flame", FXS_KIND_PARTICLES }, eye = { "eye", FXS_KIND_LUT };
    char err[256];
    int ok = 1, r;
    check(fxc_subscribe(c, "flame", 10, err, sizeof err) > 0, "a typed subscribe to flame (max_fps 10)");
    for (int i = 0; i < 3 && ok; i++) {
        struct fxc_particles p = { 0 };
        ok = wait_event(c, &ev, 20000, is_frame, &flame) == 1;
        if (!ok) break;
        p.capacity = ev.header.count_or_width;
        p.xyz = malloc(sizeof(float) * 3 * (p.capacity + 1));
        p.temperature = malloc(sizeof(float) * (p.capacity + 1));
        p.flags = malloc(p.capacity + 1);
        ok = fxc_decode_particles(&ev.header, ev.payload, &p, err, sizeof err) == 0 && p.count == p.capacity;
        printf("info flame frame %" PRIu64 ": %u particles\n", ev.header.seq, p.count);
        if (!i) {
            struct fxc_rig rig = { 0 };
            check(fxc_decode_rig(&ev.header, ev.payload, &rig, err, sizeof err) == -1 &&
                      strstr(err, "not a light-rig frame"),
                  "fxc_decode_rig refuses a particle frame: %s", err);
        }
        free(p.xyz);
        free(p.temperature);
        free(p.flags);
        fxc_event_free(&ev);
    }
    check(ok, "3 flame frames decode, count as in the header");
    check(fxc_subscribe(c, "eye", 0, err, sizeof err) > 0, "a typed subscribe to eye"); /* it sends on change only */
    r = wait_event(c, &ev, 30000, is_frame, &eye);
    struct fxc_lut lut = { 0 };
    struct fxc_lut_product prods[8] = { 0 };
    int d = r == 1 ? fxc_decode_lut(&ev.header, ev.payload, &lut, err, sizeof err) : -1;
    if (d == 1 && lut.count <= 8) {
        lut.products = prods;
        lut.capacity = 8;
        d = fxc_decode_lut(&ev.header, ev.payload, &lut, err, sizeof err);
        for (int i = 0; d == 1 && i < lut.count; i++) {
            prods[i].rgba_capacity = (size_t)prods[i].width * prods[i].height * 4;
            prods[i].rgba = malloc(prods[i].rgba_capacity + 1);
        }
        d = fxc_decode_lut(&ev.header, ev.payload, &lut, err, sizeof err);
    }
    int llut = -1;
    for (int i = 0; i < lut.count && i < 8; i++)
        if (!strcmp(prods[i].name, "LLUT")) llut = i;
    check(d == 0 && lut.count == 3 && llut >= 0 && prods[llut].width == ev.header.count_or_width &&
              prods[llut].height == ev.header.height,
          "fxc_decode_lut: 3 products, LLUT the header's size (%s)", d ? err : "");
    for (int i = 0; i < 8; i++) free(prods[i].rgba);
    fxc_event_free(&ev);
    int64_t id = fxc_unsubscribe(c, "flame", err, sizeof err);
    r = fxc_wait(c, id, &ev, 10000, err, sizeof err);
    check(r == 0 && !strcmp(ev.op, "unsubscribed"), "fxc_unsubscribe: the unsubscribed reply");
    fxc_event_free(&ev);
}

/* A frame of `kind` from `stream` in the engine encoding (codec 16). */
static int is_engine_frame(const struct fxc_event *ev, const void *arg)
{
    return is_frame(ev, arg) && ev->header.codec == FXS_CODEC_ENGINE;
}

/* The engine encoding as a native plugin reads it: fxc_subscribe_encoding, particles into
 * arrays without flags or fuel, the energy wave's texture as floats. */
static void check_engine(struct fxc_client *c)
{
    struct fxc_event ev;
    struct want_frame flame = { "flame", FXS_KIND_PARTICLES }, energy = { "energy", FXS_KIND_TEXTURE };
    char err[256];
    int64_t id = fxc_subscribe_encoding(c, "flame", 0, FXS_ENCODING_ENGINE, err, sizeof err);
    int r = fxc_wait(c, id, &ev, 10000, err, sizeof err);
    check(r == 0 && !strcmp(ev.op, "subscribed") && strstr(ev.json, "\"encoding\":\"engine\""),
          "fxc_subscribe_encoding(flame, FXS_ENCODING_ENGINE): subscribed in the engine encoding (%s)", r ? err : "");
    fxc_event_free(&ev);
    check(fxc_subscribe_encoding(c, "flame", 0, (enum fxs_encoding)7, err, sizeof err) == -1 && strstr(err, "encoding 7"),
          "an unknown encoding is refused before sending: %s", err);
    r = wait_event(c, &ev, 20000, is_engine_frame, &flame);
    struct fxc_particles p = { 0 };
    int d = r == 1 ? fxc_decode_particles(&ev.header, ev.payload, &p, err, sizeof err) : -1;
    if (d == 1) {
        p.capacity = p.count;
        p.xyz = malloc(sizeof(float) * 3 * (p.capacity + 1));
        p.temperature = malloc(sizeof(float) * (p.capacity + 1));
        d = fxc_decode_particles(&ev.header, ev.payload, &p, err, sizeof err);
    }
    /* Kelvin at the default flame's scale: no colder than the air (T_amb >= 250 K), no hotter than
     * a source (T_init 2000 K) plus all the heat its fuel releases, k_pt / k_cf x F_init =
     * 500 / 5 x 100 K, and a half float's rounding (8 K there). Hot spots reach 9000 K. */
    int sane = d == 0 && p.count > 0;
    for (uint32_t i = 0; sane && i < p.count; i++) sane = p.temperature[i] >= 250 && p.temperature[i] <= 12008;
    check(sane && p.count == ev.header.count_or_width && !p.has_flags && !p.has_fuel,
          "fxc_decode_particles reads an engine frame without flag or fuel arrays: %u particles, T in kelvin (%s)",
          p.count, d ? err : "");
    free(p.xyz);
    free(p.temperature);
    fxc_event_free(&ev);
    check(fxc_subscribe_encoding(c, "energy", 0, FXS_ENCODING_ENGINE, err, sizeof err) > 0, "energy in the engine encoding");
    r = wait_event(c, &ev, 20000, is_engine_frame, &energy);
    struct fxc_texture t = { 0 };
    d = r == 1 ? fxc_decode_texture(&ev.header, ev.payload, &t, err, sizeof err) : -1;
    if (d == 1) {
        t.capacity = (size_t)t.width * t.height * t.channels;
        t.texels = malloc(sizeof(float) * t.capacity);
        d = fxc_decode_texture(&ev.header, ev.payload, &t, err, sizeof err);
    }
    check(d == 0 && t.width == ev.header.count_or_width && t.height == ev.header.height &&
              (t.channels == 1 || t.channels == 4),
          "fxc_decode_texture: %ux%u, %u channels, as the header says (%s)", t.width, t.height, t.channels, d ? err : "");
    free(t.texels);
    fxc_event_free(&ev);
    for (int i = 0; i < 2; i++) {
        id = fxc_unsubscribe(c, i ? "energy" : "flame", err, sizeof err);
        fxc_wait(c, id, &ev, 10000, err, sizeof err);
        fxc_event_free(&ev);
    }
}

/* A subset of the flame's particles cut to a budget (fxc_frame_total says from how many). */
static int is_subset_frame(const struct fxc_event *ev, const void *arg)
{
    return is_frame(ev, arg) && fxc_frame_total(ev) > ev->header.count_or_width;
}

/* A particle budget: fxc_subscribe_budget asks for one, the reply says the step served, frames
 * come as subsets whose total fxc_frame_total reads, and they decode as any kind 1 frame. */
static void check_budget(struct fxc_client *c)
{
    struct fxc_event ev;
    struct want_frame flame = { "flame", FXS_KIND_PARTICLES };
    char err[256];
    int64_t id = fxc_subscribe_budget(c, "flame", 0, FXS_ENCODING_DEFAULT, 1500, err, sizeof err);
    int r = fxc_wait(c, id, &ev, 10000, err, sizeof err);
    check(r == 0 && !strcmp(ev.op, "subscribed") && strstr(ev.json, "\"max_particles\":1000"),
          "fxc_subscribe_budget(flame, 1500): served as 1000 (%s)", r ? err : ev.json);
    fxc_event_free(&ev);
    check(fxc_subscribe_budget(c, "flame", 0, FXS_ENCODING_DEFAULT, 999, err, sizeof err) == -1 && strstr(err, "999"),
          "a budget below 1000 is refused before sending: %s", err);
    r = wait_event(c, &ev, 20000, is_subset_frame, &flame);
    struct fxc_particles p = { .capacity = 1000 };
    p.xyz = malloc(sizeof(float) * 3 * 1000);
    p.temperature = malloc(sizeof(float) * 1000);
    p.flags = malloc(1000);
    int d = r == 1 ? fxc_decode_particles(&ev.header, ev.payload, &p, err, sizeof err) : -1;
    check(r == 1 && d == 0 && p.count == 1000 && ev.header.count_or_width == 1000 && fxc_frame_total(&ev) > 1000,
          "a subset of 1000 decodes into arrays of 1000, fxc_frame_total %u (%s)", r == 1 ? fxc_frame_total(&ev) : 0,
          d ? err : "");
    free(p.xyz);
    free(p.temperature);
    free(p.flags);
    fxc_event_free(&ev);
    id = fxc_subscribe_budget(c, "flame", 0, FXS_ENCODING_DEFAULT, 0, err, sizeof err);
    r = fxc_wait(c, id, &ev, 10000, err, sizeof err);
    check(r == 0 && !strstr(ev.json, "max_particles"), "fxc_subscribe_budget(..., 0) removes the budget");
    fxc_event_free(&ev);
    id = fxc_unsubscribe(c, "flame", err, sizeof err);
    fxc_wait(c, id, &ev, 10000, err, sizeof err);
    fxc_event_free(&ev);
}

/* The daemon stops: poll reports the end; an event taken before fxc_close outlives it. */
static void check_end(struct fxc_client *c, long pid)
{
    struct fxc_event held, ev;
    char err[256], copy[64];
    int64_t id = fxc_get(c, "flame", err, sizeof err);
    int held_r = fxc_wait(c, id, &held, 10000, err, sizeof err), r;
    check(held_r == 0, "a reply to hold");
    kill((pid_t)pid, SIGTERM);
    r = wait_event(c, &ev, 10000, is_op, "(none)");
    check(r == -1 && fxc_state(c) == FXC_CLOSED && (strstr(fxc_error(c), "closed") || strstr(fxc_error(c), "lost")),
          "the daemon stopping ends the connection: poll -1, closed (%s)", fxc_error(c));
    check(fxc_get(c, "flame", err, sizeof err) == -1, "a request on a closed connection: -1 (%s)", err);
    fxc_close(c);
    snprintf(copy, sizeof copy, "%.40s", held.json ? held.json : "");
    check(held_r == 0 && !strncmp(copy, "{\"op\":\"params\"", 14) && fxc_param_number(&held, "fps", &(double){ 0 }) == 0,
          "an event taken before fxc_close stays valid after it");
    fxc_event_free(&held);
}

static int log_lines;
static void count_line(int level, const char *line)
{
    (void)level;
    (void)line;
    log_lines++;
}

/* Connection failures as one line each, and fxc_set_log routing libwebsockets' log. */
static void check_failures_and_log(const char *url)
{
    struct fxc_client *c;
    char err[256], other[300];
    check(fxc_connect(&c, "http://127.0.0.1:1/", NULL, 1000, err, sizeof err) == -2 && !c && strstr(err, "bad URL"),
          "a bad URL: -2 (%s)", err);
    check(fxc_connect(&c, "ws://127.0.0.1:1/v1/ws", NULL, 5000, err, sizeof err) == -1 &&
              strstr(err, "connection refused"),
          "a closed port: -1 (%s)", err);
    snprintf(other, sizeof other, "%s/not/here", url);
    fxc_set_log(FXC_LOG_ERR | FXC_LOG_WARN | FXC_LOG_NOTICE, count_line);
    check(fxc_connect(&c, other, NULL, 5000, err, sizeof err) == -1 && strstr(err, "handshake failed"),
          "a wrong path: -1 (%s)", err);
    check(log_lines > 0, "fxc_set_log routes libwebsockets' log to the callback (%d lines)", log_lines);
    fxc_set_log(0, NULL);
}

int main(int argc, char **argv)
{
    struct fxc_client *a;
    double alpha = 0;
    int64_t rev = 0;
    if (argc != 3) {
        fprintf(stderr, "usage: fxc_api_check URL DAEMON_PID\n");
        return 2;
    }
    check(!strcmp(fxc_version(), FXC_VERSION), "fxc_version() is the header's %s", FXC_VERSION);
    if (!(a = check_open(argv[1], &alpha, &rev))) return 1;
    check_requests(a, rev);
    check_two_clients(argv[1], a);
    check_frames(a);
    check_engine(a);
    check_budget(a);
    check_failures_and_log(argv[1]);
    check_end(a, atol(argv[2]));
    printf("info longest fxc_poll(..., 0, ...) call: %.3f ms wall, %.3f ms CPU\n", longest_poll_ms,
           longest_poll_cpu_ms);
    return failed ? 1 : 0;
}
