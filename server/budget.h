/* budget.h — a subscriber's particle budget (subscribe's `max_particles`, PROTOCOL.md §3.5), and
 * the forms a stream's frames are made in.
 *
 * The ladder: a budget is served as the largest of its 1-2-5 steps (1000 ... 2000000) at most the
 * value asked, so each stream has a bounded number of subsets and many subscribers share each.
 * Level 0 is the full frame, levels 1..BUDGET_LEVELS-1 the steps.
 *
 * The subset: the `step` particles whose hash of their stable id is smallest. The hash is a
 * bijection of 32-bit ids (murmur3's finaliser), so the set does not depend on the particles'
 * order, and a particle stays in it from frame to frame unless newborn particles with smaller
 * hashes push it out: the subset is temporally stable, and uniform in id, so drawn in proportion
 * (the flame's shape and brightness per particle hold; clients scale by total / count).
 *
 * A form is what the hub and the engine index frames by: (encoding, level), form =
 * encoding * BUDGET_LEVELS + level, BUDGET_FORMS of them in a 32-bit mask. Only kind 1 has
 * levels; the other kinds live at level 0 of their encoding (kinds 3 and 4 at form 0). */
#ifndef FX_BUDGET_H
#define FX_BUDGET_H

#include <stdint.h>

#include "fxs_frame.h"
#include "fxs_particles.h"

#define BUDGET_LEVELS 12
#define BUDGET_FORMS (FXS_ENCODING_COUNT * BUDGET_LEVELS)
#define BUDGET_FORM_DEFAULT 0 /* the default encoding, full frames */

/* The particles of level 1..BUDGET_LEVELS-1; 0 for level 0 (no budget). */
uint32_t budget_step(int level);
/* The level a max_particles value in [FXS_MAX_PARTICLES_MIN, FXS_MAX_PARTICLES_MAX] is served at:
 * the largest step <= it. */
int budget_level(uint32_t max_particles);
/* The level whose step is exactly n, or 0 when n is no step. */
int budget_level_of_step(uint32_t n);

static inline int budget_form(enum fxs_encoding enc, int level) { return (int)enc * BUDGET_LEVELS + level; }
static inline enum fxs_encoding budget_form_encoding(int form) { return (enum fxs_encoding)(form / BUDGET_LEVELS); }
static inline int budget_form_level(int form) { return form % BUDGET_LEVELS; }
/* The form a kind's frames take for a subscription of `form`: kind 1 its own, kind 2 its
 * encoding's level 0, kinds 3 and 4 form 0 (one form for everyone). */
static inline int budget_kind_form(int form, int kind)
{
    if (kind == FXS_KIND_PARTICLES) return form;
    return fxs_kind_has_engine_form(kind) ? budget_form(budget_form_encoding(form), 0) : BUDGET_FORM_DEFAULT;
}

/* The subset's order key of a particle id (murmur3's 32-bit finaliser: a bijection). */
uint32_t budget_hash(uint32_t id);
/* The indices (ascending) of the min(step, n) particles of ids[0..n) with the smallest
 * budget_hash, in O(n); idx holds min(step, n). Returns how many, or -1 when out of memory. */
int64_t budget_select(const uint32_t *ids, uint32_t n, uint32_t step, uint32_t *idx);
/* The particles of `all` at idx[0..m) into newly allocated arrays of out (its vel only when all
 * has velocities; free with fxs_particles_free). 0, or -1 when out of memory. */
int budget_gather(const struct fxs_particles *all, const uint32_t *idx, uint32_t m, struct fxs_particles *out);

#endif
