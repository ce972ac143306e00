/* jsonfile.c — see jsonfile.h. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>

#include "jsonfile.h"

int jsonfile_read(const char *path, long max_bytes, cJSON **out)
{
    *out = NULL;
    FILE *f = fopen(path, "rb");
    if (!f) return -1;
    char *text = NULL;
    long size = fseek(f, 0, SEEK_END) == 0 ? ftell(f) : -1;
    if (size >= 0 && size <= max_bytes && fseek(f, 0, SEEK_SET) == 0 && (text = malloc((size_t)size + 1)))
        text[fread(text, 1, (size_t)size, f)] = 0;
    fclose(f);
    *out = text ? cJSON_Parse(text) : NULL;
    free(text);
    return 0;
}
