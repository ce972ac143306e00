/* flame.c — effect `flame` (seed 002, Mabuchi 2012; spec: digest 002), host side.
 *
 * Owns the device buffers and the order of kernels/flame.cl launches (the parameters, their
 * table and their packing into the kernels' array are flame_params.c's);
 * no per-particle loop runs on the host except building the solids of a scene. State lives
 * in two buffer sets (buf.st[0], buf.st[1]): a substep sorts the current set into the other one,
 * gathers density into the current set's derived arrays and integrates back into the
 * current set, so after every step one set holds the state and its derived fields in the
 * same order. Resampling (every resample_interval steps, on the steps whose 0-based index is
 * a multiple of it; digest §2.12) compacts into the other set. The host reads back only
 * the resampling totals (3 ints), the error flag, and once per frame the particles. The sort
 * and the compaction run in FL_BLOCKS serial blocks on a CPU device and one work item per
 * element on a GPU ("wide": flame_set_wide), in the same order bit for bit.
 *
 * Digest fixes applied: §9 #1 pressure sign, #3 symmetric form option, #4 stabilised
 * diffusion (also capping viscosity, §2.15), #6 derived mass, #7 d = h/2, #8 insertion
 * threshold, #9 outward insertion, #10 inherited velocity, #11 deletion rule, #12 fuel_eps and
 * F >= 0, #13 optional cooling, #14 g = 0, #15 wind (the uniform acceleration and §2.14's drag toward
 * a wind velocity), #16 kinematic obstacles, #17 disc sources, #20 up vector. */
#include "flame.h"

#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../ocl.h"

#define FL_KERNEL_FILE "flame.cl"
#ifndef FL_NL
#define FL_NL 64 /* neighbour-list slots per particle (lists of up to FL_NL - 8 neighbours, flame.cl) */
#endif
#define FL_STR2(x) #x
#define FL_STR(x) FL_STR2(x)
/* -cl-unsafe-math-optimizations (reassociation, reciprocals; not finite-math, so the NaN/Inf
 * runaway check still works): about 10% on bench_flame, device-vs-reference tests unchanged. */
#define FL_BUILD_OPTS "-cl-mad-enable -cl-unsafe-math-optimizations -DFL_NL=" FL_STR(FL_NL)
#ifndef FL_LOCAL
#define FL_LOCAL 64 /* work-group size of the per-particle kernels */
#endif
#define FL_PAD 8           /* spare elements after each sorted x, y, z array: fl_density reads 8 at a time */
#define FL_BLOCKS 16       /* work items of the serial-per-block sort/scan/compaction kernels */
#define FL_MAX_EVENTS 1024 /* profiling events kept until the next sync */
#define FL_SCAN_SUMS 4096 /* tiles of the longest scan: the cell table's 2^22 + 1 entries, or 2^22 particles */

/* ---- state ------------------------------------------------------------------------- */

/* The kernels of flame.cl, in the order a substep launches them. */
enum fl_kernel {
    FL_K_HASH, FL_K_RADIX_HIST, FL_K_SCAN_SERIAL, FL_K_RADIX_SCATTER, FL_K_REORDER, FL_K_CELL_START, /* sort */
    FL_K_DENSITY, FL_K_FORCES,                                                                     /* gather */
    FL_K_RESAMPLE_COUNT, FL_K_SCAN_BLOCKS, FL_K_COMPACT,                                           /* resample */
    FL_K_KEY_COUNT, FL_K_KEY_SCATTER, FL_K_KEY_RANK, FL_K_SCAN_REDUCE, FL_K_SCAN_TOP, FL_K_SCAN_DOWN,
    FL_K_COMPACT_WIDE, /* the wide passes' sort and resampling */
    FL_KERNEL_COUNT
};
static const char *const fl_kernel_names[FL_KERNEL_COUNT] = {
    [FL_K_HASH] = "fl_hash",           [FL_K_RADIX_HIST] = "fl_radix_hist",   [FL_K_SCAN_SERIAL] = "fl_scan_serial",
    [FL_K_RADIX_SCATTER] = "fl_radix_scatter", [FL_K_REORDER] = "fl_reorder", [FL_K_CELL_START] = "fl_cell_start",
    [FL_K_DENSITY] = "fl_density",     [FL_K_FORCES] = "fl_forces",           [FL_K_RESAMPLE_COUNT] = "fl_count",
    [FL_K_SCAN_BLOCKS] = "fl_scan_blocks", [FL_K_COMPACT] = "fl_compact",     [FL_K_KEY_COUNT] = "fl_key_count",
    [FL_K_KEY_SCATTER] = "fl_key_scatter", [FL_K_KEY_RANK] = "fl_key_rank",   [FL_K_SCAN_REDUCE] = "fl_scan_reduce",
    [FL_K_SCAN_TOP] = "fl_scan_top",       [FL_K_SCAN_DOWN] = "fl_scan_down", [FL_K_COMPACT_WIDE] = "fl_compact_wide"};

/* One state set: particle state plus derived fields, all in the same order. */
struct fl_set {
    cl_mem pos, vel, flags, id, rho_p, counts, force, dTdF;
};

/* Device memory: the two state sets and the work arrays of a substep. */
struct fl_buffers {
    struct fl_set st[2];
    int cur;               /* the set that holds the state */
    cl_mem key[2], val[2]; /* the radix sort's cell keys and particle indices, ping-pong */
    cl_mem hist;           /* the radix sort's histograms, 256 per block */
    cl_mem cs;             /* cell-start table of the hash grid */
    /* (wide passes: key[0] the keys, val[] the counting sort's slots and runs, key[1] the sorted
     * indices; after the sort key[0] and key[1] take the compaction's scanned flags) */
    cl_mem cnt;            /* wide passes: particles per key (as many entries as cs; made by the first wide sort) */
    cl_mem sums;           /* wide passes: the device scan's tile sums (FL_SCAN_SUMS) */
    cl_mem sxyz;           /* sorted x, y, z as three arrays of stride cap + FL_PAD (fl_reorder -> fl_density) */
    cl_mem nl;             /* neighbour lists, FL_NL slots per particle */
    cl_mem keep_ins, nrm;  /* resampling: what becomes of each particle, and its insertion normal */
    cl_mem bsum, tot;      /* resampling: per-block sums, and the totals the host reads (tot[3]: the sort scan's) */
    cl_mem errflag;        /* FL_ERR_* bits of the last steps */
    cl_mem prm;            /* the parameter array (FP_*) */
    int cap, cs_cap;       /* particles the per-particle buffers hold; entries of cs */
};

/* The hash grid of the current particle count: 2^k cells, sorted in passes of 8 bits. */
struct fl_grid {
    uint32_t mask;
    int passes;
};

/* A resampling step's totals (survivors, insertions, new count) and error bits, read without
 * waiting (fl_resample_begin) and applied once the queue is done (fl_resample_end). */
struct fl_resample {
    int pending;
    cl_uint tot[3];
    cl_int err;
};

struct fl_event {
    const char *name;
    cl_event ev;
};

/* Profiling events of the launches since the last sync, booked to ocl's kernel statistics. */
struct fl_events {
    struct fl_event ev[FL_MAX_EVENTS];
    int n;
};

/* The parameters as the simulation uses them. */
struct fl_params {
    struct flame_config cfg; /* as last set */
    bool configured;         /* cfg holds a set */
    double h, d, dt, t_amb, up[3]; /* d: particle spacing; up: unit */
    int interval, max_particles;   /* resample_interval */
    float P[FP_COUNT];             /* the kernels' parameter array (flame_params_pack) */
};

/* Simulated time and identity since creation or reset. */
struct fl_clock {
    uint64_t steps;
    double sim_seconds;
    uint32_t next_id; /* the id the next new particle gets */
};

struct flame {
    struct ocl *ocl;
    cl_kernel k[FL_KERNEL_COUNT];
    bool wide; /* the sort and the resampling one work item per element (GPU), not FL_BLOCKS serial blocks (CPU) */
    int n;     /* particles */
    struct fl_buffers buf;
    struct fl_grid grid;
    struct fl_resample rs;
    struct fl_events events;
    struct fl_params params;
    struct fl_clock clock;
};

static const size_t fl_sizes[8] = {16, 16, 4, 4, 8, 4, 16, 8}; /* bytes per particle of struct fl_set */

static int fl_clfail(struct fx_err *err, const char *what, cl_int rc)
{
    return fx_fail(err, "internal", "", "flame: %s: %s", what, ocl_errstr(rc));
}

static cl_mem fl_buffer(struct flame *fl, size_t bytes, cl_int *rc)
{
    return clCreateBuffer(ocl_context(fl->ocl), CL_MEM_READ_WRITE, bytes ? bytes : 16, NULL, rc);
}

static cl_mem *fl_set_mem(struct fl_set *s, int i) { return &s->pos + i; }

static void fl_release(cl_mem *m)
{
    if (*m) clReleaseMemObject(*m);
    *m = NULL;
}

/* ---- profiling events ---------------------------------------------------------------- */

static void fl_flush_events(struct flame *fl)
{
    for (int i = 0; i < fl->events.n; i++) {
        ocl_record(fl->ocl, fl->events.ev[i].name, fl->events.ev[i].ev);
        clReleaseEvent(fl->events.ev[i].ev);
    }
    fl->events.n = 0;
}

/* Completes the queue and books every kernel time. */
static int fl_finish(struct flame *fl, struct fx_err *err)
{
    cl_int rc = clFinish(ocl_queue(fl->ocl));
    fl_flush_events(fl);
    return rc == CL_SUCCESS ? 0 : fl_clfail(err, "clFinish", rc);
}

static int fl_launch(struct flame *fl, enum fl_kernel k, size_t global, size_t local, struct fx_err *err)
{
    if (fl->events.n == FL_MAX_EVENTS && fl_finish(fl, err)) return -1;
    if (global == 0) return 0;
    if (!local) { /* a fixed work-group size: PoCL compiles one work-group function per size */
        local = FL_LOCAL;
        global = (global + local - 1) / local * local;
    }
    cl_event ev;
    cl_int rc = clEnqueueNDRangeKernel(ocl_queue(fl->ocl), fl->k[k], 1, NULL, &global, &local, 0, NULL, &ev);
    if (rc != CL_SUCCESS) return fl_clfail(err, fl_kernel_names[k], rc);
    fl->events.ev[fl->events.n++] = (struct fl_event){fl_kernel_names[k], ev};
    return 0;
}

/* Kernel arguments as (size, pointer) pairs (ocl_set_args). */
#define FL_MEM(m) {sizeof(cl_mem), &(m)}
#define FL_INT(v) {sizeof(cl_int), &(v)}

static int fl_args(struct flame *fl, enum fl_kernel k, const struct ocl_arg *a, int na, struct fx_err *err)
{
    return ocl_set_args(fl->k[k], fl_kernel_names[k], a, na, err);
}

/* ---- buffers ------------------------------------------------------------------------- */

/* Grows every per-particle buffer to hold `want` particles, keeping the current state. */
static int fl_reserve(struct flame *fl, int want, struct fx_err *err)
{
    if (want <= fl->buf.cap) return 0;
    int cap = fl->buf.cap ? fl->buf.cap : 4096;
    while (cap < want) cap *= 2;
    cl_int rc = CL_SUCCESS;
    struct fl_set ns[2] = {{0}};
    for (int s = 0; s < 2 && rc == CL_SUCCESS; s++)
        for (int i = 0; i < 8 && rc == CL_SUCCESS; i++) *fl_set_mem(&ns[s], i) = fl_buffer(fl, fl_sizes[i] * cap, &rc);
    for (int i = 0; i < 4 && rc == CL_SUCCESS && fl->n > 0; i++) /* the state of the current set */
        rc = clEnqueueCopyBuffer(ocl_queue(fl->ocl), *fl_set_mem(&fl->buf.st[fl->buf.cur], i), *fl_set_mem(&ns[0], i),
                                 0, 0, fl_sizes[i] * fl->n, 0, NULL, NULL);
    if (rc == CL_SUCCESS) rc = clFinish(ocl_queue(fl->ocl));
    for (int s = 0; s < 2; s++)
        for (int i = 0; i < 8; i++) {
            fl_release(fl_set_mem(&fl->buf.st[s], i));
            if (rc == CL_SUCCESS) *fl_set_mem(&fl->buf.st[s], i) = *fl_set_mem(&ns[s], i);
            else fl_release(fl_set_mem(&ns[s], i));
        }
    if (rc != CL_SUCCESS) {
        fl->buf.cap = fl->n = 0;
        return fl_clfail(err, "allocating particle buffers", rc);
    }
    fl->buf.cur = 0;
    cl_mem *aux[] = {&fl->buf.key[0], &fl->buf.key[1], &fl->buf.val[0], &fl->buf.val[1], &fl->buf.keep_ins,
                     &fl->buf.nrm, &fl->buf.nl};
    size_t asz[] = {4, 4, 4, 4, 8, 16, 4 * FL_NL};
    for (int i = 0; i < 7 && rc == CL_SUCCESS; i++) {
        fl_release(aux[i]);
        *aux[i] = fl_buffer(fl, asz[i] * cap, &rc);
    }
    fl_release(&fl->buf.sxyz);
    if (rc == CL_SUCCESS) fl->buf.sxyz = fl_buffer(fl, 3 * sizeof(cl_float) * ((size_t)cap + FL_PAD), &rc);
    if (rc != CL_SUCCESS) return fl_clfail(err, "allocating sort buffers", rc);
    fl->buf.cap = cap;
    return 0;
}

/* Hash table of M = 2^k >= 2n keys (k in 10..22) and its cell-start array. */
static int fl_table(struct flame *fl, struct fx_err *err)
{
    int bits = 10;
    while (bits < 22 && (1 << bits) < 4 * fl->n) bits++;
    fl->grid.mask = (1u << bits) - 1u;
    fl->grid.passes = (bits + 7) / 8;
    int want = (1 << bits) + 1;
    if (want <= fl->buf.cs_cap) return 0;
    cl_int rc;
    fl_release(&fl->buf.cs);
    fl_release(&fl->buf.cnt);
    fl->buf.cs = fl_buffer(fl, sizeof(cl_uint) * (size_t)want, &rc);
    if (rc != CL_SUCCESS) return fl_clfail(err, "allocating the cell table", rc);
    fl->buf.cs_cap = want;
    return 0;
}

static int fl_upload_prm(struct flame *fl, struct fx_err *err)
{
    cl_int rc = clEnqueueWriteBuffer(ocl_queue(fl->ocl), fl->buf.prm, CL_TRUE, 0, sizeof fl->params.P, fl->params.P, 0,
                                     NULL, NULL);
    return rc == CL_SUCCESS ? 0 : fl_clfail(err, "uploading parameters", rc);
}

static int fl_zero_err(struct flame *fl, struct fx_err *err)
{
    cl_int zero[3] = {0, 0, 0};
    cl_int rc =
        clEnqueueWriteBuffer(ocl_queue(fl->ocl), fl->buf.errflag, CL_TRUE, 0, sizeof zero[0], zero, 0, NULL, NULL);
    return rc == CL_SUCCESS ? 0 : fl_clfail(err, "clearing the error flag", rc);
}

static void fl_unit(double v[3])
{
    double l = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int k = 0; k < 3; k++) v[k] = l > 0 ? v[k] / l : (k == 2);
}

/* ---- solids ------------------------------------------------------------------------------ */

struct fl_host {
    int n, cap;
    float *pos, *vel;
    uint32_t *flags, *id;
};

static int fl_host_push(struct fl_host *hp, const double r[3], float T, const double v[3], float F, uint32_t flags,
                        uint32_t id)
{
    if (hp->n == hp->cap) {
        int cap = hp->cap ? 2 * hp->cap : 256;
        float *p = realloc(hp->pos, 16 * (size_t)cap), *w = p ? realloc(hp->vel, 16 * (size_t)cap) : NULL;
        if (p) hp->pos = p;
        if (w) hp->vel = w;
        uint32_t *f = w ? realloc(hp->flags, 4 * (size_t)cap) : NULL, *i = f ? realloc(hp->id, 4 * (size_t)cap) : NULL;
        if (f) hp->flags = f;
        if (i) hp->id = i;
        if (!i) return -1;
        hp->cap = cap;
    }
    float *P = hp->pos + 4 * hp->n, *V = hp->vel + 4 * hp->n;
    for (int k = 0; k < 3; k++) {
        P[k] = (float)r[k];
        V[k] = (float)v[k];
    }
    P[3] = T;
    V[3] = F;
    hp->flags[hp->n] = flags;
    hp->id[hp->n++] = id;
    return 0;
}

static void fl_host_free(struct fl_host *hp)
{
    free(hp->pos);
    free(hp->vel);
    free(hp->flags);
    free(hp->id);
}

static uint32_t fl_flag_of(const struct flame *fl, uint32_t type, double T, double F)
{
    return type | ((T > fl->params.P[FP_TIGN] && F > fl->params.P[FP_FEPS]) ? FLAME_IS_FLAME : 0u);
}

/* A disc normal to `up` at spacing d, two layers (§9 #17). */
static int fl_add_source(struct flame *fl, struct fl_host *hp, const struct flame_source *src)
{
    double e1[3], e2[3], *u = fl->params.up, zero[3] = {0, 0, 0};
    const double *c = src->center;
    double R = src->radius, T = src->T_init, F = src->F_init, d = fl->params.d;
    double helper[3] = {fabs(u[0]) < 0.9 ? 1 : 0, fabs(u[0]) < 0.9 ? 0 : 1, 0};
    e1[0] = helper[1] * u[2] - helper[2] * u[1];
    e1[1] = helper[2] * u[0] - helper[0] * u[2];
    e1[2] = helper[0] * u[1] - helper[1] * u[0];
    fl_unit(e1);
    e2[0] = u[1] * e1[2] - u[2] * e1[1];
    e2[1] = u[2] * e1[0] - u[0] * e1[2];
    e2[2] = u[0] * e1[1] - u[1] * e1[0];
    int r = (int)floor(R / d + 1e-9);
    for (int layer = 0; layer < 2; layer++)
        for (int i = -r; i <= r; i++)
            for (int j = -r; j <= r; j++) {
                if ((i * i + j * j) * d * d > R * R * (1 + 1e-9)) continue;
                double x[3];
                for (int k = 0; k < 3; k++) x[k] = c[k] + d * (i * e1[k] + j * e2[k] - layer * u[k]);
                if (fl_host_push(hp, x, (float)T, zero, (float)F, fl_flag_of(fl, FLAME_SOURCE, T, F),
                                 fl->clock.next_id++))
                    return -1;
            }
    return 0;
}

/* Plate (one layer across the two largest extents) or filled box at spacing d. */
static int fl_add_obstacle(struct flame *fl, struct fl_host *hp, const struct flame_obstacle *ob, double t)
{
    const double *s = ob->size, *c = ob->pos, *v = ob->velocity;
    int cnt[3], thin = 0;
    for (int k = 0; k < 3; k++) {
        cnt[k] = 1 + (int)floor(s[k] / fl->params.d + 1e-9);
        if (s[k] < s[thin]) thin = k;
    }
    if (ob->shape == FLAME_PLATE) cnt[thin] = 1;
    for (int i = 0; i < cnt[0]; i++)
        for (int j = 0; j < cnt[1]; j++)
            for (int k = 0; k < cnt[2]; k++) {
                int idx[3] = {i, j, k};
                double x[3];
                for (int a = 0; a < 3; a++) x[a] = c[a] + v[a] * t + fl->params.d * (idx[a] - 0.5 * (cnt[a] - 1));
                if (fl_host_push(hp, x, (float)fl->params.t_amb, v, 0.0f, FLAME_OBSTACLE, fl->clock.next_id++))
                    return -1;
            }
    return 0;
}

static int fl_add_solids(struct flame *fl, struct fl_host *hp, const struct flame_config *c, struct fx_err *err)
{
    for (int i = 0; i < c->n_sources; i++)
        if (c->sources[i].enabled && fl_add_source(fl, hp, &c->sources[i]))
            return fx_fail(err, "internal", "", "out of memory");
    for (int i = 0; i < c->n_obstacles; i++)
        if (fl_add_obstacle(fl, hp, &c->obstacles[i], fl->clock.sim_seconds))
            return fx_fail(err, "internal", "", "out of memory");
    return 0;
}

/* Uploads host particles as the whole state (current set 0). */
static int fl_upload(struct flame *fl, int n, const float *pos, const float *vel, const uint32_t *flags,
                     const uint32_t *id, struct fx_err *err)
{
    if (n > fl->params.max_particles)
        return fx_fail(err, "limit", "max_particles", "%d particles exceed max_particles %d", n,
                       fl->params.max_particles);
    fl->n = 0;
    if (fl_reserve(fl, n, err)) return -1;
    fl->buf.cur = 0;
    fl->n = n;
    const void *src[4] = {pos, vel, flags, id};
    cl_int rc = CL_SUCCESS;
    for (int i = 0; i < 4 && rc == CL_SUCCESS && n > 0; i++)
        rc = clEnqueueWriteBuffer(ocl_queue(fl->ocl), *fl_set_mem(&fl->buf.st[0], i), CL_TRUE, 0, fl_sizes[i] * n,
                                  src[i], 0, NULL, NULL);
    if (rc != CL_SUCCESS) return fl_clfail(err, "uploading particles", rc);
    return fl_table(fl, err);
}

/* ---- one step on the device ---------------------------------------------------------- */

/* The radix sort of the hashed keys, FL_BLOCKS serial blocks a pass (CPU devices), and the
 * cell-start table from the sorted keys; *order: the sorted particle indices. */
static int fl_sort_blocks(struct flame *fl, cl_mem *order, struct fx_err *err)
{
    cl_int n = fl->n, nhist = 256 * FL_BLOCKS, m = (cl_int)fl->grid.mask + 1;
    int s = 0;
    for (int p = 0; p < fl->grid.passes; p++, s ^= 1) {
        cl_int shift = 8 * p;
        struct ocl_arg hh[] = {FL_MEM(fl->buf.key[s]), FL_INT(n), FL_INT(shift), FL_MEM(fl->buf.hist)};
        struct ocl_arg sc[] = {FL_MEM(fl->buf.hist), FL_INT(nhist)};
        struct ocl_arg sa[] = {FL_MEM(fl->buf.key[s]), FL_MEM(fl->buf.val[s]), FL_MEM(fl->buf.key[s ^ 1]),
                               FL_MEM(fl->buf.val[s ^ 1]), FL_INT(n), FL_INT(shift), FL_MEM(fl->buf.hist)};
        if (fl_args(fl, FL_K_RADIX_HIST, hh, 4, err) || fl_launch(fl, FL_K_RADIX_HIST, FL_BLOCKS, 1, err) ||
            fl_args(fl, FL_K_SCAN_SERIAL, sc, 2, err) || fl_launch(fl, FL_K_SCAN_SERIAL, 1, 1, err) ||
            fl_args(fl, FL_K_RADIX_SCATTER, sa, 7, err) || fl_launch(fl, FL_K_RADIX_SCATTER, FL_BLOCKS, 1, err))
            return -1;
    }
    struct ocl_arg ca[] = {FL_MEM(fl->buf.key[s]), FL_INT(n), FL_INT(m), FL_MEM(fl->buf.cs)};
    *order = fl->buf.val[s];
    return fl_args(fl, FL_K_CELL_START, ca, 4, err) || fl_launch(fl, FL_K_CELL_START, (size_t)n + 1, 0, err);
}

/* Exclusive scan on the device (wide passes): out[e] = the sum of in[k * stride + off] over
 * k < e, for e < len; the total into tot[tot_i]. */
static int fl_scan(struct flame *fl, cl_mem in, cl_int stride, cl_int off, cl_int len, cl_mem out, cl_int tot_i,
                   struct fx_err *err)
{
    cl_int tiles = (len + FL_SCAN_TILE - 1) / FL_SCAN_TILE;
    if (tiles > FL_SCAN_SUMS) return fx_fail(err, "internal", "", "flame: a scan of %d elements is too long", len);
    struct ocl_arg ra[] = {FL_MEM(in), FL_INT(stride), FL_INT(off), FL_INT(len), FL_MEM(fl->buf.sums)};
    struct ocl_arg ta[] = {FL_MEM(fl->buf.sums), FL_INT(tiles), FL_MEM(fl->buf.tot), FL_INT(tot_i)};
    struct ocl_arg da[] = {FL_MEM(in), FL_INT(stride), FL_INT(off), FL_INT(len), FL_MEM(fl->buf.sums), FL_MEM(out)};
    size_t wg = FL_SCAN_WG, global = (size_t)tiles * wg;
    return fl_args(fl, FL_K_SCAN_REDUCE, ra, 5, err) || fl_launch(fl, FL_K_SCAN_REDUCE, global, wg, err) ||
           fl_args(fl, FL_K_SCAN_TOP, ta, 4, err) || fl_launch(fl, FL_K_SCAN_TOP, wg, wg, err) ||
           fl_args(fl, FL_K_SCAN_DOWN, da, 6, err) || fl_launch(fl, FL_K_SCAN_DOWN, global, wg, err);
}

/* The counting sort of the hashed keys, one work item per particle (GPU devices; flame.cl's
 * wide passes): the same order as fl_sort_blocks, and the scan of the counts is the cell-start
 * table. Scratch: val[0] the particles' slots, val[1] the unranked runs; *order is key[1]. */
static int fl_sort_wide(struct flame *fl, cl_mem *order, struct fx_err *err)
{
    cl_int n = fl->n, len = (cl_int)fl->grid.mask + 2; /* cs[0 .. M] */
    cl_uint zero = 0;
    cl_int rc = CL_SUCCESS;
    if (!fl->buf.cnt) fl->buf.cnt = fl_buffer(fl, sizeof zero * (size_t)fl->buf.cs_cap, &rc);
    if (rc != CL_SUCCESS) return fl_clfail(err, "allocating the key counts", rc);
    rc = clEnqueueFillBuffer(ocl_queue(fl->ocl), fl->buf.cnt, &zero, sizeof zero, 0, sizeof zero * (size_t)len, 0, NULL,
                             NULL);
    if (rc != CL_SUCCESS) return fl_clfail(err, "clearing the key counts", rc);
    struct ocl_arg ka[] = {FL_MEM(fl->buf.key[0]), FL_INT(n), FL_MEM(fl->buf.cnt), FL_MEM(fl->buf.val[0])};
    struct ocl_arg sa[] = {FL_MEM(fl->buf.key[0]), FL_MEM(fl->buf.val[0]), FL_INT(n), FL_MEM(fl->buf.cs),
                           FL_MEM(fl->buf.val[1])};
    struct ocl_arg ra[] = {FL_MEM(fl->buf.key[0]), FL_MEM(fl->buf.val[1]), FL_INT(n), FL_MEM(fl->buf.cs),
                           FL_MEM(fl->buf.key[1])};
    *order = fl->buf.key[1];
    return fl_args(fl, FL_K_KEY_COUNT, ka, 4, err) || fl_launch(fl, FL_K_KEY_COUNT, (size_t)n, 0, err) ||
           fl_scan(fl, fl->buf.cnt, 1, 0, len, fl->buf.cs, 3, err) ||
           fl_args(fl, FL_K_KEY_SCATTER, sa, 5, err) || fl_launch(fl, FL_K_KEY_SCATTER, (size_t)n, 0, err) ||
           fl_args(fl, FL_K_KEY_RANK, ra, 5, err) || fl_launch(fl, FL_K_KEY_RANK, (size_t)n, 0, err);
}

/* Sorts the current set's particles by cell key into the other set (fl_hash, the sort,
 * fl_reorder) and builds the cell-start table. */
static int fl_sort(struct flame *fl, struct fx_err *err)
{
    struct fl_set *A = &fl->buf.st[fl->buf.cur], *B = &fl->buf.st[1 - fl->buf.cur];
    cl_int n = fl->n, stride = fl->buf.cap + FL_PAD;
    cl_uint mask = fl->grid.mask;
    cl_mem order;
    struct ocl_arg ha[] = {FL_MEM(A->pos), FL_MEM(fl->buf.key[0]), FL_MEM(fl->buf.val[0]), FL_INT(n), FL_INT(mask),
                          FL_MEM(fl->buf.prm)};
    if (fl_args(fl, FL_K_HASH, ha, 6, err) || fl_launch(fl, FL_K_HASH, (size_t)n, 0, err) ||
        (fl->wide ? fl_sort_wide(fl, &order, err) : fl_sort_blocks(fl, &order, err)))
        return -1;
    struct ocl_arg ra[] = {FL_MEM(order), FL_INT(n), FL_MEM(A->pos), FL_MEM(A->vel), FL_MEM(A->flags), FL_MEM(A->id),
                          FL_MEM(B->pos), FL_MEM(B->vel), FL_MEM(B->flags), FL_MEM(B->id), FL_MEM(fl->buf.sxyz),
                          FL_INT(stride)};
    return fl_args(fl, FL_K_REORDER, ra, 12, err) || fl_launch(fl, FL_K_REORDER, (size_t)n, 0, err);
}

/* Density pass on the sorted set B into A's derived arrays, then forces and integration
 * from B back into A (integrate = 0: the state is copied unchanged, for flame_eval). */
static int fl_gather(struct flame *fl, int integrate, int resample, struct fx_err *err)
{
    struct fl_set *A = &fl->buf.st[fl->buf.cur], *B = &fl->buf.st[1 - fl->buf.cur];
    cl_int n = fl->n, stride = fl->buf.cap + FL_PAD;
    cl_uint mask = fl->grid.mask;
    struct ocl_arg da[] = {FL_MEM(B->pos), FL_MEM(B->vel), FL_MEM(fl->buf.cs), FL_INT(mask), FL_INT(n),
                           FL_MEM(fl->buf.prm), FL_MEM(A->rho_p), FL_MEM(A->counts), FL_MEM(fl->buf.nl),
                           FL_MEM(fl->buf.sxyz), FL_INT(stride)};
    struct ocl_arg fa[] = {FL_MEM(B->pos), FL_MEM(B->vel), FL_MEM(B->flags), FL_MEM(B->id), FL_MEM(fl->buf.cs),
                           FL_INT(mask), FL_INT(n), FL_MEM(fl->buf.prm), FL_MEM(A->rho_p), FL_MEM(A->counts),
                           FL_MEM(fl->buf.nl), FL_MEM(A->pos), FL_MEM(A->vel), FL_MEM(A->flags), FL_MEM(A->id),
                           FL_MEM(A->force), FL_MEM(A->dTdF), FL_INT(integrate), FL_INT(resample),
                           FL_MEM(fl->buf.keep_ins), FL_MEM(fl->buf.nrm), FL_MEM(fl->buf.errflag)};
    if (fl_args(fl, FL_K_DENSITY, da, 11, err) || fl_launch(fl, FL_K_DENSITY, (size_t)n, 0, err) ||
        fl_args(fl, FL_K_FORCES, fa, 22, err) || fl_launch(fl, FL_K_FORCES, (size_t)n, 0, err))
        return -1;
    return 0;
}

/* Reads the error flag once the queue is done. The queue is finished even when the enqueue
 * failed: no read into the caller's variable may outlive the call. */
static int fl_read_errflag(struct flame *fl, cl_int *errflag, struct fx_err *err)
{
    cl_int rc =
        clEnqueueReadBuffer(ocl_queue(fl->ocl), fl->buf.errflag, CL_FALSE, 0, sizeof *errflag, errflag, 0, NULL, NULL);
    if (rc != CL_SUCCESS) {
        fl_finish(fl, NULL);
        return fl_clfail(err, "reading the error flag", rc);
    }
    return fl_finish(fl, err);
}

static int fl_check(const struct flame *fl, cl_int errflag, struct fx_err *err)
{
    if (errflag & FL_ERR_NAN)
        return fx_fail(err, "internal", "", "flame: non-finite particle state (NaN/Inf) after step %llu",
                       (unsigned long long)fl->clock.steps);
    if (errflag & FL_ERR_SPEED)
        return fx_fail(err, "internal", "", "flame: runaway particle speed above %g m/s after step %llu", FLAME_VMAX,
                       (unsigned long long)fl->clock.steps);
    return 0;
}

/* The compaction's launches in FL_BLOCKS serial blocks (CPU devices); tail: fl_compact's
 * arguments from id_base on. */
static int fl_compact_blocks(struct flame *fl, cl_uint cap, const struct ocl_arg *tail, struct fx_err *err)
{
    cl_int n = fl->n, nb = FL_BLOCKS;
    struct ocl_arg ca[] = {FL_MEM(fl->buf.keep_ins), FL_INT(n), FL_MEM(fl->buf.bsum)};
    struct ocl_arg sa[] = {FL_MEM(fl->buf.bsum), FL_INT(nb), FL_INT(cap), FL_MEM(fl->buf.tot)};
    struct ocl_arg xa[23] = {FL_MEM(fl->buf.keep_ins), FL_INT(n), FL_MEM(fl->buf.bsum), FL_MEM(fl->buf.tot)};
    memcpy(xa + 4, tail, 19 * sizeof *tail);
    return fl_args(fl, FL_K_RESAMPLE_COUNT, ca, 3, err) || fl_launch(fl, FL_K_RESAMPLE_COUNT, FL_BLOCKS, 1, err) ||
           fl_args(fl, FL_K_SCAN_BLOCKS, sa, 4, err) || fl_launch(fl, FL_K_SCAN_BLOCKS, 1, 1, err) ||
           fl_args(fl, FL_K_COMPACT, xa, 23, err) || fl_launch(fl, FL_K_COMPACT, FL_BLOCKS, 1, err);
}

/* The compaction one work item per particle (GPU devices): the keep and insert flags scanned
 * into key[0] and key[1] (free once the step's sort is done). */
static int fl_compact_wide(struct flame *fl, cl_uint cap, const struct ocl_arg *tail, struct fx_err *err)
{
    cl_int n = fl->n;
    struct ocl_arg xa[25] = {FL_MEM(fl->buf.keep_ins), FL_INT(n), FL_MEM(fl->buf.key[0]), FL_MEM(fl->buf.key[1]),
                             FL_MEM(fl->buf.tot), FL_INT(cap)};
    memcpy(xa + 6, tail, 19 * sizeof *tail);
    return fl_scan(fl, fl->buf.keep_ins, 2, 0, n, fl->buf.key[0], 0, err) ||
           fl_scan(fl, fl->buf.keep_ins, 2, 1, n, fl->buf.key[1], 1, err) ||
           fl_args(fl, FL_K_COMPACT_WIDE, xa, 25, err) || fl_launch(fl, FL_K_COMPACT_WIDE, (size_t)n, 0, err);
}

/* Birth and death (§2.12): count, scan, compact A into B, and the totals read without
 * waiting; fl_resample_end makes B current. */
static int fl_resample_begin(struct flame *fl, struct fx_err *err)
{
    struct fl_set *A = &fl->buf.st[fl->buf.cur], *B = &fl->buf.st[1 - fl->buf.cur];
    cl_uint cap = (cl_uint)(fl->buf.cap < fl->params.max_particles ? fl->buf.cap : fl->params.max_particles),
            idb = fl->clock.next_id;
    struct ocl_arg tail[19] = {FL_INT(idb), FL_MEM(fl->buf.prm), FL_MEM(fl->buf.nrm), FL_MEM(A->pos), FL_MEM(A->vel),
                               FL_MEM(A->flags), FL_MEM(A->id), FL_MEM(A->rho_p), FL_MEM(A->counts), FL_MEM(A->force),
                               FL_MEM(A->dTdF), FL_MEM(B->pos), FL_MEM(B->vel), FL_MEM(B->flags), FL_MEM(B->id),
                               FL_MEM(B->rho_p), FL_MEM(B->counts), FL_MEM(B->force), FL_MEM(B->dTdF)};
    if (fl->wide ? fl_compact_wide(fl, cap, tail, err) : fl_compact_blocks(fl, cap, tail, err)) return -1;
    cl_command_queue q = ocl_queue(fl->ocl);
    cl_int rc = clEnqueueReadBuffer(q, fl->buf.errflag, CL_FALSE, 0, sizeof fl->rs.err, &fl->rs.err, 0, NULL, NULL);
    if (rc == CL_SUCCESS)
        rc = clEnqueueReadBuffer(q, fl->buf.tot, CL_FALSE, 0, sizeof fl->rs.tot, fl->rs.tot, 0, NULL, NULL);
    if (rc != CL_SUCCESS) {
        fl_finish(fl, NULL); /* no read into fl may outlive the call */
        return fl_clfail(err, "reading totals", rc);
    }
    fl->rs.pending = 1;
    return 0;
}

/* Waits for fl_resample_begin's totals (survivors, insertions, new n) and applies them. */
static int fl_resample_end(struct flame *fl, struct fx_err *err)
{
    fl->rs.pending = 0;
    if (fl_finish(fl, err) || fl_check(fl, fl->rs.err, err)) return -1;
    fl->buf.cur ^= 1;
    fl->n = (int)fl->rs.tot[2];
    fl->clock.next_id += fl->rs.tot[1];
    if (fl->rs.tot[0] + fl->rs.tot[1] >= (cl_uint)fl->params.max_particles)
        return fx_fail(err, "internal", "", "flame: particle count reached max_particles %d (runaway) at step %llu",
                       fl->params.max_particles, (unsigned long long)fl->clock.steps);
    return fl_table(fl, err);
}

/* One substep, enqueued: the device may still be working on it when this returns, and a
 * resampling step's totals wait for fl_step_end. */
static int fl_step_begin(struct flame *fl, struct fx_err *err)
{
    int resample = fl->clock.steps % (uint64_t)fl->params.interval == 0;
    if (resample) {
        int want = 2 * fl->n < fl->params.max_particles ? 2 * fl->n : fl->params.max_particles;
        if (fl_reserve(fl, want, err)) return -1;
    }
    if (fl->n > 0 && (fl_sort(fl, err) || fl_gather(fl, 1, resample, err))) return -1;
    if (resample && fl->n > 0 && fl_resample_begin(fl, err)) return -1;
    fl->clock.steps++;
    fl->clock.sim_seconds += fl->params.dt;
    return 0;
}

/* Completes the substep fl_step_begin enqueued (the particle count after a resampling step
 * is known only then); nothing to do for the others. */
static int fl_step_end(struct flame *fl, struct fx_err *err) { return fl->rs.pending ? fl_resample_end(fl, err) : 0; }

static int fl_step_once(struct flame *fl, struct fx_err *err) { return fl_step_begin(fl, err) || fl_step_end(fl, err); }

/* ---- public API ---------------------------------------------------------------------------- */

int flame_particles_alloc(struct flame_particles *p, int n)
{
    memset(p, 0, sizeof *p);
    size_t m = n > 0 ? (size_t)n : 1;
    p->n = n;
    p->pos = calloc(4 * m, sizeof(float));
    p->vel = calloc(4 * m, sizeof(float));
    p->flags = calloc(m, sizeof(uint32_t));
    p->id = calloc(m, sizeof(uint32_t));
    p->rho = calloc(m, sizeof(float));
    p->pressure = calloc(m, sizeof(float));
    p->force = calloc(4 * m, sizeof(float));
    p->dT = calloc(m, sizeof(float));
    p->dF = calloc(m, sizeof(float));
    p->nbr = calloc(m, sizeof(uint16_t));
    p->flame_nbr = calloc(m, sizeof(uint16_t));
    if (p->pos && p->vel && p->flags && p->id && p->rho && p->pressure && p->force && p->dT && p->dF && p->nbr &&
        p->flame_nbr)
        return 0;
    flame_particles_free(p);
    return -1;
}

void flame_particles_free(struct flame_particles *p)
{
    void *a[] = {p->pos, p->vel, p->flags, p->id, p->rho, p->pressure, p->force, p->dT, p->dF, p->nbr, p->flame_nbr};
    for (size_t i = 0; i < sizeof a / sizeof a[0]; i++) free(a[i]);
    memset(p, 0, sizeof *p);
}

static void fl_read_params(struct flame *fl, const struct flame_config *c)
{
    fl->params.dt = c->dt;
    fl->params.t_amb = c->T_amb;
    fl->params.interval = c->resample_interval;
    flame_params_up(c, fl->params.up);
    flame_params_pack(c, fl->params.P);
}

/* Replaces the solids (sources, obstacles) by those of c, keeping the gas. */
static int fl_rebuild_solids(struct flame *fl, const struct flame_config *c, struct fx_err *err)
{
    struct flame_particles cur;
    struct fl_host hp = {0};
    if (flame_read(fl, &cur, err)) return -1;
    int rc = 0;
    for (int i = 0; i < cur.n && !rc; i++) {
        if ((cur.flags[i] & FLAME_TYPE_MASK) != FLAME_GAS) continue;
        double r[3] = {cur.pos[4 * i], cur.pos[4 * i + 1], cur.pos[4 * i + 2]};
        double v[3] = {cur.vel[4 * i], cur.vel[4 * i + 1], cur.vel[4 * i + 2]};
        rc = fl_host_push(&hp, r, cur.pos[4 * i + 3], v, cur.vel[4 * i + 3], cur.flags[i], cur.id[i]);
    }
    flame_particles_free(&cur);
    if (rc) fx_fail(err, "internal", "", "out of memory");
    if (!rc) rc = fl_add_solids(fl, &hp, c, err);
    if (!rc) rc = fl_upload(fl, hp.n, hp.pos, hp.vel, hp.flags, hp.id, err);
    fl_host_free(&hp);
    return rc;
}

/* The solids change with sources, obstacles and T_amb (an obstacle's temperature). */
static bool fl_solids_same(const struct flame_config *a, const struct flame_config *b)
{
    static const size_t at[] = {offsetof(struct flame_config, sources), offsetof(struct flame_config, obstacles),
                                offsetof(struct flame_config, T_amb)};
    for (size_t i = 0; i < sizeof at / sizeof at[0]; i++)
        if (!params_same(params_at(flame_params, at[i]), a, b)) return false;
    return true;
}

int flame_set(struct flame *fl, const struct flame_config *c, struct fx_err *err)
{
    bool solids_changed = !fl->params.configured || !fl_solids_same(&fl->params.cfg, c);
    fl->params.cfg = *c;
    fl->params.configured = true;
    fl_read_params(fl, c);
    if (fl_upload_prm(fl, err)) return -1;
    return solids_changed && fl->buf.cap ? fl_rebuild_solids(fl, c, err) : 0;
}

/* Steps, simulated time and ids back to a fresh start. */
static void fl_clock_reset(struct flame *fl)
{
    fl->clock.steps = 0;
    fl->clock.sim_seconds = 0;
    fl->clock.next_id = 0;
}

/* The initial state: the scene's solids only (§2.13). */
static int fl_restart(struct flame *fl, struct fx_err *err)
{
    struct fl_host hp = {0};
    fl_clock_reset(fl);
    int rc = fl_finish(fl, err) || fl_zero_err(fl, err) || fl_add_solids(fl, &hp, &fl->params.cfg, err) ||
             fl_upload(fl, hp.n, hp.pos, hp.vel, hp.flags, hp.id, err);
    fl_host_free(&hp);
    return rc ? -1 : 0;
}

static int fl_create_objects(struct flame *fl, struct fx_err *err)
{
    cl_int rc = CL_SUCCESS;
    /* FL_ROWS: the rows of cells a sphere of radius h reaches at most (fl_density keeps their
     * ranges): per axis, the cells its extent 2h (widened by the kernel's 1.0001) can touch */
    int axis = (int)floor(2.0002 * FL_CELLS_PER_H) + 2;
    char opts[sizeof FL_BUILD_OPTS + 32];
    snprintf(opts, sizeof opts, "%s -DFL_ROWS=%d", FL_BUILD_OPTS, axis * axis);
    cl_program prog = ocl_program(fl->ocl, FL_KERNEL_FILE, opts, err);
    if (!prog) return -1;
    for (int k = 0; k < FL_KERNEL_COUNT && rc == CL_SUCCESS; k++)
        fl->k[k] = clCreateKernel(prog, fl_kernel_names[k], &rc);
    if (rc != CL_SUCCESS) return fl_clfail(err, "clCreateKernel", rc);
    struct { cl_mem *m; size_t bytes; } fixed[] = {
        {&fl->buf.hist, 4 * 256 * FL_BLOCKS}, {&fl->buf.bsum, 8 * FL_BLOCKS}, {&fl->buf.tot, 16},
        {&fl->buf.errflag, 16}, {&fl->buf.prm, sizeof fl->params.P}, {&fl->buf.sums, 4 * FL_SCAN_SUMS}};
    for (size_t i = 0; i < sizeof fixed / sizeof fixed[0] && rc == CL_SUCCESS; i++)
        *fixed[i].m = fl_buffer(fl, fixed[i].bytes, &rc);
    return rc == CL_SUCCESS ? 0 : fl_clfail(err, "clCreateBuffer", rc);
}

struct flame *flame_new(struct ocl *ocl, const struct flame_config *c, struct fx_err *err)
{
    struct flame *fl = calloc(1, sizeof *fl);
    if (!fl) {
        fx_fail(err, "internal", "", "out of memory");
        return NULL;
    }
    fl->ocl = ocl;
    fl->wide = !ocl_is_cpu(ocl);
    fl->params.h = c->h;
    fl->params.d = c->particle_diameter * fl->params.h;
    fl->params.max_particles = c->max_particles;
    if (fl_create_objects(fl, err) || flame_set(fl, c, err) || fl_restart(fl, err)) {
        flame_free(fl);
        return NULL;
    }
    return fl;
}

void flame_free(struct flame *fl)
{
    if (!fl) return;
    if (fl->ocl) clFinish(ocl_queue(fl->ocl));
    fl_flush_events(fl);
    for (int s = 0; s < 2; s++)
        for (int i = 0; i < 8; i++) fl_release(fl_set_mem(&fl->buf.st[s], i));
    cl_mem *m[] = {&fl->buf.key[0], &fl->buf.key[1], &fl->buf.val[0], &fl->buf.val[1], &fl->buf.hist,
                   &fl->buf.cs, &fl->buf.cnt, &fl->buf.sums, &fl->buf.keep_ins, &fl->buf.nrm, &fl->buf.nl,
                   &fl->buf.sxyz, &fl->buf.bsum, &fl->buf.tot, &fl->buf.errflag, &fl->buf.prm};
    for (size_t i = 0; i < sizeof m / sizeof m[0]; i++) fl_release(m[i]);
    for (int k = 0; k < FL_KERNEL_COUNT; k++)
        if (fl->k[k]) clReleaseKernel(fl->k[k]);
    free(fl);
}

int flame_load(struct flame *fl, const struct flame_particles *p, struct fx_err *err)
{
    if (fl_finish(fl, err) || fl_zero_err(fl, err)) return -1;
    fl_clock_reset(fl);
    for (int i = 0; i < p->n; i++)
        if (p->id[i] >= fl->clock.next_id) fl->clock.next_id = p->id[i] + 1;
    return fl_upload(fl, p->n, p->pos, p->vel, p->flags, p->id, err);
}

int flame_eval(struct flame *fl, struct fx_err *err)
{
    if (fl->n > 0 && (fl_sort(fl, err) || fl_gather(fl, 0, 0, err))) return -1;
    return fl_finish(fl, err);
}

int flame_run(struct flame *fl, int steps, struct fx_err *err)
{
    for (int s = 0; s < steps; s++)
        if (fl_step_once(fl, err)) return -1;
    cl_int ef = 0;
    if (fl_read_errflag(fl, &ef, err)) return -1;
    return fl_check(fl, ef, err);
}

int flame_read(struct flame *fl, struct flame_particles *out, struct fx_err *err)
{
    int n = fl->n;
    if (flame_particles_alloc(out, n)) return fx_fail(err, "internal", "", "out of memory for %d particles", n);
    float *rho_p = malloc(8 * (size_t)(n ? n : 1)), *dtdf = malloc(8 * (size_t)(n ? n : 1));
    uint32_t *cnt = malloc(4 * (size_t)(n ? n : 1));
    struct fl_set *S = &fl->buf.st[fl->buf.cur];
    void *dst[8] = {out->pos, out->vel, out->flags, out->id, rho_p, cnt, out->force, dtdf};
    cl_int rc = rho_p && dtdf && cnt ? CL_SUCCESS : CL_OUT_OF_HOST_MEMORY;
    for (int i = 0; i < 8 && rc == CL_SUCCESS && n > 0; i++)
        rc = clEnqueueReadBuffer(ocl_queue(fl->ocl), *fl_set_mem(S, i), CL_FALSE, 0, fl_sizes[i] * n, dst[i], 0, NULL,
                                 NULL);
    cl_int fin = clFinish(ocl_queue(fl->ocl)); /* also after a failed enqueue: the reads target rho_p, dtdf, cnt */
    if (rc == CL_SUCCESS) rc = fin;
    for (int i = 0; i < n && rc == CL_SUCCESS; i++) {
        out->rho[i] = rho_p[2 * i];
        out->pressure[i] = rho_p[2 * i + 1];
        out->dT[i] = dtdf[2 * i];
        out->dF[i] = dtdf[2 * i + 1];
        out->nbr[i] = (uint16_t)(cnt[i] & 0xffffu);
        out->flame_nbr[i] = (uint16_t)(cnt[i] >> 16);
    }
    free(rho_p);
    free(dtdf);
    free(cnt);
    fl_flush_events(fl);
    if (rc != CL_SUCCESS) {
        flame_particles_free(out);
        return fl_clfail(err, "reading particles", rc);
    }
    return 0;
}

int flame_count(const struct flame *fl) { return fl->n; }
void flame_set_wide(struct flame *fl, bool wide) { fl->wide = wide; }
uint64_t flame_steps(const struct flame *fl) { return fl->clock.steps; }
double flame_sim_seconds(const struct flame *fl) { return fl->clock.sim_seconds; }

/* ---- substeps for the effect (flame_effect.c) ------------------------------------------------ */

int flame_substep(struct flame *fl, struct fx_err *err) { return fl_step_once(fl, err); }
int flame_substep_begin(struct flame *fl, struct fx_err *err) { return fl_step_begin(fl, err); }
int flame_substep_end(struct flame *fl, struct fx_err *err) { return fl_step_end(fl, err); }
bool flame_substep_syncs(const struct flame *fl) { return fl->clock.steps % (uint64_t)fl->params.interval == 0; }
int flame_finish(struct flame *fl, struct fx_err *err) { return fl_finish(fl, err); }
int flame_reset(struct flame *fl, struct fx_err *err) { return fl_restart(fl, err); }

int flame_read_frame(struct flame *fl, float *pos, float *vel, uint32_t *flags, uint32_t *id, struct fx_err *err)
{
    int n = fl->n;
    struct fl_set *S = &fl->buf.st[fl->buf.cur];
    void *dst[4] = {pos, vel, flags, id}; /* struct fl_set's first four */
    cl_int ef = 0, rc = CL_SUCCESS;
    for (int i = 0; i < 4 && rc == CL_SUCCESS && n > 0; i++)
        rc = clEnqueueReadBuffer(ocl_queue(fl->ocl), *fl_set_mem(S, i), CL_FALSE, 0, fl_sizes[i] * n, dst[i], 0, NULL,
                                 NULL);
    if (rc != CL_SUCCESS) {
        fl_finish(fl, NULL); /* the reads already queued complete before the buffers may change */
        return fl_clfail(err, "reading the frame", rc);
    }
    return fl_read_errflag(fl, &ef, err) || fl_check(fl, ef, err) ? -1 : n;
}

