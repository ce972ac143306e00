/* clfault.c — OpenCL fault injection for the tests: an LD_PRELOAD interposer of a few
 * OpenCL entry points (the real ones are reached through dlsym(RTLD_NEXT)), driven by
 * the environment variable FXS_CLFAULT, a ';'-separated list of rules:
 *
 *   build:SUBSTR
 *       clBuildProgram fails with CL_BUILD_PROGRAM_FAILURE for every program whose source
 *       (as given to clCreateProgramWithSource) contains SUBSTR, e.g. a kernel name found
 *       only in flame.cl; clGetProgramBuildInfo then returns a fake build log naming it.
 *   enqueue:KERNEL:after=N:err=CODE[:always]
 *       clEnqueueNDRangeKernel of the kernel named KERNEL returns CODE after N successful
 *       launches of it: once, or on every later launch with `always`. CODE is a number
 *       (-5) or one of CL_OUT_OF_RESOURCES, CL_OUT_OF_HOST_MEMORY,
 *       CL_MEM_OBJECT_ALLOCATION_FAILURE, CL_INVALID_COMMAND_QUEUE.
 *   lost:after_ms=T
 *       T milliseconds after the library is loaded the device is gone: every enqueue
 *       (kernel, read, write, copy, map) and clFinish returns CL_OUT_OF_RESOURCES, which is
 *       how most drivers report a lost GPU. It applies to all callers (one shared device).
 *       clFinish still drains the real queue first, so no real command outlives it.
 *
 * Example: FXS_CLFAULT='enqueue:fl_forces:after=40:err=CL_OUT_OF_RESOURCES' build/fxstreamd
 * A malformed rule is reported on stderr and ignored. Built as build/lib/libclfault.so. */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE /* memmem, RTLD_NEXT */
#endif
#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>
#include <dlfcn.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define CLF_MAX_RULES 8
#define CLF_MAX_PROGRAMS 64
#define CLF_TEXT 128

enum clf_kind { CLF_BUILD, CLF_ENQUEUE, CLF_LOST };

struct clf_rule {
    enum clf_kind kind;
    char text[CLF_TEXT]; /* build: the substring; enqueue: the kernel name */
    long after;          /* enqueue: successful launches first; lost: milliseconds */
    cl_int err;
    int always;
    long seen;           /* enqueue: launches so far */
};

static struct clf_rule clf_rules[CLF_MAX_RULES];
static int clf_nrules;
static cl_program clf_failing[CLF_MAX_PROGRAMS]; /* programs whose build is to fail */
static pthread_mutex_t clf_lock = PTHREAD_MUTEX_INITIALIZER;
static double clf_t0;

static double clf_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

static void *clf_real(const char *name)
{
    void *f = dlsym(RTLD_NEXT, name);
    if (!f) {
        fprintf(stderr, "clfault: no next definition of %s\n", name);
        abort();
    }
    return f;
}

/* The real function `name`, looked up once, as a pointer of the type of that function. */
#define CLF_REAL(name) static __typeof__(name) *real; if (!real) real = (__typeof__(name) *)clf_real(#name)

static cl_int clf_code(const char *s)
{
    static const struct { const char *name; cl_int code; } names[] = {
        {"CL_OUT_OF_RESOURCES", CL_OUT_OF_RESOURCES},
        {"CL_OUT_OF_HOST_MEMORY", CL_OUT_OF_HOST_MEMORY},
        {"CL_MEM_OBJECT_ALLOCATION_FAILURE", CL_MEM_OBJECT_ALLOCATION_FAILURE},
        {"CL_INVALID_COMMAND_QUEUE", CL_INVALID_COMMAND_QUEUE},
    };
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        if (!strcmp(s, names[i].name)) return names[i].code;
    return (cl_int)strtol(s, NULL, 10);
}

/* Parses the fields after "enqueue:KERNEL". */
static int clf_parse_enqueue(struct clf_rule *r, char *fields)
{
    r->err = CL_OUT_OF_RESOURCES;
    for (char *f = strtok(fields, ":"); f; f = strtok(NULL, ":")) {
        if (!strncmp(f, "after=", 6)) r->after = strtol(f + 6, NULL, 10);
        else if (!strncmp(f, "err=", 4)) r->err = clf_code(f + 4);
        else if (!strcmp(f, "always")) r->always = 1;
        else return -1;
    }
    return r->err != CL_SUCCESS ? 0 : -1;
}

static int clf_parse_rule(char *text, struct clf_rule *r)
{
    memset(r, 0, sizeof *r);
    char *arg = strchr(text, ':');
    if (!arg) return -1;
    *arg++ = '\0';
    if (!strcmp(text, "build") && *arg) {
        r->kind = CLF_BUILD;
        snprintf(r->text, sizeof r->text, "%s", arg);
        return 0;
    }
    if (!strcmp(text, "lost") && !strncmp(arg, "after_ms=", 9)) {
        r->kind = CLF_LOST;
        r->after = strtol(arg + 9, NULL, 10);
        return 0;
    }
    if (strcmp(text, "enqueue")) return -1;
    r->kind = CLF_ENQUEUE;
    char *fields = strchr(arg, ':');
    if (fields) *fields++ = '\0';
    snprintf(r->text, sizeof r->text, "%s", arg);
    return *arg && fields ? clf_parse_enqueue(r, fields) : -1;
}

__attribute__((constructor)) static void clf_init(void)
{
    clf_t0 = clf_now_ms();
    const char *env = getenv("FXS_CLFAULT");
    char *copy = env ? strdup(env) : NULL, *save = NULL;
    for (char *t = copy ? strtok_r(copy, ";", &save) : NULL; t; t = strtok_r(NULL, ";", &save)) {
        char rule[256];
        snprintf(rule, sizeof rule, "%s", t);
        if (clf_nrules < CLF_MAX_RULES && clf_parse_rule(t, &clf_rules[clf_nrules]) == 0) clf_nrules++;
        else fprintf(stderr, "clfault: rule ignored: %s\n", rule);
    }
    free(copy);
}

/* CL_OUT_OF_RESOURCES once a `lost` rule's time has come, else CL_SUCCESS. */
static cl_int clf_lost(void)
{
    for (int i = 0; i < clf_nrules; i++)
        if (clf_rules[i].kind == CLF_LOST && clf_now_ms() - clf_t0 >= clf_rules[i].after) return CL_OUT_OF_RESOURCES;
    return CL_SUCCESS;
}

/* The injected error for a launch of kernel k, counting the launch. */
static cl_int clf_launch(cl_kernel k)
{
    char name[CLF_TEXT] = "";
    CLF_REAL(clGetKernelInfo);
    real(k, CL_KERNEL_FUNCTION_NAME, sizeof name, name, NULL);
    cl_int rc = CL_SUCCESS;
    pthread_mutex_lock(&clf_lock);
    for (int i = 0; i < clf_nrules && rc == CL_SUCCESS; i++) {
        struct clf_rule *r = &clf_rules[i];
        if (r->kind != CLF_ENQUEUE || strcmp(r->text, name)) continue;
        long n = r->seen++;
        if (n == r->after || (r->always && n > r->after)) rc = r->err;
    }
    pthread_mutex_unlock(&clf_lock);
    return rc;
}

/* The build rule whose substring the program's source contains, or NULL. */
static const struct clf_rule *clf_build_rule(cl_uint count, const char **strings, const size_t *lengths)
{
    for (int i = 0; i < clf_nrules; i++) {
        if (clf_rules[i].kind != CLF_BUILD) continue;
        for (cl_uint s = 0; s < count; s++) {
            size_t len = lengths && lengths[s] ? lengths[s] : strlen(strings[s]);
            if (memmem(strings[s], len, clf_rules[i].text, strlen(clf_rules[i].text))) return &clf_rules[i];
        }
    }
    return NULL;
}

/* Marks (fail = 1) or unmarks a program handle as one whose build fails. */
static void clf_mark(cl_program p, int fail)
{
    pthread_mutex_lock(&clf_lock);
    int free_slot = -1;
    for (int i = 0; i < CLF_MAX_PROGRAMS; i++) {
        if (clf_failing[i] == p) clf_failing[i] = NULL; /* a reused handle */
        if (!clf_failing[i] && free_slot < 0) free_slot = i;
    }
    if (fail && free_slot >= 0) clf_failing[free_slot] = p;
    pthread_mutex_unlock(&clf_lock);
}

static int clf_marked(cl_program p)
{
    int found = 0;
    pthread_mutex_lock(&clf_lock);
    for (int i = 0; i < CLF_MAX_PROGRAMS && !found; i++) found = p && clf_failing[i] == p;
    pthread_mutex_unlock(&clf_lock);
    return found;
}

/* ---- the interposed entry points ---------------------------------------------------- */

cl_program clCreateProgramWithSource(cl_context ctx, cl_uint count, const char **strings, const size_t *lengths,
                                     cl_int *errcode_ret)
{
    CLF_REAL(clCreateProgramWithSource);
    cl_program p = real(ctx, count, strings, lengths, errcode_ret);
    if (p) clf_mark(p, clf_build_rule(count, strings, lengths) != NULL);
    return p;
}

cl_int clBuildProgram(cl_program p, cl_uint ndev, const cl_device_id *devs, const char *options,
                      void (CL_CALLBACK *notify)(cl_program, void *), void *user)
{
    CLF_REAL(clBuildProgram);
    return clf_marked(p) ? CL_BUILD_PROGRAM_FAILURE : real(p, ndev, devs, options, notify, user);
}

cl_int clGetProgramBuildInfo(cl_program p, cl_device_id dev, cl_program_build_info what, size_t size, void *value,
                             size_t *size_ret)
{
    CLF_REAL(clGetProgramBuildInfo);
    if (what != CL_PROGRAM_BUILD_LOG || !clf_marked(p)) return real(p, dev, what, size, value, size_ret);
    static const char log[] = "clfault: injected build failure (FXS_CLFAULT build rule)";
    if (size_ret) *size_ret = sizeof log;
    if (value && size < sizeof log) return CL_INVALID_VALUE;
    if (value) memcpy(value, log, sizeof log);
    return CL_SUCCESS;
}

cl_int clEnqueueNDRangeKernel(cl_command_queue q, cl_kernel k, cl_uint dim, const size_t *offset,
                              const size_t *global, const size_t *local, cl_uint nwait, const cl_event *wait,
                              cl_event *ev)
{
    CLF_REAL(clEnqueueNDRangeKernel);
    cl_int rc = clf_lost();
    if (rc == CL_SUCCESS) rc = clf_launch(k);
    return rc != CL_SUCCESS ? rc : real(q, k, dim, offset, global, local, nwait, wait, ev);
}

cl_int clEnqueueReadBuffer(cl_command_queue q, cl_mem m, cl_bool block, size_t off, size_t n, void *dst,
                           cl_uint nwait, const cl_event *wait, cl_event *ev)
{
    CLF_REAL(clEnqueueReadBuffer);
    cl_int rc = clf_lost();
    return rc != CL_SUCCESS ? rc : real(q, m, block, off, n, dst, nwait, wait, ev);
}

cl_int clEnqueueWriteBuffer(cl_command_queue q, cl_mem m, cl_bool block, size_t off, size_t n, const void *src,
                            cl_uint nwait, const cl_event *wait, cl_event *ev)
{
    CLF_REAL(clEnqueueWriteBuffer);
    cl_int rc = clf_lost();
    return rc != CL_SUCCESS ? rc : real(q, m, block, off, n, src, nwait, wait, ev);
}

cl_int clEnqueueCopyBuffer(cl_command_queue q, cl_mem src, cl_mem dst, size_t soff, size_t doff, size_t n,
                           cl_uint nwait, const cl_event *wait, cl_event *ev)
{
    CLF_REAL(clEnqueueCopyBuffer);
    cl_int rc = clf_lost();
    return rc != CL_SUCCESS ? rc : real(q, src, dst, soff, doff, n, nwait, wait, ev);
}

void *clEnqueueMapBuffer(cl_command_queue q, cl_mem m, cl_bool block, cl_map_flags flags, size_t off, size_t n,
                         cl_uint nwait, const cl_event *wait, cl_event *ev, cl_int *errcode_ret)
{
    CLF_REAL(clEnqueueMapBuffer);
    cl_int rc = clf_lost();
    if (rc == CL_SUCCESS) return real(q, m, block, flags, off, n, nwait, wait, ev, errcode_ret);
    if (errcode_ret) *errcode_ret = rc;
    return NULL;
}

cl_int clFinish(cl_command_queue q)
{
    CLF_REAL(clFinish);
    cl_int rc = real(q);
    return clf_lost() != CL_SUCCESS ? clf_lost() : rc;
}
