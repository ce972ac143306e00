/* fuzz_json.c — libFuzzer target: the strict JSON reader (server/json_strict.c) on arbitrary
 * bytes. An accepted text must print as text that is accepted again and prints the same; a
 * refusal must say why. Seeds: tests/fuzz/corpus/fuzz_json (trailing data,
 * duplicate keys, \u0000 in keys and values, RFC 8259's edges: leading zeros, 1., form feed,
 * raw control characters, escapes, surrogates, invalid UTF-8). */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "json_strict.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char why[128] = "";
    cJSON *v = json_strict_parse((const char *)data, size, why, sizeof why);
    if (!v) {
        if (!why[0]) abort(); /* every refusal says why */
        return 0;
    }
    char *text = cJSON_PrintUnformatted(v);
    if (!text) abort();
    /* what was accepted prints as text that is accepted again and prints the same (compared as
     * text: cJSON prints a number beyond double range, 1e400, as null) */
    cJSON *again = json_strict_parse(text, strlen(text), why, sizeof why);
    char *text2 = again ? cJSON_PrintUnformatted(again) : NULL;
    if (!text2 || strcmp(text, text2)) abort();
    free(text2);
    cJSON_Delete(again);
    free(text);
    cJSON_Delete(v);
    return 0;
}
