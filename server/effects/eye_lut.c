/* eye_lut.c — see eye_lut.h. The products' layouts are PROTOCOL.md §7.6; the container's
 * bytes are protocol/fxs_lut.c's; the integration test (tests/integration/test_eye_stream.py)
 * decodes them independently. */
#include "eye_lut.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "../clock.h"
#include "compound_eye_layout.h" /* kernels/: EYE_HEX, EYE_SQRT3 */

#define EYE_LUT_ZSTD_LEVEL 1 /* level 1: ~5x faster than 3 and within a few % of its size here */
#define EYE_LUT_BLOCK 65536  /* bytes compressed per unit of the packer's slices */

/* ---- pigment (digest G14, §3.4.1 ring and glow) ------------------------------------ */

void eye_pigment_size(int res, int lattice, int *w, int *h)
{
    *w = res;
    *h = lattice == EYE_HEX ? (int)lround(res * EYE_SQRT3) : res;
}

/* Distance from (x, y) to the nearest lattice point, pitches (lattice as in the kernel). */
static double eye_lattice_dist(int lattice, double x, double y)
{
    if (lattice != EYE_HEX) {
        double dx = x - floor(x) - 0.5, dy = y - floor(y) - 0.5;
        return sqrt(dx * dx + dy * dy);
    }
    const double h = EYE_SQRT3, ax = 0.5, ay = 0.25 * h, bx = 0.0, by = 0.75 * h;
    double dax = x - ax - round(x - ax), day = y - ay - h * round((y - ay) / h);
    double dbx = x - bx - round(x - bx), dby = y - by - h * round((y - by) / h);
    return sqrt(fmin(dax * dax + day * day, dbx * dbx + dby * dby));
}

/* 1 inside radius rad, 0 outside, smoothstep over a band of width soft centred on rad. */
static double eye_disc(double d, double rad, double soft)
{
    if (soft <= 0.0) return d < rad ? 1.0 : 0.0;
    double t = (d - (rad - 0.5 * soft)) / soft;
    t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
    return 1.0 - t * t * (3.0 - 2.0 * t);
}

void eye_pigment_at(const struct eye_pigment *pg, double x, double y, double rgb[3])
{
    double d = eye_lattice_dist(pg->lattice, x, y);
    double dot = eye_disc(d, pg->dot_radius, pg->softness);
    double ring = pg->ring_outer > pg->ring_inner
                      ? eye_disc(d, pg->ring_outer, pg->softness) * (1.0 - eye_disc(d, pg->ring_inner, pg->softness))
                      : 0.0;
    double glow = pg->glow_radius > 0.0 ? eye_disc(d, 0.5 * pg->glow_radius, pg->glow_radius) : 0.0;
    for (int k = 0; k < 3; k++) {
        double c = pg->base[k] + dot * (pg->dot[k] - pg->base[k]);
        c += ring * (pg->ring[k] - c);
        c += glow * pg->glow[k];
        rgb[k] = c < 0.0 ? 0.0 : (c > 1.0 ? 1.0 : c);
    }
}

void eye_pigment_tile(const struct eye_pigment *pg, int w, int h, float *rgba)
{
    double tile_h = pg->lattice == EYE_HEX ? EYE_SQRT3 : 1.0;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            double rgb[3];
            eye_pigment_at(pg, (x + 0.5) / w, (y + 0.5) / h * tile_h, rgb);
            float *px = rgba + 4 * ((size_t)y * w + x);
            for (int k = 0; k < 3; k++) px[k] = (float)rgb[k];
            px[3] = 1.0f;
        }
}

/* ---- products -------------------------------------------------------------------- */

static uint8_t eye_u8(float v) { return (uint8_t)(v <= 0.0f ? 0 : v >= 1.0f ? 255 : (int)(v * 255.0f + 0.5f)); }

/* n values to bytes as eye_u8; with SSE2, 16 at a time (clamped to [0, 1], scaled, truncated,
 * packed: the same bytes). */
static void eye_u8_row(const float *v, uint8_t *out, int n)
{
    int i = 0;
#ifdef __SSE2__
    const __m128 zero = _mm_setzero_ps(), one = _mm_set1_ps(1.0f), scale = _mm_set1_ps(255.0f), half = _mm_set1_ps(0.5f);
    for (; i + 16 <= n; i += 16) {
        __m128i q[4];
        for (int k = 0; k < 4; k++) {
            __m128 c = _mm_min_ps(_mm_max_ps(_mm_loadu_ps(v + i + 4 * k), zero), one);
            q[k] = _mm_cvttps_epi32(_mm_add_ps(_mm_mul_ps(c, scale), half));
        }
        __m128i b = _mm_packus_epi16(_mm_packs_epi32(q[0], q[1]), _mm_packs_epi32(q[2], q[3]));
        _mm_storeu_si128((__m128i *)(void *)(out + i), b);
    }
#endif
    for (; i < n; i++) out[i] = eye_u8(v[i]);
}

int eye_lut_atlas_width(int cells, int dirs) { return dirs * (cells + 2 * EYE_LUT_GUTTER); }

/* ---- symmetry ---------------------------------------------------------------------- */

int eye_lut_symmetry(int lattice, int cells, int pigment_h)
{
    return EYE_LUT_MIRROR_X | (lattice != EYE_HEX || (cells % 2 == 0 && pigment_h % 2 == 0) ? EYE_LUT_MIRROR_Y : 0);
}

/* Tile (ti, tj) is traced when it lies in the half-plane that each mirror of the symmetry
 * keeps: ti + tj <= D-1 for x (which takes it to a tile whose ti + tj is 2D-2 minus its own),
 * ti <= tj for y (which swaps ti and tj). */
static int eye_lut_traced(int dirs, int symmetry, int ti, int tj)
{
    return (!(symmetry & EYE_LUT_MIRROR_X) || ti + tj <= dirs - 1) && (!(symmetry & EYE_LUT_MIRROR_Y) || ti <= tj);
}

int eye_lut_traced_tiles(int dirs, int symmetry, int *tiles)
{
    int n = 0;
    for (int tj = 0; tj < dirs; tj++)
        for (int ti = 0; ti < dirs; ti++)
            if (eye_lut_traced(dirs, symmetry, ti, tj)) tiles[n++] = tj * dirs + ti;
    return n;
}

/* Where each tile's samples come from: source[tile] = slot * 4 + flags, slot the traced tile's
 * index among the samples, flags the mirrors (EYE_LUT_MIRROR_*) that take the tile to it. */
static void eye_lut_sources(const struct eye_lut_table *t, int *source)
{
    const int D = t->dirs;
    int slot = 0;
    for (int tile = 0; tile < D * D; tile++) source[tile] = -1;
    for (int tile = 0; tile < D * D; tile++)
        if (eye_lut_traced(D, t->symmetry, tile % D, tile / D)) source[tile] = slot++ * 4;
    for (int tj = 0; tj < D; tj++)
        for (int ti = 0; ti < D; ti++)
            for (int m = 1; m < 4 && source[tj * D + ti] < 0; m++) {
                if ((m & t->symmetry) != m) continue;
                int mi = ti, mj = tj, s;
                if (m & EYE_LUT_MIRROR_Y) s = mi, mi = mj, mj = s;
                if (m & EYE_LUT_MIRROR_X) s = mi, mi = D - 1 - mj, mj = D - 1 - s;
                if (eye_lut_traced(D, t->symmetry, mi, mj)) source[tj * D + ti] = source[mj * D + mi] | m;
            }
}

/* In-cell row of the mirror image of row cj under y (the hex lattice's mirror row is at a
 * quarter of its period). */
static int eye_lut_mirror_row(const struct eye_lut_table *t, int cj)
{
    const int C = t->cells;
    return t->lattice == EYE_HEX ? (C / 2 - 1 - cj + C) % C : C - 1 - cj;
}

/* ---- products ---------------------------------------------------------------------- */

/* Tile (ti, tj) occupies texels [ti*(C+2), (ti+1)*(C+2)) in x (likewise y); its gutter
 * repeats the opposite edge of the cell (the pattern is periodic), so bilinear filtering
 * inside a tile never reads a neighbouring direction. Rows [y0, y1). */
static void eye_lut_atlas_rows(const struct eye_lut_table *t, const int *source, uint8_t *atlas, int y0, int y1)
{
    const int C = t->cells, G = EYE_LUT_GUTTER, T = C + 2 * G, W = eye_lut_atlas_width(C, t->dirs);
    for (int y = y0; y < y1; y++) {
        int tj = y / T, cj = (y % T - G + C) % C;
        for (int ti = 0; ti < t->dirs; ti++) {
            int src = source[tj * t->dirs + ti], mj = src & EYE_LUT_MIRROR_Y ? eye_lut_mirror_row(t, cj) : cj;
            const float *row = t->samples + 4 * ((size_t)(src / 4) * C * C + (size_t)mj * C);
            uint8_t *px = atlas + 4 * ((size_t)y * W + (size_t)ti * T + G);
            if (src & EYE_LUT_MIRROR_X) {
                uint8_t tmp[4 * 64]; /* lut_cells <= 64 */
                eye_u8_row(row, tmp, 4 * C);
                for (int x = 0; x < C; x++) memcpy(px + 4 * x, tmp + 4 * (C - 1 - x), 4);
            } else {
                eye_u8_row(row, px, 4 * C);
            }
            memcpy(px - 4 * G, px + 4 * (C - G), 4 * G); /* gutters: the opposite edge */
            memcpy(px + 4 * C, px, 4 * G);
        }
    }
}

/* Calls f with the table's sources (eye_lut_sources): 0, or -1 when out of memory. */
static int eye_lut_with_sources(const struct eye_lut_table *t, uint8_t *dst,
                                void (*f)(const struct eye_lut_table *, const int *, uint8_t *, int, int), int n)
{
    int *source = malloc((size_t)t->dirs * t->dirs * sizeof *source);
    if (!source) return -1;
    eye_lut_sources(t, source);
    f(t, source, dst, 0, n);
    free(source);
    return 0;
}

int eye_lut_atlas(const struct eye_lut_table *t, uint8_t *atlas)
{
    return eye_lut_with_sources(t, atlas, eye_lut_atlas_rows, eye_lut_atlas_width(t->cells, t->dirs));
}

/* Tiles [from, to) of the macro map (a mirror only reorders a tile's samples). */
static void eye_lut_macro_tiles(const struct eye_lut_table *t, const int *source, uint8_t *macro, int from, int to)
{
    const size_t per = (size_t)t->cells * t->cells;
    for (int tile = from; tile < to; tile++) {
        double acc[4] = {0};
        const float *s = t->samples + 4 * per * (size_t)(source[tile] / 4);
        for (size_t i = 0; i < per; i++)
            for (int k = 0; k < 4; k++) acc[k] += s[4 * i + k];
        for (int k = 0; k < 4; k++) macro[4 * tile + k] = eye_u8((float)(acc[k] / per));
    }
}

int eye_lut_macro(const struct eye_lut_table *t, uint8_t *macro)
{
    return eye_lut_with_sources(t, macro, eye_lut_macro_tiles, t->dirs * t->dirs);
}

/* ---- the container (protocol/fxs_lut.h, PROTOCOL.md §7.6) ------------------------ */

enum { EYE_PACK_ATLAS, EYE_PACK_MACRO, EYE_PACK_ZSTD, EYE_PACK_DONE };

int eye_lut_pack_begin(struct eye_lut_packer *pk, const struct eye_lut_table *t, struct fx_buf *out, struct fx_err *err)
{
    const int W = eye_lut_atlas_width(t->cells, t->dirs);
    size_t pig_bytes = (size_t)t->pw * t->ph * 4;
    *pk = (struct eye_lut_packer){.t = *t, .out = out};
    pk->pig = malloc(pig_bytes);
    pk->atlas = malloc((size_t)W * W * 4);
    pk->macro = malloc((size_t)t->dirs * t->dirs * 4);
    pk->source = malloc((size_t)t->dirs * t->dirs * sizeof *pk->source);
    struct fxs_lut_product products[3] = {
        {.name = "PIGM", .width = (uint32_t)t->pw, .height = (uint32_t)t->ph, .tiles_x = 1, .tiles_y = 1, .rgba = pk->pig},
        {.name = "LLUT", .width = (uint32_t)W, .height = (uint32_t)W, .tile = (uint32_t)(t->cells + 2 * EYE_LUT_GUTTER),
         .tiles_x = (uint32_t)t->dirs, .tiles_y = (uint32_t)t->dirs, .inner = (uint32_t)t->cells, .rgba = pk->atlas},
        {.name = "LMAC", .width = (uint32_t)t->dirs, .height = (uint32_t)t->dirs, .tile = 1, .tiles_x = (uint32_t)t->dirs,
         .tiles_y = (uint32_t)t->dirs, .inner = 1, .rgba = pk->macro},
    };
    memcpy(pk->products, products, sizeof products);
    const struct fxs_lut_info info = {
        (uint32_t)t->lattice, t->tile_h,          t->lens_radius,     t->refractive_index,         t->pigment_depth,
        (uint32_t)t->max_passes, (uint32_t)t->cells, (uint32_t)t->dirs, EYE_LUT_GUTTER, (uint32_t)t->supersample,
    };
    size_t cap = fxs_lut_bound(pk->products, 3);
    out->len = 0;
    if (!pk->pig || !pk->atlas || !pk->macro || !pk->source || fx_buf_reserve(out, cap)) {
        eye_lut_pack_free(pk);
        return fx_fail(err, "internal", "", "out of memory for a %dx%d lens table", W, W);
    }
    for (size_t i = 0; i < pig_bytes; i++) pk->pig[i] = eye_u8(t->pigment[i]);
    eye_lut_sources(t, pk->source);
    pk->t.pigment = NULL;
    for (int k = 0; k < 3; k++) pk->meter[k].probe = 1;
    char msg[128];
    if (fxs_lut_encode_begin(&pk->enc, &info, pk->products, 3, EYE_LUT_ZSTD_LEVEL, out->data, cap, msg, sizeof msg)) {
        eye_lut_pack_free(pk);
        return fx_fail(err, "internal", "", "%s", msg);
    }
    return 0;
}

/* Does n units of the current stage (rows, tiles, blocks): 1 while the stage has more, 0 when
 * it is over, -1 with err. */
static int eye_lut_pack_units(struct eye_lut_packer *pk, size_t n, struct fx_err *err)
{
    if (pk->stage == EYE_PACK_ZSTD) {
        char msg[128];
        int rc = fxs_lut_encode_some(&pk->enc, n * EYE_LUT_BLOCK, msg, sizeof msg);
        if (rc < 0) return fx_fail(err, "internal", "", "%s", msg);
        pk->out->len = pk->enc.len;
        return rc;
    }
    pk->pos += n;
    if (pk->stage == EYE_PACK_ATLAS)
        eye_lut_atlas_rows(&pk->t, pk->source, pk->atlas, (int)(pk->pos - n), (int)pk->pos);
    else
        eye_lut_macro_tiles(&pk->t, pk->source, pk->macro, (int)(pk->pos - n), (int)pk->pos);
    return 1;
}

/* Units left in the current stage. */
static size_t eye_lut_pack_left(const struct eye_lut_packer *pk)
{
    const size_t W = (size_t)eye_lut_atlas_width(pk->t.cells, pk->t.dirs);
    switch (pk->stage) {
    case EYE_PACK_ATLAS: return W - pk->pos;
    case EYE_PACK_MACRO: return (size_t)pk->t.dirs * pk->t.dirs - pk->pos;
    default: {
        size_t raw = 0;
        for (int i = pk->enc.cur; i < 3; i++) raw += (size_t)pk->products[i].width * pk->products[i].height * 4;
        return (raw - pk->enc.done + EYE_LUT_BLOCK - 1) / EYE_LUT_BLOCK;
    }
    }
}

int eye_lut_pack_run(struct eye_lut_packer *pk, double slice_end, struct fx_err *err)
{
    double t0 = clock_now();
    while (pk->stage != EYE_PACK_DONE) {
        size_t left = eye_lut_pack_left(pk);
        struct slice_meter *m = &pk->meter[pk->stage];
        size_t n = left ? slice_units(m, left, t0, slice_end) : 0;
        int rc = n ? eye_lut_pack_units(pk, n, err) : 0;
        if (rc < 0) return -1;
        double t1 = clock_now();
        slice_record(m, n, t1 - t0);
        pk->stage_ms[pk->stage] += (t1 - t0) * 1e3;
        t0 = t1;
        if (n == left || (pk->stage == EYE_PACK_ZSTD && rc == 0)) {
            pk->stage++;
            pk->pos = 0;
        }
        if (pk->stage != EYE_PACK_DONE && t0 >= slice_end) return 1;
    }
    return 0;
}

void eye_lut_pack_free(struct eye_lut_packer *pk)
{
    fxs_lut_encode_free(&pk->enc);
    free(pk->pig);
    free(pk->atlas);
    free(pk->macro);
    free(pk->source);
    pk->pig = pk->atlas = pk->macro = NULL;
    pk->source = NULL;
}

int eye_lut_pack(const struct eye_lut_table *t, struct fx_buf *out, struct fx_err *err)
{
    struct eye_lut_packer pk;
    if (eye_lut_pack_begin(&pk, t, out, err)) return -1;
    int rc = eye_lut_pack_run(&pk, INFINITY, err);
    eye_lut_pack_free(&pk);
    return rc;
}
