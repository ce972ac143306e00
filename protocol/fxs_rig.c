/* fxs_rig.c — see fxs_rig.h: the kind 3 light-rig payload, byte by byte (little-endian,
 * fxs_bytes.h), every size checked against the payload on decode. */
#include "fxs_rig.h"

#include <string.h>

#include "fxs_bytes.h"

static void rig_put3(uint8_t *p, const double v[3])
{
    for (int i = 0; i < 3; i++) fxs_put_f32(p + 4 * i, (float)v[i]);
}

static void rig_get3(const uint8_t *p, double v[3])
{
    for (int i = 0; i < 3; i++) v[i] = fxs_get_f32(p + 4 * i);
}

static size_t rig_constants_bytes(const struct fxs_rig_consts *k)
{
    return FXS_RIG_CONST_FIXED + (size_t)k->n_bands * FXS_RIG_BAND_BYTES;
}

static size_t rig_encode_constants(const struct fxs_rig_consts *k, uint8_t *o)
{
    size_t n = rig_constants_bytes(k);
    memset(o, 0, n);
    fxs_put_u16(o, (unsigned)k->n_bands);
    fxs_put_u16(o + 2, k->flags);
    fxs_put_f32(o + 4, k->strength);
    fxs_put_f32(o + 8, k->outline_width);
    rig_put3(o + 12, k->outline_rgb);
    fxs_put_f32(o + 24, k->shadow_theta);
    fxs_put_f32(o + 28, k->shadow_opacity);
    rig_put3(o + 32, k->shadow_rgb);
    rig_put3(o + 44, k->plane_i);
    rig_put3(o + 56, k->plane_y);
    rig_put3(o + 68, k->plane_x);
    rig_put3(o + 80, k->plane_z);
    for (int i = 0; i < k->n_bands; i++) {
        uint8_t *b = o + FXS_RIG_CONST_FIXED + (size_t)i * FXS_RIG_BAND_BYTES;
        fxs_put_f32(b, k->bands[i].m_min);
        rig_put3(b + 4, k->bands[i].rgb);
    }
    return n;
}

static uint32_t rig_fnv1a(const uint8_t *p, size_t n)
{
    uint32_t h = 2166136261u;
    for (size_t i = 0; i < n; i++) h = (h ^ p[i]) * 16777619u;
    return h;
}

uint32_t fxs_rig_constants_id(const struct fxs_rig_consts *k)
{
    uint8_t buf[FXS_RIG_CONST_FIXED + FXS_RIG_MAX_BANDS * FXS_RIG_BAND_BYTES];
    return rig_fnv1a(buf, rig_encode_constants(k, buf));
}

size_t fxs_rig_encode(const struct fxs_rig *rig, int with_constants, uint8_t *out)
{
    uint8_t *o = out;
    memset(o, 0, FXS_RIG_HEADER_BYTES);
    memcpy(o, FXS_RIG_MAGIC, 4);
    fxs_put_u16(o + 4, FXS_RIG_VERSION);
    fxs_put_u16(o + 6, FXS_RIG_HEADER_BYTES);
    fxs_put_u16(o + 8, (unsigned)rig->n_seg);
    fxs_put_u16(o + 10, FXS_RIG_SEG_BYTES);
    fxs_put_u32(o + 12, with_constants ? FXS_RIG_FLAG_CONSTANTS : 0);
    fxs_put_u32(o + 16, fxs_rig_constants_id(&rig->k));
    size_t n = FXS_RIG_HEADER_BYTES;
    for (int i = 0; i < rig->n_seg; i++, n += FXS_RIG_SEG_BYTES) {
        const struct fxs_rig_seg *s = &rig->seg[i];
        rig_put3(out + n, s->c);
        rig_put3(out + n + 12, s->d);
        fxs_put_f32(out + n + 24, (float)s->a_lo);
        fxs_put_f32(out + n + 28, (float)s->a_hi);
        fxs_put_f32(out + n + 32, (float)s->strength);
        fxs_put_u16(out + n + 36, (unsigned)s->source);
        fxs_put_u16(out + n + 38, (unsigned)s->index);
    }
    size_t cb = with_constants ? rig_encode_constants(&rig->k, out + n) : 0;
    fxs_put_u32(o + 20, (uint32_t)cb);
    return n + cb;
}

int fxs_rig_decode(const uint8_t *p, size_t len, struct fxs_rig *rig, uint32_t *constants_id, int *has_constants)
{
    if (len < FXS_RIG_HEADER_BYTES || memcmp(p, FXS_RIG_MAGIC, 4) || fxs_get_u16(p + 4) != FXS_RIG_VERSION)
        return -1;
    size_t hb = fxs_get_u16(p + 6), ns = fxs_get_u16(p + 8), sb = fxs_get_u16(p + 10);
    uint32_t flags = fxs_get_u32(p + 12), cb = fxs_get_u32(p + 20);
    if (hb < FXS_RIG_HEADER_BYTES || sb < FXS_RIG_SEG_BYTES || ns > FXS_RIG_MAX_SEG) return -1;
    int hc = (flags & FXS_RIG_FLAG_CONSTANTS) != 0;
    if ((!hc && cb) || (hc && cb < FXS_RIG_CONST_FIXED) || hb + ns * sb + cb != len) return -1;
    rig->n_seg = (int)ns;
    for (size_t i = 0; i < ns; i++) {
        const uint8_t *q = p + hb + i * sb;
        struct fxs_rig_seg *s = &rig->seg[i];
        rig_get3(q, s->c);
        rig_get3(q + 12, s->d);
        s->a_lo = fxs_get_f32(q + 24);
        s->a_hi = fxs_get_f32(q + 28);
        s->strength = fxs_get_f32(q + 32);
        s->source = (int)fxs_get_u16(q + 36);
        s->index = (int)fxs_get_u16(q + 38);
    }
    *constants_id = fxs_get_u32(p + 16);
    *has_constants = hc;
    if (hc) {
        const uint8_t *c = p + hb + ns * sb;
        struct fxs_rig_consts *k = &rig->k;
        unsigned nb = fxs_get_u16(c);
        if (nb > FXS_RIG_MAX_BANDS || cb < FXS_RIG_CONST_FIXED + nb * FXS_RIG_BAND_BYTES) return -1;
        k->n_bands = (int)nb;
        k->flags = fxs_get_u16(c + 2);
        k->strength = fxs_get_f32(c + 4);
        k->outline_width = fxs_get_f32(c + 8);
        rig_get3(c + 12, k->outline_rgb);
        k->shadow_theta = fxs_get_f32(c + 24);
        k->shadow_opacity = fxs_get_f32(c + 28);
        rig_get3(c + 32, k->shadow_rgb);
        rig_get3(c + 44, k->plane_i);
        rig_get3(c + 56, k->plane_y);
        rig_get3(c + 68, k->plane_x);
        rig_get3(c + 80, k->plane_z);
        for (unsigned i = 0; i < nb; i++) {
            const uint8_t *b = c + FXS_RIG_CONST_FIXED + i * FXS_RIG_BAND_BYTES;
            k->bands[i].m_min = fxs_get_f32(b);
            rig_get3(b + 4, k->bands[i].rgb);
        }
    }
    return 0;
}
