/* fxctl_print.c — see fxctl_print.h. Tables: columns padded to their widest cell, the last
 * column wrapped to the terminal's width under itself. */
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include "fxctl_print.h"

#define FXP_MAX_COLS 8
#define FXP_VALUE_MAX 70   /* characters of a value shown after "=" */
#define FXP_DEFAULT_MAX 28 /* ... and of a default in describe's table */
#define FXP_WAS_INLINE 40  /* a value and what it was this long share a line */

struct fxp_table {
    int ncols, nrows, cap;
    char **cells; /* nrows x ncols, owned */
};

static int fxp_width(void)
{
    struct winsize ws;
    if (ioctl(STDOUT_FILENO, TIOCGWINSZ, &ws) == 0 && ws.ws_col >= 40) return ws.ws_col;
    return 100;
}

/* Characters on screen (UTF-8 continuation bytes do not count). */
static int fxp_len(const char *s)
{
    int n = 0;
    for (; *s; s++) n += ((unsigned char)*s & 0xC0) != 0x80;
    return n;
}

static void fxp_add(struct fxp_table *t, const char *const *row)
{
    if (t->nrows == t->cap) {
        t->cap = t->cap ? 2 * t->cap : 32;
        t->cells = realloc(t->cells, (size_t)t->cap * FXP_MAX_COLS * sizeof *t->cells);
    }
    for (int c = 0; c < t->ncols; c++) t->cells[t->nrows * FXP_MAX_COLS + c] = strdup(row[c] ? row[c] : "");
    t->nrows++;
}

/* The last cell from column `at`, wrapped at word boundaries to `room` characters. */
static void fxp_wrapped(FILE *f, const char *text, int at, int room)
{
    int col = 0;
    while (*text) {
        int word = (int)strcspn(text, " ");
        if (col && col + 1 + word > room) {
            fprintf(f, "\n%*s", at, "");
            col = 0;
        } else if (col) {
            fputc(' ', f);
            col++;
        }
        fprintf(f, "%.*s", word, text);
        col += word;
        text += word;
        while (*text == ' ') text++;
    }
    fputc('\n', f);
}

static void fxp_print(FILE *f, struct fxp_table *t)
{
    int w[FXP_MAX_COLS] = {0}, at = 0;
    for (int r = 0; r < t->nrows; r++)
        for (int c = 0; c < t->ncols - 1; c++) {
            int l = fxp_len(t->cells[r * FXP_MAX_COLS + c]);
            if (l > w[c]) w[c] = l;
        }
    for (int c = 0; c < t->ncols - 1; c++) at += w[c] + 2;
    int room = fxp_width() - at;
    if (room < 30) room = 30;
    for (int r = 0; r < t->nrows; r++) {
        for (int c = 0; c < t->ncols - 1; c++) {
            const char *s = t->cells[r * FXP_MAX_COLS + c];
            fprintf(f, "%s%*s", s, w[c] + 2 - fxp_len(s), "");
        }
        fxp_wrapped(f, t->cells[r * FXP_MAX_COLS + t->ncols - 1], at, room);
    }
    for (int i = 0; i < t->nrows * FXP_MAX_COLS; i++)
        if (i % FXP_MAX_COLS < t->ncols) free(t->cells[i]);
    free(t->cells);
}

/* Compact JSON of v, cut to max characters with "…" (buf holds at least max + 1 bytes). */
static void fxp_value(const cJSON *v, char *buf, size_t len, int max)
{
    char *s = cJSON_PrintUnformatted(v);
    snprintf(buf, len, "%s", s ? s : "?");
    if (strlen(buf) > (size_t)max) strcpy(buf + max - 3, "…");
    free(s);
}

static const char *fxp_str(const cJSON *o, const char *name)
{
    const char *s = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, name));
    return s ? s : "";
}

static double fxp_num(const cJSON *o, const char *name)
{
    return cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(o, name));
}

/* The range column of a descriptor, as PROTOCOL.md's tables write it. */
static void fxp_range(const cJSON *p, char *buf, size_t len)
{
    const char *t = fxp_str(p, "type");
    if (!strcmp(t, "enum")) {
        size_t n = 0;
        buf[0] = 0;
        for (const cJSON *c = cJSON_GetObjectItemCaseSensitive(p, "choices")->child; c && n < len; c = c->next)
            n += (size_t)snprintf(buf + n, len - n, "%s%s", n ? " | " : "", c->valuestring);
    } else if (!strcmp(t, "bool")) {
        snprintf(buf, len, "true | false");
    } else if (!strcmp(t, "object_list")) {
        snprintf(buf, len, "%g–%g items", fxp_num(p, "min_len"), fxp_num(p, "max_len"));
    } else if (!strcmp(t, "vec3") || !strcmp(t, "color")) {
        snprintf(buf, len, "3 × [%g, %g]", fxp_num(p, "min"), fxp_num(p, "max"));
    } else if (!strcmp(t, "float_list")) {
        snprintf(buf, len, "%g–%g × [%g, %g]", fxp_num(p, "min_len"), fxp_num(p, "max_len"), fxp_num(p, "min"),
                 fxp_num(p, "max"));
    } else {
        snprintf(buf, len, "%g … %g%s", fxp_num(p, "min"), fxp_num(p, "max"),
                 cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(p, "even")) ? ", even" : "");
    }
}

/* One describe row per parameter of `group`. */
static void fxp_group(FILE *f, const cJSON *params, const char *group)
{
    struct fxp_table t = {.ncols = 7};
    fprintf(f, "\n[%s]\n", group);
    fxp_add(&t, (const char *[]){"name", "type", "default", "range", "unit", "update", "doc"});
    for (const cJSON *p = params->child; p; p = p->next) {
        if (strcmp(group, fxp_str(p, "group"))) continue;
        char def[FXP_DEFAULT_MAX + 8], range[160];
        fxp_value(cJSON_GetObjectItemCaseSensitive(p, "default"), def, sizeof def, FXP_DEFAULT_MAX);
        fxp_range(p, range, sizeof range);
        fxp_add(&t, (const char *[]){fxp_str(p, "name"), fxp_str(p, "type"), def, range, fxp_str(p, "unit"),
                                     fxp_str(p, "update"), fxp_str(p, "doc")});
    }
    fxp_print(f, &t);
}

/* describe: the effect's doc, then one table per group, groups in order of first appearance. */
static void fxp_describe(FILE *f, const cJSON *r)
{
    fprintf(f, "%s\n", fxp_str(r, "effect"));
    fxp_wrapped(f, fxp_str(r, "doc"), 0, fxp_width());
    const cJSON *params = cJSON_GetObjectItemCaseSensitive(r, "params");
    for (const cJSON *p = params ? params->child : NULL; p; p = p->next) {
        bool first = true;
        for (const cJSON *q = params->child; q != p && first; q = q->next)
            first = strcmp(fxp_str(q, "group"), fxp_str(p, "group")) != 0;
        if (first) fxp_group(f, params, fxp_str(p, "group"));
    }
}

/* params (get, set, preset load): "STREAM · rev N", then name = value for each (or each of
 * `only`), with what it was from `before` when given: "(was OLD)" after a short value, else on
 * a row of its own; "(no value changed)" when `only` leaves nothing. */
static void fxp_params(FILE *f, const cJSON *r, const cJSON *only, const cJSON *before)
{
    fprintf(f, "%s · rev %.0f\n", fxp_str(r, "stream"), fxp_num(r, "rev"));
    const cJSON *params = cJSON_GetObjectItemCaseSensitive(r, "params");
    struct fxp_table t = {.ncols = 2};
    for (const cJSON *p = params ? params->child : NULL; p; p = p->next) {
        if (only && !cJSON_GetObjectItemCaseSensitive(only, p->string)) continue;
        char name[96], val[FXP_VALUE_MAX + 8], old[FXP_VALUE_MAX + 8], shown[2 * FXP_VALUE_MAX + 32];
        const cJSON *prev = cJSON_GetObjectItemCaseSensitive(before, p->string);
        snprintf(name, sizeof name, "  %s", p->string);
        fxp_value(p, val, sizeof val, FXP_VALUE_MAX);
        if (prev) fxp_value(prev, old, sizeof old, FXP_VALUE_MAX);
        else snprintf(old, sizeof old, "unset");
        int one_line = !before || fxp_len(val) + fxp_len(old) <= FXP_WAS_INLINE;
        snprintf(shown, sizeof shown, "= %s%s%s%s", val, before && one_line ? "  (was " : "", before && one_line ? old : "",
                 before && one_line ? ")" : "");
        fxp_add(&t, (const char *[]){name, shown});
        if (one_line) continue;
        snprintf(shown, sizeof shown, "  was %s", old);
        fxp_add(&t, (const char *[]){"", shown});
    }
    if (only && !t.nrows) fprintf(f, "  (no value changed)\n");
    fxp_print(f, &t);
}

/* The replies that are one sentence: created, destroyed, reset, preset_saved, preset_deleted.
 * False for another op. */
static bool fxp_sentence(FILE *f, const cJSON *r, const char *op)
{
    const char *stream = fxp_str(r, "stream"), *effect = fxp_str(r, "effect"), *name = fxp_str(r, "name");
    if (!strcmp(op, "created"))
        fprintf(f, "created stream %s (effect %s, rev %.0f)\n", stream, effect, fxp_num(r, "rev"));
    else if (!strcmp(op, "destroyed"))
        fprintf(f, "destroyed stream %s\n", stream);
    else if (!strcmp(op, "reset"))
        fprintf(f, "reset stream %s: its simulation starts over (sim_time 0)\n", stream);
    else if (!strcmp(op, "preset_saved"))
        fprintf(f, "saved preset %s of %s%s\n", name, effect,
                cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(r, "replaced")) ? ", replacing the one saved before" : "");
    else if (!strcmp(op, "preset_deleted"))
        fprintf(f, "deleted preset %s of %s\n", name, effect);
    else
        return false;
    return true;
}

static void fxp_list(FILE *f, const cJSON *r)
{
    struct fxp_table t = {.ncols = 5};
    fxp_add(&t, (const char *[]){"stream", "effect", "subscribers", "rev", "fps"});
    for (const cJSON *s = cJSON_GetObjectItemCaseSensitive(r, "streams")->child; s; s = s->next) {
        char subs[24], rev[24], fps[24];
        snprintf(subs, sizeof subs, "%.0f", fxp_num(s, "subscribers"));
        snprintf(rev, sizeof rev, "%.0f", fxp_num(s, "rev"));
        snprintf(fps, sizeof fps, "%g", fxp_num(s, "fps"));
        fxp_add(&t, (const char *[]){fxp_str(s, "stream"), fxp_str(s, "effect"), subs, rev, fps});
    }
    fxp_print(f, &t);
}

static void fxp_presets(FILE *f, const cJSON *r)
{
    struct fxp_table t = {.ncols = 4};
    fxp_add(&t, (const char *[]){"effect", "preset", "kind", "doc"});
    for (const cJSON *p = cJSON_GetObjectItemCaseSensitive(r, "presets")->child; p; p = p->next)
        fxp_add(&t, (const char *[]){fxp_str(p, "effect"), fxp_str(p, "name"),
                                     cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(p, "builtin")) ? "built-in" : "saved",
                                     fxp_str(p, "doc")});
    fxp_print(f, &t);
}

bool fxctl_print_human(FILE *f, const cJSON *reply, const cJSON *only, const cJSON *before)
{
    const char *op = fxp_str(reply, "op");
    if (!strcmp(op, "describe")) fxp_describe(f, reply);
    else if (!strcmp(op, "params")) fxp_params(f, reply, only, before);
    else if (!strcmp(op, "list")) fxp_list(f, reply);
    else if (!strcmp(op, "presets")) fxp_presets(f, reply);
    else return fxp_sentence(f, reply, op);
    return true;
}
