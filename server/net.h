/* net.h — the libwebsockets event loop: HTTP (web client, /healthz, /metrics) and the
 * fxstream.v1 WebSocket protocol on one port. It owns every socket and every session,
 * and runs on the thread that calls net_run. */
#ifndef FX_NET_H
#define FX_NET_H

#include "server.h"

struct net;

/* Binds cfg.listen:cfg.port (port 0 picks a free one). */
int net_open(struct net **out, struct server *srv, struct fx_err *err);
/* The port actually bound. */
int net_port(const struct net *net);
/* Serves until net_request_stop, then closes every WebSocket with 1001 and returns. */
void net_run(struct net *net);
/* Any thread: wakes the event loop, which then polls the sessions, the engine's frames and
 * the cluster's queue (replica.h). Takes the struct net. */
void net_notify(void *net);
/* Async-signal-safe: asks net_run to wind down. */
void net_request_stop(struct net *net);
void net_close(struct net *net);

#endif
