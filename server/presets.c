/* presets.c — see presets.h. */
#include <errno.h>
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

static bool presets_entry_ok(const cJSON *e)
{
    return cJSON_IsObject(e) && presets_str(e, "effect") && presets_str(e, "name") && presets_str(e, "doc") &&
           cJSON_IsObject(cJSON_GetObjectItemCaseSensitive(e, "params"));
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
    bool ok = cJSON_IsArray(arr);
    for (const cJSON *e = ok ? arr->child : NULL; e && ok; e = e->next) ok = presets_entry_ok(e);
    if (!ok) {
        cJSON_Delete(arr);
        return fx_fail(err, "internal", NULL, "%s: %s (left as it is)", path,
                       why[0] ? why : "not a JSON array of {effect, name, doc, params}");
    }
    cJSON_Delete(ps->user);
    ps->user = arr;
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

static int presets_writable(const struct effect_ops *ops, const char *name, struct fx_err *err)
{
    if (!hub_valid_name(name))
        return fx_fail(err, "bad_request", "name", "preset names are 1-63 characters of A-Z a-z 0-9 _ . -");
    if (presets_builtin(ops, name))
        return fx_fail(err, "read_only", "name", "\"%s\" is a built-in %s preset and cannot be changed", name, ops->name);
    return 0;
}

int presets_save(struct presets *ps, const struct effect_ops *ops, const char *name, const char *doc,
                 const cJSON *params, bool *replaced, struct fx_err *err)
{
    if (presets_writable(ops, name, err)) return -1;
    if (strlen(doc) > PRESETS_MAX_DOC)
        return fx_fail(err, "bad_request", "doc", "a preset's doc is at most %d bytes", PRESETS_MAX_DOC);
    int i = presets_user_index(ps, ops, name), count = 0;
    for (const cJSON *u = ps->user->child; u; u = u->next) count += !strcmp(presets_str(u, "effect"), ops->name);
    if (i < 0 && count >= PRESETS_MAX_PER_EFFECT)
        return fx_fail(err, "limit", "name", "%s already has %d presets (delete one first)", ops->name, count);
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
    if (presets_writable(ops, name, err)) return -1;
    int i = presets_user_index(ps, ops, name);
    if (i < 0) return presets_unknown(ps, ops, name, err);
    cJSON *before = cJSON_Duplicate(ps->user, 1);
    cJSON_DeleteItemFromArray(ps->user, i);
    return presets_commit(ps, before, err);
}
