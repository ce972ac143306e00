/* params.c — validation, defaults, merging and description of effect parameters.
 *
 * Everything is driven by an effect's param_def table (params.h). Validation builds a
 * normalised copy of each value (list items completed with field defaults) so the live
 * document is only ever replaced by a fully checked one: a bad value anywhere leaves
 * nothing half-applied. The typed side (params_load, params_pack, params_table_check) puts
 * each value where its entry says, and refuses a document or table that does not match. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "params.h"
#include "suggest.h"

static cJSON *params_check_value(const struct param_def *d, const cJSON *v, const char *path,
                                 struct fx_err *err);

static const char *const params_type_names[] = {
    [PARAM_FLOAT] = "float",           [PARAM_INT] = "int",     [PARAM_BOOL] = "bool",
    [PARAM_ENUM] = "enum",             [PARAM_VEC3] = "vec3",   [PARAM_COLOR] = "color",
    [PARAM_FLOAT_LIST] = "float_list", [PARAM_OBJECT_LIST] = "object_list",
};

#define PARAMS_PATH_MAX 96

/* path.name, or path[index] when name is NULL; long paths are truncated, not overflowed. */
static void params_subpath(char sub[PARAMS_PATH_MAX], const char *path, const char *name, int index)
{
    int n = name ? snprintf(sub, PARAMS_PATH_MAX, "%s.", path) : snprintf(sub, PARAMS_PATH_MAX, "%s[", path);
    if (n < 0 || n >= PARAMS_PATH_MAX - 1) return;
    if (name) snprintf(sub + n, (size_t)(PARAMS_PATH_MAX - n), "%s", name);
    else snprintf(sub + n, (size_t)(PARAMS_PATH_MAX - n), "%d]", index);
}

const struct param_def *params_find(const struct param_def *defs, const char *name)
{
    for (; defs->name; defs++)
        if (strcmp(defs->name, name) == 0) return defs;
    return NULL;
}

const struct param_def *params_at(const struct param_def *defs, size_t at)
{
    for (; defs->name; defs++)
        if (defs->at == at) return defs;
    return NULL;
}

/* A finite number within [min, max]; returns the value through *out. */
static int params_check_number(const struct param_def *d, const cJSON *v, const char *path, double *out,
                               struct fx_err *err)
{
    if (!cJSON_IsNumber(v)) return fx_fail(err, "bad_param", path, "%s: expected a number", path);
    double x = v->valuedouble;
    if (!isfinite(x)) return fx_fail(err, "bad_param", path, "%s: must be finite", path);
    if (x < d->min || x > d->max)
        return fx_fail(err, "bad_param", path, "%s: %g is out of range [%g, %g]", path, x, d->min, d->max);
    *out = x;
    return 0;
}

static cJSON *params_check_scalar(const struct param_def *d, const cJSON *v, const char *path,
                                  struct fx_err *err)
{
    double x;
    if (params_check_number(d, v, path, &x, err)) return NULL;
    if (d->type == PARAM_INT) {
        if (x != floor(x)) {
            fx_fail(err, "bad_param", path, "%s: expected an integer, got %g", path, x);
            return NULL;
        }
        if ((d->flags & PARAM_EVEN) && fmod(x, 2.0) != 0.0) {
            fx_fail(err, "bad_param", path, "%s: must be even, got %g", path, x);
            return NULL;
        }
    }
    return cJSON_CreateNumber(x);
}

static cJSON *params_check_enum(const struct param_def *d, const cJSON *v, const char *path,
                                struct fx_err *err)
{
    if (cJSON_IsString(v))
        for (const char *const *c = d->choices; *c; c++)
            if (strcmp(*c, v->valuestring) == 0) return cJSON_CreateString(*c);
    char list[256] = "";
    for (const char *const *c = d->choices; *c; c++) {
        size_t n = strlen(list);
        snprintf(list + n, sizeof list - n, "%s\"%s\"", n ? ", " : "", *c);
    }
    fx_fail(err, "bad_param", path, "%s: expected one of %s", path, list);
    return NULL;
}

/* Arrays of numbers: vectors, colours and float lists. */
static cJSON *params_check_numbers(const struct param_def *d, const cJSON *v, const char *path, int min_len,
                                   int max_len, struct fx_err *err)
{
    if (!cJSON_IsArray(v)) {
        fx_fail(err, "bad_param", path, "%s: expected an array", path);
        return NULL;
    }
    int n = cJSON_GetArraySize(v);
    if (n < min_len || n > max_len) {
        if (min_len == max_len)
            fx_fail(err, "bad_param", path, "%s: expected %d numbers, got %d", path, min_len, n);
        else
            fx_fail(err, "bad_param", path, "%s: length %d is out of range [%d, %d]", path, n, min_len, max_len);
        return NULL;
    }
    cJSON *out = cJSON_CreateArray();
    double norm2 = 0;
    int i = 0;
    for (const cJSON *e = v->child; e; e = e->next, i++) {
        char sub[PARAMS_PATH_MAX];
        double x;
        params_subpath(sub, path, NULL, i);
        if (params_check_number(d, e, sub, &x, err)) {
            cJSON_Delete(out);
            return NULL;
        }
        norm2 += x * x;
        cJSON_AddItemToArray(out, cJSON_CreateNumber(x));
    }
    if ((d->flags & PARAM_NONZERO) && !(norm2 > 1e-24)) {
        cJSON_Delete(out);
        fx_fail(err, "bad_param", path, "%s: must not be the zero vector", path);
        return NULL;
    }
    return out;
}

/* One list item: known fields checked, missing ones defaulted. */
static cJSON *params_check_item(const struct param_def *fields, const cJSON *v, const char *path,
                                struct fx_err *err)
{
    if (!cJSON_IsObject(v)) {
        fx_fail(err, "bad_param", path, "%s: expected an object", path);
        return NULL;
    }
    char sub[PARAMS_PATH_MAX];
    for (const cJSON *e = v->child; e; e = e->next) {
        if (!params_find(fields, e->string)) {
            params_subpath(sub, path, e->string, 0);
            fx_fail(err, "bad_param", sub, "%s: unknown field", sub);
            return NULL;
        }
    }
    cJSON *out = cJSON_CreateObject();
    for (const struct param_def *f = fields; f->name; f++) {
        params_subpath(sub, path, f->name, 0);
        const cJSON *given = cJSON_GetObjectItemCaseSensitive(v, f->name);
        cJSON *parsed = given ? NULL : cJSON_Parse(f->def);
        cJSON *val = params_check_value(f, given ? given : parsed, sub, err);
        cJSON_Delete(parsed);
        if (!val) {
            cJSON_Delete(out);
            return NULL;
        }
        cJSON_AddItemToObject(out, f->name, val);
    }
    return out;
}

static cJSON *params_check_objects(const struct param_def *d, const cJSON *v, const char *path,
                                   struct fx_err *err)
{
    if (!cJSON_IsArray(v)) {
        fx_fail(err, "bad_param", path, "%s: expected an array of objects", path);
        return NULL;
    }
    int n = cJSON_GetArraySize(v);
    if (n < d->min_len || n > d->max_len) {
        fx_fail(err, "bad_param", path, "%s: %d items is out of range [%d, %d]", path, n, d->min_len, d->max_len);
        return NULL;
    }
    cJSON *out = cJSON_CreateArray();
    int i = 0;
    for (const cJSON *e = v->child; e; e = e->next, i++) {
        char sub[PARAMS_PATH_MAX];
        params_subpath(sub, path, NULL, i);
        cJSON *item = params_check_item(d->fields, e, sub, err);
        if (!item) {
            cJSON_Delete(out);
            return NULL;
        }
        cJSON_AddItemToArray(out, item);
    }
    return out;
}

/* Returns a normalised copy of v, or NULL with err. */
static cJSON *params_check_value(const struct param_def *d, const cJSON *v, const char *path,
                                 struct fx_err *err)
{
    if (!v) {
        fx_fail(err, "bad_param", path, "%s: missing value", path);
        return NULL;
    }
    switch (d->type) {
    case PARAM_FLOAT:
    case PARAM_INT: return params_check_scalar(d, v, path, err);
    case PARAM_BOOL:
        if (cJSON_IsBool(v)) return cJSON_CreateBool(cJSON_IsTrue(v));
        fx_fail(err, "bad_param", path, "%s: expected true or false", path);
        return NULL;
    case PARAM_ENUM: return params_check_enum(d, v, path, err);
    case PARAM_VEC3:
    case PARAM_COLOR: return params_check_numbers(d, v, path, 3, 3, err);
    case PARAM_FLOAT_LIST: return params_check_numbers(d, v, path, d->min_len, d->max_len, err);
    case PARAM_OBJECT_LIST: return params_check_objects(d, v, path, err);
    }
    fx_fail(err, "internal", path, "%s: unknown parameter type", path);
    return NULL;
}

cJSON *params_defaults(const struct param_def *defs)
{
    cJSON *doc = cJSON_CreateObject();
    for (const struct param_def *d = defs; d->name; d++) {
        cJSON *parsed = cJSON_Parse(d->def);
        cJSON *val = params_check_value(d, parsed, d->name, NULL);
        cJSON_Delete(parsed);
        if (!val) {
            cJSON_Delete(doc);
            return NULL;
        }
        cJSON_AddItemToObject(doc, d->name, val);
    }
    return doc;
}

int params_merge(const struct param_def *defs, const cJSON *current, const cJSON *partial, cJSON **out,
                 struct fx_err *err)
{
    *out = NULL;
    if (!cJSON_IsObject(partial)) return fx_fail(err, "bad_request", "params", "params: expected an object");
    cJSON *doc = cJSON_Duplicate(current, 1);
    if (!doc) return fx_fail(err, "internal", NULL, "out of memory");
    for (const cJSON *e = partial->child; e; e = e->next) {
        const struct param_def *d = params_find(defs, e->string);
        cJSON *val = NULL;
        if (!d) {
            struct suggest sg;
            char hint[96];
            suggest_init(&sg, e->string);
            for (const struct param_def *k = defs; k->name; k++) suggest_offer(&sg, k->name);
            fx_fail(err, "bad_param", e->string, "%s: unknown parameter%s", e->string, suggest_text(&sg, hint, sizeof hint));
        } else
            val = params_check_value(d, e, e->string, err);
        if (!val) {
            cJSON_Delete(doc);
            return -1;
        }
        cJSON_ReplaceItemInObjectCaseSensitive(doc, d->name, val);
    }
    *out = doc;
    return 0;
}

bool params_restart_changed(const struct param_def *defs, const cJSON *a, const cJSON *b)
{
    for (const struct param_def *d = defs; d->name; d++)
        if ((d->flags & PARAM_RESTART) &&
            !cJSON_Compare(cJSON_GetObjectItemCaseSensitive(a, d->name),
                           cJSON_GetObjectItemCaseSensitive(b, d->name), 1))
            return true;
    return false;
}

static cJSON *params_describe_one(const struct param_def *d)
{
    cJSON *o = cJSON_CreateObject();
    cJSON_AddStringToObject(o, "name", d->name);
    cJSON_AddStringToObject(o, "type", params_type_names[d->type]);
    cJSON_AddItemToObject(o, "default", cJSON_Parse(d->def));
    if (d->type != PARAM_BOOL && d->type != PARAM_ENUM && d->type != PARAM_OBJECT_LIST) {
        cJSON_AddNumberToObject(o, "min", d->min);
        cJSON_AddNumberToObject(o, "max", d->max);
    }
    if (d->type == PARAM_FLOAT_LIST || d->type == PARAM_OBJECT_LIST) {
        cJSON_AddNumberToObject(o, "min_len", d->min_len);
        cJSON_AddNumberToObject(o, "max_len", d->max_len);
    }
    if (d->type == PARAM_ENUM) {
        cJSON *c = cJSON_AddArrayToObject(o, "choices");
        for (const char *const *s = d->choices; *s; s++) cJSON_AddItemToArray(c, cJSON_CreateString(*s));
    }
    if (d->type == PARAM_OBJECT_LIST) cJSON_AddItemToObject(o, "fields", params_describe(d->fields));
    if (d->flags & PARAM_EVEN) cJSON_AddTrueToObject(o, "even");
    if (d->flags & PARAM_NONZERO) cJSON_AddTrueToObject(o, "nonzero");
    cJSON_AddStringToObject(o, "unit", d->unit ? d->unit : "");
    cJSON_AddStringToObject(o, "update", (d->flags & PARAM_RESTART) ? "restart" : "live");
    cJSON_AddStringToObject(o, "doc", d->doc ? d->doc : "");
    if (d->group) cJSON_AddStringToObject(o, "group", d->group);
    return o;
}

cJSON *params_describe(const struct param_def *defs)
{
    cJSON *arr = cJSON_CreateArray();
    for (const struct param_def *d = defs; d->name; d++) cJSON_AddItemToArray(arr, params_describe_one(d));
    return arr;
}

/* ---- the typed struct ------------------------------------------------------------- */

/* Bytes one value of d takes in its struct. */
static size_t params_bytes(const struct param_def *d)
{
    switch (d->type) {
    case PARAM_FLOAT: return sizeof(double);
    case PARAM_INT:
    case PARAM_ENUM: return sizeof(int);
    case PARAM_BOOL: return sizeof(bool);
    case PARAM_VEC3:
    case PARAM_COLOR: return 3 * sizeof(double);
    case PARAM_FLOAT_LIST:
    case PARAM_OBJECT_LIST: return (size_t)d->max_len * d->item_size;
    }
    return 0;
}

static bool params_is_list(const struct param_def *d)
{
    return d->type == PARAM_FLOAT_LIST || d->type == PARAM_OBJECT_LIST;
}

/* [lo, hi) ranges of one struct, to find overlaps. */
struct params_span {
    size_t lo, hi;
    const char *name;
};

static int params_claim(struct params_span *sp, int *n, int cap, size_t lo, size_t bytes, size_t size,
                        const char *name, const char *path, struct fx_err *err)
{
    if (bytes == 0 || lo + bytes > size || lo + bytes < lo)
        return fx_fail(err, "internal", name, "parameter %s%s: its value does not fit the typed struct", path, name);
    for (int i = 0; i < *n; i++)
        if (lo < sp[i].hi && sp[i].lo < lo + bytes)
            return fx_fail(err, "internal", name, "parameter %s%s: its value overlaps %s's in the typed struct", path,
                           name, sp[i].name);
    if (*n == cap) return fx_fail(err, "internal", name, "parameter table too long");
    sp[(*n)++] = (struct params_span){lo, lo + bytes, name};
    return 0;
}

#define PARAMS_MAX_ENTRIES 128

static int params_check_layout(const struct param_def *defs, size_t size, int slots, const char *path,
                               struct fx_err *err)
{
    struct params_span sp[PARAMS_MAX_ENTRIES];
    bool used[PARAMS_MAX_ENTRIES] = {false};
    int n = 0;
    for (const struct param_def *d = defs; d->name; d++) {
        if (params_is_list(d) && (d->max_len < 1 || d->min_len > d->max_len))
            return fx_fail(err, "internal", d->name, "parameter %s%s: bad length limits", path, d->name);
        if (d->type == PARAM_FLOAT_LIST && d->item_size != sizeof(double))
            return fx_fail(err, "internal", d->name, "parameter %s%s: items must be doubles", path, d->name);
        if (d->type == PARAM_ENUM && (!d->choices || !d->choices[0]))
            return fx_fail(err, "internal", d->name, "parameter %s%s: no choices", path, d->name);
        if (params_claim(sp, &n, PARAMS_MAX_ENTRIES, d->at, params_bytes(d), size, d->name, path, err) ||
            (params_is_list(d) && params_claim(sp, &n, PARAMS_MAX_ENTRIES, d->count_at, sizeof(int), size, d->name,
                                               path, err)))
            return -1;
        if (d->type == PARAM_OBJECT_LIST) {
            char sub[PARAMS_PATH_MAX];
            snprintf(sub, sizeof sub, "%s%s[].", path, d->name);
            if (!d->fields) return fx_fail(err, "internal", d->name, "parameter %s%s: no fields", path, d->name);
            if (params_check_layout(d->fields, d->item_size, 0, sub, err)) return -1;
        }
        if (!d->slot) continue;
        int width = d->type == PARAM_VEC3 || d->type == PARAM_COLOR ? 3 : 1;
        if (params_is_list(d) || d->slot < 1 || d->slot - 1 + width > slots || slots > PARAMS_MAX_ENTRIES)
            return fx_fail(err, "internal", d->name, "parameter %s%s: bad kernel-argument slot %d", path, d->name,
                           d->slot - 1);
        for (int k = d->slot - 1; k < d->slot - 1 + width; k++) {
            if (used[k])
                return fx_fail(err, "internal", d->name, "parameter %s%s: kernel-argument slot %d taken twice", path,
                               d->name, k);
            used[k] = true;
        }
    }
    return 0;
}

int params_table_check(const struct param_def *defs, size_t size, int slots, struct fx_err *err)
{
    if (params_check_layout(defs, size, slots, "", err)) return -1;
    cJSON *doc = params_defaults(defs);
    if (!doc) return fx_fail(err, "internal", NULL, "a parameter's default is invalid");
    void *tmp = malloc(size);
    int rc = tmp ? params_load(defs, doc, tmp, size, err) : fx_fail(err, "internal", NULL, "out of memory");
    free(tmp);
    cJSON_Delete(doc);
    return rc;
}

static int params_load_one(const struct param_def *d, const cJSON *v, char *base, const char *path,
                           struct fx_err *err);

static int params_missing(const struct param_def *d, const char *path, struct fx_err *err)
{
    unsigned t = d->type;
    return fx_fail(err, "internal", d->name, "parameter %s: missing from the document or not a %s", path,
                   t < sizeof params_type_names / sizeof params_type_names[0] ? params_type_names[t] : "value");
}

static int params_load_items(const struct param_def *defs, const cJSON *obj, char *base, const char *path,
                             struct fx_err *err)
{
    for (const struct param_def *d = defs; d->name; d++) {
        char sub[PARAMS_PATH_MAX];
        if (*path) params_subpath(sub, path, d->name, 0);
        else snprintf(sub, sizeof sub, "%s", d->name);
        if (params_load_one(d, cJSON_GetObjectItemCaseSensitive(obj, d->name), base, sub, err)) return -1;
    }
    return 0;
}

static int params_load_numbers(const struct param_def *d, const cJSON *v, double *out, int min_len, int max_len,
                               const char *path, struct fx_err *err)
{
    int n = cJSON_IsArray(v) ? cJSON_GetArraySize(v) : -1;
    if (n < min_len || n > max_len) return params_missing(d, path, err);
    int i = 0;
    for (const cJSON *e = v->child; e; e = e->next, i++) {
        if (!cJSON_IsNumber(e)) return params_missing(d, path, err);
        out[i] = e->valuedouble;
    }
    return n;
}

static int params_load_one(const struct param_def *d, const cJSON *v, char *base, const char *path,
                           struct fx_err *err)
{
    void *at = base + d->at;
    int n;
    switch (d->type) {
    case PARAM_FLOAT:
        if (!cJSON_IsNumber(v)) return params_missing(d, path, err);
        *(double *)at = v->valuedouble;
        return 0;
    case PARAM_INT:
        if (!cJSON_IsNumber(v)) return params_missing(d, path, err);
        *(int *)at = (int)v->valuedouble;
        return 0;
    case PARAM_BOOL:
        if (!cJSON_IsBool(v)) return params_missing(d, path, err);
        *(bool *)at = cJSON_IsTrue(v);
        return 0;
    case PARAM_ENUM:
        for (int i = 0; cJSON_IsString(v) && d->choices[i]; i++)
            if (strcmp(d->choices[i], v->valuestring) == 0) {
                *(int *)at = i;
                return 0;
            }
        return params_missing(d, path, err);
    case PARAM_VEC3:
    case PARAM_COLOR: return params_load_numbers(d, v, at, 3, 3, path, err) < 0 ? -1 : 0;
    case PARAM_FLOAT_LIST:
        if ((n = params_load_numbers(d, v, at, d->min_len, d->max_len, path, err)) < 0) return -1;
        *(int *)(base + d->count_at) = n;
        return 0;
    case PARAM_OBJECT_LIST:
        n = cJSON_IsArray(v) ? cJSON_GetArraySize(v) : -1;
        if (n < d->min_len || n > d->max_len) return params_missing(d, path, err);
        for (int i = 0; i < n; i++) {
            char sub[PARAMS_PATH_MAX];
            params_subpath(sub, path, NULL, i);
            const cJSON *item = cJSON_GetArrayItem(v, i);
            if (!cJSON_IsObject(item)) return params_missing(d, sub, err);
            if (params_load_items(d->fields, item, (char *)at + (size_t)i * d->item_size, sub, err)) return -1;
        }
        *(int *)(base + d->count_at) = n;
        return 0;
    }
    return params_missing(d, path, err);
}

int params_load(const struct param_def *defs, const cJSON *doc, void *dst, size_t size, struct fx_err *err)
{
    memset(dst, 0, size);
    if (!cJSON_IsObject(doc)) return fx_fail(err, "internal", NULL, "parameters: not a document");
    return params_load_items(defs, doc, dst, "", err);
}

void params_pack(const struct param_def *defs, const void *src, float *slots)
{
    const char *base = src;
    for (const struct param_def *d = defs; d->name; d++) {
        if (!d->slot) continue;
        float *out = slots + d->slot - 1;
        const void *at = base + d->at;
        switch (d->type) {
        case PARAM_FLOAT: *out = (float)*(const double *)at; break;
        case PARAM_INT:
        case PARAM_ENUM: *out = (float)*(const int *)at; break;
        case PARAM_BOOL: *out = *(const bool *)at ? 1.0f : 0.0f; break;
        case PARAM_VEC3:
        case PARAM_COLOR:
            for (int k = 0; k < 3; k++) out[k] = (float)((const double *)at)[k];
            break;
        case PARAM_FLOAT_LIST:
        case PARAM_OBJECT_LIST: break; /* params_table_check refuses slots on lists */
        }
    }
}

bool params_same(const struct param_def *d, const void *a, const void *b)
{
    const char *pa = (const char *)a + d->at, *pb = (const char *)b + d->at;
    if (!params_is_list(d)) return memcmp(pa, pb, params_bytes(d)) == 0;
    int na = *(const int *)((const char *)a + d->count_at), nb = *(const int *)((const char *)b + d->count_at);
    if (na != nb) return false;
    if (d->type == PARAM_FLOAT_LIST) return memcmp(pa, pb, (size_t)na * sizeof(double)) == 0;
    for (int i = 0; i < na; i++)
        for (const struct param_def *f = d->fields; f->name; f++)
            if (!params_same(f, pa + (size_t)i * d->item_size, pb + (size_t)i * d->item_size)) return false;
    return true;
}

int params_number(const cJSON *doc, const char *name, double *out)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(doc, name);
    if (!cJSON_IsNumber(v)) return -1;
    *out = v->valuedouble;
    return 0;
}
