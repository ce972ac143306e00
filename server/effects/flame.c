/* flame.c — effect `flame` (seed 002, Mabuchi 2012; spec: digest 002), host side.
 *
 * Owns the parameter table, the device buffers and the order of kernels/flame.cl launches;
 * no per-particle loop runs on the host except building the solids of a scene. State lives
 * in two buffer sets (st[0], st[1]): a substep sorts the current set into the other one,
 * gathers density into the current set's derived arrays and integrates back into the
 * current set, so after every step one set holds the state and its derived fields in the
 * same order. Resampling (every resample_interval steps, on the steps whose 0-based index is
 * a multiple of it; digest §2.12) compacts into the other set. The host reads back only
 * the resampling totals (3 ints), the error flag, and once per frame the particles.
 *
 * Digest fixes applied: §9 #1 pressure sign, #3 symmetric form option, #4 stabilised
 * diffusion (also capping viscosity, §2.15), #6 derived mass, #7 d = h/2, #8 insertion
 * threshold, #9 outward insertion, #10 inherited velocity, #11 deletion rule, #12 fuel_eps and
 * F >= 0, #13 optional cooling, #14 g = 0, #15 wind (the uniform acceleration and §2.14's drag toward
 * a wind velocity), #16 kinematic obstacles, #17 disc sources, #20 up vector. */
#include "flame.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../clock.h"
#include "../ocl.h"
#include "fxs_frame.h"
#include "fxs_particles.h"

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
#ifndef FL_CELLS_PER_H
/* Cells of edge 2h: a particle sets up 4 rows, not 9 (cells of h) or 25 (h/2). The row set-up,
 * not the candidates, is most of fl_density's time on the sparse default flame (~8 neighbours),
 * so cells of 2h make the density pass about 1.5x faster there, and the dense lattice blocks
 * of bench_flame faster too; cells of 2.5h or 3h gain nothing more (docs/performance-log.md). */
#define FL_CELLS_PER_H 0.5
#endif
#ifndef FL_XCELLS
#define FL_XCELLS 4
#endif
/* On a GPU device a frame of 2 x 4096 particles or more is encoded as up to this many blocks
 * on as many of the host's cores (PROTOCOL.md §7.5.8), which are free during the device's
 * work: a 50k-particle frame encodes nearly 4x faster as 8 blocks, for 1-2% more bytes. On
 * a CPU device (PoCL) one thread: the other cores are the ones PoCL's workers step on, so a
 * second encoding thread slows the simulation more than it speeds the encoding. */
#define FL_ENC_THREADS_MAX 8
#define FL_FRAME_MARGIN_MS 1.0 /* frame period kept free beyond the substeps and the frame's encoding */
#define FL_PAD 8           /* spare elements after each sorted x, y, z array: fl_density reads 8 at a time */
#define FL_BLOCKS 16       /* work items of the serial-per-block sort/scan/compaction kernels */
#define FL_MAX_EVENTS 1024 /* profiling events kept until the next sync */
#define FL_VMAX 200.0      /* |v| beyond this (m/s) is a runaway */

/* ---- parameters -------------------------------------------------------------------- */

static const char *const fl_shape_names[] = {"plate", "box", NULL};
static const char *const fl_pform_names[] = {"difference", "symmetric", NULL};
static const char *const fl_diff_names[] = {"stabilized", "literal", NULL};

#define FL_F(nm, dflt, lo, hi, un, what, fl, ...) \
    {.name = nm, .type = PARAM_FLOAT, .def = dflt, .min = lo, .max = hi, .unit = un, .doc = what, .flags = fl, __VA_ARGS__}
#define FL_I(nm, dflt, lo, hi, un, what, fl, ...) \
    {.name = nm, .type = PARAM_INT, .def = dflt, .min = lo, .max = hi, .unit = un, .doc = what, .flags = fl, __VA_ARGS__}

static const struct param_def fl_source_fields[] = {
    {.name = "center", .type = PARAM_VEC3, .def = "[0,0,0]", .min = -100, .max = 100, .unit = "m",
     .doc = "centre of the burning disc (its top layer)"},
    FL_F("radius", "0.015", 0.001, 1, "m", "disc radius: a wider disc feeds a wider fire (solid particles at spacing d, 2 layers across `up`)", 0),
    FL_F("T_init", "2000", 1000, 3000, "K", "temperature the burning solid holds (Mabuchi 2012, Table 3.1)", 0),
    FL_F("F_init", "100", 0, 300, "", "fuel the burning solid holds: more fuel, a taller and brighter flame (the thesis uses 80-120)", 0),
    {.name = "enabled", .type = PARAM_BOOL, .def = "true", .unit = "", .doc = "the source burns (off: as if removed)"},
    {0},
};

static const struct param_def fl_obstacle_fields[] = {
    {.name = "shape", .type = PARAM_ENUM, .def = "\"plate\"", .choices = fl_shape_names, .unit = "",
     .doc = "plate: one layer across the two largest extents of size; box: filled block"},
    {.name = "size", .type = PARAM_VEC3, .def = "[0.04,0,0.04]", .min = 0, .max = 10, .unit = "m",
     .doc = "extents along x, y, z"},
    {.name = "pos", .type = PARAM_VEC3, .def = "[0,0.05,0.03]", .min = -100, .max = 100, .unit = "m",
     .doc = "centre at time 0 (after a reset)"},
    {.name = "velocity", .type = PARAM_VEC3, .def = "[0,-0.2,0]", .min = -20, .max = 20, .unit = "m/s",
     .doc = "the solid moves at this velocity from pos: r(t) = pos + velocity t"},
    {0},
};

/* Default scene: the thesis's 3 cm disc (digest §2.13, ch.7's real flame) on a 3.6 cm
 * non-burning base plate 4 mm under it, with h = 3.5 mm (a third of Table 3.1's, so ~10k particles
 * resolve the thesis-size flame) at dt 3 ms (the thesis's 1 ms would need 10 M particle-steps/s
 * for 10k particles in real time). Finer particles on a thesis-size source, not a bigger source,
 * give a flame several times as tall as wide (tests/bench/bench_flame_shape.c measures it,
 * tests/unit/test_flame_shape.c holds it). Without the plate, gas heated by the disc's lower
 * layer stays under it (about a tenth of the burning gas below the source plane, as the
 * thesis's free-floating source has no ground); the plate is an obstacle (digest §2.13), so no
 * new physics. */
const struct param_def flame_params[] = {
    {.name = "sources", .group = "sources", .type = PARAM_OBJECT_LIST, .def = "[{\"radius\":0.015}]", .max_len = 16,
     .fields = fl_source_fields, .unit = "", .doc = "burning solids: discs that hold fuel and heat and feed the flame"},
    {.name = "obstacles", .group = "sources", .type = PARAM_OBJECT_LIST, .max_len = 16,
     .def = "[{\"shape\":\"plate\",\"size\":[0.036,0.036,0],\"pos\":[0,0,-0.004],\"velocity\":[0,0,0]}]", .fields = fl_obstacle_fields,
     .unit = "", .doc = "solids that do not burn (ambient temperature, no fuel): a plate under the fire, a wall, a moving paddle"},
    {.name = "wind_accel", .group = "forces", .type = PARAM_VEC3, .def = "[0,0,0]", .min = -50, .max = 50, .unit = "m/s^2",
     .doc = "a uniform acceleration of the gas; across `up` the air's drag (wind_drag) limits the drift it gives "
            "to wind_accel / wind_drag"},
    /* The wind as the digest's optional drag model (§2.14 [P], f = rho k_drag (v_wind - v)): gas
     * takes up the velocity of the ambient air the thesis does not simulate, at rate wind_drag,
     * across `up` only, since buoyancy already is the net vertical force (§2.6 [P]: the air's
     * resistance to the rise is in k_buo, and §8 B4's exact buoyancy step stays exact; drag on
     * the vertical too made the flame far shorter). A uniform wind_accel leans a flame whose
     * burning gas lives ~40 ms and rises at ~2.5 m/s little (10 m/s^2: a tenth of its height,
     * a quarter as a force density like buoyancy, rho_rest a / rho); a wind *velocity* leans it
     * like a real flame, by about the ratio of wind to rise speed (2 m/s: about a third of its
     * height; test_flame_shape.c). The drag also resists the gas's sideways spreading in still
     * air, so the calm flame is narrower; 25/s leans it well and keeps the default scene at ~10k
     * particles (other rates: docs/performance-log.md). */
    {.name = "wind_velocity", .group = "forces", .type = PARAM_VEC3, .def = "[0,0,0]", .min = -20, .max = 20, .unit = "m/s",
     .doc = "velocity of the surrounding air: the flame leans downwind (the gas takes it up at wind_drag); its "
            "part along `up` is ignored"},
    FL_F("wind_drag", "25", 0, 200, "1/s", "how quickly the gas takes up the air's velocity across `up`, "
         "f = rho k (wind_velocity - v); 0: no air, the gas spreads freely", 0, .group = "forces"),
    FL_F("k_buo", "0.01", 0, 0.05, "N/(m^3 K)", "buoyancy, the force k_buo (T - T_amb) per volume along `up`: higher, a taller and faster flame (Mabuchi 2012 eq. 3.16)", 0, .group = "forces"),
    {.name = "up", .group = "forces", .type = PARAM_VEC3, .def = "[0,0,1]", .min = -1, .max = 1, .unit = "direction",
     .doc = "which way is up (normalised): buoyancy pushes along it and the source discs lie across it", .flags = PARAM_NONZERO},
    FL_F("k_stiff", "10", 0, 100, "m^2/s^2", "pressure stiffness: how strongly the gas resists compression, p = k (rho - rho_rest) (eq. 3.11)", 0, .group = "forces"),
    FL_F("k_viscosity", "0.005", 0, 0.05, "N s/m^2", "viscosity: higher smooths the flow, lower lets it swirl (eq. 3.13)", 0, .group = "forces"),
    FL_F("rho_rest", "1", 0.1, 10, "kg/m^3", "rest density of the gas; pressure p = k (rho - rho_rest), never below 0", 0, .group = "forces"),
    /* Both forms clamp eq 3.11's p at 0. Unclamped, the difference form (p_j - p_i) pushes the
     * density-deficient free boundary of a gas with no air around it outward (digest §2.5) far
     * faster than buoyancy lifts it: on the default scene no burning gas is left after 2.5 s
     * (1.2k particles), against a flame rising 7.6 cm (centroid at 2.5-3 s) with the clamp
     * (PROTOCOL.md §11.2). Default symmetric (Mueller's form, digest §9 #3): every figure of the
     * default scene and every group D behaviour is measured with it. */
    {.name = "pressure_form", .group = "forces", .type = PARAM_ENUM, .def = "\"symmetric\"", .choices = fl_pform_names, .unit = "",
     .doc = "how pressure pushes particles apart: symmetric, Mueller 2003's -(p_i+p_j)/2 (the default); difference, "
            "the thesis's eq. 3.12 with its sign corrected; both with p >= 0"},
    FL_F("T_amb", "300", 250, 400, "K", "temperature of the surrounding air; new particles start at it", 0, .group = "combustion"),
    FL_F("T_ign", "1000", 500, 2000, "K", "ignition temperature: gas above it that has fuel burns", 0, .group = "combustion"),
    FL_F("k_rs", "0.01", 0, 0.05, "", "reaction rate S = k_rs T F: how fast burning gas uses its fuel (eq. 3.17)", 0, .group = "combustion"),
    FL_F("k_cf", "5", 0, 20, "", "fuel used per unit of reaction, dF/dt = -k_cf S (eq. 3.18)", 0, .group = "combustion"),
    FL_F("k_pt", "500", 0, 2000, "", "heat released per unit of reaction, dT/dt = k_pt S: higher, a hotter flame (eq. 3.19)", 0, .group = "combustion"),
    FL_F("k_h", "0.02", 0, 0.1, "m^2/s", "heat diffusion: how quickly heat spreads to neighbours (eq. 3.20)", 0, .group = "diffusion"),
    FL_F("k_f", "0.001", 0, 0.01, "m^2/(s K)", "fuel diffusion, faster in hot gas (eq. 3.21)", 0, .group = "diffusion"),
    {.name = "diffusion_mode", .group = "diffusion", .type = PARAM_ENUM, .def = "\"stabilized\"", .choices = fl_diff_names, .unit = "",
     .doc = "stabilized: each particle's diffusion (and viscosity) weights capped at omega_max, so a step never "
            "overshoots; literal: the thesis's eqs. 3.13, 3.20 and 3.21 as printed (unstable at its k_f)"},
    FL_F("omega_max", "0.5", 0.05, 1, "", "stabilized diffusion: the cap on a particle's summed diffusion weights per step", 0, .group = "diffusion"),
    FL_F("k_cool", "0", 0, 50, "1/s", "cooling toward the air's temperature, not in the thesis: higher, a shorter flame", 0, .group = "combustion"),
    FL_F("fuel_eps", "0.001", 0, 1, "", "fuel below this no longer burns", 0, .group = "combustion"),
    FL_I("resample_interval", "5", 1, 20, "steps", "steps between the passes that add particles where the flame thins and remove spent ones", 0, .group = "numerics"),
    FL_I("insert_nbr_threshold", "24", 4, 60, "", "a burning particle with fewer neighbours gets a new one beside it: lower, fewer particles",
         0, .group = "numerics"),
    FL_F("h", "0.0035", 0.002, 0.05, "m", "smoothing length, the radius each particle interacts over: smaller, finer detail and more particles "
         "(the thesis's Table 3.1: 0.01125)",
         PARAM_RESTART, .group = "numerics"),
    FL_F("particle_diameter", "0.5", 0.25, 0.75, "h", "spacing d of the solids' particles and of inserted particles", PARAM_RESTART, .group = "numerics"),
    FL_F("mass", "0", 0, 1, "kg", "particle mass; 0 derives it so particles at spacing d have the rest density",
         PARAM_RESTART, .group = "numerics"),
    FL_F("dt", "0.003", 0.0001, 0.004, "s", "time step of the simulation", 0, .group = "numerics"),
    FL_I("max_substeps", "24", 1, 256, "steps", "most steps per frame; beyond it the stream runs slower than real "
                                                "time (see the real-time factor in /metrics)", 0, .group = "numerics"),
    FL_I("max_particles", "1000000", 1000, 4000000, "", "particle limit; reaching it is a runaway (reset)",
         PARAM_RESTART, .group = "numerics"),
    FL_I("seed", "1", 0, 1000000, "", "seed of the insertion directions: runs with the same seed are identical", PARAM_RESTART, .group = "numerics"),
    FL_F("fps", "30", 1, 240, "1/s", "frames per second of the stream", 0, .group = "output"),
    FL_F("time_scale", "1", 0, 10, "", "simulated seconds per wall second (0 pauses)", 0, .group = "output"),
    FL_F("space_scale", "1", 0.001, 1000, "", "world units per simulated metre in the frames", 0, .group = "output"),
    FL_I("pos_bits", "16", 8, 24, "bits", "position quantisation of the particle codec", 0, .group = "output"),
    {.name = "velocities", .group = "output", .type = PARAM_BOOL, .def = "false", .unit = "",
     .doc = "also send each particle's velocity (x space_scale), for velocity lines: about 0.9 byte more per "
            "particle"},
    FL_I("vel_bits", "8", 4, 12, "bits", "velocity quantisation per component, sign included (with velocities)", 0,
         .group = "output"),
    {0},
};

/* Built-in presets (presets.h). "thesis-table3.1" is the thesis's base scene: Table 3.1's h and
 * dt with a free-floating 3 cm disc (digest §3: source geometry [P]) and no air (wind_drag 0:
 * the thesis has none); 34 substeps keep its 1 ms steps in real time at 30 fps. The others are
 * looks on the default scale. */
static const struct effect_preset flame_presets[] = {
    {"thesis-table3.1", "the thesis's base scene: Table 3.1 (h 11.25 mm, dt 1 ms), a free 3 cm disc, F_init 100, no air drag",
     "{\"h\":0.01125,\"dt\":0.001,\"max_substeps\":34,\"wind_drag\":0,\"obstacles\":[],\"sources\":[{\"radius\":0.015}]}"},
    {"thesis-f80", "Table 3.1's scene at the low end of the thesis's F_init range (80): a smaller, calmer flame",
     "{\"h\":0.01125,\"dt\":0.001,\"max_substeps\":34,\"wind_drag\":0,\"obstacles\":[],"
     "\"sources\":[{\"radius\":0.015,\"F_init\":80}]}"},
    {"candle", "a narrow candle flame, about 4 cm tall: an 8 mm wick, less buoyancy, finer particles (h 2 mm)",
     "{\"h\":0.002,\"k_buo\":0.005,\"sources\":[{\"radius\":0.004,\"F_init\":60}],"
     "\"obstacles\":[{\"shape\":\"plate\",\"size\":[0.012,0.012,0],\"pos\":[0,0,-0.003],\"velocity\":[0,0,0]}]}"},
    /* Three logs in a star, each three small discs rising towards the middle (0, 7, 14 mm): their
     * flames lean together into one broad, low fire. Burning gas starts at the pit's floor all
     * across, so its lower edge is flat: a pit, not a campfire on open ground. */
    {"fire-pit", "a broad, low fire in a pit: three logs laid in a star, rising to the middle, on an 11 cm floor "
                 "(coarser particles, h 5 mm)",
     "{\"h\":0.005,\"sources\":["
     "{\"center\":[0,0.04,0],\"radius\":0.008},{\"center\":[0,0.028,0.007],\"radius\":0.008},"
     "{\"center\":[0,0.016,0.014],\"radius\":0.008},{\"center\":[-0.0346,-0.02,0],\"radius\":0.008},"
     "{\"center\":[-0.0242,-0.014,0.007],\"radius\":0.008},{\"center\":[-0.0139,-0.008,0.014],\"radius\":0.008},"
     "{\"center\":[0.0346,-0.02,0],\"radius\":0.008},{\"center\":[0.0242,-0.014,0.007],\"radius\":0.008},"
     "{\"center\":[0.0139,-0.008,0.014],\"radius\":0.008}],"
     "\"obstacles\":[{\"shape\":\"plate\",\"size\":[0.11,0.11,0],\"pos\":[0,0,-0.006],\"velocity\":[0,0,0]}]}"},
    {"gusty", "the default flame in a light breeze (wind_velocity 2 m/s along x): it leans downwind",
     "{\"wind_velocity\":[2,0,0]}"},
    {0},
};

/* ---- state ------------------------------------------------------------------------- */

enum fl_kernel { K_HASH, K_HIST, K_SCAN, K_SCATTER, K_REORDER, K_CSTART, K_DENSITY, K_FORCES, K_COUNT,
                 K_SCANB, K_COMPACT, K_N };
static const char *const fl_kernel_names[K_N] = {
    "fl_hash", "fl_radix_hist", "fl_scan_serial", "fl_radix_scatter", "fl_reorder", "fl_cell_start",
    "fl_density", "fl_forces", "fl_count", "fl_scan_blocks", "fl_compact"};

/* One state set: particle state plus derived fields, all in the same order. */
struct fl_set {
    cl_mem pos, vel, flags, id, rho_p, counts, force, dTdF;
};

struct fl_event {
    const char *name;
    cl_event ev;
};

/* A frame's substeps, which may run over several slices of the engine (effect.h): planned, done,
 * its time budget and the time its substeps took so far (ms). */
struct fl_frame_plan {
    int busy, n, done;
    double budget_ms, spent_ms;
};

struct flame {
    struct ocl *ocl;
    cl_kernel k[K_N];
    struct fl_set st[2];
    cl_mem key[2], val[2], hist, cs, keep_ins, nrm, nl, bsum, tot, errflag, prm;
    cl_mem sxyz; /* sorted x, y, z as three arrays of stride cap + FL_PAD (fl_reorder -> fl_density) */
    int cur, n, cap, cs_cap;
    uint32_t mask;
    int passes;
    uint32_t next_id;
    uint64_t steps;
    double sim_seconds, carry;
    float P[FP_COUNT];
    struct fl_event ev[FL_MAX_EVENTS];
    int nev;
    /* parameters */
    cJSON *doc;
    double h, d, dt, time_scale, space_scale, t_amb, period_ms;
    double emit_ms; /* wall time of the last frame's read-back, encoding and the substep run beside it */
    int enc_threads; /* threads a frame's encoding may use: 1 on a CPU device, else the cores up to FL_ENC_THREADS_MAX */
    double step_ms; /* recent time per substep, the wall time of its slices (moving average; 0 = none yet) */
    double fit_frac; /* the fraction of a substep that the budgets of frames cut short left over */
    int ahead;       /* substeps of the coming frame already run beside the last encoding (0 or 1) */
    struct fl_frame_plan frame; /* the frame in progress (fl_step) */
    int rs_pending;  /* a resampling step's totals are being read into rs_tot and rs_err (fl_step_end) */
    cl_uint rs_tot[3];
    cl_int rs_err;
    int interval, max_substeps, max_particles, pos_bits, vel_bits;
    int velocities;
    double up[3];
    /* frame buffers */
    float *h_pos, *h_vel, *xyz, *temp, *fuel, *vel; /* vel: 3 per particle, the frame's velocities */
    uint32_t *h_flags;
    uint8_t *flags8;
    int h_cap;
    uint8_t *payload; /* the latest frame's codec 2/3 payload, made when wanted (fl_encode) */
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
    for (int i = 0; i < fl->nev; i++) {
        ocl_record(fl->ocl, fl->ev[i].name, fl->ev[i].ev);
        clReleaseEvent(fl->ev[i].ev);
    }
    fl->nev = 0;
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
    if (fl->nev == FL_MAX_EVENTS && fl_finish(fl, err)) return -1;
    if (global == 0) return 0;
    if (!local) { /* a fixed work-group size: PoCL compiles one work-group function per size */
        local = FL_LOCAL;
        global = (global + local - 1) / local * local;
    }
    cl_event ev;
    cl_int rc = clEnqueueNDRangeKernel(ocl_queue(fl->ocl), fl->k[k], 1, NULL, &global, &local, 0, NULL, &ev);
    if (rc != CL_SUCCESS) return fl_clfail(err, fl_kernel_names[k], rc);
    fl->ev[fl->nev++] = (struct fl_event){fl_kernel_names[k], ev};
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
    if (want <= fl->cap) return 0;
    int cap = fl->cap ? fl->cap : 4096;
    while (cap < want) cap *= 2;
    cl_int rc = CL_SUCCESS;
    struct fl_set ns[2] = {{0}};
    for (int s = 0; s < 2 && rc == CL_SUCCESS; s++)
        for (int i = 0; i < 8 && rc == CL_SUCCESS; i++) *fl_set_mem(&ns[s], i) = fl_buffer(fl, fl_sizes[i] * cap, &rc);
    for (int i = 0; i < 4 && rc == CL_SUCCESS && fl->n > 0; i++) /* the state of the current set */
        rc = clEnqueueCopyBuffer(ocl_queue(fl->ocl), *fl_set_mem(&fl->st[fl->cur], i), *fl_set_mem(&ns[0], i), 0, 0,
                                 fl_sizes[i] * fl->n, 0, NULL, NULL);
    if (rc == CL_SUCCESS) rc = clFinish(ocl_queue(fl->ocl));
    for (int s = 0; s < 2; s++)
        for (int i = 0; i < 8; i++) {
            fl_release(fl_set_mem(&fl->st[s], i));
            if (rc == CL_SUCCESS) *fl_set_mem(&fl->st[s], i) = *fl_set_mem(&ns[s], i);
            else fl_release(fl_set_mem(&ns[s], i));
        }
    if (rc != CL_SUCCESS) {
        fl->cap = fl->n = 0;
        return fl_clfail(err, "allocating particle buffers", rc);
    }
    fl->cur = 0;
    cl_mem *aux[] = {&fl->key[0], &fl->key[1], &fl->val[0], &fl->val[1], &fl->keep_ins, &fl->nrm, &fl->nl};
    size_t asz[] = {4, 4, 4, 4, 8, 16, 4 * FL_NL};
    for (int i = 0; i < 7 && rc == CL_SUCCESS; i++) {
        fl_release(aux[i]);
        *aux[i] = fl_buffer(fl, asz[i] * cap, &rc);
    }
    fl_release(&fl->sxyz);
    if (rc == CL_SUCCESS) fl->sxyz = fl_buffer(fl, 3 * sizeof(cl_float) * ((size_t)cap + FL_PAD), &rc);
    if (rc != CL_SUCCESS) return fl_clfail(err, "allocating sort buffers", rc);
    fl->cap = cap;
    return 0;
}

/* Hash table of M = 2^k >= 2n keys (k in 10..22) and its cell-start array. */
static int fl_table(struct flame *fl, struct fx_err *err)
{
    int bits = 10;
    while (bits < 22 && (1 << bits) < 4 * fl->n) bits++;
    fl->mask = (1u << bits) - 1u;
    fl->passes = (bits + 7) / 8;
    int want = (1 << bits) + 1;
    if (want <= fl->cs_cap) return 0;
    cl_int rc;
    fl_release(&fl->cs);
    fl->cs = fl_buffer(fl, sizeof(cl_uint) * (size_t)want, &rc);
    if (rc != CL_SUCCESS) return fl_clfail(err, "allocating the cell table", rc);
    fl->cs_cap = want;
    return 0;
}

static int fl_upload_prm(struct flame *fl, struct fx_err *err)
{
    cl_int rc = clEnqueueWriteBuffer(ocl_queue(fl->ocl), fl->prm, CL_TRUE, 0, sizeof fl->P, fl->P, 0, NULL, NULL);
    return rc == CL_SUCCESS ? 0 : fl_clfail(err, "uploading parameters", rc);
}

static int fl_zero_err(struct flame *fl, struct fx_err *err)
{
    cl_int zero[3] = {0, 0, 0};
    cl_int rc = clEnqueueWriteBuffer(ocl_queue(fl->ocl), fl->errflag, CL_TRUE, 0, sizeof zero[0], zero, 0, NULL, NULL);
    return rc == CL_SUCCESS ? 0 : fl_clfail(err, "clearing the error flag", rc);
}

/* ---- parameters into the device array --------------------------------------------------- */

static double fl_poly6_sum(double h, double d)
{
    /* sum over a cubic lattice of spacing d of (h^2 - r^2)^3 within h, times 315/(64 pi h^9) */
    int r = (int)ceil(h / d);
    double s = 0.0;
    for (int i = -r; i <= r; i++)
        for (int j = -r; j <= r; j++)
            for (int k = -r; k <= r; k++) {
                double r2 = d * d * (i * i + j * j + k * k), q = h * h - r2;
                if (q > 0) s += q * q * q;
            }
    return s * 315.0 / (64.0 * M_PI * pow(h, 9));
}

static void fl_unit(double v[3])
{
    double l = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int k = 0; k < 3; k++) v[k] = l > 0 ? v[k] / l : (k == 2);
}

static void fl_pack(struct flame *fl, const cJSON *p)
{
    double h = fl->h, m = params_num(p, "mass"), rho0 = params_num(p, "rho_rest"), w[3], wv[3];
    if (m <= 0) m = rho0 / fl_poly6_sum(h, fl->d); /* §9 #6: 1.7626e-7 kg for the thesis's h */
    float *P = fl->P;
    memset(fl->P, 0, sizeof fl->P);
    P[FP_H] = (float)h;
    P[FP_H2] = (float)(h * h);
    P[FP_INV_CELL] = (float)(FL_CELLS_PER_H / h);
    P[FP_INV_CELLX] = (float)(FL_CELLS_PER_H * FL_XCELLS / h);
    P[FP_MASS] = (float)m;
    P[FP_POLY6] = (float)(m * 315.0 / (64.0 * M_PI * pow(h, 9)));
    P[FP_SPIKY] = (float)(45.0 / (M_PI * pow(h, 6)));
    P[FP_GPOLY6] = (float)(m * 945.0 / (32.0 * M_PI * pow(h, 9)));
    P[FP_KSTIFF] = (float)params_num(p, "k_stiff");
    P[FP_RHO0] = (float)rho0;
    P[FP_KVISC] = (float)params_num(p, "k_viscosity");
    P[FP_KBUO] = (float)params_num(p, "k_buo");
    params_vec3(p, "wind_accel", w);
    params_vec3(p, "wind_velocity", wv);
    for (int k = 0; k < 3; k++) {
        P[FP_UP + k] = (float)fl->up[k];
        P[FP_WIND + k] = (float)w[k];
        P[FP_WINDV + k] = (float)wv[k];
    }
    /* the drag's exact relaxation over one step (kernels/flame.cl fl_forces) */
    P[FP_DRAG] = (float)-expm1(-params_num(p, "wind_drag") * params_num(p, "dt"));
    static const struct { int i; const char *name; } direct[] = {
        {FP_TAMB, "T_amb"}, {FP_TIGN, "T_ign"}, {FP_KRS, "k_rs"}, {FP_KCF, "k_cf"}, {FP_KPT, "k_pt"},
        {FP_KH, "k_h"}, {FP_KF, "k_f"}, {FP_OMEGA, "omega_max"}, {FP_KCOOL, "k_cool"}, {FP_FEPS, "fuel_eps"},
        {FP_DT, "dt"}, {FP_NBR_INS, "insert_nbr_threshold"}, {FP_SEED, "seed"}};
    for (size_t i = 0; i < sizeof direct / sizeof direct[0]; i++) P[direct[i].i] = (float)params_num(p, direct[i].name);
    P[FP_DIAM] = (float)fl->d;
    P[FP_VMAX] = (float)FL_VMAX;
    P[FP_SYMMETRIC] = strcmp(params_str(p, "pressure_form"), "symmetric") == 0;
    P[FP_LITERAL] = strcmp(params_str(p, "diffusion_mode"), "literal") == 0;
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
    return type | ((T > fl->P[FP_TIGN] && F > fl->P[FP_FEPS]) ? FLAME_IS_FLAME : 0u);
}

/* A disc normal to `up` at spacing d, two layers (§9 #17). */
static int fl_add_source(struct flame *fl, struct fl_host *hp, const cJSON *src)
{
    double c[3], e1[3], e2[3], *u = fl->up, zero[3] = {0, 0, 0};
    params_vec3(src, "center", c);
    double R = params_num(src, "radius"), T = params_num(src, "T_init"), F = params_num(src, "F_init"), d = fl->d;
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
                if (fl_host_push(hp, x, (float)T, zero, (float)F, fl_flag_of(fl, FLAME_SOURCE, T, F), fl->next_id++))
                    return -1;
            }
    return 0;
}

/* Plate (one layer across the two largest extents) or filled box at spacing d. */
static int fl_add_obstacle(struct flame *fl, struct fl_host *hp, const cJSON *ob, double t)
{
    double s[3], c[3], v[3];
    params_vec3(ob, "size", s);
    params_vec3(ob, "pos", c);
    params_vec3(ob, "velocity", v);
    int cnt[3], thin = 0;
    for (int k = 0; k < 3; k++) {
        cnt[k] = 1 + (int)floor(s[k] / fl->d + 1e-9);
        if (s[k] < s[thin]) thin = k;
    }
    if (strcmp(params_str(ob, "shape"), "plate") == 0) cnt[thin] = 1;
    for (int i = 0; i < cnt[0]; i++)
        for (int j = 0; j < cnt[1]; j++)
            for (int k = 0; k < cnt[2]; k++) {
                int idx[3] = {i, j, k};
                double x[3];
                for (int a = 0; a < 3; a++) x[a] = c[a] + v[a] * t + fl->d * (idx[a] - 0.5 * (cnt[a] - 1));
                if (fl_host_push(hp, x, (float)fl->t_amb, v, 0.0f, FLAME_OBSTACLE, fl->next_id++)) return -1;
            }
    return 0;
}

static int fl_add_solids(struct flame *fl, struct fl_host *hp, const cJSON *p, struct fx_err *err)
{
    const cJSON *it;
    cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(p, "sources")) {
        if (params_bool(it, "enabled") && fl_add_source(fl, hp, it)) return fx_fail(err, "internal", "", "out of memory");
    }
    cJSON_ArrayForEach(it, cJSON_GetObjectItemCaseSensitive(p, "obstacles")) {
        if (fl_add_obstacle(fl, hp, it, fl->sim_seconds)) return fx_fail(err, "internal", "", "out of memory");
    }
    return 0;
}

/* Uploads host particles as the whole state (current set 0). */
static int fl_upload(struct flame *fl, int n, const float *pos, const float *vel, const uint32_t *flags,
                     const uint32_t *id, struct fx_err *err)
{
    if (n > fl->max_particles)
        return fx_fail(err, "limit", "max_particles", "%d particles exceed max_particles %d", n, fl->max_particles);
    fl->n = 0;
    if (fl_reserve(fl, n, err)) return -1;
    fl->cur = 0;
    fl->n = n;
    const void *src[4] = {pos, vel, flags, id};
    cl_int rc = CL_SUCCESS;
    for (int i = 0; i < 4 && rc == CL_SUCCESS && n > 0; i++)
        rc = clEnqueueWriteBuffer(ocl_queue(fl->ocl), *fl_set_mem(&fl->st[0], i), CL_TRUE, 0, fl_sizes[i] * n, src[i],
                                  0, NULL, NULL);
    if (rc != CL_SUCCESS) return fl_clfail(err, "uploading particles", rc);
    return fl_table(fl, err);
}

/* ---- one step on the device ---------------------------------------------------------- */

/* Sorts the current set's particles by cell key into the other set (fl_hash, radix passes,
 * fl_reorder) and builds the cell-start table. Returns the index of the sorted set. */
static int fl_sort(struct flame *fl, struct fx_err *err)
{
    struct fl_set *A = &fl->st[fl->cur], *B = &fl->st[1 - fl->cur];
    cl_int n = fl->n, nhist = 256 * FL_BLOCKS, m = (cl_int)fl->mask + 1;
    cl_uint mask = fl->mask;
    struct ocl_arg ha[] = {FL_MEM(A->pos), FL_MEM(fl->key[0]), FL_MEM(fl->val[0]), FL_INT(n), FL_INT(mask),
                          FL_MEM(fl->prm)};
    if (fl_args(fl, K_HASH, ha, 6, err) || fl_launch(fl, K_HASH, (size_t)n, 0, err)) return -1;
    int s = 0;
    for (int p = 0; p < fl->passes; p++, s ^= 1) {
        cl_int shift = 8 * p;
        struct ocl_arg hh[] = {FL_MEM(fl->key[s]), FL_INT(n), FL_INT(shift), FL_MEM(fl->hist)};
        struct ocl_arg sc[] = {FL_MEM(fl->hist), FL_INT(nhist)};
        struct ocl_arg sa[] = {FL_MEM(fl->key[s]), FL_MEM(fl->val[s]), FL_MEM(fl->key[s ^ 1]), FL_MEM(fl->val[s ^ 1]),
                              FL_INT(n), FL_INT(shift), FL_MEM(fl->hist)};
        if (fl_args(fl, K_HIST, hh, 4, err) || fl_launch(fl, K_HIST, FL_BLOCKS, 1, err) ||
            fl_args(fl, K_SCAN, sc, 2, err) || fl_launch(fl, K_SCAN, 1, 1, err) ||
            fl_args(fl, K_SCATTER, sa, 7, err) || fl_launch(fl, K_SCATTER, FL_BLOCKS, 1, err))
            return -1;
    }
    cl_int stride = fl->cap + FL_PAD;
    struct ocl_arg ra[] = {FL_MEM(fl->val[s]), FL_INT(n), FL_MEM(A->pos), FL_MEM(A->vel), FL_MEM(A->flags),
                          FL_MEM(A->id), FL_MEM(B->pos), FL_MEM(B->vel), FL_MEM(B->flags), FL_MEM(B->id),
                          FL_MEM(fl->sxyz), FL_INT(stride)};
    struct ocl_arg ca[] = {FL_MEM(fl->key[s]), FL_INT(n), FL_INT(m), FL_MEM(fl->cs)};
    if (fl_args(fl, K_REORDER, ra, 12, err) || fl_launch(fl, K_REORDER, (size_t)n, 0, err) ||
        fl_args(fl, K_CSTART, ca, 4, err) || fl_launch(fl, K_CSTART, (size_t)n + 1, 0, err))
        return -1;
    return 0;
}

/* Density pass on the sorted set B into A's derived arrays, then forces and integration
 * from B back into A (integrate = 0: the state is copied unchanged, for flame_eval). */
static int fl_gather(struct flame *fl, int integrate, int resample, struct fx_err *err)
{
    struct fl_set *A = &fl->st[fl->cur], *B = &fl->st[1 - fl->cur];
    cl_int n = fl->n, stride = fl->cap + FL_PAD;
    cl_uint mask = fl->mask;
    struct ocl_arg da[] = {FL_MEM(B->pos), FL_MEM(B->vel), FL_MEM(fl->cs), FL_INT(mask), FL_INT(n), FL_MEM(fl->prm),
                          FL_MEM(A->rho_p), FL_MEM(A->counts), FL_MEM(fl->nl), FL_MEM(fl->sxyz), FL_INT(stride)};
    struct ocl_arg fa[] = {FL_MEM(B->pos), FL_MEM(B->vel), FL_MEM(B->flags), FL_MEM(B->id), FL_MEM(fl->cs),
                          FL_INT(mask), FL_INT(n), FL_MEM(fl->prm), FL_MEM(A->rho_p), FL_MEM(A->counts),
                          FL_MEM(fl->nl), FL_MEM(A->pos), FL_MEM(A->vel), FL_MEM(A->flags), FL_MEM(A->id), FL_MEM(A->force),
                          FL_MEM(A->dTdF), FL_INT(integrate), FL_INT(resample), FL_MEM(fl->keep_ins),
                          FL_MEM(fl->nrm), FL_MEM(fl->errflag)};
    if (fl_args(fl, K_DENSITY, da, 11, err) || fl_launch(fl, K_DENSITY, (size_t)n, 0, err) ||
        fl_args(fl, K_FORCES, fa, 22, err) || fl_launch(fl, K_FORCES, (size_t)n, 0, err))
        return -1;
    return 0;
}

/* Reads the error flag once the queue is done. The queue is finished even when the enqueue
 * failed: no read into the caller's variable may outlive the call. */
static int fl_read_errflag(struct flame *fl, cl_int *errflag, struct fx_err *err)
{
    cl_int rc = clEnqueueReadBuffer(ocl_queue(fl->ocl), fl->errflag, CL_FALSE, 0, sizeof *errflag, errflag, 0, NULL, NULL);
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
                       (unsigned long long)fl->steps);
    if (errflag & FL_ERR_SPEED)
        return fx_fail(err, "internal", "", "flame: runaway particle speed above %g m/s after step %llu", FL_VMAX,
                       (unsigned long long)fl->steps);
    return 0;
}

/* Birth and death (§2.12): count, scan, compact A into B, and the totals read without
 * waiting; fl_resample_end makes B current. */
static int fl_resample_begin(struct flame *fl, struct fx_err *err)
{
    struct fl_set *A = &fl->st[fl->cur], *B = &fl->st[1 - fl->cur];
    cl_int n = fl->n, nb = FL_BLOCKS;
    cl_uint cap = (cl_uint)(fl->cap < fl->max_particles ? fl->cap : fl->max_particles), idb = fl->next_id;
    struct ocl_arg ca[] = {FL_MEM(fl->keep_ins), FL_INT(n), FL_MEM(fl->bsum)};
    struct ocl_arg sa[] = {FL_MEM(fl->bsum), FL_INT(nb), FL_INT(cap), FL_MEM(fl->tot)};
    struct ocl_arg xa[] = {FL_MEM(fl->keep_ins), FL_INT(n), FL_MEM(fl->bsum), FL_MEM(fl->tot), FL_INT(idb),
                          FL_MEM(fl->prm), FL_MEM(fl->nrm), FL_MEM(A->pos), FL_MEM(A->vel), FL_MEM(A->flags),
                          FL_MEM(A->id), FL_MEM(A->rho_p), FL_MEM(A->counts), FL_MEM(A->force), FL_MEM(A->dTdF),
                          FL_MEM(B->pos), FL_MEM(B->vel), FL_MEM(B->flags), FL_MEM(B->id), FL_MEM(B->rho_p),
                          FL_MEM(B->counts), FL_MEM(B->force), FL_MEM(B->dTdF)};
    if (fl_args(fl, K_COUNT, ca, 3, err) || fl_launch(fl, K_COUNT, FL_BLOCKS, 1, err) ||
        fl_args(fl, K_SCANB, sa, 4, err) || fl_launch(fl, K_SCANB, 1, 1, err) ||
        fl_args(fl, K_COMPACT, xa, 23, err) || fl_launch(fl, K_COMPACT, FL_BLOCKS, 1, err))
        return -1;
    cl_command_queue q = ocl_queue(fl->ocl);
    cl_int rc = clEnqueueReadBuffer(q, fl->errflag, CL_FALSE, 0, sizeof fl->rs_err, &fl->rs_err, 0, NULL, NULL);
    if (rc == CL_SUCCESS) rc = clEnqueueReadBuffer(q, fl->tot, CL_FALSE, 0, sizeof fl->rs_tot, fl->rs_tot, 0, NULL, NULL);
    if (rc != CL_SUCCESS) {
        fl_finish(fl, NULL); /* no read into fl may outlive the call */
        return fl_clfail(err, "reading totals", rc);
    }
    fl->rs_pending = 1;
    return 0;
}

/* Waits for fl_resample_begin's totals (survivors, insertions, new n) and applies them. */
static int fl_resample_end(struct flame *fl, struct fx_err *err)
{
    fl->rs_pending = 0;
    if (fl_finish(fl, err) || fl_check(fl, fl->rs_err, err)) return -1;
    fl->cur ^= 1;
    fl->n = (int)fl->rs_tot[2];
    fl->next_id += fl->rs_tot[1];
    if (fl->rs_tot[0] + fl->rs_tot[1] >= (cl_uint)fl->max_particles)
        return fx_fail(err, "internal", "", "flame: particle count reached max_particles %d (runaway) at step %llu",
                       fl->max_particles, (unsigned long long)fl->steps);
    return fl_table(fl, err);
}

/* One substep, enqueued: the device may still be working on it when this returns, and a
 * resampling step's totals wait for fl_step_end. */
static int fl_step_begin(struct flame *fl, struct fx_err *err)
{
    int resample = fl->steps % (uint64_t)fl->interval == 0;
    if (resample) {
        int want = 2 * fl->n < fl->max_particles ? 2 * fl->n : fl->max_particles;
        if (fl_reserve(fl, want, err)) return -1;
    }
    if (fl->n > 0 && (fl_sort(fl, err) || fl_gather(fl, 1, resample, err))) return -1;
    if (resample && fl->n > 0 && fl_resample_begin(fl, err)) return -1;
    fl->steps++;
    fl->sim_seconds += fl->dt;
    return 0;
}

/* Completes the substep fl_step_begin enqueued (the particle count after a resampling step
 * is known only then); nothing to do for the others. */
static int fl_step_end(struct flame *fl, struct fx_err *err) { return fl->rs_pending ? fl_resample_end(fl, err) : 0; }

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

static int fl_read_params(struct flame *fl, const cJSON *p)
{
    fl->dt = params_num(p, "dt");
    fl->period_ms = 1000.0 / params_num(p, "fps");
    fl->time_scale = params_num(p, "time_scale");
    fl->space_scale = params_num(p, "space_scale");
    fl->t_amb = params_num(p, "T_amb");
    fl->interval = (int)params_num(p, "resample_interval");
    fl->max_substeps = (int)params_num(p, "max_substeps");
    fl->pos_bits = (int)params_num(p, "pos_bits");
    fl->velocities = params_bool(p, "velocities");
    fl->vel_bits = (int)params_num(p, "vel_bits");
    params_vec3(p, "up", fl->up);
    fl_unit(fl->up);
    fl_pack(fl, p);
    return 0;
}

/* Replaces the solids (sources, obstacles) by those of the document, keeping the gas. */
static int fl_rebuild_solids(struct flame *fl, const cJSON *p, struct fx_err *err)
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
    if (!rc) rc = fl_add_solids(fl, &hp, p, err);
    if (!rc) rc = fl_upload(fl, hp.n, hp.pos, hp.vel, hp.flags, hp.id, err);
    fl_host_free(&hp);
    return rc;
}

int flame_set(struct flame *fl, const cJSON *params, struct fx_err *err)
{
    int solids_changed = !fl->doc ||
        !cJSON_Compare(cJSON_GetObjectItemCaseSensitive(fl->doc, "sources"),
                       cJSON_GetObjectItemCaseSensitive(params, "sources"), 1) ||
        !cJSON_Compare(cJSON_GetObjectItemCaseSensitive(fl->doc, "obstacles"),
                       cJSON_GetObjectItemCaseSensitive(params, "obstacles"), 1) ||
        params_num(fl->doc, "T_amb") != params_num(params, "T_amb");
    cJSON *copy = cJSON_Duplicate(params, 1);
    if (!copy) return fx_fail(err, "internal", "", "out of memory");
    cJSON_Delete(fl->doc);
    fl->doc = copy;
    fl_read_params(fl, params);
    if (fl_upload_prm(fl, err)) return -1;
    return solids_changed && fl->cap ? fl_rebuild_solids(fl, params, err) : 0;
}

/* Steps, simulated time, the frame plan's carry and ids back to a fresh start. */
static void fl_clock_reset(struct flame *fl)
{
    fl->steps = 0;
    fl->sim_seconds = fl->carry = 0;
    fl->ahead = 0;
    fl->frame.busy = 0;
    fl->next_id = 0;
}

/* The initial state: the scene's solids only (§2.13). */
static int fl_restart(struct flame *fl, struct fx_err *err)
{
    struct fl_host hp = {0};
    fl_clock_reset(fl);
    int rc = fl_finish(fl, err) || fl_zero_err(fl, err) || fl_add_solids(fl, &hp, fl->doc, err) ||
             fl_upload(fl, hp.n, hp.pos, hp.vel, hp.flags, hp.id, err);
    fl_host_free(&hp);
    return rc ? -1 : 0;
}

static int fl_create_objects(struct flame *fl, struct fx_err *err)
{
    cl_int rc = CL_SUCCESS;
    cl_program prog = ocl_program(fl->ocl, FL_KERNEL_FILE, FL_BUILD_OPTS, err);
    if (!prog) return -1;
    for (int k = 0; k < K_N && rc == CL_SUCCESS; k++) fl->k[k] = clCreateKernel(prog, fl_kernel_names[k], &rc);
    if (rc != CL_SUCCESS) return fl_clfail(err, "clCreateKernel", rc);
    struct { cl_mem *m; size_t bytes; } fixed[] = {
        {&fl->hist, 4 * 256 * FL_BLOCKS}, {&fl->bsum, 8 * FL_BLOCKS}, {&fl->tot, 16}, {&fl->errflag, 16},
        {&fl->prm, sizeof fl->P}};
    for (size_t i = 0; i < sizeof fixed / sizeof fixed[0] && rc == CL_SUCCESS; i++)
        *fixed[i].m = fl_buffer(fl, fixed[i].bytes, &rc);
    return rc == CL_SUCCESS ? 0 : fl_clfail(err, "clCreateBuffer", rc);
}

struct flame *flame_new(struct ocl *ocl, const cJSON *params, struct fx_err *err)
{
    struct flame *fl = calloc(1, sizeof *fl);
    if (!fl) {
        fx_fail(err, "internal", "", "out of memory");
        return NULL;
    }
    fl->ocl = ocl;
    fl->h = params_num(params, "h");
    fl->d = params_num(params, "particle_diameter") * fl->h;
    fl->max_particles = (int)params_num(params, "max_particles");
    long cores = ocl_is_cpu(ocl) ? 1 : sysconf(_SC_NPROCESSORS_ONLN);
    fl->enc_threads = cores < 1 ? 1 : cores > FL_ENC_THREADS_MAX ? FL_ENC_THREADS_MAX : (int)cores;
    if (fl_create_objects(fl, err) || flame_set(fl, params, err) || fl_restart(fl, err)) {
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
        for (int i = 0; i < 8; i++) fl_release(fl_set_mem(&fl->st[s], i));
    cl_mem *m[] = {&fl->key[0], &fl->key[1], &fl->val[0], &fl->val[1], &fl->hist, &fl->cs, &fl->keep_ins,
                   &fl->nrm, &fl->nl, &fl->sxyz, &fl->bsum, &fl->tot, &fl->errflag, &fl->prm};
    for (size_t i = 0; i < sizeof m / sizeof m[0]; i++) fl_release(m[i]);
    for (int k = 0; k < K_N; k++)
        if (fl->k[k]) clReleaseKernel(fl->k[k]);
    cJSON_Delete(fl->doc);
    free(fl->h_pos);
    free(fl->h_vel);
    free(fl->h_flags);
    free(fl->xyz);
    free(fl->temp);
    free(fl->fuel);
    free(fl->vel);
    free(fl->flags8);
    free(fl->payload);
    free(fl);
}

int flame_load(struct flame *fl, const struct flame_particles *p, struct fx_err *err)
{
    if (fl_finish(fl, err) || fl_zero_err(fl, err)) return -1;
    fl_clock_reset(fl);
    for (int i = 0; i < p->n; i++)
        if (p->id[i] >= fl->next_id) fl->next_id = p->id[i] + 1;
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
    struct fl_set *S = &fl->st[fl->cur];
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
uint64_t flame_steps(const struct flame *fl) { return fl->steps; }

/* ---- effect_ops ------------------------------------------------------------------------------ */

static int fl_frame_buffers(struct flame *fl, int n)
{
    if (n <= fl->h_cap) return 0;
    int cap = n + n / 2 + 1024;
    float **f[] = {&fl->h_pos, &fl->h_vel, &fl->xyz, &fl->temp, &fl->fuel, &fl->vel};
    size_t fs[] = {4, 4, 3, 1, 1, 3};
    for (int i = 0; i < 6; i++) {
        free(*f[i]);
        *f[i] = malloc(fs[i] * sizeof(float) * (size_t)cap);
    }
    free(fl->h_flags);
    free(fl->flags8);
    fl->h_flags = malloc(sizeof(uint32_t) * (size_t)cap);
    fl->flags8 = malloc((size_t)cap);
    fl->h_cap = 0;
    if (!fl->h_pos || !fl->h_vel || !fl->xyz || !fl->temp || !fl->fuel || !fl->vel || !fl->h_flags || !fl->flags8)
        return -1;
    fl->h_cap = cap;
    return 0;
}

/* Reads the particles once (with the error flag) into the frame arrays; returns n, or -1. */
static int fl_read_frame(struct flame *fl, struct fx_err *err)
{
    int n = fl->n;
    if (fl_frame_buffers(fl, n)) return fx_fail(err, "internal", "", "out of memory for %d particles", n);
    struct fl_set *S = &fl->st[fl->cur];
    void *dst[3] = {fl->h_pos, fl->h_vel, fl->h_flags};
    cl_int ef = 0, rc = CL_SUCCESS;
    for (int i = 0; i < 3 && rc == CL_SUCCESS && n > 0; i++)
        rc = clEnqueueReadBuffer(ocl_queue(fl->ocl), *fl_set_mem(S, i), CL_FALSE, 0, fl_sizes[i] * n, dst[i], 0, NULL,
                                 NULL);
    if (rc != CL_SUCCESS) {
        fl_finish(fl, NULL); /* the reads already queued complete before the buffers may change */
        return fl_clfail(err, "reading the frame", rc);
    }
    if (fl_read_errflag(fl, &ef, err) || fl_check(fl, ef, err)) return -1;
    float s = (float)fl->space_scale;
    for (int i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++) fl->xyz[3 * i + k] = s * fl->h_pos[4 * i + k];
        for (int k = 0; k < 3 && fl->velocities; k++) fl->vel[3 * i + k] = s * fl->h_vel[4 * i + k];
        fl->temp[i] = fl->h_pos[4 * i + 3];
        fl->fuel[i] = fl->h_vel[4 * i + 3];
        fl->flags8[i] = (uint8_t)fl->h_flags[i];
    }
    return n;
}

/* The frame's codec 2/3 payload (effect_frame.encode): made only when a subscriber takes it. */
static int fl_encode(void *self, struct effect_frame *fr, struct fx_err *err)
{
    struct flame *fl = self;
    struct fxs_particles_opts opts = {.pos_bits = fl->pos_bits, .vel_bits = fl->vel_bits, .threads = fl->enc_threads};
    size_t len = 0;
    char msg[160];
    double t0 = clock_now() * 1e3;
    free(fl->payload);
    fl->payload = NULL;
    if (fxs_particles_encode(&fr->particles, &opts, &fl->payload, &len, msg, sizeof msg))
        return fx_fail(err, "internal", "", "flame: particle encoding failed: %s", msg);
    fr->codec = fxs_particles_codec(fl->payload, len);
    fr->payload = fl->payload;
    fr->payload_bytes = len;
    fr->encode_ms = clock_now() * 1e3 - t0;
    return 0;
}

/* Simulated seconds one frame of the stream covers. */
static double fl_frame_sim(const struct flame *fl) { return fl->period_ms * 1e-3 * fl->time_scale; }

/* A frame cut short passes its `undone` substeps on to the next frames, up to one frame's
 * worth of simulated time (beyond that it is dropped: fl_step). */
static void fl_carry_over(struct flame *fl, int undone)
{
    fl->carry = fmin(fl->carry + undone * fl->dt, fl_frame_sim(fl));
}

/* Reads the particles and emits one kind 1 frame. The next frame's first substep is enqueued
 * before the encoding (when that frame will step at all), so that the device, or PoCL's
 * workers on the CPU's other cores, compute it while the host encodes: the encoding no longer
 * leaves the device idle. It completes before this returns, so no work is left in flight
 * between frames, and its time counts in emit_ms, which the next frame's budget leaves out. */
static int fl_emit_frame(struct flame *fl, effect_emit_fn emit, void *ctx, struct fx_err *err)
{
    double t_read = clock_now() * 1e3;
    int n = fl_read_frame(fl, err);
    if (n < 0) return -1;
    int pre = fl->time_scale > 0 && fl->carry + fl_frame_sim(fl) >= 0.5 * fl->dt;
    if (pre) {
        if (fl_step_begin(fl, err)) return -1;
        fl->carry -= fl->dt;
        fl->ahead = 1;
    }
    struct effect_frame fr = {
        .kind = FXS_KIND_PARTICLES,
        .count_or_width = (uint32_t)n,
        .encode = fl_encode,
        .self = fl,
        .particles = {(uint32_t)n, fl->xyz, fl->temp, fl->fuel, fl->flags8, fl->velocities ? fl->vel : NULL},
    };
    int ret = emit(ctx, &fr);
    struct fx_err end_err = {0};
    if (pre && (fl_step_end(fl, &end_err) || fl_finish(fl, &end_err)) && ret == 0) {
        *err = end_err;
        ret = -1;
    }
    fl->emit_ms = clock_now() * 1e3 - t_read;
    return ret;
}

/* Plans a frame. Real time (§7 of the digest, "time scale"): round(dt_wall * time_scale / dt)
 * substeps with the fraction carried, at most max_substeps (then the stream runs slower than
 * real time). */
static void fl_plan(struct flame *fl, double dt)
{
    fl->carry += dt * fl->time_scale;
    /* The substeps this frame owes: none when the one run ahead covered them (carry < 0), and
     * at most max_substeps counting that one. */
    int n = (int)fmax(floor(fl->carry / fl->dt + 0.5), 0), most = fl->max_substeps - fl->ahead;
    fl->ahead = 0;
    if (n > most) {
        n = most;
        fl->carry = 0;
    } else {
        fl->carry -= n * fl->dt;
    }
    /* Time budget: the substeps get the frame period less the last frame's read-back and
     * encoding (with the substep that ran beside it) and a margin; as many run as fit at the
     * recent time per substep. The plan comes from the average of earlier frames, since the
     * clock can only be read where the host waits for the device (resampling steps): deciding
     * there, all or nothing per 5-step interval, would leave a quarter of each frame's period idle.
     * The fraction of a substep a cut frame could not use goes to the next frame's budget
     * (rounding down every frame would waste half a substep a frame), and the simulated time a cut
     * frame leaves undone is carried up to one frame's worth, so a frame slowed by the host
     * catches up in the next ones; beyond that it is dropped, and a scene too slow for the
     * machine streams at a steady frame rate while /metrics reports its real-time factor. A
     * frame still stops once it is over budget. Together with the substep run beside the
     * encoding this raised the default scene's real-time factor on a 2-core host by about a
     * tenth (docs/performance-log.md). Times are the frame's own: the engine may run other
     * streams between its slices. */
    double budget = fmax(fl->period_ms - fl->emit_ms - FL_FRAME_MARGIN_MS, 0.5 * fl->period_ms);
    double fitf = fl->step_ms > 0 ? budget / fl->step_ms + fl->fit_frac : n;
    int fit = (int)fitf;
    fl->fit_frac = 0;
    if (n > fit) {
        int cut = fit > 1 ? fit : 1;
        fl_carry_over(fl, n - cut);
        n = cut;
        fl->fit_frac = fmax(fitf - n, 0); /* < 1: n = floor(fitf), or 1 when fitf < 1 */
    }
    fl->frame = (struct fl_frame_plan){.busy = 1, .n = n, .budget_ms = budget};
}

/* Runs the planned substeps until slice_end (clock.h seconds): it stops before a substep that
 * would end after it, at the recent time per substep, once one ran; the queue is then drained.
 * 0 when the substeps are done (or the budget cut them short), EFFECT_MORE, or -1 with err. */
static int fl_substeps(struct flame *fl, double slice_end, struct fx_err *err)
{
    struct fl_frame_plan *f = &fl->frame;
    double t0 = clock_now() * 1e3, synced_ms = t0, end_ms = slice_end * 1e3;
    int ran = 0, since_sync = 0;
    while (f->done < f->n) {
        if (ran && fl->step_ms > 0 && synced_ms + (since_sync + 1) * fl->step_ms > end_ms) {
            if (fl_finish(fl, err)) return -1;
            f->spent_ms += clock_now() * 1e3 - t0;
            return EFFECT_MORE;
        }
        int synced = fl->steps % (uint64_t)fl->interval == 0;
        if (fl_step_once(fl, err)) return -1;
        f->done++;
        ran++;
        since_sync++;
        if (!synced) continue;
        synced_ms = clock_now() * 1e3; /* the resampling step waited for the device */
        since_sync = 0;
        if (f->done < f->n && f->spent_ms + synced_ms - t0 > f->budget_ms) {
            fl_carry_over(fl, f->n - f->done);
            f->n = f->done;
        }
    }
    if (ran && fl_finish(fl, err)) return -1;
    f->spent_ms += clock_now() * 1e3 - t0;
    if (f->done > 0) {
        double per = f->spent_ms / f->done;
        fl->step_ms = fl->step_ms > 0 ? 0.7 * fl->step_ms + 0.3 * per : per;
    }
    return 0;
}

/* Drops the frame in progress, its undone substeps carried. */
static void fl_abandon(struct flame *fl)
{
    if (fl->frame.busy) fl_carry_over(fl, fl->frame.n - fl->frame.done);
    fl->frame.busy = 0;
}

static int fl_step(void *self, double sim_time, double dt, double slice_end, effect_emit_fn emit, void *ctx,
                   struct fx_err *err)
{
    struct flame *fl = self;
    (void)sim_time;
    if (!fl->frame.busy) fl_plan(fl, dt);
    int rc = fl_substeps(fl, slice_end, err);
    if (rc == EFFECT_MORE) return rc;
    fl->frame.busy = 0;
    return rc ? rc : fl_emit_frame(fl, emit, ctx, err);
}

static void *fl_create(struct ocl *ocl, const cJSON *params, struct fx_err *err)
{
    return flame_new(ocl, params, err);
}

static int fl_apply(void *self, const cJSON *params, struct fx_err *err)
{
    fl_abandon(self);
    return flame_set(self, params, err);
}

static int fl_reset(void *self, struct fx_err *err) { return fl_restart(self, err); }
static void fl_destroy(void *self) { flame_free(self); }
static double fl_sim_seconds(void *self) { return ((struct flame *)self)->sim_seconds; }

const struct effect_ops flame_effect = {
    .name = "flame",
    .doc = "SPH flame (Mabuchi 2012): weakly compressible SPH gas carrying temperature and fuel, combustion "
           "S = k_rs T F, stabilised heat and fuel diffusion, buoyancy, wind, burning solid sources and moving "
           "obstacles, with particles born next to flame particles and deleted away from them; every step on "
           "the OpenCL device, advancing in real time (time_scale) and streamed as particle frames.",
    .params = flame_params,
    .presets = flame_presets,
    .outputs_json = "[{\"kind\":1,\"codec\":\"particles\",\"fields\":\"xyz (x space_scale), T, F, flags "
                    "(type bits 0-1, flame bit 2), with velocities on vx vy vz (x space_scale)\",\"count\":"
                    "\"particles\",\"rate\":\"fps\"}]",
    .create = fl_create,
    .apply = fl_apply,
    .step = fl_step,
    .reset = fl_reset,
    .destroy = fl_destroy,
    .sim_seconds = fl_sim_seconds,
};
