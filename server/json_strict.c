/* json_strict.c — see json_strict.h. */
#include "json_strict.h"

#include <stdbool.h>
#include <stdio.h>
#include <string.h>

/* Byte offset of the first \u0000 escape or raw NUL inside a string of text, or -1. */
static long js_find_nul(const char *t, size_t len)
{
    bool in = false;
    for (size_t i = 0; i < len; i++) {
        if (t[i] == 0) return (long)i;
        if (!in) {
            in = t[i] == '"';
        } else if (t[i] == '"') {
            in = false;
        } else if (t[i] == '\\' && i + 1 < len) {
            if (t[i + 1] == 'u' && i + 5 < len && !memcmp(t + i + 2, "0000", 4)) return (long)i;
            i++; /* the escaped character, a quote included */
        }
    }
    return -1;
}

/* The first member name that appears twice in one object anywhere in the tree, or NULL. */
static const char *js_duplicate(const cJSON *v)
{
    for (const cJSON *a = v ? v->child : NULL; a; a = a->next) {
        if (cJSON_IsObject(v))
            for (const cJSON *b = a->next; b; b = b->next)
                if (!strcmp(a->string, b->string)) return a->string;
        const char *d = js_duplicate(a);
        if (d) return d;
    }
    return NULL;
}

cJSON *json_strict_parse(const char *text, size_t len, char *why, size_t why_len)
{
    const char *end = NULL;
    long nul = js_find_nul(text, len);
    if (nul >= 0) {
        snprintf(why, why_len, "a string contains U+0000 (byte %ld)", nul);
        return NULL;
    }
    cJSON *v = cJSON_ParseWithLengthOpts(text, len, &end, 0);
    if (!v) {
        const char *at = cJSON_GetErrorPtr();
        snprintf(why, why_len, "malformed JSON near byte %ld", at ? (long)(at - text) : 0L);
        return NULL;
    }
    size_t rest = (size_t)(end - text);
    while (rest < len && strchr(" \t\r\n", text[rest])) rest++;
    const char *dup = rest < len ? NULL : js_duplicate(v);
    if (rest < len) snprintf(why, why_len, "trailing data after the JSON value at byte %zu", rest);
    else if (dup) snprintf(why, why_len, "duplicate member \"%.64s\"", dup);
    if (rest < len || dup) {
        cJSON_Delete(v);
        return NULL;
    }
    return v;
}
