/* test_params.c — the parameter system: defaults, every type's validation, merge is
 * all-or-nothing, restart detection, describe. Uses its own table so it does not depend
 * on any effect's choices. */
#include <stdbool.h>
#include <string.h>

#include "check.h"
#include "effect.h"
#include "params.h"

static const char *const t_modes[] = {"fast", "exact", NULL};

/* The typed struct of t_defs. */
struct t_item {
    double pos[3], coef, W[8];
    int n_W;
};
struct t_config {
    double fps;
    int n;
    bool on;
    int mode;
    double up[3], color[3];
    struct t_item items[2];
    int n_items, size;
};

#define T_SLOTS 6
static const struct param_def t_item[] = {
    {PARAM_AT(struct t_item, pos), .type = PARAM_VEC3, .def = "[0,0,0]", .min = -10, .max = 10, .doc = "position"},
    {PARAM_AT(struct t_item, coef), .type = PARAM_FLOAT, .def = "1", .min = -5, .max = 5, .doc = "strength"},
    {PARAM_LIST_AT(struct t_item, W), .type = PARAM_FLOAT_LIST, .def = "[1,1,1]", .min = 0, .max = 1, .min_len = 3, .max_len = 8},
    {0},
};
static const struct param_def t_defs[] = {
    {PARAM_AT(struct t_config, fps), PARAM_SLOT(0), .type = PARAM_FLOAT, .def = "30", .min = 1, .max = 240, .unit = "1/s",
     .doc = "rate", .group = "output"},
    {PARAM_AT(struct t_config, n), PARAM_SLOT(1), .type = PARAM_INT, .def = "64", .min = 2, .max = 1024,
     .flags = PARAM_EVEN, .doc = "divisions"},
    {PARAM_AT(struct t_config, on), .type = PARAM_BOOL, .def = "true", .doc = "toggle"},
    {PARAM_AT(struct t_config, mode), PARAM_SLOT(2), .type = PARAM_ENUM, .def = "\"fast\"", .choices = t_modes, .doc = "mode"},
    {PARAM_AT(struct t_config, up), PARAM_SLOT(3), .type = PARAM_VEC3, .def = "[0,1,0]", .min = -1, .max = 1,
     .flags = PARAM_NONZERO},
    {PARAM_AT(struct t_config, color), .type = PARAM_COLOR, .def = "[1,0.5,0]", .min = 0, .max = 1},
    {PARAM_LIST_AT(struct t_config, items), .type = PARAM_OBJECT_LIST, .def = "[{\"coef\":2}]", .min_len = 0,
     .max_len = 2, .fields = t_item},
    {PARAM_AT(struct t_config, size), .type = PARAM_INT, .def = "256", .min = 16, .max = 2048, .flags = PARAM_RESTART},
    {0},
};

/* Merges partial text into the defaults; returns 0 or -1 with err filled. */
static int t_merge(const char *partial, cJSON **out, struct fx_err *err)
{
    cJSON *def = params_defaults(t_defs), *p = cJSON_Parse(partial);
    int rc = params_merge(t_defs, def, p, out, err);
    cJSON_Delete(def);
    cJSON_Delete(p);
    return rc;
}

/* Expects partial to be rejected with bad_param naming `param`. */
static void t_reject(const char *partial, const char *param)
{
    struct fx_err err = {0};
    cJSON *out = (cJSON *)1;
    int rc = t_merge(partial, &out, &err);
    CHECK(rc == -1 && out == NULL, "%s was accepted", partial);
    CHECK(!strcmp(err.code, "bad_param"), "%s: code %s", partial, err.code);
    CHECK(!strcmp(err.param, param), "%s: param \"%s\", expected \"%s\"", partial, err.param, param);
    CHECK(strlen(err.message) > 0, "%s: empty message", partial);
}

/* The typed struct of a complete document; fails the test when it does not load. */
static void t_load(const cJSON *doc, struct t_config *c)
{
    struct fx_err err = {0};
    CHECK(params_load(t_defs, doc, c, sizeof *c, &err) == 0, "params_load: %s", err.message);
}

static void test_defaults_complete(void)
{
    cJSON *d = params_defaults(t_defs);
    CHECK(d != NULL, "defaults failed");
    struct t_config c;
    t_load(d, &c);
    CHECK(c.fps == 30 && c.n == 64 && c.on && c.size == 256, "numbers and bool");
    CHECK(c.mode == 0, "mode: the index of \"fast\"");
    CHECK(c.up[0] == 0 && c.up[1] == 1 && c.up[2] == 0 && c.color[1] == 0.5, "vectors");
    CHECK(c.n_items == 1 && c.items[0].coef == 2, "items");
    CHECK(c.items[0].n_W == 3 && c.items[0].W[2] == 1, "missing item field defaulted");
    cJSON_Delete(d);
}

static void test_accepts_valid(void)
{
    struct fx_err err = {0};
    cJSON *out = NULL;
    int rc = t_merge("{\"fps\":60,\"n\":128,\"on\":false,\"mode\":\"exact\",\"up\":[0,0,1],"
                     "\"items\":[{\"pos\":[1,2,3],\"W\":[0,0.5,1,1]},{}]}",
                     &out, &err);
    CHECK(rc == 0, "rejected: %s", err.message);
    struct t_config c;
    t_load(out, &c);
    CHECK(c.fps == 60 && c.n == 128, "numbers");
    CHECK(!c.on, "bool");
    CHECK(c.mode == 1, "enum index");
    CHECK(c.up[2] == 1, "vec3");
    CHECK(c.n_items == 2 && c.items[0].pos[1] == 2 && c.items[0].n_W == 4 && c.items[0].W[1] == 0.5 &&
              c.items[1].coef == 1, "list replaced whole");
    cJSON_Delete(out);
}

/* A document that lacks a parameter, or holds it as another type, does not load: nothing
 * reads as 0 (what a renamed parameter would otherwise do). */
static void test_load_strict(void)
{
    static const char *const bad[][2] = {
        {"fps", NULL}, {"fps", "\"30\""}, {"mode", "\"slow\""}, {"up", "[0,1]"}, {"on", "1"}, {"items", "{}"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        cJSON *d = params_defaults(t_defs);
        if (bad[i][1]) cJSON_ReplaceItemInObjectCaseSensitive(d, bad[i][0], cJSON_Parse(bad[i][1]));
        else cJSON_DeleteItemFromObjectCaseSensitive(d, bad[i][0]);
        struct t_config c;
        struct fx_err err = {0};
        CHECK(params_load(t_defs, d, &c, sizeof c, &err) == -1 && !strcmp(err.code, "internal") &&
                  !strcmp(err.param, bad[i][0]) && strstr(err.message, bad[i][0]),
              "%s = %s: loaded (%s)", bad[i][0], bad[i][1] ? bad[i][1] : "missing", err.message);
        cJSON_Delete(d);
    }
    cJSON *d = params_defaults(t_defs);
    cJSON_DeleteItemFromObjectCaseSensitive(cJSON_GetArrayItem(cJSON_GetObjectItem(d, "items"), 0), "coef");
    struct t_config c;
    struct fx_err err = {0};
    CHECK(params_load(t_defs, d, &c, sizeof c, &err) == -1 && strstr(err.message, "items[0].coef"),
          "a list item without coef loaded: %s", err.message);
    cJSON_Delete(d);
}

/* params_table_check accepts the table and refuses each way a table can disagree with its struct. */
static void test_table_check(void)
{
    struct fx_err err = {0};
    CHECK(params_table_check(t_defs, sizeof(struct t_config), T_SLOTS, &err) == 0, "t_defs: %s", err.message);
    CHECK(params_table_check(t_defs, sizeof(struct t_config) - sizeof(int), T_SLOTS, &err) == -1 &&
              !strcmp(err.param, "size"), "a value past the struct's end: %s", err.message);
    CHECK(params_table_check(t_defs, sizeof(struct t_config), 5, &err) == -1 && !strcmp(err.param, "up"),
          "a slot past the array's end: %s", err.message);
    const struct param_def no_place[] = {
        {PARAM_AT(struct t_config, fps), .type = PARAM_FLOAT, .def = "30", .min = 1, .max = 240},
        {.name = "rate", .type = PARAM_FLOAT, .def = "30", .min = 1, .max = 240}, /* no PARAM_AT */
        {0},
    };
    CHECK(params_table_check(no_place, sizeof(struct t_config), 0, &err) == -1 && !strcmp(err.param, "rate") &&
              strstr(err.message, "overlaps fps"), "an entry without its place: %s", err.message);
    const struct param_def wide[] = {
        {PARAM_AT(struct t_config, n), .type = PARAM_FLOAT, .def = "3", .min = 1, .max = 240}, /* a double in an int */
        {PARAM_AT(struct t_config, on), .type = PARAM_BOOL, .def = "true"},
        {0},
    };
    CHECK(params_table_check(wide, sizeof(struct t_config), 0, &err) == -1 && !strcmp(err.param, "on"),
          "a value wider than its member: %s", err.message);
    const struct param_def twice[] = {
        {PARAM_AT(struct t_config, fps), PARAM_SLOT(0), .type = PARAM_FLOAT, .def = "30", .min = 1, .max = 240},
        {PARAM_AT(struct t_config, n), PARAM_SLOT(0), .type = PARAM_INT, .def = "2", .min = 1, .max = 240},
        {0},
    };
    CHECK(params_table_check(twice, sizeof(struct t_config), 1, &err) == -1 && !strcmp(err.param, "n"),
          "a slot taken twice: %s", err.message);
    const struct param_def bad_default[] = {
        {PARAM_AT(struct t_config, fps), .type = PARAM_FLOAT, .def = "300", .min = 1, .max = 240},
        {0},
    };
    CHECK(params_table_check(bad_default, sizeof(struct t_config), 0, &err) == -1, "a default out of range");
}

/* Every effect's table agrees with its typed struct and kernel-argument array (as at start-up). */
static void test_effect_tables(void)
{
    for (const struct effect_ops *const *e = effect_all(); *e; e++) {
        struct fx_err err = {0};
        CHECK((*e)->params_size > 0 && params_table_check((*e)->params, (*e)->params_size, (*e)->param_slots, &err) == 0,
              "%s: %s", (*e)->name, err.message);
        const struct param_def *fps = params_find((*e)->params, "fps");
        CHECK(fps && fps->type == PARAM_FLOAT, "%s: fps", (*e)->name);
    }
}

static void test_pack_and_same(void)
{
    cJSON *d = params_defaults(t_defs), *e = NULL;
    struct t_config a, b;
    t_load(d, &a);
    float slots[T_SLOTS] = {0};
    params_pack(t_defs, &a, slots);
    CHECK(slots[0] == 30 && slots[1] == 64 && slots[2] == 0 && slots[3] == 0 && slots[4] == 1 && slots[5] == 0,
          "slots %g %g %g %g %g %g", slots[0], slots[1], slots[2], slots[3], slots[4], slots[5]);
    struct fx_err err = {0};
    CHECK(t_merge("{\"items\":[{\"coef\":2,\"W\":[1,1,0.5]}]}", &e, &err) == 0, "%s", err.message);
    if (e) t_load(e, &b);
    const struct param_def *items = params_at(t_defs, offsetof(struct t_config, items));
    const struct param_def *fps = params_at(t_defs, offsetof(struct t_config, fps));
    CHECK(items && !strcmp(items->name, "items") && fps && !strcmp(fps->name, "fps"), "params_at");
    CHECK(items && fps && !params_same(items, &a, &b) && params_same(fps, &a, &b), "params_same");
    cJSON_Delete(d);
    cJSON_Delete(e);
}

static void test_rejects_bad_values(void)
{
    t_reject("{\"fps\":0}", "fps");              /* below range */
    t_reject("{\"fps\":1e999}", "fps");          /* infinity */
    t_reject("{\"fps\":\"30\"}", "fps");         /* wrong type */
    t_reject("{\"fps\":null}", "fps");
    t_reject("{\"n\":63}", "n");                 /* odd */
    t_reject("{\"n\":64.5}", "n");               /* not an integer */
    t_reject("{\"on\":1}", "on");
    t_reject("{\"mode\":\"slow\"}", "mode");
    t_reject("{\"up\":[0,0]}", "up");            /* wrong length */
    t_reject("{\"up\":[0,0,0]}", "up");          /* zero direction */
    t_reject("{\"up\":[0,2,0]}", "up[1]");
    t_reject("{\"color\":[1,1,\"x\"]}", "color[2]");
    t_reject("{\"items\":[{},{},{}]}", "items"); /* too many */
    t_reject("{\"items\":[{\"coef\":9}]}", "items[0].coef");
    t_reject("{\"items\":[{\"W\":[1,1]}]}", "items[0].W");
    t_reject("{\"items\":[{\"W\":[1,1,2]}]}", "items[0].W[2]");
    t_reject("{\"items\":[{\"bogus\":1}]}", "items[0].bogus");
    t_reject("{\"items\":[3]}", "items[0]");
    t_reject("{\"nope\":1}", "nope");
}

static void test_all_or_nothing(void)
{
    cJSON *cur = params_defaults(t_defs), *before = cJSON_Duplicate(cur, 1);
    cJSON *p = cJSON_Parse("{\"fps\":60,\"mode\":\"exact\",\"n\":3}");
    cJSON *out = NULL;
    struct fx_err err = {0};
    CHECK(params_merge(t_defs, cur, p, &out, &err) == -1, "accepted");
    CHECK(out == NULL, "output on failure");
    CHECK(cJSON_Compare(cur, before, 1), "current document modified");
    cJSON *notobj = cJSON_Parse("[1]");
    CHECK(params_merge(t_defs, cur, notobj, &out, &err) == -1 && !strcmp(err.code, "bad_request"), "non-object");
    cJSON_Delete(notobj);
    cJSON_Delete(p);
    cJSON_Delete(cur);
    cJSON_Delete(before);
}

static void test_restart_changed(void)
{
    cJSON *a = params_defaults(t_defs), *b = NULL, *c = NULL;
    cJSON *p1 = cJSON_Parse("{\"fps\":10}"), *p2 = cJSON_Parse("{\"size\":512}");
    params_merge(t_defs, a, p1, &b, NULL);
    params_merge(t_defs, a, p2, &c, NULL);
    CHECK(!params_restart_changed(t_defs, a, b), "live change flagged restart");
    CHECK(params_restart_changed(t_defs, a, c), "restart change missed");
    cJSON_Delete(a), cJSON_Delete(b), cJSON_Delete(c), cJSON_Delete(p1), cJSON_Delete(p2);
}

static void test_describe(void)
{
    cJSON *d = params_describe(t_defs);
    CHECK(cJSON_GetArraySize(d) == 8, "count");
    const cJSON *fps = cJSON_GetArrayItem(d, 0), *mode = cJSON_GetArrayItem(d, 3);
    const cJSON *items = cJSON_GetArrayItem(d, 6), *size = cJSON_GetArrayItem(d, 7);
    CHECK(!strcmp(cJSON_GetObjectItem(fps, "type")->valuestring, "float"), "type");
    CHECK(cJSON_GetObjectItem(fps, "min")->valuedouble == 1, "min");
    CHECK(!strcmp(cJSON_GetObjectItem(fps, "unit")->valuestring, "1/s"), "unit");
    CHECK(!strcmp(cJSON_GetObjectItem(fps, "update")->valuestring, "live"), "live");
    CHECK(!strcmp(cJSON_GetObjectItem(size, "update")->valuestring, "restart"), "restart");
    CHECK(cJSON_GetArraySize(cJSON_GetObjectItem(mode, "choices")) == 2, "choices");
    CHECK(cJSON_GetArraySize(cJSON_GetObjectItem(items, "fields")) == 3, "fields");
    CHECK(!strcmp(cJSON_GetStringValue(cJSON_GetObjectItem(fps, "group")), "output"), "group");
    CHECK(!cJSON_GetObjectItem(size, "group"), "a parameter without a group has no \"group\"");
    cJSON_Delete(d);
}

int main(void)
{
    RUN(test_defaults_complete);
    RUN(test_accepts_valid);
    RUN(test_load_strict);
    RUN(test_table_check);
    RUN(test_effect_tables);
    RUN(test_pack_and_same);
    RUN(test_rejects_bad_values);
    RUN(test_all_or_nothing);
    RUN(test_restart_changed);
    RUN(test_describe);
    return CHECK_DONE();
}
