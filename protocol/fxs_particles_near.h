/* fxs_particles_near.h — the neighbour search of the particle codec's attribute coding
 * (PROTOCOL.md §7.5.4): for each particle in tree order, the nearest of the few particles
 * just before it, by exact squared distance of the quantised positions, the latest on ties.
 * Internal to protocol/; shared by the encoder (both attribute modes in one pass) and the
 * decoder (every neighbour found before the attributes are decoded), so the two cannot find
 * different neighbours. A file of its own so that the vector paths can be read, and checked
 * against the scalar one (FXS_PT_SCALAR), apart from the coding around them.
 *
 * Every search takes n particles with quantised coordinates x, y, z (tree order, as
 * doubles: integers < 2^24, so squared distances are exact) and sets nbs[j], the nearest of
 * j - 1 ... j - 8 (-1 for j = 0). keys_exact: every axis has at most 23 bits, so
 * distance * 32 + k is exact in a double (fxs_pt_near_key) and the fast paths may compare
 * such keys. */
#ifndef FXS_PARTICLES_NEAR_H
#define FXS_PARTICLES_NEAR_H

#include <stdint.h>

/* The key of the candidate k particles before particle j: its squared distance * 32 + k.
 * The smallest key is the nearest candidate, the latest on ties. */
static inline double fxs_pt_near_key(const double *x, const double *y, const double *z, uint32_t j, uint32_t k)
{
    double dx = x[j] - x[j - k], dy = y[j] - y[j - k], dz = z[j] - z[j - k];
    return (dx * dx + dy * dy + dz * dz) * 32.0 + (double)k;
}

/* nbs only (attribute mode 0 and the velocities, decoding). */
void fxs_pt_near(uint32_t n, int keys_exact, const double *x, const double *y, const double *z, int32_t *nbs);

/* nbs, and sk[j]: the k (1 ... 16) of the nearest of j - 1 ... j - 16 whose fl equals fl[j],
 * 0 when none has (encoding: mode 1 takes that particle as the same-flags neighbour). */
void fxs_pt_near_same(uint32_t n, int keys_exact, const double *x, const double *y, const double *z, const double *fl,
                      int32_t *nbs, uint8_t *sk);

/* nbs, and near4[j]: the k (1 ... 16) of the 4 nearest of j - 1 ... j - 16, nearest first,
 * one a byte from the lowest (0 past the candidates j has) (decoding mode 1: the same-flags
 * neighbour is usually the first of them with the flags just decoded). */
void fxs_pt_near4(uint32_t n, int keys_exact, const double *x, const double *y, const double *z, int32_t *nbs,
                  uint32_t *near4);

#endif
