/* jsonfile.h — reading a whole JSON file (the config file, the state directory's streams).
 * One reader with one size bound, so a huge or truncated file is handled the same way
 * everywhere. */
#ifndef FX_JSONFILE_H
#define FX_JSONFILE_H

#include <cjson/cJSON.h>

/* Reads and parses path. Returns 0 with *out set, NULL when the text is not JSON or is
 * longer than max_bytes; or -1 with errno set when the file cannot be read. */
int jsonfile_read(const char *path, long max_bytes, cJSON **out);

#endif
