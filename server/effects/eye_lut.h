/* eye_lut.h — the products of the compound eye's lens look-up table (digest §8.1) and
 * their kind 4 container (protocol/PROTOCOL.md §7.6).
 *
 * The pigment tile is computed here on the host (it is small and the LUT kernel samples
 * it); the LUT samples come from kernels/compound_eye.cl (eye_lut) and are laid out here
 * into the atlas with gutters; the macro map is their per-direction mean. All three are
 * RGBA8 (linear values, not sRGB); protocol/fxs_lut.h packs them into one container. */
#ifndef FX_EYE_LUT_H
#define FX_EYE_LUT_H

#include <stdint.h>

#include "buf.h"
#include "err.h"
#include "fxs_lut.h"
#include "../slice.h"

#define EYE_LUT_GUTTER 1 /* texels around each LLUT tile */

/* The pigment pattern (digest G14): a disc per lens with a smoothstep edge, an optional
 * ring and an optional additive central glow; distances in pitches from the nearest
 * lattice point. */
struct eye_pigment {
    int lattice; /* EYE_SQUARE | EYE_HEX */
    double dot_radius, softness, ring_inner, ring_outer, glow_radius;
    double dot[3], base[3], ring[3], glow[3];
};

/* Tile size for a resolution: res x res (square lattice) or res x round(res*sqrt3) (hex). */
void eye_pigment_size(int res, int lattice, int *w, int *h);

/* Fills rgba (w*h*4 floats, row 0 first) with the pattern sampled at texel centres. */
void eye_pigment_tile(const struct eye_pigment *pg, int w, int h, float *rgba);

/* The pigment colour at a point given in pitches (periodic). */
void eye_pigment_at(const struct eye_pigment *pg, double x, double y, double rgb[3]);

/* The table's mirror symmetries (digest §6.8 and its hex analogue). The lattice, the pigment
 * and the tracer are symmetric under x -> 1 - x, and under the mirror through a lattice row
 * (square: y -> 1 - y; hex: y -> sqrt3/2 - y); on the hemi-octahedral map x -> -x takes
 * direction tile (ti, tj) to (D-1-tj, D-1-ti) and y -> -y to (tj, ti). A mirror maps the
 * table's samples onto its samples when it maps their grids onto themselves: always for x;
 * for y on the square lattice, and on the hex lattice when the in-cell samples per axis and
 * the pigment tile's height are even. The kernel then traces only the tiles no mirror takes to
 * another traced one (about a quarter), and the packer copies the rest. */
#define EYE_LUT_MIRROR_X 1
#define EYE_LUT_MIRROR_Y 2
int eye_lut_symmetry(int lattice, int cells, int pigment_h);
/* Writes the direction tiles to trace under those mirrors (tj * dirs + ti, ascending) into
 * tiles (dirs * dirs ints at most) and returns their count. */
int eye_lut_traced_tiles(int dirs, int symmetry, int *tiles);

/* What goes into one container. samples: the eye_lut kernel's output, cells*cells float4 for
 * each traced tile (eye_lut_traced_tiles, in its order; every tile when symmetry is 0),
 * sample = cj*cells + ci. */
struct eye_lut_table {
    int lattice, max_passes, cells, dirs, supersample, symmetry;
    float tile_h, lens_radius, refractive_index, pigment_depth;
    const float *pigment; /* pw x ph x 4 floats */
    int pw, ph;
    const float *samples;
};

/* Lays out the three products and packs the container into out (reset to empty first). */
int eye_lut_pack(const struct eye_lut_table *t, struct fx_buf *out, struct fx_err *err);

/* The same in pieces, for the daemon's slices (effect.h): begin, then eye_lut_pack_run until it
 * returns 0 (out holds the container), then free (also to abandon it). The table's samples must
 * stay as they are until then; the pigment is copied at begin. */
struct eye_lut_packer {
    struct eye_lut_table t;
    struct fx_buf *out;
    int stage;    /* laying out the atlas, the macro map, compressing, done */
    size_t pos;   /* atlas rows or macro tiles done in the stage */
    uint8_t *pig, *atlas, *macro;
    int *source; /* per tile: where its samples come from (eye_lut.c) */
    struct fxs_lut_product products[3];
    struct fxs_lut_encoder enc;
    struct slice_meter meter[3]; /* per stage: atlas rows, macro tiles, compressed blocks */
    double stage_ms[3];          /* time spent in each stage so far */
};
int eye_lut_pack_begin(struct eye_lut_packer *pk, const struct eye_lut_table *t, struct fx_buf *out, struct fx_err *err);
/* Works until slice_end (INFINITY: to the end): 0 when the container is complete, 1 when work is
 * left, -1 with err. */
int eye_lut_pack_run(struct eye_lut_packer *pk, double slice_end, struct fx_err *err);
void eye_lut_pack_free(struct eye_lut_packer *pk);

/* The LLUT atlas (RGBA8, atlas_w x atlas_w with atlas_w = dirs*(cells+2)) and the LMAC map
 * (dirs x dirs) of a table, as packed; exposed for tests. 0, or -1 when out of memory. */
int eye_lut_atlas_width(int cells, int dirs);
int eye_lut_atlas(const struct eye_lut_table *t, uint8_t *atlas);
int eye_lut_macro(const struct eye_lut_table *t, uint8_t *macro);

#endif
