/* suggest.c — see suggest.h. */
#include "suggest.h"

#include <stdio.h>
#include <string.h>

#define SUGGEST_MAX 64 /* longer names are compared by their first 64 characters */

/* Levenshtein distance of a[0..n) and b[0..m), n, m <= SUGGEST_MAX. */
static int suggest_distance(const char *a, size_t n, const char *b, size_t m)
{
    int row[SUGGEST_MAX + 1];
    for (size_t j = 0; j <= m; j++) row[j] = (int)j;
    for (size_t i = 1; i <= n; i++) {
        int diag = row[0];
        row[0] = (int)i;
        for (size_t j = 1; j <= m; j++) {
            int up = row[j], best = diag + (a[i - 1] != b[j - 1]);
            if (up + 1 < best) best = up + 1;
            if (row[j - 1] + 1 < best) best = row[j - 1] + 1;
            diag = up;
            row[j] = best;
        }
    }
    return row[m];
}

void suggest_init(struct suggest *s, const char *word)
{
    s->word = word;
    s->best = NULL;
    s->dist = 1 << 30;
}

void suggest_offer(struct suggest *s, const char *candidate)
{
    size_t n = strnlen(s->word, SUGGEST_MAX), m = strnlen(candidate, SUGGEST_MAX);
    int d = suggest_distance(s->word, n, candidate, m);
    if (d < s->dist) {
        s->dist = d;
        s->best = candidate;
    }
}

const char *suggest_text(const struct suggest *s, char *buf, size_t len)
{
    int limit = (int)strnlen(s->word, SUGGEST_MAX) / 3;
    if (limit < 1) limit = 1;
    if (s->best && s->dist > 0 && s->dist <= limit) snprintf(buf, len, " (did you mean \"%s\"?)", s->best);
    else if (len) buf[0] = 0;
    return buf;
}
