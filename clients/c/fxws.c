/* fxws.c — see fxws.h. Moved out of fxclient.c unchanged in behaviour (same messages,
 * same limits) so that fxpool.c can share it. */
#include "fxws.h"

#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <netdb.h>
#include <poll.h>
#include <pthread.h>
#include <sys/socket.h>
#include <unistd.h>

#include <libwebsockets.h>

#define FXWS_PROBE_WAIT_MS 1000
#define FXWS_RX_MIN_CAP 65536

void fxws_set_err(char *buf, size_t len, const char *fmt, ...)
{
    va_list ap;
    if (!buf || !len) return;
    va_start(ap, fmt);
    vsnprintf(buf, len, fmt, ap);
    va_end(ap);
}

/* ---- logging ---------------------------------------------------------------- */

static int fxws_log_chosen; /* fxws_log_set was called: fxws_log_default leaves lws alone */
static pthread_once_t fxws_log_once = PTHREAD_ONCE_INIT;

void fxws_log_set(int levels, void (*emit)(int level, const char *line))
{
    __atomic_store_n(&fxws_log_chosen, 1, __ATOMIC_RELEASE);
    lws_set_log_level(levels, emit ? emit : lwsl_emit_stderr);
}

static void fxws_log_quiet(void)
{
    if (!__atomic_load_n(&fxws_log_chosen, __ATOMIC_ACQUIRE)) lws_set_log_level(0, NULL);
}

void fxws_log_default(void) { pthread_once(&fxws_log_once, fxws_log_quiet); }

/* ---- URL ------------------------------------------------------------------ */

static int fxws_url_port(struct fxws_url *u, const char *s, size_t n, char *eb, size_t el)
{
    char digits[8];
    char *end;
    long v;
    if (n == 0 || n >= sizeof digits) {
        fxws_set_err(eb, el, "bad URL: port must be a number from 1 to 65535");
        return -1;
    }
    memcpy(digits, s, n);
    digits[n] = 0;
    v = strtol(digits, &end, 10);
    if (*end || v < 1 || v > 65535 || digits[0] < '0' || digits[0] > '9') {
        fxws_set_err(eb, el, "bad URL: port \"%s\" must be a number from 1 to 65535", digits);
        return -1;
    }
    u->port = (int)v;
    return 0;
}

/* Splits "host[:port]" (host may be "[v6]") of n bytes into u->host and u->port. */
static int fxws_url_authority(struct fxws_url *u, const char *s, size_t n, char *eb, size_t el)
{
    const char *colon = NULL, *hs = s, *he;
    if (n && s[0] == '[') {
        he = memchr(s, ']', n);
        if (!he) { fxws_set_err(eb, el, "bad URL: unterminated [IPv6] host"); return -1; }
        hs = s + 1;
        if (he + 1 < s + n) {
            if (he[1] != ':') { fxws_set_err(eb, el, "bad URL: junk after ]"); return -1; }
            colon = he + 1;
        }
    } else {
        colon = memchr(s, ':', n);
        he = colon ? colon : s + n;
    }
    if (he == hs || (size_t)(he - hs) >= sizeof u->host) {
        fxws_set_err(eb, el, "bad URL: missing or too long host");
        return -1;
    }
    memcpy(u->host, hs, (size_t)(he - hs));
    u->host[he - hs] = 0;
    u->port = FXWS_DEFAULT_PORT;
    if (colon && fxws_url_port(u, colon + 1, (size_t)(s + n - colon - 1), eb, el)) return -1;
    snprintf(u->host_header, sizeof u->host_header, "%.*s", (int)n, s);
    return 0;
}

int fxws_url_parse(struct fxws_url *u, const char *url, char *eb, size_t el)
{
    const char *auth, *slash;
    if (!url) { fxws_set_err(eb, el, "bad URL: none given"); return -1; }
    u->tls = strncmp(url, "wss://", 6) == 0;
    if (!u->tls && strncmp(url, "ws://", 5) != 0) {
        fxws_set_err(eb, el, "bad URL \"%s\": expected ws://host[:port][/path] or wss://...", url);
        return -1;
    }
    auth = url + (u->tls ? 6 : 5);
    slash = strchr(auth, '/');
    if (!slash) slash = auth + strlen(auth);
    if (fxws_url_authority(u, auth, (size_t)(slash - auth), eb, el)) return -1;
    if (strlen(slash) >= sizeof u->path) { fxws_set_err(eb, el, "bad URL: path too long"); return -1; }
    snprintf(u->path, sizeof u->path, "%s", *slash && strcmp(slash, "/") ? slash : FXWS_DEFAULT_PATH);
    return 0;
}

/* ---- name resolution and connect diagnosis ---------------------------------- */

struct addrinfo *fxws_resolve(const struct fxws_url *u, char *eb, size_t el)
{
    struct addrinfo hints, *ai = NULL;
    char port[8];
    int r;
    memset(&hints, 0, sizeof hints);
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_STREAM;
    snprintf(port, sizeof port, "%d", u->port);
    if ((r = getaddrinfo(u->host, port, &hints, &ai))) {
        fxws_set_err(eb, el, "cannot resolve host \"%s\": %s", u->host, gai_strerror(r));
        return NULL;
    }
    return ai;
}

int fxws_probe_errno(const struct fxws_url *u)
{
    struct addrinfo *ai = fxws_resolve(u, NULL, 0);
    struct pollfd pfd = { .fd = -1, .events = POLLOUT };
    int err = 0;
    socklen_t len = sizeof err;
    if (!ai) return EHOSTUNREACH;
    pfd.fd = socket(ai->ai_family, ai->ai_socktype | SOCK_NONBLOCK, ai->ai_protocol);
    if (pfd.fd < 0) err = errno;
    else if (connect(pfd.fd, ai->ai_addr, ai->ai_addrlen) && errno != EINPROGRESS) err = errno;
    else if (poll(&pfd, 1, FXWS_PROBE_WAIT_MS) != 1) err = ETIMEDOUT;
    else if (getsockopt(pfd.fd, SOL_SOCKET, SO_ERROR, &err, &len)) err = errno;
    if (pfd.fd >= 0) close(pfd.fd);
    freeaddrinfo(ai);
    return err;
}

int fxws_connect_needs_probe(int tcp_up, const char *why)
{
    return !tcp_up && why && strstr(why, "Unable to connect") != NULL;
}

void fxws_connect_error(const struct fxws_url *u, int tcp_up, const char *why, int e, char *out, size_t outlen)
{
    const char *w = why ? why : "unknown error";
    if (!tcp_up && strstr(w, "Unable to connect") && e)
        fxws_set_err(out, outlen, "%s %s:%d", e == ECONNREFUSED ? "connection refused by" : strerror(e), u->host,
                     u->port);
    else if (tcp_up)
        fxws_set_err(out, outlen, "WebSocket handshake failed with %s://%s%s (%s)%s", fxws_scheme(u), u->host_header, u->path, w,
                     strstr(w, "HS:") ? "" : ": the server hung up; wrong path or subprotocol?");
    else
        fxws_set_err(out, outlen, "cannot connect to %s:%d (%s)", u->host, u->port, w);
}

int fxws_check_subprotocol(const struct fxws_url *u, struct lws *wsi, char *out, size_t outlen)
{
    char proto[64] = "";
    if (lws_hdr_copy(wsi, proto, sizeof proto, WSI_TOKEN_PROTOCOL) < 0) proto[0] = 0;
    if (!strcmp(proto, FXWS_SUBPROTOCOL)) return 0;
    if (proto[0])
        fxws_set_err(out, outlen, "WebSocket handshake failed with %s://%s%s: server chose subprotocol \"%s\", not \"%s\"", fxws_scheme(u),
                     u->host_header, u->path, proto, FXWS_SUBPROTOCOL);
    else
        fxws_set_err(out, outlen, "WebSocket handshake failed with %s://%s%s: server did not accept subprotocol \"%s\"", fxws_scheme(u),
                     u->host_header, u->path, FXWS_SUBPROTOCOL);
    return 1;
}

void fxws_peer_close(const uint8_t *in, size_t len, int *code, char *out, size_t outlen, char *reason_out,
                     size_t reason_len)
{
    *code = len >= 2 ? (in[0] << 8) | in[1] : 0;
    if (len >= 2)
        fxws_set_err(out, outlen, "server closed the connection (code %d%s%.*s)", *code, len > 2 ? ": " : "",
                     (int)(len - 2), (const char *)in + 2);
    else
        fxws_set_err(out, outlen, "server closed the connection (no close code)");
    if (len >= 2) fxws_set_err(reason_out, reason_len, "%.*s", (int)(len - 2), (const char *)in + 2);
    else fxws_set_err(reason_out, reason_len, "%s", "");
}

/* ---- outgoing text ------------------------------------------------------------ */

struct fxws_out {
    struct fxws_out *next;
    size_t len;
    unsigned char data[]; /* LWS_PRE, then the text */
};

int fxws_outq_push(struct fxws_outq *q, const char *text, size_t len)
{
    struct fxws_out *o = malloc(sizeof *o + LWS_PRE + len);
    if (!o) return -1;
    o->next = NULL;
    o->len = len;
    memcpy(o->data + LWS_PRE, text, len);
    if (q->tail) q->tail->next = o;
    else q->head = o;
    q->tail = o;
    q->n++;
    return 0;
}

int fxws_outq_write(struct fxws_outq *q, struct lws *wsi, char *err, size_t errlen)
{
    struct fxws_out *o = q->head;
    int n;
    if (!o) return 0;
    q->head = o->next;
    if (!q->head) q->tail = NULL;
    q->n--;
    n = lws_write(wsi, o->data + LWS_PRE, o->len, LWS_WRITE_TEXT);
    free(o);
    if (n < 0) {
        fxws_set_err(err, errlen, "write to server failed");
        return -1;
    }
    if (q->head) lws_callback_on_writable(wsi);
    return 0;
}

void fxws_outq_free(struct fxws_outq *q)
{
    while (q->head) {
        struct fxws_out *o = q->head;
        q->head = o->next;
        free(o);
    }
    memset(q, 0, sizeof *q);
}

/* ---- reassembly ------------------------------------------------------------- */

int fxws_rx_append(struct fxws_rx *rx, struct lws *wsi, const void *in, size_t len, size_t max_bytes, size_t keep,
                   char *err, size_t errlen)
{
    size_t want;
    if (!rx->active) {
        rx->active = 1;
        rx->binary = lws_frame_is_binary(wsi);
        rx->len = 0;
        rx->total = 0;
    }
    if (rx->total + len > max_bytes) {
        fxws_set_err(err, errlen, "message larger than %zu bytes from server", max_bytes);
        return -1;
    }
    want = rx->len < keep ? keep - rx->len : 0; /* bytes of this chunk to keep */
    if (want > len) want = len;
    if (rx->len + want > rx->cap) {
        size_t cap = rx->cap ? rx->cap : (keep < FXWS_RX_MIN_CAP ? keep : FXWS_RX_MIN_CAP);
        uint8_t *p;
        while (cap < rx->len + want) cap *= 2;
        if (!(p = realloc(rx->buf, cap))) {
            fxws_set_err(err, errlen, "out of memory reassembling a %zu-byte message", rx->total + len);
            return -2;
        }
        rx->buf = p;
        rx->cap = cap;
    }
    if (want) memcpy(rx->buf + rx->len, in, want);
    rx->len += want;
    rx->total += len;
    if (!lws_is_final_fragment(wsi) || lws_remaining_packet_payload(wsi)) return 0;
    rx->active = 0;
    return 1;
}

void fxws_rx_free(struct fxws_rx *rx)
{
    free(rx->buf);
    memset(rx, 0, sizeof *rx);
}

/* ---- TLS and access token ------------------------------------------------------ */

void fxws_tls_context(struct lws_context_creation_info *info, const char *ca_file)
{
    info->options |= LWS_SERVER_OPTION_DO_SSL_GLOBAL_INIT;
    info->client_ssl_ca_filepath = ca_file;
}

int fxws_ssl_flags(const struct fxws_url *u) { return u->tls ? LCCSCF_USE_SSL : 0; }

void fxws_connect_info(struct lws_client_connect_info *ci, struct lws_context *ctx, const struct fxws_url *u)
{
    memset(ci, 0, sizeof *ci);
    ci->context = ctx;
    ci->address = u->host;
    ci->port = u->port;
    ci->path = u->path;
    ci->host = u->host_header;
    ci->ssl_connection = fxws_ssl_flags(u);
    ci->protocol = FXWS_SUBPROTOCOL;
}

const char *fxws_scheme(const struct fxws_url *u) { return u->tls ? "wss" : "ws"; }

int fxws_append_auth(struct lws *wsi, void *in, size_t len, const char *token)
{
    char value[300];
    unsigned char **p = (unsigned char **)in, *end = *p + len;
    if (!token || !*token) return 0;
    int n = snprintf(value, sizeof value, "Bearer %s", token);
    if (n < 0 || (size_t)n >= sizeof value) return -1;
    return lws_add_http_header_by_token(wsi, WSI_TOKEN_HTTP_AUTHORIZATION, (unsigned char *)value, n, p, end) ? -1 : 0;
}
