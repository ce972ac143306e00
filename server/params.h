/* params.h — effect parameters as data.
 *
 * Each effect declares one table of struct param_def. Validation, defaults, the
 * `describe` reply, JSON I/O and persistence all derive from that table, so a
 * parameter exists in exactly one place. A parameter document is a cJSON object
 * holding every parameter (complete, validated, normalised); a change is a partial
 * object merged all-or-nothing into a copy, never into the live document.
 *
 * The effect itself never reads the document: each entry also says where its value goes
 * in the effect's typed parameter struct (PARAM_AT: the struct member of the same name),
 * and, for values the kernels take as they are, which slot of the effect's float
 * kernel-argument array (PARAM_SLOT). params_load fills the struct from a document,
 * params_pack fills the slots from the struct, and params_table_check (run at start-up
 * and by the unit tests) proves the table and the struct agree. */
#ifndef FX_PARAMS_H
#define FX_PARAMS_H

#include <stdbool.h>
#include <stddef.h>
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
    /* Where params_load puts the value in the typed struct (list items: in the item's struct),
     * by type: FLOAT double, INT int, BOOL bool, ENUM int (the index in choices), VEC3 and
     * COLOR double[3], FLOAT_LIST double[max_len], OBJECT_LIST max_len items of item_size
     * bytes; a list's length is an int at count_at. */
    size_t at, count_at, item_size;
    int slot; /* 1 + the index in the effect's float kernel-argument array (params_pack); 0: none */
};

/* The entry of struct member `member` of the effect's typed struct `type`: name and place
 * are the member's, so a parameter's name is written once. */
#define PARAM_AT(type, member) .name = #member, .at = offsetof(type, member)
/* A list member: its items at `member`, its length at n_<member>. */
#define PARAM_LIST_AT(type, member) \
    PARAM_AT(type, member), .count_at = offsetof(type, n_##member), .item_size = sizeof(((type *)0)->member[0])
/* The value also goes, as float(s), to slot `index` of the kernel-argument array. */
#define PARAM_SLOT(index) .slot = (index) + 1

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

/* Proves a table matches its typed struct of `size` bytes and its kernel-argument array
 * of `slots` floats: every value lies inside the struct (list items inside their item)
 * without overlapping another, lists have a length and items, enums choices, slots are
 * in range and distinct and hold numbers, and the defaults load. Code internal naming
 * the entry otherwise. Run at start-up (effects_init) and by the unit tests. */
int params_table_check(const struct param_def *defs, size_t size, int slots, struct fx_err *err);

/* Fills the typed struct dst (size bytes as the table was checked against; zeroed first)
 * from a complete validated document. A value missing from the document or of another
 * type than its entry fails (code internal, naming the parameter): nothing reads as 0. */
int params_load(const struct param_def *defs, const cJSON *doc, void *dst, size_t size, struct fx_err *err);

/* Writes every slotted value of the typed struct src into slots (as float: numbers, bool
 * 0/1, an enum's index, a vector's three components in three slots from its own). */
void params_pack(const struct param_def *defs, const void *src, float *slots);

/* True when parameter d holds the same value in the typed structs a and b. */
bool params_same(const struct param_def *d, const void *a, const void *b);

/* The entry named name, or NULL. */
const struct param_def *params_find(const struct param_def *defs, const char *name);
/* The entry whose value is at offset `at` of the typed struct (PARAM_AT's), or NULL. */
const struct param_def *params_at(const struct param_def *defs, size_t at);

/* The number `name` of a complete document, for holders of a document that have no typed
 * struct (the hub's fps): -1 when it is missing or not a number. */
int params_number(const cJSON *doc, const char *name, double *out);

#endif
