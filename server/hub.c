/* hub.c — see hub.h. */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "clock.h"
#include "hub.h"
#include "log.h"

int hub_init(struct hub *hub, int max_streams, bool clustered)
{
    memset(hub, 0, sizeof *hub);
    pthread_condattr_t ca;
    pthread_condattr_init(&ca);
    pthread_condattr_setclock(&ca, CLOCK_MONOTONIC);
    pthread_mutex_init(&hub->mu, NULL);
    pthread_cond_init(&hub->cv, &ca);
    pthread_condattr_destroy(&ca);
    hub->max_streams = max_streams;
    hub->clustered = clustered;
    hub->next_channel = 1;
    return 0;
}

uint64_t hub_rev_from_json(const cJSON *v)
{
    bool ok = cJSON_IsNumber(v) && v->valuedouble >= 1 && v->valuedouble < HUB_REV_MAX &&
              v->valuedouble == floor(v->valuedouble);
    return ok ? (uint64_t)v->valuedouble : 0;
}

int hub_rev_check(const char *name, uint64_t rev, struct fx_err *err)
{
    if ((double)rev + 1 < HUB_REV_MAX) return 0;
    return fx_fail(err, "limit", "stream", "stream %s is at revision 10^15 - 1: no more changes (re-create it)", name);
}

void hub_free(struct hub *hub)
{
    hub_release_all(hub->streams, hub->n);
    pthread_mutex_destroy(&hub->mu);
    pthread_cond_destroy(&hub->cv);
}

/* Caller holds mu. */
static void hub_changed(struct hub *hub)
{
    hub->gen++;
    pthread_cond_broadcast(&hub->cv);
}

bool hub_valid_name(const char *name)
{
    size_t n = strlen(name);
    if (n == 0 || n >= STREAM_NAME_MAX) return false;
    for (size_t i = 0; i < n; i++) {
        char c = name[i];
        if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
              c == '-' || c == '.'))
            return false;
    }
    return true;
}

static int hub_index(const struct hub *hub, const char *name)
{
    for (int i = 0; i < hub->n; i++)
        if (strcmp(hub->streams[i]->name, name) == 0) return i;
    return -1;
}

int hub_create(struct hub *hub, const struct effect_ops *effect, const char *name, cJSON *params,
               uint64_t rev, struct fx_err *err)
{
    double fps;
    if (!hub_valid_name(name))
        return fx_fail(err, "bad_request", "stream",
                       "stream name must be 1-%d characters of A-Z a-z 0-9 _ . -", STREAM_NAME_MAX - 1);
    if (params_number(params, "fps", &fps)) /* effect_params makes every document: a bug */
        return fx_fail(err, "internal", "params", "stream \"%s\": parameters without fps", name);
    pthread_mutex_lock(&hub->mu);
    int rc = 0;
    if (hub_index(hub, name) >= 0)
        rc = fx_fail(err, "exists", "stream", "a stream named \"%s\" already exists", name);
    else if (hub->n >= hub->max_streams)
        rc = fx_fail(err, "limit", "stream", "stream limit reached (%d)", hub->max_streams);
    else if (hub->n == hub->cap) {
        int cap = hub->cap ? 2 * hub->cap : 8;
        struct stream **p = realloc(hub->streams, (size_t)cap * sizeof *p);
        if (!p) rc = fx_fail(err, "internal", NULL, "out of memory");
        else {
            hub->streams = p;
            hub->cap = cap;
        }
    }
    struct stream *s = rc ? NULL : calloc(1, sizeof *s);
    if (!rc && !s) rc = fx_fail(err, "internal", NULL, "out of memory");
    if (!rc) {
        atomic_init(&s->refs, 1);
        snprintf(s->name, sizeof s->name, "%s", name);
        s->effect = effect;
        s->channel = hub->next_channel++;
        s->params = params;
        s->fps = fps;
        s->rev = rev;
        s->params_gen = 1;
        s->lease = (struct stream_lease){.owned = !hub->clustered, .until = INFINITY};
        hist_init(&s->step_time, hist_step_bounds, hist_step_nb);
        hist_init(&s->encode_time, hist_step_bounds, hist_step_nb);
        hist_init(&s->frame_age, hist_age_bounds, hist_age_nb);
        hub->streams[hub->n++] = s;
        hub_changed(hub);
    }
    pthread_mutex_unlock(&hub->mu);
    return rc;
}

struct stream *hub_destroy(struct hub *hub, const char *name, struct fx_err *err)
{
    pthread_mutex_lock(&hub->mu);
    int i = hub_index(hub, name);
    struct stream *s = NULL;
    if (i < 0) {
        fx_fail(err, "unknown_stream", "stream", "no stream named \"%s\"", name);
    } else {
        s = hub->streams[i]; /* the table's reference passes to the caller */
        memmove(hub->streams + i, hub->streams + i + 1, (size_t)(hub->n - i - 1) * sizeof *hub->streams);
        hub->n--;
        s->destroyed = true;
        hub_changed(hub);
    }
    pthread_mutex_unlock(&hub->mu);
    return s;
}

struct stream *hub_find(struct hub *hub, const char *name)
{
    pthread_mutex_lock(&hub->mu);
    int i = hub_index(hub, name);
    struct stream *s = i >= 0 ? hub->streams[i] : NULL;
    if (s) stream_ref(s);
    pthread_mutex_unlock(&hub->mu);
    return s;
}

struct stream **hub_snapshot(struct hub *hub, int *n)
{
    pthread_mutex_lock(&hub->mu);
    struct stream **out = malloc((size_t)(hub->n ? hub->n : 1) * sizeof *out);
    *n = out ? hub->n : 0;
    for (int i = 0; i < *n; i++) {
        out[i] = hub->streams[i];
        stream_ref(out[i]);
    }
    pthread_mutex_unlock(&hub->mu);
    return out;
}

void hub_release_all(struct stream **streams, int n)
{
    for (int i = 0; i < n; i++) stream_unref(streams[i]);
    free(streams);
}

void stream_ref(struct stream *s) { atomic_fetch_add(&s->refs, 1); }

void stream_unref(struct stream *s)
{
    if (!s || atomic_fetch_sub(&s->refs, 1) != 1) return;
    for (int form = 0; form < BUDGET_FORMS; form++)
        for (int k = 0; k <= FXS_KIND_MAX; k++) frame_unref(s->latest[form][k]);
    cJSON_Delete(s->params);
    free(s);
}

void hub_set_params(struct hub *hub, struct stream *s, cJSON *doc, uint64_t rev)
{
    pthread_mutex_lock(&hub->mu);
    cJSON_Delete(s->params);
    s->params = doc;
    if (params_number(doc, "fps", &s->fps)) /* effect_params makes every document: a bug */
        log_error("stream %s: parameters without fps; keeping %g frames/s", s->name, s->fps);
    s->rev = rev;
    s->params_gen++;
    hub_changed(hub);
    pthread_mutex_unlock(&hub->mu);
}

cJSON *hub_get_params(struct hub *hub, struct stream *s, uint64_t *rev)
{
    pthread_mutex_lock(&hub->mu);
    cJSON *doc = cJSON_Duplicate(s->params, 1);
    *rev = s->rev;
    pthread_mutex_unlock(&hub->mu);
    return doc;
}

void hub_status(struct hub *hub, struct stream *s, struct stream_status *out)
{
    pthread_mutex_lock(&hub->mu);
    *out = (struct stream_status){.rev = s->rev, .params_gen = s->params_gen, .reset_gen = s->reset_gen,
                                  .error_gen = s->error_gen, .lease = s->lease,
                                  .subscribers = s->subscribers, .fps = s->fps, .realtime = s->realtime,
                                  .achieved_fps = s->achieved_fps, .engine_share = s->engine_share,
                                  .failing = s->failing};
    memcpy(out->subscribers_by, s->subscribers_by, sizeof out->subscribers_by);
    memcpy(out->error, s->error, sizeof out->error);
    pthread_mutex_unlock(&hub->mu);
}

void hub_set_realtime(struct hub *hub, struct stream *s, double factor)
{
    pthread_mutex_lock(&hub->mu);
    s->realtime = factor;
    pthread_mutex_unlock(&hub->mu);
}

void hub_set_pace(struct hub *hub, struct stream *s, double achieved_fps, double engine_share)
{
    pthread_mutex_lock(&hub->mu);
    s->achieved_fps = achieved_fps;
    s->engine_share = engine_share;
    pthread_mutex_unlock(&hub->mu);
}

uint64_t hub_generation(struct hub *hub, bool *stopping)
{
    pthread_mutex_lock(&hub->mu);
    uint64_t gen = hub->gen;
    *stopping = hub->stopping;
    pthread_mutex_unlock(&hub->mu);
    return gen;
}

void hub_request_reset(struct hub *hub, struct stream *s)
{
    pthread_mutex_lock(&hub->mu);
    s->reset_gen++;
    hub_changed(hub);
    pthread_mutex_unlock(&hub->mu);
}

void hub_set_lease(struct hub *hub, struct stream *s, const struct stream_lease *lease)
{
    pthread_mutex_lock(&hub->mu);
    const struct stream_lease *was = &s->lease;
    /* a renewal that only pushes `until` further needs no engine wake-up */
    bool news = was->owned != lease->owned || was->gen != lease->gen || was->remote_demand != lease->remote_demand ||
                was->until <= clock_now();
    s->lease = *lease;
    if (news) hub_changed(hub);
    pthread_mutex_unlock(&hub->mu);
}

void hub_add_subscriber(struct hub *hub, struct stream *s, int form, int delta)
{
    pthread_mutex_lock(&hub->mu);
    s->subscribers += delta;
    s->subscribers_by[form] += delta;
    hub_changed(hub);
    pthread_mutex_unlock(&hub->mu);
}

/* The slot of a kind's frames for a subscription of a form (budget_kind_form). */
static struct frame **hub_slot(struct stream *s, int form, int kind)
{
    return &s->latest[budget_kind_form(form, kind)][kind];
}

void hub_publish(struct hub *hub, struct stream *s, int form, struct frame *f, bool again)
{
    struct frame **slot = hub_slot(s, form, f->hdr.kind);
    pthread_mutex_lock(&hub->mu);
    struct frame *old = *slot;
    *slot = f;
    pthread_mutex_unlock(&hub->mu);
    frame_unref(old);
    if (!again) atomic_fetch_add(&s->frames_produced, 1);
    if (hub->notify) hub->notify(hub->notify_ctx);
}

void hub_drop(struct hub *hub, struct stream *s, int form, int kind, uint64_t seq)
{
    struct frame **slot = hub_slot(s, form, kind), *old = NULL;
    pthread_mutex_lock(&hub->mu);
    if (*slot && (*slot)->hdr.seq < seq) {
        old = *slot;
        *slot = NULL;
    }
    pthread_mutex_unlock(&hub->mu);
    frame_unref(old);
}

void hub_stream_error(struct hub *hub, struct stream *s, const char *message)
{
    pthread_mutex_lock(&hub->mu);
    snprintf(s->error, sizeof s->error, "%s", message);
    s->error_gen++;
    s->failing = true;
    pthread_mutex_unlock(&hub->mu);
    if (hub->notify) hub->notify(hub->notify_ctx);
}

void hub_stream_recovered(struct hub *hub, struct stream *s)
{
    pthread_mutex_lock(&hub->mu);
    s->failing = false;
    pthread_mutex_unlock(&hub->mu);
}

struct frame *hub_latest(struct hub *hub, struct stream *s, int form, int kind)
{
    pthread_mutex_lock(&hub->mu);
    struct frame *f = *hub_slot(s, form, kind);
    if (f) frame_ref(f);
    pthread_mutex_unlock(&hub->mu);
    return f;
}

uint64_t hub_latest_seq_of(struct hub *hub, struct stream *s, int form, int kind)
{
    pthread_mutex_lock(&hub->mu);
    struct frame *f = *hub_slot(s, form, kind);
    uint64_t seq = f ? f->hdr.seq : 0;
    pthread_mutex_unlock(&hub->mu);
    return seq;
}

uint64_t hub_latest_seq(struct hub *hub, struct stream *s, int kind)
{
    uint64_t seq = 0;
    pthread_mutex_lock(&hub->mu);
    for (int form = 0; form < BUDGET_FORMS; form++) {
        const struct frame *f = s->latest[form][kind];
        if (f && f->hdr.seq > seq) seq = f->hdr.seq;
    }
    pthread_mutex_unlock(&hub->mu);
    return seq;
}

void hub_wait(struct hub *hub, uint64_t seen_gen, double deadline)
{
    struct timespec ts;
    ts.tv_sec = (time_t)floor(deadline);
    ts.tv_nsec = (long)((deadline - floor(deadline)) * 1e9);
    pthread_mutex_lock(&hub->mu);
    while (hub->gen == seen_gen && !hub->stopping)
        if (pthread_cond_timedwait(&hub->cv, &hub->mu, &ts)) break;
    pthread_mutex_unlock(&hub->mu);
}

void hub_stop(struct hub *hub)
{
    pthread_mutex_lock(&hub->mu);
    hub->stopping = true;
    hub_changed(hub);
    pthread_mutex_unlock(&hub->mu);
}
