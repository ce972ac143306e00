/* fxload_run.h — one fxload run on libfxclient's pool, from the first connection to the last
 * close (fxload_run.c says how): the ramp, the requests, routing what arrives to the
 * measurements and to set mode, the end of the run. */
#ifndef FXLOAD_RUN_H
#define FXLOAD_RUN_H

struct ld;

/* The run, from the first connection to the last close. Returns 0 (reports follow), or an
 * exit status when it ended without a report (a fatal error, already on stderr). */
int ld_run(struct ld *ld);

#endif
