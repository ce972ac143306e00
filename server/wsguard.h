/* wsguard.h — the RFC 6455 framing rule that libwebsockets 4.1 does not enforce on a
 * server: every frame a client sends is masked (§5.1: "a server MUST close the connection
 * upon receiving a frame that is not masked"; lws 4.1.6 parses the mask bit and unmasks,
 * or not, without a check or a hook). The guard reads the bytes lws reads, on the network
 * thread only: it interposes recv() (plain connections) and SSL_read() (TLS), follows each
 * connection's HTTP request and then its frame headers, and withholds a frame whose mask bit
 * is clear. The connection is then closed with 1002 (protocol error) and nothing of that
 * frame reaches lws. Everything else passes through untouched, including every read made on
 * another thread. Issue 15 item 13. */
#ifndef FX_WSGUARD_H
#define FX_WSGUARD_H

#include <stdbool.h>

struct lws;

/* On the thread that runs lws_service, before it first does: guard this thread's reads
 * (tls: the vhost speaks TLS, so SSL_read carries the plain bytes). */
void wsguard_start(bool tls);
/* A new connection was accepted (LWS_CALLBACK_SERVER_NEW_CLIENT_INSTANTIATED): its socket
 * starts with an HTTP request. Any earlier connection on the same descriptor is forgotten. */
void wsguard_open(struct lws *wsi);
/* Whether the connection sent an unmasked frame; then its close reason is set to 1002 and
 * the caller closes it (a callback returning -1). */
bool wsguard_close_if_bad(struct lws *wsi);
/* Frees the guard's table (after the last lws_service). */
void wsguard_stop(void);

#endif
