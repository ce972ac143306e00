/* energy_wave.c — effect `energy_wave` (seed 000, Watanabe 2016; spec: digest 000).
 *
 * Owns the parameter table, the host side of kernels/energy_wave.cl (packing the sources
 * wave_sources.c unpacked, and each frame's curve weights, into the device buffers of
 * energy_wave_layout.h; the camera), the colour map, the EXR frame, and handing the same
 * sources and weights to the light rig (light_rig.c). Everything per frame is small uploads
 * plus one kernel and one read-back; big buffers (device output, host image, RGBA, EXR
 * bytes) are allocated once per texture size and reused. A frame that would hold the engine
 * past its slice (effect.h) runs the kernel in pieces, a rectangle of work-groups at a time,
 * each read back, checked and colour-mapped at once: the same work-items compute the same
 * texels, so the picture does not depend on the slicing. */
#include "energy_wave.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "buf.h"
#include "../clock.h"
#include "exr.h"
#include "../ocl.h"
#include "../slice.h"
#include "../vec3.h"
#include "energy_wave_layout.h" /* kernels/: record strides, camera block */
#include "fxs_frame.h"
#include "light_rig.h"
#include "wave_sources.h"

/* The device's strength rows hold every span a curve may have. */
_Static_assert(WAVE_MAX_W - 2 <= EW_MAX_SPANS, "curve strength spans do not fit the kernel's rows");

static const char *const ew_mode_names[] = {[EW_MODE_SIMPSON] = "simpson", [EW_MODE_ADAPTIVE] = "adaptive", NULL};
static const char *const ew_output_names[] = {[EW_OUTPUT_Y] = "Y", [EW_OUTPUT_RGBA] = "RGBA", NULL};

/* ---- parameters -------------------------------------------------------------------- */

/* Entries of struct energy_wave_config (EW_AT, EW_POS, EW_DIR) and of its list items (EW_ITEM). */
#define EW_AT(member) PARAM_AT(struct energy_wave_config, member)
#define EW_LIST(member) PARAM_LIST_AT(struct energy_wave_config, member)
#define EW_POS(at, dflt, what, ...) \
    {at, .type = PARAM_VEC3, .def = dflt, .min = -1000, .max = 1000, .unit = "world units", .doc = what, __VA_ARGS__}
#define EW_DIR(at, dflt, what, ...)                                                                              \
    {at, .type = PARAM_VEC3, .def = dflt, .min = -1000, .max = 1000, .unit = "direction",          \
     .doc = what ", normalised by the server", .flags = PARAM_NONZERO, __VA_ARGS__}
#define EW_COEF(item, dflt)                                                                                 \
    {PARAM_AT(item, coef), .type = PARAM_FLOAT, .def = dflt, .min = -20, .max = 20, .unit = "",                  \
     .doc = "energy coefficient (sign unrestricted, Watanabe 2016 eq. 3.28)"}

static const struct param_def ew_point_fields[] = {
    EW_POS(PARAM_AT(struct energy_wave_point, pos), "[0,0,0]", "point source M (Watanabe 2016 eq. 3.2)"),
    EW_COEF(struct energy_wave_point, "4.0"),
    {0},
};

static const struct param_def ew_line_fields[] = {
    EW_POS(PARAM_AT(struct energy_wave_line, pos), "[0,0,0]", "any point M on the infinite line (Watanabe 2016 eq. 3.3)"),
    EW_DIR(PARAM_AT(struct energy_wave_line, dir), "[0,0,1]", "line direction D"),
    EW_COEF(struct energy_wave_line, "4.0"),
    {0},
};

static const struct param_def ew_torus_fields[] = {
    EW_POS(PARAM_AT(struct energy_wave_torus, center), "[0,0,0]", "centre of the torus"),
    EW_DIR(PARAM_AT(struct energy_wave_torus, axis), "[0,0,1]", "torus axis (local z)"),
    {PARAM_AT(struct energy_wave_torus, R), .type = PARAM_FLOAT, .def = "1.0", .min = 0.01, .max = 100, .unit = "world units",
     .doc = "radius of the centre circle (Watanabe 2016 eq. 3.7)"},
    EW_COEF(struct energy_wave_torus, "5.1"),
    {0},
};

static const struct param_def ew_curve_fields[] = {
    EW_POS(PARAM_AT(struct energy_wave_curve, p0), "[-1,0,0]", "Bezier control point B0 (curve start)"),
    EW_POS(PARAM_AT(struct energy_wave_curve, p1), "[0,1,0]", "Bezier control point B1"),
    EW_POS(PARAM_AT(struct energy_wave_curve, p2), "[1,0,0]", "Bezier control point B2 (curve end)"),
    EW_COEF(struct energy_wave_curve, "8.0"),
    {PARAM_LIST_AT(struct energy_wave_curve, W), .type = PARAM_FLOAT_LIST, .def = "[1,1,1,1,1,1,1]", .min = 0, .max = 1, .min_len = 3,
     .max_len = WAVE_MAX_W, .unit = "", .doc = "strength sequence along the curve (quadratic B-spline, Watanabe 2016 eq. 3.25)"},
    {0},
};

/* Light rig (digest 003): the toon ramp's bands, eq. 2.5 by default. */
static const struct param_def ew_band_fields[] = {
    {PARAM_AT(struct energy_wave_band, m_min), .type = PARAM_FLOAT, .def = "-1", .min = -1, .max = 1, .unit = "",
     .doc = "lower end of the band in m = N.L (Nito 2011 eq. 2.4); bands ascend, m below the first band takes its colour"},
    {PARAM_AT(struct energy_wave_band, color), .type = PARAM_COLOR, .def = "[1,1,1]", .min = 0, .max = 1, .unit = "linear RGB",
     .doc = "toon colour of the band (Nito 2011 eq. 2.5)"},
    {0},
};

/* Default scene: the torus of thesis Fig. 5.2 (R 3.0, t_i 7.4) seen at 45 degrees, a ring that
 * reads at once as an energy effect and is smooth everywhere (a curve with a non-uniform W, or
 * the pulse, has B jump across its medial axis: digest 000 §2.3), framed by a 7.5-wide
 * billboard, in an electric blue. The thesis's joined curves are the preset thesis-fig5.6. */
static const char ew_default_tori[] = "[{\"center\":[0,0,0],\"axis\":[0,1,1],\"R\":3.0,\"coef\":7.4}]";

const struct param_def energy_wave_params[] = {
    {EW_LIST(points), .group = "sources", .type = PARAM_OBJECT_LIST, .def = "[]", .max_len = WAVE_MAX_SRC, .fields = ew_point_fields,
     .unit = "", .doc = "point sources 1/max(eps,|P-M|)"},
    {EW_LIST(lines), .group = "sources", .type = PARAM_OBJECT_LIST, .def = "[]", .max_len = WAVE_MAX_SRC, .fields = ew_line_fields,
     .unit = "", .doc = "infinite line sources"},
    {EW_LIST(tori), .group = "sources", .type = PARAM_OBJECT_LIST, .def = ew_default_tori, .max_len = WAVE_MAX_SRC, .fields = ew_torus_fields,
     .unit = "", .doc = "torus sources: 1/distance to the centre circle of radius R"},
    {EW_LIST(curves), .group = "sources", .type = PARAM_OBJECT_LIST, .def = "[]", .max_len = WAVE_MAX_SRC,
     .fields = ew_curve_fields, .unit = "", .doc = "quadratic Bezier sources with B-spline strength W"},
    {EW_AT(epsilon), PARAM_SLOT(EW_CAM_EPS), .group = "sources", .type = PARAM_FLOAT, .def = "0.05", .min = 1e-5, .max = 0.5, .unit = "world units",
     .doc = "distance floor of every kernel 1/max(eps, d)"},
    {EW_AT(alpha), PARAM_SLOT(EW_CAM_ALPHA), .group = "integration", .type = PARAM_FLOAT, .def = "1.0", .min = 0.01, .max = 100, .unit = "",
     .doc = "attenuation gain: zeta(s) = alpha/(s+beta)^2 (Watanabe 2016 eq. 3.31): higher, a brighter wave"},
    {EW_AT(beta), PARAM_SLOT(EW_CAM_BETA), .group = "integration", .type = PARAM_FLOAT, .def = "1.0", .min = 0.01, .max = 10, .unit = "",
     .doc = "attenuation offset in ray parameter s (must stay > 0)"},
    {EW_AT(divisions), .group = "integration", .type = PARAM_INT, .def = "200", .min = 2, .max = 1024, .unit = "",
     .doc = "Simpson divisions n (n+1 samples per ray), used by mode simpson", .flags = PARAM_EVEN},
    {EW_AT(mode), .group = "integration", .type = PARAM_ENUM, .def = "\"adaptive\"", .choices = ew_mode_names, .unit = "",
     .doc = "simpson: Watanabe 2016's composite Simpson rule with `divisions` (n+1 samples per ray); adaptive: "
            "closed forms for points/lines, and per torus/curve Gauss-Legendre nodes in u (10 a curve's span, 6 either side of a torus's peak) where "
            "s = s* + w sinh(u) around the ray's closest approach (on 2 CPU cores about 10x faster than "
            "simpson n=200 on curves, 4.4x on a torus, and more accurate, no banding; ignores `divisions`)"},
    EW_POS(EW_AT(eye), "[0,0,48]", "camera position V", .group = "camera"),
    EW_POS(EW_AT(center), "[0,0,18]", "billboard centre C; rays start on the billboard and look away from eye", .group = "camera"),
    EW_DIR(EW_AT(up), "[0,1,0]", "camera up vector, not parallel to eye->center", .group = "camera"),
    {EW_AT(size), .group = "camera", .type = PARAM_FLOAT, .def = "7.5", .min = 0.01, .max = 1000, .unit = "world units",
     .doc = "billboard width l (height l*height/width)"},
    {EW_AT(width), .group = "camera", .type = PARAM_INT, .def = "256", .min = 16, .max = 2048, .unit = "texels",
     .doc = "texture width"},
    {EW_AT(height), .group = "camera", .type = PARAM_INT, .def = "256", .min = 16, .max = 2048, .unit = "texels",
     .doc = "texture height"},
    {EW_AT(nu), PARAM_SLOT(EW_CAM_NU), .group = "integration", .type = PARAM_FLOAT, .def = "2.0", .min = 1.05, .max = 16, .unit = "",
     .doc = "ray end E = V + nu(S - V) (Watanabe 2016 eq. 4.3, in a translation-invariant form)"},
    {EW_AT(fps), .group = "output", .type = PARAM_FLOAT, .def = "30", .min = 1, .max = 240, .unit = "1/s",
     .doc = "frames per second of the stream"},
    /* Default rle: lossless and 2.3 ms at 512^2 half Y (bench_exr); zip is 1.8x smaller but 16 ms,
     * b44a 1.5 ms but lossy (~3% at steep peaks). */
    {EW_AT(compression), .group = "output", .type = PARAM_ENUM, .def = "\"rle\"", .choices = exr_codec_names, .unit = "",
     .doc = "OpenEXR compression of the texture frames (rle: lossless and fast; zip: smallest; b44a: lossy)"},
    {EW_AT(output), .group = "output", .type = PARAM_ENUM, .def = "\"Y\"", .choices = ew_output_names, .unit = "",
     .doc = "Y: raw luminance B (HDR, half float); RGBA: colour map clamp((1-B)Cb + B Ce), A = clamp(B)"},
    {EW_AT(color_energy), .group = "output", .type = PARAM_COLOR, .def = "[0.05,0.35,1.0]", .min = 0, .max = 1, .unit = "linear RGB",
     .doc = "energy colour C_e of the RGBA colour map (Watanabe 2016 eq. 4.8)"},
    {EW_AT(color_background), .group = "output", .type = PARAM_COLOR, .def = "[0,0,0]", .min = 0, .max = 1, .unit = "linear RGB",
     .doc = "background colour C_b of the RGBA colour map (Watanabe 2016 eq. 4.8)"},
    {EW_AT(animate), .group = "animation", .type = PARAM_BOOL, .def = "true", .unit = "",
     .doc = "multiply each curve's W by a travelling pulse (Watanabe 2016 eq. 5.1)"},
    {EW_AT(anim_rate), .group = "animation", .type = PARAM_FLOAT, .def = "30", .min = 0.1, .max = 240, .unit = "frames/s",
     .doc = "animation frames per second of stream time (Watanabe 2016 eq. 5.1; a pulse enters every 7n + 10 frames)"},
    /* The light rig (Nito 2011; kind 3 frames, PROTOCOL.md §7.7): on by default, so every
     * energy_wave stream can light its surroundings; ~1 kB a frame. */
    {EW_AT(light_rig), .group = "light rig", .type = PARAM_BOOL, .def = "true", .unit = "",
     .doc = "also send a light-rig frame (kind 3: centre-line segments, toon ramp, outline, shadow) with "
            "every texture, for clients that light their own scene with the wave"},
    {EW_AT(curve_segments), .group = "light rig", .type = PARAM_INT, .def = "8", .min = 1, .max = 32, .unit = "",
     .doc = "light rig: chords per Bezier curve of the centre line (64 segments in all at most)"},
    {EW_AT(torus_segments), .group = "light rig", .type = PARAM_INT, .def = "12", .min = 3, .max = 32, .unit = "",
     .doc = "light rig: chords per torus centre circle"},
    {EW_AT(light_strength), .group = "light rig", .type = PARAM_FLOAT, .def = "1", .min = 0, .max = 1, .unit = "",
     .doc = "light rig: mix of the toon colour over the client's own shading (1: full replacement, as in Nito 2011)"},
    {EW_LIST(ramp), .group = "light rig", .type = PARAM_OBJECT_LIST, .def = "[]", .min_len = 0, .max_len = FXS_RIG_MAX_BANDS,
     .fields = ew_band_fields, .unit = "",
     .doc = "light rig: toon colour bands over m = N.L in [-1, 1], m_min ascending (Nito 2011 eq. 2.5); empty: three bands "
            "that follow color_energy C_e (0.3 C_e from -1, 0.05 + 0.6 C_e from -0.3, 0.2 + 0.8 C_e from 0)"},
    {EW_AT(features), .group = "light rig", .type = PARAM_BOOL, .def = "true", .unit = "",
     .doc = "light rig: multiply the feature texture onto the toon colour (Nito 2011 eq. 2.6)"},
    {EW_AT(outline), .group = "light rig", .type = PARAM_BOOL, .def = "true", .unit = "",
     .doc = "light rig: draw back-face outlines (Nito 2011 eq. 2.7)"},
    {EW_AT(outline_width), .group = "light rig", .type = PARAM_FLOAT, .def = "0.005", .min = 0, .max = 0.05, .unit = "x depth",
     .doc = "light rig: outline thickness d, R' = R + d|R_z|U in view space (Nito 2011 eq. 2.7)"},
    {EW_AT(outline_color), .group = "light rig", .type = PARAM_COLOR, .def = "[0,0,0]", .min = 0, .max = 1, .unit = "linear RGB",
     .doc = "light rig: outline colour"},
    {EW_AT(shadow), .group = "shadow", .type = PARAM_BOOL, .def = "true", .unit = "",
     .doc = "light rig: draw the clamped planar shadows (Nito 2011 eqs. 2.8-2.32)"},
    {EW_AT(shadow_theta), .group = "shadow", .type = PARAM_FLOAT, .def = "60", .min = 0, .max = 89, .unit = "degrees",
     .doc = "light rig: largest angle theta of the shadow direction from the plane's downward normal; "
            "a shadow is at most height x tan(theta) long (Nito 2011 eq. 2.14)"},
    {EW_AT(shadow_color), .group = "shadow", .type = PARAM_COLOR, .def = "[0.02,0.03,0.06]", .min = 0, .max = 1, .unit = "linear RGB",
     .doc = "light rig: shadow colour"},
    {EW_AT(shadow_opacity), .group = "shadow", .type = PARAM_FLOAT, .def = "0.65", .min = 0, .max = 1, .unit = "",
     .doc = "light rig: shadow opacity where t >= 0 (Nito 2011 eq. 2.32; 0 elsewhere)"},
    EW_POS(EW_AT(shadow_plane_point), "[0,-9,0]", "light rig: a point I of the shadow-receiving plane", .group = "shadow"),
    EW_DIR(EW_AT(shadow_plane_normal), "[0,1,0]", "light rig: up normal Y of the shadow-receiving plane", .group = "shadow"),
    {0},
};

/* Built-in presets (presets.h): the thesis's ch. 5 figures where the digest gives the values
 * (000 §4: torus R and t_i of Figs 5.1/5.2, curve b_i of Figs 5.3/5.4/5.6, W of Fig 5.6); the
 * camera, billboard size and control points are not given and are ours. A preset is loaded
 * over the defaults (a torus on a 7.5-wide billboard), so the curve scenes drop the torus and
 * widen the billboard to 20.4 (at 30 units from the eye) to frame the joined curves. */
#define EW_JOINED_CURVES(coef, w0, w1)                                                                      \
    "\"tori\":[],\"size\":20.4,"                                                                           \
    "\"curves\":[{\"p0\":[-13.2,-4.2,1.8],\"p1\":[-6.6,9.0,-1.8],\"p2\":[0,0,0],\"coef\":" coef ",\"W\":" w0 "}," \
    "{\"p0\":[0,0,0],\"p1\":[6.6,-9.0,1.8],\"p2\":[13.2,4.2,-1.8],\"coef\":" coef ",\"W\":" w1 "}]"
#define EW_FLAT_W "[1,1,1,1,1,1,1]"
#define EW_FIG56 EW_JOINED_CURVES("8.0", "[1.0,0.2,0.6,1.0,0.5,0.8,1.0]", "[1.0,0.8,0.5,1.0,0.6,0.2,1.0]")
static const struct effect_preset energy_wave_presets[] = {
    {"thesis-fig5.1", "Fig. 5.1: a torus with R 0.9 and t_i 5.1, seen at an angle (the hole partly filled by glow)",
     "{\"curves\":[],\"tori\":[{\"R\":0.9,\"coef\":5.1,\"axis\":[0,1,1]}],\"size\":3.6}"},
    {"thesis-fig5.2", "Fig. 5.2: a torus with R 3.0 and t_i 7.4, seen at an angle (a clear ring; the default stream's "
                      "scene)",
     "{\"curves\":[],\"tori\":[{\"R\":3.0,\"coef\":7.4,\"axis\":[0,1,1]}],\"size\":7.5}"},
    {"thesis-fig5.3", "Fig. 5.3: two C1-joined Bezier curves, b_i 5.0, all strengths at maximum, no pulse",
     "{" EW_JOINED_CURVES("5.0", EW_FLAT_W, EW_FLAT_W) ",\"animate\":false}"},
    {"thesis-fig5.4", "Fig. 5.4: the same curves with b_i 7.5",
     "{" EW_JOINED_CURVES("7.5", EW_FLAT_W, EW_FLAT_W) ",\"animate\":false}"},
    {"thesis-fig5.6", "Fig. 5.6 (right) and 5.7: the joined curves with b_i 8.0, W = [1.0,0.2,0.6,1.0,0.5,0.8,1.0], "
                      "the eq. 5.1 pulse running",
     "{" EW_FIG56 "}"},
    {"plasma-ring", "artist look: a magenta torus ring, R 2, lit surroundings in its colour",
     "{\"curves\":[],\"tori\":[{\"R\":2.0,\"coef\":6.5,\"axis\":[0.3,1,0.8]}],\"size\":6,"
     "\"color_energy\":[1.0,0.3,0.85]}"},
    {"ember-arc", "artist look: the joined curves of Fig. 5.6 as a warm orange arc with a slower pulse",
     "{" EW_FIG56 ",\"color_energy\":[1.0,0.45,0.12],\"anim_rate\":20}"},
    {0},
};

/* ---- state ------------------------------------------------------------------------- */


struct energy_wave {
    struct ocl *ocl;
    cl_kernel k_simpson, k_adaptive;
    int lanes; /* texels per work-item (the kernels' build option EW_LANES) */
    cl_mem d_out, d_cam, d_pts, d_lns, d_tor, d_cur, d_spl;
    size_t out_texels;
    struct energy_wave_config cfg; /* the parameters in use */
    struct wave_sources src;       /* and their sources, unpacked */
    /* packed uploads */
    float cam[EW_CAM_FLOATS];
    float pts[WAVE_MAX_SRC * EW_PT_STRIDE], lns[WAVE_MAX_SRC * EW_LN_STRIDE], tor[WAVE_MAX_SRC * EW_TO_STRIDE];
    float cur[WAVE_MAX_SRC * EW_CV_STRIDE], spl[WAVE_MAX_SRC * EW_SPL_ROW];
    /* reused frame buffers: the frame in progress (luminance B, its colour map) and the last one
     * completed, its texels emitted; swapped when a frame completes, so what was emitted stays as
     * it is while the next frame is computed over several slices (effect.h) */
    float *img, *rgba, *done_img, *done_rgba;
    struct fx_buf exr;
    /* this frame's curve weights (W times the pulses), shared by the kernel and the rig */
    double w[WAVE_MAX_SRC][WAVE_MAX_W];
    /* light rig: its settings, this frame's rig and its payload */
    struct light_rig lr;
    struct fxs_rig rig;
    uint8_t rig_payload[FXS_RIG_MAX_PAYLOAD];
    /* the frame in progress: work-items of the kernel's grid done (row-major), and what one costs */
    int busy;
    size_t done;
    struct slice_meter meter;
    /* device time of the frame in progress and of the last one completed */
    struct energy_wave_split split, last_split;
};

/* A frame's pieces are counted in groups of EW_GROUP work-items of one row, rows padded to whole
 * groups (the kernel skips the work-items past the texture's edge); the first piece is
 * EW_PROBE_GROUPS before their cost is known. On a CPU device each group is a work-group, every
 * launch alike: PoCL compiles a kernel once per work-group size, so sizes left to it (one per
 * piece size) cost a compilation each; a GPU's driver chooses its own. */
#define EW_GROUP 16
#define EW_PROBE_GROUPS 2

static void ew_put3(float *dst, const double v[3])
{
    for (int k = 0; k < 3; k++) dst[k] = (float)v[k];
}

/* Camera: f = normalize(C − V), r = normalize(f × up), u = r × f; the kernel builds
 * S = C + x·l·r + y·l·(H/W)·u from the scaled r and u. */
static void ew_pack_camera(struct energy_wave *ew, const struct energy_wave_config *p)
{
    const double *V = p->eye, *C = p->center, *up = p->up;
    double f[3], r[3], u[3];
    for (int k = 0; k < 3; k++) f[k] = C[k] - V[k];
    vec3_normalize(f);
    vec3_cross(f, up, r);
    vec3_normalize(r);
    vec3_cross(r, f, u);
    double l = p->size, lh = l * ew->cfg.height / ew->cfg.width;
    memset(ew->cam, 0, sizeof ew->cam);
    params_pack(energy_wave_params, p, ew->cam); /* nu, alpha, beta, epsilon */
    ew_put3(ew->cam + EW_CAM_CENTER, C);
    for (int k = 0; k < 3; k++) {
        ew->cam[EW_CAM_RIGHT + k] = (float)(l * r[k]);
        ew->cam[EW_CAM_UP + k] = (float)(lh * u[k]);
    }
    ew_put3(ew->cam + EW_CAM_EYE, V);
}

/* Points, lines and tori in the kernel's layouts (the strides above). */
static void ew_pack_sources(struct energy_wave *ew)
{
    const struct wave_sources *src = &ew->src;
    for (int i = 0; i < src->np; i++) {
        float *dst = ew->pts + EW_PT_STRIDE * i;
        ew_put3(dst, src->point[i].pos);
        dst[3] = (float)src->point[i].coef;
    }
    for (int i = 0; i < src->nl; i++) {
        float *dst = ew->lns + EW_LN_STRIDE * i;
        ew_put3(dst, src->line[i].pos);
        dst[3] = (float)src->line[i].coef;
        ew_put3(dst + 4, src->line[i].dir);
        dst[7] = 0.0f;
    }
    for (int i = 0; i < src->nt; i++) {
        const struct wave_torus *t = &src->torus[i];
        float *dst = ew->tor + EW_TO_STRIDE * i;
        memset(dst, 0, EW_TO_STRIDE * sizeof *dst);
        ew_put3(dst, t->c);
        dst[3] = (float)t->R;
        ew_put3(dst + 4, t->e1);
        dst[7] = (float)t->coef;
        ew_put3(dst + 8, t->e2);
        ew_put3(dst + 12, t->e3);
    }
}

/* One curve record: (3.10) C₂ = B₀ − 2B₁ + B₂, C₁ = 2(B₁ − B₀), C₀ = B₀, plus |C₂|²,
 * C₁·C₂, |C₁|², the strength's span count nw − 2 and the lit range [t_lo, t_hi] (S > 0 only
 * there). */
void energy_wave_pack_curve(float *dst, const double b[3][3], double coef, int nw, double t_lo, double t_hi)
{
    double C0[3], C1[3], C2[3];
    for (int k = 0; k < 3; k++) {
        C0[k] = b[0][k];
        C1[k] = 2.0 * (b[1][k] - b[0][k]);
        C2[k] = b[0][k] - 2.0 * b[1][k] + b[2][k];
    }
    memset(dst, 0, EW_CV_STRIDE * sizeof *dst);
    ew_put3(dst, C0);
    dst[3] = (float)coef;
    ew_put3(dst + 4, C1);
    dst[7] = (float)vec3_dot(C2, C2);
    ew_put3(dst + 8, C2);
    dst[11] = (float)vec3_dot(C1, C2);
    dst[12] = (float)vec3_dot(C1, C1);
    dst[13] = (float)(nw - 2);
    dst[14] = (float)t_lo;
    dst[15] = (float)t_hi;
}

/* The strength S(t) of weights w[0..nw-1] as the kernel's span quadratics: S at both ends and
 * the middle of span k gives c0 = S(0), c1 = 4S(½) − 3S(0) − S(1), c2 = 2S(1) − 4S(½) + 2S(0)
 * in x = t·spans − k. */
void energy_wave_pack_strength(float *dst, int nw, const double *w)
{
    int spans = nw - 2;
    for (int k = 0; k < spans; k++) {
        double s0 = light_rig_bspline(nw, w, (double)k / spans), sm = light_rig_bspline(nw, w, (k + 0.5) / spans);
        double s1 = light_rig_bspline(nw, w, k + 1 == spans ? 1.0 : (double)(k + 1) / spans);
        dst[3 * k] = (float)s0;
        dst[3 * k + 1] = (float)(4.0 * sm - 3.0 * s0 - s1);
        dst[3 * k + 2] = (float)(2.0 * s1 - 4.0 * sm + 2.0 * s0);
    }
}

/* Packs the curves with their (animated) weights; curves whose strength is zero
 * everywhere are left out, so the pulse costs nothing where it is not. Returns count. */
static int ew_pack_curves(struct energy_wave *ew)
{
    int nc = 0;
    for (int i = 0; i < ew->src.nc; i++) {
        const struct wave_curve *c = &ew->src.curve[i];
        int first = -1, last = -1;
        for (int k = 0; k < c->nw; k++)
            if (ew->w[i][k] > 0.0) {
                if (first < 0) first = k;
                last = k;
            }
        if (first < 0 || c->coef == 0.0) continue;
        /* N_i² is supported on [u_i, u_{i+3}] with u_i = clamp((i−2)/(nw−2), 0, 1) */
        double lo = (first - 2.0) / (c->nw - 2.0), hi = (last + 1.0) / (c->nw - 2.0);
        energy_wave_pack_curve(ew->cur + nc * EW_CV_STRIDE, c->b, c->coef, c->nw, lo < 0 ? 0 : lo, hi > 1 ? 1 : hi);
        energy_wave_pack_strength(ew->spl + nc * EW_SPL_ROW, c->nw, ew->w[i]);
        nc++;
    }
    return nc;
}

/* ---- OpenCL objects ------------------------------------------------------------------ */

static cl_mem ew_buffer(struct energy_wave *ew, cl_mem_flags flags, size_t bytes, struct fx_err *err)
{
    cl_int rc;
    cl_mem m = clCreateBuffer(ocl_context(ew->ocl), flags, bytes, NULL, &rc);
    if (rc != CL_SUCCESS) fx_fail(err, "internal", "", "clCreateBuffer(%zu bytes): %s", bytes, ocl_errstr(rc));
    return m;
}

/* Texels per work-item: 16 where the device's native float vector holds 16 (AVX-512: one
 * instruction per operation on all of them), else 8. */
static int ew_lanes(const struct ocl *ocl)
{
    cl_uint native = 0;
    clGetDeviceInfo(ocl_device(ocl), CL_DEVICE_NATIVE_VECTOR_WIDTH_FLOAT, sizeof native, &native, NULL);
    return native >= EW_LANES_WIDE ? EW_LANES_WIDE : EW_LANES_NARROW;
}

static int ew_kernels_create(struct energy_wave *ew, struct fx_err *err)
{
    cl_int rc;
    char opts[96];
    ew->lanes = ew_lanes(ew->ocl);
    snprintf(opts, sizeof opts, "%s -DEW_LANES=%d", ENERGY_WAVE_CL_OPTS, ew->lanes);
    cl_program prog = ocl_program(ew->ocl, ENERGY_WAVE_CL, opts, err);
    if (!prog) return -1;
    ew->k_simpson = clCreateKernel(prog, "ew_render_simpson", &rc);
    if (rc == CL_SUCCESS) ew->k_adaptive = clCreateKernel(prog, "ew_render_adaptive", &rc);
    if (rc != CL_SUCCESS) return fx_fail(err, "internal", "", "clCreateKernel: %s", ocl_errstr(rc));
    if (!(ew->d_cam = ew_buffer(ew, CL_MEM_READ_ONLY, sizeof ew->cam, err))) return -1;
    if (!(ew->d_pts = ew_buffer(ew, CL_MEM_READ_ONLY, sizeof ew->pts, err))) return -1;
    if (!(ew->d_lns = ew_buffer(ew, CL_MEM_READ_ONLY, sizeof ew->lns, err))) return -1;
    if (!(ew->d_tor = ew_buffer(ew, CL_MEM_READ_ONLY, sizeof ew->tor, err))) return -1;
    if (!(ew->d_cur = ew_buffer(ew, CL_MEM_READ_ONLY, sizeof ew->cur, err))) return -1;
    if (!(ew->d_spl = ew_buffer(ew, CL_MEM_READ_ONLY, sizeof ew->spl, err))) return -1;
    return 0;
}

/* (Re)allocates the per-texel buffers when the texture grows. */
static int ew_frame_buffers(struct energy_wave *ew, struct fx_err *err)
{
    size_t texels = (size_t)ew->cfg.width * (size_t)ew->cfg.height;
    if (texels <= ew->out_texels) return 0;
    if (ew->d_out) clReleaseMemObject(ew->d_out);
    ew->d_out = NULL;
    float **bufs[] = {&ew->img, &ew->rgba, &ew->done_img, &ew->done_rgba};
    ew->out_texels = 0;
    for (size_t i = 0; i < sizeof bufs / sizeof bufs[0]; i++) {
        free(*bufs[i]);
        *bufs[i] = malloc(texels * (i % 2 ? 4 : 1) * sizeof(float));
    }
    if (!ew->img || !ew->rgba || !ew->done_img || !ew->done_rgba)
        return fx_fail(err, "internal", "", "out of memory for %zu texels", texels);
    if (!(ew->d_out = ew_buffer(ew, CL_MEM_WRITE_ONLY, texels * sizeof(float), err))) return -1;
    ew->out_texels = texels;
    return 0;
}

/* ---- public API ---------------------------------------------------------------------- */

int energy_wave_set(struct energy_wave *ew, const struct energy_wave_config *params, struct fx_err *err)
{
    ew->busy = 0; /* a frame in progress is dropped */
    ew->meter = (struct slice_meter){.probe = EW_PROBE_GROUPS};
    ew->cfg = *params;
    ew_pack_camera(ew, params);
    wave_sources_read(params, &ew->src);
    ew_pack_sources(ew);
    light_rig_read(params, &ew->lr);
    return ew_frame_buffers(ew, err);
}

struct energy_wave *energy_wave_new(struct ocl *ocl, const struct energy_wave_config *params, struct fx_err *err)
{
    struct energy_wave *ew = calloc(1, sizeof *ew);
    if (!ew) {
        fx_fail(err, "internal", "", "out of memory");
        return NULL;
    }
    ew->ocl = ocl;
    if (ew_kernels_create(ew, err) || energy_wave_set(ew, params, err)) {
        energy_wave_free(ew);
        return NULL;
    }
    return ew;
}

void energy_wave_free(struct energy_wave *ew)
{
    if (!ew) return;
    if (ew->ocl) clFinish(ocl_queue(ew->ocl)); /* a failed step may leave uploads from ew's arrays queued */
    cl_mem mems[] = {ew->d_out, ew->d_cam, ew->d_pts, ew->d_lns, ew->d_tor, ew->d_cur, ew->d_spl};
    for (size_t i = 0; i < sizeof mems / sizeof mems[0]; i++)
        if (mems[i]) clReleaseMemObject(mems[i]);
    if (ew->k_simpson) clReleaseKernel(ew->k_simpson);
    if (ew->k_adaptive) clReleaseKernel(ew->k_adaptive);
    free(ew->img);
    free(ew->rgba);
    free(ew->done_img);
    free(ew->done_rgba);
    fx_buf_free(&ew->exr);
    free(ew);
}

static int ew_upload(struct energy_wave *ew, int nc, struct fx_err *err)
{
    cl_command_queue q = ocl_queue(ew->ocl);
    const size_t f = sizeof(float);
    struct { cl_mem m; const void *src; size_t bytes; } up[] = {
        {ew->d_cam, ew->cam, sizeof ew->cam},
        {ew->d_pts, ew->pts, (size_t)ew->src.np * EW_PT_STRIDE * f},
        {ew->d_lns, ew->lns, (size_t)ew->src.nl * EW_LN_STRIDE * f},
        {ew->d_tor, ew->tor, (size_t)ew->src.nt * EW_TO_STRIDE * f},
        {ew->d_cur, ew->cur, (size_t)nc * EW_CV_STRIDE * f},
        {ew->d_spl, ew->spl, (size_t)nc * EW_SPL_ROW * f},
    };
    for (size_t i = 0; i < sizeof up / sizeof up[0]; i++) {
        if (!up[i].bytes) continue;
        cl_int rc = clEnqueueWriteBuffer(q, up[i].m, CL_FALSE, 0, up[i].bytes, up[i].src, 0, NULL, NULL);
        if (rc != CL_SUCCESS) return fx_fail(err, "internal", "", "clEnqueueWriteBuffer: %s", ocl_errstr(rc));
    }
    return 0;
}

/* The render kernel's arguments (the Simpson kernel takes `divisions` as a 14th). */
static int ew_set_args(struct energy_wave *ew, cl_kernel k, const char *name, int nc, struct fx_err *err)
{
    const struct ocl_arg a[] = {
        {sizeof(cl_mem), &ew->d_out}, {sizeof(cl_mem), &ew->d_cam}, {sizeof(cl_mem), &ew->d_pts},
        {sizeof(int), &ew->src.np},   {sizeof(cl_mem), &ew->d_lns}, {sizeof(int), &ew->src.nl},
        {sizeof(cl_mem), &ew->d_tor}, {sizeof(int), &ew->src.nt},   {sizeof(cl_mem), &ew->d_cur},
        {sizeof(int), &nc},           {sizeof(cl_mem), &ew->d_spl}, {sizeof(int), &ew->cfg.width},
        {sizeof(int), &ew->cfg.height}, {sizeof(int), &ew->cfg.divisions}};
    return ocl_set_args(k, name, a, k == ew->k_simpson ? 14 : 13, err);
}

static cl_kernel ew_kernel(const struct energy_wave *ew, const char **name)
{
    *name = ew->cfg.mode == EW_MODE_SIMPSON ? "ew_render_simpson" : "ew_render_adaptive";
    return ew->cfg.mode == EW_MODE_SIMPSON ? ew->k_simpson : ew->k_adaptive;
}

/* Work-groups per row of the kernel's grid (EW_GROUP work-items of ew->lanes texels each), and in all. */
static size_t ew_groups_x(const struct energy_wave *ew)
{
    return ((size_t)ew->cfg.width + EW_GROUP * ew->lanes - 1) / (EW_GROUP * ew->lanes);
}
static size_t ew_groups(const struct energy_wave *ew) { return ew_groups_x(ew) * (size_t)ew->cfg.height; }

/* Starts a frame at sim_time: the curve weights, the uploads and the kernel's arguments. */
static int ew_frame_begin(struct energy_wave *ew, double sim_time, struct fx_err *err)
{
    wave_sources_weights(&ew->src, sim_time, ew->w);
    int nc = ew_pack_curves(ew);
    const char *name;
    cl_kernel k = ew_kernel(ew, &name);
    if (ew_upload(ew, nc, err) || ew_set_args(ew, k, name, nc, err)) return -1;
    ew->done = 0;
    ew->split = (struct energy_wave_split){0};
    return 0;
}

/* The duration of a completed profiling event, 0 where the device does not say. */
static double ew_event_ms(cl_event ev)
{
    cl_ulong t0, t1;
    if (clGetEventProfilingInfo(ev, CL_PROFILING_COMMAND_START, sizeof t0, &t0, NULL) != CL_SUCCESS ||
        clGetEventProfilingInfo(ev, CL_PROFILING_COMMAND_END, sizeof t1, &t1, NULL) != CL_SUCCESS || t1 < t0)
        return 0.0;
    return (double)(t1 - t0) * 1e-6;
}

/* Runs the frame's next n work-groups (at most) as one rectangle of the grid, the rest of a row
 * or whole rows, and reads their texels back into out, texels [*from, *to); ew->done moves on.
 * 0, or -1 with err. */
static int ew_frame_piece(struct energy_wave *ew, size_t n, float *out, size_t *from, size_t *to, struct fx_err *err)
{
    const size_t gx = ew_groups_x(ew), w = (size_t)ew->cfg.width, j = ew->done / gx, x = ew->done % gx;
    size_t groups[2] = {gx, n / gx};
    if (x > 0 || n < gx) { /* within a row */
        groups[0] = n < gx - x ? n : gx - x;
        groups[1] = 1;
    }
    const size_t span = EW_GROUP * (size_t)ew->lanes; /* texels of a group */
    size_t offset[2] = {x * EW_GROUP, j}, global[2] = {groups[0] * EW_GROUP, groups[1]}, local[2] = {EW_GROUP, 1};
    const size_t *wg = ocl_is_cpu(ew->ocl) ? local : NULL;
    *from = j * w + x * span;
    *to = groups[1] > 1 || (x + groups[0]) * span >= w ? (j + groups[1]) * w : j * w + (x + groups[0]) * span;
    const char *name;
    cl_kernel k = ew_kernel(ew, &name);
    cl_event ev, rev;
    cl_command_queue q = ocl_queue(ew->ocl);
    cl_int rc = clEnqueueNDRangeKernel(q, k, 2, offset, global, wg, 0, NULL, &ev);
    if (rc != CL_SUCCESS) return fx_fail(err, "internal", "", "%s: %s", name, ocl_errstr(rc));
    rc = clEnqueueReadBuffer(q, ew->d_out, CL_TRUE, *from * sizeof(float), (*to - *from) * sizeof(float), out + *from,
                             0, NULL, &rev);
    if (rc == CL_SUCCESS) {
        ocl_record(ew->ocl, name, ev);
        ew->split.kernel_ms += ew_event_ms(ev);
        ew->split.read_back_ms += ew_event_ms(rev);
        ew->split.pieces++;
        clReleaseEvent(rev);
    }
    clReleaseEvent(ev);
    if (rc != CL_SUCCESS) return fx_fail(err, "internal", "", "read-back of %s: %s", name, ocl_errstr(rc));
    ew->done += groups[0] * groups[1];
    return 0;
}

int energy_wave_render(struct energy_wave *ew, double sim_time, float *out, struct fx_err *err)
{
    size_t from, to;
    ew->busy = 0;
    if (ew_frame_begin(ew, sim_time, err) || ew_frame_piece(ew, ew_groups(ew), out, &from, &to, err)) return -1;
    ew->last_split = ew->split;
    return 0;
}

void energy_wave_last_split(const struct energy_wave *ew, struct energy_wave_split *out) { *out = ew->last_split; }

/* ---- effect_ops ---------------------------------------------------------------------- */

static float ew_clamp01(double v) { return (float)(v < 0.0 ? 0.0 : (v > 1.0 ? 1.0 : v)); }

/* digest §2.7 proposal: RGBA = clamp((1−B)C_b + B·C_e, 0, 1), A = clamp(B, 0, 1), texels [from, to). */
static void ew_colour_map(const struct energy_wave *ew, size_t from, size_t to)
{
    const double *Cb = ew->cfg.color_background, *Ce = ew->cfg.color_energy;
    for (size_t i = from; i < to; i++) {
        double B = ew->img[i];
        float *px = ew->rgba + 4 * i;
        for (int c = 0; c < 3; c++) px[c] = ew_clamp01((1.0 - B) * Cb[c] + B * Ce[c]);
        px[3] = ew_clamp01(B);
    }
}

static int ew_check_finite(const float *img, size_t from, size_t to, struct fx_err *err)
{
    for (size_t i = from; i < to; i++)
        if (!isfinite(img[i]))
            return fx_fail(err, "internal", "", "energy_wave rendered a non-finite value at texel %zu", i);
    return 0;
}

/* The texture frame's EXR (effect_frame.encode): made only when a subscriber takes it. */
static int ew_encode(void *self, struct effect_frame *fr, struct fx_err *err)
{
    struct energy_wave *ew = self;
    double t0 = clock_now() * 1e3;
    struct exr_image im = {ew->cfg.width, ew->cfg.height, (int)fr->channels, fr->texels, ew->cfg.compression};
    ew->exr.len = 0;
    if (exr_write_mem(&im, &ew->exr, err)) return -1;
    fr->codec = FXS_CODEC_EXR;
    fr->payload = ew->exr.data;
    fr->payload_bytes = ew->exr.len;
    fr->encode_ms = clock_now() * 1e3 - t0;
    return 0;
}

/* Renders the frame's next pieces into ew->img (and ew->rgba) until slice_end: 0 when the
 * texture is complete (then in ew->done_img and ew->done_rgba), EFFECT_MORE, or -1 with err. */
static int ew_render_slice(struct energy_wave *ew, double sim_time, double slice_end, struct fx_err *err)
{
    if (!ew->busy && ew_frame_begin(ew, sim_time, err)) return -1;
    ew->busy = 1;
    const size_t total = ew_groups(ew);
    double t0 = clock_now();
    do {
        size_t from, to, before = ew->done;
        if (ew_frame_piece(ew, slice_units(&ew->meter, total - before, t0, slice_end), ew->img, &from, &to, err) ||
            ew_check_finite(ew->img, from, to, err)) {
            ew->busy = 0;
            return -1;
        }
        if (ew->cfg.output == EW_OUTPUT_RGBA) ew_colour_map(ew, from, to);
        double t1 = clock_now();
        slice_record(&ew->meter, ew->done - before, t1 - t0);
        t0 = t1;
    } while (ew->done < total && t0 < slice_end);
    if (ew->done < total) return EFFECT_MORE;
    ew->busy = 0;
    ew->last_split = ew->split;
    float *img = ew->img, *rgba = ew->rgba;
    ew->img = ew->done_img;
    ew->rgba = ew->done_rgba;
    ew->done_img = img;
    ew->done_rgba = rgba;
    return 0;
}

static int ew_step(void *self, double sim_time, double dt, double slice_end, effect_emit_fn emit, void *ctx,
                   struct fx_err *err)
{
    struct energy_wave *ew = self;
    (void)dt;
    int rc = ew_render_slice(ew, sim_time, slice_end, err);
    if (rc) return rc;
    struct effect_frame fr = {
        .kind = FXS_KIND_TEXTURE,
        .count_or_width = (uint32_t)ew->cfg.width,
        .height = (uint32_t)ew->cfg.height,
        .encode = ew_encode,
        .self = ew,
        .texels = ew->cfg.output == EW_OUTPUT_RGBA ? ew->done_rgba : ew->done_img,
        .channels = ew->cfg.output == EW_OUTPUT_RGBA ? 4 : 1,
    };
    if (emit(ctx, &fr)) return -1;
    if (!ew->cfg.light_rig) return 0;
    /* The light rig at the same time as the texture. The constants (~150 bytes with 3 bands)
     * go into every frame: the hub keeps only the newest frame per kind for late
     * subscribers, and they cost far less than the texture (PROTOCOL.md §7.7). */
    double t0 = clock_now() * 1e3;
    light_rig_build(&ew->lr, &ew->src, ew->w, &ew->rig);
    struct effect_frame rf = {
        .kind = FXS_KIND_LIGHT_RIG,
        .codec = FXS_CODEC_LIGHT_RIG,
        .count_or_width = (uint32_t)ew->rig.n_seg,
        .payload = ew->rig_payload,
        .payload_bytes = fxs_rig_encode(&ew->rig, 1, ew->rig_payload),
    };
    rf.encode_ms = clock_now() * 1e3 - t0;
    return emit(ctx, &rf);
}

/* Cross-field rules: eye ≠ center, and up not parallel to eye→center. */
static int ew_check(const void *typed, struct fx_err *err)
{
    const struct energy_wave_config *params = typed;
    const double *V = params->eye, *C = params->center, *up = params->up;
    double f[3], x[3];
    for (int k = 0; k < 3; k++) f[k] = C[k] - V[k];
    double ff = vec3_dot(f, f);
    if (ff < 1e-12) return fx_fail(err, "bad_param", "center", "center must differ from eye");
    vec3_cross(f, up, x);
    if (vec3_dot(x, x) <= 1e-10 * ff * vec3_dot(up, up))
        return fx_fail(err, "bad_param", "up", "up must not be parallel to the eye->center direction");
    return light_rig_check(params, err);
}

static void *ew_create(struct ocl *ocl, const void *params, struct fx_err *err)
{
    return energy_wave_new(ocl, params, err);
}

static int ew_apply(void *self, const void *params, struct fx_err *err)
{
    return energy_wave_set(self, params, err);
}

/* The effect has no state beyond its parameters (time comes with every step) but the frame in
 * progress, which a reset drops. */
static int ew_reset(void *self, struct fx_err *err)
{
    (void)err;
    ((struct energy_wave *)self)->busy = 0;
    return 0;
}

static void ew_destroy(void *self) { energy_wave_free(self); }

const struct effect_ops energy_wave_effect = {
    .name = "energy_wave",
    .doc = "Energy wave (Watanabe 2016): per-texel line integral of a 1/distance energy field made of point, "
           "line, torus and quadratic Bezier sources (B-spline strength W, optional travelling pulse), seen "
           "through a billboard camera; streamed as OpenEXR textures (raw luminance Y or colour-mapped RGBA).",
    .params = energy_wave_params,
    .params_size = sizeof(struct energy_wave_config),
    .param_slots = EW_CAM_FLOATS,
    .presets = energy_wave_presets,
    .outputs_json = "[{\"kind\":2,\"codec\":\"exr\",\"channels\":\"Y (raw B, half) or RGBA (colour map), "
                    "per `output`\",\"size\":\"width x height\",\"rate\":\"fps\"},"
                    "{\"kind\":3,\"codec\":\"rig1\",\"channels\":\"centre-line segments, toon ramp, outline "
                    "and shadow constants (PROTOCOL.md 7.7)\",\"size\":\"segments\",\"rate\":\"fps, when "
                    "light_rig is on\"}]",
    .check = ew_check,
    .create = ew_create,
    .apply = ew_apply,
    .step = ew_step,
    .reset = ew_reset,
    .destroy = ew_destroy,
};
