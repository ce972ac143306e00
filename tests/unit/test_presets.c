/* test_presets.c — presets.c: every built-in preset of every effect is valid and named by
 * the rules; user presets are saved, listed, loaded back from presets.json after a restart,
 * deleted; built-ins are read-only; the per-effect limit and the size bound hold; every entry of
 * presets.json is checked as a save is (or the start is refused naming it); and a save or
 * delete whose file write fails leaves memory and the file as they were (`unavailable`). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "check.h"
#include "effect.h"
#include "effects/compound_eye.h"
#include "effects/energy_wave.h"
#include "effects/flame.h"
#include "hub.h"
#include "jsonfile.h"
#include "presets.h"

static char tp_dir[64];

static const struct effect_ops *tp_flame(void) { return effect_find("flame"); }
static cJSON *tp_longest(const struct param_def *defs);

static void test_builtins_valid(void)
{
    int total = 0;
    for (const struct effect_ops *const *e = effect_all(); *e; e++) {
        int n = 0;
        for (const struct effect_preset *p = (*e)->presets; p && p->name; p++, n++) {
            struct fx_err err = {0};
            cJSON *partial = cJSON_Parse(p->params);
            cJSON *doc = partial ? effect_params(*e, NULL, partial, &err) : NULL;
            CHECK(doc, "%s/%s: %s", (*e)->name, p->name, partial ? err.message : "not JSON");
            CHECK(hub_valid_name(p->name), "%s/%s: name", (*e)->name, p->name);
            CHECK(p->doc && strlen(p->doc) > 10 && strlen(p->doc) <= PRESETS_MAX_DOC, "%s/%s: doc", (*e)->name, p->name);
            for (const struct effect_preset *q = (*e)->presets; q != p; q++)
                CHECK(strcmp(q->name, p->name), "%s: %s twice", (*e)->name, p->name);
            cJSON_Delete(doc);
            cJSON_Delete(partial);
        }
        CHECK(n >= 3, "%s has %d built-in presets", (*e)->name, n);
        total += n;
    }
    CHECK(total >= 9, "%d presets", total);
}

/* The typed parameters of a preset (a partial document over the defaults): 0, or -1. */
static int tp_typed(const struct effect_ops *ops, const cJSON *preset, void *typed, size_t size)
{
    struct fx_err err = {0};
    cJSON *doc = preset ? effect_params(ops, NULL, preset, &err) : NULL;
    int rc = doc ? params_load(ops->params, doc, typed, size, &err) : -1;
    cJSON_Delete(doc);
    return rc;
}

/* The thesis presets carry the digests' values (002 Table 3.1 and no air drag, 004 §3). */
static void test_thesis_values(void)
{
    struct presets ps;
    struct fx_err err = {0};
    CHECK(!presets_load(&ps, NULL, &err), "%s", err.message);
    cJSON *fl = presets_params(&ps, tp_flame(), "thesis-table3.1", &err);
    struct flame_config f;
    CHECK(!tp_typed(tp_flame(), fl, &f, sizeof f) && f.h == 0.01125 && f.dt == 0.001 &&
              f.wind_drag == 0, "flame thesis preset");
    cJSON *eye = presets_params(&ps, effect_find("compound_eye"), "thesis", &err);
    struct compound_eye_config e;
    CHECK(!tp_typed(effect_find("compound_eye"), eye, &e, sizeof e) && e.density == 300 &&
              e.refractive_index == 1.491 && e.lattice == EYE_SQUARE, "eye thesis preset");
    cJSON *fig = presets_params(&ps, effect_find("energy_wave"), "thesis-fig5.2", &err);
    static struct energy_wave_config w;
    CHECK(!tp_typed(effect_find("energy_wave"), fig, &w, sizeof w) && w.n_tori == 1 && w.tori[0].R == 3.0 &&
              w.tori[0].coef == 7.4, "Fig. 5.2 torus");
    cJSON_Delete(fl);
    cJSON_Delete(eye);
    cJSON_Delete(fig);
    presets_free(&ps);
}

static cJSON *tp_doc(double fps)
{
    cJSON *partial = cJSON_CreateObject();
    cJSON_AddNumberToObject(partial, "fps", fps);
    struct fx_err err = {0};
    cJSON *doc = effect_params(tp_flame(), NULL, partial, &err);
    cJSON_Delete(partial);
    return doc;
}

static int tp_count(const struct presets *ps)
{
    cJSON *l = presets_list(ps, tp_flame());
    int n = 0;
    for (const cJSON *e = l->child; e; e = e->next) n += !cJSON_IsTrue(cJSON_GetObjectItem(e, "builtin"));
    cJSON_Delete(l);
    return n;
}

static void test_save_reload_delete(void)
{
    struct presets ps;
    struct fx_err err = {0};
    bool replaced = true;
    CHECK(!presets_load(&ps, tp_dir, &err), "%s", err.message);
    cJSON *doc = tp_doc(12);
    CHECK(!presets_save(&ps, tp_flame(), "slow", "twelve", doc, &replaced, &err) && !replaced, "%s", err.message);
    CHECK(!presets_save(&ps, tp_flame(), "slow", "again", doc, &replaced, &err) && replaced, "replace");
    CHECK(presets_save(&ps, tp_flame(), "candle", "", doc, &replaced, &err) && !strcmp(err.code, "read_only"),
          "a built-in's name: %s", err.code);
    CHECK(presets_save(&ps, tp_flame(), "bad name", "", doc, &replaced, &err) && !strcmp(err.code, "bad_request"),
          "an invalid name: %s", err.code);
    presets_free(&ps);

    CHECK(!presets_load(&ps, tp_dir, &err), "reload: %s", err.message);
    cJSON *back = presets_params(&ps, tp_flame(), "slow", &err);
    CHECK(back && cJSON_Compare(back, doc, 1), "the saved document comes back after a restart");
    CHECK(tp_count(&ps) == 1, "one user preset");
    CHECK(presets_delete(&ps, tp_flame(), "fire-pit", &err) && !strcmp(err.code, "read_only"), "delete a built-in");
    CHECK(presets_delete(&ps, tp_flame(), "slw", &err) && !strcmp(err.code, "unknown_preset") &&
              strstr(err.message, "did you mean \"slow\""), "%s", err.message);
    CHECK(!presets_delete(&ps, tp_flame(), "slow", &err), "%s", err.message);
    presets_free(&ps);
    CHECK(!presets_load(&ps, tp_dir, &err) && tp_count(&ps) == 0, "deleted for good");
    presets_free(&ps);
    cJSON_Delete(back);
    cJSON_Delete(doc);
}

static void test_limit(void)
{
    struct presets ps;
    struct fx_err err = {0};
    bool replaced;
    cJSON *doc = tp_doc(20);
    presets_load(&ps, NULL, &err);
    char name[16];
    for (int i = 0; i < PRESETS_MAX_PER_EFFECT; i++) {
        snprintf(name, sizeof name, "p%d", i);
        CHECK(!presets_save(&ps, tp_flame(), name, "", doc, &replaced, &err), "%s", err.message);
    }
    CHECK(presets_save(&ps, tp_flame(), "one-more", "", doc, &replaced, &err) && !strcmp(err.code, "limit"), "limit");
    CHECK(!presets_save(&ps, tp_flame(), "p3", "", doc, &replaced, &err) && replaced, "replacing at the limit");
    presets_free(&ps);
    cJSON_Delete(doc);
}

/* A write that fails (the temporary file's name taken by a directory: refused even for root)
 * changes nothing, in memory or on disk. */
static void test_write_failure(void)
{
    struct presets ps;
    struct fx_err err = {0};
    bool replaced;
    cJSON *doc = tp_doc(15);
    CHECK(!presets_load(&ps, tp_dir, &err), "%s", err.message);
    CHECK(!presets_save(&ps, tp_flame(), "kept", "", doc, &replaced, &err), "%s", err.message);
    char tmp[128];
    snprintf(tmp, sizeof tmp, "%s/presets.json.tmp", tp_dir);
    CHECK(!mkdir(tmp, 0755), "mkdir %s", tmp);
    CHECK(presets_save(&ps, tp_flame(), "lost", "", doc, &replaced, &err) && !strcmp(err.code, "unavailable"),
          "save: %s", err.code);
    CHECK(presets_delete(&ps, tp_flame(), "kept", &err) && !strcmp(err.code, "unavailable"), "delete: %s", err.code);
    CHECK(tp_count(&ps) == 1, "memory unchanged");
    rmdir(tmp);
    presets_free(&ps);
    CHECK(!presets_load(&ps, tp_dir, &err) && tp_count(&ps) == 1, "file unchanged");
    cJSON *k = presets_params(&ps, tp_flame(), "kept", &err);
    CHECK(k, "kept survives");
    cJSON_Delete(k);
    presets_delete(&ps, tp_flame(), "kept", &err);
    presets_free(&ps);
    cJSON_Delete(doc);
}

static void test_bad_file(void)
{
    struct presets ps;
    struct fx_err err = {0};
    CHECK(!jsonfile_write(tp_dir, "presets.json", "[{\"effect\":\"flame\"}]"), "write");
    CHECK(presets_load(&ps, tp_dir, &err) && strstr(err.message, "presets.json"), "a malformed file is refused: %s",
          err.message);
    presets_free(&ps);
    CHECK(!jsonfile_write(tp_dir, "presets.json", "[]"), "write");
}

/* Loads presets.json holding `entries` (the inside of the array): refused with a message that
 * names the file, the entry and has `why`, or (why NULL) accepted. The file is left as it is. */
static void tp_load_case(const char *entries, const char *why)
{
    struct presets ps;
    struct fx_err err = {0};
    char text[8192], back[8192] = "";
    snprintf(text, sizeof text, "[%s]", entries);
    CHECK(!jsonfile_write(tp_dir, "presets.json", text), "write");
    int rc = presets_load(&ps, tp_dir, &err);
    presets_free(&ps);
    if (!why) {
        CHECK(!rc, "%s: refused (%s)", entries, err.message);
        return;
    }
    CHECK(rc && strstr(err.message, "presets.json") && strstr(err.message, why), "%s: %s (wanted \"%s\")", entries,
          rc ? err.message : "accepted", why);
    char path[128];
    snprintf(path, sizeof path, "%s/presets.json", tp_dir);
    FILE *f = fopen(path, "r");
    size_t n = f ? fread(back, 1, sizeof back - 1, f) : 0;
    if (f) fclose(f);
    CHECK(n == strlen(text) && !memcmp(back, text, n), "%s: the file is left as it is", entries);
}

#define TP_E(effect, name, rest) "{\"effect\":\"" effect "\",\"name\":\"" name "\",\"doc\":\"\"," rest "}"
#define TP_P "\"params\":{\"fps\":20}"

/* Every entry of presets.json is checked as preset_save checks a new one: unchecked, each of
 * these would load and then be listed, sent or impossible to delete. */
static void test_bad_entries(void)
{
    tp_load_case(TP_E("flame", "ok", TP_P) "," TP_E("energy_wave", "ok", TP_P), NULL);
    tp_load_case(TP_E("flame", "ok", TP_P) "," TP_E("flame", "a\xff", TP_P), "invalid UTF-8");
    tp_load_case(TP_E("flame", "a\\u00ff", TP_P), "entry 1 (flame/a\xc3\xbf): preset names are 1-63 characters");
    tp_load_case(TP_E("flame", "x", "\"params\":{\"fps\":1e999}"), "entry 1 (flame/x): params.fps is not a finite number");
    tp_load_case(TP_E("flame", "x", "\"params\":{\"sources\":[{\"radius\":-1e999}]}"), "params.sources[0].radius");
    tp_load_case(TP_E("flame", "candle", TP_P), "entry 1 (flame/candle): \"candle\" is a built-in flame preset");
    tp_load_case(TP_E("flame", "../../x", TP_P), "entry 1 (flame/../../x): preset names are");
    tp_load_case(TP_E("flame", "twice", TP_P) "," TP_E("flame", "twice", TP_P), "entry 2 (flame/twice): a second preset");
    tp_load_case(TP_E("smoke", "x", TP_P), "entry 1 (smoke/x): no effect named \"smoke\"");
    tp_load_case(TP_E("flame", "x", "\"params\":[]"), "entry 1 (flame/x): not an object {effect, name, doc, params}");
    tp_load_case(TP_E("flame", "x", TP_P ",\"extra\":1"), "entry 1 (flame/x): not an object {effect, name, doc, params}");
    tp_load_case("{\"effect\":\"flame\",\"name\":\"x\",\"doc\":7," TP_P "}", "entry 1 (flame/x): not an object {effect, name, doc, params}");
    char big[4096] = "", one[96];
    for (int i = 0; i < PRESETS_MAX_PER_EFFECT + 1; i++) {
        snprintf(one, sizeof one, "%s" TP_E("flame", "p%d", TP_P), i ? "," : "", i);
        strcat(big, one);
    }
    tp_load_case(big, "entry 65 (flame/p64): flame already has 64 presets");
    char doc[400];
    snprintf(doc, sizeof doc, "{\"effect\":\"flame\",\"name\":\"x\",\"doc\":\"%0*d\"," TP_P "}", PRESETS_MAX_DOC + 1, 0);
    tp_load_case(doc, "entry 1 (flame/x): a preset's doc is at most 200 bytes");
    CHECK(!jsonfile_write(tp_dir, "presets.json", "[]"), "write");
}

/* A value of d as long as it can print: lists at their longest, numbers with 17 digits. */
static cJSON *tp_longest_value(const struct param_def *d, int i)
{
    double x = d->type == PARAM_INT ? d->max : d->min + (d->max - d->min) * (0.1234567890123457 + 0.01 * i);
    if (d->flags & PARAM_EVEN) x = 2 * floor(d->max / 2);
    cJSON *a = d->type == PARAM_FLOAT || d->type == PARAM_INT ? cJSON_CreateNumber(x)
               : d->type == PARAM_BOOL ? cJSON_CreateFalse() : d->type == PARAM_ENUM ? NULL : cJSON_CreateArray();
    int n = d->type == PARAM_VEC3 || d->type == PARAM_COLOR ? 3 : d->max_len;
    if (d->type == PARAM_ENUM) {
        const char *const *c = d->choices, *best = *c;
        for (; *c; c++) best = strlen(*c) > strlen(best) ? *c : best;
        a = cJSON_CreateString(best);
    } else if (d->type == PARAM_OBJECT_LIST) {
        for (int k = 0; k < n; k++) cJSON_AddItemToArray(a, tp_longest(d->fields));
    } else if (cJSON_IsArray(a)) {
        for (int k = 0; k < n; k++) cJSON_AddItemToArray(a, tp_longest_value(&(struct param_def){.type = PARAM_FLOAT,
                                                             .min = d->min, .max = d->max}, k + 1));
    }
    return a;
}

static cJSON *tp_longest(const struct param_def *defs)
{
    cJSON *o = cJSON_CreateObject();
    for (; defs->name; defs++) cJSON_AddItemToObject(o, defs->name, tp_longest_value(defs, 0));
    return o;
}

/* A preset's parameters are bounded in size, so a presets reply is too. */
static void test_params_size(void)
{
    struct presets ps;
    struct fx_err err = {0};
    bool replaced;
    cJSON *doc = tp_doc(20);
    CHECK(!presets_load(&ps, NULL, &err), "%s", err.message);
    char *pad = malloc(PRESETS_MAX_PARAMS_BYTES);
    memset(pad, 'x', PRESETS_MAX_PARAMS_BYTES - 1);
    pad[PRESETS_MAX_PARAMS_BYTES - 1] = 0;
    cJSON_AddStringToObject(doc, "pad", pad);
    CHECK(presets_save(&ps, tp_flame(), "huge", "", doc, &replaced, &err) && !strcmp(err.code, "limit") &&
              strstr(err.message, "at most 32768 bytes"), "a document over the bound: %s %s", err.code, err.message);
    CHECK(tp_count(&ps) == 0, "nothing saved");
    presets_free(&ps);
    for (const struct effect_ops *const *e = effect_all(); *e; e++) {
        cJSON *partial = tp_longest((*e)->params), *defaults = params_defaults((*e)->params), *d = NULL;
        struct fx_err perr = {0};
        CHECK(!params_merge((*e)->params, defaults, partial, &d, &perr), "%s: %s", (*e)->name, perr.message);
        char *text = d ? cJSON_PrintUnformatted(d) : NULL;
        CHECK(text && strlen(text) < PRESETS_MAX_PARAMS_BYTES, "%s: its longest document (%zu bytes) fits", (*e)->name,
              text ? strlen(text) : 0);
        free(text);
        cJSON_Delete(d);
        cJSON_Delete(defaults);
        cJSON_Delete(partial);
    }
    free(pad);
    cJSON_Delete(doc);
}

int main(void)
{
    snprintf(tp_dir, sizeof tp_dir, "/tmp/fxs-presets-XXXXXX");
    if (!mkdtemp(tp_dir)) return 1;
    RUN(test_builtins_valid);
    RUN(test_thesis_values);
    RUN(test_save_reload_delete);
    RUN(test_limit);
    RUN(test_write_failure);
    RUN(test_bad_file);
    RUN(test_bad_entries);
    RUN(test_params_size);
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tp_dir);
    if (system(cmd)) fprintf(stderr, "cannot remove %s\n", tp_dir);
    return CHECK_DONE();
}
