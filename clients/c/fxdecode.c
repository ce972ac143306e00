/* fxdecode.c — the payload decoders of libfxclient's public API (fxclient.h): each checks
 * the frame's kind and codec, runs the codec of protocol/ into the caller's arrays and turns
 * its result into the public structs, so those stay the same when a codec's internals change.
 * Particles come in either encoding (codecs 2 and 3, or the engine encoding's 16); textures
 * only in the engine encoding (the default's are OpenEXR files).
 * Results: 0 decoded, 1 arrays missing or too small (counts filled), -1 not this kind and
 * codec or malformed (errbuf says which). */
#include "fxclient.h"
#include "fxs_engine.h"
#include "fxs_lut.h"
#include "fxs_particles.h"
#include "fxs_rig.h"
#include "fxws.h"

#include <inttypes.h>
#include <string.h>

#define FXD_CODEC(c) (1u << (c)) /* a codec in fxd_check's set */

/* -1 with "not a NAME frame (kind K codec C)" unless h is of `kind` and a codec of the set. */
static int fxd_check(const struct fxs_header *h, const uint8_t *payload, unsigned kind, uint32_t codecs,
                     const char *name, char *eb, size_t el)
{
    if (!h || (!payload && h->payload_bytes)) {
        fxws_set_err(eb, el, "no frame given");
        return -1;
    }
    if (h->kind == kind && h->codec < 32 && (codecs & FXD_CODEC(h->codec))) return 0;
    fxws_set_err(eb, el, "not a %s frame (kind %u, codec %" PRIu32 ")", name, (unsigned)h->kind, h->codec);
    return -1;
}

int fxc_decode_particles(const struct fxs_header *h, const uint8_t *payload, struct fxc_particles *out, char *eb,
                         size_t el)
{
    if (fxd_check(h, payload, FXS_KIND_PARTICLES,
                  FXD_CODEC(FXS_CODEC_PARTICLES) | FXD_CODEC(FXS_CODEC_PARTICLES_BLOCKS) | FXD_CODEC(FXS_CODEC_ENGINE),
                  "particle", eb, el))
        return -1;
    /* the engine encoding's codec has the same two calls, and neither flags nor fuel */
    int engine = h->codec == FXS_CODEC_ENGINE;
    int (*info)(const uint8_t *, size_t, uint32_t *, int *, char *, size_t) =
        engine ? fxs_engine_particles_info : fxs_particles_info;
    int (*into)(const uint8_t *, size_t, struct fxs_particles *, uint32_t, char *, size_t) =
        engine ? fxs_engine_decode_particles_into : fxs_particles_decode_into;
    struct fxs_particles p = { 0, out->xyz, out->temperature, engine ? NULL : out->fuel, engine ? NULL : out->flags,
                               out->velocity };
    uint32_t n;
    int vel;
    if (info(payload, h->payload_bytes, &n, &vel, eb, el)) return -1;
    out->count = n;
    out->has_velocity = vel;
    out->has_flags = out->has_fuel = !engine;
    if (n != h->count_or_width) {
        fxws_set_err(eb, el, "header count %" PRIu32 " but %" PRIu32 " particles in the payload", h->count_or_width, n);
        return -1;
    }
    if (n > out->capacity || (n && (!out->xyz || !out->temperature || (!engine && !out->flags)))) return 1;
    return into(payload, h->payload_bytes, &p, out->capacity, eb, el) ? -1 : 0; /* 1 (too small) cannot happen */
}

int fxc_decode_texture(const struct fxs_header *h, const uint8_t *payload, struct fxc_texture *out, char *eb,
                       size_t el)
{
    struct fxs_engine_info in;
    if (h && h->kind == FXS_KIND_TEXTURE && h->codec == FXS_CODEC_EXR) {
        fxws_set_err(eb, el, "an OpenEXR texture (codec 1): read it with OpenEXR (fxc_decode_texture reads the "
                             "engine encoding, codec 16)");
        return -1;
    }
    if (fxd_check(h, payload, FXS_KIND_TEXTURE, FXD_CODEC(FXS_CODEC_ENGINE), "texture", eb, el) ||
        fxs_engine_info(payload, h->payload_bytes, &in, eb, el))
        return -1;
    if (in.width != h->count_or_width || in.height != h->height) {
        fxws_set_err(eb, el, "header %" PRIu32 "x%" PRIu32 " but a %" PRIu32 "x%" PRIu32 " texture in the payload",
                     h->count_or_width, h->height, in.width, in.height);
        return -1;
    }
    int r = fxs_engine_decode_texture_into(payload, h->payload_bytes, &in, out->texels, out->capacity, eb, el);
    if (r >= 0) {
        out->width = in.width;
        out->height = in.height;
        out->channels = in.format == FXS_ENGINE_RGBA16F ? 4 : 1;
    }
    return r;
}

static void fxd_vec3(float out[3], const double in[3])
{
    for (int i = 0; i < 3; i++) out[i] = (float)in[i];
}

static void fxd_rig_constants(struct fxc_rig_constants *o, const struct fxs_rig_consts *k)
{
    o->flags = k->flags;
    o->strength = (float)k->strength;
    o->outline_width = (float)k->outline_width;
    fxd_vec3(o->outline_rgb, k->outline_rgb);
    o->shadow_theta = (float)k->shadow_theta;
    o->shadow_opacity = (float)k->shadow_opacity;
    fxd_vec3(o->shadow_rgb, k->shadow_rgb);
    fxd_vec3(o->plane_i, k->plane_i);
    fxd_vec3(o->plane_y, k->plane_y);
    fxd_vec3(o->plane_x, k->plane_x);
    fxd_vec3(o->plane_z, k->plane_z);
    o->n_bands = k->n_bands;
    for (int i = 0; i < k->n_bands; i++) {
        o->bands[i].m_min = (float)k->bands[i].m_min;
        fxd_vec3(o->bands[i].rgb, k->bands[i].rgb);
    }
}

int fxc_decode_rig(const struct fxs_header *h, const uint8_t *payload, struct fxc_rig *out, char *eb, size_t el)
{
    struct fxs_rig rig;
    if (fxd_check(h, payload, FXS_KIND_LIGHT_RIG, FXD_CODEC(FXS_CODEC_LIGHT_RIG), "light-rig", eb, el))
        return -1;
    if (fxs_rig_decode(payload, h->payload_bytes, &rig, &out->constants_id, &out->has_constants)) {
        fxws_set_err(eb, el, "malformed light-rig payload (%" PRIu32 " bytes)", h->payload_bytes);
        return -1;
    }
    out->count = rig.n_seg;
    if (rig.n_seg > out->capacity || (rig.n_seg && !out->segments)) return 1;
    for (int i = 0; i < rig.n_seg; i++) {
        struct fxc_rig_segment *s = &out->segments[i];
        fxd_vec3(s->c, rig.seg[i].c);
        fxd_vec3(s->d, rig.seg[i].d);
        s->a_lo = (float)rig.seg[i].a_lo;
        s->a_hi = (float)rig.seg[i].a_hi;
        s->strength = (float)rig.seg[i].strength;
        s->source = rig.seg[i].source;
        s->index = rig.seg[i].index;
    }
    if (out->has_constants) fxd_rig_constants(&out->constants, &rig.k);
    return 0;
}

/* Entry i of the container into the caller's product (its rgba and rgba_capacity kept) and e.
 * 0 when its rgba has room for the texels, 1 when not, -1 when the entry is malformed. */
static int fxd_lut_entry(const uint8_t *payload, size_t len, int i, struct fxc_lut_product *o,
                         struct fxs_lut_product *e, char *eb, size_t el)
{
    if (fxs_lut_entry(payload, len, i, e, eb, el) < 0) return -1;
    memcpy(o->name, e->name, sizeof o->name);
    o->width = e->width;
    o->height = e->height;
    o->tile = e->tile;
    o->tiles_x = e->tiles_x;
    o->tiles_y = e->tiles_y;
    o->inner = e->inner;
    return o->rgba && o->rgba_capacity >= (size_t)e->width * e->height * 4 ? 0 : 1;
}

int fxc_decode_lut(const struct fxs_header *h, const uint8_t *payload, struct fxc_lut *out, char *eb, size_t el)
{
    struct fxs_lut_info info;
    struct fxs_lut_product e;
    int count, r;
    if (fxd_check(h, payload, FXS_KIND_LUT, FXD_CODEC(FXS_CODEC_LUT_PACK), "look-up table", eb, el) ||
        (count = fxs_lut_header(payload, h->payload_bytes, &info, eb, el)) < 0)
        return -1;
    out->count = count;
    out->lattice = info.lattice;
    out->tile_h = info.tile_h;
    out->lens_radius = info.lens_radius;
    out->refractive_index = info.refractive_index;
    out->pigment_depth = info.pigment_depth;
    out->max_passes = info.max_passes;
    out->cells = info.cells;
    out->dirs = info.dirs;
    out->gutter = info.gutter;
    out->supersample = info.supersample;
    r = count > out->capacity || (count && !out->products);
    for (int i = 0; i < count && i < out->capacity && out->products; i++) { /* the directory, the room */
        int ri = fxd_lut_entry(payload, h->payload_bytes, i, &out->products[i], &e, eb, el);
        if (ri < 0) return -1;
        r |= ri;
    }
    for (int i = 0; !r && i < count; i++) /* the texels, once all have room */
        if (fxs_lut_entry(payload, h->payload_bytes, i, &e, eb, el) < 0 ||
            fxs_lut_texels_into(payload, h->payload_bytes, &e, out->products[i].rgba, out->products[i].rgba_capacity,
                                eb, el))
            return -1;
    return r;
}
