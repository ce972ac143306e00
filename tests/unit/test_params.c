/* test_params.c — the parameter system: defaults, every type's validation, merge is
 * all-or-nothing, restart detection, describe. Uses its own table so it does not depend
 * on any effect's choices. */
#include <string.h>

#include "check.h"
#include "params.h"

static const char *const t_modes[] = {"fast", "exact", NULL};
static const struct param_def t_item[] = {
    {.name = "pos", .type = PARAM_VEC3, .def = "[0,0,0]", .min = -10, .max = 10, .doc = "position"},
    {.name = "coef", .type = PARAM_FLOAT, .def = "1", .min = -5, .max = 5, .doc = "strength"},
    {.name = "W", .type = PARAM_FLOAT_LIST, .def = "[1,1,1]", .min = 0, .max = 1, .min_len = 3, .max_len = 8},
    {0},
};
static const struct param_def t_defs[] = {
    {.name = "fps", .type = PARAM_FLOAT, .def = "30", .min = 1, .max = 240, .unit = "1/s", .doc = "rate", .group = "output"},
    {.name = "n", .type = PARAM_INT, .def = "64", .min = 2, .max = 1024, .flags = PARAM_EVEN, .doc = "divisions"},
    {.name = "on", .type = PARAM_BOOL, .def = "true", .doc = "toggle"},
    {.name = "mode", .type = PARAM_ENUM, .def = "\"fast\"", .choices = t_modes, .doc = "mode"},
    {.name = "up", .type = PARAM_VEC3, .def = "[0,1,0]", .min = -1, .max = 1, .flags = PARAM_NONZERO},
    {.name = "color", .type = PARAM_COLOR, .def = "[1,0.5,0]", .min = 0, .max = 1},
    {.name = "items", .type = PARAM_OBJECT_LIST, .def = "[{\"coef\":2}]", .min_len = 0, .max_len = 2, .fields = t_item},
    {.name = "size", .type = PARAM_INT, .def = "256", .min = 16, .max = 2048, .flags = PARAM_RESTART},
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

static void test_defaults_complete(void)
{
    cJSON *d = params_defaults(t_defs);
    CHECK(d != NULL, "defaults failed");
    CHECK(params_num(d, "fps") == 30, "fps");
    CHECK(!strcmp(params_str(d, "mode"), "fast"), "mode");
    const cJSON *items = cJSON_GetObjectItem(d, "items");
    CHECK(cJSON_GetArraySize(items) == 1, "items");
    const cJSON *it = cJSON_GetArrayItem(items, 0);
    CHECK(params_num(it, "coef") == 2, "item coef");
    CHECK(cJSON_GetArraySize(cJSON_GetObjectItem(it, "W")) == 3, "missing item field defaulted");
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
    CHECK(params_num(out, "fps") == 60 && params_num(out, "n") == 128, "numbers");
    CHECK(!params_bool(out, "on"), "bool");
    double up[3];
    params_vec3(out, "up", up);
    CHECK(up[2] == 1, "vec3");
    CHECK(cJSON_GetArraySize(cJSON_GetObjectItem(out, "items")) == 2, "list replaced whole");
    cJSON_Delete(out);
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
    RUN(test_rejects_bad_values);
    RUN(test_all_or_nothing);
    RUN(test_restart_changed);
    RUN(test_describe);
    return CHECK_DONE();
}
