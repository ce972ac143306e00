/* suggest.c — see suggest.h. */
#include "suggest.h"

#include <stdio.h>
#include <string.h>

#define SUGGEST_MAX 64 /* longer names are compared by their first 64 characters */

/* Optimal string alignment distance of a[0..n) and b[0..m), n, m <= SUGGEST_MAX: insertions,
 * deletions, substitutions and swaps of two adjacent characters (k_bou for k_buo) each count
 * one edit. Three rows: the one before the previous is what a swap extends. */
static int suggest_distance(const char *a, size_t n, const char *b, size_t m)
{
    int rows[3][SUGGEST_MAX + 1];
    for (size_t j = 0; j <= m; j++) rows[0][j] = (int)j;
    for (size_t i = 1; i <= n; i++) {
        int *cur = rows[i % 3], *prev = rows[(i - 1) % 3], *prev2 = rows[(i + 1) % 3];
        cur[0] = (int)i;
        for (size_t j = 1; j <= m; j++) {
            int best = prev[j - 1] + (a[i - 1] != b[j - 1]);
            if (prev[j] + 1 < best) best = prev[j] + 1;
            if (cur[j - 1] + 1 < best) best = cur[j - 1] + 1;
            if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] && prev2[j - 2] + 1 < best)
                best = prev2[j - 2] + 1;
            cur[j] = best;
        }
    }
    return rows[n % 3][m];
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
