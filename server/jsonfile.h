/* jsonfile.h — reading a whole JSON file (the config file, the state directory's streams).
 * One reader with one size bound, so a huge or truncated file is handled the same way
 * everywhere. */
#ifndef FX_JSONFILE_H
#define FX_JSONFILE_H

#include <cjson/cJSON.h>

/* Reads and parses path strictly (json_strict.h). Returns 0 with *out set, or NULL with the
 * reason in why when the text is not exactly one JSON value or is longer than max_bytes; or
 * -1 with errno set when the file cannot be read. */
int jsonfile_read(const char *path, long max_bytes, cJSON **out, char *why, size_t why_len);

#endif
