/* fuzz_params.c — libFuzzer target: parameter validation (effect_params, the one path of
 * create, set, config and restored state) for every effect. The first byte picks the
 * effect, the rest is a partial parameter document as JSON text; an accepted document
 * must validate again unchanged (idempotence) and print as JSON. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "effect.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const struct effect_ops *const *all = effect_all();
    int nfx = 0;
    while (all[nfx]) nfx++;
    if (size < 1) return 0;
    const struct effect_ops *fx = all[data[0] % nfx];
    cJSON *partial = cJSON_ParseWithLength((const char *)data + 1, size - 1);
    if (!partial) return 0;
    struct fx_err err = {0};
    cJSON *doc = effect_params(fx, NULL, partial, &err);
    if (doc) {
        cJSON *again = effect_params(fx, doc, NULL, &err);
        if (!again || !cJSON_Compare(doc, again, 1)) abort(); /* a valid document stays valid */
        char *text = cJSON_PrintUnformatted(doc);
        if (!text) abort();
        free(text);
        cJSON_Delete(again);
    } else if (!err.code[0] || !err.message[0]) {
        abort(); /* every refusal says why */
    }
    cJSON_Delete(doc);
    cJSON_Delete(partial);
    return 0;
}
