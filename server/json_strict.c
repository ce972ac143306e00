/* json_strict.c — see json_strict.h. */
#include "json_strict.h"

#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
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

static int js_cmp(const void *a, const void *b) { return strcmp(*(const char *const *)a, *(const char *const *)b); }

/* A member name that appears twice in object v, or NULL: its names sorted, neighbours compared
 * (n log n: a 64 KiB request of ~6000 members compared pairwise took tens of ms). */
static const char *js_duplicate_member(const cJSON *v)
{
    int n = cJSON_GetArraySize(v);
    const char **names = n > 1 ? malloc(sizeof *names * (size_t)n) : NULL, *dup = NULL;
    if (!names) return NULL; /* 0 or 1 member (or out of memory: cJSON's first-wins stays) */
    int i = 0;
    for (const cJSON *m = v->child; m; m = m->next) names[i++] = m->string;
    qsort(names, (size_t)n, sizeof *names, js_cmp);
    for (i = 1; i < n && !dup; i++)
        if (!strcmp(names[i - 1], names[i])) dup = names[i];
    free(names);
    return dup;
}

/* The first duplicate member name in any object of the tree, or NULL. */
static const char *js_duplicate(const cJSON *v)
{
    const char *d = cJSON_IsObject(v) ? js_duplicate_member(v) : NULL;
    for (const cJSON *a = v->child; a && !d; a = a->next) d = js_duplicate(a);
    return d;
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
