/* wsguard.h — the RFC 6455 framing rules that libwebsockets 4.1 does not enforce on a
 * server. Every frame a client sends is masked (§5.1: "a server MUST close the connection
 * upon receiving a frame that is not masked"; lws 4.1.6 parses the mask bit and unmasks, or
 * not, without a check or a hook). The guard reads the bytes lws reads, on the network thread
 * only: it interposes recv() (plain connections) and SSL_read() (TLS), follows each
 * connection's handshake to the byte where lws ends it (lwsreq.h) and then its frame headers,
 * and withholds a frame whose mask bit is clear. The connection is then closed with 1002
 * (protocol error) and nothing of that frame reaches lws. Everything else passes through
 * untouched, including every read made on another thread or of a socket lws does not own.
 * And a client's close frame is checked (RFC 6455 5.5.1, 7.4), since lws echoes whatever it
 * holds. */
#ifndef FX_WSGUARD_H
#define FX_WSGUARD_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

struct lws;

/* On the thread that runs lws_service, before it first does: guard this thread's reads
 * (tls: the vhost speaks TLS, so SSL_read carries the plain bytes). */
void wsguard_start(bool tls);
/* A new connection was accepted on socket fd (LWS_CALLBACK_SERVER_NEW_CLIENT_INSTANTIATED): it
 * starts with an HTTP request. */
void wsguard_open(struct lws *wsi, int fd);
/* lws destroys the connection (LWS_CALLBACK_WSI_DESTROY, its socket already closed): its
 * socket is no longer followed. */
void wsguard_close(struct lws *wsi);
/* lws ended an HTTP transaction (the response went out): it parses the connection's next
 * request afresh from the next byte it reads, and so does the guard. (What lws reads before
 * that it does not parse as a request: the guard then stops following the connection.) */
void wsguard_next_request(struct lws *wsi);
/* Whether a WebSocket upgrade of the connection may be accepted (LWS_CALLBACK_FILTER_PROTOCOL_
 * CONNECTION): only when the guard saw its headers, and those of the requests before it on
 * the connection, end where lws ended them (lwsreq.h), so that it follows the frames after. */
bool wsguard_upgrade_ok(struct lws *wsi);
/* Whether the connection sent an unmasked frame; then its close reason is set to 1002 and
 * the caller closes it (a callback returning -1). */
bool wsguard_close_if_bad(struct lws *wsi);
/* The status to answer a client's close frame with instead of lws's echo of it, or 0 when the
 * echo is right (RFC 6455 5.5.1, 7.4): a payload of one byte, or a status code a client may
 * not send (below 1000, 1004-1006, 1012-2999, 5000 and up), is 1002; a reason that is not
 * UTF-8 (a character cut off at its end included) is 1007. *why names the problem. lws 4.1
 * echoes all of these (it rewrites only codes below 3000 to 1002 and checks the reason's
 * bytes but not that its last character is whole). */
int wsguard_close_status(const uint8_t *payload, size_t len, const char **why);
/* Frees the guard's table (after the last lws_service). */
void wsguard_stop(void);

#endif
