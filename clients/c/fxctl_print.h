/* fxctl_print.h — fxctl's output for people (stdout a terminal, no --json): `describe` as a
 * table by group, `get` as aligned name = value, `set` as the changed values with the new
 * rev, `list` and `presets` as tables. Every other reply, and everything when stdout is not
 * a terminal or with --json, stays one line of JSON (fxctl.c). */
#ifndef FXCTL_PRINT_H
#define FXCTL_PRINT_H

#include <stdbool.h>
#include <stdio.h>
#include <cjson/cJSON.h>

/* Prints reply (op describe, params, list or presets) for a person and returns true; false
 * when the reply has no human form (the caller prints its JSON). `only` (may be NULL): for a
 * `params` reply, the names to show (a set's changed parameters); NULL shows every one. */
bool fxctl_print_human(FILE *f, const cJSON *reply, const cJSON *only);

#endif
