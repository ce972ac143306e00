/* fxctl_sub.c — see fxctl_sub.h. */
#include "fxctl_sub.h"

#include <stdio.h>
#include <string.h>
#include <time.h>

#include <cjson/cJSON.h>

#include "fxctl_save.h"

#define FXCTL_STALE_MS 1000 /* a first frame older than this gets a note */

struct fxctl_sub {
    const struct fxctl_sub_opts *o;
    uint32_t channel;
    long got;                        /* steps (frames of o->kind) counted */
    int done;
    int64_t deadline_ms;             /* for the next step */
    int64_t last_frame_ms;           /* when the current step's latest frame came */
    double step_time;                /* the current step's sim_time */
    unsigned step_kinds;             /* a bit per kind: the current step's frames */
    unsigned earlier_kinds;          /* ... the earlier steps' */
    long by_kind[FXS_KIND_MAX + 1];  /* frames of the stream per kind, filtered ones too; [0]: unknown kinds */
};

static int64_t fxctl_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

static const char *fxctl_kind_name(unsigned kind)
{
    static const char *const names[] = { "unknown", "particles", "texture", "light rig", "look-up table" };
    return names[kind <= FXS_KIND_MAX ? kind : 0];
}

static unsigned fxctl_kind_bit(unsigned kind) { return 1u << (kind <= FXS_KIND_MAX ? kind : 0); }

/* Whether h opens a step: the first frame, another sim_time, or a kind the step already has. */
static int fxctl_new_step(const struct fxctl_sub *s, const struct fxs_header *h)
{
    return !s->step_kinds || h->sim_time != s->step_time || (s->step_kinds & fxctl_kind_bit(h->kind));
}

/* Counts h: a step (or a frame of --kind) more, or another frame of the current step. Returns
 * 0 when h is not to be printed: another stream's, a kind filtered out, or the step after the
 * last (which ends the last one). */
static int fxctl_count(struct fxctl_sub *s, const struct fxs_header *h, int64_t now)
{
    if (h->channel != s->channel) return 0;
    s->by_kind[h->kind <= FXS_KIND_MAX ? h->kind : 0]++;
    if (s->o->kind && h->kind != s->o->kind) return 0;
    if (s->o->kind || fxctl_new_step(s, h)) {
        if (s->got == s->o->count) {
            s->done = 1;
            return 0;
        }
        s->got++;
        s->earlier_kinds |= s->step_kinds;
        s->step_kinds = 0;
        s->step_time = h->sim_time;
        s->deadline_ms = now + s->o->timeout_ms;
    }
    s->step_kinds |= fxctl_kind_bit(h->kind);
    s->last_frame_ms = now;
    /* the last step is complete once it has the kinds of the earlier ones */
    if (s->got == s->o->count && (s->o->kind || (s->earlier_kinds && (s->step_kinds & s->earlier_kinds) == s->earlier_kinds)))
        s->done = 1;
    return 1;
}

static int fxctl_on_frame(struct fxctl_sub *s, const struct fxc_event *ev)
{
    char line[1024];
    int first = !s->got;
    if (!fxctl_count(s, &ev->header, fxctl_now_ms())) return 0;
    fxctl_frame_line(line, sizeof line, s->o->stream, ev);
    printf("%s\n", line);
    fflush(stdout);
    if (first && fxctl_age_ms(ev) > FXCTL_STALE_MS)
        fprintf(stderr, "fxctl: note: the first frame is %.1f s old (the stream's newest, sent at once on subscribe: it "
                        "only sends on change, or it is paused)\n", fxctl_age_ms(ev) / 1000);
    return s->o->out_dir && fxctl_save_frame(s->o->out_dir, s->o->stream, ev, line) ? 1 : 0;
}

/* Prints the stream's params events; fails when the stream goes away. */
static int fxctl_on_event(struct fxctl_sub *s, const struct fxc_event *ev)
{
    if (!ev->stream || strcmp(ev->stream, s->o->stream)) return 0;
    if (!strcmp(ev->op, "params")) {
        printf("%s\n", ev->json);
        fflush(stdout);
    } else if (!strcmp(ev->op, "unsubscribed")) {
        cJSON *j = cJSON_Parse(ev->json);
        const char *why = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(j, "reason"));
        fprintf(stderr, "fxctl: unsubscribed from stream \"%s\" (%s) after %ld of %ld %s\n", s->o->stream,
                why ? why : "no reason given", s->got, s->o->count, s->o->kind ? "frames" : "steps");
        cJSON_Delete(j);
        return 1;
    } else if (!strcmp(ev->op, "error")) {
        fprintf(stderr, "fxctl: stream \"%s\" reported: %s\n", s->o->stream, ev->json);
    }
    return 0;
}

/* The timeout's one line: what was awaited and what the stream sent instead. */
static void fxctl_timeout(const struct fxctl_sub *s)
{
    const struct fxctl_sub_opts *o = s->o;
    char sent[256] = "";
    size_t n = 0;
    for (unsigned k = 1; k <= FXS_KIND_MAX + 1 && n < sizeof sent; k++) { /* kinds 1.., unknown ones last */
        unsigned i = k % (FXS_KIND_MAX + 1);
        if (s->by_kind[i])
            n += (size_t)snprintf(sent + n, sizeof sent - n, "%s%ld of kind %u (%s)", n ? ", " : "", s->by_kind[i], i,
                                  fxctl_kind_name(i));
    }
    fprintf(stderr, "fxctl: timeout after %d ms waiting for %s %ld of %ld of \"%s\"", o->timeout_ms,
            o->kind ? "frame" : "step", s->got + 1, o->count, o->stream);
    if (o->kind && !s->by_kind[o->kind])
        fprintf(stderr, ": no frame of kind %d (%s) came", o->kind, fxctl_kind_name((unsigned)o->kind));
    fprintf(stderr, "%s%s\n", sent[0] ? "; the stream sent " : "; no frame came", sent);
}

int fxctl_subscribe(struct fxc_client *c, const struct fxctl_sub_opts *o, uint32_t channel)
{
    struct fxctl_sub s = { .o = o, .channel = channel, .deadline_ms = fxctl_now_ms() + o->timeout_ms };
    char err[512];
    int r = 0;
    while (!r && !s.done) {
        struct fxc_event ev;
        int64_t now = fxctl_now_ms(), until = s.deadline_ms;
        int last = s.got == o->count, n; /* the last step began: wait only for the rest of it */
        if (last && s.last_frame_ms + FXCTL_SETTLE_MS < until) until = s.last_frame_ms + FXCTL_SETTLE_MS;
        n = fxc_poll(c, &ev, until > now ? (int)(until - now) : 0, err, sizeof err);
        if (n == 0 && last) break;
        if (n == 0) fxctl_timeout(&s);
        if (n < 0) fprintf(stderr, "fxctl: %s\n", err);
        if (n <= 0) return 1;
        r = ev.type == FXC_EVENT_FRAME ? fxctl_on_frame(&s, &ev) : fxctl_on_event(&s, &ev);
        fxc_event_free(&ev);
    }
    return r;
}
