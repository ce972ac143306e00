/* fxload_conn.h — the connections of an fxload run: one record per connection (its place in
 * libfxclient's pool, its group's subscriptions, set mode's outstanding set), the table of
 * them with each one's group, and what is done with them outside the pool's callbacks:
 * finding an open one, sending fxload's own control requests (`get`, the restoring `set`),
 * servicing the pool until a condition holds, closing them all politely. */
#ifndef FXLOAD_CONN_H
#define FXLOAD_CONN_H

#include <stdint.h>

#include <cjson/cJSON.h>

#include "fxs_frame.h"

/* Ids of fxload's own requests: the prefix, then the stream's index in ld.streams. */
#define LD_GET_ID "get:"
#define LD_RESTORE_ID "restore:"

struct ld;
struct fxp_conn;

/* One subscription of a connection. */
struct ld_sub {
    uint32_t channel; /* 0 until `subscribed` */
    uint64_t last_seq[FXS_KIND_MAX + 1];
};

enum ld_conn_state { LDC_IDLE, LDC_CONNECTING, LDC_OPEN, LDC_DONE };

struct ld_conn {
    struct ld *ld;
    struct fxp_conn *c;      /* NULL once closed */
    enum ld_conn_state state;
    int group;               /* subscribe mode: index into ld.groups; set mode: -1 */
    struct ld_sub *subs;     /* the group's n subscriptions */
    int set_busy;            /* set mode: a set is outstanding */
    double set_id;
    int64_t set_sent_us;
    int set_spec;
};

/* Allocates ld.conns and ld.subs and assigns each connection its group (fxload_plan.h).
 * Returns 0, or -1 out of memory. */
int ld_conns_create(struct ld *ld);
/* An open connection, NULL when none is. */
struct ld_conn *ld_open_conn(struct ld *ld);
/* Sends {"op":op,"id":"PREFIX INDEX","stream":...,"params":params} (params may be NULL)
 * about stream ld.streams[index] on lc. Returns 0, or -1 when it cannot be queued. */
int ld_send_control(struct ld_conn *lc, const char *op, const char *prefix, int index, const cJSON *params);
/* Services the pool until done(ld), wait_us passed, or no connection is left. */
void ld_service_until(struct ld *ld, int (*done)(const struct ld *ld), int64_t wait_us);
/* Closes every connection politely (bounded wait). */
void ld_close_all(struct ld *ld);

#endif
