/* presets.c — see presets.h. */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "hub.h"
#include "jsonfile.h"
#include "presets.h"
#include "suggest.h"

#define PRESETS_FILE "presets.json"
#define PRESETS_MAX_BYTES (64L << 20) /* 3 effects x 64 presets of a few kB: far below */

static const struct effect_preset *presets_builtin(const struct effect_ops *ops, const char *name)
{
    for (const struct effect_preset *p = ops->presets; p && p->name; p++)
        if (!strcmp(p->name, name)) return p;
    return NULL;
}

static const char *presets_str(const cJSON *o, const char *name)
{
    return cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, name));
}

/* Index of the effect's user preset `name` in ps->user, or -1. */
static int presets_user_index(const struct presets *ps, const struct effect_ops *ops, const char *name)
{
    int i = 0;
    for (const cJSON *e = ps->user ? ps->user->child : NULL; e; e = e->next, i++) {
        const char *ef = presets_str(e, "effect"), *nm = presets_str(e, "name");
        if (ef && nm && !strcmp(ef, ops->name) && !strcmp(nm, name)) return i;
    }
    return -1;
}

static int presets_count(const struct presets *ps, const struct effect_ops *ops)
{
    int n = 0;
    for (const cJSON *u = ps->user->child; u; u = u->next) n += !strcmp(presets_str(u, "effect"), ops->name);
    return n;
}

static int presets_bad_name(struct fx_err *err)
{
    return fx_fail(err, "bad_request", "name", "preset names are 1-63 characters of A-Z a-z 0-9 _ . -");
}

static int presets_read_only(const struct effect_ops *ops, const char *name, struct fx_err *err)
{
    return fx_fail(err, "read_only", "name", "\"%s\" is a built-in %s preset and cannot be changed", name, ops->name);
}

/* What a new user preset `name` of ops must pass, in the order of PROTOCOL.md §3 (fields, then
 * state): a valid name and doc, not a built-in's name, room for one more unless it replaces
 * one (*index: the preset it replaces, or -1), parameters within PRESETS_MAX_PARAMS_BYTES. */
int presets_check_fields(const char *name, const char *doc, struct fx_err *err)
{
    if (!hub_valid_name(name)) return presets_bad_name(err);
    if (strlen(doc) > PRESETS_MAX_DOC)
        return fx_fail(err, "bad_request", "doc", "a preset's doc is at most %d bytes", PRESETS_MAX_DOC);
    return 0;
}

static int presets_check(const struct presets *ps, const struct effect_ops *ops, const char *name, const char *doc,
                         const cJSON *params, int *index, struct fx_err *err)
{
    if (presets_check_fields(name, doc, err)) return -1;
    if (presets_builtin(ops, name)) return presets_read_only(ops, name, err);
    *index = presets_user_index(ps, ops, name);
    int count = presets_count(ps, ops);
    if (*index < 0 && count >= PRESETS_MAX_PER_EFFECT)
        return fx_fail(err, "limit", "name", "%s already has %d presets (delete one first)", ops->name, count);
    char *text = cJSON_PrintUnformatted(params);
    size_t n = text ? strlen(text) : 0;
    cJSON_free(text);
    if (!text) return fx_fail(err, "internal", NULL, "out of memory");
    if (n > PRESETS_MAX_PARAMS_BYTES)
        return fx_fail(err, "limit", NULL, "the parameters are %zu bytes as JSON; a preset holds at most %d bytes",
                       n, PRESETS_MAX_PARAMS_BYTES);
    return 0;
}

/* Fails naming the first number of v (at path) that is not finite: the reader takes 1e999 as
 * infinity, which no parameter accepts and JSON cannot print (it went out as null). */
static int presets_finite(const cJSON *v, const char *path, struct fx_err *err)
{
    if (cJSON_IsNumber(v) && !isfinite(v->valuedouble))
        return fx_fail(err, "bad_param", path, "%s is not a finite number", path);
    int i = 0;
    for (const cJSON *c = v->child; c; c = c->next, i++) {
        char sub[256];
        if (cJSON_IsObject(v)) snprintf(sub, sizeof sub, "%s.%s", path, c->string);
        else snprintf(sub, sizeof sub, "%s[%d]", path, i);
        if (presets_finite(c, sub, err)) return -1;
    }
    return 0;
}

/* Entry e of presets.json checked as a save would check it against the entries before it
 * (ps->user), and appended there; -1 with err saying why (without the file's name). */
static int presets_load_entry(struct presets *ps, const cJSON *e, struct fx_err *err)
{
    const char *effect = presets_str(e, "effect"), *name = presets_str(e, "name"), *doc = presets_str(e, "doc");
    const cJSON *params = cJSON_GetObjectItemCaseSensitive(e, "params");
    if (!cJSON_IsObject(e) || cJSON_GetArraySize(e) != 4 || !effect || !name || !doc || !cJSON_IsObject(params))
        return fx_fail(err, "internal", NULL, "not an object {effect, name, doc, params} of three strings and an object");
    const struct effect_ops *ops = effect_find(effect);
    int index;
    if (!ops) fx_fail(err, "unknown_effect", "effect", "no effect named \"%s\"", effect);
    if (!ops || presets_check(ps, ops, name, doc, params, &index, err) || presets_finite(params, "params", err)) return -1;
    if (index >= 0) return fx_fail(err, "internal", NULL, "a second preset named \"%s\" for %s", name, effect);
    cJSON_AddItemToArray(ps->user, cJSON_Duplicate(e, 1));
    return 0;
}

int presets_load(struct presets *ps, const char *dir, struct fx_err *err)
{
    memset(ps, 0, sizeof *ps);
    snprintf(ps->dir, sizeof ps->dir, "%s", dir ? dir : "");
    ps->user = cJSON_CreateArray();
    if (!ps->dir[0]) return 0;
    char path[sizeof ps->dir + 32], why[128] = "";
    snprintf(path, sizeof path, "%s/%s", ps->dir, PRESETS_FILE);
    cJSON *arr = NULL;
    if (jsonfile_read(path, PRESETS_MAX_BYTES, &arr, why, sizeof why))
        return errno == ENOENT ? 0 : fx_fail(err, "internal", NULL, "cannot read %s: %s", path, strerror(errno));
    if (!cJSON_IsArray(arr)) {
        cJSON_Delete(arr);
        return fx_fail(err, "internal", NULL, "%s: %s (left as it is)", path, why[0] ? why : "not a JSON array of presets");
    }
    int i = 1;
    for (const cJSON *e = arr->child; e; e = e->next, i++) {
        struct fx_err why_entry = {0};
        if (!presets_load_entry(ps, e, &why_entry)) continue;
        const char *ef = presets_str(e, "effect"), *nm = presets_str(e, "name");
        char which[160] = "";
        if (ef && nm) snprintf(which, sizeof which, " (%.64s/%.64s)", ef, nm);
        cJSON_Delete(arr);
        cJSON_Delete(ps->user);
        ps->user = cJSON_CreateArray();
        return fx_fail(err, "internal", NULL, "%s: entry %d%s: %s (left as it is)", path, i, which, why_entry.message);
    }
    cJSON_Delete(arr);
    return 0;
}

void presets_free(struct presets *ps)
{
    cJSON_Delete(ps->user);
    ps->user = NULL;
}

static cJSON *presets_item(const char *effect, const char *name, bool builtin, const char *doc, cJSON *params)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "effect", effect);
    cJSON_AddStringToObject(o, "name", name);
    cJSON_AddBoolToObject(o, "builtin", builtin);
    cJSON_AddStringToObject(o, "doc", doc);
    cJSON_AddItemToObject(o, "params", params);
    return o;
}

cJSON *presets_list(const struct presets *ps, const struct effect_ops *ops)
{
    cJSON *arr = cJSON_CreateArray();
    for (const struct effect_ops *const *e = effect_all(); *e; e++) {
        if (ops && *e != ops) continue;
        for (const struct effect_preset *p = (*e)->presets; p && p->name; p++)
            cJSON_AddItemToArray(arr, presets_item((*e)->name, p->name, true, p->doc, cJSON_Parse(p->params)));
        for (const cJSON *u = ps->user->child; u; u = u->next)
            if (!strcmp(presets_str(u, "effect"), (*e)->name))
                cJSON_AddItemToArray(arr, presets_item((*e)->name, presets_str(u, "name"), false, presets_str(u, "doc"),
                                                       cJSON_Duplicate(cJSON_GetObjectItemCaseSensitive(u, "params"), 1)));
    }
    return arr;
}

static int presets_unknown(const struct presets *ps, const struct effect_ops *ops, const char *name, struct fx_err *err)
{
    struct suggest sg;
    char hint[96];
    suggest_init(&sg, name);
    for (const struct effect_preset *p = ops->presets; p && p->name; p++) suggest_offer(&sg, p->name);
    for (const cJSON *u = ps->user->child; u; u = u->next)
        if (!strcmp(presets_str(u, "effect"), ops->name)) suggest_offer(&sg, presets_str(u, "name"));
    return fx_fail(err, "unknown_preset", "name", "%s has no preset named \"%.64s\"%s", ops->name, name,
                   suggest_text(&sg, hint, sizeof hint));
}

cJSON *presets_params(const struct presets *ps, const struct effect_ops *ops, const char *name, struct fx_err *err)
{
    const struct effect_preset *b = presets_builtin(ops, name);
    if (b) return cJSON_Parse(b->params);
    int i = presets_user_index(ps, ops, name);
    if (i < 0) {
        presets_unknown(ps, ops, name, err);
        return NULL;
    }
    return cJSON_Duplicate(cJSON_GetObjectItemCaseSensitive(cJSON_GetArrayItem(ps->user, i), "params"), 1);
}

/* Writes the user presets; on failure puts `before` back (ownership either way). */
static int presets_commit(struct presets *ps, cJSON *before, struct fx_err *err)
{
    if (ps->dir[0]) {
        char *text = cJSON_Print(ps->user);
        int rc = text ? jsonfile_write(ps->dir, PRESETS_FILE, text) : -1;
        int e = text ? errno : ENOMEM;
        cJSON_free(text);
        if (rc) {
            cJSON_Delete(ps->user);
            ps->user = before;
            return fx_fail(err, "unavailable", NULL, "cannot save %s/%s: %s (nothing changed)", ps->dir, PRESETS_FILE,
                           strerror(e));
        }
    }
    cJSON_Delete(before);
    return 0;
}

int presets_save(struct presets *ps, const struct effect_ops *ops, const char *name, const char *doc,
                 const cJSON *params, bool *replaced, struct fx_err *err)
{
    int i;
    if (presets_check(ps, ops, name, doc, params, &i, err)) return -1;
    cJSON *before = cJSON_Duplicate(ps->user, 1);
    cJSON *item = cJSON_CreateObject();
    cJSON_AddStringToObject(item, "effect", ops->name);
    cJSON_AddStringToObject(item, "name", name);
    cJSON_AddStringToObject(item, "doc", doc);
    cJSON_AddItemToObject(item, "params", cJSON_Duplicate(params, 1));
    if (i >= 0) cJSON_ReplaceItemInArray(ps->user, i, item);
    else cJSON_AddItemToArray(ps->user, item);
    *replaced = i >= 0;
    return presets_commit(ps, before, err);
}

int presets_delete(struct presets *ps, const struct effect_ops *ops, const char *name, struct fx_err *err)
{
    if (!hub_valid_name(name)) return presets_bad_name(err);
    if (presets_builtin(ops, name)) return presets_read_only(ops, name, err);
    int i = presets_user_index(ps, ops, name);
    if (i < 0) return presets_unknown(ps, ops, name, err);
    cJSON *before = cJSON_Duplicate(ps->user, 1);
    cJSON_DeleteItemFromArray(ps->user, i);
    return presets_commit(ps, before, err);
}
