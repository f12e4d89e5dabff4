/* exact.cl: exact hard shadows, one receiver per work-item, against its light-space cells' lists
 * (its fine cell's and its coarse cell's: lightspace.h).
 *
 * Meaning (DESIGN.md): a receiver p is in shadow when the segment from s to a point light (the ray
 * from s against a directional light's travel direction) hits a triangle at a distance greater than eps
 * from s and before the light; s = p + eps n when normals are given, else s = p. A normal facing away
 * from the light (n . (light - p) <= 0) is in shadow without testing.
 *
 * Build options:
 *   LIGHT_POINT   1: point light at (lx, ly, lz); 0: directional light travelling along (lx, ly, lz) (unit)
 *   NORMALS       1: normals given
 *   TEST_DOT5     0: watertight test (after the plane cull) on WT_FLOATS records; 1: dot5 on DOT5_FLOATS
 *   COARSE        1: also walk the receiver's coarse-cell list (0 when no primitive is coarse)
 *   LISTS_LINKED  0: CSR lists (offsets, items); 1: linked lists (heads, nodes)
 *   BRUTE         1: test every triangle (no lists): the fallback for points a view cannot place
 *   INPUT_F64     1: points and normals arrive as float64 world coordinates and are made relative to
 *                 (ox, oy, oz) and rounded here, exactly as the host would (needs cl_khr_fp64);
 *                 0: they arrive as float32, already relative
 *   NVIEWS, PERSPECTIVE: the light-space grid (lightspace.h)
 *
 * Output: out[i] = 1 in shadow, 0 lit, 2 "no cell" (behind a single perspective view: the host
 * classifies those points again with BRUTE), 3 the point is not finite, 4 the normal is zero or not
 * finite (the host raises).
 */
#include "lightspace.h"
#include "ray_triangle.h"

#ifndef LIGHT_POINT
#define LIGHT_POINT 1
#endif
#ifndef NORMALS
#define NORMALS 0
#endif
#ifndef TEST_DOT5
#define TEST_DOT5 0
#endif
#ifndef LISTS_LINKED
#define LISTS_LINKED 0
#endif
#ifndef BRUTE
#define BRUTE 0
#endif
#ifndef INPUT_F64
#define INPUT_F64 0
#endif
#ifndef COARSE
#define COARSE 1
#endif

#if INPUT_F64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double input_t;
#define INPUT_SQRT(x) __builtin_sqrt(x)
#else
typedef float input_t;
#define INPUT_SQRT(x) SC_SQRT(x)
#endif

#define SC_FINITE(x) ((x) - (x) == 0.0f)

#if TEST_DOT5
#define TRI_HIT(t) dot5_hit(sx, sy, sz, dx, dy, dz, tris + DOT5_FLOATS * (t), tmin, tmax)
#else
#define TRI_HIT(t) (!wt_culled(tris + WT_FLOATS * (t), sx, sy, sz) &&                                 \
                    wt_hit(&ray, tris[WT_FLOATS * (t)], tris[WT_FLOATS * (t) + 1], tris[WT_FLOATS * (t) + 2], \
                           tris[WT_FLOATS * (t) + 3], tris[WT_FLOATS * (t) + 4], tris[WT_FLOATS * (t) + 5],   \
                           tris[WT_FLOATS * (t) + 6], tris[WT_FLOATS * (t) + 7], tris[WT_FLOATS * (t) + 8],   \
                           tmin, tmax))
#endif

/* Walk one cell's list until a hit */
#if LISTS_LINKED
#define WALK(cell)                                                                                   \
    for (int node = lists_a[cell]; node >= 0 && !hit; node = lists_b[2 * node + 1]) {                \
        const int t = lists_b[2 * node];                                                             \
        hit = TRI_HIT(t);                                                                            \
    }
#else
#define WALK(cell)                                                                                   \
    {                                                                                                \
        const int end = lists_a[(cell) + 1];                                                         \
        for (int k = lists_a[cell]; k < end && !hit; ++k) {                                          \
            const int t = lists_b[k];                                                                \
            hit = TRI_HIT(t);                                                                        \
        }                                                                                            \
    }
#endif

/* Contract: points (n x 3, float32 relative to the local origin, or float64 world with INPUT_F64 and
 * the origin in (ox, oy, oz)), normals likewise if NORMALS (any non-zero length); tris: triangle
 * records (see TEST_DOT5); views: the grid the lists were built on; lists_a, lists_b: (offsets, items)
 * or (heads, nodes); (lx, ly, lz): light position (relative) or direction; eps: absolute offset.
 * Writes out[0..n). */
__kernel void exact_classify(__global const input_t *points, __global const input_t *normals, int n,
                             input_t ox, input_t oy, input_t oz,
                             __global const float *tris, int ntris,
                             __constant const float *views,
                             __global const int *lists_a, __global const int *lists_b,
                             float lx, float ly, float lz, float eps, __global uchar *out)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    float sx = (float)(points[3 * i] - ox), sy = (float)(points[3 * i + 1] - oy), sz = (float)(points[3 * i + 2] - oz);
    if (!(SC_FINITE(sx) & SC_FINITE(sy) & SC_FINITE(sz))) {
        out[i] = 3;
        return;
    }

    /* Direction to the light */
#if LIGHT_POINT
    float dx = lx - sx, dy = ly - sy, dz = lz - sz;
#else
    const float dx = -lx, dy = -ly, dz = -lz;
#endif

    /* Back-facing receivers are in shadow; the others start eps along their (unit) normal */
#if NORMALS
    {
        const input_t mx = normals[3 * i], my = normals[3 * i + 1], mz = normals[3 * i + 2];
        float nx_ = (float)mx, ny_ = (float)my, nz_ = (float)mz;
        float len2 = nx_ * nx_ + ny_ * ny_ + nz_ * nz_;
        if (!(len2 > 1.0e-30f && len2 < 1.0e30f)) {
            /* tiny, huge or invalid: rescale in the input precision first */
            const input_t big = (mx < 0 ? -mx : mx) > (my < 0 ? -my : my) ? (mx < 0 ? -mx : mx) : (my < 0 ? -my : my);
            const input_t scale = big > (mz < 0 ? -mz : mz) ? big : (mz < 0 ? -mz : mz);
            if (!(scale > 0) || !(mx - mx == 0) || !(my - my == 0) || !(mz - mz == 0)) {
                out[i] = 4;
                return;
            }
            nx_ = (float)(mx / scale); ny_ = (float)(my / scale); nz_ = (float)(mz / scale);
            len2 = nx_ * nx_ + ny_ * ny_ + nz_ * nz_;
        }
        const float inv = 1.0f / SC_SQRT(len2);
        nx_ *= inv; ny_ *= inv; nz_ *= inv;
        if (dot3(nx_, ny_, nz_, dx, dy, dz) <= 0.0f) {
            out[i] = 1;
            return;
        }
        sx += eps * nx_; sy += eps * ny_; sz += eps * nz_;
#if LIGHT_POINT
        dx = lx - sx; dy = ly - sy; dz = lz - sz;
#endif
    }
#endif

    /* The interval of the segment (point light: t in units of |light - s|) or of the ray */
#if LIGHT_POINT
    const float tmin = eps / SC_SQRT(dot3(dx, dy, dz, dx, dy, dz));
    const float tmax = 1.0f;
#else
    const float tmin = eps;
    const float tmax = SC_BIG;
#endif
#if !TEST_DOT5
    const WtRay ray = wt_setup(sx, sy, sz, dx, dy, dz);
#endif

    int hit = 0;
#if BRUTE
    for (int t = 0; t < ntris && !hit; ++t)
        hit = TRI_HIT(t);
#else
    /* The receiver's cells: its segment projects onto them, so their lists hold every possible blocker */
    float w;
    int coarse;
    const int cell = ls_point_cells(views, sx, sy, sz, &w, &coarse);
#if PERSPECTIVE && NVIEWS == 1
    if (!(w > 0.0f)) {
        out[i] = 2;
        return;
    }
#endif
    WALK(cell)
#if COARSE
    WALK(coarse)
#endif
#endif
    out[i] = (uchar)hit;
}

/* Triangles as 9 floats each from relative float32 vertices and int faces (the corners are copied bit
 * for bit, so triangles sharing a vertex share its floats: what watertightness needs). */
__kernel void gather_triangles(__global const float *vertices, __global const int *faces, int ntris,
                               __global float *tris)
{
    const int t = get_global_id(0);
    if (t >= ntris)
        return;
    for (int k = 0; k < 3; ++k) {
        const int v = faces[3 * t + k];
        tris[9 * t + 3 * k] = vertices[3 * v];
        tris[9 * t + 3 * k + 1] = vertices[3 * v + 1];
        tris[9 * t + 3 * k + 2] = vertices[3 * v + 2];
    }
}

/* Watertight records from 9-float triangles and the light (point: its relative position; directional:
 * the direction its light travels): see WT_FLOATS in ray_triangle.h. */
__kernel void wt_records(__global const float *tris, int ntris, float lx, float ly, float lz, __global float *rec)
{
    const int t = get_global_id(0);
    if (t >= ntris)
        return;
    __global const float *v = tris + 9 * t;
    __global float *r = rec + WT_FLOATS * t;
    for (int k = 0; k < 9; ++k)
        r[k] = v[k];
    const float ux = v[3] - v[0], uy = v[4] - v[1], uz = v[5] - v[2];
    const float vx = v[6] - v[0], vy = v[7] - v[1], vz = v[8] - v[2];
    float nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    const float len = SC_SQRT(nx * nx + ny * ny + nz * nz);
    const float inv = (len > 0.0f) ? 1.0f / len : 0.0f;
    nx *= inv; ny *= inv; nz *= inv;
    /* How far the computed unit normal may lean off the true one: the cross product's rounding is
     * ~eps |u| |v| per component, over |u x v| = |u| |v| sin(angle), so a sliver's normal leans by
     * ~eps / sin(angle) (2e-4 at an aspect of 4e-4); NORMAL_ULPS of it, and 1e-6 for the rest. */
    const float lean = (len > 0.0f) ? NORMAL_ULPS * FLT_EPSILON * SC_SQRT(ux * ux + uy * uy + uz * uz) *
                                          SC_SQRT(vx * vx + vy * vy + vz * vz) * inv : 0.0f;
    const float rel = 1.0e-6f + lean;
#if LIGHT_POINT
    const float ax = lx - v[0], ay = ly - v[1], az = lz - v[2];
    r[12] = nx * ax + ny * ay + nz * az;
    r[13] = rel * (SC_ABS(ax) + SC_ABS(ay) + SC_ABS(az)) + 1.0e-30f;
#else
    r[12] = -(nx * lx + ny * ly + nz * lz);
    r[13] = rel;
#endif
    r[9] = nx; r[10] = ny; r[11] = nz;
    r[14] = rel; r[15] = 0.0f;
}

/* Dot5 records from 9-float triangles: see DOT5_FLOATS in ray_triangle.h. */
__kernel void dot5_records(__global const float *tris, int ntris, __global float *rec)
{
    const int t = get_global_id(0);
    if (t >= ntris)
        return;
    const float p0x = tris[9 * t], p0y = tris[9 * t + 1], p0z = tris[9 * t + 2];
    const float ux = tris[9 * t + 3] - p0x, uy = tris[9 * t + 4] - p0y, uz = tris[9 * t + 5] - p0z;
    const float vx = tris[9 * t + 6] - p0x, vy = tris[9 * t + 7] - p0y, vz = tris[9 * t + 8] - p0z;
    float nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    const float uu = dot3(ux, uy, uz, ux, uy, uz), uv = dot3(ux, uy, uz, vx, vy, vz), vv = dot3(vx, vy, vz, vx, vy, vz);
    const float den = uv * uv - uu * vv;
    float inv = 1.0f / den;
    if (!(den != 0.0f) || !(nx != 0.0f || ny != 0.0f || nz != 0.0f)) {
        nx = 0.0f; ny = 0.0f; nz = 0.0f; inv = 0.0f;
    }
    __global float *r = rec + DOT5_FLOATS * t;
    r[0] = p0x; r[1] = p0y; r[2] = p0z;
    r[3] = nx; r[4] = ny; r[5] = nz;
    r[6] = ux; r[7] = uy; r[8] = uz;
    r[9] = vx; r[10] = vy; r[11] = vz;
    r[12] = uu * inv; r[13] = uv * inv; r[14] = vv * inv; r[15] = 0.0f;
}
