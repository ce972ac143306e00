/* json_strict.h — the one JSON reader for untrusted text: requests, the config file and the
 * state files. cJSON alone accepts text that is not one JSON value or that it cannot hold: it
 * stops at the end of the first value (`{"op":"list"}{"op":"destroy"}` ran list and dropped the
 * rest), keeps the first of duplicate members (`{"op":"get","op":"destroy"}`), ends strings
 * at U+0000 (`"list\u0000x"` read as "list"), and reads what RFC 8259 does not allow (`0200`
 * as 200, `1.`, form feed as whitespace, raw control characters and invalid UTF-8 in
 * strings). This reader follows RFC 8259's grammar exactly, requires UTF-8 (§8.1) and
 * rejects the rest, so what is acted on is exactly what was sent. Numbers beyond double
 * range (1e400) are grammatical and read as infinity: the callers' range checks refuse
 * them. */
#ifndef FX_JSON_STRICT_H
#define FX_JSON_STRICT_H

#include <stddef.h>
#include <cjson/cJSON.h>

/* Parses text[0..len) as exactly one JSON value with optional surrounding whitespace. Returns
 * the tree, or NULL with a message in why naming the byte (e.g. "trailing data after the JSON
 * value at byte 13", "duplicate member \"op\"", "a string contains U+0000 (byte 12)",
 * "invalid number at byte 50: a leading zero"). */
cJSON *json_strict_parse(const char *text, size_t len, char *why, size_t why_len);

#endif
