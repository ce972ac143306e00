/* access.c — see access.h. */
#include "access.h"

#include <arpa/inet.h>

#include <stdio.h>
#include <string.h>
#include <strings.h>

static const char *const access_names[] = {"none", "view", "tune", "admin"};

const char *access_role_name(enum access_role r) { return access_names[r]; }

static int access_parse_role(const char *name, size_t len, enum access_role *out)
{
    for (int r = ACCESS_VIEW; r <= ACCESS_ADMIN; r++)
        if (strlen(access_names[r]) == len && !strncmp(access_names[r], name, len)) {
            *out = (enum access_role)r;
            return 0;
        }
    return -1;
}

static int access_add(struct access *a, const char *role, size_t role_len, const char *token, size_t len,
                      const char *what, struct fx_err *err)
{
    enum access_role r;
    if (access_parse_role(role, role_len, &r))
        return fx_fail(err, "bad_request", what, "%s: role \"%.*s\" is not view, tune or admin", what, (int)role_len,
                       role);
    if (len < ACCESS_TOKEN_MIN || len > ACCESS_TOKEN_MAX)
        return fx_fail(err, "bad_request", what, "%s: a token needs %d to %d characters, this one has %zu", what,
                       ACCESS_TOKEN_MIN, ACCESS_TOKEN_MAX, len);
    for (size_t i = 0; i < len; i++)
        if (token[i] <= ' ' || token[i] > '~' || token[i] == ',')
            return fx_fail(err, "bad_request", what, "%s: tokens are printable ASCII without spaces or commas", what);
    for (int i = 0; i < a->ntokens; i++)
        if (strlen(a->tokens[i].token) == len && !memcmp(a->tokens[i].token, token, len))
            return fx_fail(err, "bad_request", what, "%s: the same token is configured twice", what);
    if (a->ntokens == ACCESS_MAX_TOKENS)
        return fx_fail(err, "bad_request", what, "%s: more than %d tokens", what, ACCESS_MAX_TOKENS);
    struct access_token *t = &a->tokens[a->ntokens++];
    memcpy(t->token, token, len);
    t->token[len] = 0;
    t->role = r;
    return 0;
}

int access_add_token(struct access *a, const char *role, const char *token, const char *what, struct fx_err *err)
{
    return access_add(a, role, strlen(role), token, strlen(token), what, err);
}

int access_add_env(struct access *a, const char *spec, struct fx_err *err)
{
    const char *what = "FXSTREAMD_TOKENS";
    for (const char *p = spec; *p;) {
        const char *end = strchr(p, ','), *colon;
        if (!end) end = p + strlen(p);
        colon = memchr(p, ':', (size_t)(end - p));
        if (!colon)
            return fx_fail(err, "bad_request", what, "%s: expected role:token[,role:token...]", what);
        if (access_add(a, p, (size_t)(colon - p), colon + 1, (size_t)(end - colon - 1), what, err)) return -1;
        p = *end ? end + 1 : end;
    }
    return 0;
}

/* Appends v to one of the name tables (allowed_origins, allowed_hosts), named key in errors. */
static int access_append(char (*table)[ACCESS_ORIGIN_MAX], int *n, const char *v, const char *key,
                         struct fx_err *err)
{
    if (*n == ACCESS_MAX_ORIGINS) return fx_fail(err, "bad_request", key, "%s: more than %d", key, ACCESS_MAX_ORIGINS);
    snprintf(table[(*n)++], ACCESS_ORIGIN_MAX, "%s", v);
    return 0;
}

int access_add_origin(struct access *a, const char *origin, struct fx_err *err)
{
    size_t n = strlen(origin);
    bool scheme = !strncmp(origin, "http://", 7) || !strncmp(origin, "https://", 8);
    if (!scheme || n >= ACCESS_ORIGIN_MAX || origin[n - 1] == '/')
        return fx_fail(err, "bad_request", "allowed_origins",
                       "allowed_origins: \"%.80s\" is not an origin like https://host[:port]", origin);
    return access_append(a->origins, &a->norigins, origin, "allowed_origins", err);
}

int access_add_host(struct access *a, const char *host, struct fx_err *err)
{
    size_t n = strlen(host);
    if (!n || n >= ACCESS_ORIGIN_MAX || strspn(host, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.-") != n)
        return fx_fail(err, "bad_request", "allowed_hosts",
                       "allowed_hosts: \"%.80s\" is not a host name (letters, digits, dots, dashes; no port)", host);
    return access_append(a->hosts, &a->nhosts, host, "allowed_hosts", err);
}

bool access_host_ok(const struct access *a, const char *host)
{
    if (a->ntokens > 0) return true;
    if (!host) return false;
    char name[ACCESS_ORIGIN_MAX];
    size_t n = host[0] == '[' ? strcspn(host, "]") + 1 : strcspn(host, ":");
    const char *rest = host + n;
    if (n >= sizeof name || (*rest && (rest[0] != ':' || strspn(rest + 1, "0123456789") != strlen(rest + 1))))
        return false;
    snprintf(name, sizeof name, "%.*s", (int)n, host);
    struct in_addr v4;
    if (!strcasecmp(name, "localhost") || !strcmp(name, "[::1]")) return true;
    if (inet_pton(AF_INET, name, &v4) == 1 && (ntohl(v4.s_addr) >> 24) == 127) return true;
    for (int i = 0; i < a->nhosts; i++)
        if (!strcasecmp(a->hosts[i], name)) return true;
    return false;
}

/* 0 when equal; the time depends on the lengths only, not on where the bytes differ. */
static int access_diff(const char *stored, const char *s, size_t len)
{
    size_t n = strlen(stored);
    unsigned char d = (unsigned char)(n != len);
    for (size_t i = 0; i < len; i++) d |= (unsigned char)(s[i] ^ (i < n ? stored[i] : 0));
    return d;
}

enum access_role access_lookup(const struct access *a, const char *token, size_t len)
{
    enum access_role r = ACCESS_NONE;
    if (len > ACCESS_TOKEN_MAX) return ACCESS_NONE;
    for (int i = 0; i < a->ntokens; i++)
        if (!access_diff(a->tokens[i].token, token, len)) r = a->tokens[i].role;
    return r;
}

enum access_role access_default_role(const struct access *a) { return a->ntokens ? ACCESS_NONE : ACCESS_ADMIN; }

bool access_origin_ok(const struct access *a, const char *origin, const char *host, bool tls)
{
    if (!origin) return true; /* not a browser: tokens are the protection */
    for (int i = 0; i < a->norigins; i++)
        if (!strcasecmp(a->origins[i], origin)) return true;
    if (!host) return false;
    char own[ACCESS_ORIGIN_MAX];
    snprintf(own, sizeof own, "%s://%s", tls ? "https" : "http", host);
    return !strcasecmp(own, origin);
}
