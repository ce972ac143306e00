/* access.h — who may do what: access tokens, roles, and the browser Origin check.
 *
 * Roles are ordered: view (list, describe, subscribe, unsubscribe, get) < tune (+ set,
 * reset) < admin (+ create, destroy). Tokens come from the config file's `tokens` and the
 * FXSTREAMD_TOKENS environment variable; a connection presents one in its WebSocket
 * handshake (`Authorization: Bearer TOKEN`) or with the `auth` op. With no token
 * configured every connection is admin, and main.c then refuses to listen beyond
 * loopback. Origins: a browser's handshake carries `Origin`; it must be the daemon's own
 * origin (the page it serves) or be in `allowed_origins`, so a web page elsewhere cannot
 * drive a daemon on the user's machine; without tokens the Host header must also name this
 * machine (access_host_ok), or a rebinding domain would count as the daemon's own origin. */
#ifndef FX_ACCESS_H
#define FX_ACCESS_H

#include <stdbool.h>
#include <stddef.h>

#include "err.h"

enum access_role { ACCESS_NONE, ACCESS_VIEW, ACCESS_TUNE, ACCESS_ADMIN };

#define ACCESS_TOKEN_MIN 16  /* characters: shorter tokens are refused at start */
#define ACCESS_TOKEN_MAX 128
#define ACCESS_MAX_TOKENS 64
#define ACCESS_MAX_ORIGINS 32
#define ACCESS_ORIGIN_MAX 256

struct access_token {
    char token[ACCESS_TOKEN_MAX + 1];
    enum access_role role;
};

struct access {
    struct access_token tokens[ACCESS_MAX_TOKENS];
    int ntokens;
    char origins[ACCESS_MAX_ORIGINS][ACCESS_ORIGIN_MAX];
    int norigins;
    char hosts[ACCESS_MAX_ORIGINS][ACCESS_ORIGIN_MAX]; /* allowed_hosts: names besides loopback */
    int nhosts;
};

/* "view", "tune", "admin" (ACCESS_NONE: "none"). */
const char *access_role_name(enum access_role r);

/* Adds a token with its role name; bad_request naming `what` on a bad role, a token that
 * is too short or long or has characters outside printable ASCII, a duplicate, or too many. */
int access_add_token(struct access *a, const char *role, const char *token, const char *what, struct fx_err *err);

/* Adds tokens from "role:token,role:token" (the FXSTREAMD_TOKENS variable). */
int access_add_env(struct access *a, const char *spec, struct fx_err *err);

int access_add_origin(struct access *a, const char *origin, struct fx_err *err);

/* The role of a presented token (len bytes), ACCESS_NONE when it matches none. Compares
 * against every configured token in time independent of where they differ. */
enum access_role access_lookup(const struct access *a, const char *token, size_t len);

/* The role a connection starts with: admin when no token is configured, else none. */
enum access_role access_default_role(const struct access *a);

int access_add_host(struct access *a, const char *host, struct fx_err *err);

/* Whether a WebSocket handshake's Host header (NULL: none) may connect. With tokens, any:
 * the token is the protection. Without tokens every connection is admin, so only the names
 * this machine answers to: localhost, 127.0.0.0/8, [::1], and `allowed_hosts`, any port. A
 * page on a DNS-rebinding domain (attacker.example resolving to 127.0.0.1) sends its own name
 * as Host and as Origin, so the Origin check alone let it in. */
bool access_host_ok(const struct access *a, const char *host);

/* Whether a handshake's Origin header (NULL: none, as from non-browser clients) may
 * connect; host is the handshake's Host header (NULL: none), tls whether it came over TLS. */
bool access_origin_ok(const struct access *a, const char *origin, const char *host, bool tls);

#endif
