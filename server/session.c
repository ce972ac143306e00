/* session.c — see session.h. One function per op; each validates everything first,
 * then changes state in one step, then replies. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "budget.h"
#include "clock.h"
#include "effect.h"
#include "log.h"
#include "ocl.h"
#include "session.h"
#include "json_strict.h"
#include "store.h"
#include "suggest.h"

#define SESSION_MAX_AUTH_FAILURES 5 /* wrong tokens on one connection before it is closed */

void session_send(struct session *ss, cJSON *msg)
{
    char *text = cJSON_PrintUnformatted(msg);
    cJSON_Delete(msg);
    if (!text) return;
    size_t len = strlen(text);
    const struct limits *l = &ss->srv->cfg.limits;
    bool event = !ss->replying;
    if (event && (ss->q_count >= l->max_queued_messages || ss->q_event_bytes + len > (size_t)l->max_queued_bytes)) {
        /* The peer is not reading what it is sent: close rather than grow without bound (in
         * messages, and in bytes: 60 subscribers of a stream set 100 times a second). Replies
         * are bounded by not reading requests meanwhile (session_backlogged). */
        ss->kill = "messages not read";
        free(text);
        if (ss->srv->wake) ss->srv->wake(ss);
        return;
    }
    struct outmsg *m = malloc(sizeof *m + FRAME_HEADROOM + len);
    if (m) {
        m->next = NULL;
        m->len = len;
        m->event = event;
        memcpy(m->data + FRAME_HEADROOM, text, len);
        if (ss->q_tail) ss->q_tail->next = m;
        else ss->q_head = m;
        ss->q_tail = m;
        ss->q_count++;
        ss->q_bytes += len;
        if (event) ss->q_event_bytes += len;
    }
    free(text);
    if (ss->srv->wake) ss->srv->wake(ss);
}

bool session_backlogged(const struct session *ss)
{
    const struct limits *l = &ss->srv->cfg.limits;
    return ss->q_bytes > (size_t)l->max_queued_bytes || ss->q_count >= l->max_queued_messages;
}

struct outmsg *session_pop(struct session *ss)
{
    struct outmsg *m = ss->q_head;
    if (!m) return NULL;
    ss->q_head = m->next;
    if (!ss->q_head) ss->q_tail = NULL;
    ss->q_count--;
    ss->q_bytes -= m->len;
    if (m->event) ss->q_event_bytes -= m->len;
    return m;
}

/* The request's id as it goes back: strings as they came; numbers as the shortest text that
 * reads back as the same double (cJSON's own printing keeps 15 digits when they are "close
 * enough", so 9007199254740991 came back as 9.00719925474099e+15). */
static cJSON *session_id_copy(const cJSON *id)
{
    if (!cJSON_IsNumber(id)) return cJSON_Duplicate(id, 1);
    char text[32];
    for (int digits = 15; digits <= 17; digits++) {
        snprintf(text, sizeof text, "%.*g", digits, id->valuedouble);
        if (strtod(text, NULL) == id->valuedouble) break;
    }
    return cJSON_CreateRaw(text);
}

/* A reply object with the request's id echoed. */
static cJSON *session_reply(const char *op, const cJSON *id)
{
    cJSON *r = cJSON_CreateObject();
    cJSON_AddStringToObject(r, "op", op);
    if (id) cJSON_AddItemToObject(r, "id", session_id_copy(id));
    return r;
}

static void session_error(struct session *ss, const cJSON *id, const struct fx_err *err)
{
    cJSON *r = session_reply("error", id);
    cJSON_AddStringToObject(r, "code", err->code);
    cJSON_AddStringToObject(r, "message", err->message);
    if (err->param[0]) cJSON_AddStringToObject(r, "param", err->param);
    atomic_fetch_add(&ss->srv->counters.errors_out, 1);
    session_send(ss, r);
}

static cJSON *session_hello(struct server *srv)
{
    const struct limits *l = &srv->cfg.limits;
    cJSON *h = session_reply("hello", NULL);
    cJSON_AddStringToObject(h, "protocol", "fxstream.v1");
    cJSON_AddStringToObject(h, "server", "fxstreamd/" FX_VERSION);
    cJSON_AddStringToObject(h, "device", srv->ocl ? ocl_device_name(srv->ocl) : "none");
    cJSON *names = cJSON_AddArrayToObject(h, "effects");
    for (const struct effect_ops *const *e = effect_all(); *e; e++)
        cJSON_AddItemToArray(names, cJSON_CreateString((*e)->name));
    cJSON *encs = cJSON_AddArrayToObject(h, "encodings");
    for (int i = 0; i < FXS_ENCODING_COUNT; i++)
        cJSON_AddItemToArray(encs, cJSON_CreateString(fxs_encoding_name((enum fxs_encoding)i)));
    cJSON *lim = cJSON_AddObjectToObject(h, "limits");
    cJSON_AddNumberToObject(lim, "max_connections", l->max_connections);
    cJSON_AddNumberToObject(lim, "max_queued_messages", l->max_queued_messages);
    cJSON_AddNumberToObject(lim, "max_queued_bytes", l->max_queued_bytes);
    cJSON_AddNumberToObject(lim, "max_message_bytes", l->max_message_bytes);
    cJSON_AddNumberToObject(lim, "max_json_depth", l->max_json_depth);
    cJSON_AddNumberToObject(lim, "max_streams", l->max_streams);
    cJSON_AddNumberToObject(lim, "max_subscriptions", l->max_subscriptions);
    cJSON_AddNumberToObject(lim, "max_control_per_sec", l->max_control_per_sec);
    return h;
}

static void session_add_auth(cJSON *hello, const struct session *ss)
{
    cJSON *a = cJSON_AddObjectToObject(hello, "auth");
    cJSON_AddBoolToObject(a, "required", ss->srv->cfg.access.ntokens > 0);
    cJSON_AddStringToObject(a, "role", access_role_name(ss->role));
}

void session_open(struct session *ss, struct server *srv, enum access_role role)
{
    memset(ss, 0, sizeof *ss);
    ss->srv = srv;
    ss->role = role;
    ss->tokens = srv->cfg.limits.max_control_per_sec;
    ss->last_refill = clock_now();
    ss->next = srv->sessions;
    if (srv->sessions) srv->sessions->prev = ss;
    srv->sessions = ss;
    srv->nsessions++;
    atomic_fetch_add(&srv->counters.connections_total, 1);
    cJSON *hello = session_hello(srv);
    session_add_auth(hello, ss);
    session_send(ss, hello);
}

static void session_drop_sub(struct session *ss, int i)
{
    hub_add_subscriber(&ss->srv->hub, ss->subs[i].s, ss->subs[i].form, -1);
    stream_unref(ss->subs[i].s);
    ss->subs[i] = ss->subs[--ss->nsubs];
}

void session_close(struct session *ss)
{
    while (ss->nsubs) session_drop_sub(ss, ss->nsubs - 1);
    free(ss->subs);
    struct outmsg *m;
    while ((m = session_pop(ss))) free(m);
    frame_unref(ss->cur);
    if (ss->cur_stream) stream_unref(ss->cur_stream);
    fx_buf_free(&ss->rx);
    if (ss->prev) ss->prev->next = ss->next;
    else ss->srv->sessions = ss->next;
    if (ss->next) ss->next->prev = ss->prev;
    ss->srv->nsessions--;
}

/* ---- request field access: every field is checked for presence and type ---- */

/* Fails unless every member of req is one of the allowed names (besides op and id). */
static int session_only(const cJSON *req, const char *op, const char *const *allowed, struct fx_err *err)
{
    for (const cJSON *e = req->child; e; e = e->next) {
        if (!strcmp(e->string, "op") || !strcmp(e->string, "id")) continue;
        bool ok = false;
        for (const char *const *a = allowed; *a && !ok; a++) ok = !strcmp(*a, e->string);
        if (!ok) return fx_fail(err, "bad_request", e->string, "unknown field \"%s\" for op \"%s\"", e->string, op);
    }
    return 0;
}

static const char *session_str(const cJSON *req, const char *name, struct fx_err *err)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(req, name);
    if (!v) {
        fx_fail(err, "bad_request", name, "missing field \"%s\"", name);
        return NULL;
    }
    if (!cJSON_IsString(v)) {
        fx_fail(err, "bad_request", name, "field \"%s\" must be a string", name);
        return NULL;
    }
    return v->valuestring;
}

/* The stream named by req's "stream" field, referenced, or NULL with err. */
static struct stream *session_stream(struct session *ss, const cJSON *req, struct fx_err *err)
{
    const char *name = session_str(req, "stream", err);
    if (!name) return NULL;
    struct stream *s = hub_find(&ss->srv->hub, name);
    if (!s) {
        struct suggest sg;
        char hint[96];
        int n;
        struct stream **all = hub_snapshot(&ss->srv->hub, &n);
        suggest_init(&sg, name);
        for (int i = 0; i < n; i++) suggest_offer(&sg, all[i]->name);
        fx_fail(err, "unknown_stream", "stream", "no stream named \"%s\"%s", name, suggest_text(&sg, hint, sizeof hint));
        hub_release_all(all, n);
    }
    return s;
}

static int session_find_sub(const struct session *ss, const struct stream *s)
{
    for (int i = 0; i < ss->nsubs; i++)
        if (ss->subs[i].s == s) return i;
    return -1;
}

/* ---- ops ---- */

static int session_op_list(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {NULL};
    if (session_only(req, "list", allowed, err)) return -1;
    cJSON *r = session_reply("list", id);
    cJSON *arr = cJSON_AddArrayToObject(r, "streams");
    int n;
    struct stream **all = hub_snapshot(&ss->srv->hub, &n);
    for (int i = 0; i < n; i++) {
        cJSON *o = cJSON_CreateObject();
        struct stream_status st;
        hub_status(&ss->srv->hub, all[i], &st);
        cJSON_AddStringToObject(o, "stream", all[i]->name);
        cJSON_AddStringToObject(o, "effect", all[i]->effect->name);
        cJSON_AddNumberToObject(o, "subscribers", st.subscribers);
        cJSON_AddNumberToObject(o, "rev", (double)st.rev);
        cJSON_AddNumberToObject(o, "fps", st.fps);
        cJSON_AddItemToArray(arr, o);
    }
    hub_release_all(all, n);
    session_send(ss, r);
    return 0;
}

static const struct effect_ops *session_effect(const cJSON *req, struct fx_err *err)
{
    const char *name = session_str(req, "effect", err);
    if (!name) return NULL;
    const struct effect_ops *ops = effect_find(name);
    if (!ops) {
        struct suggest sg;
        char hint[96];
        suggest_init(&sg, name);
        for (const struct effect_ops *const *e = effect_all(); *e; e++) suggest_offer(&sg, (*e)->name);
        fx_fail(err, "unknown_effect", "effect", "no effect named \"%s\"%s", name, suggest_text(&sg, hint, sizeof hint));
    }
    return ops;
}

static int session_op_describe(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"effect", NULL};
    if (session_only(req, "describe", allowed, err)) return -1;
    const struct effect_ops *ops = session_effect(req, err);
    if (!ops) return -1;
    cJSON *r = session_reply("describe", id);
    cJSON_AddStringToObject(r, "effect", ops->name);
    cJSON_AddStringToObject(r, "doc", ops->doc);
    cJSON_AddItemToObject(r, "params", params_describe(ops->params));
    cJSON_AddItemToObject(r, "outputs", cJSON_Parse(ops->outputs_json));
    session_send(ss, r);
    return 0;
}

/* Sends a copy of the reply r, without its id, as an event to every connection but `except`
 * that may list streams, so their stream lists follow creates and destroys made elsewhere
 * (PROTOCOL.md §4). */
static void session_announce(struct server *srv, const struct session *except, const cJSON *r)
{
    cJSON *ev = cJSON_Duplicate(r, 1);
    cJSON_DeleteItemFromObjectCaseSensitive(ev, "id");
    for (struct session *o = srv->sessions; o; o = o->next)
        if (o != except && o->role >= ACCESS_VIEW) session_send(o, cJSON_Duplicate(ev, 1));
    cJSON_Delete(ev);
}

static cJSON *session_created_msg(const struct stream *s, const cJSON *id, uint64_t rev)
{
    cJSON *r = session_reply("created", id);
    cJSON_AddStringToObject(r, "stream", s->name);
    cJSON_AddStringToObject(r, "effect", s->effect->name);
    cJSON_AddNumberToObject(r, "rev", (double)rev);
    return r;
}

void session_event_created(struct server *srv, const struct session *except, const struct stream *s, uint64_t rev)
{
    cJSON *ev = session_created_msg(s, NULL, rev);
    session_announce(srv, except, ev);
    cJSON_Delete(ev);
}

static int session_op_create(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"effect", "stream", "params", NULL};
    if (session_only(req, "create", allowed, err)) return -1;
    const struct effect_ops *ops = session_effect(req, err);
    const char *name = ops ? session_str(req, "stream", err) : NULL;
    if (!name) return -1;
    cJSON *doc = effect_params(ops, NULL, cJSON_GetObjectItemCaseSensitive(req, "params"), err);
    if (!doc) return -1;
    cJSON *stored = cJSON_Duplicate(doc, 1); /* doc goes to the hub */
    if (hub_create(&ss->srv->hub, ops, name, doc, 1, err)) {
        cJSON_Delete(doc);
        cJSON_Delete(stored);
        return -1;
    }
    int rc = store_commit(ss->srv, &(struct store_change){.op = STORE_CREATE, .stream = name, .effect = ops->name,
                                                          .params = stored}, err);
    cJSON_Delete(stored);
    if (rc) { /* not yet announced nor subscribed: undone cleanly */
        stream_unref(hub_destroy(&ss->srv->hub, name, &(struct fx_err){0}));
        return -1;
    }
    struct stream *s = hub_find(&ss->srv->hub, name); /* only this thread adds and removes streams */
    log_info("stream %s created (effect %s)", name, ops->name);
    session_event_created(ss->srv, ss, s, 1);
    session_send(ss, session_created_msg(s, id, 1));
    stream_unref(s);
    return 0;
}

static void session_stream_gone(struct server *srv, struct stream *s)
{
    for (struct session *o = srv->sessions; o; o = o->next) {
        int i = session_find_sub(o, s);
        if (i < 0) continue;
        session_drop_sub(o, i);
        cJSON *ev = session_reply("unsubscribed", NULL);
        cJSON_AddStringToObject(ev, "stream", s->name);
        cJSON_AddStringToObject(ev, "reason", "destroyed");
        session_send(o, ev);
    }
}

void session_event_destroyed(struct server *srv, const struct session *except, struct stream *s)
{
    session_stream_gone(srv, s);
    cJSON *ev = session_reply("destroyed", NULL);
    cJSON_AddStringToObject(ev, "stream", s->name);
    session_announce(srv, except, ev);
    cJSON_Delete(ev);
}

static int session_op_destroy(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"stream", NULL};
    if (session_only(req, "destroy", allowed, err)) return -1;
    struct stream *s = session_stream(ss, req, err);
    if (!s) return -1;
    int rc = store_commit(ss->srv, &(struct store_change){.op = STORE_DESTROY, .stream = s->name}, err);
    stream_unref(s);
    const char *name = cJSON_GetObjectItemCaseSensitive(req, "stream")->valuestring;
    if (rc || !(s = hub_destroy(&ss->srv->hub, name, err))) return -1;
    session_event_destroyed(ss->srv, ss, s);
    stream_unref(s);
    log_info("stream %s destroyed", name);
    cJSON *r = session_reply("destroyed", id);
    cJSON_AddStringToObject(r, "stream", name);
    session_send(ss, r);
    return 0;
}

/* subscribe's `encoding` (absent: the default), or -1 with err. */
static int session_encoding(const cJSON *req, struct fx_err *err)
{
    const cJSON *e = cJSON_GetObjectItemCaseSensitive(req, "encoding");
    if (!e) return FXS_ENCODING_DEFAULT;
    if (!cJSON_IsString(e)) return fx_fail(err, "bad_request", "encoding", "encoding must be a string: \"default\" or \"engine\"");
    struct suggest sg;
    char hint[96];
    suggest_init(&sg, e->valuestring);
    for (int i = 0; i < FXS_ENCODING_COUNT; i++) {
        if (!strcmp(e->valuestring, fxs_encoding_name((enum fxs_encoding)i))) return i;
        suggest_offer(&sg, fxs_encoding_name((enum fxs_encoding)i));
    }
    return fx_fail(err, "bad_request", "encoding", "encoding must be \"default\" or \"engine\", got \"%.64s\"%s",
                   e->valuestring, suggest_text(&sg, hint, sizeof hint));
}

/* subscribe's `max_particles` as its budget level (budget.h; absent: 0, no budget), or -1 with err. */
static int session_budget(const struct session *ss, const cJSON *req, struct fx_err *err)
{
    const cJSON *mp = cJSON_GetObjectItemCaseSensitive(req, "max_particles");
    if (!mp) return 0;
    double v = cJSON_IsNumber(mp) ? mp->valuedouble : NAN;
    if (!(v >= FXS_MAX_PARTICLES_MIN && v <= FXS_MAX_PARTICLES_MAX && v == floor(v)))
        return fx_fail(err, "bad_request", "max_particles", "max_particles must be an integer in [%u, %u]",
                       FXS_MAX_PARTICLES_MIN, FXS_MAX_PARTICLES_MAX);
    if (ss->srv->cluster)
        return fx_fail(err, "bad_request", "max_particles",
                       "max_particles is not offered in cluster mode: frames cross Redis per encoding only, so this "
                       "daemon could not serve the budget (subscribe without it, or to a single-node daemon)");
    return budget_level((uint32_t)v);
}

static int session_op_subscribe(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"stream", "max_fps", "encoding", "max_particles", NULL};
    if (session_only(req, "subscribe", allowed, err)) return -1;
    const cJSON *mf = cJSON_GetObjectItemCaseSensitive(req, "max_fps");
    if (mf && !(cJSON_IsNumber(mf) && mf->valuedouble >= FXS_MAX_FPS_MIN && mf->valuedouble <= FXS_MAX_FPS_MAX))
        return fx_fail(err, "bad_request", "max_fps", "max_fps must be a number in [%g, %g]", FXS_MAX_FPS_MIN,
                       FXS_MAX_FPS_MAX);
    int enc = session_encoding(req, err);
    if (enc < 0) return -1;
    int level = session_budget(ss, req, err);
    if (level < 0) return -1;
    int form = budget_form((enum fxs_encoding)enc, level);
    struct stream *s = session_stream(ss, req, err);
    if (!s) return -1;
    int i = session_find_sub(ss, s);
    if (i < 0 && ss->nsubs >= ss->srv->cfg.limits.max_subscriptions) {
        stream_unref(s);
        return fx_fail(err, "limit", "stream", "subscription limit reached (%d per connection)",
                       ss->srv->cfg.limits.max_subscriptions);
    }
    if (i < 0) {
        struct sub *p = realloc(ss->subs, (size_t)(ss->nsubs + 1) * sizeof *p);
        if (!p) {
            stream_unref(s);
            return fx_fail(err, "internal", NULL, "out of memory");
        }
        ss->subs = p;
        i = ss->nsubs++;
        memset(&p[i], 0, sizeof p[i]);
        p[i].s = s; /* the reference passes to the subscription */
        p[i].form = form;
        p[i].step_time = NAN; /* no step sent yet: the first frame (sim_time 0 too) starts one */
        struct stream_status st;
        hub_status(&ss->srv->hub, s, &st);
        p[i].error_gen = st.error_gen;
        if (ss->srv->cfg.pause_idle && !st.subscribers && !st.lease.remote_demand) /* paused: its frames are old */
            for (int k = 1; k <= FXS_KIND_MAX; k++) p[i].paused_seq[k] = hub_latest_seq(&ss->srv->hub, s, k);
        hub_add_subscriber(&ss->srv->hub, s, form, +1);
    } else {
        stream_unref(s); /* already subscribed: only max_fps, the encoding and the budget change */
        struct sub *sub = &ss->subs[i];
        if (sub->form != form) { /* the newest frames again, in the new form */
            hub_add_subscriber(&ss->srv->hub, sub->s, sub->form, -1);
            hub_add_subscriber(&ss->srv->hub, sub->s, form, +1);
            sub->form = form;
            memset(sub->last_seq, 0, sizeof sub->last_seq);
            sub->step_time = NAN;
        }
    }
    ss->subs[i].min_interval = mf ? 1.0 / mf->valuedouble : 0;
    cJSON *r = session_reply("subscribed", id);
    cJSON_AddStringToObject(r, "stream", ss->subs[i].s->name);
    cJSON_AddNumberToObject(r, "channel", ss->subs[i].s->channel);
    cJSON_AddStringToObject(r, "encoding", fxs_encoding_name((enum fxs_encoding)enc));
    if (level) cJSON_AddNumberToObject(r, "max_particles", budget_step(level));
    session_send(ss, r);
    if (ss->srv->wake) ss->srv->wake(ss); /* the current frame goes out right away */
    return 0;
}

static int session_op_unsubscribe(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"stream", NULL};
    if (session_only(req, "unsubscribe", allowed, err)) return -1;
    struct stream *s = session_stream(ss, req, err);
    if (!s) return -1;
    int i = session_find_sub(ss, s);
    if (i < 0) fx_fail(err, "bad_request", "stream", "not subscribed to \"%s\"", s->name);
    stream_unref(s);
    if (i < 0) return -1;
    cJSON *r = session_reply("unsubscribed", id);
    cJSON_AddStringToObject(r, "stream", ss->subs[i].s->name);
    session_drop_sub(ss, i);
    session_send(ss, r);
    return 0;
}

static cJSON *session_params_msg(struct stream *s, const cJSON *id, uint64_t rev, cJSON *doc)
{
    cJSON *r = session_reply("params", id);
    cJSON_AddStringToObject(r, "stream", s->name);
    cJSON_AddNumberToObject(r, "rev", rev);
    cJSON_AddItemToObject(r, "params", doc);
    return r;
}

static int session_op_get(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"stream", NULL};
    if (session_only(req, "get", allowed, err)) return -1;
    struct stream *s = session_stream(ss, req, err);
    if (!s) return -1;
    uint64_t rev;
    cJSON *doc = hub_get_params(&ss->srv->hub, s, &rev);
    session_send(ss, session_params_msg(s, id, rev, doc));
    stream_unref(s);
    return 0;
}

void session_event_params(struct server *srv, const struct session *except, struct stream *s, uint64_t rev,
                          const cJSON *doc)
{
    for (struct session *o = srv->sessions; o; o = o->next)
        if (o != except && session_find_sub(o, s) >= 0)
            session_send(o, session_params_msg(s, NULL, rev, cJSON_Duplicate(doc, 1)));
}

/* A set's partial document, made again on another document (store.h: rebase). */
struct session_partial {
    const struct effect_ops *effect;
    const cJSON *partial;
};

static cJSON *session_rebase(const void *ctx, const cJSON *current, struct fx_err *err)
{
    const struct session_partial *p = ctx;
    return effect_params(p->effect, current, p->partial, err);
}

/* Installs an accepted complete document, validated at revision rev: stored first (store.h),
 * then applied at the stored revision (rev + 1, or later when it was re-made on a newer
 * document: partial, NULL for a whole document), broadcast to the stream's other subscribers
 * and sent to the requester (PROTOCOL.md §3.8). A document equal to the current one changes
 * nothing and is only sent back at revision rev. Takes doc; -1 with err when it could not be
 * stored. */
static int session_accept_params(struct session *ss, struct stream *s, uint64_t rev, const cJSON *id, cJSON *doc,
                                 const cJSON *partial, struct fx_err *err)
{
    uint64_t now;
    cJSON *cur = hub_get_params(&ss->srv->hub, s, &now);
    bool same = now == rev && cJSON_Compare(cur, doc, 1);
    cJSON_Delete(cur);
    if (same) { /* nothing changes: no revision, no store, no broadcast, no restart */
        session_send(ss, session_params_msg(s, id, rev, doc));
        return 0;
    }
    struct session_partial p = {s->effect, partial};
    struct store_change c = {.op = STORE_SET, .stream = s->name, .effect = s->effect->name, .params = doc,
                             .rev = rev, .rebase = partial ? session_rebase : NULL, .rebase_ctx = &p};
    if (store_commit(ss->srv, &c, err)) {
        cJSON_Delete(doc);
        return -1;
    }
    if (c.rebased) {
        cJSON_Delete(doc);
        doc = c.rebased;
    }
    hub_set_params(&ss->srv->hub, s, cJSON_Duplicate(doc, 1), c.rev);
    session_event_params(ss->srv, ss, s, c.rev, doc);
    session_send(ss, session_params_msg(s, id, c.rev, doc));
    return 0;
}

static int session_op_set(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"stream", "params", NULL};
    if (session_only(req, "set", allowed, err)) return -1;
    const cJSON *partial = cJSON_GetObjectItemCaseSensitive(req, "params");
    if (!partial) return fx_fail(err, "bad_request", "params", "missing field \"params\"");
    struct stream *s = session_stream(ss, req, err);
    if (!s) return -1;
    uint64_t rev;
    cJSON *cur = hub_get_params(&ss->srv->hub, s, &rev);
    cJSON *doc = hub_rev_check(s->name, rev, err) ? NULL : effect_params(s->effect, cur, partial, err);
    cJSON_Delete(cur);
    int rc = doc ? session_accept_params(ss, s, rev, id, doc, partial, err) : -1;
    stream_unref(s);
    return rc;
}

static int session_op_reset(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"stream", NULL};
    if (session_only(req, "reset", allowed, err)) return -1;
    struct stream *s = session_stream(ss, req, err);
    if (!s) return -1;
    if (store_commit(ss->srv, &(struct store_change){.op = STORE_RESET, .stream = s->name}, err)) {
        stream_unref(s);
        return -1;
    }
    hub_request_reset(&ss->srv->hub, s);
    cJSON *r = session_reply("reset", id);
    cJSON_AddStringToObject(r, "stream", s->name);
    session_send(ss, r);
    stream_unref(s);
    return 0;
}

/* ---- presets (presets.h, PROTOCOL.md §3.12) ---- */

/* A preset op's write outcome, for the state condition of /healthz and /metrics (store.h). */
static void session_note_write(struct session *ss, int rc, const struct fx_err *err)
{
    if (!rc) store_note(ss->srv, NULL);
    else if (!strcmp(err->code, "unavailable")) store_note(ss->srv, err->message);
}

static int session_op_presets(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"effect", NULL};
    if (session_only(req, "presets", allowed, err)) return -1;
    const struct effect_ops *ops = NULL;
    if (cJSON_GetObjectItemCaseSensitive(req, "effect") && !(ops = session_effect(req, err))) return -1;
    cJSON *r = session_reply("presets", id);
    cJSON_AddItemToObject(r, "presets", presets_list(&ss->srv->presets, ops));
    session_send(ss, r);
    return 0;
}

/* preset_save's fields in the order of PROTOCOL.md §3 (stream, name, doc: presence, type and
 * form), before any state; the stream's existence is checked by the caller next. */
static int session_preset_fields(const cJSON *req, const char **name, const char **doc, struct fx_err *err)
{
    *doc = "";
    if (!session_str(req, "stream", err) || !(*name = session_str(req, "name", err))) return -1;
    if (cJSON_GetObjectItemCaseSensitive(req, "doc") && !(*doc = session_str(req, "doc", err))) return -1;
    return presets_check_fields(*name, *doc, err);
}

static int session_op_preset_save(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"stream", "name", "doc", NULL};
    if (session_only(req, "preset_save", allowed, err)) return -1;
    const char *name, *doc;
    struct stream *s = session_preset_fields(req, &name, &doc, err) ? NULL : session_stream(ss, req, err);
    if (!s) return -1;
    uint64_t rev;
    bool replaced = false;
    cJSON *params = hub_get_params(&ss->srv->hub, s, &rev);
    int rc = presets_save(&ss->srv->presets, s->effect, name, doc, params, &replaced, err);
    cJSON_Delete(params);
    session_note_write(ss, rc, err);
    if (!rc) {
        log_info("preset %s/%s saved from stream %s", s->effect->name, name, s->name);
        cJSON *r = session_reply("preset_saved", id);
        cJSON_AddStringToObject(r, "effect", s->effect->name);
        cJSON_AddStringToObject(r, "name", name);
        cJSON_AddBoolToObject(r, "replaced", replaced);
        session_announce(ss->srv, ss, r);
        session_send(ss, r);
    }
    stream_unref(s);
    return rc;
}

static int session_op_preset_load(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"stream", "name", NULL};
    if (session_only(req, "preset_load", allowed, err)) return -1;
    const char *name = session_str(req, "stream", err) ? session_str(req, "name", err) : NULL;
    struct stream *s = name ? session_stream(ss, req, err) : NULL;
    if (!s) return -1;
    uint64_t rev;
    cJSON_Delete(hub_get_params(&ss->srv->hub, s, &rev));
    cJSON *preset = hub_rev_check(s->name, rev, err) ? NULL : presets_params(&ss->srv->presets, s->effect, name, err);
    cJSON *doc = preset ? effect_params(s->effect, NULL, preset, err) : NULL;
    cJSON_Delete(preset);
    int rc = doc ? session_accept_params(ss, s, rev, id, doc, NULL, err) : -1;
    stream_unref(s);
    return rc;
}

static int session_op_preset_delete(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"effect", "name", NULL};
    if (session_only(req, "preset_delete", allowed, err)) return -1;
    const struct effect_ops *ops = session_effect(req, err);
    const char *name = ops ? session_str(req, "name", err) : NULL;
    if (!name) return -1;
    int rc = presets_delete(&ss->srv->presets, ops, name, err);
    session_note_write(ss, rc, err);
    if (rc) return -1;
    log_info("preset %s/%s deleted", ops->name, name);
    cJSON *r = session_reply("preset_deleted", id);
    cJSON_AddStringToObject(r, "effect", ops->name);
    cJSON_AddStringToObject(r, "name", name);
    session_announce(ss->srv, ss, r);
    session_send(ss, r);
    return 0;
}

/* {"op":"auth","token":T}: the connection takes the token's role. A wrong token changes
 * nothing; SESSION_MAX_AUTH_FAILURES of them close the connection. */
static int session_op_auth(struct session *ss, const cJSON *req, const cJSON *id, struct fx_err *err)
{
    static const char *const allowed[] = {"token", NULL};
    if (session_only(req, "auth", allowed, err)) return -1;
    const char *token = session_str(req, "token", err);
    if (!token) return -1;
    enum access_role r = access_lookup(&ss->srv->cfg.access, token, strlen(token));
    if (r == ACCESS_NONE) {
        if (++ss->auth_failures >= SESSION_MAX_AUTH_FAILURES) ss->kill = "too many failed authentications";
        return fx_fail(err, "unauthorized", "token", "invalid token (%d of %d attempts left)",
                       SESSION_MAX_AUTH_FAILURES - ss->auth_failures, SESSION_MAX_AUTH_FAILURES);
    }
    ss->role = r;
    cJSON *rep = session_reply("auth", id);
    cJSON_AddStringToObject(rep, "role", access_role_name(r));
    session_send(ss, rep);
    return 0;
}

static const struct {
    const char *op;
    int (*fn)(struct session *, const cJSON *, const cJSON *, struct fx_err *);
    enum access_role role; /* the least role that may use it */
} session_ops[] = {
    {"auth", session_op_auth, ACCESS_NONE},
    {"list", session_op_list, ACCESS_VIEW},
    {"describe", session_op_describe, ACCESS_VIEW},
    {"create", session_op_create, ACCESS_ADMIN},
    {"destroy", session_op_destroy, ACCESS_ADMIN},
    {"subscribe", session_op_subscribe, ACCESS_VIEW},
    {"unsubscribe", session_op_unsubscribe, ACCESS_VIEW},
    {"get", session_op_get, ACCESS_VIEW},
    {"set", session_op_set, ACCESS_TUNE},
    {"reset", session_op_reset, ACCESS_TUNE},
    {"presets", session_op_presets, ACCESS_VIEW},
    {"preset_load", session_op_preset_load, ACCESS_TUNE},
    {"preset_save", session_op_preset_save, ACCESS_ADMIN},
    {"preset_delete", session_op_preset_delete, ACCESS_ADMIN},
};

static int session_allowed(const struct session *ss, const char *op, enum access_role need, struct fx_err *err)
{
    if (ss->role >= need) return 0;
    if (ss->role == ACCESS_NONE)
        return fx_fail(err, "unauthorized", NULL,
                       "not authenticated: send {\"op\":\"auth\",\"token\":...} first (or connect with "
                       "\"Authorization: Bearer TOKEN\")");
    return fx_fail(err, "forbidden", "op", "%s needs role %s; this connection has role %s", op,
                   access_role_name(need), access_role_name(ss->role));
}

/* Nesting depth of JSON text, counted outside strings, without parsing it. */
static int session_json_depth(const char *t, size_t len)
{
    int depth = 0, max = 0;
    bool in_str = false;
    for (size_t i = 0; i < len; i++) {
        char c = t[i];
        if (in_str) {
            if (c == '\\') i++;
            else if (c == '"') in_str = false;
        } else if (c == '"') {
            in_str = true;
        } else if (c == '{' || c == '[') {
            if (++depth > max) max = depth;
        } else if (c == '}' || c == ']') {
            depth--;
        }
    }
    return max;
}

/* Token bucket: max_control_per_sec per second with an equal burst. */
static bool session_rate_ok(struct session *ss)
{
    double rate = ss->srv->cfg.limits.max_control_per_sec, now = clock_now();
    ss->tokens = fmin(rate, ss->tokens + (now - ss->last_refill) * rate);
    ss->last_refill = now;
    if (ss->tokens < 1) return false;
    ss->tokens -= 1;
    return true;
}

static int session_dispatch(struct session *ss, const cJSON *req, const cJSON **id, struct fx_err *err)
{
    if (!cJSON_IsObject(req)) return fx_fail(err, "bad_request", NULL, "a control message must be a JSON object");
    const cJSON *idv = cJSON_GetObjectItemCaseSensitive(req, "id");
    if (idv && !cJSON_IsNumber(idv) && !cJSON_IsString(idv))
        return fx_fail(err, "bad_request", "id", "id must be a number or a string");
    if (idv && cJSON_IsNumber(idv) && !(fabs(idv->valuedouble) < 9007199254740992.0))
        return fx_fail(err, "bad_request", "id", "a numeric id must be below 2^53 in magnitude, where every "
                                                 "integer reads back exactly; use a string");
    *id = idv;
    const cJSON *op = cJSON_GetObjectItemCaseSensitive(req, "op");
    if (!op) return fx_fail(err, "bad_request", "op", "missing field \"op\"");
    if (!cJSON_IsString(op)) return fx_fail(err, "bad_request", "op", "field \"op\" must be a string");
    for (size_t i = 0; i < sizeof session_ops / sizeof session_ops[0]; i++)
        if (!strcmp(session_ops[i].op, op->valuestring))
            return session_allowed(ss, session_ops[i].op, session_ops[i].role, err) ? -1
                                                                                  : session_ops[i].fn(ss, req, idv, err);
    struct suggest sg;
    char hint[96];
    suggest_init(&sg, op->valuestring);
    for (size_t i = 0; i < sizeof session_ops / sizeof session_ops[0]; i++) suggest_offer(&sg, session_ops[i].op);
    return fx_fail(err, "unknown_op", "op", "unknown op \"%.64s\"%s", op->valuestring, suggest_text(&sg, hint, sizeof hint));
}

void session_handle(struct session *ss, const char *text, size_t len)
{
    const struct limits *l = &ss->srv->cfg.limits;
    struct fx_err err = {0};
    const cJSON *id = NULL;
    cJSON *req = NULL;
    char why[128];
    atomic_fetch_add(&ss->srv->counters.messages_in, 1);
    ss->replying = true;
    if (!session_rate_ok(ss))
        fx_fail(&err, "limit", NULL, "more than %d control messages per second", l->max_control_per_sec);
    else if (session_json_depth(text, len) > l->max_json_depth)
        fx_fail(&err, "bad_json", NULL, "JSON nested deeper than %d levels", l->max_json_depth);
    else if (!(req = json_strict_parse(text, len, why, sizeof why)))
        fx_fail(&err, "bad_json", NULL, "%s", why);
    else
        session_dispatch(ss, req, &id, &err);
    if (err.code[0]) session_error(ss, id, &err);
    ss->replying = false;
    cJSON_Delete(req);
}

void session_receive(struct session *ss, const void *data, size_t len, bool final, bool binary)
{
    size_t max = (size_t)ss->srv->cfg.limits.max_message_bytes;
    struct fx_err err = {0};
    if (!ss->rx_overflow && ss->rx.len + len > max) ss->rx_overflow = true;
    if (!ss->rx_overflow && fx_buf_append(&ss->rx, data, len)) ss->rx_overflow = true;
    if (!final) return;
    if (binary)
        fx_fail(&err, "bad_request", NULL, "binary messages are not accepted; send JSON text");
    else if (ss->rx_overflow)
        fx_fail(&err, "limit", NULL, "message exceeds %zu bytes", max);
    if (err.code[0]) {
        ss->replying = true;
        session_error(ss, NULL, &err);
        ss->replying = false;
    } else {
        session_handle(ss, (const char *)ss->rx.data, ss->rx.len);
    }
    ss->rx.len = 0; /* the next fragment starts a new message */
    ss->rx_overflow = false;
    if (ss->rx.cap > 2 * max) fx_buf_free(&ss->rx);
}

void session_poll_errors(struct session *ss)
{
    for (int i = 0; i < ss->nsubs; i++) {
        struct sub *sub = &ss->subs[i];
        struct stream_status st;
        hub_status(&ss->srv->hub, sub->s, &st);
        bool fresh = st.error_gen != sub->error_gen;
        sub->error_gen = st.error_gen;
        const char *msg = st.error;
        if (!fresh) continue;
        cJSON *ev = session_reply("error", NULL);
        cJSON_AddStringToObject(ev, "code", "internal");
        cJSON_AddStringToObject(ev, "stream", sub->s->name);
        cJSON_AddStringToObject(ev, "message", msg);
        session_send(ss, ev);
    }
}
