/* fxctl_print.h — fxctl's output for people (stdout a terminal, no --json): `describe` as a
 * table by group, `get` as aligned name = value, `set` as the changed values with the new
 * rev, `preset load` as the values that changed with what they were, `list` and `presets` as
 * tables, `create`, `destroy`, `reset`, `preset save` and `preset delete` as one sentence.
 * Every other reply (subscribe's and watch's lines), and everything when stdout is not a
 * terminal or with --json, stays one line of JSON (fxctl.c). */
#ifndef FXCTL_PRINT_H
#define FXCTL_PRINT_H

#include <stdbool.h>
#include <stdio.h>
#include <cjson/cJSON.h>

/* Prints reply for a person and returns true; false when the reply has no human form (the
 * caller prints its JSON). For a `params` reply: `only` (may be NULL) names the parameters to
 * show (a set's, or those a preset load changed), NULL shows every one; `before` (may be
 * NULL), the values before the change, adds "(was OLD)" to each. */
bool fxctl_print_human(FILE *f, const cJSON *reply, const cJSON *only, const cJSON *before);

#endif
