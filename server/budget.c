/* budget.c — see budget.h. */
#include "budget.h"

#include <stdlib.h>
#include <string.h>

static const uint32_t budget_ladder[BUDGET_LEVELS] = {
    0, 1000, 2000, 5000, 10000, 20000, 50000, 100000, 200000, 500000, 1000000, 2000000,
};

uint32_t budget_step(int level) { return level > 0 && level < BUDGET_LEVELS ? budget_ladder[level] : 0; }

int budget_level(uint32_t max_particles)
{
    int level = 1;
    while (level + 1 < BUDGET_LEVELS && budget_ladder[level + 1] <= max_particles) level++;
    return level;
}

int budget_level_of_step(uint32_t n)
{
    for (int level = 1; level < BUDGET_LEVELS; level++)
        if (budget_ladder[level] == n) return level;
    return 0;
}

uint32_t budget_hash(uint32_t id)
{
    id ^= id >> 16;
    id *= 0x85ebca6bu;
    id ^= id >> 13;
    id *= 0xc2b2ae35u;
    id ^= id >> 16;
    return id;
}

static void budget_swap(uint32_t *a, uint32_t *b)
{
    uint32_t t = *a;
    *a = *b;
    *b = t;
}

/* The k-th smallest of v[0..n) (k < n), reordering v: quickselect with a median-of-three pivot
 * (the hashes are well mixed, so expected linear time). */
static uint32_t budget_kth(uint32_t *v, int64_t n, int64_t k)
{
    int64_t lo = 0, hi = n - 1;
    while (lo < hi) {
        int64_t mid = lo + (hi - lo) / 2, i = lo, j = hi;
        if (v[mid] < v[lo]) budget_swap(&v[mid], &v[lo]);
        if (v[hi] < v[lo]) budget_swap(&v[hi], &v[lo]);
        if (v[hi] < v[mid]) budget_swap(&v[hi], &v[mid]);
        uint32_t pivot = v[mid];
        while (i <= j) { /* Hoare partition: [lo, j] <= pivot <= [i, hi] */
            while (v[i] < pivot) i++;
            while (v[j] > pivot) j--;
            if (i <= j) budget_swap(&v[i++], &v[j--]);
        }
        if (k <= j) hi = j;
        else if (k >= i) lo = i;
        else return v[k];
    }
    return v[k];
}

int64_t budget_select(const uint32_t *ids, uint32_t n, uint32_t step, uint32_t *idx)
{
    if (n <= step) {
        for (uint32_t i = 0; i < n; i++) idx[i] = i;
        return n;
    }
    if (step == 0) return 0;
    uint32_t *h = malloc((size_t)n * sizeof *h);
    if (!h) return -1;
    for (uint32_t i = 0; i < n; i++) h[i] = budget_hash(ids[i]);
    uint32_t threshold = budget_kth(h, n, step - 1);
    free(h);
    uint32_t m = 0;
    for (uint32_t i = 0; i < n && m < step; i++) /* unique ids have unique hashes: exactly step */
        if (budget_hash(ids[i]) <= threshold) idx[m++] = i;
    return m;
}

int budget_gather(const struct fxs_particles *all, const uint32_t *idx, uint32_t m, struct fxs_particles *out)
{
    size_t k = m ? m : 1;
    *out = (struct fxs_particles){.n = m};
    out->xyz = malloc(3 * k * sizeof *out->xyz);
    out->temp = malloc(k * sizeof *out->temp);
    out->fuel = malloc(k * sizeof *out->fuel);
    out->flags = malloc(k);
    if (all->vel) out->vel = malloc(3 * k * sizeof *out->vel);
    if (!out->xyz || !out->temp || !out->fuel || !out->flags || (all->vel && !out->vel)) {
        fxs_particles_free(out);
        return -1;
    }
    for (uint32_t j = 0; j < m; j++) {
        uint32_t i = idx[j];
        memcpy(out->xyz + 3 * j, all->xyz + 3 * (size_t)i, 3 * sizeof *out->xyz);
        if (out->vel) memcpy(out->vel + 3 * j, all->vel + 3 * (size_t)i, 3 * sizeof *out->vel);
        out->temp[j] = all->temp[i];
        out->fuel[j] = all->fuel[i];
        out->flags[j] = all->flags[i];
    }
    return 0;
}
