/* compound_eye.c — effect `compound_eye` (seed 004, Sagawa 2014; spec: digest 004).
 *
 * Owns the parameter table, the host side of kernels/compound_eye.cl and the two modes:
 * "lut" regenerates the lens table (eye_lut.h) only when a parameter that shapes it
 * changes and then emits it once, as one kind 4 frame (the hub keeps the latest frame
 * per kind for late subscribers, so all products travel together); "bake" renders the
 * model's view texture (eye_model.h) and emits a kind 2 EXR whenever anything changed.
 * A step with nothing new emits nothing. A table or view that would hold the engine past its
 * slice (effect.h) is traced a range of work-items at a time, read back once whole, and a
 * table is then packed in pieces too (eye_lut.h): the same work-items compute the same
 * samples, so the products do not depend on the slicing. Both are computed only after a change
 * or a reset, which end the life of the frame emitted before (effect.h), so they are computed in
 * place of its table or texels. On a CPU both trace their rays in the order of what each cost
 * the run before (eye_order.h: on the default view 2.7 passes a traced texel, but 5.2 for the
 * slowest of 16 neighbours in atlas order); the first run of a size goes in index order. */
#include "compound_eye.h"

#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "buf.h"
#include "../clock.h"
#include "exr.h"
#include "../effect.h"
#include "../ocl.h"
#include "../slice.h"
#include "eye_lut.h"
#include "eye_model.h"
#include "eye_order.h"
#include "fxs_frame.h"


/* An enum parameter's value is its index here: the constants of compound_eye_layout.h and
 * compound_eye_params.h. */
static const char *const eye_mode_names[] = {[EYE_MODE_LUT] = "lut", [EYE_MODE_BAKE] = "bake", NULL};
static const char *const eye_lattice_names[] = {[EYE_SQUARE] = "square", [EYE_HEX] = "hex", NULL};
static const char *const eye_search_names[] = {[EYE_SEARCH_EXACT] = "exact", [EYE_SEARCH_SLICES] = "slices", NULL};
static const char *const eye_select_names[] = {[EYE_SELECT_ALL] = "all", [EYE_SELECT_THESIS4] = "thesis4", NULL};
static const char *const eye_tir_names[] = {[EYE_TIR_REFLECT] = "reflect", [EYE_TIR_MISS] = "miss", [EYE_TIR_ABSORB] = "absorb",
                                            NULL};
static const char *const eye_normal_names[] = {[EYE_NORMAL_OBJECT] = "object", [EYE_NORMAL_LENS] = "lens", NULL};

/* ---- parameters -------------------------------------------------------------------- */

#define EYE_LUT_DOC(text) text " (regenerates the lens table)"
#define EYE_AT(member) PARAM_AT(struct compound_eye_config, member)
#define EYE_COLOR(nm, dflt, what, ...) \
    {EYE_AT(nm), .type = PARAM_COLOR, .def = dflt, .min = 0, .max = 1, .unit = "linear RGB", .doc = EYE_LUT_DOC(what), __VA_ARGS__}
#define EYE_FRAC(nm, dflt, lo, hi, what, ...) \
    {EYE_AT(nm), .type = PARAM_FLOAT, .def = dflt, .min = lo, .max = hi, .unit = "pitch", .doc = EYE_LUT_DOC(what), __VA_ARGS__}
#define EYE_COEF(nm, dflt, what, ...) \
    {EYE_AT(nm), .type = PARAM_FLOAT, .def = dflt, .min = 0, .max = 1, .unit = "", .doc = what, __VA_ARGS__}

const struct param_def compound_eye_params[] = {
    {EYE_AT(mode), .group = "output", .type = PARAM_ENUM, .def = "\"lut\"", .choices = eye_mode_names, .unit = "", .flags = PARAM_RESTART,
     .doc = "lut: send the lens look-up table (kind 4) on each change that affects it, the client shades; "
            "bake: send the model's shaded view texture (kind 2 EXR) on each change"},
    {EYE_AT(lattice), .group = "lenses", .type = PARAM_ENUM, .def = "\"hex\"", .choices = eye_lattice_names, .unit = "",
     .doc = EYE_LUT_DOC("lens lattice: square (Sagawa 2014, 4 side pupils) or hex (real eyes, 6 side pupils)")},
    {EYE_AT(density), .group = "lenses", .type = PARAM_FLOAT, .def = "60", .min = 1, .max = 1000, .unit = "cells per UV unit",
     .doc = "ommatidium density R_t (Sagawa 2014 eq. 5.1): higher, more and smaller lenses; a client uniform in "
            "mode lut (the thesis: 300 on its own UV layout)"},
    EYE_FRAC(lens_radius, "1.0", 0.5, 3.0,
             "lens sphere radius r / pitch; gap-free coverage needs >= 0.7071 (square) or >= 0.5774 (hex)", .group = "lenses"),
    {EYE_AT(refractive_index), .group = "lenses", .type = PARAM_FLOAT, .def = "1.491", .min = 1.05, .max = 1.95, .unit = "",
     .doc = EYE_LUT_DOC("lens refractive index n (Sagawa 2014: 1.491, PMMA)")},
    {EYE_AT(pigment_depth), .group = "lenses", .type = PARAM_FLOAT, .def = "2.0", .min = 2.0, .max = 4.0, .unit = "lens radii",
     .doc = EYE_LUT_DOC("depth of the pigment plane below the surface (Sagawa 2014: 2r; below 2r it would cut the lenses)")},
    {EYE_AT(max_passes), .group = "rays", .type = PARAM_INT, .def = "8", .min = 0, .max = 64, .unit = "",
     .doc = EYE_LUT_DOC("l: neighbouring lenses a ray may pass through (0: exit the first lens; >= 3 converged)")},
    {EYE_AT(sphere_search), .group = "rays", .type = PARAM_ENUM, .def = "\"exact\"", .choices = eye_search_names, .unit = "",
     .doc = EYE_LUT_DOC("entry lens: exact (walk the crossed cells) or slices (Sagawa 2014's slice planes)")},
    {EYE_AT(slice_steps), .group = "rays", .type = PARAM_INT, .def = "16", .min = 4, .max = 64, .unit = "",
     .doc = EYE_LUT_DOC("slice planes down to depth r, with sphere_search slices")},
    {EYE_AT(neighbor_select), .group = "rays", .type = PARAM_ENUM, .def = "\"all\"", .choices = eye_select_names, .unit = "",
     .doc = EYE_LUT_DOC("next lens: all (any overlapping lens, farthest exit wins) or thesis4 (Sagawa 2014 "
                        "Fig. 5.10: only the 3 neighbouring lenses on the side the ray is heading to)")},
    {EYE_AT(tir_policy), .group = "rays", .type = PARAM_ENUM, .def = "\"reflect\"", .choices = eye_tir_names, .unit = "",
     .doc = EYE_LUT_DOC("total internal reflection at exit: reflect (up to 4 times, then miss), miss (base "
                        "colour) or absorb (pigment colour)")},
    EYE_FRAC(dot_radius, "0.2", 0.05, 0.5, "pigment dot radius", .group = "pigment"),
    EYE_FRAC(dot_softness, "0.03", 0.0, 0.2, "width of the dot's smoothstep edge", .group = "pigment"),
    EYE_COLOR(dot_color, "[0.03,0.008,0.005]", "pigment dot colour", .group = "pigment"),
    EYE_COLOR(base_color, "[0.42,0.06,0.03]", "pigment-free (body fluid) colour, also what missed rays see", .group = "pigment"),
    EYE_FRAC(ring_inner, "0.21", 0.0, 0.5, "inner radius of an optional pigment ring (off when ring_outer <= ring_inner)", .group = "pigment"),
    EYE_FRAC(ring_outer, "0.3", 0.0, 0.5, "outer radius of the optional pigment ring", .group = "pigment"),
    EYE_COLOR(ring_color, "[0.16,0.03,0.015]", "ring colour", .group = "pigment"),
    EYE_FRAC(glow_radius, "0", 0.0, 0.5, "radius of an optional additive central glow (0: off)", .group = "pigment"),
    EYE_COLOR(glow_color, "[0.6,0.15,0.05]", "central glow colour (added)", .group = "pigment"),
    {EYE_AT(pigment_res), .group = "pigment", .type = PARAM_INT, .def = "128", .min = 32, .max = 256, .unit = "texels",
     .doc = EYE_LUT_DOC("pigment tile width (height x sqrt 3 on the hex lattice)")},
    {EYE_AT(lut_cells), .group = "table", .type = PARAM_INT, .def = "32", .min = 8, .max = 64, .unit = "texels",
     .doc = EYE_LUT_DOC("C: in-cell samples per axis of each direction tile")},
    {EYE_AT(lut_dirs), .group = "table", .type = PARAM_INT, .def = "32", .min = 8, .max = 64, .unit = "tiles",
     .doc = EYE_LUT_DOC("D: direction tiles per axis (hemi-octahedral map)")},
    {EYE_AT(lut_supersample), .group = "table", .type = PARAM_INT, .def = "1", .min = 1, .max = 8, .unit = "",
     .doc = EYE_LUT_DOC("SS: SS x SS rays per table texel, over its footprint in the cell (1: a table "
                        "change takes some 30-40 ms on 2 CPU cores; 2 is 4x the rays)")},
    EYE_COEF(ka, "0.2", "ambient coefficient a of the Phong shading (Sagawa 2014 eq. 5.31; a client uniform in mode lut)", .group = "shading"),
    EYE_COEF(kd, "0.8", "diffuse coefficient d of the Phong shading (Sagawa 2014 eq. 5.31)", .group = "shading"),
    EYE_COEF(ks, "0.3", "specular coefficient s of the Phong shading (Sagawa 2014 eq. 5.31)", .group = "shading"),
    {EYE_AT(shininess), .group = "shading", .type = PARAM_FLOAT, .def = "32", .min = 1, .max = 256, .unit = "",
     .doc = "Phong exponent of the specular term"},
    {EYE_AT(shading_normal), .group = "shading", .type = PARAM_ENUM, .def = "\"lens\"", .choices = eye_normal_names, .unit = "",
     .doc = "normal for Phong: lens (the lens sphere at the entry point, Sagawa 2014 Fig. 6.20 c-d) or object"},
    {EYE_AT(model), .group = "bake", .type = PARAM_ENUM, .def = "\"hemisphere\"", .choices = eye_model_names, .unit = "",
     .flags = PARAM_RESTART,
     .doc = "mode bake: a built-in model or the name of an OBJ file (without .obj) in the assets directory"},
    {EYE_AT(bake_size), .group = "bake", .type = PARAM_INT, .def = "512", .min = 128, .max = 2048, .unit = "texels",
     .flags = PARAM_RESTART, .doc = "mode bake: width and height of the view texture"},
    {EYE_AT(eye), .group = "bake", .type = PARAM_VEC3, .def = "[0.4,0.3,3]", .min = -1000, .max = 1000, .unit = "model units",
     .doc = "mode bake: eye position in the model's space"},
    {EYE_AT(light), .group = "bake", .type = PARAM_VEC3, .def = "[0.4,0.6,1]", .min = -1000, .max = 1000, .unit = "direction",
     .flags = PARAM_NONZERO, .doc = "mode bake: direction towards the light, normalised by the server"},
    {EYE_AT(compression), .group = "bake", .type = PARAM_ENUM, .def = "\"rle\"", .choices = exr_codec_names, .unit = "",
     .doc = "mode bake: OpenEXR compression of the view texture"},
    {EYE_AT(fps), .group = "output", .type = PARAM_FLOAT, .def = "30", .min = 1, .max = 120, .unit = "1/s",
     .doc = "steps per second; a step sends a frame only when something changed"},
    {0},
};

/* Built-in presets (presets.h): the thesis's settings (digest 004 §3: square lattice, R_t 300,
 * n 1.491, texture plane at 2r, the slice-plane search and 3-candidate neighbour rule, l of the
 * order of 10) with the digest's plain pigment (a black dot on pale grey, §8.3), its Fig. 6.18
 * density sweep at 50, and artist looks on the default hex eye (a red-brown fly eye). */
#define EYE_PLAIN_PIGMENT "\"base_color\":[0.8,0.78,0.72],\"dot_color\":[0.02,0.02,0.02],\"ring_inner\":0,\"ring_outer\":0"
static const struct effect_preset compound_eye_presets[] = {
    {"thesis", "the thesis's settings: square lattice, R_t 300, n 1.491, slice search, thesis4 neighbours, l = 10",
     "{\"lattice\":\"square\",\"density\":300,\"refractive_index\":1.491,\"pigment_depth\":2.0,"
     "\"sphere_search\":\"slices\",\"neighbor_select\":\"thesis4\",\"max_passes\":10," EYE_PLAIN_PIGMENT "}"},
    {"thesis-fig6.18-r50", "Fig. 6.18 at R_t 50: the thesis's square lattice, coarse enough to see each lens",
     "{\"lattice\":\"square\",\"density\":50,\"sphere_search\":\"slices\",\"neighbor_select\":\"thesis4\","
     "\"max_passes\":10," EYE_PLAIN_PIGMENT "}"},
    {"insect-hex", "a red-brown fly eye, hex lattice at density 60: one central and six side pseudopupils, dark-ringed "
                   "(the default stream)", "{}"},
    {"jewel-beetle", "artist look: green-gold lenses with a soft inner glow and a glossy highlight",
     "{\"base_color\":[0.16,0.42,0.22],\"dot_color\":[0.01,0.04,0.02],\"ring_inner\":0,\"ring_outer\":0,\"glow_radius\":0.16,"
     "\"glow_color\":[0.35,0.55,0.1],\"ks\":0.6,\"shininess\":80}"},
    {"fly-red", "artist look: a brighter orange-red fly eye with dark-ringed pupils",
     "{\"base_color\":[0.55,0.1,0.06],\"dot_color\":[0.04,0.01,0.01],\"ring_inner\":0.21,\"ring_outer\":0.3,"
     "\"ring_color\":[0.22,0.04,0.02]}"},
    {0},
};

/* Every parameter whose change regenerates the lens table (mode lut). */
static const size_t eye_lut_keys[] = {
    offsetof(struct compound_eye_config, lattice), offsetof(struct compound_eye_config, lens_radius),
    offsetof(struct compound_eye_config, refractive_index), offsetof(struct compound_eye_config, pigment_depth),
    offsetof(struct compound_eye_config, max_passes), offsetof(struct compound_eye_config, sphere_search),
    offsetof(struct compound_eye_config, slice_steps), offsetof(struct compound_eye_config, neighbor_select),
    offsetof(struct compound_eye_config, tir_policy), offsetof(struct compound_eye_config, dot_radius),
    offsetof(struct compound_eye_config, dot_softness), offsetof(struct compound_eye_config, dot_color),
    offsetof(struct compound_eye_config, base_color), offsetof(struct compound_eye_config, ring_inner),
    offsetof(struct compound_eye_config, ring_outer), offsetof(struct compound_eye_config, ring_color),
    offsetof(struct compound_eye_config, glow_radius), offsetof(struct compound_eye_config, glow_color),
    offsetof(struct compound_eye_config, pigment_res), offsetof(struct compound_eye_config, lut_cells),
    offsetof(struct compound_eye_config, lut_dirs), offsetof(struct compound_eye_config, lut_supersample),
};

/* ---- state ------------------------------------------------------------------------- */

struct compound_eye {
    struct ocl *ocl;
    cl_kernel k_lut, k_bake, k_gather;
    int lanes;                      /* rays per work-item of the kernels (compound_eye_program) */
    struct compound_eye_config cfg; /* the parameters in use */
    bool configured;                /* cfg holds a set */
    int mode, dirty; /* dirty: the next step has something new to send */
    struct eye_optics optics;
    struct eye_pigment pigment;
    float *pig;      /* pigment tile, pw x ph RGBA */
    int pw, ph;
    cl_mem d_pig, d_lut, d_geo, d_out, d_tiles;
    size_t d_pig_bytes, d_lut_bytes, d_tiles_bytes;
    float *samples;  /* LUT kernel output, for the traced tiles (eye_lut.h) */
    int symmetry, traced; /* the table's mirrors (eye_lut.h) and the tiles traced under them */
    struct fx_buf table;
    /* bake */
    int size, compression;
    float *rgba;
    cl_mem d_atlas; /* the model's atlas, 16 floats a texel (d_geo: laid out in the order) */
    struct fx_buf exr;
    /* the table or view in progress (eye_step): its stage, the kernel's work-items done and
     * what one costs, the packer of a table, and its time */
    int busy;
    size_t done;
    struct slice_meter meter;
    struct eye_lut_packer packer;
    double pack_ms;
    struct compound_eye_split split; /* of the last table or view */
    struct eye_order order;          /* the rays' order, of the table or of the view */
};

enum { EYE_IDLE, EYE_TRACING, EYE_PACKING };
#define EYE_GROUP 64 /* work-items of a group (eye_items) */

/* Drops the table or view in progress. */
static void eye_abandon(struct compound_eye *ce)
{
    if (ce->busy == EYE_PACKING) eye_lut_pack_free(&ce->packer);
    ce->busy = EYE_IDLE;
}

void eye_optics_from_params(const struct compound_eye_config *p, struct eye_optics *o)
{
    memset(o, 0, sizeof *o);
    o->lattice = p->lattice;
    o->r = (float)p->lens_radius;
    o->n = (float)p->refractive_index;
    o->plane = (float)(p->pigment_depth * p->lens_radius);
    o->tile_h = o->lattice == EYE_HEX ? (float)EYE_SQRT3 : 1.0f;
    o->max_passes = p->max_passes;
    o->search = p->sphere_search;
    o->slices = p->slice_steps;
    o->select = p->neighbor_select;
    o->tir = p->tir_policy;
}

void eye_pigment_from_params(const struct compound_eye_config *p, struct eye_pigment *pg)
{
    pg->lattice = p->lattice;
    pg->dot_radius = p->dot_radius;
    pg->softness = p->dot_softness;
    pg->ring_inner = p->ring_inner;
    pg->ring_outer = p->ring_outer;
    pg->glow_radius = p->glow_radius;
    memcpy(pg->dot, p->dot_color, sizeof pg->dot);
    memcpy(pg->base, p->base_color, sizeof pg->base);
    memcpy(pg->ring, p->ring_color, sizeof pg->ring);
    memcpy(pg->glow, p->glow_color, sizeof pg->glow);
}

static bool eye_table_changed(const struct compound_eye_config *a, const struct compound_eye_config *b)
{
    for (size_t i = 0; i < sizeof eye_lut_keys / sizeof eye_lut_keys[0]; i++)
        if (!params_same(params_at(compound_eye_params, eye_lut_keys[i]), a, b)) return true;
    return false;
}

static cl_mem eye_buffer(struct compound_eye *ce, cl_mem_flags flags, size_t bytes, void *host, struct fx_err *err)
{
    cl_int rc;
    cl_mem m = clCreateBuffer(ocl_context(ce->ocl), flags, bytes, host, &rc);
    if (rc != CL_SUCCESS) fx_fail(err, "internal", "", "clCreateBuffer(%zu bytes): %s", bytes, ocl_errstr(rc));
    return m;
}

/* Recomputes the pigment tile and uploads it (buffer regrown when needed). */
static int eye_pigment_upload(struct compound_eye *ce, int res, struct fx_err *err)
{
    double t0 = clock_now();
    eye_pigment_size(res, ce->pigment.lattice, &ce->pw, &ce->ph);
    size_t bytes = (size_t)ce->pw * ce->ph * 4 * sizeof(float);
    float *pig = realloc(ce->pig, bytes);
    if (!pig) return fx_fail(err, "internal", "", "out of memory for the pigment tile");
    ce->pig = pig;
    eye_pigment_tile(&ce->pigment, ce->pw, ce->ph, ce->pig);
    if (bytes > ce->d_pig_bytes) {
        if (ce->d_pig) clReleaseMemObject(ce->d_pig);
        ce->d_pig_bytes = 0;
        if (!(ce->d_pig = eye_buffer(ce, CL_MEM_READ_ONLY, bytes, NULL, err))) return -1;
        ce->d_pig_bytes = bytes;
    }
    cl_int rc = clEnqueueWriteBuffer(ocl_queue(ce->ocl), ce->d_pig, CL_TRUE, 0, bytes, ce->pig, 0, NULL, NULL);
    ce->split.pigment = (clock_now() - t0) * 1e3;
    return rc == CL_SUCCESS ? 0 : fx_fail(err, "internal", "", "pigment upload: %s", ocl_errstr(rc));
}

int compound_eye_set(struct compound_eye *ce, const struct compound_eye_config *params, struct fx_err *err)
{
    eye_abandon(ce);
    ce->meter = (struct slice_meter){.probe = 1}; /* counted in work-groups */
    if (!ce->configured || ce->mode == EYE_MODE_BAKE || eye_table_changed(&ce->cfg, params)) ce->dirty = 1;
    ce->cfg = *params;
    ce->configured = true;
    eye_optics_from_params(params, &ce->optics);
    eye_pigment_from_params(params, &ce->pigment);
    ce->compression = params->compression;
    return eye_pigment_upload(ce, params->pigment_res, err);
}

/* ---- OpenCL ------------------------------------------------------------------------ */

/* Mirrors struct eye_shading in kernels/compound_eye.cl. */
struct eye_shading {
    cl_float4 eye, light;
    float ka, kd, ks, shininess, density;
    int lens_normal, pad0, pad1;
};

static cl_float4 eye_f4(const double v[3], double w)
{
    cl_float4 f = {{(float)v[0], (float)v[1], (float)v[2], (float)w}};
    return f;
}

int compound_eye_build_options(struct ocl *ocl, char *opts)
{
    cl_uint width = 0;
    if (clGetDeviceInfo(ocl_device(ocl), CL_DEVICE_PREFERRED_VECTOR_WIDTH_FLOAT, sizeof width, &width, NULL) != CL_SUCCESS)
        width = 0;
    int lanes = width >= 16 ? 16 : 8;
    snprintf(opts, COMPOUND_EYE_OPTS_MAX, "%s -DEYE_LANES=%d", COMPOUND_EYE_CL_OPTS, lanes);
    return lanes;
}

static int eye_kernels_create(struct compound_eye *ce, struct fx_err *err)
{
    cl_int rc;
    char opts[COMPOUND_EYE_OPTS_MAX];
    ce->lanes = compound_eye_build_options(ce->ocl, opts);
    cl_program prog = ocl_program(ce->ocl, COMPOUND_EYE_CL, opts, err);
    if (!prog) return -1;
    ce->k_lut = clCreateKernel(prog, "eye_lut", &rc);
    if (rc == CL_SUCCESS) ce->k_bake = clCreateKernel(prog, "eye_bake", &rc);
    if (rc == CL_SUCCESS) ce->k_gather = clCreateKernel(prog, "eye_bake_gather", &rc);
    return rc == CL_SUCCESS ? 0 : fx_fail(err, "internal", "", "clCreateKernel: %s", ocl_errstr(rc));
}

/* Work-items for n rays, each tracing ce->lanes of them (kernels/compound_eye.cl), in whole
 * groups of EYE_GROUP (the kernels store nothing past n). On a CPU device each group is a
 * work-group, every launch alike, since PoCL compiles a kernel once per work-group size; a GPU's
 * driver chooses its own. */
static size_t eye_items(const struct compound_eye *ce, size_t n)
{
    size_t lanes = (size_t)ce->lanes, items = (n + lanes - 1) / lanes;
    return (items + EYE_GROUP - 1) / EYE_GROUP * EYE_GROUP;
}

/* Device milliseconds of a completed profiling event (0 when the queue does not profile). */
static double eye_event_ms(cl_event ev)
{
    cl_ulong t0 = 0, t1 = 0;
    if (clGetEventProfilingInfo(ev, CL_PROFILING_COMMAND_START, sizeof t0, &t0, NULL) != CL_SUCCESS ||
        clGetEventProfilingInfo(ev, CL_PROFILING_COMMAND_END, sizeof t1, &t1, NULL) != CL_SUCCESS)
        return 0.0;
    return t1 > t0 ? (double)(t1 - t0) * 1e-6 : 0.0;
}

/* Starts the split of a table or view (the pigment's time is its parameters'). */
static void eye_split_start(struct compound_eye *ce)
{
    ce->split = (struct compound_eye_split){.pigment = ce->split.pigment};
}

void compound_eye_split(const struct compound_eye *ce, struct compound_eye_split *out)
{
    *out = ce->split;
    out->launch_read = fmax(ce->split.launch_read - ce->split.kernel, 0.0);
}

/* Runs kernel k (its arguments set) over its 1-D range of work-items for n rays from work-group
 * ce->done on, a piece at a time until slice_end, waiting for each. 0 when every work-item ran,
 * EFFECT_MORE, or -1 with err. */
static int eye_run(struct compound_eye *ce, cl_kernel k, const char *name, size_t n, double slice_end,
                   struct fx_err *err)
{
    const size_t groups = eye_items(ce, n) / EYE_GROUP, local = EYE_GROUP;
    const size_t *wg = ocl_is_cpu(ce->ocl) ? &local : NULL;
    double t0 = clock_now();
    do {
        size_t m = slice_units(&ce->meter, groups - ce->done, t0, slice_end);
        size_t offset = ce->done * EYE_GROUP, global = m * EYE_GROUP;
        cl_event ev;
        cl_int rc = clEnqueueNDRangeKernel(ocl_queue(ce->ocl), k, 1, &offset, &global, wg, 0, NULL, &ev);
        if (rc != CL_SUCCESS) return fx_fail(err, "internal", "", "%s: %s", name, ocl_errstr(rc));
        rc = clWaitForEvents(1, &ev);
        if (rc == CL_SUCCESS) {
            ocl_record(ce->ocl, name, ev);
            ce->split.kernel += eye_event_ms(ev);
        }
        clReleaseEvent(ev);
        if (rc != CL_SUCCESS) return fx_fail(err, "internal", "", "%s: %s", name, ocl_errstr(rc));
        ce->done += m;
        double t1 = clock_now();
        ce->split.launch_read += (t1 - t0) * 1e3;
        slice_record(&ce->meter, m, t1 - t0);
        t0 = t1;
    } while (ce->done < groups && t0 < slice_end);
    return ce->done < groups ? EFFECT_MORE : 0;
}

/* After a complete run of n rays: their results (float4 each) read back from out into host, in
 * ray order, and the next run's order (eye_order_update: 1 when it changed). -1 with err. */
static int eye_run_finish(struct compound_eye *ce, cl_mem out, float *host, size_t n, struct fx_err *err)
{
    double t0 = clock_now();
    cl_int rc = clEnqueueReadBuffer(ocl_queue(ce->ocl), out, CL_TRUE, 0, n * 4 * sizeof(float), host, 0, NULL, NULL);
    if (rc != CL_SUCCESS) return fx_fail(err, "internal", "", "read-back of %zu rays: %s", n, ocl_errstr(rc));
    int r = eye_order_update(&ce->order, ce->ocl, err);
    ce->split.lane_use = ce->order.lane_use;
    ce->split.launch_read += (clock_now() - t0) * 1e3;
    return r;
}

/* ---- mode lut ---------------------------------------------------------------------- */

/* The table's dimensions from the parameters. */
static void eye_table_dims(const struct compound_eye *ce, int *cells, int *dirs, int *ss)
{
    *cells = ce->cfg.lut_cells;
    *dirs = ce->cfg.lut_dirs;
    *ss = ce->cfg.lut_supersample;
}

/* Chooses the table's symmetry and uploads the tiles to trace under it (buffer regrown when
 * needed). */
static int eye_lut_tiles_upload(struct compound_eye *ce, int cells, int dirs, struct fx_err *err)
{
    size_t bytes = (size_t)dirs * dirs * sizeof(cl_int);
    cl_int *tiles = malloc(bytes);
    if (!tiles) return fx_fail(err, "internal", "", "out of memory for the table's tiles");
    ce->symmetry = eye_lut_symmetry(ce->optics.lattice, cells, ce->ph);
    ce->traced = eye_lut_traced_tiles(dirs, ce->symmetry, tiles);
    if (bytes > ce->d_tiles_bytes) {
        if (ce->d_tiles) clReleaseMemObject(ce->d_tiles);
        ce->d_tiles_bytes = 0;
        if (!(ce->d_tiles = eye_buffer(ce, CL_MEM_READ_ONLY, bytes, NULL, err))) {
            free(tiles);
            return -1;
        }
        ce->d_tiles_bytes = bytes;
    }
    cl_int rc = clEnqueueWriteBuffer(ocl_queue(ce->ocl), ce->d_tiles, CL_TRUE, 0, (size_t)ce->traced * sizeof(cl_int),
                                     tiles, 0, NULL, NULL);
    free(tiles);
    return rc == CL_SUCCESS ? 0 : fx_fail(err, "internal", "", "upload of the table's tiles: %s", ocl_errstr(rc));
}

/* Starts a table: the sample buffers (regrown when needed) and the LUT kernel's arguments. */
static int eye_lut_start(struct compound_eye *ce, struct fx_err *err)
{
    int cells, dirs, ss;
    eye_table_dims(ce, &cells, &dirs, &ss);
    if (eye_lut_tiles_upload(ce, cells, dirs, err)) return -1;
    size_t n = (size_t)cells * cells * ce->traced, bytes = n * 4 * sizeof(float);
    if (bytes > ce->d_lut_bytes) {
        float *s = realloc(ce->samples, bytes);
        if (!s) return fx_fail(err, "internal", "", "out of memory for %zu table samples", n);
        ce->samples = s;
        if (ce->d_lut) clReleaseMemObject(ce->d_lut);
        ce->d_lut_bytes = 0;
        if (!(ce->d_lut = eye_buffer(ce, CL_MEM_WRITE_ONLY, bytes, NULL, err))) return -1;
        ce->d_lut_bytes = bytes;
    }
    size_t npad = eye_items(ce, n) * (size_t)ce->lanes; /* a table of another size: index order */
    if ((n != ce->order.n || npad != ce->order.npad) && eye_order_reset(&ce->order, ce->ocl, n, npad, ce->lanes, err))
        return -1;
    cl_float4 dot = eye_f4(ce->pigment.dot, 1.0), base = eye_f4(ce->pigment.base, 0.0);
    const struct ocl_arg a[] = {
        {sizeof(cl_mem), &ce->d_lut}, {sizeof(cl_mem), &ce->order.d_cost}, {sizeof(cl_mem), &ce->order.d_order},
        {sizeof(cl_mem), &ce->d_pig}, {sizeof(int), &ce->pw}, {sizeof(int), &ce->ph}, {sizeof ce->optics, &ce->optics},
        {sizeof(cl_mem), &ce->d_tiles}, {sizeof(int), &ce->traced}, {sizeof(int), &cells}, {sizeof(int), &dirs},
        {sizeof(int), &ss}, {sizeof dot, &dot}, {sizeof base, &base}};
    ce->done = 0;
    ce->pack_ms = 0;
    eye_split_start(ce);
    return ocl_set_args(ce->k_lut, "eye_lut", a, 14, err);
}

/* Starts packing the traced samples. */
static int eye_lut_pack_start(struct compound_eye *ce, struct fx_err *err)
{
    struct eye_lut_table t = {
        .lattice = ce->optics.lattice,
        .max_passes = ce->optics.max_passes,
        .tile_h = ce->optics.tile_h,
        .lens_radius = ce->optics.r,
        .refractive_index = ce->optics.n,
        .pigment_depth = (float)ce->cfg.pigment_depth,
        .pigment = ce->pig,
        .pw = ce->pw,
        .ph = ce->ph,
        .samples = ce->samples,
        .symmetry = ce->symmetry,
    };
    eye_table_dims(ce, &t.cells, &t.dirs, &t.supersample);
    return eye_lut_pack_begin(&ce->packer, &t, &ce->table, err);
}

/* Works on the table until slice_end: traces its samples, then packs them. 0 when ce->table
 * holds the container, EFFECT_MORE, or -1 with err. */
static int eye_table_slice(struct compound_eye *ce, double slice_end, struct fx_err *err)
{
    int rc = 0;
    if (ce->busy == EYE_IDLE) {
        if (eye_lut_start(ce, err)) return -1;
        ce->busy = EYE_TRACING;
    }
    if (ce->busy == EYE_TRACING) {
        int cells, dirs, ss;
        eye_table_dims(ce, &cells, &dirs, &ss);
        size_t n = (size_t)cells * cells * ce->traced;
        rc = eye_run(ce, ce->k_lut, "eye_lut", n, slice_end, err);
        if (!rc && eye_run_finish(ce, ce->d_lut, ce->samples, n, err) < 0) rc = -1;
        if (!rc && !(rc = eye_lut_pack_start(ce, err))) ce->busy = EYE_PACKING;
        if (!rc && clock_now() >= slice_end) rc = EFFECT_MORE;
    }
    if (ce->busy == EYE_PACKING && !rc) {
        double t0 = clock_now();
        rc = eye_lut_pack_run(&ce->packer, slice_end, err);
        ce->pack_ms += (clock_now() - t0) * 1e3;
        rc = rc > 0 ? EFFECT_MORE : rc;
        ce->split.atlas = ce->packer.stage_ms[0];
        ce->split.macro = ce->packer.stage_ms[1];
        ce->split.zstd = ce->packer.stage_ms[2];
        if (!rc) eye_abandon(ce); /* done: frees the packer */
    }
    if (rc < 0) eye_abandon(ce);
    return rc;
}

int compound_eye_table(struct compound_eye *ce, const void **data, size_t *len, struct fx_err *err)
{
    eye_abandon(ce);
    if (eye_table_slice(ce, INFINITY, err)) return -1;
    *data = ce->table.data;
    *len = ce->table.len;
    return 0;
}

/* ---- mode bake --------------------------------------------------------------------- */

/* Lays the view's geometry out in the rays' order (eye_bake_gather). */
static int eye_bake_layout(struct compound_eye *ce, struct fx_err *err)
{
    int npad = (int)ce->order.npad;
    size_t global = ce->order.npad;
    const struct ocl_arg a[] = {
        {sizeof(cl_mem), &ce->d_geo}, {sizeof(cl_mem), &ce->d_atlas}, {sizeof(cl_mem), &ce->order.d_order},
        {sizeof(int), &npad}};
    if (ocl_set_args(ce->k_gather, "eye_bake_gather", a, 4, err)) return -1;
    cl_int rc = clEnqueueNDRangeKernel(ocl_queue(ce->ocl), ce->k_gather, 1, NULL, &global, NULL, 0, NULL, NULL);
    if (rc == CL_SUCCESS) rc = clFinish(ocl_queue(ce->ocl));
    return rc == CL_SUCCESS ? 0 : fx_fail(err, "internal", "", "eye_bake_gather: %s", ocl_errstr(rc));
}

static int eye_bake_setup(struct compound_eye *ce, const struct compound_eye_config *p, struct fx_err *err)
{
    struct eye_mesh mesh;
    ce->size = p->bake_size;
    size_t texels = (size_t)ce->size * ce->size, npad = eye_items(ce, texels) * (size_t)ce->lanes;
    if (eye_model_load(eye_model_names[p->model], &mesh, err)) return -1;
    /* the atlas, 16 floats a texel (eye_model.h), for npad texels: the padding is uncovered */
    float *atlas = calloc(npad * 16, sizeof(float));
    ce->rgba = malloc(texels * 4 * sizeof(float));
    if (!atlas || !ce->rgba) {
        free(atlas);
        eye_mesh_free(&mesh);
        return fx_fail(err, "internal", "", "out of memory for a %d^2 bake", ce->size);
    }
    eye_model_atlas(&mesh, ce->size, atlas);
    eye_mesh_free(&mesh);
    ce->d_atlas = eye_buffer(ce, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, npad * 16 * sizeof(float), atlas, err);
    free(atlas);
    if (!ce->d_atlas || !(ce->d_geo = eye_buffer(ce, CL_MEM_READ_WRITE, npad * 16 * sizeof(float), NULL, err)) ||
        !(ce->d_out = eye_buffer(ce, CL_MEM_WRITE_ONLY, texels * 4 * sizeof(float), NULL, err)) ||
        eye_order_reset(&ce->order, ce->ocl, texels, npad, ce->lanes, err))
        return -1;
    return eye_bake_layout(ce, err);
}

int compound_eye_bake_size(const struct compound_eye *ce) { return ce->size; }

/* Starts a view: the bake kernel's arguments. */
static int eye_bake_start(struct compound_eye *ce, struct fx_err *err)
{
    const struct compound_eye_config *p = &ce->cfg;
    double eye[3], light[3];
    memcpy(eye, p->eye, sizeof eye);
    memcpy(light, p->light, sizeof light);
    double ll = sqrt(light[0] * light[0] + light[1] * light[1] + light[2] * light[2]);
    for (int k = 0; k < 3; k++) light[k] /= ll;
    struct eye_shading s = {
        .eye = eye_f4(eye, 1.0),
        .light = eye_f4(light, 0.0),
        .ka = (float)p->ka,
        .kd = (float)p->kd,
        .ks = (float)p->ks,
        .shininess = (float)p->shininess,
        .density = (float)p->density,
        .lens_normal = p->shading_normal,
    };
    cl_float4 dot = eye_f4(ce->pigment.dot, 1.0), base = eye_f4(ce->pigment.base, 0.0);
    int n = ce->size * ce->size, npad = (int)(eye_items(ce, (size_t)n) * (size_t)ce->lanes);
    const struct ocl_arg a[] = {
        {sizeof(cl_mem), &ce->d_out}, {sizeof(cl_mem), &ce->order.d_cost}, {sizeof(cl_mem), &ce->d_geo},
        {sizeof(cl_mem), &ce->order.d_order}, {sizeof(cl_mem), &ce->d_pig}, {sizeof(int), &ce->pw}, {sizeof(int), &ce->ph},
        {sizeof ce->optics, &ce->optics}, {sizeof s, &s}, {sizeof dot, &dot}, {sizeof base, &base}, {sizeof(int), &n},
        {sizeof(int), &npad}};
    ce->done = 0;
    eye_split_start(ce);
    return ocl_set_args(ce->k_bake, "eye_bake", a, 13, err);
}

/* Renders the view into rgba until slice_end: 0 when it is complete, EFFECT_MORE, or -1 with err. */
static int eye_bake_slice(struct compound_eye *ce, float *rgba, double slice_end, struct fx_err *err)
{
    if (ce->busy == EYE_IDLE) {
        if (eye_bake_start(ce, err)) return -1;
        ce->busy = EYE_TRACING;
    }
    size_t texels = (size_t)ce->size * ce->size;
    int rc = eye_run(ce, ce->k_bake, "eye_bake", texels, slice_end, err);
    if (!rc) {
        int changed = eye_run_finish(ce, ce->d_out, rgba, texels, err);
        rc = changed < 0 || (changed && eye_bake_layout(ce, err)) ? -1 : 0;
    }
    if (rc <= 0) eye_abandon(ce);
    return rc;
}

int compound_eye_bake(struct compound_eye *ce, float *rgba, struct fx_err *err)
{
    eye_abandon(ce);
    return eye_bake_slice(ce, rgba, INFINITY, err);
}

/* ---- life cycle -------------------------------------------------------------------- */

struct compound_eye *compound_eye_new(struct ocl *ocl, const struct compound_eye_config *params, struct fx_err *err)
{
    struct compound_eye *ce = calloc(1, sizeof *ce);
    if (!ce) {
        fx_fail(err, "internal", "", "out of memory");
        return NULL;
    }
    ce->ocl = ocl;
    ce->mode = params->mode;
    if (eye_kernels_create(ce, err) || compound_eye_set(ce, params, err) ||
        (ce->mode == EYE_MODE_BAKE && eye_bake_setup(ce, params, err))) {
        compound_eye_free(ce);
        return NULL;
    }
    return ce;
}

void compound_eye_free(struct compound_eye *ce)
{
    if (!ce) return;
    eye_abandon(ce);
    cl_mem mems[] = {ce->d_pig, ce->d_lut, ce->d_geo, ce->d_out, ce->d_tiles, ce->d_atlas};
    for (size_t i = 0; i < sizeof mems / sizeof mems[0]; i++)
        if (mems[i]) clReleaseMemObject(mems[i]);
    if (ce->k_lut) clReleaseKernel(ce->k_lut);
    if (ce->k_bake) clReleaseKernel(ce->k_bake);
    if (ce->k_gather) clReleaseKernel(ce->k_gather);
    free(ce->pig);
    free(ce->samples);
    free(ce->rgba);
    eye_order_free(&ce->order);
    fx_buf_free(&ce->table);
    fx_buf_free(&ce->exr);
    free(ce);
}

/* ---- effect_ops -------------------------------------------------------------------- */

static int eye_emit_table(struct compound_eye *ce, double slice_end, effect_emit_fn emit, void *ctx, struct fx_err *err)
{
    int rc = eye_table_slice(ce, slice_end, err);
    if (rc) return rc;
    int W = eye_lut_atlas_width(ce->cfg.lut_cells, ce->cfg.lut_dirs);
    struct effect_frame fr = {
        .kind = FXS_KIND_LUT,
        .codec = FXS_CODEC_LUT_PACK,
        .count_or_width = (uint32_t)W,
        .height = (uint32_t)W,
        .payload = ce->table.data,
        .payload_bytes = ce->table.len,
        .encode_ms = ce->pack_ms,
    };
    return emit(ctx, &fr);
}

/* The view texture's EXR (effect_frame.encode): made only when a subscriber takes it. */
static int eye_encode_bake(void *self, struct effect_frame *fr, struct fx_err *err)
{
    struct compound_eye *ce = self;
    double t0 = clock_now() * 1e3;
    struct exr_image im = {ce->size, ce->size, 4, ce->rgba, ce->compression};
    ce->exr.len = 0;
    if (exr_write_mem(&im, &ce->exr, err)) return -1;
    fr->codec = FXS_CODEC_EXR;
    fr->payload = ce->exr.data;
    fr->payload_bytes = ce->exr.len;
    fr->encode_ms = clock_now() * 1e3 - t0;
    return 0;
}

static int eye_emit_bake(struct compound_eye *ce, double slice_end, effect_emit_fn emit, void *ctx, struct fx_err *err)
{
    int rc = eye_bake_slice(ce, ce->rgba, slice_end, err);
    if (rc) return rc;
    struct effect_frame fr = {
        .kind = FXS_KIND_TEXTURE,
        .count_or_width = (uint32_t)ce->size,
        .height = (uint32_t)ce->size,
        .encode = eye_encode_bake,
        .self = ce,
        .texels = ce->rgba,
        .channels = 4,
    };
    return emit(ctx, &fr);
}

static int eye_step(void *self, double sim_time, double dt, double slice_end, effect_emit_fn emit, void *ctx,
                    struct fx_err *err)
{
    struct compound_eye *ce = self;
    (void)sim_time;
    (void)dt;
    if (!ce->dirty) return 0; /* nothing new: the hub still holds the last frame */
    int rc = ce->mode == EYE_MODE_LUT ? eye_emit_table(ce, slice_end, emit, ctx, err)
                                      : eye_emit_bake(ce, slice_end, emit, ctx, err);
    if (!rc) ce->dirty = 0;
    return rc;
}

/* Cross-parameter rules: gap-free lens coverage (digest §2.1 [D]: the union of the
 * spheres covers the plane at depth r only if r >= the lattice's covering radius), a
 * ring with inner <= outer, and an OBJ model that loads. */
/* The assets directory's OBJ files become choices of `model` (eye_model.h). */
static int eye_init(const struct effect_env *env, struct fx_err *err) { return eye_models_set_dir(env->assets_dir, err); }

static int eye_check(const void *typed, struct fx_err *err)
{
    const struct compound_eye_config *p = typed;
    int hex = p->lattice == EYE_HEX;
    double r = p->lens_radius, rmin = hex ? 1.0 / EYE_SQRT3 : sqrt(0.5);
    if (r < rmin - 1e-9)
        return fx_fail(err, "bad_param", "lens_radius",
                       "lens_radius %g leaves gaps between the lenses of the %s lattice (needs >= %.4f)", r,
                       hex ? "hex" : "square", rmin);
    if (p->ring_inner > p->ring_outer)
        return fx_fail(err, "bad_param", "ring_inner", "ring_inner must not exceed ring_outer");
    return eye_model_check(eye_model_names[p->model], err);
}

static void *eye_create(struct ocl *ocl, const void *params, struct fx_err *err)
{
    return compound_eye_new(ocl, params, err);
}

static int eye_apply(void *self, const void *params, struct fx_err *err) { return compound_eye_set(self, params, err); }

/* A reset sends the current table (or view) again, computed afresh. */
static int eye_reset(void *self, struct fx_err *err)
{
    (void)err;
    eye_abandon(self);
    ((struct compound_eye *)self)->dirty = 1;
    return 0;
}

static void eye_destroy(void *self) { compound_eye_free(self); }

const struct effect_ops compound_eye_effect = {
    .name = "compound_eye",
    .doc = "Compound eye (Sagawa 2014): view rays refract through a lattice of overlapping ommatidium lens spheres "
           "onto a pigment plane, which shows the moving pseudopupils. Mode lut sends a lens look-up table (kind 4: "
           "pigment tile, in-cell position x view direction atlas, far-field map) whenever a parameter that shapes "
           "it changes, for one look-up per pixel on the client; mode bake sends a model's shaded view texture "
           "(kind 2 EXR) whenever the view changes.",
    .params = compound_eye_params,
    .params_size = sizeof(struct compound_eye_config),
    .presets = compound_eye_presets,
    .outputs_json = "[{\"kind\":4,\"codec\":\"lut_pack\",\"products\":\"PIGM, LLUT, LMAC (RGBA8, zstd)\","
                    "\"size\":\"LLUT atlas lut_dirs*(lut_cells+2) square\",\"rate\":\"on change, mode lut\"},"
                    "{\"kind\":2,\"codec\":\"exr\",\"channels\":\"RGBA (half)\",\"size\":\"bake_size square\","
                    "\"rate\":\"on change, at most fps, mode bake\"}]",
    .init = eye_init,
    .check = eye_check,
    .create = eye_create,
    .apply = eye_apply,
    .step = eye_step,
    .reset = eye_reset,
    .destroy = eye_destroy,
};
