/* jsonfile.h — reading a whole JSON file (the config file, the state directory's files) and
 * writing one atomically. One reader with one size bound, so a huge or truncated file is
 * handled the same way everywhere, and one writer, so no state file can be left torn. */
#ifndef FX_JSONFILE_H
#define FX_JSONFILE_H

#include <cjson/cJSON.h>

/* Reads and parses path strictly (json_strict.h). Returns 0 with *out set, or NULL with the
 * reason in why when the text is not exactly one JSON value or is longer than max_bytes; or
 * -1 with errno set when the file cannot be read. */
int jsonfile_read(const char *path, long max_bytes, cJSON **out, char *why, size_t why_len);

/* Writes text to dir/name atomically: a temporary file, fsync'ed, renamed over the old one,
 * then the directory fsync'ed, so a crash at any moment leaves the old or the new file.
 * 0, or -1 with errno set (the old file is untouched). */
int jsonfile_write(const char *dir, const char *name, const char *text);

#endif
