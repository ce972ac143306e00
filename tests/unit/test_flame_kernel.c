/* test_flame_kernel.c — the flame OpenCL kernels (kernels/flame.cl through
 * server/effects/flame.h) against the double-precision reference (tests/ref/flame_ref.c).
 *
 * One SPH evaluation (flame_eval) of small random particle sets — gas, sources and
 * obstacles mixed, random T, F and v, clusters of close pairs, clusters ±1e3 h apart —
 * is compared particle by particle (matched by id) with the reference: ρ, p, force, dT,
 * dF, the neighbour and flame-neighbour counts and the flame flag, in every pressure
 * form and diffusion mode. Tolerances are relative to the largest value of each quantity
 * in the set (float32 sums of ~30 terms). Then digest §8 groups B and C through flame_run:
 * isolated particles (invariant, worked step, no ignition, exact buoyancy, the wind drag of
 * §2.14 step by step against the reference), solids
 * bit-identical, kinematic obstacles, resampling (deletion rule, insertion geometry,
 * N changes only on resampling steps, no source → no insertion), determinism, and
 * positivity/boundedness over a few thousand steps of the default scene. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "../ref/flame_ref.h"
#include "check.h"
#include "effects/flame.h"
#include "kernels.h"
#include "ocl.h"
#include "params.h"

static struct ocl *tfk_ocl;
static cJSON *tfk_defaults;
static struct flame_ref_params tfk_flagp; /* T_ign, fuel_eps of the latest tfk_new (load flags) */

/* ---------------------------------------------------------------- setup */

static unsigned long long tfk_rng = 0x9E3779B97F4A7C15ULL;

static double tfk_rand(double lo, double hi)
{
    tfk_rng ^= tfk_rng << 13;
    tfk_rng ^= tfk_rng >> 7;
    tfk_rng ^= tfk_rng << 17;
    return lo + (hi - lo) * ((tfk_rng >> 11) * (1.0 / 9007199254740992.0));
}

/* A complete document: the defaults merged with the JSON text partial. NULL on failure. */
static cJSON *tfk_doc(const char *partial)
{
    cJSON *in = cJSON_Parse(partial ? partial : "{}"), *out = NULL;
    struct fx_err err = {0};
    if (!in) {
        CHECK(0, "bad test JSON %s", partial);
        return NULL;
    }
    if (params_merge(flame_params, tfk_defaults, in, &out, &err))
        CHECK(0, "params_merge %s: %s (%s): %s", partial, err.code, err.param, err.message);
    cJSON_Delete(in);
    return out;
}

/* A simulation from partial parameters; rp (may be NULL) gets the reference's view. */
static struct flame *tfk_new(const char *partial, struct flame_ref_params *rp)
{
    cJSON *doc = tfk_doc(partial);
    if (!doc) return NULL;
    struct fx_err err = {0};
    struct flame_config c;
    struct flame *fl = params_load(flame_params, doc, &c, sizeof c, &err) ? NULL : flame_new(tfk_ocl, &c, &err);
    CHECK(fl != NULL, "flame_new(%s): %s: %s", partial, err.code, err.message);
    if (rp) {
        flame_ref_defaults(rp);
        flame_ref_params_from_json(doc, rp);
        rp->cap_viscosity = 1; /* flame.c caps viscosity like diffusion (not in the digest) */
        tfk_flagp = *rp;
    }
    cJSON_Delete(doc);
    return fl;
}

static int tfk_type(uint32_t flags) { return (int)(flags & FLAME_TYPE_MASK); }

/* Device arrays from reference particles (ids 0..n-1, flame bit as the state implies). */
static int tfk_to_device(const struct flame_ref_particle *ps, int n, struct flame_particles *out)
{
    const struct flame_ref_params *rp = &tfk_flagp;
    if (flame_particles_alloc(out, n)) return -1;
    for (int i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++) {
            out->pos[4 * i + k] = (float)ps[i].r[k];
            out->vel[4 * i + k] = (float)ps[i].v[k];
        }
        out->pos[4 * i + 3] = (float)ps[i].T;
        out->vel[4 * i + 3] = (float)ps[i].F;
        out->flags[i] = (uint32_t)ps[i].type |
                        (flame_ref_is_flame(rp, (float)ps[i].T, (float)ps[i].F) ? FLAME_IS_FLAME : 0u);
        out->id[i] = (uint32_t)i;
    }
    return 0;
}

static void tfk_from_device(const struct flame_particles *in, int i, struct flame_ref_particle *q)
{
    for (int k = 0; k < 3; k++) {
        q->r[k] = in->pos[4 * i + k];
        q->v[k] = in->vel[4 * i + k];
    }
    q->T = in->pos[4 * i + 3];
    q->F = in->vel[4 * i + 3];
    q->type = tfk_type(in->flags[i]);
}

/* Rounds every value to float, as the device stores it. */
static void tfk_round(struct flame_ref_particle *q)
{
    for (int k = 0; k < 3; k++) {
        q->r[k] = (float)q->r[k];
        q->v[k] = (float)q->v[k];
    }
    q->T = (float)q->T;
    q->F = (float)q->F;
}

/* Loads ps into fl and reads the state after one evaluation (out allocated). */
static int tfk_load_eval(struct flame *fl, const struct flame_ref_particle *ps, int n, struct flame_particles *out)
{
    struct flame_particles in;
    struct fx_err err = {0};
    if (tfk_to_device(ps, n, &in)) return -1;
    int rc = flame_load(fl, &in, &err);
    CHECK(rc == 0, "flame_load: %s: %s", err.code, err.message);
    if (!rc) {
        rc = flame_eval(fl, &err);
        CHECK(rc == 0, "flame_eval: %s: %s", err.code, err.message);
    }
    if (!rc) {
        rc = flame_read(fl, out, &err);
        CHECK(rc == 0, "flame_read: %s: %s", err.code, err.message);
    }
    flame_particles_free(&in);
    return rc;
}

/* index of each id in p (ids < n_ids), -1 where absent. */
static int *tfk_index_by_id(const struct flame_particles *p, int n_ids)
{
    int *idx = malloc(sizeof(int) * (size_t)(n_ids > 0 ? n_ids : 1));
    for (int i = 0; i < n_ids; i++) idx[i] = -1;
    for (int i = 0; i < p->n; i++)
        if ((int)p->id[i] < n_ids) idx[p->id[i]] = i;
    return idx;
}

/* ---------------------------------------------------------------- random sets */

/* n particles in `clusters` cubes sized for ~20 neighbours each; cluster 0 at the origin,
 * the others ±1e3 h away when far. Mixed types, random T, F, v; 10 % close pairs. */
static struct flame_ref_particle *tfk_random_set(const struct flame_ref_params *p, int n, int clusters, int far)
{
    struct flame_ref_particle *ps = calloc((size_t)n, sizeof *ps);
    int per = (n + clusters - 1) / clusters;
    double side = p->h * cbrt(per * 4.18879 / 20.0), centre[3] = {0, 0, 0};
    for (int i = 0; i < n; i++) {
        struct flame_ref_particle *q = &ps[i];
        if (i % per == 0 && i > 0)
            for (int k = 0; k < 3; k++) centre[k] = far ? (tfk_rand(0, 1) < 0.5 ? -1 : 1) * 1e3 * p->h * tfk_rand(0.5, 1) : 2 * side * (i / per);
        int close = i % per > 0 && tfk_rand(0, 1) < 0.1;
        for (int k = 0; k < 3; k++) {
            q->r[k] = close ? ps[i - 1].r[k] + tfk_rand(-0.15, 0.15) * p->h : centre[k] + tfk_rand(0, side);
            q->v[k] = tfk_rand(-0.5, 0.5);
        }
        double u = tfk_rand(0, 1);
        q->type = u < 0.1 ? FLAME_REF_SOURCE : u < 0.2 ? FLAME_REF_OBSTACLE : FLAME_REF_GAS;
        q->T = q->type == FLAME_REF_OBSTACLE ? p->T_amb : tfk_rand(p->T_amb, 2600);
        q->F = q->type == FLAME_REF_OBSTACLE || tfk_rand(0, 1) < 0.3 ? 0 : tfk_rand(0, 120);
        tfk_round(q);
    }
    return ps;
}

/* Pairs of i within 1e-5 h of the support boundary: float may count them either way. */
static int tfk_ambiguous(const struct flame_ref_params *p, const struct flame_ref_particle *ps, int n, int i)
{
    int c = 0;
    for (int j = 0; j < n; j++)
        if (j != i && fabs(flame_ref_dist(ps[i].r, ps[j].r) - p->h) < 1e-5 * p->h) c++;
    return c;
}

/* ---------------------------------------------------------------- comparison */

struct tfk_scale { double rho, p, f, dT, dF; };

/* The device's force: pressure + viscosity + buoyancy with the updated T (§2.10). */
static double tfk_fdev(const struct flame_ref_params *p, const struct flame_ref_particle *q,
                       const struct flame_ref_eval *e, int k)
{
    double T = q->T + p->dt * (e->dT - p->k_cool * (q->T - p->T_amb));
    return e->f_press[k] + e->f_visc[k] + p->k_buo * (T - p->T_amb) * p->up[k];
}

static void tfk_scales(const struct flame_ref_params *p, const struct flame_ref_eval *ev,
                       const struct flame_ref_particle *ps, int n, struct tfk_scale *s)
{
    memset(s, 0, sizeof *s);
    for (int i = 0; i < n; i++) {
        s->rho = fmax(s->rho, ev[i].rho);
        s->p = fmax(s->p, fabs(ev[i].p));
        for (int k = 0; k < 3; k++) s->f = fmax(s->f, fabs(tfk_fdev(p, &ps[i], &ev[i], k)));
        if (ps[i].type != FLAME_REF_GAS) continue;
        s->dT = fmax(s->dT, fabs(ev[i].dT));
        s->dF = fmax(s->dF, fabs(ev[i].dF));
    }
}

/* One quantity: |got - want| <= rel * scale; prints the first few misses. Returns 1 if bad. */
static int tfk_near(const char *what, int id, double got, double want, double scale, double rel, int *printed)
{
    double tol = rel * scale + 1e-30;
    if (fabs(got - want) <= tol && got == got) return 0;
    if ((*printed)++ < 4)
        fprintf(stderr, "    id %d %s: device %.9g, reference %.9g (tol %.3g)\n", id, what, got, want, tol);
    return 1;
}

struct tfk_bad { int rho, p, f, dT, dF, nbr, fnbr, flag, missing; };

static void tfk_compare_one(const struct flame_ref_params *rp, const struct flame_ref_particle *ps, int n,
                            const struct flame_ref_eval *e, const struct flame_particles *out, int i, int id,
                            const struct tfk_scale *s, struct tfk_bad *b, int *printed)
{
    const double rel = 1e-4;
    b->rho += tfk_near("rho", id, out->rho[i], e->rho, s->rho, rel, printed);
    b->p += tfk_near("pressure", id, out->pressure[i], e->p, fmax(s->p, rp->k_stiff * s->rho), rel, printed);
    if (ps[id].type == FLAME_REF_GAS) {
        for (int k = 0; k < 3; k++) b->f += tfk_near("force", id, out->force[4 * i + k], tfk_fdev(rp, &ps[id], e, k), s->f, rel,
                             printed);
        b->dT += tfk_near("dT", id, out->dT[i], e->dT, s->dT, rel, printed);
        b->dF += tfk_near("dF", id, out->dF[i], e->dF, s->dF, rel, printed);
    }
    int amb = tfk_ambiguous(rp, ps, n, id);
    if (abs(out->nbr[i] - e->nbr) > amb || abs(out->flame_nbr[i] - e->flame_nbr) > amb) {
        b->nbr += out->nbr[i] != e->nbr;
        b->fnbr += out->flame_nbr[i] != e->flame_nbr;
        if ((*printed)++ < 4)
            fprintf(stderr, "    id %d (%.9g %.9g %.9g): nbr %d/%d flame_nbr %d/%d (device/reference)\n", id,
                    ps[id].r[0], ps[id].r[1], ps[id].r[2], out->nbr[i], e->nbr, out->flame_nbr[i], e->flame_nbr);
    }
    int flag = (out->flags[i] & FLAME_IS_FLAME) != 0; /* flame_eval keeps the loaded flag */
    if (flag != e->is_flame) {
        b->flag++;
        if ((*printed)++ < 4)
            fprintf(stderr, "    id %d: flame flag %d, reference %d (T %g F %g)\n", id, flag, e->is_flame, ps[id].T,
                    ps[id].F);
    }
}

/* Loads ps into fl, evaluates on both sides and compares everything. */
static void tfk_eval_compare(const char *label, struct flame *fl, const struct flame_ref_params *rp,
                             const struct flame_ref_particle *ps, int n)
{
    struct flame_particles out;
    if (!fl || tfk_load_eval(fl, ps, n, &out)) return;
    struct flame_ref_eval *ev = calloc((size_t)n, sizeof *ev);
    flame_ref_eval_all(rp, ps, n, ev);
    struct tfk_scale s;
    tfk_scales(rp, ev, ps, n, &s);
    struct tfk_bad b = {0};
    int printed = 0, *idx = tfk_index_by_id(&out, n);
    CHECK(out.n == n, "%s: %d particles read back, %d loaded", label, out.n, n);
    for (int id = 0; id < n; id++) {
        if (idx[id] < 0) {
            b.missing++;
            continue;
        }
        tfk_compare_one(rp, ps, n, &ev[id], &out, idx[id], id, &s, &b, &printed);
    }
    CHECK(b.missing + b.rho + b.p + b.f + b.dT + b.dF + b.nbr + b.fnbr + b.flag == 0,
          "%s (n %d): bad missing %d rho %d p %d force %d dT %d dF %d nbr %d flame_nbr %d flag %d "
          "(scales rho %g p %g f %g dT %g dF %g)",
          label, n, b.missing, b.rho, b.p, b.f, b.dT, b.dF, b.nbr, b.fnbr, b.flag, s.rho, s.p, s.f, s.dT, s.dF);
    free(idx);
    free(ev);
    flame_particles_free(&out);
}

/* ---------------------------------------------------------------- SPH evaluation */

static void tfk_eval_case(const char *label, const char *partial, int n, int clusters, int far)
{
    struct flame_ref_params rp;
    struct flame *fl = tfk_new(partial, &rp);
    if (!fl) return;
    struct flame_ref_particle *ps = tfk_random_set(&rp, n, clusters, far);
    tfk_eval_compare(label, fl, &rp, ps, n);
    free(ps);
    flame_free(fl);
}

static void test_eval_small(void) { tfk_eval_case("200 mixed", NULL, 200, 1, 0); }

static void test_eval_mixed(void) { tfk_eval_case("2000 mixed, 3 clusters", NULL, 2000, 3, 0); }

static void test_eval_far_apart(void) { tfk_eval_case("1200 in 6 clusters ±1e3 h", NULL, 1200, 6, 1); }

/* The row hash's multiplier of cy or cz, read from the embedded kernel source so the test
 * follows the kernel: "#define NAME 0x...u". 0 if absent. */
static uint32_t tfk_kernel_hex(const char *name)
{
    const char *src = kernels_source("flame.cl"), *at = src ? strstr(src, name) : NULL;
    return at ? (uint32_t)strtoul(at + strlen(name), NULL, 16) : 0;
}

/* Forced hash collisions for every table the code can choose (M = 2^k, k <= 22): cells of
 * edge h along y and z (h/4 along x) hash to (cx + HP1 cy + HP2 cz) mod M, so the rows
 * (cy, cz) and (cy + dy, cz + dz) share every key when dy HP1 + dz HP2 = 0 mod 2^22. The
 * smallest such (dy, dz) (~2^11 cells) is found from the kernel's own multipliers; 500 groups
 * of 4 particles near the origin get exact twins shifted by (dy, dz) cells, so every occupied
 * cell's key run after the sort holds the particles of two places ~2000 h apart, and each
 * place's densities, forces and neighbour counts must still match the reference's (a key run
 * taken for a cell without the position and row tests would count the twins). */
static void test_eval_hash_collisions(void)
{
    uint32_t hp1 = tfk_kernel_hex("#define FL_HP1"), hp2 = tfk_kernel_hex("#define FL_HP2");
    const uint32_t m22 = (1u << 22) - 1u;
    CHECK((hp2 & 1u) && hp1, "row hash multipliers found in flame.cl (%#x, %#x), the second odd", hp1, hp2);
    if (!(hp2 & 1u) || !hp1) return;
    uint32_t inv = hp2; /* hp2^-1 mod 2^32 by Newton's iteration */
    for (int i = 0; i < 5; i++) inv *= 2u - hp2 * inv;
    int dy = 0, dz = 0, best = 1 << 30;
    for (int y = 1; y <= 4096; y++) {
        int z = (int)((0u - (uint32_t)y * hp1) * inv & m22);
        if (z > (1 << 21)) z -= 1 << 22;
        if ((y > abs(z) ? y : abs(z)) < best) best = y > abs(z) ? y : abs(z), dy = y, dz = z;
    }
    CHECK((((uint32_t)dy * hp1 + (uint32_t)dz * hp2) & m22) == 0 && best <= 4096,
          "rows (0,0) and (%d,%d) share every key of a table of up to 2^22", dy, dz);
    struct flame_ref_params rp;
    struct flame *fl = tfk_new(NULL, &rp);
    if (!fl) return;
    const int n = 4000, half = n / 2;
    struct flame_ref_particle *ps = tfk_random_set(&rp, n, 1, 0);
    for (int i = 0; i < half; i += 4) { /* groups inside one y/z cell each, cells spread over 12 h */
        double c[3] = {tfk_rand(-6, 6) * rp.h, (floor(tfk_rand(-6, 6)) + 0.5) * rp.h,
                       (floor(tfk_rand(-6, 6)) + 0.5) * rp.h};
        for (int j = i; j < i + 4; j++) {
            for (int k = 0; k < 3; k++) ps[j].r[k] = c[k] + tfk_rand(-0.35, 0.35) * rp.h;
            tfk_round(&ps[j]);
            ps[j + half] = ps[j];
            ps[j + half].r[1] += dy * rp.h;
            ps[j + half].r[2] += dz * rp.h;
            tfk_round(&ps[j + half]);
        }
    }
    tfk_eval_compare("2000 particles and their twins in colliding rows", fl, &rp, ps, n);
    free(ps);
    flame_free(fl);
}

static void test_eval_symmetric_literal(void)
{
    tfk_eval_case("symmetric pressure", "{\"pressure_form\":\"symmetric\"}", 600, 1, 0);
    tfk_eval_case("literal diffusion", "{\"diffusion_mode\":\"literal\"}", 600, 1, 0);
}

static void test_eval_other_params(void)
{
    tfk_eval_case("h 0.02, omega 0.2, stiff", "{\"h\":0.02,\"omega_max\":0.2,\"k_stiff\":40,\"k_viscosity\":0.02}",
                  500, 1, 0);
    tfk_eval_case("up y, wind, T_ign 1500, k_buo 0.05",
                  "{\"up\":[0,1,0],\"wind_accel\":[3,0,1],\"T_ign\":1500,\"k_buo\":0.05,\"fuel_eps\":0.5}", 500, 1, 0);
}

/* d = 0.499 h lattice (no pair exactly at h): interior ρ ≈ 1 and 32 neighbours on device. */
static void test_eval_lattice(void)
{
    struct flame_ref_params rp;
    struct flame *fl = tfk_new(NULL, &rp);
    if (!fl) return;
    const int side = 9;
    struct flame_ref_particle *ps = calloc(side * side * side, sizeof *ps);
    int n = 0;
    for (int i = 0; i < side; i++)
        for (int j = 0; j < side; j++)
            for (int k = 0; k < side; k++, n++) {
                ps[n].r[0] = 0.1 + i * 0.499 * rp.h;
                ps[n].r[1] = -0.2 + j * 0.499 * rp.h;
                ps[n].r[2] = 0.3 + k * 0.499 * rp.h;
                ps[n].T = 1500;
                ps[n].F = 10;
                tfk_round(&ps[n]);
            }
    tfk_eval_compare("lattice 0.499h", fl, &rp, ps, n);
    struct flame_particles out;
    if (!tfk_load_eval(fl, ps, n, &out)) {
        int *idx = tfk_index_by_id(&out, n), c = idx[(side / 2) * side * side + (side / 2) * side + side / 2];
        CHECK(c >= 0 && out.nbr[c] == 32 && fabs(out.rho[c] - 1.0) < 0.02, "centre nbr %d rho %g",
              c >= 0 ? out.nbr[c] : -1, c >= 0 ? out.rho[c] : 0);
        free(idx);
        flame_particles_free(&out);
    }
    free(ps);
    flame_free(fl);
}

/* ---------------------------------------------------------------- group B through flame_run */

/* Isolated gas particles 10 h apart (no neighbours), states from `tf` pairs. */
static struct flame_ref_particle *tfk_isolated(const struct flame_ref_params *rp, const double (*tf)[2], int n)
{
    struct flame_ref_particle *ps = calloc((size_t)n, sizeof *ps);
    for (int i = 0; i < n; i++) {
        ps[i].r[0] = 10 * rp->h * i;
        ps[i].T = tf[i][0];
        ps[i].F = tf[i][1];
        tfk_round(&ps[i]);
    }
    return ps;
}

/* Loads ps and runs `steps`, then reads back; returns 0 on success. */
static int tfk_load_run(struct flame *fl, const struct flame_ref_particle *ps, int n, int steps,
                        struct flame_particles *out)
{
    struct flame_particles in;
    struct fx_err err = {0};
    if (tfk_to_device(ps, n, &in)) return -1;
    int rc = flame_load(fl, &in, &err);
    CHECK(rc == 0, "flame_load: %s: %s", err.code, err.message);
    if (!rc && steps > 0) {
        rc = flame_run(fl, steps, &err);
        CHECK(rc == 0, "flame_run: %s: %s", err.code, err.message);
    }
    if (!rc) {
        rc = flame_read(fl, out, &err);
        CHECK(rc == 0, "flame_read: %s: %s", err.code, err.message);
    }
    flame_particles_free(&in);
    return rc;
}

/* One step of isolated particles through flame_run. The first step after flame_load is a
 * resampling step (index 0) that appends neighbours to lone flame particles after the
 * integration, so every step reloads the particles alone: each one stays isolated. */
static int tfk_isolated_step(struct flame *fl, struct flame_ref_particle *ps, int n)
{
    struct flame_particles out;
    if (tfk_load_run(fl, ps, n, 1, &out)) return -1;
    int *idx = tfk_index_by_id(&out, n), rc = 0;
    for (int i = 0; i < n; i++) {
        if (idx[i] < 0) {
            CHECK(0, "isolated particle %d (T %g F %g) deleted", i, ps[i].T, ps[i].F);
            rc = -1;
            continue;
        }
        tfk_from_device(&out, idx[i], &ps[i]);
    }
    free(idx);
    flame_particles_free(&out);
    return rc;
}

/* B2: T0 = 1200, F0 = 10 → T = 1260, F = 9.4 after one step of 1 ms. */
static void test_run_worked_step(void)
{
    struct flame_ref_params rp;
    struct flame *fl = tfk_new("{\"dt\":0.001}", &rp);
    if (!fl) return;
    const double tf[3][2] = {{1200, 10}, {1200, 10}, {2000, 100}};
    struct flame_ref_particle *ps = tfk_isolated(&rp, tf, 3);
    if (!tfk_isolated_step(fl, ps, 3)) {
        CHECK_NEAR(ps[0].T, 1260, 1260 * 2e-7);
        CHECK_NEAR(ps[0].F, 9.4, 9.4 * 2e-7);
        CHECK(ps[0].T == ps[1].T && ps[0].F == ps[1].F, "same input, different result");
        CHECK_NEAR(ps[2].T, 3000, 3000 * 2e-7); /* S = 2000: +1000 K, -10 fuel */
        CHECK_NEAR(ps[2].F, 90, 90 * 2e-7);
    }
    free(ps);
    flame_free(fl);
}

/* A step burns at most the fuel it has: at dt = 4 ms an Euler step at 8000 K would burn 160 of
 * 100 units; the particle burns its 100 and gains exactly 100 k_pt/k_cf = 10000 K (the invariant
 * T + 100F), while a slower case (1200 K, F 10: burns 2.4) is the plain Euler step. The two are
 * h/2 apart without diffusion (k_h = k_f = 0), so the second, still burning, keeps the first
 * (no fuel left, no flame) through the resampling of the step. */
static void test_run_burn_limit(void)
{
    struct flame_ref_params rp;
    struct flame *fl = tfk_new("{\"dt\":0.004,\"k_h\":0,\"k_f\":0}", &rp);
    if (!fl) return;
    const double tf[2][2] = {{8000, 100}, {1200, 10}};
    struct flame_ref_particle *ps = tfk_isolated(&rp, tf, 2);
    ps[1].r[0] = (float)(0.5 * rp.h);
    struct flame_ref_particle ref[2] = {ps[0], ps[1]};
    if (!tfk_isolated_step(fl, ps, 2)) {
        flame_ref_step(&rp, ref, 2, NULL);
        CHECK_NEAR(ps[0].F, 0, 1e-6);
        CHECK_NEAR(ps[0].T, 18000, 18000 * 2e-7);
        CHECK_NEAR(ps[1].T, 1440, 1440 * 2e-7);
        CHECK_NEAR(ps[1].F, 7.6, 7.6 * 2e-7);
        for (int i = 0; i < 2; i++) {
            CHECK_NEAR(ref[i].T, ps[i].T, ps[i].T * 2e-7);
            CHECK_NEAR(ref[i].F, ps[i].F, 1e-5);
        }
    }
    free(ps);
    flame_free(fl);
}

/* B1/B2 for one particle: E = T + 100F conserved to 1e-5 per step, T within 1e-4 of the
 * reference's Euler steps and on the logistic curve within tol until the fuel is spent (F < 0.01; below fuel_eps the lone particle is
 * no flame and the death rule removes it), for at most 300 steps. */
static void tfk_burn_case(struct flame *fl, const struct flame_ref_params *rp, double T0, double F0, double tol)
{
    const double tf[1][2] = {{T0, F0}};
    struct flame_ref_particle *ps = tfk_isolated(rp, tf, 1), ref = ps[0];
    double ratio = rp->k_pt / rp->k_cf, E = ps[0].T + ratio * ps[0].F, worst_e = 0, worst_l = 0, worst_r = 0;
    int s = 0;
    while (s < 300 && ps[0].F >= 0.01) {
        double e0 = ps[0].T + ratio * ps[0].F;
        if (tfk_isolated_step(fl, ps, 1)) break;
        flame_ref_step(rp, &ref, 1, NULL);
        s++;
        worst_e = fmax(worst_e, fabs(ps[0].T + ratio * ps[0].F - e0) / e0);
        double an = flame_ref_logistic_T(rp, T0, F0, s * rp->dt);
        worst_l = fmax(worst_l, fabs(ps[0].T - an) / an);
        worst_r = fmax(worst_r, fabs(ps[0].T - ref.T) / ref.T);
    }
    CHECK(worst_e < 1e-5, "T0 %g F0 %g: invariant T + 100F drifts %g per step", T0, F0, worst_e);
    CHECK(worst_r < 1e-4, "T0 %g F0 %g: %g from the reference's Euler steps", T0, F0, worst_r);
    CHECK(worst_l < tol, "T0 %g F0 %g: logistic deviation %g (tol %g)", T0, F0, worst_l, tol);
    CHECK(fabs(ps[0].T - E) < 0.01 * E, "T0 %g F0 %g: T = %g after %d steps, want E = %g", T0, F0, ps[0].T, s, E);
    free(ps);
}

static void test_run_invariant_logistic(void)
{
    struct flame_ref_params rp;
    struct flame *fl = tfk_new("{\"dt\":0.001}", &rp);
    if (!fl) return;
    tfk_burn_case(fl, &rp, 1200, 10, 0.01); /* the digest's case: rate 110/s, dt rate 0.11 */
    tfk_burn_case(fl, &rp, 1500, 50, 0.05); /* rate 325/s: Euler's own error reaches ~3 % */
    tfk_burn_case(fl, &rp, 1100, 2, 0.01);
    flame_free(fl);
}

/* §9 #13: a lone non-reacting flame particle at 2000 K cools by dt k_cool (T - T_amb). */
static void test_run_cooling(void)
{
    struct flame_ref_params rp;
    struct flame *fl = tfk_new("{\"dt\":0.001,\"k_rs\":0,\"k_cool\":5}", &rp);
    if (!fl) return;
    const double tf[1][2] = {{2000, 10}};
    struct flame_ref_particle *ps = tfk_isolated(&rp, tf, 1);
    double T = 2000;
    for (int s = 0; s < 10 && !tfk_isolated_step(fl, ps, 1); s++) {
        T -= rp.dt * rp.k_cool * (T - rp.T_amb);
        CHECK_NEAR(ps[0].T, T, 1e-6 * T);
    }
    free(ps);
    flame_free(fl);
}

/* B4: a lone flame particle that does not react (k_rs = 0) keeps T = 2000 and gains
 * Δv = dt k_buo 1700/ρ along `up` every step; at T_amb the force is exactly zero. */
static void tfk_buoyancy_case(const char *partial, int axis)
{
    struct flame_ref_params rp;
    struct flame *fl = tfk_new(partial, &rp);
    if (!fl) return;
    const double tf[1][2] = {{2000, 10}};
    struct flame_ref_particle *ps = tfk_isolated(&rp, tf, 1);
    double rho = rp.mass * flame_ref_w_poly6(0, rp.h), want = rp.dt * rp.k_buo * 1700 / rho;
    for (int s = 0; s < 5; s++) {
        double v0[3] = {ps[0].v[0], ps[0].v[1], ps[0].v[2]};
        if (tfk_isolated_step(fl, ps, 1)) break;
        for (int k = 0; k < 3; k++)
            CHECK(fabs(ps[0].v[k] - v0[k] - (k == axis ? want : 0)) <= 2e-6 * want * (s + 1), "%s step %d: Δv[%d] %.9g, want %.9g",
                  partial, s, k, ps[0].v[k] - v0[k], k == axis ? want : 0);
        CHECK(ps[0].T == 2000 && ps[0].F == 10, "T %g F %g", ps[0].T, ps[0].F);
    }
    free(ps);
    flame_free(fl);
}

static void test_run_buoyancy(void)
{
    tfk_buoyancy_case("{\"dt\":0.001,\"k_rs\":0}", 2);
    tfk_buoyancy_case("{\"dt\":0.001,\"k_rs\":0,\"k_buo\":0.03,\"up\":[0,1,0]}", 1);
    struct flame_ref_params rp;
    struct flame *fl = tfk_new(NULL, &rp);
    if (!fl) return;
    struct flame_ref_particle q = {.T = rp.T_amb};
    tfk_round(&q);
    struct flame_particles out;
    if (!tfk_load_eval(fl, &q, 1, &out)) {
        CHECK(out.force[0] == 0 && out.force[1] == 0 && out.force[2] == 0, "force at T_amb %g %g %g", out.force[0],
              out.force[1], out.force[2]);
        CHECK(out.dT[0] == 0 && out.dF[0] == 0, "dT %g dF %g", out.dT[0], out.dF[0]);
        flame_particles_free(&out);
    }
    flame_free(fl);
}

/* §2.14 drag: lone flame particles (k_rs = 0, so T and F stay) moving in every direction
 * relax toward wind_velocity across `up` by exp(-wind_drag dt) a step, while along `up`
 * only buoyancy acts; the device follows the reference's steps (flame_ref_drag) to float
 * rounding for 20 steps, with a tilted `up` too. */
static void tfk_drag_case(const char *partial)
{
    struct flame_ref_params rp;
    struct flame *fl = tfk_new(partial, &rp);
    if (!fl) return;
    const double tf[3][2] = {{2000, 10}, {1500, 5}, {2500, 1}};
    struct flame_ref_particle *ps = tfk_isolated(&rp, tf, 3), ref[3];
    const double v0[3][3] = {{0.5, 0.5, 1}, {-3, 2, -1}, {0, 0, 0}};
    for (int i = 0; i < 3; i++) {
        memcpy(ps[i].v, v0[i], sizeof v0[i]);
        tfk_round(&ps[i]);
        ref[i] = ps[i];
    }
    double worst = 0, worst_up = 0;
    for (int s = 0; s < 20 && !tfk_isolated_step(fl, ps, 3); s++) {
        flame_ref_step(&rp, ref, 3, NULL);
        for (int i = 0; i < 3; i++) {
            double du = 0, ru = 0;
            for (int k = 0; k < 3; k++) {
                worst = fmax(worst, fabs(ps[i].v[k] - ref[i].v[k]));
                du += ps[i].v[k] * rp.up[k];
                ru += ref[i].v[k] * rp.up[k];
            }
            worst_up = fmax(worst_up, fabs(du - ru));
        }
    }
    /* the reference's own check: along up, v0 + 20 buoyancy steps (ρ of a lone particle) */
    double rho = rp.mass * flame_ref_w_poly6(0, rp.h), up0 = 0, up1 = 0, across = 0;
    for (int k = 0; k < 3; k++) {
        up0 += v0[0][k] * rp.up[k];
        up1 += ref[0].v[k] * rp.up[k];
    }
    CHECK_NEAR(up1, up0 + 20 * rp.dt * rp.k_buo * 1700 / rho, 1e-9);
    for (int k = 0; k < 3; k++) {
        double rel0 = v0[0][k] - rp.wind_velocity[k], rel = ref[0].v[k] - rp.wind_velocity[k], a0 = 0, a = 0;
        for (int j = 0; j < 3; j++) {
            a0 += (v0[0][j] - rp.wind_velocity[j]) * rp.up[j];
            a += (ref[0].v[j] - rp.wind_velocity[j]) * rp.up[j];
        }
        across = fmax(across, fabs((rel - a * rp.up[k]) - (rel0 - a0 * rp.up[k]) * exp(-20 * rp.wind_drag * rp.dt)));
    }
    CHECK(across < 1e-12, "%s: reference drag %g from exp(-k t)", partial, across);
    CHECK(worst < 2e-5, "%s: device velocity %g m/s from the reference", partial, worst);
    CHECK(worst_up < 2e-5, "%s: device velocity along up %g m/s from the reference", partial, worst_up);
    free(ps);
    flame_free(fl);
}

static void test_run_drag(void)
{
    tfk_drag_case("{\"k_rs\":0,\"wind_velocity\":[2,-1,5],\"wind_drag\":30}");
    tfk_drag_case("{\"k_rs\":0,\"wind_velocity\":[-1,3,0.5],\"wind_drag\":200,\"dt\":0.004,\"up\":[0,0.6,0.8]}");
}

/* B3: T0 = 900 with fuel, and T0 = 1500 without, never ignite. They sit next to a burning
 * source so the death rule keeps them; diffusion and all forces are off, so their T and F
 * must stay bit-identical for 300 steps of flame_run (resampling included). */
static void test_run_no_ignition(void)
{
    struct flame_ref_params rp;
    struct flame *fl = tfk_new("{\"k_h\":0,\"k_f\":0,\"k_buo\":0,\"k_stiff\":0,\"k_viscosity\":0,\"dt\":0.001}", &rp);
    if (!fl) return;
    struct flame_ref_particle ps[3] = {
        {.r = {0, 0, 0}, .T = 1500, .F = 10, .type = FLAME_REF_SOURCE},
        {.r = {0.3 * rp.h, 0, 0}, .T = 900, .F = 10},
        {.r = {-0.3 * rp.h, 0, 0}, .T = 1500, .F = 0},
    };
    for (int i = 0; i < 3; i++) tfk_round(&ps[i]);
    struct flame_particles out;
    if (!tfk_load_run(fl, ps, 3, 300, &out)) {
        int *idx = tfk_index_by_id(&out, 3);
        for (int i = 1; i < 3; i++) {
            CHECK(idx[i] >= 0, "particle %d deleted", i);
            if (idx[i] < 0) continue;
            float T = out.pos[4 * idx[i] + 3], F = out.vel[4 * idx[i] + 3];
            CHECK(T == (float)ps[i].T && F == (float)ps[i].F, "T0 %g F0 %g -> T %g F %g", ps[i].T, ps[i].F, T, F);
            CHECK(!(out.flags[idx[i]] & FLAME_IS_FLAME), "flame flag set");
        }
        free(idx);
        flame_particles_free(&out);
    }
    flame_free(fl);
}

/* ---------------------------------------------------------------- group C through flame_run */

/* The digest's 3 cm disc (digest §9 #17) at the thesis's scale (Table 3.1's h, ~1.7k particles)
 * with no base plate: the effect's default scene has 10k particles on a plate. */
#define TFK_THESIS "\"obstacles\":[],\"h\":0.01125"
#define TFK_SCENE "\"sources\":[{\"radius\":0.015}]," TFK_THESIS

static int tfk_run(struct flame *fl, int steps)
{
    struct fx_err err = {0};
    int rc = flame_run(fl, steps, &err);
    CHECK(rc == 0, "flame_run(%d) at step %llu: %s: %s", steps, (unsigned long long)flame_steps(fl), err.code,
          err.message);
    return rc;
}

static int tfk_read(struct flame *fl, struct flame_particles *out)
{
    struct fx_err err = {0};
    int rc = flame_read(fl, out, &err);
    CHECK(rc == 0, "flame_read: %s: %s", err.code, err.message);
    return rc;
}

static int tfk_find(const struct flame_particles *p, uint32_t id)
{
    for (int i = 0; i < p->n; i++)
        if (p->id[i] == id) return i;
    return -1;
}

/* C1/C2 for one solid of the initial state s0 (index i) found at index j of s after `steps`. */
static void tfk_check_solid(const struct flame_particles *s0, int i, const struct flame_particles *s, int j,
                            int steps, double dt)
{
    int type = tfk_type(s0->flags[i]);
    CHECK(j >= 0, "solid id %u (type %d) deleted after %d steps", s0->id[i], type, steps);
    if (j < 0) return;
    CHECK(s->flags[j] == s0->flags[i], "solid id %u flags %u -> %u", s0->id[i], s0->flags[i], s->flags[j]);
    CHECK(s->pos[4 * j + 3] == s0->pos[4 * i + 3] && !memcmp(&s->vel[4 * j], &s0->vel[4 * i], 16),
          "solid id %u: T/v/F changed", s0->id[i]);
    if (type == FLAME_SOURCE) {
        CHECK(!memcmp(&s->pos[4 * j], &s0->pos[4 * i], 12), "source id %u moved", s0->id[i]);
        return;
    }
    for (int k = 0; k < 3; k++) {
        double want = s0->pos[4 * i + k] + s0->vel[4 * i + k] * dt * steps, got = s->pos[4 * j + k];
        CHECK(fabs(got - want) <= 1e-6 + steps * 1.2e-7 * fabs(want), "obstacle id %u axis %d after %d steps: %.9g, "
              "want r0 + v t = %.9g", s0->id[i], k, steps, got, want);
    }
}

/* C1/C2: sources bit-identical, obstacles at r0 + v t with T, F, v constant, none deleted. */
static void test_run_solids(void)
{
    struct flame_ref_params rp;
    struct flame *fl = tfk_new("{" TFK_SCENE ",\"obstacles\":[{\"pos\":[0,0.03,0.03],\"velocity\":[0,-0.2,0.05]}]}",
                               &rp);
    struct flame_particles s0, s;
    if (!fl || tfk_read(fl, &s0)) goto done;
    int solids = 0;
    for (int i = 0; i < s0.n; i++) solids += tfk_type(s0.flags[i]) != FLAME_GAS;
    CHECK(solids == s0.n && solids > 100, "initial state: %d solids of %d particles", solids, s0.n);
    for (int chunk = 1; chunk <= 4; chunk++) {
        if (tfk_run(fl, 50) || tfk_read(fl, &s)) break;
        int now = 0;
        for (int j = 0; j < s.n; j++) now += tfk_type(s.flags[j]) != FLAME_GAS;
        CHECK(now == solids && s.n > solids, "after %d steps: %d solids (want %d), %d particles", 50 * chunk, now,
              solids, s.n);
        for (int i = 0; i < s0.n; i++) tfk_check_solid(&s0, i, &s, tfk_find(&s, s0.id[i]), 50 * chunk, rp.dt);
        flame_particles_free(&s);
    }
    flame_particles_free(&s0);
done:
    flame_free(fl);
}

/* Müller normal at particle p from the particles of s (inserted ones, rho = 0, skipped). */
static void tfk_normal(const struct flame_ref_params *rp, const struct flame_particles *s, int p, double n[3])
{
    n[0] = n[1] = n[2] = 0;
    for (int j = 0; j < s->n; j++) {
        if (j == p || s->rho[j] <= 0) continue;
        double x[3], g[3];
        for (int k = 0; k < 3; k++) x[k] = (double)s->pos[4 * p + k] - s->pos[4 * j + k];
        flame_ref_grad_poly6(x, rp->h, g);
        for (int k = 0; k < 3; k++) n[k] += rp->mass / s->rho[j] * g[k];
    }
}

/* C4 for one inserted particle q and its parent p (both indices of s). Returns 1 when the
 * insertion went outward (against the reference normal), 0 inward, -1 undetermined. */
static int tfk_check_insert(const struct flame_ref_params *rp, const struct flame_particles *s, int q, int p)
{
    double dist = 0, dot = 0, n[3];
    tfk_normal(rp, s, p, n);
    for (int k = 0; k < 3; k++) {
        double dx = (double)s->pos[4 * q + k] - s->pos[4 * p + k];
        dist += dx * dx;
        dot += dx * n[k];
    }
    dist = sqrt(dist);
    CHECK(fabs(dist - rp->d) <= 2e-6 + 1e-6 * fabs(s->pos[4 * p + 2]), "inserted id %u: %.9g from parent id %u, "
          "want d = %.9g", s->id[q], dist, s->id[p], rp->d);
    CHECK(s->pos[4 * q + 3] == (float)rp->T_amb && s->vel[4 * q + 3] == 0, "inserted id %u: T %g F %g", s->id[q],
          s->pos[4 * q + 3], s->vel[4 * q + 3]);
    CHECK(!memcmp(&s->vel[4 * q], &s->vel[4 * p], 12), "inserted id %u: velocity not the parent's", s->id[q]);
    CHECK(tfk_type(s->flags[q]) == FLAME_GAS, "inserted id %u: flags %u", s->id[q], s->flags[q]);
    double nn = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (nn * rp->h < 0.5) return -1; /* nearly symmetric neighbourhood: direction is arbitrary */
    return dot < 0;
}

/* C3/C4 on the state read right after a resampling step: survivors carry the counts of the
 * pass that decided, inserted particles (rho = 0) follow in parent order. */
static void tfk_check_resampled(const struct flame_ref_params *rp, const struct flame_particles *s)
{
    int ns = 0, bad_death = 0, *parents = malloc(sizeof(int) * (size_t)(s->n ? s->n : 1)), np = 0, out = 0, in = 0;
    if (!parents) {
        CHECK(0, "out of memory");
        return;
    }
    uint32_t max_id = 0;
    while (ns < s->n && s->rho[ns] > 0) ns++;
    for (int i = 0; i < ns; i++) {
        if (s->id[i] > max_id) max_id = s->id[i];
        int gas = tfk_type(s->flags[i]) == FLAME_GAS, flame = (s->flags[i] & FLAME_IS_FLAME) != 0;
        if (gas && !flame && s->flame_nbr[i] == 0 && bad_death++ < 3)
            fprintf(stderr, "    survivor id %u: not a flame, no flame neighbour (nbr %d)\n", s->id[i], s->nbr[i]);
        if (flame && s->nbr[i] < rp->insert_nbr_threshold) parents[np++] = i;
    }
    CHECK(bad_death == 0, "%d survivors without a flame neighbour", bad_death);
    CHECK(s->n - ns == np, "%d inserted particles, %d flame particles below the threshold", s->n - ns, np);
    for (int q = ns; q < s->n; q++) {
        CHECK(s->rho[q] == 0 && s->id[q] > max_id, "inserted id %u (rho %g) not after the survivors", s->id[q],
              s->rho[q]);
        if (q - ns >= np) break;
        int r = tfk_check_insert(rp, s, q, parents[q - ns]);
        out += r == 1;
        in += r == 0;
    }
    CHECK(out + in > 10 && in <= 0.05 * (out + in), "insertions against the Müller normal: %d outward, %d inward",
          out, in);
    printf("  info: n %d, %d survivors, %d inserted: %d outward, %d inward, %d undetermined\n", s->n, ns, s->n - ns,
           out, in, np - out - in);
    free(parents);
}

/* C3/C4 after resampling steps 40 and 200 of the 3 cm scene at Table 3.1's h, and steps 20 and
 * 40 at the default h (3.5 mm: particles of ~5e-9 kg, where a colour normal summed with the
 * mass had a squared length below float's normal range, which a GPU compiler flushed to 0:
 * every insertion then went in a random direction). */
static void test_run_resampling(void)
{
    const char *docs[2] = {"{" TFK_SCENE "}", "{\"sources\":[{\"radius\":0.015}],\"obstacles\":[]}"};
    const int at[2][2] = {{41, 201}, {21, 41}}; /* steps run, so the last one's index resamples */
    for (int c = 0; c < 2; c++) {
        struct flame_ref_params rp;
        struct flame *fl = tfk_new(docs[c], &rp);
        struct flame_particles s;
        int done = 0;
        for (int k = 0; fl && k < 2; k++) {
            if (tfk_run(fl, at[c][k] - done) || tfk_read(fl, &s)) break;
            done = at[c][k];
            tfk_check_resampled(&rp, &s);
            flame_particles_free(&s);
        }
        flame_free(fl);
    }
}

/* C5: N changes only across steps whose index is a multiple of resample_interval. */
static void test_run_count_changes(void)
{
    const char *docs[2] = {"{" TFK_SCENE "}", "{" TFK_SCENE ",\"resample_interval\":3}"};
    const int interval[2] = {5, 3};
    for (int c = 0; c < 2; c++) {
        struct flame *fl = tfk_new(docs[c], NULL);
        if (!fl) continue;
        int changes = 0, n = flame_count(fl);
        for (int s = 0; s < 60; s++) {
            uint64_t idx = flame_steps(fl);
            if (tfk_run(fl, 1)) break;
            int m = flame_count(fl);
            CHECK(m == n || idx % (uint64_t)interval[c] == 0, "interval %d: N %d -> %d on step %llu", interval[c], n,
                  m, (unsigned long long)idx);
            changes += m != n;
            n = m;
        }
        CHECK(changes >= 5, "interval %d: N changed only %d times", interval[c], changes);
        flame_free(fl);
    }
}

/* C6: no source, no fuel, or too cold: nothing is ever inserted. */
static void test_run_no_source(void)
{
    const char *docs[3] = {"{\"sources\":[],\"obstacles\":[]}", "{" TFK_THESIS ",\"sources\":[{\"radius\":0.015,\"F_init\":0}]}",
                           "{" TFK_THESIS ",\"T_ign\":1500,\"sources\":[{\"radius\":0.015,\"T_init\":1200}]}"};
    for (int c = 0; c < 3; c++) {
        struct flame *fl = tfk_new(docs[c], NULL);
        if (!fl) continue;
        int n0 = flame_count(fl);
        CHECK(c == 0 ? n0 == 0 : n0 > 30, "%s: %d initial particles", docs[c], n0);
        for (int s = 0; s < 10; s++) {
            if (tfk_run(fl, 10)) break;
            CHECK(flame_count(fl) == n0, "%s: N %d -> %d after %d steps", docs[c], n0, flame_count(fl), 10 * s + 10);
        }
        flame_free(fl);
    }
}

/* Two read-back states are the same bit for bit: count, positions, velocities, flags, ids,
 * densities and neighbour counts. */
static int tfk_same_state(const struct flame_particles *a, const struct flame_particles *b)
{
    size_t n = (size_t)a->n;
    return a->n == b->n && !memcmp(a->pos, b->pos, 16 * n) && !memcmp(a->vel, b->vel, 16 * n) &&
           !memcmp(a->flags, b->flags, 4 * n) && !memcmp(a->id, b->id, 4 * n) && !memcmp(a->rho, b->rho, 4 * n) &&
           !memcmp(a->nbr, b->nbr, 2 * n);
}

/* C7: same document twice: identical N(t) and bit-identical final state. */
static void test_run_determinism(void)
{
    struct flame *a = tfk_new("{" TFK_SCENE ",\"seed\":7}", NULL), *b = tfk_new("{" TFK_SCENE ",\"seed\":7}", NULL);
    struct flame_particles sa, sb;
    int same = 1;
    for (int s = 0; a && b && s < 30 && same; s++) {
        if (tfk_run(a, 10) || tfk_run(b, 10)) break;
        same = flame_count(a) == flame_count(b);
        CHECK(same, "N(%d): %d vs %d", 10 * s + 10, flame_count(a), flame_count(b));
    }
    if (a && b && same && !tfk_read(a, &sa)) {
        if (!tfk_read(b, &sb)) {
            CHECK(tfk_same_state(&sa, &sb), "states differ after 300 steps (n %d)", sa.n);
            flame_particles_free(&sb);
        }
        flame_particles_free(&sa);
    }
    flame_free(a);
    flame_free(b);
}

/* The wide passes (GPU: counting sort, device scans) and the serial blocks (CPU) give the same
 * state bit for bit: the same document stepped both ways, resampling and a growing table
 * included, compared every 25 steps. */
static void tfk_wide_case(const char *partial, int steps)
{
    struct flame *a = tfk_new(partial, NULL), *b = tfk_new(partial, NULL);
    struct flame_particles sa, sb;
    int same = a && b, s = 0;
    if (same) {
        flame_set_wide(a, false);
        flame_set_wide(b, true);
    }
    for (; same && s < steps; s += 25) {
        if (tfk_run(a, 25) || tfk_run(b, 25) || tfk_read(a, &sa)) break;
        if (tfk_read(b, &sb)) {
            flame_particles_free(&sa);
            break;
        }
        same = tfk_same_state(&sa, &sb);
        CHECK(same, "%s: blocks and wide differ after %d steps (n %d vs %d)", partial, s + 25, sa.n, sb.n);
        flame_particles_free(&sa);
        flame_particles_free(&sb);
    }
    CHECK(s >= steps, "%s: compared %d of %d steps", partial, s, steps);
    flame_free(a);
    flame_free(b);
}

static void test_run_wide_same(void)
{
    tfk_wide_case("{}", 300);
    tfk_wide_case("{" TFK_SCENE ",\"seed\":3,\"wind_velocity\":[1,0,0]}", 200);
}

/* B5/B6: F >= 0, T >= T_amb - 1e-3, everything finite, over `steps` of the scene. */
static void tfk_positivity(const char *partial, int steps, int every)
{
    struct flame_ref_params rp;
    struct flame *fl = tfk_new(partial, &rp);
    struct flame_particles s;
    for (int done = 0; fl && done < steps; done += every) {
        if (tfk_run(fl, every) || tfk_read(fl, &s)) break;
        int bad = 0;
        for (int i = 0; i < s.n; i++) {
            float T = s.pos[4 * i + 3], F = s.vel[4 * i + 3];
            int fin = isfinite(s.pos[4 * i]) && isfinite(s.pos[4 * i + 1]) && isfinite(s.pos[4 * i + 2]) &&
                      isfinite(s.vel[4 * i]) && isfinite(s.vel[4 * i + 1]) && isfinite(s.vel[4 * i + 2]);
            int flag = (s.flags[i] & FLAME_IS_FLAME) != 0, want = flame_ref_is_flame(&rp, T, F);
            if ((!fin || !(F >= 0) || !(T >= rp.T_amb - 1e-3) || flag != want) && bad++ < 3)
                fprintf(stderr, "    step %d id %u: T %g F %g finite %d flame flag %d\n", done + every, s.id[i], T, F,
                        fin, flag);
        }
        CHECK(bad == 0, "%s: %d bad particles of %d after %d steps", partial, bad, s.n, done + every);
        flame_particles_free(&s);
        if (bad) break;
    }
    flame_free(fl);
}

/* The effect's default scene (6 cm disc) and the 3 cm one with wind. */
static void test_run_positivity(void)
{
    tfk_positivity("{}", 2000, 250);
    tfk_positivity("{" TFK_SCENE ",\"wind_accel\":[8,0,0]}", 2000, 250);
}

int main(void)
{
    struct fx_err err = {0};
    if (ocl_open(&tfk_ocl, CHECK_DEVICE(), &err)) return CHECK_ABORT("ocl_open(%s): %s: %s", CHECK_DEVICE(), err.code, err.message);
    tfk_defaults = params_defaults(flame_params);
    flame_ref_defaults(&tfk_flagp);
    flame_ref_params_from_json(tfk_defaults, &tfk_flagp);
    RUN(test_eval_small);
    RUN(test_eval_mixed);
    RUN(test_eval_far_apart);
    RUN(test_eval_hash_collisions);
    RUN(test_eval_symmetric_literal);
    RUN(test_eval_other_params);
    RUN(test_eval_lattice);
    RUN(test_run_worked_step);
    RUN(test_run_invariant_logistic);
    RUN(test_run_burn_limit);
    RUN(test_run_cooling);
    RUN(test_run_buoyancy);
    RUN(test_run_drag);
    RUN(test_run_no_ignition);
    RUN(test_run_solids);
    RUN(test_run_resampling);
    RUN(test_run_count_changes);
    RUN(test_run_no_source);
    RUN(test_run_determinism);
    RUN(test_run_wide_same);
    RUN(test_run_positivity);
    cJSON_Delete(tfk_defaults);
    ocl_close(tfk_ocl);
    return CHECK_DONE();
}
