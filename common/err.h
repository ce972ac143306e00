/* err.h — errors as values.
 *
 * Every fallible function in the daemon returns 0 or -1 and fills a struct fx_err.
 * The code is one of the protocol's error codes, so a failure deep in validation
 * reaches the client as {"op":"error","code":...,"message":...,"param":...}
 * without translation layers. */
#ifndef FX_ERR_H
#define FX_ERR_H

#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "utf8.h"

struct fx_err {
    char code[24];    /* bad_json, bad_request, unknown_op, unknown_effect, unknown_stream,
                         exists, bad_param, limit, internal, unknown_preset, read_only,
                         unavailable, unauthorized, forbidden */
    char param[96];   /* offending parameter path (e.g. "curves[1].W[3]"), or "" */
    char message[320];
};

/* Replaces every byte of s that does not belong to a well-formed UTF-8 sequence (RFC 3629: no
 * overlong forms, surrogates or code points above U+10FFFF) with '?', in place. Messages quote
 * client text with bounded widths (%.64s) and are bounded themselves: a cut can split a
 * character, and a reply must still be valid UTF-8 (RFC 6455 text frames). */
static inline void fx_utf8_sanitize(char *s)
{
    unsigned char *p = (unsigned char *)s;
    for (size_t left = strlen(s), n; left; p += n, left -= n)
        if (!(n = utf8_seq_len(p, left))) *p = '?', n = 1;
}

/* Fills err (if non-NULL) and returns -1, so callers can `return fx_fail(...)`. */
static inline int fx_fail(struct fx_err *err, const char *code, const char *param, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static inline int fx_fail(struct fx_err *err, const char *code, const char *param, const char *fmt, ...)
{
    if (!err) return -1;
    va_list ap;
    snprintf(err->code, sizeof err->code, "%s", code);
    snprintf(err->param, sizeof err->param, "%s", param ? param : "");
    va_start(ap, fmt);
    vsnprintf(err->message, sizeof err->message, fmt, ap);
    va_end(ap);
    fx_utf8_sanitize(err->param);
    fx_utf8_sanitize(err->message);
    return -1;
}

#endif
