/* test_session.c — the control protocol without sockets: every op, every error code,
 * all-or-nothing `set`, broadcasts to other subscribers, message size / depth / rate
 * limits. Sessions are driven through session_handle/session_receive and their queued
 * replies read back with session_pop; no engine runs (frames are not needed here). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "budget.h"
#include "check.h"
#include "log.h"
#include "session.h"

static struct server t_srv;

/* The forms (budget.h) of full frames in each encoding. */
#define T_DEFAULT budget_form(FXS_ENCODING_DEFAULT, 0)
#define T_ENGINE budget_form(FXS_ENCODING_ENGINE, 0)

static void t_server_init(void)
{
    memset(&t_srv, 0, sizeof t_srv);
    t_srv.cfg.limits = (struct limits){.max_connections = 8, .max_streams = 4, .max_subscriptions = 2,
                                       .max_message_bytes = 4096, .max_json_depth = 8,
                                       .max_control_per_sec = 1000, .max_queued_messages = 64,
                                       .max_queued_bytes = 1 << 20};
    hub_init(&t_srv.hub, t_srv.cfg.limits.max_streams, false);
}

static void t_server_free(void)
{
    while (t_srv.sessions) {
        struct session *s = t_srv.sessions;
        session_close(s);
        free(s);
    }
    hub_free(&t_srv.hub);
}

static struct session *t_open(void)
{
    struct session *s = malloc(sizeof *s);
    session_open(s, &t_srv, ACCESS_ADMIN);
    return s;
}

/* The next queued message, parsed (caller deletes), or NULL. */
static cJSON *t_next(struct session *s)
{
    struct outmsg *m = session_pop(s);
    if (!m) return NULL;
    cJSON *j = cJSON_ParseWithLength((const char *)m->data + FRAME_HEADROOM, m->len);
    free(m);
    return j;
}

static void t_drain(struct session *s)
{
    cJSON *j;
    while ((j = t_next(s))) cJSON_Delete(j);
}

/* Sends text and returns the single reply (caller deletes). */
static cJSON *t_req(struct session *s, const char *text)
{
    session_handle(s, text, strlen(text));
    return t_next(s);
}

static const char *t_op(const cJSON *j) { return j ? cJSON_GetObjectItem(j, "op")->valuestring : "(none)"; }
static const char *t_code(const cJSON *j)
{
    const cJSON *c = j ? cJSON_GetObjectItem(j, "code") : NULL;
    return c ? c->valuestring : "(none)";
}

/* Expects an error reply with code. */
static void t_expect_error(struct session *s, const char *text, const char *code)
{
    cJSON *r = t_req(s, text);
    CHECK(r && !strcmp(t_op(r), "error"), "%s -> op %s", text, t_op(r));
    CHECK(!strcmp(t_code(r), code), "%s -> code %s, expected %s", text, t_code(r), code);
    CHECK(r && cJSON_IsString(cJSON_GetObjectItem(r, "message")), "%s: no message", text);
    cJSON_Delete(r);
    CHECK(t_next(s) == NULL, "%s: extra messages", text);
}

static void test_hello(void)
{
    t_server_init();
    struct session *s = t_open();
    cJSON *h = t_next(s);
    CHECK(!strcmp(t_op(h), "hello"), "first message %s", t_op(h));
    CHECK(!strcmp(cJSON_GetObjectItem(h, "protocol")->valuestring, "fxstream.v1"), "protocol");
    CHECK(cJSON_GetArraySize(cJSON_GetObjectItem(h, "effects")) >= 1, "effects");
    CHECK(cJSON_GetObjectItem(cJSON_GetObjectItem(h, "limits"), "max_message_bytes")->valueint == 4096, "limits");
    const cJSON *enc = cJSON_GetObjectItem(h, "encodings");
    CHECK(cJSON_GetArraySize(enc) == 2 && !strcmp(cJSON_GetArrayItem(enc, 1)->valuestring, "engine"), "encodings");
    cJSON_Delete(h);
    t_server_free();
}

static void test_lifecycle(void)
{
    t_server_init();
    struct session *s = t_open();
    t_drain(s);
    cJSON *r = t_req(s, "{\"op\":\"create\",\"id\":7,\"effect\":\"energy_wave\",\"stream\":\"a\",\"params\":{\"fps\":10}}");
    CHECK(!strcmp(t_op(r), "created") && cJSON_GetObjectItem(r, "id")->valueint == 7, "create -> %s", t_op(r));
    cJSON_Delete(r);
    r = t_req(s, "{\"op\":\"list\",\"id\":\"x\"}");
    CHECK(!strcmp(t_op(r), "list") && !strcmp(cJSON_GetObjectItem(r, "id")->valuestring, "x"), "list");
    const cJSON *st = cJSON_GetArrayItem(cJSON_GetObjectItem(r, "streams"), 0);
    CHECK(st && !strcmp(cJSON_GetObjectItem(st, "stream")->valuestring, "a"), "listed");
    CHECK(st && cJSON_GetObjectItem(st, "fps")->valuedouble == 10, "fps from params");
    cJSON_Delete(r);
    r = t_req(s, "{\"op\":\"get\",\"stream\":\"a\"}");
    CHECK(!strcmp(t_op(r), "params") && cJSON_GetObjectItem(r, "rev")->valueint == 1, "get");
    CHECK(cJSON_GetObjectItem(cJSON_GetObjectItem(r, "params"), "width") != NULL, "complete params");
    cJSON_Delete(r);
    r = t_req(s, "{\"op\":\"set\",\"stream\":\"a\",\"params\":{\"fps\":20}}");
    CHECK(!strcmp(t_op(r), "params") && cJSON_GetObjectItem(r, "rev")->valueint == 2, "set -> rev 2");
    cJSON_Delete(r);
    r = t_req(s, "{\"op\":\"reset\",\"stream\":\"a\"}");
    CHECK(!strcmp(t_op(r), "reset"), "reset");
    cJSON_Delete(r);
    r = t_req(s, "{\"op\":\"describe\",\"effect\":\"energy_wave\"}");
    CHECK(!strcmp(t_op(r), "describe") && cJSON_GetArraySize(cJSON_GetObjectItem(r, "params")) > 10, "describe");
    CHECK(cJSON_IsArray(cJSON_GetObjectItem(r, "outputs")), "outputs");
    cJSON_Delete(r);
    r = t_req(s, "{\"op\":\"destroy\",\"stream\":\"a\"}");
    CHECK(!strcmp(t_op(r), "destroyed"), "destroy");
    cJSON_Delete(r);
    t_expect_error(s, "{\"op\":\"get\",\"stream\":\"a\"}", "unknown_stream");
    t_server_free();
}

static void test_error_codes(void)
{
    t_server_init();
    struct session *s = t_open();
    t_drain(s);
    t_expect_error(s, "{\"op\":", "bad_json");
    t_expect_error(s, "", "bad_json");
    t_expect_error(s, "[[[[[[[[[[1]]]]]]]]]]", "bad_json"); /* depth 10 > 8 */
    t_expect_error(s, "[1]", "bad_request");
    t_expect_error(s, "{\"id\":1}", "bad_request");
    t_expect_error(s, "{\"op\":5}", "bad_request");
    t_expect_error(s, "{\"op\":\"list\",\"id\":[1]}", "bad_request");
    t_expect_error(s, "{\"op\":\"list\",\"extra\":1}", "bad_request");
    t_expect_error(s, "{\"op\":\"fly\"}", "unknown_op");
    t_expect_error(s, "{\"op\":\"describe\",\"effect\":\"smoke\"}", "unknown_effect");
    t_expect_error(s, "{\"op\":\"create\",\"effect\":\"smoke\",\"stream\":\"b\"}", "unknown_effect");
    t_expect_error(s, "{\"op\":\"subscribe\",\"stream\":\"nope\"}", "unknown_stream");
    t_expect_error(s, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"bad name!\"}", "bad_request");
    t_expect_error(s, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"b\",\"params\":{\"fps\":0}}",
                   "bad_param");
    cJSON_Delete(t_req(s, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"b\"}"));
    t_expect_error(s, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"b\"}", "exists");
    t_expect_error(s, "{\"op\":\"set\",\"stream\":\"b\",\"params\":{\"nosuch\":1}}", "bad_param");
    t_expect_error(s, "{\"op\":\"set\",\"stream\":\"b\",\"params\":{\"fps\":1e999}}", "bad_param");
    t_expect_error(s, "{\"op\":\"set\",\"stream\":\"b\"}", "bad_request");
    t_expect_error(s, "{\"op\":\"subscribe\",\"stream\":\"b\",\"max_fps\":-1}", "bad_request");
    t_expect_error(s, "{\"op\":\"unsubscribe\",\"stream\":\"b\"}", "bad_request");
    for (int i = 0; i < 3; i++) {
        char req[128];
        snprintf(req, sizeof req, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"c%d\"}", i);
        cJSON_Delete(t_req(s, req));
    }
    t_expect_error(s, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"c9\"}", "limit"); /* 4 streams */
    cJSON_Delete(t_req(s, "{\"op\":\"subscribe\",\"stream\":\"c0\"}"));
    cJSON_Delete(t_req(s, "{\"op\":\"subscribe\",\"stream\":\"c1\"}"));
    t_expect_error(s, "{\"op\":\"subscribe\",\"stream\":\"c2\"}", "limit"); /* 2 per connection */
    t_server_free();
}

static void test_error_echoes_id_and_param(void)
{
    t_server_init();
    struct session *s = t_open();
    t_drain(s);
    cJSON_Delete(t_req(s, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"a\"}"));
    cJSON *r = t_req(s, "{\"op\":\"set\",\"id\":42,\"stream\":\"a\",\"params\":{\"alpha\":\"x\"}}");
    CHECK(cJSON_GetObjectItem(r, "id") && cJSON_GetObjectItem(r, "id")->valueint == 42, "id echoed");
    CHECK(cJSON_GetObjectItem(r, "param") && !strcmp(cJSON_GetObjectItem(r, "param")->valuestring, "alpha"),
          "param named");
    cJSON_Delete(r);
    t_server_free();
}

static void test_set_all_or_nothing(void)
{
    t_server_init();
    struct session *s = t_open();
    t_drain(s);
    cJSON_Delete(t_req(s, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"a\"}"));
    cJSON *before = t_req(s, "{\"op\":\"get\",\"stream\":\"a\"}");
    t_expect_error(s, "{\"op\":\"set\",\"stream\":\"a\",\"params\":{\"fps\":15,\"alpha\":-1}}", "bad_param");
    cJSON *after = t_req(s, "{\"op\":\"get\",\"stream\":\"a\"}");
    CHECK(cJSON_Compare(before, after, 1), "state changed by a rejected set");
    cJSON_Delete(before);
    cJSON_Delete(after);
    t_server_free();
}

static void test_broadcast(void)
{
    t_server_init();
    struct session *a = t_open(), *b = t_open(), *c = t_open(), *none = malloc(sizeof *none);
    session_open(none, &t_srv, ACCESS_NONE); /* not authenticated: may not list, hears nothing */
    t_drain(a), t_drain(b), t_drain(c), t_drain(none);
    cJSON_Delete(t_req(a, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"x\"}"));
    for (int k = 0; k < 2; k++) { /* the other connections hear of the new stream */
        cJSON *cr = t_next(k ? c : b);
        CHECK(!strcmp(t_op(cr), "created") && cr && !cJSON_GetObjectItem(cr, "id") &&
                  !strcmp(cJSON_GetObjectItem(cr, "stream")->valuestring, "x"),
              "created event to connection %d", k);
        cJSON_Delete(cr);
    }
    CHECK(t_next(a) == NULL, "the creator gets no event of its own create");
    CHECK(t_next(none) == NULL, "a connection that may not list gets no created event");
    cJSON *r = t_req(b, "{\"op\":\"subscribe\",\"stream\":\"x\",\"max_fps\":5}");
    CHECK(!strcmp(t_op(r), "subscribed") && cJSON_GetObjectItem(r, "channel")->valueint > 0, "subscribed");
    cJSON_Delete(r);
    CHECK(t_srv.hub.streams[0]->subscribers == 1, "subscriber counted");
    cJSON_Delete(t_req(a, "{\"op\":\"set\",\"stream\":\"x\",\"params\":{\"fps\":12}}"));
    cJSON *ev = t_next(b);
    CHECK(!strcmp(t_op(ev), "params") && cJSON_GetObjectItem(ev, "rev")->valueint == 2, "broadcast to subscriber");
    CHECK(ev && !cJSON_GetObjectItem(ev, "id"), "broadcast has no id");
    cJSON_Delete(ev);
    CHECK(t_next(c) == NULL, "non-subscriber got the broadcast");
    cJSON_Delete(t_req(a, "{\"op\":\"destroy\",\"stream\":\"x\"}"));
    ev = t_next(b);
    CHECK(!strcmp(t_op(ev), "unsubscribed") && !strcmp(cJSON_GetObjectItem(ev, "reason")->valuestring, "destroyed"),
          "destroy tells subscribers");
    cJSON_Delete(ev);
    for (int k = 0; k < 2; k++) {
        ev = t_next(k ? c : b);
        CHECK(!strcmp(t_op(ev), "destroyed") && ev && !cJSON_GetObjectItem(ev, "id"), "destroyed event to %d", k);
        cJSON_Delete(ev);
    }
    CHECK(b->nsubs == 0, "subscription dropped");
    t_server_free();
}

/* subscribe's `encoding`: the reply names it, the hub counts subscribers per encoding, a new
 * one replaces the old; a bad one is bad_request (param encoding, with the nearest name),
 * checked after max_fps and before the stream, and changes nothing. */
static void test_subscribe_encoding(void)
{
    t_server_init();
    struct session *s = t_open();
    t_drain(s);
    cJSON_Delete(t_req(s, "{\"op\":\"create\",\"effect\":\"flame\",\"stream\":\"f\"}"));
    struct stream *st = t_srv.hub.streams[0];
    cJSON *r = t_req(s, "{\"op\":\"subscribe\",\"stream\":\"f\",\"encoding\":\"engine\"}");
    CHECK(!strcmp(t_op(r), "subscribed") && !strcmp(cJSON_GetObjectItem(r, "encoding")->valuestring, "engine"), "engine");
    cJSON_Delete(r);
    CHECK(st->subscribers == 1 && st->subscribers_by[T_ENGINE] == 1 && st->subscribers_by[T_DEFAULT] == 0,
          "counted as engine");
    r = t_req(s, "{\"op\":\"subscribe\",\"stream\":\"f\"}");
    CHECK(!strcmp(cJSON_GetObjectItem(r, "encoding")->valuestring, "default"), "omitted: default");
    cJSON_Delete(r);
    CHECK(st->subscribers == 1 && st->subscribers_by[T_ENGINE] == 0 && st->subscribers_by[T_DEFAULT] == 1,
          "re-subscribing moves the subscription to the default");
    r = t_req(s, "{\"op\":\"subscribe\",\"stream\":\"f\",\"encoding\":\"engin\"}");
    CHECK(!strcmp(t_code(r), "bad_request") && !strcmp(cJSON_GetObjectItem(r, "param")->valuestring, "encoding") &&
          strstr(cJSON_GetObjectItem(r, "message")->valuestring, "did you mean \"engine\""), "misspelt encoding");
    cJSON_Delete(r);
    t_expect_error(s, "{\"op\":\"subscribe\",\"stream\":\"f\",\"encoding\":2}", "bad_request");
    t_expect_error(s, "{\"op\":\"subscribe\",\"stream\":\"nope\",\"encoding\":\"x\"}", "bad_request");
    t_expect_error(s, "{\"op\":\"subscribe\",\"stream\":\"f\",\"encoding\":\"x\",\"max_fps\":0}", "bad_request");
    r = t_req(s, "{\"op\":\"subscribe\",\"stream\":\"f\",\"encoding\":\"x\",\"max_fps\":0}");
    CHECK(!strcmp(cJSON_GetObjectItem(r, "param")->valuestring, "max_fps"), "max_fps is checked first");
    cJSON_Delete(r);
    CHECK(st->subscribers_by[T_DEFAULT] == 1 && st->subscribers_by[T_ENGINE] == 0, "errors changed nothing");
    cJSON_Delete(t_req(s, "{\"op\":\"unsubscribe\",\"stream\":\"f\"}"));
    CHECK(st->subscribers == 0 && st->subscribers_by[T_DEFAULT] == 0, "unsubscribed");
    t_server_free();
}

/* The `max_particles` of a reply, or -1 when absent. */
static double t_max_particles(const cJSON *r)
{
    const cJSON *v = cJSON_GetObjectItem(r, "max_particles");
    return cJSON_IsNumber(v) ? v->valuedouble : -1;
}

/* subscribe's `max_particles`: served as the ladder's step at most the value (the reply says
 * which), counted in its form beside the encoding; subscribing again replaces it (omitted:
 * removed); anything but an integer in [1000, 4194304] is bad_request (param max_particles),
 * checked after max_fps and encoding and before the stream, and changes nothing. */
static void test_subscribe_budget(void)
{
    t_server_init();
    struct session *s = t_open();
    t_drain(s);
    cJSON_Delete(t_req(s, "{\"op\":\"create\",\"effect\":\"flame\",\"stream\":\"f\"}"));
    struct stream *st = t_srv.hub.streams[0];
    static const struct { const char *asked; double served; int level; } ladder[] = {
        {"1000", 1000, 1}, {"1999", 1000, 1}, {"25000", 20000, 5}, {"200000", 200000, 8},
        {"1e6", 1000000, 10}, {"4194304", 2000000, 11},
    };
    for (size_t i = 0; i < sizeof ladder / sizeof ladder[0]; i++) {
        char req[160];
        snprintf(req, sizeof req, "{\"op\":\"subscribe\",\"stream\":\"f\",\"max_particles\":%s}", ladder[i].asked);
        cJSON *r = t_req(s, req);
        CHECK(!strcmp(t_op(r), "subscribed") && t_max_particles(r) == ladder[i].served, "%s served as %g, not %g",
              ladder[i].asked, t_max_particles(r), ladder[i].served);
        cJSON_Delete(r);
        int form = budget_form(FXS_ENCODING_DEFAULT, ladder[i].level);
        CHECK(st->subscribers == 1 && st->subscribers_by[form] == 1 && st->subscribers_by[T_DEFAULT] == 0,
              "%s counted in form %d", ladder[i].asked, form);
    }
    cJSON *r = t_req(s, "{\"op\":\"subscribe\",\"stream\":\"f\",\"encoding\":\"engine\",\"max_particles\":5000}");
    CHECK(t_max_particles(r) == 5000 && !strcmp(cJSON_GetObjectItem(r, "encoding")->valuestring, "engine"), "engine, 5000");
    cJSON_Delete(r);
    int engine5k = budget_form(FXS_ENCODING_ENGINE, budget_level(5000));
    CHECK(st->subscribers_by[engine5k] == 1 && st->subscribers == 1, "engine 5000 counted in form %d", engine5k);
    static const char *const bad[] = {"999", "4194305", "1500.5", "-1000", "\"2000\"", "true", "null", "[2000]", "1e300"};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        char req[160];
        snprintf(req, sizeof req, "{\"op\":\"subscribe\",\"stream\":\"f\",\"max_particles\":%s}", bad[i]);
        r = t_req(s, req);
        const cJSON *param = cJSON_GetObjectItem(r, "param");
        CHECK(!strcmp(t_code(r), "bad_request") && cJSON_IsString(param) && !strcmp(param->valuestring, "max_particles"),
              "max_particles %s -> %s", bad[i], t_code(r));
        cJSON_Delete(r);
    }
    r = t_req(s, "{\"op\":\"subscribe\",\"stream\":\"nope\",\"max_particles\":10}");
    CHECK(!strcmp(cJSON_GetObjectItem(r, "param")->valuestring, "max_particles"), "checked before the stream");
    cJSON_Delete(r);
    r = t_req(s, "{\"op\":\"subscribe\",\"stream\":\"f\",\"max_particles\":10,\"encoding\":\"x\"}");
    CHECK(!strcmp(cJSON_GetObjectItem(r, "param")->valuestring, "encoding"), "checked after encoding");
    cJSON_Delete(r);
    CHECK(st->subscribers == 1 && st->subscribers_by[engine5k] == 1, "errors changed nothing");
    r = t_req(s, "{\"op\":\"subscribe\",\"stream\":\"f\",\"encoding\":\"engine\"}");
    CHECK(t_max_particles(r) == -1, "omitted: no max_particles in the reply");
    cJSON_Delete(r);
    CHECK(st->subscribers_by[engine5k] == 0 && st->subscribers_by[T_ENGINE] == 1, "omitted: the budget is removed");
    cJSON_Delete(t_req(s, "{\"op\":\"unsubscribe\",\"stream\":\"f\"}"));
    CHECK(st->subscribers == 0 && st->subscribers_by[T_ENGINE] == 0, "unsubscribed");
    t_server_free();
}

static void test_stream_error_event(void)
{
    t_server_init();
    struct session *a = t_open(), *b = t_open();
    t_drain(a), t_drain(b);
    cJSON_Delete(t_req(a, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"x\"}"));
    cJSON_Delete(t_req(a, "{\"op\":\"subscribe\",\"stream\":\"x\"}"));
    t_drain(b); /* the created event */
    struct stream *s = hub_find(&t_srv.hub, "x");
    hub_stream_error(&t_srv.hub, s, "kernel failed: CL_OUT_OF_RESOURCES");
    session_poll_errors(a);
    session_poll_errors(b);
    cJSON *ev = t_next(a);
    CHECK(!strcmp(t_op(ev), "error") && !strcmp(t_code(ev), "internal"), "subscriber gets internal (%s)", t_code(ev));
    CHECK(ev && !strcmp(cJSON_GetObjectItem(ev, "stream")->valuestring, "x"), "event names the stream");
    CHECK(ev && strstr(cJSON_GetObjectItem(ev, "message")->valuestring, "CL_OUT_OF_RESOURCES"), "message kept");
    CHECK(ev && !cJSON_GetObjectItem(ev, "id"), "event has no id");
    cJSON_Delete(ev);
    CHECK(t_next(b) == NULL, "non-subscriber got the stream error");
    session_poll_errors(a);
    CHECK(t_next(a) == NULL, "the same error reported twice");
    stream_unref(s);
    t_server_free();
}

static void test_receive_limits(void)
{
    t_server_init();
    struct session *s = t_open();
    t_drain(s);
    /* A message in two fragments is reassembled. */
    session_receive(s, "{\"op\":", 6, false, false);
    session_receive(s, "\"list\"}", 7, true, false);
    cJSON *r = t_next(s);
    CHECK(!strcmp(t_op(r), "list"), "fragments -> %s", t_op(r));
    cJSON_Delete(r);
    /* Oversized: limit, and the next message works. */
    char *big = malloc(5000);
    memset(big, ' ', 5000);
    session_receive(s, big, 3000, false, false);
    session_receive(s, big, 2000, true, false);
    free(big);
    r = t_next(s);
    CHECK(!strcmp(t_code(r), "limit"), "oversized -> %s", t_code(r));
    cJSON_Delete(r);
    session_receive(s, "{}", 2, true, true);
    r = t_next(s);
    CHECK(!strcmp(t_code(r), "bad_request"), "binary -> %s", t_code(r));
    cJSON_Delete(r);
    r = t_req(s, "{\"op\":\"list\"}");
    CHECK(!strcmp(t_op(r), "list"), "usable after errors");
    cJSON_Delete(r);
    t_server_free();
}

/* Sends text and expects a reply with op `op` (and role `role` when given). */
static void t_expect_op(struct session *s, const char *text, const char *op, const char *role)
{
    cJSON *r = t_req(s, text);
    CHECK(!strcmp(t_op(r), op), "%s -> %s (%s), expected %s", text, t_op(r), t_code(r), op);
    const cJSON *rl = r ? cJSON_GetObjectItem(r, "role") : NULL;
    if (role) CHECK(rl && !strcmp(rl->valuestring, role), "%s: role %s", text, rl ? rl->valuestring : "(none)");
    cJSON_Delete(r);
    t_drain(s);
}

/* Roles by token: none < view < tune < admin, each op at its least role (access.h). */
static void test_roles(void)
{
    t_server_init();
    struct fx_err err = {0};
    CHECK(!access_add_token(&t_srv.cfg.access, "view", "view-token-0123456789", "t", &err), "%s", err.message);
    CHECK(!access_add_token(&t_srv.cfg.access, "tune", "tune-token-0123456789", "t", &err), "%s", err.message);
    CHECK(!access_add_token(&t_srv.cfg.access, "admin", "admin-token-012345678", "t", &err), "%s", err.message);
    struct session *s = malloc(sizeof *s);
    session_open(s, &t_srv, access_default_role(&t_srv.cfg.access));
    cJSON *h = t_next(s);
    const cJSON *auth = cJSON_GetObjectItem(h, "auth");
    CHECK(auth && cJSON_IsTrue(cJSON_GetObjectItem(auth, "required")), "hello says auth is required");
    CHECK(auth && !strcmp(cJSON_GetObjectItem(auth, "role")->valuestring, "none"), "hello: role none");
    cJSON_Delete(h);
    t_expect_error(s, "{\"op\":\"list\"}", "unauthorized");
    t_expect_error(s, "{\"op\":\"auth\",\"token\":\"view-token-012345678X\"}", "unauthorized");
    t_expect_error(s, "{\"op\":\"auth\",\"token\":7}", "bad_request");
    t_expect_error(s, "{\"op\":\"auth\",\"token\":\"view-token-0123456789\",\"x\":1}", "bad_request");
    t_expect_op(s, "{\"op\":\"auth\",\"token\":\"view-token-0123456789\"}", "auth", "view");
    t_expect_op(s, "{\"op\":\"list\"}", "list", NULL);
    t_expect_error(s, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"a\"}", "forbidden");
    t_expect_op(s, "{\"op\":\"auth\",\"token\":\"admin-token-012345678\"}", "auth", "admin");
    t_expect_op(s, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"a\"}", "created", NULL);
    t_expect_op(s, "{\"op\":\"auth\",\"token\":\"view-token-0123456789\"}", "auth", "view");
    t_expect_op(s, "{\"op\":\"subscribe\",\"stream\":\"a\"}", "subscribed", NULL);
    t_expect_op(s, "{\"op\":\"get\",\"stream\":\"a\"}", "params", NULL);
    t_expect_error(s, "{\"op\":\"set\",\"stream\":\"a\",\"params\":{}}", "forbidden");
    t_expect_error(s, "{\"op\":\"reset\",\"stream\":\"a\"}", "forbidden");
    t_expect_op(s, "{\"op\":\"auth\",\"token\":\"tune-token-0123456789\"}", "auth", "tune");
    t_expect_op(s, "{\"op\":\"set\",\"stream\":\"a\",\"params\":{}}", "params", NULL);
    t_expect_op(s, "{\"op\":\"reset\",\"stream\":\"a\"}", "reset", NULL);
    t_expect_error(s, "{\"op\":\"destroy\",\"stream\":\"a\"}", "forbidden");
    CHECK(s->kill == NULL, "still open after one wrong token");
    for (int i = 0; i < 4; i++) t_expect_error(s, "{\"op\":\"auth\",\"token\":\"wrong-token-0123456789\"}", "unauthorized");
    CHECK(s->kill != NULL, "closed after 5 wrong tokens");
    CHECK(s->role == ACCESS_TUNE, "a wrong token changes nothing (role %s)", access_role_name(s->role));
    t_server_free();
}

/* Token and origin rules of access.c. */
static void test_access_rules(void)
{
    struct access a;
    struct fx_err err = {0};
    memset(&a, 0, sizeof a);
    CHECK(access_default_role(&a) == ACCESS_ADMIN, "no tokens: admin");
    CHECK(access_add_token(&a, "root", "0123456789abcdef", "t", &err) && !strcmp(err.code, "bad_request"), "bad role");
    CHECK(access_add_token(&a, "view", "short", "t", &err), "short token refused");
    CHECK(access_add_token(&a, "view", "0123456789 abcdef", "t", &err), "space refused");
    CHECK(!access_add_env(&a, "view:0123456789abcdef,admin:fedcba9876543210", &err), "env: %s", err.message);
    CHECK(access_add_env(&a, "tune:0123456789abcdef", &err), "duplicate token refused");
    CHECK(access_add_env(&a, "tune", &err), "env without a colon refused");
    CHECK(access_default_role(&a) == ACCESS_NONE, "tokens: none until authenticated");
    CHECK(access_lookup(&a, "fedcba9876543210", 16) == ACCESS_ADMIN, "admin token");
    CHECK(access_lookup(&a, "fedcba987654321", 15) == ACCESS_NONE, "a prefix is not the token");
    CHECK(access_lookup(&a, "fedcba98765432100", 17) == ACCESS_NONE, "an extension is not the token");
    CHECK(access_origin_ok(&a, NULL, "h:1", false), "no Origin: not a browser, allowed");
    CHECK(access_origin_ok(&a, "http://h:1", "h:1", false), "own origin allowed");
    CHECK(!access_origin_ok(&a, "https://h:1", "h:1", false), "scheme must match");
    CHECK(!access_origin_ok(&a, "http://evil.example", "h:1", false), "foreign origin refused");
    CHECK(access_origin_ok(&a, "https://h:1", "h:1", true), "own origin over TLS");
    CHECK(!access_add_origin(&a, "https://studio.example", &err), "origin: %s", err.message);
    CHECK(access_add_origin(&a, "studio.example", &err), "origin without a scheme refused");
    CHECK(access_origin_ok(&a, "https://studio.example", "h:1", false), "listed origin allowed");
    CHECK(access_origin_ok(&a, "http://h:1", "h:1", false), "with a list, the own origin still");
    CHECK(!access_origin_ok(&a, "http://evil.example", "h:1", false), "with a list, others refused");
}

static void test_rate_limit(void)
{
    t_server_init();
    t_srv.cfg.limits.max_control_per_sec = 5;
    struct session *s = t_open();
    t_drain(s);
    int limited = 0;
    for (int i = 0; i < 20; i++) {
        cJSON *r = t_req(s, "{\"op\":\"list\"}");
        limited += !strcmp(t_code(r), "limit");
        cJSON_Delete(r);
    }
    CHECK(limited >= 10, "only %d of 20 rate-limited", limited);
    t_server_free();
}

/* The send queue: a reply is queued whatever its size and then holds the
 * connection's requests back (session_backlogged) until it has gone; events a connection does
 * not read close it past max_queued_bytes. */
static void test_send_queue(void)
{
    t_server_init();
    t_srv.cfg.limits.max_queued_bytes = 4096;
    struct session *a = t_open(), *b = t_open();
    t_drain(a), t_drain(b);
    const char *describe = "{\"op\":\"describe\",\"effect\":\"energy_wave\"}"; /* ~11 kB */
    session_handle(a, describe, strlen(describe));
    CHECK(a->q_count == 1 && a->q_bytes > 4096 && !a->kill, "a reply over max_queued_bytes is queued (%zu bytes)",
          a->q_bytes);
    CHECK(session_backlogged(a), "then the connection is backlogged: its requests wait");
    session_handle(a, describe, strlen(describe)); /* one read together with the first */
    CHECK(a->q_count == 2 && !a->kill, "a second reply asked for is queued too");
    cJSON *r = t_next(a);
    CHECK(!strcmp(t_op(r), "describe") && session_backlogged(a), "the first goes out; still backlogged");
    cJSON_Delete(r);
    r = t_next(a);
    CHECK(!strcmp(t_op(r), "describe") && !session_backlogged(a), "the second goes out; requests are read again");
    cJSON_Delete(r);
    cJSON_Delete(t_req(b, "{\"op\":\"create\",\"effect\":\"energy_wave\",\"stream\":\"x\"}"));
    cJSON_Delete(t_req(a, "{\"op\":\"subscribe\",\"stream\":\"x\"}"));
    t_drain(a);
    session_handle(a, describe, strlen(describe)); /* a reply waiting: events beside it are counted alone */
    char set[96];
    for (int i = 0; i < 11 && !a->kill; i++) {
        snprintf(set, sizeof set, "{\"op\":\"set\",\"stream\":\"x\",\"params\":{\"alpha\":%d}}", 2 + i);
        cJSON_Delete(t_req(b, set));
        CHECK(i >= 3 || (!a->kill && a->q_count == 2 + i), "~1 kB events beside an 11 kB reply are queued (%d)", a->q_count);
    }
    CHECK(a->kill && !strcmp(a->kill, "messages not read"), "more than 4 kB of events not read: closed (%s)",
          a->kill ? a->kill : "open");
    t_server_free();
}

int main(void)
{
    log_set_level(LOG_WARN);
    RUN(test_hello);
    RUN(test_lifecycle);
    RUN(test_error_codes);
    RUN(test_error_echoes_id_and_param);
    RUN(test_set_all_or_nothing);
    RUN(test_broadcast);
    RUN(test_subscribe_encoding);
    RUN(test_subscribe_budget);
    RUN(test_stream_error_event);
    RUN(test_receive_limits);
    RUN(test_rate_limit);
    RUN(test_send_queue);
    RUN(test_roles);
    RUN(test_access_rules);
    return CHECK_DONE();
}
