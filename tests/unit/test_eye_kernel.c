/* test_eye_kernel.c — the compound eye's OpenCL tracer (kernels/compound_eye.cl through
 * server/effects/compound_eye.h) against the double-precision reference (tests/ref/eye_ref),
 * plus the digest §6 properties that concern the device code: no NaN or infinity over the
 * whole hemisphere of view directions (every TIR policy, both lattices), lattice
 * translation invariance, partial work-items (8 or 16 rays each), and the look-up table
 * products (sizes, every LLUT texel against the reference, gutters, macro map). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../ref/eye_ref.h"
#include "../ref/kernel_probe.h"
#include "check.h"
#include "effects/compound_eye.h"
#include "effects/eye_lut.h"
#include "fxs_frame.h"
#include "fxs_lut.h"
#include "ocl.h"
#include "params.h"
#include "slices.h"

#define TEK_N 4096

static struct ocl *tek_ocl;

/* An effect state of the complete document doc (its typed parameters). */
static struct compound_eye *tek_new(const cJSON *doc, struct fx_err *err)
{
    struct compound_eye_config c;
    return params_load(compound_eye_params, doc, &c, sizeof c, err) ? NULL : compound_eye_new(tek_ocl, &c, err);
}
static unsigned long long tek_rng = 0x9e3779b97f4a7c15ull;

static double tek_rand(double lo, double hi)
{
    tek_rng ^= tek_rng << 13;
    tek_rng ^= tek_rng >> 7;
    tek_rng ^= tek_rng << 17;
    return lo + (hi - lo) * ((tek_rng >> 11) * (1.0 / 9007199254740992.0));
}

static struct eye_optics tek_optics(int hex, double r, double n, int passes, int tir)
{
    struct eye_optics o = {.r = (float)r, .n = (float)n, .plane = (float)(2 * r),
                           .tile_h = hex ? (float)EYE_SQRT3 : 1.0f, .lattice = hex, .max_passes = passes,
                           .slices = 16, .tir = tir};
    return o;
}

static struct eye_ref_optics tek_ref(const struct eye_optics *o)
{
    struct eye_ref_optics r = {o->lattice == EYE_HEX, o->r, o->n, o->plane, o->max_passes, o->tir,
                               o->search == EYE_SEARCH_SLICES ? o->slices : 0, o->select == EYE_SELECT_THESIS4};
    return r;
}

/* A random view direction with polar angle <= max_deg (towards the surface). */
static void tek_dir(double max_deg, double d[3])
{
    double ct = cos(max_deg * M_PI / 180), z = tek_rand(ct, 1.0), ph = tek_rand(0, 2 * M_PI), s = sqrt(1 - z * z);
    d[0] = s * cos(ph);
    d[1] = s * sin(ph);
    d[2] = -z;
}

struct tek_batch {
    float p[2 * TEK_N], d[3 * TEK_N], land[2 * TEK_N], normal[3 * TEK_N];
    int status[TEK_N], passes[TEK_N], entered[TEK_N];
};
static struct tek_batch tek_b;

static int tek_trace(const struct eye_optics *o, int n)
{
    struct fx_err err = {0};
    struct eye_rays_out out = {tek_b.land, tek_b.status, tek_b.passes, tek_b.entered, tek_b.normal};
    int rc = probe_eye_trace(tek_ocl, o, n, tek_b.p, tek_b.d, &out, &err);
    CHECK(rc == 0, "probe_eye_trace: %s", err.message);
    return rc;
}

/* Kernel vs reference on random rays: the landing must agree for the great majority;
 * rays near a decision boundary (which lens, TIR or not) may legitimately differ in float
 * (at most 26 of 4096 here, status 1 of 4096). */
static void tek_compare(const struct eye_optics *o, double max_deg, const char *what)
{
    struct eye_ref_optics ro = tek_ref(o);
    for (int i = 0; i < TEK_N; i++) {
        double d[3];
        tek_dir(max_deg, d);
        tek_b.p[2 * i] = (float)tek_rand(0, 1);
        tek_b.p[2 * i + 1] = (float)tek_rand(0, o->tile_h);
        for (int k = 0; k < 3; k++) tek_b.d[3 * i + k] = (float)d[k];
    }
    if (tek_trace(o, TEK_N)) return;
    int agree = 0, status_agree = 0;
    double worst = 0;
    for (int i = 0; i < TEK_N; i++) {
        double d[3] = {tek_b.d[3 * i], tek_b.d[3 * i + 1], tek_b.d[3 * i + 2]};
        struct eye_ref_hit h;
        eye_ref_trace(&ro, tek_b.p[2 * i], tek_b.p[2 * i + 1], d, &h);
        if (h.status != tek_b.status[i]) continue;
        status_agree++;
        double e = h.status == EYE_REF_LANDED
                       ? hypot(h.land[0] - tek_b.land[2 * i], h.land[1] - tek_b.land[2 * i + 1])
                       : 0.0;
        if (e < 1e-3 * (1 + hypot(h.land[0], h.land[1])) && h.passes == tek_b.passes[i]) agree++;
        else if (e > worst) worst = e;
    }
    CHECK(status_agree >= TEK_N * 0.998, "%s: status agrees on %d of %d rays", what, status_agree, TEK_N);
    CHECK(agree >= TEK_N * 0.99, "%s: %d of %d rays agree with the reference (worst miss %.3g pitches)", what, agree,
          TEK_N, worst);
}

static void test_kernel_matches_reference(void)
{
    struct eye_optics o = tek_optics(0, 1.0, 1.491, 10, EYE_TIR_REFLECT);
    tek_compare(&o, 75, "square r=1 l=10 reflect");
    o = tek_optics(0, 0.75, 1.491, 3, EYE_TIR_MISS);
    tek_compare(&o, 75, "square r=0.75 l=3 miss");
    o = tek_optics(1, 1.2, 1.6, 10, EYE_TIR_ABSORB);
    tek_compare(&o, 75, "hex r=1.2 n=1.6 l=10 absorb");
    o = tek_optics(0, 1.5, 1.3, 0, EYE_TIR_REFLECT);
    tek_compare(&o, 80, "square r=1.5 l=0");
    o = tek_optics(0, 1.0, 1.491, 10, EYE_TIR_REFLECT);
    o.search = EYE_SEARCH_SLICES;
    o.select = EYE_SELECT_THESIS4;
    tek_compare(&o, 70, "square slices + thesis4");
    o = tek_optics(1, 0.9, 1.491, 8, EYE_TIR_REFLECT);
    o.select = EYE_SELECT_THESIS4;
    tek_compare(&o, 70, "hex thesis4");
}

/* §6.14: no NaN/Inf anywhere on the hemisphere, grazing rays included. */
static void test_no_nan_over_hemisphere(void)
{
    const int g = 64, n = g * g;
    for (int cfg = 0; cfg < 6; cfg++) {
        struct eye_optics o = tek_optics(cfg & 1, cfg < 2 ? 0.75 : cfg < 4 ? 1.0 : 2.5, cfg < 4 ? 1.491 : 1.9, 10, cfg % 3);
        for (int k = 0; k < n; k++) {
            double th = (k % g + 0.5) / g * 0.5 * M_PI * 0.9999, ph = (k / g) * 2 * M_PI / g;
            tek_b.d[3 * k] = (float)(sin(th) * cos(ph));
            tek_b.d[3 * k + 1] = (float)(sin(th) * sin(ph));
            tek_b.d[3 * k + 2] = (float)-cos(th);
            tek_b.p[2 * k] = (float)tek_rand(0, 1);
            tek_b.p[2 * k + 1] = (float)tek_rand(0, 1);
        }
        if (tek_trace(&o, n)) return;
        int bad = 0;
        for (int k = 0; k < n; k++) {
            int fin = isfinite(tek_b.normal[3 * k]) && isfinite(tek_b.normal[3 * k + 1]) && isfinite(tek_b.normal[3 * k + 2]);
            if (tek_b.status[k] == EYE_LANDED) fin = fin && isfinite(tek_b.land[2 * k]) && isfinite(tek_b.land[2 * k + 1]);
            bad += !fin || tek_b.status[k] < 0 || tek_b.status[k] > 2;
        }
        CHECK(bad == 0, "config %d: %d non-finite results", cfg, bad);
    }
}

/* §6.7: shifting the entry point by whole periods shifts the landing by the same (float:
 * a ray within rounding of a lens or TIR boundary may flip, hence 99%). */
static void test_lattice_translation(void)
{
    for (int hex = 0; hex < 2; hex++) {
        struct eye_optics o = tek_optics(hex, 1.0, 1.491, 10, EYE_TIR_REFLECT);
        const int n = 1024;
        for (int i = 0; i < n; i++) {
            double d[3];
            tek_dir(60, d);
            int k = i % (n / 2), shift = i >= n / 2;
            if (!shift) {
                tek_b.p[2 * k] = (float)tek_rand(0, 1);
                tek_b.p[2 * k + 1] = (float)tek_rand(0, o.tile_h);
                for (int c = 0; c < 3; c++) tek_b.d[3 * k + c] = (float)d[c];
            } else {
                tek_b.p[2 * i] = tek_b.p[2 * k] + 3.0f;
                tek_b.p[2 * i + 1] = tek_b.p[2 * k + 1] - 2.0f * o.tile_h;
                memcpy(tek_b.d + 3 * i, tek_b.d + 3 * k, 3 * sizeof(float));
            }
        }
        if (tek_trace(&o, n)) return;
        int same = 0;
        for (int k = 0; k < n / 2; k++) {
            int i = k + n / 2;
            float ex = tek_b.land[2 * i] - 3.0f - tek_b.land[2 * k];
            float ey = tek_b.land[2 * i + 1] + 2.0f * o.tile_h - tek_b.land[2 * k + 1];
            same += tek_b.status[i] == tek_b.status[k] &&
                    (tek_b.status[k] != EYE_LANDED || (fabsf(ex) < 2e-3f && fabsf(ey) < 2e-3f));
        }
        CHECK(same >= n / 2 * 0.99, "%s: %d of %d shifted rays identical", hex ? "hex" : "square", same, n / 2);
    }
}

/* Each work-item traces 8 or 16 rays (compound_eye_build_options): a count that leaves a
 * partial work-item traces the same as the full batch, and a bake whose texel count is not a
 * multiple of either is whole. */
static void test_partial_work_items(void)
{
    struct eye_optics o = tek_optics(1, 1.1, 1.491, 10, EYE_TIR_REFLECT);
    const int n = 13;
    for (int i = 0; i < 64; i++) {
        double d[3];
        tek_dir(75, d);
        tek_b.p[2 * i] = (float)tek_rand(0, 1);
        tek_b.p[2 * i + 1] = (float)tek_rand(0, o.tile_h);
        for (int k = 0; k < 3; k++) tek_b.d[3 * i + k] = (float)d[k];
    }
    if (tek_trace(&o, 64)) return;
    float land[2 * n];
    int status[n], passes[n];
    memcpy(land, tek_b.land, sizeof land);
    memcpy(status, tek_b.status, sizeof status);
    memcpy(passes, tek_b.passes, sizeof passes);
    if (tek_trace(&o, n)) return;
    CHECK(!memcmp(land, tek_b.land, sizeof land) && !memcmp(status, tek_b.status, sizeof status) &&
              !memcmp(passes, tek_b.passes, sizeof passes),
          "13 rays traced alone differ from the same rays in a batch of 64");

    cJSON *doc = params_defaults(compound_eye_params), *bake = NULL;
    cJSON *partial = cJSON_Parse("{\"mode\":\"bake\",\"bake_size\":129}");
    struct fx_err err = {0};
    CHECK(params_merge(compound_eye_params, doc, partial, &bake, &err) == 0, "merge: %s", err.message);
    struct compound_eye *ce = bake ? tek_new(bake, &err) : NULL;
    CHECK(ce != NULL, "compound_eye_new: %s", err.message);
    static float rgba[129 * 129 * 4];
    if (ce && compound_eye_bake(ce, rgba, &err) == 0) {
        int bad = 0, covered = 0;
        for (int k = 0; k < 129 * 129; k++) {
            float a = rgba[4 * k + 3];
            covered += a == 1.0f;
            bad += !(a == 0.0f || a == 1.0f) || !isfinite(rgba[4 * k]) || (a == 0.0f && rgba[4 * k] != 0.0f);
        }
        CHECK(bad == 0 && covered > 129 * 129 / 2, "bake 129^2: %d bad texels, %d covered", bad, covered);
    } else {
        CHECK(0, "bake 129^2: %s", err.message);
    }
    compound_eye_free(ce);
    cJSON_Delete(doc);
    cJSON_Delete(partial);
    cJSON_Delete(bake);
}

/* The table: built from the default document, packed, and consistent with its parts. */
static void test_table_products(void)
{
    cJSON *doc = params_defaults(compound_eye_params), *small = NULL;
    cJSON *partial = cJSON_Parse("{\"lut_cells\":8,\"lut_dirs\":8,\"lut_supersample\":1,\"lattice\":\"hex\"}");
    struct fx_err err = {0};
    CHECK(params_merge(compound_eye_params, doc, partial, &small, &err) == 0, "merge: %s", err.message);
    struct compound_eye *ce = small ? tek_new(small, &err) : NULL;
    CHECK(ce != NULL, "compound_eye_new: %s", err.message);
    const void *data = NULL;
    size_t len = 0;
    if (ce) CHECK(compound_eye_table(ce, &data, &len, &err) == 0, "table: %s", err.message);
    if (data) {
        const uint8_t *b = data;
        CHECK(!memcmp(b, FXS_LUT_MAGIC, 4), "magic");
        CHECK(fxs_get_u16(b + 8) == 3, "three products");
        const char *names[3] = {"PIGM", "LLUT", "LMAC"};
        int w[3] = {128, 8 * 10, 8}, h[3] = {(int)lround(128 * EYE_SQRT3), 8 * 10, 8};
        for (int i = 0; i < 3; i++) {
            const uint8_t *e = b + FXS_LUT_HEADER_BYTES + i * FXS_LUT_ENTRY_BYTES;
            CHECK(!memcmp(e, names[i], 4), "product %d is %s", i, names[i]);
            CHECK((int)fxs_get_u32(e + 12) == w[i] && (int)fxs_get_u32(e + 16) == h[i], "%s size %ux%u", names[i],
                  fxs_get_u32(e + 12), fxs_get_u32(e + 16));
            CHECK(fxs_get_u32(e + 20) + fxs_get_u32(e + 24) <= len && fxs_get_u32(e + 20) % 8 == 0, "%s within the payload",
                  names[i]);
        }
    }
    compound_eye_free(ce);
    cJSON_Delete(doc);
    cJSON_Delete(partial);
    cJSON_Delete(small);
}

/* Every texel of a table's LLUT (those the kernel traced and those copied by symmetry) is the
 * colour the double-precision reference sees along its sample ray: the pigment where it lands,
 * the base colour with alpha 0 where it misses, the dot colour where it is absorbed. */
static void tek_table_vs_reference(const char *partial_json)
{
    struct fx_err err = {0};
    cJSON *defaults = params_defaults(compound_eye_params), *partial = cJSON_Parse(partial_json), *doc = NULL;
    CHECK(params_merge(compound_eye_params, defaults, partial, &doc, &err) == 0, "merge: %s", err.message);
    struct compound_eye_config cfg;
    int loaded = doc && params_load(compound_eye_params, doc, &cfg, sizeof cfg, &err) == 0;
    struct compound_eye *ce = loaded ? compound_eye_new(tek_ocl, &cfg, &err) : NULL;
    CHECK(ce != NULL, "compound_eye_new: %s", err.message);
    const void *data = NULL;
    size_t len = 0;
    if (ce && compound_eye_table(ce, &data, &len, &err) == 0) {
        struct fxs_lut_info info;
        struct fxs_lut_product e;
        char msg[128] = "";
        uint8_t *llut = fxs_lut_header(data, len, &info, msg, sizeof msg) >= 2 && fxs_lut_entry(data, len, 1, &e, msg, sizeof msg) >= 0
                            ? fxs_lut_texels(data, len, &e, msg, sizeof msg)
                            : NULL;
        CHECK(llut != NULL, "LLUT: %s", msg);
        struct eye_optics o;
        eye_optics_from_params(&cfg, &o);
        struct eye_ref_optics ro = tek_ref(&o);
        struct eye_pigment pg;
        eye_pigment_from_params(&cfg, &pg);
        const int C = (int)info.cells, D = (int)info.dirs, T = C + 2 * EYE_LUT_GUTTER, W = D * T;
        int agree = 0, n = 0, worst = 0;
        for (int tj = 0; llut && tj < D; tj++)
            for (int ti = 0; ti < D; ti++) {
                double u = (2.0 * ti + 1) / D - 1, v = (2.0 * tj + 1) / D - 1, px = (u + v) / 2, py = (u - v) / 2;
                double w[3] = {px, py, 1 - fabs(px) - fabs(py)}, wl = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
                double d[3] = {-w[0] / wl, -w[1] / wl, -w[2] / wl};
                for (int cj = 0; cj < C; cj++)
                    for (int ci = 0; ci < C; ci++) {
                        struct eye_ref_hit h;
                        eye_ref_trace(&ro, (ci + 0.5) / C, (cj + 0.5) / C * o.tile_h, d, &h);
                        double want[4] = {0, 0, 0, h.status != EYE_REF_MISSED};
                        if (h.status == EYE_REF_LANDED) eye_pigment_at(&pg, h.land[0], h.land[1], want);
                        for (int k = 0; k < 3 && h.status != EYE_REF_LANDED; k++)
                            want[k] = h.status == EYE_REF_MISSED ? pg.base[k] : pg.dot[k];
                        const uint8_t *got = llut + 4 * ((size_t)(tj * T + EYE_LUT_GUTTER + cj) * W + ti * T + EYE_LUT_GUTTER + ci);
                        int diff = 0;
                        for (int k = 0; k < 4; k++) {
                            int dk = abs(got[k] - (int)lround(want[k] * 255));
                            diff = dk > diff ? dk : diff;
                        }
                        agree += diff <= 4;
                        worst = diff > worst ? diff : worst;
                        n++;
                    }
            }
        CHECK(n > 0 && agree >= 0.995 * n, "%s: %d of %d table texels within 4/255 of the reference (worst %d)",
              partial_json, agree, n, worst);
        free(llut);
    } else {
        CHECK(0, "table: %s", err.message);
    }
    compound_eye_free(ce);
    cJSON_Delete(defaults);
    cJSON_Delete(partial);
    cJSON_Delete(doc);
}

static void test_table_matches_reference(void)
{
    tek_table_vs_reference("{\"lut_cells\":16,\"lut_dirs\":12}"); /* hex, both mirrors */
    tek_table_vs_reference("{\"lut_cells\":16,\"lut_dirs\":11,\"lattice\":\"square\",\"sphere_search\":\"slices\","
                           "\"neighbor_select\":\"thesis4\",\"max_passes\":10,\"lut_supersample\":1}");
    tek_table_vs_reference("{\"lut_cells\":15,\"lut_dirs\":10,\"pigment_res\":129}"); /* hex, x mirror only */
}

/* The atlas gutter repeats the opposite edge of its own tile; the macro map is the tile mean. */
static void test_atlas_gutters(void)
{
    enum { C = 4, D = 2 };
    static float samples[D * D * C * C * 4];
    for (int i = 0; i < D * D * C * C * 4; i++) samples[i] = (float)((i * 37) % 251) / 250.0f;
    struct eye_lut_table t = {.cells = C, .dirs = D, .samples = samples};
    int W = eye_lut_atlas_width(C, D);
    CHECK(W == D * (C + 2), "atlas width %d", W);
    uint8_t atlas[D * (C + 2) * D * (C + 2) * 4], macro[D * D * 4];
    eye_lut_atlas(&t, atlas);
    eye_lut_macro(&t, macro);
    for (int tile = 0; tile < D * D; tile++) {
        int ox = (tile % D) * (C + 2), oy = (tile / D) * (C + 2);
        for (int k = 0; k < 4; k++) {
            /* left gutter column = last sample column, top gutter row = last sample row */
            CHECK(atlas[4 * ((oy + 1) * W + ox) + k] == atlas[4 * ((oy + 1) * W + ox + C) + k], "left gutter");
            CHECK(atlas[4 * (oy * W + ox + 2) + k] == atlas[4 * ((oy + C) * W + ox + 2) + k], "top gutter");
            CHECK(atlas[4 * ((oy + C + 1) * W + ox + 3) + k] == atlas[4 * ((oy + 1) * W + ox + 3) + k], "bottom gutter");
            double mean = 0;
            for (int s = 0; s < C * C; s++) mean += samples[4 * (tile * C * C + s) + k];
            CHECK(abs(macro[4 * tile + k] - (int)lround(mean / (C * C) * 255)) <= 1, "macro = tile mean");
        }
    }
}

/* A table or view stepped by a new compound_eye effect with the given budget per call (slices.h). */
static int tek_sliced_step(const cJSON *doc, double budget, struct slices_frame *out)
{
    struct fx_err err = {0};
    void *typed = effect_typed(&compound_eye_effect, doc, &err);
    void *ce = typed ? compound_eye_effect.create(tek_ocl, typed, &err) : NULL;
    free(typed);
    int rc = ce ? slices_step(&compound_eye_effect, ce, 0, budget, out, &err) : -1;
    CHECK(rc == 0 && out->payload, "step with %g s per call: %s", budget, err.message);
    if (ce) compound_eye_effect.destroy(ce);
    return rc || !out->payload ? -1 : 0;
}

/* The products of a table (decompressed) and a bake's EXR payload stepped a work-group or a
 * packing unit per call are those stepped whole, byte for byte. */
static void test_sliced_steps(void)
{
    static const char *const partials[] = {
        "{\"lut_cells\":8,\"lut_dirs\":8,\"lut_supersample\":2,\"lattice\":\"hex\"}",
        "{\"mode\":\"bake\",\"bake_size\":129}",
    };
    for (int i = 0; i < 2; i++) {
        cJSON *doc = params_defaults(compound_eye_params), *p = cJSON_Parse(partials[i]), *full = NULL;
        struct fx_err err = {0};
        CHECK(params_merge(compound_eye_params, doc, p, &full, &err) == 0, "merge: %s", err.message);
        uint16_t kind = i ? FXS_KIND_TEXTURE : FXS_KIND_LUT;
        struct slices_frame whole = {.kind = kind}, piece = {.kind = kind};
        if (full && !tek_sliced_step(full, INFINITY, &whole) && !tek_sliced_step(full, 0, &piece)) {
            CHECK(whole.calls == 1 && piece.calls >= 8, "%s: %d calls whole, %d in pieces", partials[i], whole.calls,
                  piece.calls);
            if (i == 1) {
                CHECK(piece.len == whole.len && !memcmp(piece.payload, whole.payload, whole.len),
                      "bake: the view in pieces is the whole view");
            } else {
                char msg[128] = "";
                for (int k = 0; k < 3; k++) {
                    struct fxs_lut_product a, b;
                    uint8_t *ta = NULL, *tb = NULL;
                    if (fxs_lut_entry(whole.payload, whole.len, k, &a, msg, sizeof msg) == 3 &&
                        fxs_lut_entry(piece.payload, piece.len, k, &b, msg, sizeof msg) == 3) {
                        ta = fxs_lut_texels(whole.payload, whole.len, &a, msg, sizeof msg);
                        tb = fxs_lut_texels(piece.payload, piece.len, &b, msg, sizeof msg);
                    }
                    CHECK(ta && tb && a.raw == b.raw && !memcmp(ta, tb, a.raw),
                          "table product %d in pieces is the whole one %s", k, msg);
                    free(ta);
                    free(tb);
                }
            }
        }
        slices_free(&whole);
        slices_free(&piece);
        cJSON_Delete(doc);
        cJSON_Delete(p);
        cJSON_Delete(full);
    }
}

/* The rays are traced in the order of what they cost the run before (eye_order.h): a stream's
 * second table or view, in that order, is its first, in index order, byte for byte, with busier
 * lanes; a third keeps the order. A GPU device keeps index order (no lanes measured). */
static void test_ray_order(void)
{
    static const char *const partials[] = {"{\"lut_cells\":16,\"lut_dirs\":16,\"max_passes\":10}",
                                           "{\"mode\":\"bake\",\"bake_size\":200,\"max_passes\":10}"};
    static float view[3][200 * 200 * 4];
    for (int i = 0; i < 2; i++) {
        cJSON *doc = params_defaults(compound_eye_params), *p = cJSON_Parse(partials[i]), *full = NULL;
        struct fx_err err = {0};
        CHECK(params_merge(compound_eye_params, doc, p, &full, &err) == 0, "merge: %s", err.message);
        struct compound_eye *ce = full ? tek_new(full, &err) : NULL;
        CHECK(ce != NULL, "compound_eye_new: %s", err.message);
        struct compound_eye_split sp[3];
        uint8_t *table[3] = {0};
        size_t len[3] = {0};
        int ok = 1;
        for (int v = 0; ce && ok && v < 3; v++) {
            const void *data;
            ok = i ? compound_eye_bake(ce, view[v], &err) == 0 : compound_eye_table(ce, &data, &len[v], &err) == 0;
            if (ok && !i && (table[v] = malloc(len[v]))) memcpy(table[v], data, len[v]);
            compound_eye_split(ce, &sp[v]);
        }
        CHECK(ok, "%s: %s", partials[i], err.message);
        if (ce && ok) {
            int same = i ? !memcmp(view[0], view[1], sizeof view[0]) && !memcmp(view[0], view[2], sizeof view[0])
                         : table[0] && table[1] && table[2] && len[0] == len[1] && len[0] == len[2] &&
                               !memcmp(table[0], table[1], len[0]) && !memcmp(table[0], table[2], len[0]);
            CHECK(same, "%s: the products in index order and in cost order differ", partials[i]);
            if (ocl_is_cpu(tek_ocl))
                CHECK(sp[0].lane_use < 0.8 && sp[1].lane_use > 0.95 && sp[2].lane_use == sp[1].lane_use,
                      "%s: lanes busy %.3f in index order, %.3f and %.3f in cost order", partials[i], sp[0].lane_use,
                      sp[1].lane_use, sp[2].lane_use);
            else
                CHECK(isnan(sp[0].lane_use) && isnan(sp[1].lane_use) && isnan(sp[2].lane_use),
                      "%s: a GPU sorted its rays (lanes busy %.3f, %.3f, %.3f)", partials[i], sp[0].lane_use,
                      sp[1].lane_use, sp[2].lane_use);
        }
        for (int v = 0; v < 3; v++) free(table[v]);
        compound_eye_free(ce);
        cJSON_Delete(doc);
        cJSON_Delete(p);
        cJSON_Delete(full);
    }
}

int main(void)
{
    struct fx_err err = {0};
    if (ocl_open(&tek_ocl, CHECK_DEVICE(), &err)) return CHECK_ABORT("ocl_open(%s): %s: %s", CHECK_DEVICE(), err.code, err.message);
    RUN(test_kernel_matches_reference);
    RUN(test_no_nan_over_hemisphere);
    RUN(test_lattice_translation);
    RUN(test_partial_work_items);
    RUN(test_table_products);
    RUN(test_table_matches_reference);
    RUN(test_atlas_gutters);
    RUN(test_sliced_steps);
    RUN(test_ray_order);
    ocl_close(tek_ocl);
    return CHECK_DONE();
}
