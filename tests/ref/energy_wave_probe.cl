/* energy_wave_probe.cl — test-only entry points into kernels/energy_wave.cl's device functions
 * (lane 0 of each vector), for the unit tests: the cubic solver, the B-spline strength and the
 * curve's nearest point. Never in the daemon: tests/ref/kernel_probe.c builds it appended to
 * energy_wave.cl's source (which comes first, layout header included) in one program. */

__kernel void ew_test_cubic(__global const float *abc, __global float *roots, __global int *nroots)
{
    int i = get_global_id(0);
    fv r0, r1, r2;
    iv three = ew_cubic((fv)(abc[3 * i]), (fv)(abc[3 * i + 1]), (fv)(abc[3 * i + 2]), &r0, &r1, &r2);
    nroots[i] = three.s0 ? 3 : 1;
    roots[3 * i] = r0.s0;
    roots[3 * i + 1] = three.s0 ? r1.s0 : 0.0f;
    roots[3 * i + 2] = three.s0 ? r2.s0 : 0.0f;
}

__kernel void ew_test_bspline(__global const float *spl, int spans, __global const float *t, __global float *out)
{
    int i = get_global_id(0);
    out[i] = ew_bspline(spl, spans, (fv)(t[i])).s0;
}

__kernel void ew_test_curve_nearest(__global const float *cv, __global const float *p, __global float *dist,
                                    __global float *tparam)
{
    int i = get_global_id(0);
    fv t, d2 = ew_curve_nearest_sq(cv, v3_make((fv)(p[3 * i]), (fv)(p[3 * i + 1]), (fv)(p[3 * i + 2])), &t);
    dist[i] = sqrt(d2.s0);
    tparam[i] = t.s0;
}
