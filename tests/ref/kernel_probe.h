/* kernel_probe.h — runs test-only entry points into a kernel file's device functions on host
 * arrays, for the unit tests and the benchmarks: tests/ref/energy_wave_probe.cl's ew_test_*
 * (compiled after kernels/energy_wave.cl in one program, so the daemon's program has none),
 * compound_eye.cl's eye_trace_rays. The daemon never runs them, so the host side lives here
 * rather than in server/. */
#ifndef FX_KERNEL_PROBE_H
#define FX_KERNEL_PROBE_H

#include <stddef.h>

#include "effects/compound_eye.h"
#include "err.h"

struct ocl;

/* One kernel argument: a buffer of `bytes` (filled from `in` when given, read back into `out`
 * when given), or, with bytes 0, a value of `value_bytes` at `in`. */
struct probe_arg {
    size_t bytes;
    const void *in;
    void *out;
    size_t value_bytes;
};

/* Source text of tests/ref/`file` (embedded in build/gen/probe_kernels.c), or NULL. */
const char *probe_kernels_source(const char *file);

/* Runs `kernel` over `global` work-items: of kernels/`file` built with `opts`, or, given a
 * probe file (tests/ref/, embedded as probe_kernels_source), of a program of kernels/`file`
 * followed by the probe file. */
int probe_run(struct ocl *ocl, const char *file, const char *probe_file, const char *opts, const char *kernel,
              size_t global, const struct probe_arg *args, int nargs, struct fx_err *err);

/* compound_eye.cl's eye_trace_rays on n rays: entry points p[2k..2k+1] (pitches), unit
 * directions d[3k..3k+2] (d.z < 0). Fills land[2k..], status[k], passes[k], entered[k] and the
 * entry normal normal[3k..] (any output may be NULL). */
struct eye_rays_out {
    float *land;
    int *status, *passes, *entered;
    float *normal;
};
int probe_eye_trace(struct ocl *ocl, const struct eye_optics *o, int n, const float *p, const float *d,
                    struct eye_rays_out *out, struct fx_err *err);

#endif
