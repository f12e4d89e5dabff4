/* subdivision.h: exact evaluation of one Catmull-Clark limit-surface patch (the patch-table contract).
 *
 * A patch is 16 control points of a uniform bicubic B-spline (levels == 0), or a patch with one
 * extraordinary vertex at (u, v) = (0, 0) (levels == L > 0), evaluated exactly by Stam's sub-domains:
 * for n = 1..L and k = 0, 1, 2 a 16-point B-spline sub-patch at first + ((n - 1) * 3 + k) * 16
 *   k = 0: u in [2^-n, 2^(1-n)], v in [0, 2^-n]
 *   k = 1: u and v in [2^-n, 2^(1-n)]
 *   k = 2: u in [0, 2^-n], v in [2^-n, 2^(1-n)]
 * and the extraordinary vertex's limit position at first + 48 * L (used when u and v are below 2^-L).
 * Control points are row-major: points[first + 4 * j + i], i along u, j along v; 3 floats per point.
 *
 * Precision: positions are float32-accurate everywhere. Derivatives near an EV come from sub-patches
 * whose float32 points differ by ~0.5^n of the patch size, so below max(u, v) ~ 2^-10 they carry
 * rounding noise; a caller needing a normal there evaluates at (2^-10, 2^-10) (the host's
 * SubdivisionSurface.limit_normals does it in float64 instead).
 */
#ifndef SHADOWCL_SUBDIVISION_H
#define SHADOWCL_SUBDIVISION_H

#include "vecmath.h"

/* Uniform cubic B-spline basis at t in [0, 1] and its derivative. */
INLINE void bspline_basis(float t, float b[4], float d[4])
{
    const float s = 1.0f - t;
    const float t2 = t * t;
    b[0] = s * s * s * (1.0f / 6.0f);
    b[1] = (3.0f * t2 * t - 6.0f * t2 + 4.0f) * (1.0f / 6.0f);
    b[2] = (-3.0f * t2 * t + 3.0f * t2 + 3.0f * t + 1.0f) * (1.0f / 6.0f);
    b[3] = t2 * t * (1.0f / 6.0f);
    d[0] = -0.5f * s * s;
    d[1] = 1.5f * t2 - 2.0f * t;
    d[2] = -1.5f * t2 + t + 0.5f;
    d[3] = 0.5f * t2;
}

/* The bicubic B-spline with 16 control points from points[3 * first]; derivatives scaled by `scale`. */
INLINE float3 bspline_patch_eval(global const float* points, uint first, float u, float v, float scale,
                                 float3* du, float3* dv)
{
    float bu[4], du_b[4], bv[4], dv_b[4];
    bspline_basis(u, bu, du_b);
    bspline_basis(v, bv, dv_b);
    float3 p = (float3)(0.0f), pu = (float3)(0.0f), pv = (float3)(0.0f);
    for (int j = 0; j < 4; ++j) {
        float3 row = (float3)(0.0f), row_u = (float3)(0.0f);
        for (int i = 0; i < 4; ++i) {
            float x, y, z;
            LOAD3(points, (int)first + 4 * j + i, x, y, z);
            const float3 c = (float3)(x, y, z);
            row += bu[i] * c;
            row_u += du_b[i] * c;
        }
        p += bv[j] * row;
        pu += bv[j] * row_u;
        pv += dv_b[j] * row;
    }
    if (du) *du = pu * scale;
    if (dv) *dv = pv * scale;
    return p;
}

/* The limit position at (u, v) in [0, 1]^2 of the patch (first, levels), with partial derivatives
 * (du, dv may be 0 to skip them; at the extraordinary vertex itself they are zero). Parameters outside
 * [0, 1]^2 (or NaN) extrapolate a sub-patch or return the EV's limit: never a read outside the patch. */
INLINE float3 patch_eval(global const float* points, uint first, uint levels, float u, float v,
                         float3* du, float3* dv)
{
    if (levels == 0u) return bspline_patch_eval(points, first, u, v, 1.0f, du, dv);
    const float m = SC_MAX(u, v);
    /* Sub-domain level n with m in [2^-n, 2^(1-n)): n = -(binary exponent of m), clamped to [1, L]. */
    const int exponent = (int)((as_uint(m) >> 23) & 0xffu) - 127;
    if (m < as_float((uint)(127 - (int)levels) << 23)) {
        if (du) *du = (float3)(0.0f);
        if (dv) *dv = (float3)(0.0f);
        float x, y, z;
        LOAD3(points, (int)(first + 48u * levels), x, y, z);
        return (float3)(x, y, z);
    }
    const int n = clamp(-exponent, 1, (int)levels);
    const float scale = as_float((uint)(127 + n) << 23); /* 2^n, exact */
    float uu = u * scale, vv = v * scale;
    uint k;
    if (vv < 1.0f) {
        k = 0u;
        uu -= 1.0f;
    } else if (uu >= 1.0f) {
        k = 1u;
        uu -= 1.0f;
        vv -= 1.0f;
    } else {
        k = 2u;
        vv -= 1.0f;
    }
    return bspline_patch_eval(points, first + ((uint)(n - 1) * 3u + k) * 16u, uu, vv, scale, du, dv);
}

#endif
