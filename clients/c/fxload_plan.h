/* fxload_plan.h — which streams an fxload run uses and how its connections share them: the
 * --streams groups (GROUP[:WEIGHT],... with GROUP = STREAM[+STREAM...]) or, in set mode, the
 * streams --set names, entered into the run's stream table (ld.streams, ld.groups in
 * fxload_state.h); the look-up of a stream by name; and the smooth weighted round-robin that
 * gives each connection its group. */
#ifndef FXLOAD_PLAN_H
#define FXLOAD_PLAN_H

struct ld;
struct ld_stream;

/* Fills ld.streams and ld.groups from the checked options (ld_opts_check). Returns 0 or LD_USAGE. */
int ld_plan_streams(struct ld *ld);
/* The stream called name, NULL when it is not one of the run's. */
struct ld_stream *ld_stream_find(struct ld *ld, const char *name);
/* The index in ld.groups of the group the next connection subscribes to. */
int ld_plan_next_group(struct ld *ld);

#endif
