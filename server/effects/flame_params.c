/* flame_params.c — the flame's parameter table, its built-in presets, and the packing of the
 * typed parameters (flame_params.h) into the kernels' parameter array. Sections (§) without a
 * document named are the flame's digest's (digest 002, after Mabuchi 2012's thesis).
 *
 * A value the kernels take as it is goes to its FP_* slot straight from the table
 * (PARAM_SLOT); flame_params_pack adds what derives from several (kernel constants of h and
 * the mass, the unit up vector, the drag's relaxation over one step). */
#include "flame_params.h"

#include <math.h>
#include <string.h>

#include "../vec3.h"

static const char *const fl_shape_names[] = {[FLAME_PLATE] = "plate", [FLAME_BOX] = "box", NULL};
/* The kernels take pressure_form's and diffusion_mode's index as flags (FP_SYMMETRIC, FP_LITERAL). */
static const char *const fl_pform_names[] = {[FLAME_PRESSURE_DIFFERENCE] = "difference", [FLAME_PRESSURE_SYMMETRIC] = "symmetric", NULL};
static const char *const fl_diff_names[] = {[FLAME_DIFFUSION_STABILIZED] = "stabilized", [FLAME_DIFFUSION_LITERAL] = "literal", NULL};

/* Entries of struct flame_config (FL_*) and of its list items (FL_SRC, FL_OBS). */
#define FL_AT(member) PARAM_AT(struct flame_config, member)
#define FL_SRC(member) PARAM_AT(struct flame_source, member)
#define FL_OBS(member) PARAM_AT(struct flame_obstacle, member)
#define FL_F(nm, dflt, lo, hi, un, what, fl, ...) \
    {FL_AT(nm), .type = PARAM_FLOAT, .def = dflt, .min = lo, .max = hi, .unit = un, .doc = what, .flags = fl, __VA_ARGS__}
#define FL_SRC_F(nm, dflt, lo, hi, un, what) \
    {FL_SRC(nm), .type = PARAM_FLOAT, .def = dflt, .min = lo, .max = hi, .unit = un, .doc = what}
#define FL_I(nm, dflt, lo, hi, un, what, fl, ...) \
    {FL_AT(nm), .type = PARAM_INT, .def = dflt, .min = lo, .max = hi, .unit = un, .doc = what, .flags = fl, __VA_ARGS__}

static const struct param_def fl_source_fields[] = {
    {FL_SRC(center), .type = PARAM_VEC3, .def = "[0,0,0]", .min = -100, .max = 100, .unit = "m",
     .doc = "centre of the burning disc (its top layer)"},
    FL_SRC_F(radius, "0.015", 0.001, 1, "m", "disc radius: a wider disc feeds a wider fire (solid particles at spacing d, 2 layers across `up`)"),
    FL_SRC_F(T_init, "2000", 1000, 3000, "K", "temperature the burning solid holds (Mabuchi 2012, Table 3.1)"),
    FL_SRC_F(F_init, "100", 0, 300, "", "fuel the burning solid holds: more fuel, a taller and brighter flame (the thesis uses 80-120)"),
    {FL_SRC(enabled), .type = PARAM_BOOL, .def = "true", .unit = "", .doc = "the source burns (off: as if removed)"},
    {0},
};

static const struct param_def fl_obstacle_fields[] = {
    {FL_OBS(shape), .type = PARAM_ENUM, .def = "\"plate\"", .choices = fl_shape_names, .unit = "",
     .doc = "plate: one layer across the two largest extents of size; box: filled block"},
    {FL_OBS(size), .type = PARAM_VEC3, .def = "[0.04,0,0.04]", .min = 0, .max = 10, .unit = "m",
     .doc = "extents along x, y, z"},
    {FL_OBS(pos), .type = PARAM_VEC3, .def = "[0,0.05,0.03]", .min = -100, .max = 100, .unit = "m",
     .doc = "centre at time 0 (after a reset)"},
    {FL_OBS(velocity), .type = PARAM_VEC3, .def = "[0,-0.2,0]", .min = -20, .max = 20, .unit = "m/s",
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
    {PARAM_LIST_AT(struct flame_config, sources), .group = "sources", .type = PARAM_OBJECT_LIST, .def = "[{\"radius\":0.015}]", .max_len = FLAME_MAX_SOLIDS,
     .fields = fl_source_fields, .unit = "", .doc = "burning solids: discs that hold fuel and heat and feed the flame"},
    {PARAM_LIST_AT(struct flame_config, obstacles), .group = "sources", .type = PARAM_OBJECT_LIST, .max_len = FLAME_MAX_SOLIDS,
     .def = "[{\"shape\":\"plate\",\"size\":[0.036,0.036,0],\"pos\":[0,0,-0.004],\"velocity\":[0,0,0]}]", .fields = fl_obstacle_fields,
     .unit = "", .doc = "solids that do not burn (ambient temperature, no fuel): a plate under the fire, a wall, a moving paddle"},
    {FL_AT(wind_accel), PARAM_SLOT(FP_WIND), .group = "forces", .type = PARAM_VEC3, .def = "[0,0,0]", .min = -50, .max = 50, .unit = "m/s^2",
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
    {FL_AT(wind_velocity), PARAM_SLOT(FP_WINDV), .group = "forces", .type = PARAM_VEC3, .def = "[0,0,0]", .min = -20, .max = 20, .unit = "m/s",
     .doc = "velocity of the surrounding air: the flame leans downwind (the gas takes it up at wind_drag); its "
            "part along `up` is ignored"},
    FL_F(wind_drag, "25", 0, 200, "1/s", "how quickly the gas takes up the air's velocity across `up`, "
         "f = rho k (wind_velocity - v); 0: no air, the gas spreads freely", 0, .group = "forces"),
    FL_F(k_buo, "0.01", 0, 0.05, "N/(m^3 K)", "buoyancy, the force k_buo (T - T_amb) per volume along `up`: higher, a taller and faster flame (Mabuchi 2012 eq. 3.16)", 0, .group = "forces", PARAM_SLOT(FP_KBUO)),
    {FL_AT(up), .group = "forces", .type = PARAM_VEC3, .def = "[0,0,1]", .min = -1, .max = 1, .unit = "direction",
     .doc = "which way is up (normalised): buoyancy pushes along it and the source discs lie across it", .flags = PARAM_NONZERO},
    FL_F(k_stiff, "10", 0, 100, "m^2/s^2", "pressure stiffness: how strongly the gas resists compression, p = k (rho - rho_rest) (eq. 3.11)", 0, .group = "forces", PARAM_SLOT(FP_KSTIFF)),
    FL_F(k_viscosity, "0.005", 0, 0.05, "N s/m^2", "viscosity: higher smooths the flow, lower lets it swirl (eq. 3.13)", 0, .group = "forces", PARAM_SLOT(FP_KVISC)),
    FL_F(rho_rest, "1", 0.1, 10, "kg/m^3", "rest density of the gas; pressure p = k (rho - rho_rest), never below 0", 0, .group = "forces", PARAM_SLOT(FP_RHO0)),
    /* Both forms clamp eq 3.11's p at 0. Unclamped, the difference form (p_j - p_i) pushes the
     * density-deficient free boundary of a gas with no air around it outward (digest §2.5) far
     * faster than buoyancy lifts it: on the default scene no burning gas is left after 2.5 s
     * (1.2k particles), against a flame rising 7.6 cm (centroid at 2.5-3 s) with the clamp
     * (PROTOCOL.md §11.2). Default symmetric (Mueller's form, digest §9 #3): every figure of the
     * default scene and every group D behaviour is measured with it. */
    {FL_AT(pressure_form), PARAM_SLOT(FP_SYMMETRIC), .group = "forces", .type = PARAM_ENUM, .def = "\"symmetric\"", .choices = fl_pform_names, .unit = "",
     .doc = "how pressure pushes particles apart: symmetric, Mueller 2003's -(p_i+p_j)/2 (the default); difference, "
            "the thesis's eq. 3.12 with its sign corrected; both with p >= 0"},
    FL_F(T_amb, "300", 250, 400, "K", "temperature of the surrounding air; new particles start at it", 0, .group = "combustion", PARAM_SLOT(FP_TAMB)),
    FL_F(T_ign, "1000", 500, 2000, "K", "ignition temperature: gas above it that has fuel burns", 0, .group = "combustion", PARAM_SLOT(FP_TIGN)),
    FL_F(k_rs, "0.01", 0, 0.05, "", "reaction rate S = k_rs T F: how fast burning gas uses its fuel (eq. 3.17)", 0, .group = "combustion", PARAM_SLOT(FP_KRS)),
    FL_F(k_cf, "5", 0, 20, "", "fuel used per unit of reaction, dF/dt = -k_cf S (eq. 3.18)", 0, .group = "combustion", PARAM_SLOT(FP_KCF)),
    FL_F(k_pt, "500", 0, 2000, "", "heat released per unit of reaction, dT/dt = k_pt S: higher, a hotter flame (eq. 3.19)", 0, .group = "combustion", PARAM_SLOT(FP_KPT)),
    FL_F(k_h, "0.02", 0, 0.1, "m^2/s", "heat diffusion: how quickly heat spreads to neighbours (eq. 3.20)", 0, .group = "diffusion", PARAM_SLOT(FP_KH)),
    FL_F(k_f, "0.001", 0, 0.01, "m^2/(s K)", "fuel diffusion, faster in hot gas (eq. 3.21)", 0, .group = "diffusion", PARAM_SLOT(FP_KF)),
    {FL_AT(diffusion_mode), PARAM_SLOT(FP_LITERAL), .group = "diffusion", .type = PARAM_ENUM, .def = "\"stabilized\"", .choices = fl_diff_names, .unit = "",
     .doc = "stabilized: each particle's diffusion (and viscosity) weights capped at omega_max, so a step never "
            "overshoots; literal: the thesis's eqs. 3.13, 3.20 and 3.21 as printed (unstable at its k_f)"},
    FL_F(omega_max, "0.5", 0.05, 1, "", "stabilized diffusion: the cap on a particle's summed diffusion weights per step", 0, .group = "diffusion", PARAM_SLOT(FP_OMEGA)),
    FL_F(k_cool, "0", 0, 50, "1/s", "cooling toward the air's temperature, not in the thesis: higher, a shorter flame", 0, .group = "combustion", PARAM_SLOT(FP_KCOOL)),
    FL_F(fuel_eps, "0.001", 0, 1, "", "fuel below this no longer burns", 0, .group = "combustion", PARAM_SLOT(FP_FEPS)),
    FL_I(resample_interval, "5", 1, 20, "steps", "steps between the passes that add particles where the flame thins and remove spent ones", 0, .group = "numerics"),
    FL_I(insert_nbr_threshold, "24", 4, 60, "", "a burning particle with fewer neighbours gets a new one beside it: lower, fewer particles",
         0, .group = "numerics", PARAM_SLOT(FP_NBR_INS)),
    FL_F(h, "0.0035", 0.002, 0.05, "m", "smoothing length, the radius each particle interacts over: smaller, finer detail and more particles "
         "(the thesis's Table 3.1: 0.01125)",
         PARAM_RESTART, .group = "numerics"),
    FL_F(particle_diameter, "0.5", 0.25, 0.75, "h", "spacing d of the solids' particles and of inserted particles", PARAM_RESTART, .group = "numerics"),
    FL_F(mass, "0", 0, 1, "kg", "particle mass; 0 derives it so particles at spacing d have the rest density",
         PARAM_RESTART, .group = "numerics"),
    FL_F(dt, "0.003", 0.0001, 0.004, "s", "time step of the simulation", 0, .group = "numerics", PARAM_SLOT(FP_DT)),
    FL_I(max_substeps, "24", 1, 256, "steps", "most steps per frame; beyond it the stream runs slower than real "
                                                "time (see the real-time factor in /metrics)", 0, .group = "numerics"),
    FL_I(max_particles, "1000000", 1000, 4000000, "", "particle limit; reaching it is a runaway (reset)",
         PARAM_RESTART, .group = "numerics"),
    FL_I(seed, "1", 0, 1000000, "", "seed of the insertion directions: runs with the same seed are identical", PARAM_RESTART, .group = "numerics", PARAM_SLOT(FP_SEED)),
    FL_F(fps, "30", 1, 240, "1/s", "frames per second of the stream", 0, .group = "output"),
    FL_F(time_scale, "1", 0, 10, "", "simulated seconds per wall second (0 pauses)", 0, .group = "output"),
    FL_F(space_scale, "1", 0.001, 1000, "", "world units per simulated metre in the frames", 0, .group = "output"),
    FL_I(pos_bits, "16", 8, 24, "bits", "position quantisation of the particle codec", 0, .group = "output"),
    {FL_AT(velocities), .group = "output", .type = PARAM_BOOL, .def = "false", .unit = "",
     .doc = "also send each particle's velocity (x space_scale), for velocity lines: about 0.9 byte more per "
            "particle"},
    FL_I(vel_bits, "8", 4, 12, "bits", "velocity quantisation per component, sign included (with velocities)", 0,
         .group = "output"),
    {0},
};

/* Built-in presets (presets.h). "thesis-table3.1" is the thesis's base scene: Table 3.1's h and
 * dt with a free-floating 3 cm disc (digest §3: source geometry [P]) and no air (wind_drag 0:
 * the thesis has none); 34 substeps keep its 1 ms steps in real time at 30 fps. The others are
 * looks on the default scale. */
const struct effect_preset flame_presets[] = {
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
    /* The default flame's shape at GPU scale: 5.4x the default's particles per volume (h 2 mm
     * against 3.5 mm) over an 8 cm disc with 1.5x the fuel, on a plate 2 mm below it. */
    {"large", "a big flame for GPUs: an 8 cm burner at fine resolution (h 2 mm), about 220k particles and 19 cm "
              "tall; real time needs about 75 M particle-steps/s",
     "{\"h\":0.002,\"sources\":[{\"radius\":0.04,\"F_init\":150}],"
     "\"obstacles\":[{\"shape\":\"plate\",\"size\":[0.096,0.096,0],\"pos\":[0,0,-0.002],\"velocity\":[0,0,0]}]}"},
    {0},
};

/* ---- the kernels' parameter array ----------------------------------------------------- */

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

void flame_params_up(const struct flame_config *c, double up[3])
{
    memcpy(up, c->up, sizeof c->up);
    vec3_normalize(up); /* never zero: PARAM_NONZERO */
}

void flame_params_pack(const struct flame_config *c, float P[FP_COUNT])
{
    double h = c->h, d = c->particle_diameter * h, m = c->mass, up[3];
    if (m <= 0) m = c->rho_rest / fl_poly6_sum(h, d); /* §9 #6: 1.7626e-7 kg for the thesis's h */
    memset(P, 0, FP_COUNT * sizeof *P);
    params_pack(flame_params, c, P);
    P[FP_H] = (float)h;
    P[FP_H2] = (float)(h * h);
    P[FP_INV_CELL] = (float)(FL_CELLS_PER_H / h);
    P[FP_INV_CELLX] = (float)(FL_CELLS_PER_H * FL_XCELLS / h);
    P[FP_MASS] = (float)m;
    P[FP_POLY6] = (float)(m * 315.0 / (64.0 * M_PI * pow(h, 9)));
    P[FP_SPIKY] = (float)(45.0 / (M_PI * pow(h, 6)));
    P[FP_GPOLY6] = (float)(m * 945.0 / (32.0 * M_PI * pow(h, 9)));
    flame_params_up(c, up);
    for (int k = 0; k < 3; k++) P[FP_UP + k] = (float)up[k];
    /* the drag's exact relaxation over one step (kernels/flame.cl fl_forces) */
    P[FP_DRAG] = (float)-expm1(-c->wind_drag * c->dt);
    P[FP_DIAM] = (float)d;
    P[FP_VMAX] = (float)FLAME_VMAX;
}
