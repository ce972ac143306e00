/* params.h — effect parameters as data.
 *
 * Each effect declares one table of struct param_def. Validation, defaults, the
 * `describe` reply, JSON I/O and persistence all derive from that table, so a
 * parameter exists in exactly one place. A parameter document is a cJSON object
 * holding every parameter (complete, validated, normalised); a change is a partial
 * object merged all-or-nothing into a copy, never into the live document. */
#ifndef FX_PARAMS_H
#define FX_PARAMS_H

#include <stdbool.h>
#include <cjson/cJSON.h>

#include "err.h"

enum param_type {
    PARAM_FLOAT,       /* finite number in [min, max] */
    PARAM_INT,         /* integral number in [min, max] */
    PARAM_BOOL,
    PARAM_ENUM,        /* string, one of choices */
    PARAM_VEC3,        /* [x, y, z], each in [min, max] */
    PARAM_COLOR,       /* [r, g, b], each in [min, max] (linear, usually 0..1) */
    PARAM_FLOAT_LIST,  /* [v...], length in [min_len, max_len], each in [min, max] */
    PARAM_OBJECT_LIST, /* [{...}...], length in [min_len, max_len], items per `fields` */
};

enum param_flag {
    PARAM_RESTART = 1u << 0, /* changing it restarts the effect's state (reported by describe) */
    PARAM_EVEN = 1u << 1,    /* PARAM_INT: must be even */
    PARAM_NONZERO = 1u << 2, /* PARAM_VEC3: must not be the zero vector (a direction) */
};

struct param_def {
    const char *name;
    enum param_type type;
    const char *def;                /* default as JSON text, e.g. "2.0", "[0,0,1]", "[]" */
    double min, max;                /* numbers, vector components, list elements */
    int min_len, max_len;           /* lists */
    const char *const *choices;     /* PARAM_ENUM: NULL-terminated */
    const struct param_def *fields; /* PARAM_OBJECT_LIST: item fields, {0}-terminated */
    const char *unit;               /* "", "s", "1/s", "world units", ... */
    const char *doc;
    const char *group;              /* top-level parameters: the panel folder ("sources", "forces", ...) */
    unsigned flags;
};

/* A complete document holding every default. Tables end with an entry whose name is NULL.
 * Returns NULL only when out of memory or when a table default is itself invalid (a bug,
 * caught by the unit tests). */
cJSON *params_defaults(const struct param_def *defs);

/* Validates `partial` (a JSON object of top-level parameter names; lists are replaced
 * whole) against defs and merges it into a copy of `current`. On success *out holds a
 * new complete document and 0 is returned. On failure returns -1, *out is NULL, err says
 * which parameter (err->param is a path like "curves[1].W[3]") and why (code bad_param
 * for any value problem, bad_request when partial is not an object). `current` is never
 * modified. Missing fields of list items take their defaults. */
int params_merge(const struct param_def *defs, const cJSON *current, const cJSON *partial, cJSON **out,
                 struct fx_err *err);

/* True when a parameter flagged PARAM_RESTART differs between the two documents. */
bool params_restart_changed(const struct param_def *defs, const cJSON *a, const cJSON *b);

/* The schema as JSON for `describe`: [{"name","type","default","min","max","unit",
 * "live"|"restart","doc","group",...}] ("group" only where the table sets one). */
cJSON *params_describe(const struct param_def *defs);

/* Typed reads from a validated document (or list item). They do not fail: a missing or
 * mistyped value returns 0 / false / "" / zero vector, which validation rules out. */
double params_num(const cJSON *obj, const char *name);
bool params_bool(const cJSON *obj, const char *name);
const char *params_str(const cJSON *obj, const char *name);
void params_vec3(const cJSON *obj, const char *name, double out[3]);
/* The index of a PARAM_ENUM value in its NULL-terminated choices (0 when absent). */
int params_enum(const cJSON *obj, const char *name, const char *const *choices);

#endif
