/* fxs_particles_format.c — the codec 2 block's layout and grid, shared by both sides
 * (fxs_particles_format.h says what is shared and why): the header (PROTOCOL.md §7.5.1,
 * velocity block §7.5.7), the quantisation steps, the kd-tree's split schedule (§7.5.3)
 * and the models' initial state. */
#include "fxs_particles_format.h"

#include <math.h>
#include <string.h>

#include "fxs_bytes.h"

#define R4(v) v, v, v, v
#define R16(v) R4(v), R4(v), R4(v), R4(v)
const uint8_t fxs_pt_cclass_tab[257] = {
    0, 0, 0, 1, 2, 3, 4, 5, 6,                                             /* c = 0 ... 8 (0, 1 unused) */
    R4(7), R4(8),                                                          /* 9-12, 13-16 */
    R16(9), R16(10), R16(10),                                              /* 17-32, 33-64 */
    R16(11), R16(11), R16(11), R16(11),                                    /* 65-128 */
    R16(12), R16(12), R16(12), R16(12), R16(12), R16(12), R16(12), R16(12) /* 129-256 */
};
#undef R16
#undef R4

void fxs_pt_models_init(struct fxs_pt_models *m)
{
    fxs_rc_prob *p = (fxs_rc_prob *)m;
    for (size_t i = 0; i < sizeof *m / sizeof *p; i++) p[i] = FXS_RC_PROB_INIT;
}

/* Without stdio: the decoder also runs as WebAssembly, where printf's machinery would
 * import file functions. */
int fxs_pt_fail(char *err, size_t errlen, const char *msg)
{
    static const char prefix[] = "particles: ";
    size_t at = 0;
    if (!err || !errlen) return -1;
    for (const char *s = prefix; *s && at + 1 < errlen; s++) err[at++] = *s;
    for (const char *s = msg; *s && at + 1 < errlen; s++) err[at++] = *s;
    err[at] = 0;
    return -1;
}

void fxs_pt_steps(struct fxs_pt_frame *f)
{
    double r = 0;
    for (int a = 0; a < 3; a++)
        if ((double)f->hi[a] - (double)f->lo[a] > r) r = (double)f->hi[a] - (double)f->lo[a];
    for (int a = 0; a < 3; a++) f->step[a] = r / (double)((1u << f->pos_bits) - 1u);
    f->step[3] = ((double)f->hi[3] - (double)f->lo[3]) / (double)((1u << f->temp_bits) - 1u);
    f->step[4] = ((double)f->hi[4] - (double)f->lo[4]) / (double)((1u << f->fuel_bits) - 1u);
    for (int a = 0; a < 3 && f->vel; a++) f->vstep[a] = (double)f->vmax[a] / (double)fxs_pt_vqmax(f->vel_bits);
}

/* Splits from the top bit down; at each bit x, then y, then z (axes that have it). */
void fxs_pt_schedule(struct fxs_pt_frame *f)
{
    int top = 0, d = 0, left[3];
    for (int a = 0; a < 3; a++) {
        left[a] = f->abits[a];
        if (f->abits[a] > top) top = f->abits[a];
    }
    for (int b = top - 1; b >= 0; b--)
        for (int a = 0; a < 3; a++)
            if (b < f->abits[a]) {
                for (int c = 0; c < 3; c++) f->left[d][c] = (uint8_t)left[c];
                f->axis[d++] = (uint8_t)a;
                left[a]--;
            }
    for (int c = 0; c < 3; c++) f->left[d][c] = 0;
    f->depth = d;
}

void fxs_pt_header_put(const struct fxs_pt_frame *f, uint8_t *out, uint32_t rc_len, uint32_t bits_len)
{
    memset(out, 0, FXS_PARTICLES_HEADER_BYTES);
    memcpy(out, FXS_PT_MAGIC, 4);
    out[4] = FXS_PT_VERSION;
    out[5] = (uint8_t)f->pos_bits;
    out[6] = (uint8_t)f->temp_bits;
    out[7] = (uint8_t)f->fuel_bits;
    for (int a = 0; a < 3; a++) out[8 + a] = (uint8_t)f->abits[a];
    out[11] = (uint8_t)(f->mode | (f->vel ? FXS_PT_HAS_VEL : 0u));
    fxs_put_u32(out + 12, f->n);
    for (int c = 0; c < 3; c++) {
        fxs_put_f32(out + 16 + 4 * c, f->lo[c]);
        fxs_put_f32(out + 28 + 4 * c, f->hi[c]);
    }
    fxs_put_f32(out + 40, f->lo[3]);
    fxs_put_f32(out + 44, f->hi[3]);
    fxs_put_f32(out + 48, f->lo[4]);
    fxs_put_f32(out + 52, f->hi[4]);
    fxs_put_u32(out + 56, rc_len);
    fxs_put_u32(out + 60, bits_len);
    if (f->vel) {
        uint8_t *vb = out + FXS_PARTICLES_HEADER_BYTES;
        memset(vb, 0, FXS_PARTICLES_VEL_BLOCK_BYTES);
        vb[0] = (uint8_t)f->vel_bits;
        for (int a = 0; a < 3; a++) fxs_put_f32(vb + 4 + 4 * a, f->vmax[a]);
    }
}

int fxs_pt_header_get(const uint8_t *buf, size_t len, struct fxs_pt_frame *f, uint32_t *rl, uint32_t *bl)
{
    if (len < FXS_PARTICLES_HEADER_BYTES || memcmp(buf, FXS_PT_MAGIC, 4)) return -1;
    if (buf[4] != FXS_PT_VERSION) return -2;
    f->pos_bits = buf[5];
    f->temp_bits = buf[6];
    f->fuel_bits = buf[7];
    for (int a = 0; a < 3; a++) f->abits[a] = buf[8 + a];
    f->mode = buf[11] & 0x0Fu;
    f->vel = (buf[11] & FXS_PT_HAS_VEL) != 0;
    f->n = fxs_get_u32(buf + 12);
    for (int c = 0; c < 3; c++) {
        f->lo[c] = fxs_get_f32(buf + 16 + 4 * c);
        f->hi[c] = fxs_get_f32(buf + 28 + 4 * c);
    }
    f->lo[3] = fxs_get_f32(buf + 40);
    f->hi[3] = fxs_get_f32(buf + 44);
    f->lo[4] = fxs_get_f32(buf + 48);
    f->hi[4] = fxs_get_f32(buf + 52);
    *rl = fxs_get_u32(buf + 56);
    *bl = fxs_get_u32(buf + 60);
    if ((buf[11] & ~FXS_PT_HAS_VEL) > 1) return -3;
    if (f->vel) {
        const uint8_t *vb = buf + FXS_PARTICLES_HEADER_BYTES;
        if (len < FXS_PARTICLES_HEADER_BYTES + FXS_PARTICLES_VEL_BLOCK_BYTES) return -1;
        if (vb[1] || vb[2] || vb[3]) return -4;
        f->vel_bits = vb[0];
        for (int a = 0; a < 3; a++) f->vmax[a] = fxs_get_f32(vb + 4 + 4 * a);
    }
    return 0;
}

const char *fxs_pt_header_check(const struct fxs_pt_frame *f)
{
    if (f->pos_bits < 8 || f->pos_bits > 24 || f->temp_bits < 2 || f->temp_bits > 16 || f->fuel_bits < 2 ||
        f->fuel_bits > 16)
        return "bad bit widths";
    for (int a = 0; a < 3; a++)
        if (f->abits[a] > f->pos_bits) return "bad axis bits";
    if (f->n > FXS_PARTICLES_MAX_N) return "particle count over the limit";
    for (int c = 0; c < 5; c++)
        if (!isfinite(f->lo[c]) || !isfinite(f->hi[c]) || f->lo[c] > f->hi[c]) return "bad bounds";
    if (f->vel && (f->vel_bits < 2 || f->vel_bits > 16)) return "bad velocity bits";
    for (int a = 0; a < 3 && f->vel; a++)
        if (!isfinite(f->vmax[a]) || !(f->vmax[a] >= 0)) return "bad velocity bounds";
    return NULL;
}
