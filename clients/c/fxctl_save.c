/* fxctl_save.c — see fxctl_save.h. */
#include "fxctl_save.h"

#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cjson/cJSON.h>

#include "exr.h"
#include "png.h"

double fxctl_age_ms(const struct fxc_event *ev)
{
    return ((double)ev->recv_time_us - (double)ev->header.server_time_us) / 1000.0;
}

/* Shortest of %.15g / %.17g that reads back as v (cJSON's rule); non-finite as 0. */
static void fxctl_fmt_double(char *buf, size_t len, double v)
{
    if (!isfinite(v)) v = 0;
    snprintf(buf, len, "%.15g", v);
    if (strtod(buf, NULL) != v) snprintf(buf, len, "%.17g", v);
}

void fxctl_frame_line(char *buf, size_t len, const char *stream, const struct fxc_event *ev)
{
    const struct fxs_header *h = &ev->header;
    cJSON *name = cJSON_CreateString(stream);
    char *qname = cJSON_PrintUnformatted(name);
    char size[96], sim[32];
    uint32_t total = fxc_frame_total(ev);
    if (h->kind == FXS_KIND_TEXTURE || h->kind == FXS_KIND_LUT)
        snprintf(size, sizeof size, "\"width\":%" PRIu32 ",\"height\":%" PRIu32, h->count_or_width, h->height);
    else if (total)
        snprintf(size, sizeof size, "\"count\":%" PRIu32 ",\"total\":%" PRIu32, h->count_or_width, total);
    else
        snprintf(size, sizeof size, "\"count\":%" PRIu32, h->count_or_width);
    fxctl_fmt_double(sim, sizeof sim, h->sim_time);
    snprintf(buf, len,
             "{\"stream\":%s,\"channel\":%" PRIu32 ",\"kind\":%u,\"seq\":%" PRIu64 ",\"param_rev\":%" PRIu32
             ",\"sim_time\":%s,\"server_time_us\":%" PRIu64 ",\"latency_ms\":%.3f,\"codec\":%" PRIu32
             ",\"payload_bytes\":%" PRIu32 ",%s,\"flags\":%" PRIu32 "}",
             qname ? qname : "null", h->channel, (unsigned)h->kind, h->seq, h->param_rev, sim, h->server_time_us,
             fxctl_age_ms(ev), h->codec, h->payload_bytes, size, h->flags);
    free(qname);
    cJSON_Delete(name);
}

static int fxctl_write_file(const char *path, const void *data, size_t len)
{
    FILE *f = fopen(path, "wb");
    int ok = f && fwrite(data, 1, len, f) == len;
    if (f && fclose(f)) ok = 0;
    if (!ok) fprintf(stderr, "fxctl: cannot write %s: %s\n", path, strerror(errno));
    return ok ? 0 : -1;
}

/* Writes decoded particles as binary little-endian PLY: float x y z temperature, then float
 * fuel and uchar flags when the frame carries them (codecs 2 and 3, not the engine encoding),
 * then float vx vy vz when it carries velocities. */
static int fxctl_write_ply(const char *path, uint32_t codec, const struct fxc_particles *p)
{
    FILE *f = fopen(path, "wb");
    int ok = f != NULL, attrs = p->has_fuel && p->has_flags;
    size_t size = 16 + (attrs ? 5 : 0) + (p->has_velocity ? 12 : 0);
    if (ok)
        ok = fprintf(f, "ply\nformat binary_little_endian 1.0\ncomment fxstream kind 1 codec %" PRIu32
                        "\nelement vertex %" PRIu32 "\nproperty float x\nproperty float y\nproperty float z\n"
                        "property float temperature\n%s%send_header\n",
                     codec, p->count, attrs ? "property float fuel\nproperty uchar flags\n" : "",
                     p->has_velocity ? "property float vx\nproperty float vy\nproperty float vz\n" : "") > 0;
    for (uint32_t i = 0; ok && i < p->count; i++) {
        uint8_t rec[33], *r = rec;
        float v[8] = { p->xyz[3 * i], p->xyz[3 * i + 1], p->xyz[3 * i + 2], p->temperature[i], attrs ? p->fuel[i] : 0 };
        int nv = attrs ? 5 : 4;
        if (p->has_velocity) memcpy(v + nv, p->velocity + 3 * (size_t)i, 12);
        for (int c = 0; c < nv + (p->has_velocity ? 3 : 0); c++) {
            uint32_t u;
            memcpy(&u, &v[c], 4);
            fxs_put_u32(r, u);
            r += 4;
            if (attrs && c == 4) *r++ = p->flags[i]; /* the flags byte sits between fuel and vx */
        }
        ok = fwrite(rec, 1, size, f) == size;
    }
    if (f && fclose(f)) ok = 0;
    if (!ok) fprintf(stderr, "fxctl: cannot write %s: %s\n", path, strerror(errno));
    return ok ? 0 : -1;
}

/* Decodes a particle frame (either encoding) into arrays sized from its header and writes
 * BASE.ply. */
static int fxctl_save_particles(const char *base, const struct fxc_event *ev)
{
    size_t n = ev->header.count_or_width ? ev->header.count_or_width : 1;
    float *fl = malloc(n * 8 * sizeof *fl); /* xyz, temperature, fuel, velocity */
    uint8_t *flags = malloc(n);
    struct fxc_particles p = { .capacity = (uint32_t)n, .xyz = fl, .flags = flags };
    char err[256], path[4200];
    int r = -1;
    if (fl) {
        p.temperature = fl + 3 * n;
        p.fuel = fl + 4 * n;
        p.velocity = fl + 5 * n;
    }
    if (!fl || !flags) snprintf(err, sizeof err, "out of memory");
    else if (fxc_decode_particles(&ev->header, ev->payload, &p, err, sizeof err) == 0) r = 0;
    if (r) fprintf(stderr, "fxctl: frame %" PRIu64 ": %s\n", ev->header.seq, err);
    snprintf(path, sizeof path, "%s.ply", base);
    if (!r) r = fxctl_write_ply(path, ev->header.codec, &p);
    free(fl);
    free(flags);
    return r;
}

/* Decodes an engine-encoded texture (kind 2 codec 16) and writes it as BASE.exr: the EXR of its
 * halves, the pixels the default encoding's EXR holds (uncompressed here). */
static int fxctl_save_engine_texture(const char *base, const struct fxc_event *ev)
{
    const struct fxs_header *h = &ev->header;
    struct fxc_texture t = { 0 };
    struct fx_buf exr = { 0 };
    struct fx_err e = { 0 };
    char err[sizeof e.message] = "", path[4200];
    int r = fxc_decode_texture(h, ev->payload, &t, err, sizeof err);
    if (r == 1) {
        t.capacity = (size_t)t.width * t.height * t.channels;
        r = (t.texels = malloc(t.capacity * sizeof *t.texels)) ? fxc_decode_texture(h, ev->payload, &t, err, sizeof err) : -1;
        if (!t.texels) snprintf(err, sizeof err, "out of memory");
    }
    if (!r && exr_write_mem(&(struct exr_image){ (int)t.width, (int)t.height, (int)t.channels, t.texels, EXR_CODEC_NONE },
                            &exr, &e)) {
        snprintf(err, sizeof err, "%s", e.message);
        r = -1;
    }
    if (r) fprintf(stderr, "fxctl: frame %" PRIu64 ": %s\n", h->seq, err);
    snprintf(path, sizeof path, "%s.exr", base);
    if (!r) r = fxctl_write_file(path, exr.data, exr.len);
    free(t.texels);
    fx_buf_free(&exr);
    return r;
}

/* Each product of a look-up table frame as BASE-NAME.png: the directory first (a call with no
 * texel buffers), then the texels. */
static int fxctl_save_lut(const char *base, const struct fxc_event *ev)
{
    struct fxc_lut lut = { 0 };
    char err[256] = "", path[4300];
    int r = fxc_decode_lut(&ev->header, ev->payload, &lut, err, sizeof err);
    if (r == 1 && (lut.products = calloc((size_t)lut.count, sizeof *lut.products))) {
        lut.capacity = lut.count;
        r = fxc_decode_lut(&ev->header, ev->payload, &lut, err, sizeof err);
        for (int i = 0; r == 1 && i < lut.count; i++) {
            lut.products[i].rgba_capacity = (size_t)lut.products[i].width * lut.products[i].height * 4;
            if (!(lut.products[i].rgba = malloc(lut.products[i].rgba_capacity ? lut.products[i].rgba_capacity : 1))) r = -1;
        }
        if (r == 1) r = fxc_decode_lut(&ev->header, ev->payload, &lut, err, sizeof err);
    }
    if (r > 0 && !err[0]) snprintf(err, sizeof err, "out of memory");
    for (int i = 0; r == 0 && i < lut.count; i++) {
        const struct fxc_lut_product *e = &lut.products[i];
        snprintf(path, sizeof path, "%s-%s.png", base, e->name);
        if (png_write_rgba8(path, e->rgba, e->width, e->height)) {
            snprintf(err, sizeof err, "cannot write %.100s: %.40s", path, strerror(errno));
            r = -1;
        }
    }
    for (int i = 0; lut.products && i < lut.count; i++) free(lut.products[i].rgba);
    free(lut.products);
    if (r) fprintf(stderr, "fxctl: frame %" PRIu64 ": %s\n", ev->header.seq, err[0] ? err : "out of memory");
    return r ? -1 : 0;
}

/* Writes the frame's data files: .exr (texture codec 1 as received, or the engine encoding's
 * decoded), .ply (particles, decoded) and the payload as received in .bin (for other decoders
 * to compare), or .bin alone, plus one PNG per product of a look-up table (kind 4 codec 1). */
static int fxctl_save_payload(const char *base, const struct fxc_event *ev)
{
    const struct fxs_header *h = &ev->header;
    int exr = h->kind == FXS_KIND_TEXTURE && h->codec == FXS_CODEC_EXR;
    int engine_tex = h->kind == FXS_KIND_TEXTURE && h->codec == FXS_CODEC_ENGINE;
    int particles = h->kind == FXS_KIND_PARTICLES && (h->codec == FXS_CODEC_PARTICLES ||
                                                      h->codec == FXS_CODEC_PARTICLES_BLOCKS || h->codec == FXS_CODEC_ENGINE);
    char path[4200];
    snprintf(path, sizeof path, "%s.%s", base, exr ? "exr" : "bin");
    if (h->kind == FXS_KIND_LUT && h->codec == FXS_CODEC_LUT_PACK && fxctl_save_lut(base, ev)) return -1;
    if (particles && fxctl_save_particles(base, ev)) return -1;
    if (engine_tex && fxctl_save_engine_texture(base, ev)) return -1;
    return fxctl_write_file(path, ev->payload, h->payload_bytes);
}

int fxctl_save_frame(const char *dir, const char *stream, const struct fxc_event *ev, const char *line)
{
    const struct fxs_header *h = &ev->header;
    char path[4096], *safe = strdup(stream);
    int r;
    if (!safe) return -1;
    for (char *c = safe; *c; c++)
        if (*c == '/') *c = '_';
    snprintf(path, sizeof path, "%s/%s-%" PRIu64 "%s", dir, safe, h->seq, h->kind == FXS_KIND_LIGHT_RIG ? "-rig" : "");
    free(safe);
    r = fxctl_save_payload(path, ev);
    strncat(path, ".json", sizeof path - strlen(path) - 1);
    if (!r) {
        char *text = malloc(strlen(line) + 2);
        r = text ? 0 : -1;
        if (text) {
            sprintf(text, "%s\n", line);
            r = fxctl_write_file(path, text, strlen(text));
            free(text);
        }
    }
    return r;
}
