/* utf8.h — the one definition of well-formed UTF-8 (RFC 3629: shortest forms only, no
 * surrogates, nothing above U+10FFFF) for everything the daemon reads or sends as text: the
 * JSON reader, error messages that quote client text, the reason of a client's close frame. */
#ifndef FX_UTF8_H
#define FX_UTF8_H

#include <stdbool.h>
#include <stddef.h>

/* The length (1-4) of the well-formed sequence at p[0..left), or 0 when none starts there
 * (a stray continuation byte, a bad lead byte, a sequence cut short or malformed). */
static inline size_t utf8_seq_len(const unsigned char *p, size_t left)
{
    unsigned c = left ? p[0] : 0x80;
    size_t n = c < 0x80 ? 1 : c >= 0xc2 && c <= 0xdf ? 2 : c >= 0xe0 && c <= 0xef ? 3 : c >= 0xf0 && c <= 0xf4 ? 4 : 0;
    if (!n || n > left) return 0;
    unsigned lo = c == 0xe0 ? 0xa0 : c == 0xf0 ? 0x90 : 0x80, hi = c == 0xed ? 0x9f : c == 0xf4 ? 0x8f : 0xbf;
    for (size_t k = 1; k < n; k++)
        if (p[k] < (k == 1 ? lo : 0x80) || p[k] > (k == 1 ? hi : 0xbf)) return 0;
    return n;
}

/* Whether p[0..len) is well-formed UTF-8 throughout. */
static inline bool utf8_valid(const unsigned char *p, size_t len)
{
    for (size_t i = 0, n; i < len; i += n)
        if (!(n = utf8_seq_len(p + i, len - i))) return false;
    return true;
}

#endif
