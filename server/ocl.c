/* ocl.c — the OpenCL layer (see ocl.h): device selection, one context and one
 * in-order profiling queue, a program cache and per-kernel timing totals.
 *
 * Shaped for a single engine thread: device/context/queue are created once at open,
 * programs are built lazily and cached by (file, options) for the life of the ocl.
 * Only the kernel statistics are shared with other threads (/metrics), so they alone
 * sit behind a mutex in a fixed-size table. */
#include "ocl.h"

#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#include "kernels.h"

#define OCL_MAX_PLATFORMS 16
#define OCL_MAX_DEVICES 32
#define OCL_MAX_PROGRAMS 32
#define OCL_MAX_STATS 64

struct ocl_program_entry {
    char *file;
    char *options;
    cl_program program;
};

struct ocl {
    cl_platform_id platform;
    cl_device_id device;
    cl_context context;
    cl_command_queue queue;
    char device_name[256];
    char platform_name[256];
    struct ocl_program_entry programs[OCL_MAX_PROGRAMS];
    int nprograms;
    pthread_mutex_t stats_lock;
    struct ocl_kernel_stat stats[OCL_MAX_STATS];
    char stat_names[OCL_MAX_STATS][64];
    int nstats;
};

/* All devices of all platforms, in clinfo -l order. */
struct ocl_inventory {
    cl_platform_id platforms[OCL_MAX_PLATFORMS];
    cl_uint nplatforms;
    cl_device_id devices[OCL_MAX_PLATFORMS][OCL_MAX_DEVICES];
    cl_uint ndevices[OCL_MAX_PLATFORMS];
};

const char *ocl_errstr(cl_int code)
{
    switch (code) {
#define OCL_CASE(c) case c: return #c
    OCL_CASE(CL_SUCCESS);
    OCL_CASE(CL_DEVICE_NOT_FOUND);
    OCL_CASE(CL_DEVICE_NOT_AVAILABLE);
    OCL_CASE(CL_COMPILER_NOT_AVAILABLE);
    OCL_CASE(CL_MEM_OBJECT_ALLOCATION_FAILURE);
    OCL_CASE(CL_OUT_OF_RESOURCES);
    OCL_CASE(CL_OUT_OF_HOST_MEMORY);
    OCL_CASE(CL_PROFILING_INFO_NOT_AVAILABLE);
    OCL_CASE(CL_MEM_COPY_OVERLAP);
    OCL_CASE(CL_IMAGE_FORMAT_MISMATCH);
    OCL_CASE(CL_IMAGE_FORMAT_NOT_SUPPORTED);
    OCL_CASE(CL_BUILD_PROGRAM_FAILURE);
    OCL_CASE(CL_MAP_FAILURE);
    OCL_CASE(CL_MISALIGNED_SUB_BUFFER_OFFSET);
    OCL_CASE(CL_EXEC_STATUS_ERROR_FOR_EVENTS_IN_WAIT_LIST);
    OCL_CASE(CL_COMPILE_PROGRAM_FAILURE);
    OCL_CASE(CL_LINKER_NOT_AVAILABLE);
    OCL_CASE(CL_LINK_PROGRAM_FAILURE);
    OCL_CASE(CL_DEVICE_PARTITION_FAILED);
    OCL_CASE(CL_KERNEL_ARG_INFO_NOT_AVAILABLE);
    OCL_CASE(CL_INVALID_VALUE);
    OCL_CASE(CL_INVALID_DEVICE_TYPE);
    OCL_CASE(CL_INVALID_PLATFORM);
    OCL_CASE(CL_INVALID_DEVICE);
    OCL_CASE(CL_INVALID_CONTEXT);
    OCL_CASE(CL_INVALID_QUEUE_PROPERTIES);
    OCL_CASE(CL_INVALID_COMMAND_QUEUE);
    OCL_CASE(CL_INVALID_HOST_PTR);
    OCL_CASE(CL_INVALID_MEM_OBJECT);
    OCL_CASE(CL_INVALID_IMAGE_FORMAT_DESCRIPTOR);
    OCL_CASE(CL_INVALID_IMAGE_SIZE);
    OCL_CASE(CL_INVALID_SAMPLER);
    OCL_CASE(CL_INVALID_BINARY);
    OCL_CASE(CL_INVALID_BUILD_OPTIONS);
    OCL_CASE(CL_INVALID_PROGRAM);
    OCL_CASE(CL_INVALID_PROGRAM_EXECUTABLE);
    OCL_CASE(CL_INVALID_KERNEL_NAME);
    OCL_CASE(CL_INVALID_KERNEL_DEFINITION);
    OCL_CASE(CL_INVALID_KERNEL);
    OCL_CASE(CL_INVALID_ARG_INDEX);
    OCL_CASE(CL_INVALID_ARG_VALUE);
    OCL_CASE(CL_INVALID_ARG_SIZE);
    OCL_CASE(CL_INVALID_KERNEL_ARGS);
    OCL_CASE(CL_INVALID_WORK_DIMENSION);
    OCL_CASE(CL_INVALID_WORK_GROUP_SIZE);
    OCL_CASE(CL_INVALID_WORK_ITEM_SIZE);
    OCL_CASE(CL_INVALID_GLOBAL_OFFSET);
    OCL_CASE(CL_INVALID_EVENT_WAIT_LIST);
    OCL_CASE(CL_INVALID_EVENT);
    OCL_CASE(CL_INVALID_OPERATION);
    OCL_CASE(CL_INVALID_GL_OBJECT);
    OCL_CASE(CL_INVALID_BUFFER_SIZE);
    OCL_CASE(CL_INVALID_MIP_LEVEL);
    OCL_CASE(CL_INVALID_GLOBAL_WORK_SIZE);
    OCL_CASE(CL_INVALID_PROPERTY);
    OCL_CASE(CL_INVALID_IMAGE_DESCRIPTOR);
    OCL_CASE(CL_INVALID_COMPILER_OPTIONS);
    OCL_CASE(CL_INVALID_LINKER_OPTIONS);
    OCL_CASE(CL_INVALID_DEVICE_PARTITION_COUNT);
#undef OCL_CASE
    default: return "CL_UNKNOWN_ERROR";
    }
}

static int ocl_inventory_load(struct ocl_inventory *inv, struct fx_err *err)
{
    cl_int rc = clGetPlatformIDs(OCL_MAX_PLATFORMS, inv->platforms, &inv->nplatforms);
    if (rc != CL_SUCCESS || inv->nplatforms == 0)
        return fx_fail(err, "internal", "", "no OpenCL platform found (%s); install an ICD such as pocl-opencl-icd",
                       ocl_errstr(rc));
    if (inv->nplatforms > OCL_MAX_PLATFORMS) inv->nplatforms = OCL_MAX_PLATFORMS;
    for (cl_uint p = 0; p < inv->nplatforms; p++) {
        if (clGetDeviceIDs(inv->platforms[p], CL_DEVICE_TYPE_ALL, OCL_MAX_DEVICES, inv->devices[p],
                           &inv->ndevices[p]) != CL_SUCCESS)
            inv->ndevices[p] = 0;
        if (inv->ndevices[p] > OCL_MAX_DEVICES) inv->ndevices[p] = OCL_MAX_DEVICES;
    }
    return 0;
}

static cl_device_type ocl_device_type(cl_device_id dev)
{
    cl_device_type type = 0;
    clGetDeviceInfo(dev, CL_DEVICE_TYPE, sizeof type, &type, NULL);
    return type;
}

/* "0:0 pthread-haswell-AMD EPYC (cpu); 1:0 ..." into out, for error messages. */
static void ocl_inventory_describe(const struct ocl_inventory *inv, char *out, size_t cap)
{
    size_t len = 0;
    out[0] = '\0';
    for (cl_uint p = 0; p < inv->nplatforms; p++)
        for (cl_uint d = 0; d < inv->ndevices[p] && len < cap; d++) {
            char name[128] = "";
            cl_device_id dev = inv->devices[p][d];
            clGetDeviceInfo(dev, CL_DEVICE_NAME, sizeof name, name, NULL);
            int n = snprintf(out + len, cap - len, "%s%u:%u %s (%s)", len ? "; " : "", p, d, name,
                             (ocl_device_type(dev) & CL_DEVICE_TYPE_GPU) ? "gpu" : "cpu");
            if (n < 0) break;
            len += (size_t)n;
        }
    if (!out[0]) snprintf(out, cap, "none");
}

/* First device of the given type in clinfo order; 0 when none. */
static int ocl_find_type(const struct ocl_inventory *inv, cl_device_type type, cl_uint *pp, cl_uint *dd)
{
    for (cl_uint p = 0; p < inv->nplatforms; p++)
        for (cl_uint d = 0; d < inv->ndevices[p]; d++)
            if (ocl_device_type(inv->devices[p][d]) & type) {
                *pp = p;
                *dd = d;
                return 1;
            }
    return 0;
}

/* Resolves device_spec to a (platform, device) index pair; 0 when nothing matches. */
static int ocl_match_spec(const struct ocl_inventory *inv, const char *spec, cl_uint *pp, cl_uint *dd)
{
    unsigned p, d;
    char tail;
    if (!spec || !spec[0] || strcmp(spec, "auto") == 0)
        return ocl_find_type(inv, CL_DEVICE_TYPE_GPU, pp, dd) || ocl_find_type(inv, CL_DEVICE_TYPE_ALL, pp, dd);
    if (strcmp(spec, "cpu") == 0) return ocl_find_type(inv, CL_DEVICE_TYPE_CPU, pp, dd);
    if (strcmp(spec, "gpu") == 0) return ocl_find_type(inv, CL_DEVICE_TYPE_GPU, pp, dd);
    if (sscanf(spec, "%u:%u%c", &p, &d, &tail) != 2) return 0;
    if (p >= inv->nplatforms || d >= inv->ndevices[p]) return 0;
    *pp = p;
    *dd = d;
    return 1;
}

static int ocl_create_objects(struct ocl *ocl, struct fx_err *err)
{
    cl_int rc;
    cl_context_properties props[] = {CL_CONTEXT_PLATFORM, (cl_context_properties)ocl->platform, 0};
    ocl->context = clCreateContext(props, 1, &ocl->device, NULL, NULL, &rc);
    if (rc != CL_SUCCESS)
        return fx_fail(err, "internal", "", "clCreateContext on %s failed: %s", ocl->device_name, ocl_errstr(rc));
    ocl->queue = clCreateCommandQueue(ocl->context, ocl->device, CL_QUEUE_PROFILING_ENABLE, &rc);
    if (rc != CL_SUCCESS)
        return fx_fail(err, "internal", "", "clCreateCommandQueue on %s failed: %s", ocl->device_name,
                       ocl_errstr(rc));
    return 0;
}

int ocl_open(struct ocl **out, const char *device_spec, struct fx_err *err)
{
    struct ocl_inventory inv;
    cl_uint p, d;
    *out = NULL;
    if (ocl_inventory_load(&inv, err)) return -1;
    if (!ocl_match_spec(&inv, device_spec, &p, &d)) {
        char list[256];
        ocl_inventory_describe(&inv, list, sizeof list);
        return fx_fail(err, "internal", "", "no OpenCL device matches \"%s\" (use auto, cpu, gpu or P:D); available: %s",
                       device_spec ? device_spec : "", list);
    }
    struct ocl *ocl = calloc(1, sizeof *ocl);
    if (!ocl) return fx_fail(err, "internal", "", "out of memory");
    ocl->platform = inv.platforms[p];
    ocl->device = inv.devices[p][d];
    clGetDeviceInfo(ocl->device, CL_DEVICE_NAME, sizeof ocl->device_name, ocl->device_name, NULL);
    clGetPlatformInfo(ocl->platform, CL_PLATFORM_NAME, sizeof ocl->platform_name, ocl->platform_name, NULL);
    pthread_mutex_init(&ocl->stats_lock, NULL);
    if (ocl_create_objects(ocl, err)) {
        ocl_close(ocl);
        return -1;
    }
    *out = ocl;
    return 0;
}

void ocl_close(struct ocl *ocl)
{
    if (!ocl) return;
    for (int i = 0; i < ocl->nprograms; i++) {
        clReleaseProgram(ocl->programs[i].program);
        free(ocl->programs[i].file);
        free(ocl->programs[i].options);
    }
    if (ocl->queue) clReleaseCommandQueue(ocl->queue);
    if (ocl->context) clReleaseContext(ocl->context);
    pthread_mutex_destroy(&ocl->stats_lock);
    free(ocl);
}

const char *ocl_device_name(const struct ocl *ocl) { return ocl->device_name; }
const char *ocl_platform_name(const struct ocl *ocl) { return ocl->platform_name; }
cl_context ocl_context(const struct ocl *ocl) { return ocl->context; }
cl_device_id ocl_device(const struct ocl *ocl) { return ocl->device; }
cl_command_queue ocl_queue(const struct ocl *ocl) { return ocl->queue; }
bool ocl_is_cpu(const struct ocl *ocl) { return (ocl_device_type(ocl->device) & CL_DEVICE_TYPE_CPU) != 0; }

/* Fails with the build log; fx_err keeps its beginning (the first errors). */
static int ocl_build_failed(struct ocl *ocl, cl_program prog, const char *file, cl_int rc, struct fx_err *err)
{
    size_t n = 0;
    clGetProgramBuildInfo(prog, ocl->device, CL_PROGRAM_BUILD_LOG, 0, NULL, &n);
    char *log = calloc(n + 1, 1);
    if (log && n) clGetProgramBuildInfo(prog, ocl->device, CL_PROGRAM_BUILD_LOG, n, log, NULL);
    fx_fail(err, "internal", "", "OpenCL build of %s failed (%s): %s", file, ocl_errstr(rc), log ? log : "");
    free(log);
    return -1;
}

static cl_program ocl_build(struct ocl *ocl, const char *file, const char *options, struct fx_err *err)
{
    cl_int rc;
    const char *src = kernels_source(file);
    if (!src) {
        fx_fail(err, "internal", "", "kernel file %s is not embedded in this build", file);
        return NULL;
    }
    cl_program prog = clCreateProgramWithSource(ocl->context, 1, &src, NULL, &rc);
    if (rc != CL_SUCCESS) {
        fx_fail(err, "internal", "", "clCreateProgramWithSource(%s) failed: %s", file, ocl_errstr(rc));
        return NULL;
    }
    rc = clBuildProgram(prog, 1, &ocl->device, options, NULL, NULL);
    if (rc != CL_SUCCESS) {
        ocl_build_failed(ocl, prog, file, rc, err);
        clReleaseProgram(prog);
        return NULL;
    }
    return prog;
}

cl_program ocl_program(struct ocl *ocl, const char *file, const char *options, struct fx_err *err)
{
    const char *opts = options ? options : "";
    for (int i = 0; i < ocl->nprograms; i++)
        if (strcmp(ocl->programs[i].file, file) == 0 && strcmp(ocl->programs[i].options, opts) == 0)
            return ocl->programs[i].program;
    if (ocl->nprograms == OCL_MAX_PROGRAMS) {
        fx_fail(err, "internal", "", "OpenCL program cache full (%d programs)", OCL_MAX_PROGRAMS);
        return NULL;
    }
    cl_program prog = ocl_build(ocl, file, opts, err);
    if (!prog) return NULL;
    struct ocl_program_entry *e = &ocl->programs[ocl->nprograms];
    e->file = strdup(file);
    e->options = strdup(opts);
    if (!e->file || !e->options) {
        free(e->file);
        free(e->options);
        clReleaseProgram(prog);
        fx_fail(err, "internal", "", "out of memory");
        return NULL;
    }
    e->program = prog;
    ocl->nprograms++;
    return prog;
}

/* Index of the stat slot for name, creating it; -1 when the table is full. */
static int ocl_stat_slot(struct ocl *ocl, const char *name)
{
    for (int i = 0; i < ocl->nstats; i++)
        if (strcmp(ocl->stat_names[i], name) == 0) return i;
    if (ocl->nstats == OCL_MAX_STATS) return -1;
    int i = ocl->nstats++;
    snprintf(ocl->stat_names[i], sizeof ocl->stat_names[i], "%s", name);
    ocl->stats[i].name = ocl->stat_names[i];
    return i;
}

void ocl_record(struct ocl *ocl, const char *kernel_name, cl_event ev)
{
    cl_ulong t0 = 0, t1 = 0;
    if (clGetEventProfilingInfo(ev, CL_PROFILING_COMMAND_START, sizeof t0, &t0, NULL) != CL_SUCCESS ||
        clGetEventProfilingInfo(ev, CL_PROFILING_COMMAND_END, sizeof t1, &t1, NULL) != CL_SUCCESS)
        return;
    pthread_mutex_lock(&ocl->stats_lock);
    int i = ocl_stat_slot(ocl, kernel_name);
    if (i >= 0) {
        ocl->stats[i].runs++;
        ocl->stats[i].total_ms += t1 > t0 ? (double)(t1 - t0) * 1e-6 : 0.0;
    }
    pthread_mutex_unlock(&ocl->stats_lock);
}

int ocl_stats(const struct ocl *ocl, struct ocl_kernel_stat *out, int max)
{
    struct ocl *m = (struct ocl *)ocl; /* the lock is the only mutable part */
    pthread_mutex_lock(&m->stats_lock);
    int n = ocl->nstats < max ? ocl->nstats : max;
    memcpy(out, ocl->stats, (size_t)(n > 0 ? n : 0) * sizeof *out);
    pthread_mutex_unlock(&m->stats_lock);
    return n;
}

int ocl_set_args(cl_kernel k, const char *name, const struct ocl_arg *a, int n, struct fx_err *err)
{
    for (int i = 0; i < n; i++) {
        cl_int rc = clSetKernelArg(k, (cl_uint)i, a[i].size, a[i].ptr);
        if (rc != CL_SUCCESS) return fx_fail(err, "internal", "", "clSetKernelArg(%s, %d): %s", name, i, ocl_errstr(rc));
    }
    return 0;
}
