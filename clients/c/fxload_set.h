/* fxload_set.h — fxload's set mode (fxload_set.c says how): the `set` messages at --rate, and
 * leaving the streams as they were, from the values before the run to their restore. */
#ifndef FXLOAD_SET_H
#define FXLOAD_SET_H

#include <cjson/cJSON.h>

struct ld;
struct ld_stream;

/* Keeps, from a `get` reply of st, the values of the parameters --set changes on st. */
void ld_set_take_before(struct ld *ld, struct ld_stream *st, const cJSON *reply);
/* Sends the sets due by now (seconds since t0), at --rate over the idle connections. */
void ld_send_due_sets(struct ld *ld, double now);
/* The reply to the restoring set of ld.streams[index]. */
void ld_set_on_restore_reply(struct ld *ld, int index, const cJSON *m, const char *op);
/* After the run: waits for the sets in flight, then (unless --keep) restores the values. */
void ld_set_finish(struct ld *ld);

#endif
