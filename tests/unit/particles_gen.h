/* particles_gen.h — synthetic particle frames for the codec test and bench.
 *
 * Until the real flame can be dumped, frames look like the SPH flame (digest 002):
 * particles on a jittered lattice of spacing d = h/2 = 5.625 mm filling a flame shape
 * (a tapering body of revolution over a 3 cm source disc, dense core) plus a sparser
 * plume of ambient gas above, T and F fields that fall off from the core, source and
 * flame flags, and the order the simulation gives: sorted by grid cell of size h
 * (linear cell index, x fastest). Header-only (static), deterministic. */
#ifndef PARTICLES_GEN_H
#define PARTICLES_GEN_H

#include <math.h>
#include <stdio.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fxs_particles.h"

#define PGEN_H 0.01125
#define PGEN_D (PGEN_H / 2)
/* A flame of height PGEN_H0 (metres) holds about PGEN_N0 particles. */
#define PGEN_H0 0.3
#define PGEN_N0 18000.0

static uint64_t pgen_rng = 88172645463325252ull;
static inline double pgen_rand(void) /* [0, 1) */
{
    pgen_rng ^= pgen_rng << 13;
    pgen_rng ^= pgen_rng >> 7;
    pgen_rng ^= pgen_rng << 17;
    return (double)(pgen_rng >> 11) / 9007199254740992.0;
}

static inline int pgen_alloc(struct fxs_particles *p, uint32_t n)
{
    size_t m = n ? n : 1;
    p->n = n;
    p->xyz = calloc(3 * m, sizeof *p->xyz);
    p->temp = calloc(m, sizeof *p->temp);
    p->fuel = calloc(m, sizeof *p->fuel);
    p->flags = calloc(m, 1);
    return p->xyz && p->temp && p->fuel && p->flags ? 0 : -1;
}

/* Uniform random particles in a box, random T (300..2300), F (0..120), flags 0..7. */
static inline int pgen_random(struct fxs_particles *p, uint32_t n, double size)
{
    if (pgen_alloc(p, n)) return -1;
    for (uint32_t i = 0; i < n; i++) {
        for (int a = 0; a < 3; a++) p->xyz[3 * i + a] = (float)((pgen_rand() - 0.5) * size);
        p->temp[i] = (float)(300 + 2000 * pgen_rand());
        p->fuel[i] = (float)(120 * pgen_rand());
        p->flags[i] = (uint8_t)(pgen_rand() * 8);
    }
    return 0;
}

/* Radius of the flame body at height z (metres) for a flame of height H. */
static inline double pgen_radius(double z, double H)
{
    double t = z / H;
    if (t < 0 || t > 1) return 0;
    return H / 8 * (1 + 1.2 * sin(M_PI * t)) * sqrt(1 - t) + 1e-9;
}

/* One candidate particle at lattice site (i, j, k); returns 1 when it is kept. */
static inline int pgen_site(int i, int j, int k, double H, float *xyz, float *T, float *F, uint8_t *fl)
{
    double x = i * PGEN_D + (pgen_rand() - 0.5) * 0.6 * PGEN_D, y = j * PGEN_D + (pgen_rand() - 0.5) * 0.6 * PGEN_D;
    double z = k * PGEN_D + (pgen_rand() - 0.5) * 0.6 * PGEN_D, r = sqrt(x * x + y * y);
    double R = pgen_radius(z, H), plume = H / 6 + 0.3 * (z - 0.6 * H);
    int core = r < R, smoke = !core && z > 0.6 * H && z < 1.6 * H && r < plume && pgen_rand() < 0.12;
    double heat, fuel;
    if (!core && !smoke) return 0;
    heat = core ? exp(-(r * r) / (R * R) * 2) * (1 - 0.5 * z / H) : 0.1 * exp(-(z - H) / H);
    fuel = core ? 100 * exp(-z / (0.3 * H)) * exp(-r / R) : 0;
    if (!core) z += (pgen_rand() - 0.5) * PGEN_D; /* smoke is less ordered */
    xyz[0] = (float)x, xyz[1] = (float)y, xyz[2] = (float)z;
    *T = (float)(300 + 1900 * heat + (core ? 5 * pgen_rand() : 0));
    *F = (float)(fuel < 1e-3 ? 0 : fuel);
    *fl = (uint8_t)(core && z < 2 * PGEN_D && r < H / 8 ? 1 : 0);
    if (*T > 1000 && *F > 1e-3) *fl |= 4;
    return 1;
}

struct pgen_sortrec {
    uint64_t cell;
    uint32_t i;
};
static int pgen_cmp(const void *a, const void *b)
{
    const struct pgen_sortrec *x = a, *y = b;
    return x->cell < y->cell ? -1 : x->cell > y->cell ? 1 : (x->i > y->i) - (x->i < y->i);
}

/* Sorts p by cell of size h (the simulation's order). */
static inline int pgen_sort_cells(struct fxs_particles *p)
{
    struct pgen_sortrec *r = malloc((p->n ? p->n : 1) * sizeof *r);
    struct fxs_particles q = { 0 };
    if (!r || pgen_alloc(&q, p->n)) return -1;
    for (uint32_t i = 0; i < p->n; i++) {
        uint64_t c[3];
        for (int a = 0; a < 3; a++) c[a] = (uint64_t)(int64_t)floor(p->xyz[3 * i + a] / PGEN_H + 1024);
        r[i].cell = c[2] << 40 | c[1] << 20 | c[0];
        r[i].i = i;
    }
    qsort(r, p->n, sizeof *r, pgen_cmp);
    for (uint32_t j = 0; j < p->n; j++) {
        uint32_t i = r[j].i;
        memcpy(q.xyz + 3 * j, p->xyz + 3 * i, 3 * sizeof(float));
        q.temp[j] = p->temp[i], q.fuel[j] = p->fuel[i], q.flags[j] = p->flags[i];
    }
    free(p->xyz), free(p->temp), free(p->fuel), free(p->flags), free(r);
    *p = q;
    return 0;
}

/* An SPH-like flame of about n particles (the count is what the shape holds). */
static inline int pgen_flame(struct fxs_particles *p, uint32_t n)
{
    double H = PGEN_H0 * cbrt(n / PGEN_N0);
    int ri = (int)(0.45 * H / PGEN_D) + 4, kz = (int)(1.7 * H / PGEN_D) + 2;
    size_t cap = (size_t)(2 * ri + 1) * (2 * ri + 1) * (kz + 1), m = 0;
    if (pgen_alloc(p, (uint32_t)cap)) return -1;
    for (int k = 0; k <= kz; k++)
        for (int j = -ri; j <= ri; j++)
            for (int i = -ri; i <= ri; i++)
                m += (size_t)pgen_site(i, j, k, H, p->xyz + 3 * m, p->temp + m, p->fuel + m, p->flags + m);
    p->n = (uint32_t)m;
    return pgen_sort_cells(p);
}

/* Velocities for p (p->vel, 3n, allocated; freed by fxs_particles_free) like an SPH flame's:
 * hot gas rises with its heat (up to ~2 m/s), spreads and swirls around the axis, with some
 * noise; sources (type 1) are at rest. Deterministic (pgen_rand). */
static inline int pgen_velocities(struct fxs_particles *p)
{
    p->vel = calloc(3 * (size_t)(p->n ? p->n : 1), sizeof *p->vel);
    if (!p->vel) return -1;
    for (uint32_t i = 0; i < p->n; i++) {
        const float *r = p->xyz + 3 * (size_t)i;
        double heat = (p->temp[i] - 300.0) / 1900.0, noise = 0.05 + 0.1 * heat;
        if ((p->flags[i] & 3u) == 1u) continue;
        p->vel[3 * i] = (float)(0.8 * r[0] - 3.0 * r[1] + noise * (pgen_rand() - 0.5));
        p->vel[3 * i + 1] = (float)(0.8 * r[1] + 3.0 * r[0] + noise * (pgen_rand() - 0.5));
        p->vel[3 * i + 2] = (float)(0.1 + 1.9 * heat + 2 * r[2] + noise * (pgen_rand() - 0.5));
    }
    return 0;
}

/* Reads a binary PLY as fxctl writes it (x y z temperature fuel flags, then vx vy vz when
 * the frame had velocities; little endian) into p (allocated, p->vel only with velocities;
 * free with fxs_particles_free). 0, or -1 when it cannot be read. */
static inline int pgen_read_ply(const char *path, struct fxs_particles *p)
{
    FILE *f = fopen(path, "rb");
    char line[256];
    unsigned n = 0;
    int ok = 0, vel = 0;
    size_t size;
    if (!f) return -1;
    while (fgets(line, sizeof line, f)) {
        if (sscanf(line, "element vertex %u", &n) == 1) continue;
        if (!strcmp(line, "property float vx\n")) vel = 1;
        if (!strcmp(line, "end_header\n")) {
            ok = 1;
            break;
        }
    }
    if (ok) ok = !pgen_alloc(p, n);
    if (ok && vel) ok = (p->vel = malloc(12 * (size_t)(n ? n : 1))) != NULL;
    size = vel ? 33 : 21;
    for (uint32_t i = 0; i < n && ok; i++) {
        uint8_t rec[33];
        ok = fread(rec, 1, size, f) == size;
        memcpy(p->xyz + 3 * i, rec, 12), memcpy(p->temp + i, rec + 12, 4), memcpy(p->fuel + i, rec + 16, 4);
        p->flags[i] = rec[20];
        if (vel) memcpy(p->vel + 3 * i, rec + 21, 12);
    }
    fclose(f);
    return ok ? 0 : -1;
}

#endif
