/* presets.h — named parameter sets per effect, for the ops `presets`, `preset_save`,
 * `preset_load` and `preset_delete` (PROTOCOL.md §3.12).
 *
 * Built-in presets are declared by each effect next to its parameter table
 * (effect_ops.presets): read-only partial documents over the effect's defaults (the theses'
 * figures and a few artist looks). User presets are complete documents saved from a stream.
 * Loading either gives the stream the effect's defaults with the preset's values over them,
 * so a preset looks the same whatever the stream held before.
 *
 * All user presets are one file, <state-dir>/presets.json ([{effect, name, doc, params}]),
 * written atomically (jsonfile_write) before the op is acknowledged: a write that fails
 * leaves memory and the file as they were and the op fails with `unavailable`. Without a
 * state directory user presets last until the daemon stops. Each entry of the file is checked
 * at start as a save checks a new preset (effect, name, doc, count, size, finite numbers); the
 * first that fails stops the start, naming the file and the entry. Parameter values are not
 * checked against the effect's ranges, so a preset saved before an upgrade that changed them
 * is kept and listed; loading it is a bad_param error.
 * Network thread only. */
#ifndef FX_PRESETS_H
#define FX_PRESETS_H

#include <stdbool.h>
#include <cjson/cJSON.h>

#include "effect.h"
#include "err.h"

#define PRESETS_MAX_PER_EFFECT 64      /* user presets of one effect */
#define PRESETS_MAX_DOC 200            /* bytes of a preset's description */
#define PRESETS_MAX_PARAMS_BYTES 32768 /* a preset's params as compact JSON: every valid document fits */

struct presets {
    char dir[4096];  /* state directory, "" = not persisted */
    cJSON *user;     /* [{effect, name, doc, params}] in save order */
};

/* Reads <dir>/presets.json when dir is set (a missing file is no presets). Fails when the
 * file exists but is not a JSON array of preset objects each of which a save would accept. */
int presets_load(struct presets *ps, const char *dir, struct fx_err *err);
void presets_free(struct presets *ps);

/* [{effect, name, builtin, doc, params}] of one effect (NULL: every effect), each effect's
 * built-ins first, then its user presets in save order. */
cJSON *presets_list(const struct presets *ps, const struct effect_ops *ops);

/* A new copy of the preset's parameters (partial for a built-in, complete for a user one),
 * or NULL with unknown_preset (param `name`). */
cJSON *presets_params(const struct presets *ps, const struct effect_ops *ops, const char *name, struct fx_err *err);

/* The checks of a new preset's name and doc alone (bad_request, param name or doc): the first
 * of presets_save's, which a request makes before it looks at any state. */
int presets_check_fields(const char *name, const char *doc, struct fx_err *err);

/* Saves params (a complete document of the effect) as a user preset, replacing one of that name
 * (*replaced). Errors, in this order: bad_request (name, doc), read_only (a built-in's name),
 * limit (PRESETS_MAX_PER_EFFECT; params over PRESETS_MAX_PARAMS_BYTES), unavailable (the file
 * could not be written; nothing changed). */
int presets_save(struct presets *ps, const struct effect_ops *ops, const char *name, const char *doc,
                 const cJSON *params, bool *replaced, struct fx_err *err);

/* Deletes a user preset. Errors: read_only, unknown_preset, unavailable. */
int presets_delete(struct presets *ps, const struct effect_ops *ops, const char *name, struct fx_err *err);

#endif
