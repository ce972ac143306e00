/* jsonfile.c — see jsonfile.h. */
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

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

static int jsonfile_write_all(int fd, const char *text, size_t len)
{
    while (len) {
        ssize_t w = write(fd, text, len);
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) return -1;
        text += w;
        len -= (size_t)w;
    }
    return 0;
}

int jsonfile_write(const char *dir, const char *name, const char *text)
{
    char tmp[PATH_MAX + 64], path[PATH_MAX + 64];
    snprintf(tmp, sizeof tmp, "%s/%s.tmp", dir, name);
    snprintf(path, sizeof path, "%s/%s", dir, name);
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) return -1;
    int rc = jsonfile_write_all(fd, text, strlen(text)) || fsync(fd);
    rc |= close(fd);
    if (rc || rename(tmp, path)) {
        int e = errno;
        unlink(tmp);
        errno = e;
        return -1;
    }
    int dfd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (dfd >= 0) {
        fsync(dfd);
        close(dfd);
    }
    return 0;
}
