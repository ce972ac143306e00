/* jsonfile.c — see jsonfile.h. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "jsonfile.h"
#include "json_strict.h"

int jsonfile_read(const char *path, long max_bytes, cJSON **out, char *why, size_t why_len)
{
    *out = NULL;
    FILE *f = fopen(path, "rb");
    if (!f) return -1;
    char *text = NULL;
    long size = fseek(f, 0, SEEK_END) == 0 ? ftell(f) : -1;
    size_t n = 0;
    if (size >= 0 && size <= max_bytes && fseek(f, 0, SEEK_SET) == 0 && (text = malloc((size_t)size + 1)))
        n = fread(text, 1, (size_t)size, f);
    fclose(f);
    if (!text) snprintf(why, why_len, "larger than %ld bytes", max_bytes);
    *out = text ? json_strict_parse(text, n, why, why_len) : NULL; /* n, not strlen: a NUL byte is refused */
    free(text);
    return 0;
}
