/* ocl.h — the OpenCL layer: one device, one context, one in-order profiling queue,
 * and a program cache.
 *
 * Only the engine thread (and tests/benches) use it. Programs are built once per
 * (kernel file, build options) and kept; a failed build returns the compiler's build
 * log in the error message. Kernel times are recorded from profiling events so
 * /metrics can report them per kernel. Kernel sources are embedded in the binary at
 * build time (kernels.h), so the daemon runs from any directory. */
#ifndef FX_OCL_H
#define FX_OCL_H

#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>
#include <stdbool.h>
#include <stdint.h>

#include "err.h"

struct ocl;

/* device_spec: NULL or "" or "auto" (first GPU if any, else first CPU device), "cpu",
 * "gpu", or "P:D" (platform index : device index as listed by clinfo -l). */
int ocl_open(struct ocl **out, const char *device_spec, struct fx_err *err);
void ocl_close(struct ocl *ocl);

const char *ocl_device_name(const struct ocl *ocl); /* "pthread-haswell-AMD EPYC ..." */
const char *ocl_platform_name(const struct ocl *ocl);
cl_context ocl_context(const struct ocl *ocl);
cl_device_id ocl_device(const struct ocl *ocl);
cl_command_queue ocl_queue(const struct ocl *ocl);
/* Whether the device runs on the host's own cores (a CPU device such as PoCL's). */
bool ocl_is_cpu(const struct ocl *ocl);

/* The built program for an embedded kernel file (e.g. "energy_wave.cl") and options.
 * Cached: the returned program is owned by ocl and valid until ocl_close. */
cl_program ocl_program(struct ocl *ocl, const char *file, const char *options, struct fx_err *err);

/* Adds the duration of a completed profiling event to the kernel's totals. */
void ocl_record(struct ocl *ocl, const char *kernel_name, cl_event ev);

struct ocl_kernel_stat {
    const char *name;
    uint64_t runs;
    double total_ms;
};
/* Copies up to max kernel stats into out; returns how many. */
int ocl_stats(const struct ocl *ocl, struct ocl_kernel_stat *out, int max);

/* One kernel argument: its size and a pointer to its value. */
struct ocl_arg {
    size_t size;
    const void *ptr;
};
/* Sets arguments 0 .. n-1 of kernel k (called `name` in messages); fails with the first
 * error's code, naming the argument. */
int ocl_set_args(cl_kernel k, const char *name, const struct ocl_arg *a, int n, struct fx_err *err);

/* Human-readable name of an OpenCL error code ("CL_OUT_OF_RESOURCES"). */
const char *ocl_errstr(cl_int code);

#endif
