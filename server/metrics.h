/* metrics.h — the daemon's observability documents: GET /metrics (Prometheus text
 * exposition format) and GET /healthz (JSON). Both are rendered on demand from the
 * hub's per-stream counters, the server's counters and the OpenCL kernel times. */
#ifndef FX_METRICS_H
#define FX_METRICS_H

#include "buf.h"
#include "server.h"

int metrics_render(struct server *srv, struct fx_buf *out);
int metrics_health(struct server *srv, struct fx_buf *out);

#endif
