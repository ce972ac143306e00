/* json_strict.h — the one JSON reader for untrusted text: requests, the config file and the
 * state file. cJSON alone accepts text that is not one JSON value or that it cannot hold: it
 * stops at the end of the first value (`{"op":"list"}{"op":"destroy"}` ran list and dropped the
 * rest), keeps the first of duplicate members (`{"op":"get","op":"destroy"}`), and ends strings
 * at U+0000 (`"list\u0000x"` read as "list"). This reader rejects all three, so what is acted
 * on is exactly what was sent (issue 15 items 9-11). */
#ifndef FX_JSON_STRICT_H
#define FX_JSON_STRICT_H

#include <stddef.h>
#include <cjson/cJSON.h>

/* Parses text[0..len) as exactly one JSON value with optional surrounding whitespace. Returns
 * the tree, or NULL with a message in why (e.g. "trailing data after the JSON value at byte
 * 13", "duplicate member \"op\"", "a string contains U+0000 (byte 12)"). */
cJSON *json_strict_parse(const char *text, size_t len, char *why, size_t why_len);

#endif
