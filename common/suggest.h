/* suggest.h — "did you mean": the known name nearest to a misspelt one, for the error messages
 * of unknown parameters, ops, effects, streams and presets and for fxctl's commands, so a client
 * or a person at fxctl sees `alpa: unknown parameter (did you mean "alpha"?)`. The distance is
 * optimal string alignment: a dropped, added or changed letter and a swap of two adjacent ones
 * (`alhpa`) each count one edit. In common/, as the daemon and fxctl both link it. */
#ifndef FX_SUGGEST_H
#define FX_SUGGEST_H

#include <stddef.h>

struct suggest {
    const char *word; /* the unknown name */
    const char *best; /* the nearest candidate so far, or NULL */
    int dist;
};

void suggest_init(struct suggest *s, const char *word);
/* Considers one known name. */
void suggest_offer(struct suggest *s, const char *candidate);
/* ` (did you mean "NAME"?)` when a candidate is within a third of the word's length (at least
 * one edit), else "" (buf holds the text; returned). */
const char *suggest_text(const struct suggest *s, char *buf, size_t len);

#endif
