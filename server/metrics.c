/* metrics.c — see metrics.h. */
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "clock.h"
#include "cluster.h"
#include "metrics.h"
#include "ocl.h"
#include "relay.h"
#include "session.h"

static double metrics_uptime(const struct server *srv)
{
    return clock_now() - srv->start_time;
}

static void metrics_printf(struct fx_buf *out, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void metrics_printf(struct fx_buf *out, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(NULL, 0, fmt, ap);
    va_end(ap);
    if (n < 0 || fx_buf_reserve(out, (size_t)n + 1)) return;
    va_start(ap, fmt);
    vsnprintf((char *)out->data + out->len, (size_t)n + 1, fmt, ap);
    va_end(ap);
    out->len += (size_t)n;
}

static void metrics_head(struct fx_buf *out, const char *name, const char *type, const char *help)
{
    metrics_printf(out, "# HELP %s %s\n# TYPE %s %s\n", name, help, name, type);
}

/* A stream and its guarded fields read once (hub_status), for one scrape. */
struct m_row {
    struct stream *s;
    struct stream_status st;
};

/* One metric line per stream, value read by `get`. */
static void metrics_per_stream(struct fx_buf *out, const struct m_row *rows, int n, const char *name,
                               const char *type, const char *help, double (*get)(const struct m_row *))
{
    metrics_head(out, name, type, help);
    for (int i = 0; i < n; i++)
        metrics_printf(out, "%s{stream=\"%s\",effect=\"%s\"} %.9g\n", name, rows[i].s->name,
                       rows[i].s->effect->name, get(&rows[i]));
}

static double m_subs(const struct m_row *r) { return r->st.subscribers; }
static double m_rev(const struct m_row *r) { return (double)r->st.rev; }
static double m_errors(const struct m_row *r) { return (double)r->st.error_gen; }
static double m_realtime(const struct m_row *r) { return r->st.realtime; }
static double m_failing(const struct m_row *r) { return r->st.failing; }
static double m_produced(const struct m_row *r) { return (double)atomic_load(&r->s->frames_produced); }
static double m_sent(const struct m_row *r) { return (double)atomic_load(&r->s->frames_sent); }
static double m_skipped(const struct m_row *r) { return (double)atomic_load(&r->s->frames_skipped); }
static double m_bytes(const struct m_row *r) { return (double)atomic_load(&r->s->bytes_sent); }
static double m_steps(const struct m_row *r) { return (double)atomic_load(&r->s->steps); }
static double m_particles(const struct m_row *r) { return atomic_load(&r->s->particles); }
static double m_fps(const struct m_row *r) { return r->st.fps; }
static double m_achieved(const struct m_row *r) { return r->st.achieved_fps; }
static double m_engine_s(const struct m_row *r) { return (double)atomic_load(&r->s->engine_ns) * 1e-9; }
static double m_share(const struct m_row *r) { return r->st.engine_share; }

/* Every live stream with its status; free() the result (references released by the caller
 * through hub_release_all on *all). */
static struct m_row *metrics_rows(struct server *srv, struct stream ***all, int *n)
{
    *all = hub_snapshot(&srv->hub, n);
    struct m_row *rows = calloc((size_t)(*n > 0 ? *n : 1), sizeof *rows);
    for (int i = 0; rows && i < *n; i++) {
        rows[i].s = (*all)[i];
        hub_status(&srv->hub, (*all)[i], &rows[i].st);
    }
    return rows;
}

static void metrics_global(struct server *srv, struct fx_buf *out, int nstreams)
{
    const struct counters *c = &srv->counters;
    metrics_head(out, "fxs_up", "gauge", "1 while the daemon serves.");
    metrics_printf(out, "fxs_up 1\n");
    metrics_head(out, "fxs_uptime_seconds", "gauge", "Seconds since start.");
    metrics_printf(out, "fxs_uptime_seconds %.3f\n", metrics_uptime(srv));
    metrics_head(out, "fxs_connections", "gauge", "Open WebSocket connections.");
    metrics_printf(out, "fxs_connections %d\n", srv->nsessions);
    /* not fxs_connections_total: a counter's family is its name without _total, the gauge's */
    metrics_head(out, "fxs_connections_accepted_total", "counter", "WebSocket connections accepted.");
    metrics_printf(out, "fxs_connections_accepted_total %llu\n", (unsigned long long)atomic_load(&c->connections_total));
    metrics_head(out, "fxs_messages_received_total", "counter", "Control messages received.");
    metrics_printf(out, "fxs_messages_received_total %llu\n", (unsigned long long)atomic_load(&c->messages_in));
    metrics_head(out, "fxs_errors_sent_total", "counter", "Error replies sent.");
    metrics_printf(out, "fxs_errors_sent_total %llu\n", (unsigned long long)atomic_load(&c->errors_out));
    metrics_head(out, "fxs_frames_sent_total", "counter", "Frames sent to subscribers, all streams.");
    metrics_printf(out, "fxs_frames_sent_total %llu\n", (unsigned long long)atomic_load(&c->frames_sent));
    metrics_head(out, "fxs_frames_skipped_total", "counter", "Frames subscribers skipped, all streams.");
    metrics_printf(out, "fxs_frames_skipped_total %llu\n", (unsigned long long)atomic_load(&c->frames_skipped));
    metrics_head(out, "fxs_connections_stalled_total", "counter",
                 "Connections closed because their socket stayed full for stall_timeout_s.");
    metrics_printf(out, "fxs_connections_stalled_total %llu\n", (unsigned long long)atomic_load(&c->stalled_closed));
    metrics_head(out, "fxs_state_writes_total", "counter",
                 "Writes of streams.json tried, one per accepted create, destroy or parameter change.");
    metrics_printf(out, "fxs_state_writes_total %llu\n", (unsigned long long)atomic_load(&c->state_writes));
    metrics_head(out, "fxs_state_write_failures_total", "counter",
                 "State writes (streams.json, presets.json) the disk refused; each change stayed unapplied.");
    metrics_printf(out, "fxs_state_write_failures_total %llu\n",
                   (unsigned long long)atomic_load(&c->state_write_failures));
    metrics_head(out, "fxs_state_writable", "gauge",
                 "0 after a state write failed, until one succeeds (changes are refused with unavailable meanwhile).");
    metrics_printf(out, "fxs_state_writable %d\n", srv->state_error[0] ? 0 : 1);
    metrics_head(out, "fxs_handshakes_evicted_total", "counter",
                 "Connections dropped before their first request to make room for newer ones.");
    metrics_printf(out, "fxs_handshakes_evicted_total %llu\n", (unsigned long long)atomic_load(&c->handshakes_evicted));
    metrics_head(out, "fxs_bytes_sent_total", "counter", "Frame bytes sent, all streams.");
    metrics_printf(out, "fxs_bytes_sent_total %llu\n", (unsigned long long)atomic_load(&c->bytes_sent));
    metrics_head(out, "fxs_streams", "gauge", "Streams defined.");
    metrics_printf(out, "fxs_streams %d\n", nstreams);
    metrics_head(out, "fxs_engine_busy_seconds_total", "counter", "Engine thread time spent on streams (their steps, and their outputs encoded for new subscriptions), all streams.");
    metrics_printf(out, "fxs_engine_busy_seconds_total %.6f\n", (double)atomic_load(&srv->engine.busy_ns) * 1e-9);
}

/* Cluster mode: the number of streams this daemon holds the lease of; with names set, their
 * names go into it, and those it relays into relaying. */
static int metrics_leases(struct server *srv, cJSON *names, cJSON *relaying)
{
    int n, held = 0;
    struct stream **all = hub_snapshot(&srv->hub, &n);
    for (int i = 0; i < n; i++) {
        struct stream_status st;
        hub_status(&srv->hub, all[i], &st);
        held += st.lease.owned;
        if (st.lease.owned && names) cJSON_AddItemToArray(names, cJSON_CreateString(all[i]->name));
        if (!st.lease.owned && st.subscribers > 0 && relaying)
            cJSON_AddItemToArray(relaying, cJSON_CreateString(all[i]->name));
    }
    hub_release_all(all, n);
    return held;
}

/* Cluster mode only: the Redis link, the changes that went through it, leases and frames. */
static void metrics_cluster(struct server *srv, struct fx_buf *out)
{
    if (!srv->cluster) return;
    const struct counters *c = &srv->counters;
    struct cluster_status st;
    cluster_status(srv->cluster, &st);
    metrics_head(out, "fxs_cluster_info", "gauge", "This daemon's node id and role in the cluster (always 1).");
    metrics_printf(out, "fxs_cluster_info{node=\"%s\",role=\"%s\"} 1\n", st.node, cluster_role_name(srv->cfg.cluster.role));
    metrics_head(out, "fxs_cluster_link_up", "gauge",
                 "1 while this daemon is subscribed to the cluster's Redis (changes are refused with unavailable otherwise).");
    metrics_printf(out, "fxs_cluster_link_up{node=\"%s\"} %d\n", st.node, st.link_up);
    metrics_head(out, "fxs_cluster_in_sync", "gauge",
                 "1 while the local copy of the streams has every change of Redis's counter up to fxs_cluster_change.");
    metrics_printf(out, "fxs_cluster_in_sync %d\n", st.in_sync);
    metrics_head(out, "fxs_cluster_change", "gauge", "The number of the last Redis change the local copy has applied.");
    metrics_printf(out, "fxs_cluster_change %llu\n", (unsigned long long)st.seq);
    metrics_head(out, "fxs_cluster_link_losses_total", "counter", "Times the subscription to Redis was lost.");
    metrics_printf(out, "fxs_cluster_link_losses_total %llu\n", (unsigned long long)st.link_losses);
    metrics_head(out, "fxs_cluster_bad_values_total", "counter",
                 "Values read from Redis that did not parse or could not be right, by kind; each was logged and "
                 "repaired or ignored.");
    for (int k = 0; k < CLUSTER_BAD_COUNT; k++)
        metrics_printf(out, "fxs_cluster_bad_values_total{what=\"%s\"} %llu\n", cluster_bad_name(k),
                       (unsigned long long)st.bad[k]);
    static const struct {
        const char *name, *help;
        size_t off;
    } k[] = {
        {"fxs_cluster_changes_total", "Creates, destroys, sets and resets this daemon made in Redis.",
         offsetof(struct counters, cluster_changes)},
        {"fxs_cluster_change_failures_total", "Changes Redis did not take (unreachable, or its state said no); none applied.",
         offsetof(struct counters, cluster_failures)},
        {"fxs_cluster_rebases_total", "Sets made again on a newer document another daemon had stored first.",
         offsetof(struct counters, cluster_rebases)},
        {"fxs_cluster_applied_total", "Other daemons' changes applied to the local copy.",
         offsetof(struct counters, cluster_applied)},
        {"fxs_cluster_reloads_total", "Reloads of the whole state from Redis (start, reconnection, missed change).",
         offsetof(struct counters, cluster_reloads)},
        {"fxs_cluster_leases_taken_total", "Stream leases this daemon took (new streams, or taken over from a daemon gone).",
         offsetof(struct counters, cluster_leases_taken)},
        {"fxs_cluster_leases_lost_total", "Stream leases this daemon lost to another (it was paused or cut off past the TTL).",
         offsetof(struct counters, cluster_leases_lost)},
        {"fxs_cluster_frames_published_total", "Frames this daemon computed and published through Redis.",
         offsetof(struct counters, cluster_frames_published)},
        {"fxs_cluster_frames_fenced_total", "Frames Redis refused because their lease had been taken over (fencing).",
         offsetof(struct counters, cluster_frames_fenced)},
        {"fxs_cluster_frames_relayed_total", "Frames computed by other daemons that came through Redis to subscribers here.",
         offsetof(struct counters, cluster_frames_relayed)},
    };
    for (size_t i = 0; i < sizeof k / sizeof k[0]; i++) {
        metrics_head(out, k[i].name, "counter", k[i].help);
        metrics_printf(out, "%s %llu\n", k[i].name,
                       (unsigned long long)atomic_load((const atomic_uint_fast64_t *)((const char *)c + k[i].off)));
    }
    metrics_head(out, "fxs_cluster_leases", "gauge", "Streams this daemon holds the lease of (computes).");
    metrics_printf(out, "fxs_cluster_leases %d\n", metrics_leases(srv, NULL, NULL));
    metrics_head(out, "fxs_cluster_relay_latency_seconds", "histogram",
                 "From the owner's frame time to the frame's arrival here through Redis (relayed frames).");
    hist_render(out, relay_latency(srv->relay), "fxs_cluster_relay_latency_seconds", "");
}

static void metrics_kernels(struct server *srv, struct fx_buf *out)
{
    struct ocl_kernel_stat st[64];
    int n = srv->ocl ? ocl_stats(srv->ocl, st, 64) : 0;
    metrics_head(out, "fxs_kernel_seconds_total", "counter", "OpenCL kernel execution time (profiling events).");
    for (int i = 0; i < n; i++)
        metrics_printf(out, "fxs_kernel_seconds_total{kernel=\"%s\"} %.9g\n", st[i].name, st[i].total_ms * 1e-3);
    metrics_head(out, "fxs_kernel_runs_total", "counter", "OpenCL kernel launches.");
    for (int i = 0; i < n; i++)
        metrics_printf(out, "fxs_kernel_runs_total{kernel=\"%s\"} %llu\n", st[i].name, (unsigned long long)st[i].runs);
}

/* Updates each stream's delivered frames per second per subscriber and kind, over the time
 * since the last update (the first: since the start) when that is a second or more (a scrape
 * sooner reuses it). */
static void metrics_update_rates(struct server *srv, const struct m_row *rows, int n)
{
    double now = metrics_uptime(srv);
    for (int i = 0; i < n; i++) {
        struct stream *s = rows[i].s;
        int subs = rows[i].st.subscribers;
        double dt = now - s->rate_time;
        if (dt < 1.0) continue;
        for (int k = 1; k <= FXS_KIND_MAX; k++) {
            uint64_t c = atomic_load(&s->sent_by_kind[k]);
            s->delivered_fps[k] = subs > 0 ? (double)(c - s->rate_base[k]) / dt / subs : 0;
            s->rate_base[k] = c;
        }
        s->rate_time = now;
    }
}

static void metrics_delivered(struct fx_buf *out, struct stream **all, int n)
{
    metrics_head(out, "fxs_stream_delivered_fps", "gauge",
                 "Frames of each kind sent per subscriber per second, over the last second or more between scrapes "
                 "(compare with the stream's fps: below it, subscribers skip).");
    for (int i = 0; i < n; i++)
        for (int k = 1; k <= FXS_KIND_MAX; k++)
            if (atomic_load(&all[i]->sent_by_kind[k]) || all[i]->delivered_fps[k] > 0)
                metrics_printf(out, "fxs_stream_delivered_fps{stream=\"%s\",effect=\"%s\",kind=\"%d\"} %.4g\n",
                               all[i]->name, all[i]->effect->name, k, all[i]->delivered_fps[k]);
}

static void metrics_histograms(struct fx_buf *out, struct stream **all, int n)
{
    static const struct {
        const char *name, *help;
        size_t off;
    } h[] = {
        {"fxs_stream_step_seconds", "Engine time per completed step of the effect, all its slices, encoding included.",
         offsetof(struct stream, step_time)},
        {"fxs_stream_encode_seconds", "Wall time encoding the frames of one step.", offsetof(struct stream, encode_time)},
        {"fxs_stream_frame_age_seconds", "Age of a frame (since its server_time) when its sending starts.",
         offsetof(struct stream, frame_age)},
    };
    for (size_t j = 0; j < sizeof h / sizeof h[0]; j++) {
        metrics_head(out, h[j].name, "histogram", h[j].help);
        for (int i = 0; i < n; i++) {
            char labels[160];
            snprintf(labels, sizeof labels, "stream=\"%s\",effect=\"%s\"", all[i]->name, all[i]->effect->name);
            hist_render(out, (const struct histogram *)((const char *)all[i] + h[j].off), h[j].name, labels);
        }
    }
}

/* Bytes waiting to be sent (queued replies and the rest of the frame being sent), summed by
 * the connections' role. */
static void metrics_queues(struct server *srv, struct fx_buf *out)
{
    double bytes[ACCESS_ADMIN + 1] = {0};
    for (const struct session *ss = srv->sessions; ss; ss = ss->next)
        bytes[ss->role] += (double)ss->q_bytes + (ss->cur ? (double)(ss->cur->len - ss->cur_off) : 0);
    metrics_head(out, "fxs_send_queue_bytes", "gauge",
                 "Bytes queued for sending (replies, events and the rest of the frame in flight) by connection role.");
    for (int r = ACCESS_NONE; r <= ACCESS_ADMIN; r++)
        metrics_printf(out, "fxs_send_queue_bytes{role=\"%s\"} %.0f\n", access_role_name((enum access_role)r), bytes[r]);
}

int metrics_render(struct server *srv, struct fx_buf *out)
{
    int n;
    struct stream **all;
    struct m_row *rows = metrics_rows(srv, &all, &n);
    if (!rows) {
        hub_release_all(all, n);
        return -1;
    }
    metrics_global(srv, out, n);
    metrics_update_rates(srv, rows, n);
    metrics_per_stream(out, rows, n, "fxs_stream_subscribers", "gauge", "Subscribers per stream.", m_subs);
    metrics_per_stream(out, rows, n, "fxs_stream_param_rev", "gauge", "Parameter revision.", m_rev);
    metrics_per_stream(out, rows, n, "fxs_stream_errors_total", "counter", "Stream failures (OpenCL build, kernel or device error, NaN), one per error event.", m_errors);
    metrics_per_stream(out, rows, n, "fxs_stream_realtime_factor", "gauge",
                       "Simulated seconds per wall second over the last second of stepping.", m_realtime);
    metrics_per_stream(out, rows, n, "fxs_stream_failing", "gauge",
                       "1 while the stream is failing (its last error, in /healthz, not yet followed by a good step).",
                       m_failing);
    metrics_per_stream(out, rows, n, "fxs_stream_frames_produced_total", "counter", "Frames encoded.", m_produced);
    metrics_per_stream(out, rows, n, "fxs_stream_frames_sent_total", "counter", "Frames sent, all subscribers.", m_sent);
    metrics_per_stream(out, rows, n, "fxs_stream_frames_skipped_total", "counter",
                       "Frames a subscriber skipped (latest frame wins).", m_skipped);
    metrics_per_stream(out, rows, n, "fxs_stream_bytes_sent_total", "counter", "Frame bytes sent.", m_bytes);
    metrics_per_stream(out, rows, n, "fxs_stream_steps_total", "counter", "Steps completed.", m_steps);
    metrics_per_stream(out, rows, n, "fxs_stream_particles", "gauge",
                       "Particles in the latest particle frame (kind 1); 0 for effects without particles.", m_particles);
    metrics_per_stream(out, rows, n, "fxs_stream_fps", "gauge", "The stream's fps parameter: steps due per second.", m_fps);
    metrics_per_stream(out, rows, n, "fxs_stream_achieved_fps", "gauge",
                       "Steps completed per second over the last second or more (0 while paused); below fxs_stream_fps "
                       "when the stream's steps need more of the engine than it gets.",
                       m_achieved);
    metrics_per_stream(out, rows, n, "fxs_stream_engine_seconds_total", "counter",
                       "Engine thread time spent on the stream: every slice of its steps (kernels, read-backs, encoding), and its "
                       "latest outputs encoded for a subscription to an encoding not made before.",
                       m_engine_s);
    metrics_per_stream(out, rows, n, "fxs_stream_engine_share", "gauge",
                       "The stream's share of the engine thread over about the last second (exponential decay, 1 s).",
                       m_share);
    metrics_delivered(out, all, n);
    metrics_histograms(out, all, n);
    free(rows);
    hub_release_all(all, n);
    metrics_queues(srv, out);
    metrics_cluster(srv, out);
    metrics_kernels(srv, out);
    return 0;
}

/* Cluster mode: {node, role, redis, link, in_sync, change, leases, relaying, frames_published,
 * frames_relayed[, last_error]}. */
static void metrics_health_cluster(struct server *srv, cJSON *h)
{
    struct cluster_status st;
    cluster_status(srv->cluster, &st);
    cJSON *o = cJSON_AddObjectToObject(h, "cluster");
    cJSON_AddStringToObject(o, "node", st.node);
    cJSON_AddStringToObject(o, "role", cluster_role_name(srv->cfg.cluster.role));
    cJSON_AddStringToObject(o, "redis", st.url);
    cJSON_AddStringToObject(o, "link", st.link_up ? "up" : "down");
    cJSON_AddBoolToObject(o, "in_sync", st.in_sync);
    cJSON_AddNumberToObject(o, "change", (double)st.seq);
    metrics_leases(srv, cJSON_AddArrayToObject(o, "leases"), cJSON_AddArrayToObject(o, "relaying"));
    cJSON_AddNumberToObject(o, "frames_published", (double)atomic_load(&srv->counters.cluster_frames_published));
    cJSON_AddNumberToObject(o, "frames_relayed", (double)atomic_load(&srv->counters.cluster_frames_relayed));
    if (st.last_error[0]) cJSON_AddStringToObject(o, "last_error", st.last_error);
}

int metrics_health(struct server *srv, struct fx_buf *out)
{
    int n;
    struct stream **all = hub_snapshot(&srv->hub, &n);
    cJSON *h = cJSON_CreateObject();
    bool linked = !srv->cluster || cluster_link_up(srv->cluster);
    cJSON_AddStringToObject(h, "status", srv->state_error[0] || !linked ? "degraded" : "ok");
    cJSON_AddStringToObject(h, "version", FX_VERSION);
    cJSON_AddNumberToObject(h, "uptime_s", metrics_uptime(srv));
    cJSON_AddStringToObject(h, "device", srv->ocl ? ocl_device_name(srv->ocl) : "none");
    cJSON_AddStringToObject(h, "platform", srv->ocl ? ocl_platform_name(srv->ocl) : "none");
    cJSON_AddNumberToObject(h, "connections", srv->nsessions);
    cJSON_AddNumberToObject(h, "quarantined", srv->quarantined); /* stored streams set aside at start */
    cJSON *state = cJSON_AddObjectToObject(h, "state"); /* store.h: the last state write's outcome */
    cJSON_AddBoolToObject(state, "writable", !srv->state_error[0]);
    if (srv->state_error[0]) cJSON_AddStringToObject(state, "last_error", srv->state_error);
    if (srv->cluster) metrics_health_cluster(srv, h);
    cJSON *arr = cJSON_AddArrayToObject(h, "streams");
    for (int i = 0; i < n; i++) {
        struct stream_status st;
        hub_status(&srv->hub, all[i], &st);
        cJSON *o = cJSON_CreateObject();
        cJSON_AddStringToObject(o, "stream", all[i]->name);
        cJSON_AddStringToObject(o, "effect", all[i]->effect->name);
        cJSON_AddNumberToObject(o, "subscribers", st.subscribers);
        cJSON_AddNumberToObject(o, "rev", (double)st.rev);
        if (st.error[0]) cJSON_AddStringToObject(o, "last_error", st.error);
        cJSON_AddBoolToObject(o, "failing", st.failing);
        cJSON_AddItemToArray(arr, o);
    }
    hub_release_all(all, n);
    char *text = cJSON_PrintUnformatted(h);
    cJSON_Delete(h);
    int rc = text ? fx_buf_append(out, text, strlen(text)) : -1;
    free(text);
    return rc;
}
