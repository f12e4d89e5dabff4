/* ray_triangle.h: the ray/triangle tests of shadowcl, written once for every method.
 *
 * Both answer "does the ray o + t D hit the triangle for tmin < t < tmax?" (t in units of |D|) and
 * return an int (0/1) without branches, so a caller can OR several tests and check once per block.
 *
 * 1. Watertight (Woop, Benthin & Wald 2013, JCGT 2(1) "Watertight Ray/Triangle Intersection").
 *    Per ray: kz = the dominant axis of D, kx, ky the other two; the shear Sx = Dkx/Dkz,
 *    Sy = Dky/Dkz, Sz = 1/Dkz maps the ray onto +z. Per vertex a = v - o:
 *        ax = a[kx] - Sx a[kz],  ay = a[ky] - Sy a[kz],  az = Sz a[kz]
 *    (written as dot products with the shear rows, which give bit-identical results because the rows
 *    hold exactly 1, 0 and -Sx: 1*x and 0*y are exact and contraction is off), then the 2D edge
 *    functions U = cx by - cy bx, V = ax cy - ay cx, W = bx ay - by ax.
 *    Why it is watertight: a vertex's sheared coordinates depend only on the vertex and the ray, so two
 *    triangles sharing an edge compute the edge function from the same floats in the opposite order,
 *    and with FP_CONTRACT OFF, x*y - z*w and z*w - x*y round to exact negatives: a ray can never be
 *    strictly outside both triangles of a shared edge.
 *    Tie rule (replacing the paper's double-precision recomputation when U, V or W is exactly 0.0,
 *    since doubles are optional in OpenCL 1.2): a zero edge function counts as inside for either
 *    orientation (the test accepts all >= 0 or all <= 0). A ray exactly on a shared edge therefore hits
 *    both triangles, a ray exactly through a vertex hits every triangle around it: conservative (one
 *    extra hit at most on a mesh's silhouette, at measure zero) and never a leak. det = U+V+W = 0
 *    (a degenerate triangle or a ray in the triangle's plane) is no hit.
 *    Both faces count (shadows do not depend on winding).
 *
 * 2. Dot5 (Badouel 1990 as in Lai & Cheng, section 4.2): intersect the triangle's plane, then the
 *    barycentric s, t of the plane point from 5 dot products:
 *        s = ((u.v)(w.v) - (v.v)(w.u)) / ((u.v)^2 - (u.u)(v.v)),
 *        t = ((u.v)(w.u) - (u.u)(w.v)) / ((u.v)^2 - (u.u)(v.v)),
 *    u = V1 - V0, v = V2 - V0, w = P - V0; a hit when s >= 0, t >= 0, s + t <= 1. The per-triangle
 *    terms are precomputed (DOT5_FLOATS per triangle, below). Each triangle rounds on its own, so rays
 *    through shared edges can leak: this is the variant the bench uses to show what watertightness buys.
 */
#ifndef SHADOWCL_RAY_TRIANGLE_H
#define SHADOWCL_RAY_TRIANGLE_H

#include "vecmath.h"

/* WT_REFINE_F64 1 (needs cl_khr_fp64): a triangle the float32 edge functions call hit gets its hit
 * distance again in double from the same float32 inputs. The edge functions decide inside-ness
 * watertightly in float32, but T (the scaled distance) is a sum of products of sheared coordinates: for
 * a long triangle met at a grazing angle near the ray's origin its rounding can exceed T itself (a
 * 31-unit strip met at 0.04 degrees 0.01 from the receiver came out behind the origin: a leak). */
#ifndef WT_REFINE_F64
#define WT_REFINE_F64 0
#endif
#if WT_REFINE_F64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#endif

typedef struct {
    float ox, oy, oz;           /* ray origin */
    float dx, dy, dz;           /* direction */
    int kx, ky, kz;             /* axis permutation: kz the dominant axis of the direction */
    float xx, xy, xz;           /* shear row for x: e_kx - Sx e_kz */
    float yx, yy, yz;           /* shear row for y: e_ky - Sy e_kz */
    float zx, zy, zz;           /* scaled z row:   Sz e_kz */
} WtRay;

/* Per-ray set-up of the watertight test for origin o and direction D (not necessarily unit). */
INLINE WtRay wt_setup(float ox, float oy, float oz, float dx, float dy, float dz)
{
    const float ax = SC_ABS(dx), ay = SC_ABS(dy), az = SC_ABS(dz);
    const int kz = (ax >= ay && ax >= az) ? 0 : ((ay >= az) ? 1 : 2);
    const int kx = (kz == 2) ? 0 : kz + 1;
    const int ky = (kx == 2) ? 0 : kx + 1;
    const float dkz = (kz == 0) ? dx : ((kz == 1) ? dy : dz);
    const float dkx = (kx == 0) ? dx : ((kx == 1) ? dy : dz);
    const float dky = (ky == 0) ? dx : ((ky == 1) ? dy : dz);
    const float sz = 1.0f / dkz, sx = dkx * sz, sy = dky * sz;   /* one division: any consistent shear will do */
    WtRay r;
    r.ox = ox; r.oy = oy; r.oz = oz;
    r.dx = dx; r.dy = dy; r.dz = dz;
    r.kx = kx; r.ky = ky; r.kz = kz;
    r.xx = (kx == 0) ? 1.0f : ((kz == 0) ? -sx : 0.0f);
    r.xy = (kx == 1) ? 1.0f : ((kz == 1) ? -sx : 0.0f);
    r.xz = (kx == 2) ? 1.0f : ((kz == 2) ? -sx : 0.0f);
    r.yx = (ky == 0) ? 1.0f : ((kz == 0) ? -sy : 0.0f);
    r.yy = (ky == 1) ? 1.0f : ((kz == 1) ? -sy : 0.0f);
    r.yz = (ky == 2) ? 1.0f : ((kz == 2) ? -sy : 0.0f);
    r.zx = (kz == 0) ? sz : 0.0f;
    r.zy = (kz == 1) ? sz : 0.0f;
    r.zz = (kz == 2) ? sz : 0.0f;
    return r;
}

#if WT_REFINE_F64
INLINE double wt_axis(double x, double y, double z, int k) { return (k == 0) ? x : ((k == 1) ? y : z); }

/* The hit distance of a triangle the float32 test found inside, against (tmin, tmax), in double. */
INLINE int wt_interval_f64(const WtRay *r, float v0x, float v0y, float v0z, float v1x, float v1y, float v1z,
                           float v2x, float v2y, float v2z, float tmin, float tmax)
{
    const double a0 = (double)v0x - r->ox, a1 = (double)v0y - r->oy, a2 = (double)v0z - r->oz;
    const double b0 = (double)v1x - r->ox, b1 = (double)v1y - r->oy, b2 = (double)v1z - r->oz;
    const double c0 = (double)v2x - r->ox, c1 = (double)v2y - r->oy, c2 = (double)v2z - r->oz;
    const double dkz = wt_axis(r->dx, r->dy, r->dz, r->kz);
    const double sx = wt_axis(r->dx, r->dy, r->dz, r->kx) / dkz, sy = wt_axis(r->dx, r->dy, r->dz, r->ky) / dkz;
    const double az = wt_axis(a0, a1, a2, r->kz), bz = wt_axis(b0, b1, b2, r->kz), cz = wt_axis(c0, c1, c2, r->kz);
    const double ax = wt_axis(a0, a1, a2, r->kx) - sx * az, ay = wt_axis(a0, a1, a2, r->ky) - sy * az;
    const double bx = wt_axis(b0, b1, b2, r->kx) - sx * bz, by = wt_axis(b0, b1, b2, r->ky) - sy * bz;
    const double cx = wt_axis(c0, c1, c2, r->kx) - sx * cz, cy = wt_axis(c0, c1, c2, r->ky) - sy * cz;
    const double U = cx * by - cy * bx, V = ax * cy - ay * cx, W = bx * ay - by * ax;
    const double det = U + V + W;
    const double T = (U * az + V * bz + W * cz) / dkz;           /* t = T / det in units of the direction */
    const double sgn = (det < 0.0) ? -1.0 : 1.0;
    const double Ts = T * sgn, ad = det * sgn;
    return (Ts > tmin * ad) & (Ts < tmax * ad);
}
#endif

/* Watertight hit of triangle (v0, v1, v2) for tmin < t < tmax. */
INLINE int wt_hit(const WtRay *r, float v0x, float v0y, float v0z, float v1x, float v1y, float v1z,
                  float v2x, float v2y, float v2z, float tmin, float tmax)
{
    const float a0 = v0x - r->ox, a1 = v0y - r->oy, a2 = v0z - r->oz;
    const float b0 = v1x - r->ox, b1 = v1y - r->oy, b2 = v1z - r->oz;
    const float c0 = v2x - r->ox, c1 = v2y - r->oy, c2 = v2z - r->oz;
    /* Shear and scale the vertices */
    const float ax = r->xx * a0 + r->xy * a1 + r->xz * a2, ay = r->yx * a0 + r->yy * a1 + r->yz * a2;
    const float bx = r->xx * b0 + r->xy * b1 + r->xz * b2, by = r->yx * b0 + r->yy * b1 + r->yz * b2;
    const float cx = r->xx * c0 + r->xy * c1 + r->xz * c2, cy = r->yx * c0 + r->yy * c1 + r->yz * c2;
    const float az = r->zx * a0 + r->zy * a1 + r->zz * a2;
    const float bz = r->zx * b0 + r->zy * b1 + r->zz * b2;
    const float cz = r->zx * c0 + r->zy * c1 + r->zz * c2;
    /* Edge functions; zero counts as inside for either orientation */
    const float U = cx * by - cy * bx;
    const float V = ax * cy - ay * cx;
    const float W = bx * ay - by * ax;
    const int inside = ((U >= 0.0f) & (V >= 0.0f) & (W >= 0.0f)) | ((U <= 0.0f) & (V <= 0.0f) & (W <= 0.0f));
#if WT_REFINE_F64
    if (!inside)
        return 0;
    return wt_interval_f64(r, v0x, v0y, v0z, v1x, v1y, v1z, v2x, v2y, v2z, tmin, tmax);
#endif
    /* Scaled hit distance against the interval, sign of det folded in */
    const float det = U + V + W;
    const float T = U * az + V * bz + W * cz;
    const float sgn = (det < 0.0f) ? -1.0f : 1.0f;
    const float Ts = T * sgn, ad = det * sgn;
    return inside & (Ts > tmin * ad) & (Ts < tmax * ad);
}

/* Watertight triangle record (WT_FLOATS = 16 floats, one 64-byte line): the corners v0, v1, v2 as
 * stored (9), then for the plane cull the unit normal n (3), fL = n.(light - v0) for a point light or
 * n.(-direction) for a directional light, and its rounding bound eL (2), the relative bound rel of the
 * plane test (1: 1e-6 plus how far the computed normal may lean, large for slivers), 1 float of padding. */
#define WT_FLOATS 16
#define NORMAL_ULPS 8.0f   /* the cross product's rounding, in FLT_EPSILON, that the cull allows for */

/* Plane cull: 1 when the segment from s to the light certainly stays on one side of the triangle's
 * plane (s and the light both farther than their rounding bounds from it, on the same side), so no
 * test can hit. A segment through a shared edge or vertex crosses both planes there, so the cull never
 * removes one; it only skips triangles the segment does not reach. Degenerate triangles (n = 0) are
 * never culled (their test says no hit). */
INLINE int wt_culled(__global const float *t, float sx, float sy, float sz)
{
    const float a0 = sx - t[0], a1 = sy - t[1], a2 = sz - t[2];
    const float fs = t[9] * a0 + t[10] * a1 + t[11] * a2;
    const float es = t[14] * (SC_ABS(a0) + SC_ABS(a1) + SC_ABS(a2));
    const float fl = t[12], el = t[13];
    return ((fs > es) & (fl > el)) | ((fs < -es) & (fl < -el));
}

/* Dot5 triangle record: V0 (3), n = u x v (3), u (3), v (3), uu/den, uv/den, vv/den, pad (3): 16 floats.
 * Degenerate triangles are stored with n = 0 and zero coefficients: the plane distance is NaN, no hit. */
#define DOT5_FLOATS 16

INLINE int dot5_hit(float ox, float oy, float oz, float dx, float dy, float dz, __global const float *t,
                    float tmin, float tmax)
{
    const float p0x = t[0], p0y = t[1], p0z = t[2];
    const float nx = t[3], ny = t[4], nz = t[5];
    const float ux = t[6], uy = t[7], uz = t[8];
    const float vx = t[9], vy = t[10], vz = t[11];
    const float uu = t[12], uv = t[13], vv = t[14];
    /* Plane intersection P_I = o + s D */
    const float s = dot3(nx, ny, nz, p0x - ox, p0y - oy, p0z - oz) / dot3(nx, ny, nz, dx, dy, dz);
    const float wx = ox + s * dx - p0x, wy = oy + s * dy - p0y, wz = oz + s * dz - p0z;
    /* The two per-ray dot products; u.u, u.v, v.v (over the denominator) are per triangle */
    const float wu = dot3(wx, wy, wz, ux, uy, uz), wv = dot3(wx, wy, wz, vx, vy, vz);
    const float bs = uv * wv - vv * wu;
    const float bt = uv * wu - uu * wv;
    return (s > tmin) & (s < tmax) & (bs >= 0.0f) & (bt >= 0.0f) & (bs + bt <= 1.0f);
}

#endif
