/* subdivision.cl: limit-surface evaluation of a patch table. Host: the package host/shadowcl/subdivision/
 * (surface.py launches it); NumPy reference: host/shadowcl/reference/subdivision.py; tests:
 * tests/test_subdivision.py. */
#include "subdivision.h"

/* evaluate: for each query q < n, the limit position of patch[q] at (u[q], v[q]) in that patch's own
 * parameters; built with -DDERIVATIVES also d/du and d/dv (zero exactly at an extraordinary vertex),
 * else out_du and out_dv are not touched (patch_eval gets null pointers).
 * points/first/levels: the patch table; out_* are (n, 3) float arrays. */
kernel void evaluate(global const float* points, global const uint* first, global const uint* levels,
                     global const int* patch, global const float* u, global const float* v, const int n,
                     global float* out_position, global float* out_du, global float* out_dv)
{
    const int q = get_global_id(0);
    if (q >= n) return;
    const int p = patch[q];
#ifdef DERIVATIVES
    float3 du, dv;
    const float3 position = patch_eval(points, first[p], levels[p], u[q], v[q], &du, &dv);
    vstore3(du, q, out_du);
    vstore3(dv, q, out_dv);
#else
    const float3 position = patch_eval(points, first[p], levels[p], u[q], v[q], 0, 0);
#endif
    vstore3(position, q, out_position);
}
