/* test_presets.c — presets.c: every built-in preset of every effect is valid and named by
 * the rules; user presets are saved, listed, loaded back from presets.json after a restart,
 * deleted; built-ins are read-only; the per-effect limit holds; and a save or delete whose
 * file write fails leaves memory and the file as they were (`unavailable`). */
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "check.h"
#include "effect.h"
#include "hub.h"
#include "jsonfile.h"
#include "presets.h"

static char tp_dir[64];

static const struct effect_ops *tp_flame(void) { return effect_find("flame"); }

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

/* The thesis presets carry the digests' values (002 Table 3.1 and no air drag, 004 §3). */
static void test_thesis_values(void)
{
    struct presets ps;
    struct fx_err err = {0};
    CHECK(!presets_load(&ps, NULL, &err), "%s", err.message);
    cJSON *fl = presets_params(&ps, tp_flame(), "thesis-table3.1", &err);
    CHECK(fl && params_num(fl, "h") == 0.01125 && params_num(fl, "dt") == 0.001 && params_num(fl, "wind_drag") == 0,
          "flame thesis preset");
    cJSON *eye = presets_params(&ps, effect_find("compound_eye"), "thesis", &err);
    CHECK(eye && params_num(eye, "density") == 300 && params_num(eye, "refractive_index") == 1.491 &&
              !strcmp(params_str(eye, "lattice"), "square"), "eye thesis preset");
    cJSON *fig = presets_params(&ps, effect_find("energy_wave"), "thesis-fig5.2", &err);
    const cJSON *torus = fig ? cJSON_GetArrayItem(cJSON_GetObjectItem(fig, "tori"), 0) : NULL;
    CHECK(torus && params_num(torus, "R") == 3.0 && params_num(torus, "coef") == 7.4, "Fig. 5.2 torus");
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
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf %s", tp_dir);
    if (system(cmd)) fprintf(stderr, "cannot remove %s\n", tp_dir);
    return CHECK_DONE();
}
