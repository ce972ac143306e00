/* wave_scenes.h — energy_wave scenes the unit tests share. The default stream is a torus
 * (Fig. 5.2); the tests of the curves, the B-spline strengths and the eq. (5.1) pulse use the
 * thesis's joined curves with W of Fig. 5.6 and the pulse running, as the built-in preset
 * thesis-fig5.6 defines them (so the tests follow the preset, not a copy of it).
 * Header-only (static). */
#ifndef WAVE_SCENES_H
#define WAVE_SCENES_H

#include <stdio.h>
#include <stdlib.h>

#include <cjson/cJSON.h>

#include "effect.h"
#include "effects/energy_wave.h"
#include "presets.h"

/* The typed parameters of a complete document (static: valid until the next call). A document
 * that does not load is the caller's bug: the message goes to stderr and the process exits. */
static inline const struct energy_wave_config *wave_typed(const cJSON *doc)
{
    static struct energy_wave_config c;
    struct fx_err err = {0};
    if (params_load(energy_wave_params, doc, &c, sizeof c, &err)) {
        fprintf(stderr, "wave_typed: %s\n", err.message);
        exit(1);
    }
    return &c;
}

/* The preset's partial document with the keys of extra_json (an object, or NULL) over it;
 * NULL on failure. */
static cJSON *wave_fig56_partial(const char *extra_json)
{
    struct presets ps;
    struct fx_err err = {0};
    if (presets_load(&ps, NULL, &err)) return NULL;
    cJSON *p = presets_params(&ps, effect_find("energy_wave"), "thesis-fig5.6", &err);
    presets_free(&ps);
    cJSON *extra = extra_json ? cJSON_Parse(extra_json) : NULL, *it;
    if (!p || (extra_json && !extra)) {
        fprintf(stderr, "  wave_fig56_partial: %s\n", p ? "bad extra JSON" : err.message);
        cJSON_Delete(p);
        cJSON_Delete(extra);
        return NULL;
    }
    if (extra) cJSON_ArrayForEach(it, extra) {
            cJSON_DeleteItemFromObjectCaseSensitive(p, it->string);
            cJSON_AddItemToObject(p, it->string, cJSON_Duplicate(it, 1));
        }
    cJSON_Delete(extra);
    return p;
}

#endif
