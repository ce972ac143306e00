/* slice.c — see slice.h. */
#include "slice.h"

#include <math.h>

size_t slice_units(const struct slice_meter *m, size_t left, double now, double end)
{
    if (isinf(end) || left <= 1) return left;
    double n = m->per_unit > 0 ? floor((end - now) / m->per_unit) : (double)(m->probe ? m->probe : 1);
    if (m->largest && n > (double)SLICE_GROWTH * (double)m->largest) n = (double)SLICE_GROWTH * (double)m->largest;
    if (n < 1) n = 1;
    return n >= (double)left ? left : (size_t)n;
}

void slice_record(struct slice_meter *m, size_t units, double seconds)
{
    if (!units) return;
    double per = seconds / (double)units;
    m->per_unit = m->per_unit > 0 ? 0.5 * (m->per_unit + per) : per;
    if (units > m->largest) m->largest = units;
}
