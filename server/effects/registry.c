/* registry.c — the list of effects the daemon can run, and the validation of their
 * parameter documents that every entry point shares.
 *
 * Adding an effect is one line here plus its module; the protocol (`hello`,
 * `describe`, `create`) reads everything else from the effect's own table. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../effect.h"

extern const struct effect_ops compound_eye_effect;
extern const struct effect_ops energy_wave_effect;
extern const struct effect_ops flame_effect;

static const struct effect_ops *const registry_effects[] = {
    &energy_wave_effect,
    &flame_effect,
    &compound_eye_effect,
    NULL,
};

const struct effect_ops *const *effect_all(void) { return registry_effects; }

/* The table matches the typed struct, and holds the fps every stream is paced by. */
static int registry_check_table(const struct effect_ops *ops, struct fx_err *err)
{
    const struct param_def *fps = params_find(ops->params, "fps");
    if (!fps || fps->type != PARAM_FLOAT)
        return fx_fail(err, "internal", NULL, "effect %s: no float parameter fps", ops->name);
    if (params_table_check(ops->params, ops->params_size, ops->param_slots, err)) {
        char msg[sizeof err->message];
        snprintf(msg, sizeof msg, "%s", err->message);
        return fx_fail(err, "internal", NULL, "effect %s: %s", ops->name, msg);
    }
    return 0;
}

int effects_init(const struct effect_env *env, struct fx_err *err)
{
    for (int i = 0; registry_effects[i]; i++)
        if ((registry_effects[i]->init && registry_effects[i]->init(env, err)) ||
            registry_check_table(registry_effects[i], err))
            return -1;
    return 0;
}

const struct effect_ops *effect_find(const char *name)
{
    for (int i = 0; registry_effects[i]; i++)
        if (strcmp(registry_effects[i]->name, name) == 0) return registry_effects[i];
    return NULL;
}

cJSON *effect_params(const struct effect_ops *ops, const cJSON *base, const cJSON *partial, struct fx_err *err)
{
    cJSON *defaults = base ? NULL : params_defaults(ops->params);
    cJSON *empty = partial ? NULL : cJSON_CreateObject();
    cJSON *doc = NULL;
    if (!base && !defaults) fx_fail(err, "internal", NULL, "effect %s: invalid default parameters", ops->name);
    else if (!params_merge(ops->params, base ? base : defaults, partial ? partial : empty, &doc, err)) {
        void *typed = effect_typed(ops, doc, err);
        if (!typed || (ops->check && ops->check(typed, err))) {
            cJSON_Delete(doc);
            doc = NULL;
        }
        free(typed);
    }
    cJSON_Delete(defaults);
    cJSON_Delete(empty);
    return doc;
}

void *effect_typed(const struct effect_ops *ops, const cJSON *doc, struct fx_err *err)
{
    void *typed = malloc(ops->params_size);
    if (!typed) fx_fail(err, "internal", NULL, "out of memory");
    else if (params_load(ops->params, doc, typed, ops->params_size, err)) {
        free(typed);
        typed = NULL;
    }
    return typed;
}
