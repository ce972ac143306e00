/* fxctl_sub.h — `fxctl subscribe` after the subscribed reply: receives the stream's frames
 * and counts steps (the frames one simulation step produced, sent together with the same
 * sim_time: energy's texture and its light rig) or, with --kind, frames of that kind. Each
 * counted step or frame must come within the timeout, which frames of other kinds and events
 * do not extend; when it passes, the error names what the stream did send (a --kind it never
 * sends: "no frame of kind 2 (texture) came; the stream sent 57 of kind 1 (particles)").
 * The last step ends when it holds every kind the earlier ones held, when the next step
 * begins, or FXCTL_SETTLE_MS after its latest frame. Also prints the stream's params events
 * and fails when it is destroyed; frames go through fxctl_save.h. */
#ifndef FXCTL_SUB_H
#define FXCTL_SUB_H

#include <stdint.h>

#include "fxclient.h"

#define FXCTL_SETTLE_MS 250 /* wait for the rest of the last step once its first frame came */

struct fxctl_sub_opts {
    const char *stream;
    long count;          /* steps, or frames of `kind` */
    int kind;            /* 0: every kind, counting steps */
    int timeout_ms;      /* for each step (frame of `kind`) */
    const char *out_dir; /* NULL: print only */
};

/* Returns 0 once o->count steps (frames) were printed, else 1 after one line on stderr. */
int fxctl_subscribe(struct fxc_client *c, const struct fxctl_sub_opts *o, uint32_t channel);

#endif
