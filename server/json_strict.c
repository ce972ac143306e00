/* json_strict.c — see json_strict.h.
 *
 * The text is first checked against RFC 8259's grammar here (js_value and its helpers, one
 * recursive-descent pass that builds nothing), then parsed by cJSON, whose tree is checked
 * for duplicate members. cJSON alone is laxer than the grammar: it takes any byte up to a
 * space as whitespace, reads numbers with strtod (0200, 1., -00) and copies control
 * characters in strings; none of that reaches it now. */
#include "json_strict.h"
#include "utf8.h"

#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define JS_MAX_DEPTH CJSON_NESTING_LIMIT /* cJSON's own: deeper text is refused either way */

struct js {
    const unsigned char *t;
    size_t len, i;
    int depth;
    char *why;
    size_t why_len;
};

static bool js_fail(struct js *j, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(j->why, j->why_len, fmt, ap);
    va_end(ap);
    return false;
}

static int js_peek(const struct js *j) { return j->i < j->len ? j->t[j->i] : -1; }

/* RFC 8259 §2: whitespace is space, tab, line feed and carriage return only. */
static void js_space(struct js *j)
{
    while (j->i < j->len && (j->t[j->i] == ' ' || j->t[j->i] == '\t' || j->t[j->i] == '\n' || j->t[j->i] == '\r'))
        j->i++;
}

/* What stands at the current position, for a message: "end of text" or the byte. */
static bool js_unexpected(struct js *j, const char *wanted)
{
    int c = js_peek(j);
    if (c < 0) return js_fail(j, "malformed JSON near byte %zu: the text ends where %s is expected", j->i, wanted);
    if (c >= 0x20 && c < 0x7f)
        return js_fail(j, "malformed JSON near byte %zu: '%c' where %s is expected", j->i, c, wanted);
    return js_fail(j, "malformed JSON near byte %zu: byte 0x%02x where %s is expected", j->i, c, wanted);
}

static bool js_digit(const struct js *j) { return js_peek(j) >= '0' && js_peek(j) <= '9'; }

/* number = [ minus ] int [ frac ] [ exp ]; int = zero / ( digit1-9 *DIGIT ) */
static bool js_number(struct js *j)
{
    size_t start = j->i;
    if (js_peek(j) == '-') j->i++;
    if (!js_digit(j)) return js_fail(j, "invalid number at byte %zu: a digit must follow '-'", start);
    if (js_peek(j) == '0') {
        j->i++;
        if (js_digit(j)) return js_fail(j, "invalid number at byte %zu: a leading zero", start);
    }
    while (js_digit(j)) j->i++;
    if (js_peek(j) == '.') {
        j->i++;
        if (!js_digit(j)) return js_fail(j, "invalid number at byte %zu: a digit must follow '.'", start);
        while (js_digit(j)) j->i++;
    }
    if (js_peek(j) == 'e' || js_peek(j) == 'E') {
        j->i++;
        if (js_peek(j) == '+' || js_peek(j) == '-') j->i++;
        if (!js_digit(j)) return js_fail(j, "invalid number at byte %zu: a digit must follow the exponent", start);
        while (js_digit(j)) j->i++;
    }
    return true;
}

static int js_hex4(const unsigned char *p)
{
    int v = 0;
    for (int k = 0; k < 4; k++) {
        int c = p[k], d = c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10
                        : c >= 'A' && c <= 'F' ? c - 'A' + 10 : -1;
        if (d < 0) return -1;
        v = v << 4 | d;
    }
    return v;
}

/* One \uXXXX escape at j->i (the backslash), a surrogate pair taken whole. */
static bool js_escape_u(struct js *j)
{
    size_t at = j->i;
    int u = j->i + 6 <= j->len ? js_hex4(j->t + j->i + 2) : -1;
    if (u < 0) return js_fail(j, "invalid \\u escape at byte %zu: four hex digits must follow", at);
    if (u == 0) return js_fail(j, "a string contains U+0000 (byte %zu)", at);
    j->i += 6;
    if (u >= 0xdc00 && u <= 0xdfff) return js_fail(j, "unpaired UTF-16 surrogate \\u%04X at byte %zu", u, at);
    if (u < 0xd800 || u > 0xdbff) return true;
    int lo = j->i + 6 <= j->len && j->t[j->i] == '\\' && j->t[j->i + 1] == 'u' ? js_hex4(j->t + j->i + 2) : -1;
    if (lo < 0xdc00 || lo > 0xdfff) return js_fail(j, "unpaired UTF-16 surrogate \\u%04X at byte %zu", u, at);
    j->i += 6;
    return true;
}

static bool js_string(struct js *j)
{
    size_t start = j->i++;
    while (j->i < j->len) {
        unsigned c = j->t[j->i];
        if (c == '"') {
            j->i++;
            return true;
        }
        if (c == 0) return js_fail(j, "a string contains U+0000 (byte %zu)", j->i);
        if (c < 0x20)
            return js_fail(j, "a raw control character U+%04X in a string at byte %zu (escape it: \\u%04x)", c, j->i, c);
        if (c == '\\') {
            int e = j->i + 1 < j->len ? j->t[j->i + 1] : -1;
            if (e == 'u') {
                if (!js_escape_u(j)) return false;
                continue;
            }
            if (e <= 0 || !strchr("\"\\/bfnrt", e))
                return js_fail(j, "invalid escape in a string at byte %zu (only \\\" \\\\ \\/ \\b \\f \\n \\r \\t \\uXXXX)", j->i);
            j->i += 2;
        } else if (c < 0x80) {
            j->i++;
        } else {
            size_t n = utf8_seq_len(j->t + j->i, j->len - j->i);
            if (!n) return js_fail(j, "invalid UTF-8 in a string at byte %zu", j->i);
            j->i += n;
        }
    }
    return js_fail(j, "malformed JSON near byte %zu: the string that starts there never ends", start);
}

static bool js_value(struct js *j);

/* An object or an array, at its opening bracket. */
static bool js_container(struct js *j, bool object)
{
    char close = object ? '}' : ']';
    if (++j->depth > JS_MAX_DEPTH) return js_fail(j, "JSON nested deeper than %d levels at byte %zu", JS_MAX_DEPTH, j->i);
    j->i++;
    js_space(j);
    if (js_peek(j) == close) {
        j->i++;
        j->depth--;
        return true;
    }
    for (;;) {
        if (object) {
            if (js_peek(j) != '"') return js_unexpected(j, "a member name");
            if (!js_string(j)) return false;
            js_space(j);
            if (js_peek(j) != ':') return js_unexpected(j, "':'");
            j->i++;
        }
        if (!js_value(j)) return false;
        js_space(j);
        if (js_peek(j) == close) break;
        if (js_peek(j) != ',') return js_unexpected(j, object ? "',' or '}'" : "',' or ']'");
        j->i++;
        js_space(j);
    }
    j->i++;
    j->depth--;
    return true;
}

static bool js_literal(struct js *j, const char *word)
{
    size_t n = strlen(word);
    if (j->len - j->i < n || memcmp(j->t + j->i, word, n)) return js_unexpected(j, "a value");
    j->i += n;
    return true;
}

/* A value with the whitespace before it. */
static bool js_value(struct js *j)
{
    js_space(j);
    switch (js_peek(j)) {
    case '{': return js_container(j, true);
    case '[': return js_container(j, false);
    case '"': return js_string(j);
    case 't': return js_literal(j, "true");
    case 'f': return js_literal(j, "false");
    case 'n': return js_literal(j, "null");
    default: return js_peek(j) == '-' || js_digit(j) ? js_number(j) : js_unexpected(j, "a value");
    }
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
    struct js j = {(const unsigned char *)text, len, 0, 0, why, why_len};
    if (!js_value(&j)) return NULL;
    js_space(&j);
    if (j.i < len) {
        snprintf(why, why_len, "trailing data after the JSON value at byte %zu", j.i);
        return NULL;
    }
    cJSON *v = cJSON_ParseWithLength(text, len);
    if (!v) { /* the grammar holds: only memory can fail here */
        snprintf(why, why_len, "cannot parse the JSON text (out of memory)");
        return NULL;
    }
    const char *dup = js_duplicate(v);
    if (dup) {
        snprintf(why, why_len, "duplicate member \"%.64s\"", dup);
        cJSON_Delete(v);
        return NULL;
    }
    return v;
}
