/* fxs_particles_near.h — the neighbour search of the particle codec's attribute coding
 * (PROTOCOL.md §7.5.4): for each particle in tree order, the nearest of the few particles
 * just before it, by exact squared distance of the quantised positions, the latest on ties.
 * Internal to protocol/; a search of its own so that its vector paths can be read (and
 * checked against the scalar one, FXS_PT_SCALAR) apart from the coding around them. */
#ifndef FXS_PARTICLES_NEAR_H
#define FXS_PARTICLES_NEAR_H

#include <stdint.h>

#include "fxs_particles_format.h"

/* The neighbour search of both attribute modes, one pass over f->n particles with quantised
 * positions q (3n, tree order) and flags fl: nbs[j], the nearest of j - 1 ... j - 8 (-1 for
 * j = 0), and sk[j], the k (1 ... 16) of the nearest of j - 1 ... j - 16 with the flags of
 * j (0: none), from which mode 1 takes the same-flags neighbour (else the latest particle
 * with those flags). pd: scratch for 4n doubles. */
void fxs_pt_neighbours(const struct fxs_pt_frame *f, const uint32_t *q, const uint8_t *fl, int32_t *nbs, uint8_t *sk,
                       double *pd);

#endif
