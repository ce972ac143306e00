/* lwsreq.c — see lwsreq.h. The states, as lws_parse (lib/roles/http/parsers.c, 4.1) has them:
 *
 * - A name (WSI_TOKEN_NAME_PART): at a line's start a \n ends the headers. Each byte, lower-
 *   cased, is matched against lws's header names ("host:", "get ", "\r\n", ...; none is the
 *   start of another). A whole name ends the part: "\r\n" ends the headers, a method starts
 *   the request line, any other header its value. A byte that matches no name makes the name
 *   unknown (the request's first line: lws refuses it); an unknown name, \n included, runs on
 *   until its first ':' after that byte, then its value starts.
 * - The request line after the method: lws decodes %XX here; a \n ends the line (a \r too, up
 *   to the next \n). An escape we do not follow ends in LWSREQ_LOST.
 * - A value, known or not, ends at the next \n, whatever comes before it (\r, bytes past a
 *   token's length limit: lws skips to the \n). */
#include <stdlib.h>
#include <string.h>

#include <libwebsockets.h>

#include "lwsreq.h"

enum { LWSREQ_NAME, LWSREQ_REQLINE, LWSREQ_VALUE };
enum { LWSREQ_UP_NONE, LWSREQ_UP_VALUE, LWSREQ_UP_WEBSOCKET, LWSREQ_UP_OTHER };

static struct lwsreq_token {
    const char *s;
    uint8_t len, id;
} lwsreq_tok[WSI_TOKEN_COUNT];
static int lwsreq_ntok;

static int lwsreq_cmp(const void *a, const void *b)
{
    return strcmp(((const struct lwsreq_token *)a)->s, ((const struct lwsreq_token *)b)->s);
}

void lwsreq_init(void)
{
    if (lwsreq_ntok) return;
    for (int i = 0; i < WSI_TOKEN_COUNT; i++) {
        const char *s = (const char *)lws_token_to_string((enum lws_token_indexes)i);
        if (s && *s) lwsreq_tok[lwsreq_ntok++] = (struct lwsreq_token){s, (uint8_t)strlen(s), (uint8_t)i};
    }
    qsort(lwsreq_tok, (size_t)lwsreq_ntok, sizeof lwsreq_tok[0], lwsreq_cmp);
}

static void lwsreq_name_start(struct lwsreq *r)
{
    r->part = LWSREQ_NAME;
    r->line_start = true;
    r->unknown = false;
    r->lo = 0;
    r->hi = (uint8_t)lwsreq_ntok;
    r->nlen = 0;
}

void lwsreq_start(struct lwsreq *r)
{
    memset(r, 0, sizeof *r);
    lwsreq_name_start(r);
}

static bool lwsreq_method(int id)
{
    return id == WSI_TOKEN_GET_URI || id == WSI_TOKEN_POST_URI || id == WSI_TOKEN_OPTIONS_URI || id == WSI_TOKEN_PUT_URI ||
           id == WSI_TOKEN_PATCH_URI || id == WSI_TOKEN_DELETE_URI || id == WSI_TOKEN_CONNECT || id == WSI_TOKEN_HEAD_URI;
}

/* The end of the headers: how the request asked to go on. After a body the next request
 * starts where the body ends, which is not followed. */
static enum lwsreq_end lwsreq_done(const struct lwsreq *r)
{
    return r->up == LWSREQ_UP_WEBSOCKET ? LWSREQ_WEBSOCKET : r->body ? LWSREQ_LOST : LWSREQ_OTHER;
}

/* A whole known name was read. */
static enum lwsreq_end lwsreq_token(struct lwsreq *r, int id)
{
    if (id == WSI_TOKEN_CHALLENGE) return lwsreq_done(r); /* "\r\n" at a line's start */
    if (lwsreq_method(id)) {
        if (r->method || id == WSI_TOKEN_CONNECT) return LWSREQ_LOST;
        r->method = true;
        r->part = LWSREQ_REQLINE;
        r->esc = 0;
        return LWSREQ_MORE;
    }
    r->part = LWSREQ_VALUE;
    r->body = r->body || id == WSI_TOKEN_HTTP_CONTENT_LENGTH || id == WSI_TOKEN_HTTP_TRANSFER_ENCODING;
    if (id == WSI_TOKEN_UPGRADE && r->up == LWSREQ_UP_NONE) {
        r->up = LWSREQ_UP_VALUE;
        r->upn = 0;
    }
    return LWSREQ_MORE;
}

/* Narrows [lo, hi) to the names whose byte nlen is c (the table is sorted: they are together). */
static void lwsreq_narrow(struct lwsreq *r, uint8_t c)
{
    int lo = r->lo, hi = r->hi, n = r->nlen;
    while (lo < hi && (lwsreq_tok[lo].len <= n || (uint8_t)lwsreq_tok[lo].s[n] < c)) lo++;
    int end = lo;
    while (end < hi && lwsreq_tok[end].len > n && (uint8_t)lwsreq_tok[end].s[n] == c) end++;
    r->lo = (uint8_t)lo;
    r->hi = (uint8_t)end;
    r->nlen++;
}

static enum lwsreq_end lwsreq_name_byte(struct lwsreq *r, uint8_t b, bool first)
{
    if (r->line_start && b == '\n') return lwsreq_done(r); /* an empty line */
    r->line_start = r->line_start && first;                /* lws sees the second byte as a line's start too */
    if (r->unknown) {
        if (b == ':') r->part = LWSREQ_VALUE;
        return LWSREQ_MORE;
    }
    lwsreq_narrow(r, b >= 'A' && b <= 'Z' ? (uint8_t)(b + 'a' - 'A') : b);
    if (r->lo == r->hi) { /* no name lws knows: on the request's first line, lws refuses it */
        r->unknown = true;
        return r->method ? LWSREQ_MORE : LWSREQ_LOST;
    }
    return lwsreq_tok[r->lo].len == r->nlen ? lwsreq_token(r, lwsreq_tok[r->lo].id) : LWSREQ_MORE;
}

static int lwsreq_hex(uint8_t b)
{
    return b >= '0' && b <= '9' ? b - '0' : b >= 'a' && b <= 'f' ? b - 'a' + 10 : b >= 'A' && b <= 'F' ? b - 'A' + 10 : -1;
}

/* The request line after its method. lws decodes %XX in the path (and takes a decoded \r or
 * \n as the line's end, a decoded NUL as an error), and not in the version after it; the
 * difference matters only for such escapes, which are LWSREQ_LOST wherever they are. */
static enum lwsreq_end lwsreq_reqline_byte(struct lwsreq *r, uint8_t b)
{
    if (r->esc) {
        int h = lwsreq_hex(b);
        if (h < 0) return LWSREQ_LOST;
        if (r->esc++ == 1) {
            r->hex = (uint8_t)h;
            return LWSREQ_MORE;
        }
        int v = r->hex << 4 | h;
        r->esc = 0;
        return v == 0 || v == '\r' || v == '\n' ? LWSREQ_LOST : LWSREQ_MORE;
    }
    if (b == '%') r->esc = 1;
    else if (b == '\n') lwsreq_name_start(r);
    else if (b == '\r') r->part = LWSREQ_VALUE;
    return LWSREQ_MORE;
}

/* A value byte; the first Upgrade's value is compared as lws compares it (strcasecmp after its
 * leading spaces, up to the \r or \n that ends it). */
static void lwsreq_value_byte(struct lwsreq *r, uint8_t b)
{
    static const char want[] = "websocket";
    if (r->up != LWSREQ_UP_VALUE || (b == ' ' && r->upn == 0)) return;
    if (b == '\r' || b == '\n') {
        r->up = r->upn == sizeof want - 1 ? LWSREQ_UP_WEBSOCKET : LWSREQ_UP_OTHER;
    } else if (r->upn < sizeof want - 1 && (b | 0x20) == want[r->upn]) {
        r->upn++;
    } else {
        r->upn = 0xff; /* no longer "websocket" */
    }
}

enum lwsreq_end lwsreq_byte(struct lwsreq *r, uint8_t b)
{
    bool first = !r->started;
    r->started = true;
    switch (r->part) {
    case LWSREQ_NAME: return lwsreq_name_byte(r, b, first);
    case LWSREQ_REQLINE: return lwsreq_reqline_byte(r, b);
    default:
        lwsreq_value_byte(r, b);
        if (b == '\n') lwsreq_name_start(r);
        return LWSREQ_MORE;
    }
}
