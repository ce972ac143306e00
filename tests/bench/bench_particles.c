/* bench_particles.c — the kind 1 particle codec against Draco and plain zstd.
 *
 * On the same frames, one line per figure: bytes per particle, encode and decode time
 * per million particles of
 *   (a) codec 2 (protocol/fxs_particles_enc.c) at pos_bits 12/16/20 (T 10, F 8 bits), and at
 *       12/16/20 bits with T and F at 8 bits: the quantisation given to Draco (equal
 *       quantisation: codec 2's position step is Draco's -qp step, largest extent /
 *       (2^B - 1) for all axes; T and F 8 bits over their range in both); then the wire
 *       cost of velocities (§7.5.7): the default without them, and with them at vel_bits
 *       4/6/8/10/12 (synthetic frames get pgen_velocities' field); and codec 3, the
 *       default as blocks on 2, 4 and 8 threads (§7.5.8);
 *   (b) Draco point cloud (draco_encoder/draco_decoder, -qp = pos bits, cl 7 and 10),
 *       fed a PLY with x, y, z and T, F, flags as red, green, blue (uchar: T and F
 *       quantised to 8 bits over their range, flags exact), because Draco's PLY reader
 *       keeps no other attribute; its own "ms to encode/decode" figures (no file I/O);
 *   (c) zstd level 1 and 3 of the raw arrays (xyz, T, F as float32, flags u8);
 *   (d) codec 1's values (grid order, deltas) as LEB128 byte streams + zstd -3: zstd as
 *       the entropy stage of an ordered scheme, for comparison;
 *   (e) the engine encoding (protocol/fxs_engine.c, PROTOCOL.md §7.8: half-float texels in one
 *       zstd frame), without and with velocities: what a game engine subscription costs the
 *       daemon and the wire.
 * Frames: synthetic SPH-like flames (tests/unit/particles_gen.h: 10k, 50k, 200k),
 * plus every DIR/<stream>-<seq>.ply that `fxctl subscribe flame --out DIR` wrote when
 * FXS_BENCH_PLY_DIR=DIR is set (real flame frames, all of them, in name order; with
 * velocities when the stream sent them). Each line says which. FXS_BENCH_VEL_ONLY=1 prints
 * only the velocity lines.
 * Last, the decode table: each frame's default payload (what the flame stream sends: 16-bit
 * positions, T 10 and F 8 bits, no velocities) decoded by the C decoder here and, in node
 * (V8, Chrome's engine), by the page's two decoders (tests/bench/particles_js_bench.mjs: the
 * C decoder as WebAssembly, and fxs_particles.js's decode()), with the targets beside them. */
#include <dirent.h>
#include <stdio.h>
#include <unistd.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <zstd.h>

#include "fxs_engine.h"
#include "fxs_particles.h"
#include "../unit/particles_gen.h"

static double bp_now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

static int bp_reps(uint32_t n) { return n < 20000 ? 30 : n < 100000 ? 10 : 4; }

static void bp_line(const char *frame, uint32_t n, const char *what, double bytes, double enc_s, double dec_s)
{
    printf("%-22s n=%-7u %-34s %6.3f B/particle  encode %8.1f ms/M  decode %8.1f ms/M  (%.3f ms / %.3f ms per 10k)\n",
           frame, n, what, bytes / n, enc_s * 1e9 / n, dec_s * 1e9 / n, enc_s * 1e7 / n, dec_s * 1e7 / n);
}

/* ---- the decode table --------------------------------------------------------------------- */

#define BP_DECODE_C_TARGET 60.0   /* ms per million particles: the decode targets */
#define BP_DECODE_WEB_TARGET 100.0
#define BP_MAX_FRAMES 4096

/* Each frame's default payload, written to bp_dir for the JavaScript figures. */
static struct bp_dec {
    char name[64], path[512];
    uint32_t n;
    double c_ms;
} bp_decs[BP_MAX_FRAMES];
static int bp_ndecs;
static char bp_dir[] = "/tmp/bench_particles_dec_XXXXXX";

/* Encodes p as the flame stream would by default, times the C decoder on it and keeps the
 * payload for bp_decode_table. */
static void bp_decode_record(const char *frame, const struct fxs_particles *pv)
{
    struct fxs_particles p = *pv, d;
    struct fxs_particles_opts o = { .pos_bits = FXS_PARTICLES_DEFAULT_POS_BITS };
    struct bp_dec *r = &bp_decs[bp_ndecs];
    uint8_t *enc = NULL;
    size_t len;
    char err[200];
    double td = 1e9;
    p.vel = NULL;
    if (bp_ndecs == BP_MAX_FRAMES) {
        printf("%s: left out of the decode table (it keeps the first %d frames)\n", frame, BP_MAX_FRAMES);
        return;
    }
    if (!bp_ndecs && !mkdtemp(bp_dir)) return;
    if (fxs_particles_encode(&p, &o, &enc, &len, err, sizeof err)) {
        printf("%s: encode failed: %s\n", frame, err);
        return;
    }
    for (int k = 0; k < 3 * bp_reps(p.n); k++) {
        double t0 = bp_now();
        int bad = fxs_particles_decode(enc, len, &d, err, sizeof err);
        td = fmin(td, bp_now() - t0);
        if (bad) {
            printf("%s: decode failed: %s\n", frame, err);
            free(enc);
            return;
        }
        fxs_particles_free(&d);
    }
    snprintf(r->name, sizeof r->name, "%s", frame);
    snprintf(r->path, sizeof r->path, "%s/%d.bin", bp_dir, bp_ndecs);
    r->n = p.n;
    r->c_ms = td * 1e9 / p.n;
    FILE *f = fopen(r->path, "wb");
    if (f && fwrite(enc, 1, len, f) == len && !fclose(f)) bp_ndecs++;
    else if (f) fclose(f);
    free(enc);
}

/* The decode table: the C figures, and the JavaScript ones from node. */
static void bp_decode_table(void)
{
    static const char *script = "tests/bench/particles_js_bench.mjs", *wasm = "clients/web/dist/fxs_particles.wasm";
    double js[BP_MAX_FRAMES], web[BP_MAX_FRAMES];
    char cmd[1024], line[1024];
    for (int i = 0; i < bp_ndecs; i++) js[i] = web[i] = -1;
    if (access(script, R_OK) || access(wasm, R_OK)) {
        printf("decode in node: not measured (%s or %s missing: run from the repository root after make)\n", script, wasm);
    } else {
        snprintf(cmd, sizeof cmd, "node %s %s %s", script, wasm, bp_dir);
        FILE *f = popen(cmd, "r");
        while (f && fgets(line, sizeof line, f)) {
            char path[512];
            unsigned n;
            double a, b;
            if (sscanf(line, "%511s %u %lf %lf", path, &n, &a, &b) != 4) {
                printf("decode in node: %s", line);
                continue;
            }
            for (int i = 0; i < bp_ndecs; i++)
                if (!strcmp(path, bp_decs[i].path)) js[i] = a, web[i] = b;
        }
        if (!f || pclose(f)) printf("decode in node: node failed (%s)\n", cmd);
    }
    printf("decode, ms per million particles, of each frame's default payload (16-bit positions, T 10, F 8 bits);\n"
           "C: this decoder; WebAssembly (the C decoder, the page's) and JavaScript (fxs_particles.js): in node\n");
    printf("%-24s %8s %22s %28s %12s\n", "frame", "n", "C (target <= 60)", "WebAssembly (target <= 100)", "JavaScript");
    double worst_c = 0, worst_w = -1;
    for (int i = 0; i < bp_ndecs; i++) {
        const struct bp_dec *r = &bp_decs[i];
        worst_c = fmax(worst_c, r->c_ms);
        if (web[i] >= 0) worst_w = fmax(worst_w, web[i]);
        char w[32] = "-", j[32] = "-";
        if (web[i] >= 0) snprintf(w, sizeof w, "%.1f %s", web[i], web[i] <= BP_DECODE_WEB_TARGET ? "met" : "missed");
        if (js[i] >= 0) snprintf(j, sizeof j, "%.1f", js[i]);
        printf("%-24s %8u %15.1f %6s %28s %12s\n", r->name, r->n, r->c_ms, r->c_ms <= BP_DECODE_C_TARGET ? "met" : "missed",
               w, j);
        remove(r->path);
    }
    if (bp_ndecs) rmdir(bp_dir);
    if (!bp_ndecs) return;
    char w[32] = "-";
    if (worst_w >= 0) snprintf(w, sizeof w, "%.1f", worst_w);
    printf("particle decode, slowest of %d frames: C %.1f ms per million (target <= %.0f: %s), WebAssembly %s ms "
           "(target <= %.0f: %s)\n", bp_ndecs, worst_c, BP_DECODE_C_TARGET, worst_c <= BP_DECODE_C_TARGET ? "met" : "missed",
           w, BP_DECODE_WEB_TARGET, worst_w < 0 ? "not measured" : worst_w <= BP_DECODE_WEB_TARGET ? "met" : "missed");
}

/* ---- (a) codec 2 ------------------------------------------------------------------------ */

/* Codec 2 (or 3) with o; with the frame's velocities when o->vel_bits is set, else without. */
static void bp_ours(const char *frame, const struct fxs_particles *pv, const struct fxs_particles_opts *o)
{
    struct fxs_particles d, copy = *pv, *p = &copy;
    uint8_t *enc = NULL;
    size_t len = 0;
    char err[200], what[64];
    double te = 1e9, td = 1e9;
    if (!o->vel_bits) copy.vel = NULL;
    for (int r = 0; r < bp_reps(p->n); r++) {
        double t0 = bp_now();
        free(enc);
        if (fxs_particles_encode(p, o, &enc, &len, err, sizeof err)) {
            printf("%s: encode failed: %s\n", frame, err);
            return;
        }
        double t1 = bp_now();
        if (fxs_particles_decode(enc, len, &d, err, sizeof err)) printf("%s: decode failed: %s\n", frame, err);
        double t2 = bp_now();
        fxs_particles_free(&d);
        te = fmin(te, t1 - t0), td = fmin(td, t2 - t1);
    }
    snprintf(what, sizeof what, "fxs codec %u pos %d T %d F %d%s", fxs_particles_codec(enc, len), o->pos_bits,
             o->temp_bits ? o->temp_bits : FXS_PARTICLES_DEFAULT_TEMP_BITS,
             o->fuel_bits ? o->fuel_bits : FXS_PARTICLES_DEFAULT_FUEL_BITS, o->vel_bits ? "" : pv->vel ? " no vel" : "");
    if (o->vel_bits) snprintf(what + strlen(what), sizeof what - strlen(what), " vel %d", o->vel_bits);
    if (o->threads > 1) snprintf(what + strlen(what), sizeof what - strlen(what), " %d threads", o->threads);
    bp_line(frame, p->n, what, (double)len, te, td);
    free(enc);
}

/* ---- (b) Draco ---------------------------------------------------------------------------- */

static uint8_t bp_q8(float v, float lo, float hi) { return hi > lo ? (uint8_t)((v - lo) / (hi - lo) * 255 + 0.5f) : 0; }

static int bp_write_draco_ply(const char *path, const struct fxs_particles *p)
{
    FILE *f = fopen(path, "wb");
    float lo[2] = { INFINITY, INFINITY }, hi[2] = { -INFINITY, -INFINITY };
    if (!f) return -1;
    for (uint32_t i = 0; i < p->n; i++) {
        lo[0] = fminf(lo[0], p->temp[i]), hi[0] = fmaxf(hi[0], p->temp[i]);
        lo[1] = fminf(lo[1], p->fuel[i]), hi[1] = fmaxf(hi[1], p->fuel[i]);
    }
    fprintf(f, "ply\nformat binary_little_endian 1.0\nelement vertex %u\nproperty float x\nproperty float y\n"
               "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n", p->n);
    for (uint32_t i = 0; i < p->n; i++) {
        uint8_t c[3] = { bp_q8(p->temp[i], lo[0], hi[0]), bp_q8(p->fuel[i], lo[1], hi[1]), p->flags[i] };
        fwrite(p->xyz + 3 * i, 4, 3, f);
        fwrite(c, 1, 3, f);
    }
    return fclose(f);
}

/* Runs cmd and returns the "(N ms to ...)" figure it prints, or -1. */
static double bp_run_ms(const char *cmd)
{
    FILE *f = popen(cmd, "r");
    char line[512];
    double ms = -1;
    if (!f) return -1;
    while (fgets(line, sizeof line, f)) {
        const char *s = strstr(line, "ms to ");
        if (s) {
            while (s > line && s[-1] == ' ') s--;
            while (s > line && (s[-1] == '.' || (s[-1] >= '0' && s[-1] <= '9'))) s--;
            ms = atof(s);
        }
    }
    return pclose(f) == 0 ? ms : -1;
}

static long bp_file_size(const char *path)
{
    FILE *f = fopen(path, "rb");
    long n = -1;
    if (f && fseek(f, 0, SEEK_END) == 0) n = ftell(f);
    if (f) fclose(f);
    return n;
}

static void bp_draco(const char *frame, const struct fxs_particles *p, int pb, int cl)
{
    char dir[] = "/tmp/bench_particles_XXXXXX", cmd[1024], what[64];
    double te = 1e9, td = 1e9;
    long size;
    if (!mkdtemp(dir)) return;
    snprintf(cmd, sizeof cmd, "%s/in.ply", dir);
    if (bp_write_draco_ply(cmd, p)) return;
    for (int r = 0; r < 3; r++) {
        snprintf(cmd, sizeof cmd, "draco_encoder -point_cloud -i %s/in.ply -o %s/out.drc -qp %d -cl %d 2>&1", dir, dir, pb, cl);
        te = fmin(te, bp_run_ms(cmd) * 1e-3);
        snprintf(cmd, sizeof cmd, "draco_decoder -i %s/out.drc -o %s/out.ply 2>&1", dir, dir);
        td = fmin(td, bp_run_ms(cmd) * 1e-3);
    }
    snprintf(cmd, sizeof cmd, "%s/out.drc", dir);
    size = bp_file_size(cmd);
    snprintf(what, sizeof what, "draco cl %d pos %d T 8 F 8", cl, pb);
    if (size > 0 && te >= 0 && td >= 0) bp_line(frame, p->n, what, (double)size, te, td);
    else printf("%-22s %s: draco_encoder/draco_decoder failed or missing\n", frame, what);
    snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
    if (system(cmd)) return;
}

/* ---- (c) zstd of raw floats ------------------------------------------------------------------ */

static void bp_zstd_buf(const char *frame, uint32_t n, const char *what, const uint8_t *raw, size_t len, int level)
{
    size_t cap = ZSTD_compressBound(len), clen = 0;
    uint8_t *c = malloc(cap), *d = malloc(len);
    double te = 1e9, td = 1e9;
    for (int r = 0; r < bp_reps(n); r++) {
        double t0 = bp_now();
        clen = ZSTD_compress(c, cap, raw, len, level);
        double t1 = bp_now();
        size_t dl = ZSTD_decompress(d, len, c, clen);
        double t2 = bp_now();
        if (ZSTD_isError(clen) || dl != len) printf("%s: zstd failed\n", frame);
        te = fmin(te, t1 - t0), td = fmin(td, t2 - t1);
    }
    bp_line(frame, n, what, (double)clen, te, td);
    free(c);
    free(d);
}

static void bp_zstd_raw(const char *frame, const struct fxs_particles *p, int level)
{
    size_t n = p->n, len = n * 21;
    uint8_t *raw = malloc(len);
    char what[64];
    memcpy(raw, p->xyz, 12 * n);
    memcpy(raw + 12 * n, p->temp, 4 * n);
    memcpy(raw + 16 * n, p->fuel, 4 * n);
    memcpy(raw + 20 * n, p->flags, n);
    snprintf(what, sizeof what, "zstd -%d raw float32 arrays", level);
    bp_zstd_buf(frame, p->n, what, raw, len, level);
    free(raw);
}

/* ---- (d) codec 1's values, zstd as the entropy stage ---------------------------------------------- */

struct bp_rec {
    uint64_t key;
    uint32_t i;
};
static int bp_rec_cmp(const void *a, const void *b)
{
    const struct bp_rec *x = a, *y = b;
    return x->key < y->key ? -1 : x->key > y->key;
}

static uint32_t bp_q(float v, float lo, float hi, int bits)
{
    uint32_t m = (1u << bits) - 1;
    return hi > lo ? (uint32_t)(((double)v - lo) / ((double)hi - lo) * m + 0.5) : 0;
}

static size_t bp_leb(uint8_t *o, uint32_t v)
{
    size_t k = 0;
    for (; v >= 128; v >>= 7) o[k++] = (uint8_t)(v | 128);
    o[k++] = (uint8_t)v;
    return k;
}

/* Values of codec 1 in its order, one LEB128 stream per kind, streams concatenated. */
static size_t bp_transform(const struct fxs_particles *p, int pb, uint8_t *out)
{
    float lo[5], hi[5];
    int k = 0, m, bits[5] = { pb, pb, pb, 10, 8 };
    struct bp_rec *r = malloc(p->n * sizeof *r);
    uint8_t *st[7];
    size_t len[7] = { 0 }, o = 0;
    uint32_t prev[3] = { 0 };
    uint64_t prev_cell = 0;
    while (k < 10 && (1ull << (3 * (k + 1))) <= p->n) k++;
    m = pb - k;
    for (int c = 0; c < 5; c++) lo[c] = INFINITY, hi[c] = -INFINITY;
    for (uint32_t i = 0; i < p->n; i++) {
        float v[5] = { p->xyz[3 * i], p->xyz[3 * i + 1], p->xyz[3 * i + 2], p->temp[i], p->fuel[i] };
        for (int c = 0; c < 5; c++) lo[c] = fminf(lo[c], v[c]), hi[c] = fmaxf(hi[c], v[c]);
    }
    for (uint32_t i = 0; i < p->n; i++) {
        uint32_t q[3];
        for (int a = 0; a < 3; a++) q[a] = bp_q(p->xyz[3 * i + a], lo[a], hi[a], pb);
        r[i].key = ((uint64_t)(q[2] >> m) << (2 * k) | (uint64_t)(q[1] >> m) << k | (q[0] >> m)) << m | (q[0] & ((1u << m) - 1));
        r[i].i = i;
    }
    qsort(r, p->n, sizeof *r, bp_rec_cmp);
    for (int s = 0; s < 7; s++) st[s] = malloc(p->n * 5 + 8);
    for (uint32_t j = 0; j < p->n; j++) {
        uint32_t i = r[j].i, q[5];
        uint64_t cell = r[j].key >> m;
        for (int c = 0; c < 5; c++) q[c] = bp_q(c < 3 ? p->xyz[3 * i + c] : c == 3 ? p->temp[i] : p->fuel[i], lo[c], hi[c], bits[c]);
        len[0] += bp_leb(st[0] + len[0], (uint32_t)(cell - prev_cell));
        len[1] += bp_leb(st[1] + len[1], cell == prev_cell && j ? (q[0] & ((1u << m) - 1)) - prev[0] : q[0] & ((1u << m) - 1));
        len[2] += bp_leb(st[2] + len[2], q[1] & ((1u << m) - 1));
        len[3] += bp_leb(st[3] + len[3], q[2] & ((1u << m) - 1));
        for (int c = 3; c < 5; c++) {
            int32_t dlt = (int32_t)q[c] - (int32_t)prev[c - 2];
            len[c + 1] += bp_leb(st[c + 1] + len[c + 1], ((uint32_t)dlt << 1) ^ (uint32_t)(dlt >> 31));
            prev[c - 2] = q[c];
        }
        st[6][len[6]++] = p->flags[i];
        prev_cell = cell, prev[0] = q[0] & ((1u << m) - 1);
    }
    for (int s = 0; s < 7; s++) memcpy(out + o, st[s], len[s]), o += len[s], free(st[s]);
    free(r);
    return o;
}

static void bp_zstd_transform(const char *frame, const struct fxs_particles *p, int pb)
{
    uint8_t *buf = malloc((size_t)p->n * 40 + 64);
    double t0 = bp_now();
    size_t len = bp_transform(p, pb, buf);
    double tt = bp_now() - t0;
    char what[64];
    snprintf(what, sizeof what, "codec 1 values+LEB128+zstd-3 pos %d", pb);
    printf("%-22s (transform alone, qsort: %.1f ms/M; zstd times below exclude it)\n", frame, tt * 1e9 / p->n);
    bp_zstd_buf(frame, p->n, what, buf, len, 3);
    free(buf);
}

/* ---- frames ---------------------------------------------------------------------------------- */

/* The wire cost of velocities: the default payload without them, then with them. */
/* ---- (e) the engine encoding ----------------------------------------------------------- */

static void bp_engine(const char *frame, const struct fxs_particles *pv, int with_vel)
{
    struct fxs_particles d, p = *pv;
    uint8_t *enc = NULL;
    size_t len = 0;
    char err[200];
    double te = 1e9, td = 1e9;
    if (!with_vel) p.vel = NULL;
    for (int r = 0; r < bp_reps(p.n); r++) {
        double t0 = bp_now();
        free(enc);
        if (fxs_engine_encode_particles(&p, FXS_ENGINE_ZSTD_LEVEL, &enc, &len, err, sizeof err)) {
            printf("%s: engine encode failed: %s\n", frame, err);
            return;
        }
        double t1 = bp_now();
        if (fxs_engine_decode_particles(enc, len, &d, err, sizeof err)) printf("%s: engine decode failed: %s\n", frame, err);
        double t2 = bp_now();
        fxs_particles_free(&d);
        te = t1 - t0 < te ? t1 - t0 : te;
        td = t2 - t1 < td ? t2 - t1 : td;
    }
    bp_line(frame, p.n, with_vel ? "engine (FXE1, zstd 3) with vel" : "engine (FXE1, zstd 3)", (double)len, te, td);
    free(enc);
}

static void bp_vel(const char *name, const struct fxs_particles *p)
{
    bp_ours(name, p, &(struct fxs_particles_opts){ .pos_bits = 16 });
    for (int vb = 4; vb <= 12; vb += 2) bp_ours(name, p, &(struct fxs_particles_opts){ .pos_bits = 16, .vel_bits = vb });
}

static void bp_frame(const char *name, const struct fxs_particles *p)
{
    static const int bits[] = { 12, 16, 20 };
    const char *vel_only = getenv("FXS_BENCH_VEL_ONLY");
    bp_decode_record(name, p);
    if (p->vel) bp_vel(name, p);
    if (vel_only && *vel_only == '1') {
        printf("\n");
        return;
    }
    for (int b = 0; b < 3; b++) bp_ours(name, p, &(struct fxs_particles_opts){ .pos_bits = bits[b] });
    for (int b = 0; b < 3; b++)
        bp_ours(name, p, &(struct fxs_particles_opts){ .pos_bits = bits[b], .temp_bits = 8, .fuel_bits = 8 });
    for (int t = 2; t <= 8; t *= 2) /* blocks on t threads (§7.5.8: a GPU device's frames) */
        bp_ours(name, p, &(struct fxs_particles_opts){ .pos_bits = 16, .threads = t });
    bp_engine(name, p, 0);
    if (p->vel) bp_engine(name, p, 1);
    for (int b = 0; b < 3; b++) bp_draco(name, p, bits[b], 7);
    bp_draco(name, p, 16, 10);
    bp_zstd_raw(name, p, 1);
    bp_zstd_raw(name, p, 3);
    bp_zstd_transform(name, p, 16);
    printf("\n");
}

static int bp_ply_name(const struct dirent *e)
{
    size_t l = strlen(e->d_name);
    return l >= 5 && !strcmp(e->d_name + l - 4, ".ply");
}

/* Every .ply in dir, in name order. */
static void bp_real_frames(const char *dir)
{
    struct dirent **names;
    int count = 0, total = scandir(dir, &names, bp_ply_name, alphasort);
    if (total < 0) {
        printf("real frames: cannot open %s\n", dir);
        return;
    }
    for (int i = 0; i < total; i++) {
        char path[4096], name[64];
        struct fxs_particles p = { 0 };
        snprintf(path, sizeof path, "%s/%s", dir, names[i]->d_name);
        if (pgen_read_ply(path, &p) || !p.n) {
            printf("real frames: %s: not a readable particle PLY, skipped\n", path);
        } else {
            snprintf(name, sizeof name, "real:%.17s", names[i]->d_name);
            bp_frame(name, &p);
            count++;
        }
        fxs_particles_free(&p);
        free(names[i]);
    }
    free(names);
    printf("real frames: %d of %d .ply files in %s\n\n", count, total, dir);
}

int main(void)
{
    static const uint32_t sizes[] = { 10000, 50000, 200000 };
    const char *dir = getenv("FXS_BENCH_PLY_DIR");
    printf("bench_particles: frames are synthetic SPH-like flames (tests/unit/particles_gen.h, sorted by cell)%s\n",
           dir ? " and real flame frames from FXS_BENCH_PLY_DIR" : "; set FXS_BENCH_PLY_DIR to add real flame frames");
    for (size_t s = 0; s < sizeof sizes / sizeof sizes[0]; s++) {
        struct fxs_particles p = { 0 };
        char name[64];
        if (pgen_flame(&p, sizes[s]) || pgen_velocities(&p)) return 1;
        snprintf(name, sizeof name, "synthetic-flame-%uk", sizes[s] / 1000);
        bp_frame(name, &p);
        fxs_particles_free(&p);
    }
    if (dir) bp_real_frames(dir);
    bp_decode_table();
    return 0;
}
