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
 * distance again in double from the same float32 inputs, where the float32 one's error bound does not
 * settle the answer (wt_certain). The edge functions decide inside-ness
 * watertightly in float32, but T (the scaled distance) is a sum of products of sheared coordinates: for
 * a long triangle met at a grazing angle near the ray's origin its rounding can exceed T itself (a
 * 31-unit strip met at 0.04 degrees 0.01 from the receiver came out behind the origin: a leak). */
#ifndef WT_REFINE_F64
#define WT_REFINE_F64 0
#endif
#if WT_REFINE_F64
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#endif

/* Every test below is written over lanes (vecmath.h): with LANES > 1 one triangle is tested against
 * LANES rays at once, each lane bit for bit what the scalar test gives for its ray. */

typedef struct {
    lfloat ox, oy, oz;          /* ray origin */
    lfloat dx, dy, dz;          /* direction */
    lfloat xx, xy, xz;          /* shear row for x: e_kx - Sx e_kz (kz the dominant axis of D, kx, ky next) */
    lfloat yx, yy, yz;          /* shear row for y: e_ky - Sy e_kz */
    lfloat zx, zy, zz;          /* scaled z row:   Sz e_kz */
} WtRay;

/* Per-ray set-up of the watertight test for origin o and direction D (not necessarily unit). The
 * permutation is (kz, kx, ky) = (0, 1, 2), (1, 2, 0) or (2, 0, 1), chosen per lane. */
INLINE WtRay wt_setup(lfloat ox, lfloat oy, lfloat oz, lfloat dx, lfloat dy, lfloat dz)
{
    const lfloat ax = SC_LABS(dx), ay = SC_LABS(dy), az = SC_LABS(dz);
    const lint k0 = (ax >= ay) & (ax >= az);
    const lint k1 = !k0 & (ay >= az);
    const lint k2 = !k0 & !k1;
    const lfloat one = (lfloat)1.0f, zero = (lfloat)0.0f;
    const lfloat dkz = k0 ? dx : (k1 ? dy : dz);
    const lfloat dkx = k0 ? dy : (k1 ? dz : dx);
    const lfloat dky = k0 ? dz : (k1 ? dx : dy);
    const lfloat sz = one / dkz, sx = dkx * sz, sy = dky * sz;   /* one division: any consistent shear will do */
    WtRay r;
    r.ox = ox; r.oy = oy; r.oz = oz;
    r.dx = dx; r.dy = dy; r.dz = dz;
    r.xx = k2 ? one : (k0 ? -sx : zero);
    r.xy = k0 ? one : (k1 ? -sx : zero);
    r.xz = k1 ? one : (k2 ? -sx : zero);
    r.yx = k1 ? one : (k0 ? -sy : zero);
    r.yy = k2 ? one : (k1 ? -sy : zero);
    r.yz = k0 ? one : (k2 ? -sy : zero);
    r.zx = k0 ? sz : zero;
    r.zy = k1 ? sz : zero;
    r.zz = k2 ? sz : zero;
    return r;
}

/* The hit's sign-folded interval test: t = T / det strictly inside (tmin, tmax), det != 0. */
#define WT_IN_INTERVAL(T, det, tmin, tmax)                                                          \
    ((((det) > 0) & ((T) > (tmin) * (det)) & ((T) < (tmax) * (det))) |                              \
     (((det) < 0) & ((T) < (tmin) * (det)) & ((T) > (tmax) * (det))))

#if WT_REFINE_F64
/* The hit distance of a triangle the float32 test found inside, against (tmin, tmax), in double, for
 * one ray (origin o, shear rows x, y, z): the same shear (its float32 rows are exact in double), the
 * products and sums unrounded to float32. */
INLINE int wt_interval_f64(float ox, float oy, float oz, float xx, float xy, float xz, float yx, float yy, float yz,
                           float zx, float zy, float zz, float v0x, float v0y, float v0z, float v1x, float v1y,
                           float v1z, float v2x, float v2y, float v2z, float tmin, float tmax)
{
    const double a0 = (double)v0x - ox, a1 = (double)v0y - oy, a2 = (double)v0z - oz;
    const double b0 = (double)v1x - ox, b1 = (double)v1y - oy, b2 = (double)v1z - oz;
    const double c0 = (double)v2x - ox, c1 = (double)v2y - oy, c2 = (double)v2z - oz;
    const double ax = xx * a0 + xy * a1 + xz * a2, ay = yx * a0 + yy * a1 + yz * a2, az = zx * a0 + zy * a1 + zz * a2;
    const double bx = xx * b0 + xy * b1 + xz * b2, by = yx * b0 + yy * b1 + yz * b2, bz = zx * b0 + zy * b1 + zz * b2;
    const double cx = xx * c0 + xy * c1 + xz * c2, cy = yx * c0 + yy * c1 + yz * c2, cz = zx * c0 + zy * c1 + zz * c2;
    const double U = cx * by - cy * bx, V = ax * cy - ay * cx, W = bx * ay - by * ax;
    const double det = U + V + W;
    const double T = U * az + V * bz + W * cz;
    return WT_IN_INTERVAL(T, det, (double)tmin, (double)tmax);
}

/* wt_interval_f64 for the lanes in `inside` (the others 0), one lane at a time: refinement is rare
 * (only the lanes wt_certain cannot settle), and PoCL's LLVM 14 miscompiled the same arithmetic on
 * double8 vectors (68 of 4,000 masks wrong on the default scene) and could not lower double16. */
NOINLINE lint wt_refine(const WtRay *r, lint inside, float v0x, float v0y, float v0z, float v1x, float v1y,
                      float v1z, float v2x, float v2y, float v2z, lfloat tmin, lfloat tmax)
{
#if LANES == 1
    return inside && wt_interval_f64(r->ox, r->oy, r->oz, r->xx, r->xy, r->xz, r->yx, r->yy, r->yz, r->zx, r->zy,
                                     r->zz, v0x, v0y, v0z, v1x, v1y, v1z, v2x, v2y, v2z, tmin, tmax);
#else
    float ox[LANES], oy[LANES], oz[LANES], xx[LANES], xy[LANES], xz[LANES], yx[LANES], yy[LANES], yz[LANES];
    float zx[LANES], zy[LANES], zz[LANES], t0[LANES], t1[LANES];
    int in[LANES], out[LANES];
    LANE_STORE(r->ox, ox); LANE_STORE(r->oy, oy); LANE_STORE(r->oz, oz);
    LANE_STORE(r->xx, xx); LANE_STORE(r->xy, xy); LANE_STORE(r->xz, xz);
    LANE_STORE(r->yx, yx); LANE_STORE(r->yy, yy); LANE_STORE(r->yz, yz);
    LANE_STORE(r->zx, zx); LANE_STORE(r->zy, zy); LANE_STORE(r->zz, zz);
    LANE_STORE(tmin, t0); LANE_STORE(tmax, t1); LANE_STORE(inside, in);
    for (int j = 0; j < LANES; ++j)
        out[j] = (in[j] && wt_interval_f64(ox[j], oy[j], oz[j], xx[j], xy[j], xz[j], yx[j], yy[j], yz[j], zx[j], zy[j],
                                           zz[j], v0x, v0y, v0z, v1x, v1y, v1z, v2x, v2y, v2z, t0[j], t1[j])) ? -1 : 0;
    return LANE_LOAD(int, out);
#endif
}
#endif

#if WT_REFINE_F64
/* The lanes whose float32 distance test below cannot differ from the double refinement's: T and det
 * are within e_T and e_det of what exact arithmetic gives from the same float32 inputs (which the
 * refinement computes to ~2^-29 of these bounds), and det, T - tmin det and det - T / tmax are each
 * farther from zero than their bounds. Derivation, with u = 2^-24 and no contraction (top of file):
 * a shear row holds 1, -S (|S| <= 1) and 0, so a sheared x or y is off by at most 4u N (N = |a0| + |a1|
 * + |a2|, the vertex's unsheared magnitude) and a scaled z by 2u |z|; then U = cx by - cy bx is off by
 * u (4 (Nb Lc + Nc Lb) + 2 Lb Lc + 32 u Nb Nc) (L = |x| + |y|), det by e_U + e_V + e_W + 2u (|U| + |V| +
 * |W|), T by |az| e_U + |bz| e_V + |cz| e_W + 5u (|U az| + |V bz| + |W cz|), and each comparison adds
 * its own rounding. Everything below uses FLT_EPSILON = 2u, which doubles the bounds: room for the
 * second-order terms and for the bounds' own rounding. A NaN or an infinity anywhere is never
 * certain. Measured (2026-12-02, 1.2 M receivers): classify on a city of 4 icospheres 24.9 -> 16.4 ms
 * with every hit refined -> only the uncertain lanes, the default scene 11.3 -> 9.5 ms. */
INLINE lint wt_certain(lfloat ax, lfloat ay, lfloat az, lfloat bx, lfloat by, lfloat bz, lfloat cx, lfloat cy,
                       lfloat cz, lfloat na, lfloat nb, lfloat nc, lfloat U, lfloat V, lfloat W, lfloat det,
                       lfloat T, lfloat tmin, lfloat tmax)
{
    const float e = FLT_EPSILON;
    const lfloat la = SC_LABS(ax) + SC_LABS(ay), lb = SC_LABS(bx) + SC_LABS(by), lc = SC_LABS(cx) + SC_LABS(cy);
    const lfloat eU = e * (4.0f * (nb * lc + nc * lb) + 2.0f * lb * lc + 32.0f * e * nb * nc);
    const lfloat eV = e * (4.0f * (nc * la + na * lc) + 2.0f * lc * la + 32.0f * e * nc * na);
    const lfloat eW = e * (4.0f * (na * lb + nb * la) + 2.0f * la * lb + 32.0f * e * na * nb);
    const lfloat e_det = eU + eV + eW + 2.0f * e * (SC_LABS(U) + SC_LABS(V) + SC_LABS(W));
    const lfloat e_T = SC_LABS(az) * eU + SC_LABS(bz) * eV + SC_LABS(cz) * eW +
                       6.0f * e * (SC_LABS(U * az) + SC_LABS(V * bz) + SC_LABS(W * cz));
    const lfloat itmax = 1.0f / tmax;                 /* T < tmax det as T / tmax < det: no overflow */
    const lfloat near = T - tmin * det, far = det - T * itmax;
    const lfloat e_near = e_T + tmin * e_det + 2.0f * e * (SC_LABS(T) + tmin * SC_LABS(det));
    const lfloat e_far = e_det + itmax * e_T + 2.0f * e * (SC_LABS(det) + itmax * SC_LABS(T));
    return (SC_LABS(det) > e_det) & (SC_LABS(near) > e_near) & (SC_LABS(far) > e_far);
}
#endif

/* Watertight hit of triangle (v0, v1, v2) for tmin < t < tmax. */
INLINE lint wt_hit(const WtRay *r, float v0x, float v0y, float v0z, float v1x, float v1y, float v1z,
                   float v2x, float v2y, float v2z, lfloat tmin, lfloat tmax)
{
    const lfloat a0 = v0x - r->ox, a1 = v0y - r->oy, a2 = v0z - r->oz;
    const lfloat b0 = v1x - r->ox, b1 = v1y - r->oy, b2 = v1z - r->oz;
    const lfloat c0 = v2x - r->ox, c1 = v2y - r->oy, c2 = v2z - r->oz;
    /* Shear and scale the vertices */
    const lfloat ax = r->xx * a0 + r->xy * a1 + r->xz * a2, ay = r->yx * a0 + r->yy * a1 + r->yz * a2;
    const lfloat bx = r->xx * b0 + r->xy * b1 + r->xz * b2, by = r->yx * b0 + r->yy * b1 + r->yz * b2;
    const lfloat cx = r->xx * c0 + r->xy * c1 + r->xz * c2, cy = r->yx * c0 + r->yy * c1 + r->yz * c2;
    /* Edge functions; zero counts as inside for either orientation */
    const lfloat U = cx * by - cy * bx;
    const lfloat V = ax * cy - ay * cx;
    const lfloat W = bx * ay - by * ax;
    const lint inside = ((U >= 0.0f) & (V >= 0.0f) & (W >= 0.0f)) | ((U <= 0.0f) & (V <= 0.0f) & (W <= 0.0f));
#if WT_REFINE_F64
    if (!LANE_ANY(inside))
        return inside;
#endif
    const lfloat az = r->zx * a0 + r->zy * a1 + r->zz * a2;
    const lfloat bz = r->zx * b0 + r->zy * b1 + r->zz * b2;
    const lfloat cz = r->zx * c0 + r->zy * c1 + r->zz * c2;
    const lfloat det = U + V + W;
    const lfloat T = U * az + V * bz + W * cz;
    const lint hit = inside & WT_IN_INTERVAL(T, det, tmin, tmax);
#if WT_REFINE_F64
    const lint unsure = inside & !wt_certain(ax, ay, az, bx, by, bz, cx, cy, cz,
                                             SC_LABS(a0) + SC_LABS(a1) + SC_LABS(a2),
                                             SC_LABS(b0) + SC_LABS(b1) + SC_LABS(b2),
                                             SC_LABS(c0) + SC_LABS(c1) + SC_LABS(c2), U, V, W, det, T, tmin, tmax);
    if (LANE_ANY(unsure))
        return (hit & !unsure) | wt_refine(r, unsure, v0x, v0y, v0z, v1x, v1y, v1z, v2x, v2y, v2z, tmin, tmax);
#endif
    return hit;
}

/* Watertight triangle record (WT_FLOATS = 32 floats, two 64-byte lines). The first line: the corners
 * v0, v1, v2 as stored (9), then for the plane test the unit normal n (3), fL = n.(light - v0) for a
 * point light or n.(-direction) for a directional light, and its rounding bound eL (2), the relative
 * bound rel of the plane test (1: 1e-6 plus how far the computed normal may lean, large for slivers),
 * 1 float of padding. The second line, for the cone test: the three edge planes m0, m1, m2 (9), through
 * the light (point) or along its direction (directional), each oriented so that a line to the light
 * through the triangle is on its positive side (wt_cone); the rounding scale tau and offset sigma of
 * their values (2); the planes' offsets
 * w0, w1, w2 (3: m_k . v_k for a directional light, 0 for a point light); 2 floats of padding. */
#define WT_FLOATS 32
#define NORMAL_ULPS 8.0f   /* the cross product's rounding, in FLT_EPSILON, that the cull allows for */

/* Plane test: 1 where the tested part of the segment, from s + tmin d (a hit counts only beyond tmin)
 * to the light, certainly stays on one side of the triangle's plane (both ends farther than their
 * rounding bounds from it, on the same side), so no test can hit; in *crossing the lanes where it
 * certainly crosses the plane (the ends certainly on opposite sides). A segment through a shared edge or
 * vertex crosses both planes there, so the cull never removes one; it only skips triangles the segment
 * does not reach. Starting at tmin rather than at s culls the plane a receiver lies on (a point on a
 * face, given without normals): measured on the default scene's ground, one-shot 101 -> ~60 ms. The
 * bound covers s - v0 (exact near v0) and the tmin d step with the record's relative bound. Degenerate
 * triangles (n = 0) are neither culled nor crossed (their test says no hit). */
INLINE lint wt_plane(__global const float *t, lfloat sx, lfloat sy, lfloat sz, lfloat dx, lfloat dy, lfloat dz,
                     lfloat tmin, lint *crossing)
{
    const lfloat a0 = (sx - t[0]) + tmin * dx, a1 = (sy - t[1]) + tmin * dy, a2 = (sz - t[2]) + tmin * dz;
    const lfloat fs = t[9] * a0 + t[10] * a1 + t[11] * a2;
    const lfloat es = t[14] * (SC_LABS(a0) + SC_LABS(a1) + SC_LABS(a2) +
                               tmin * (SC_LABS(dx) + SC_LABS(dy) + SC_LABS(dz)));
    const float fl = t[12], el = t[13];        /* the light's side: one per triangle */
    const lint above = fs > es, below = fs < -es;
    *crossing = (fl > el) ? below : ((fl < -el) ? above : (lint)0);
    return (fl > el) ? above : ((fl < -el) ? below : (lint)0);
}

/* Cone test: the lanes whose line to the light certainly misses the triangle (outside one of its edge
 * planes by more than the rounding bound), and in *inside those whose line certainly passes through it
 * (inside all three). The planes contain the light (point light: x = d = light - s, the values m_k . d)
 * or its direction (directional: x = s, the values m_k . s - w_k); x_norm = |x|_1. With the plane
 * test's crossing, inside is a hit, and outside is a miss: what the watertight test would say, decided
 * without it, except near an edge or a vertex (within the bound: exact.cl wt_cone_record), where
 * neither is certain and the watertight test decides (a lane on a shared edge goes to it). */
INLINE lint wt_cone(__global const float *t, lfloat x, lfloat y, lfloat z, lfloat x_norm, lint *inside)
{
    const lfloat bound = t[25] * x_norm + t[26];
    const lfloat e0 = t[16] * x + t[17] * y + t[18] * z - t[27];
    const lfloat e1 = t[19] * x + t[20] * y + t[21] * z - t[28];
    const lfloat e2 = t[22] * x + t[23] * y + t[24] * z - t[29];
    *inside = (e0 > bound) & (e1 > bound) & (e2 > bound);
    return (e0 < -bound) | (e1 < -bound) | (e2 < -bound);
}

/* Dot5 triangle record: V0 (3), n = u x v (3), u (3), v (3), uu/den, uv/den, vv/den, pad (3): 16 floats.
 * Degenerate triangles are stored with n = 0 and zero coefficients: the plane distance is NaN, no hit. */
#define DOT5_FLOATS 16

INLINE lint dot5_hit(lfloat ox, lfloat oy, lfloat oz, lfloat dx, lfloat dy, lfloat dz, __global const float *t,
                     lfloat tmin, lfloat tmax)
{
    const float p0x = t[0], p0y = t[1], p0z = t[2];
    const float nx = t[3], ny = t[4], nz = t[5];
    const float ux = t[6], uy = t[7], uz = t[8];
    const float vx = t[9], vy = t[10], vz = t[11];
    const float uu = t[12], uv = t[13], vv = t[14];
    /* Plane intersection P_I = o + s D */
    const lfloat s = (nx * (p0x - ox) + ny * (p0y - oy) + nz * (p0z - oz)) / (nx * dx + ny * dy + nz * dz);
    const lfloat wx = ox + s * dx - p0x, wy = oy + s * dy - p0y, wz = oz + s * dz - p0z;
    /* The two per-ray dot products; u.u, u.v, v.v (over the denominator) are per triangle */
    const lfloat wu = wx * ux + wy * uy + wz * uz, wv = wx * vx + wy * vy + wz * vz;
    const lfloat bs = uv * wv - vv * wu;
    const lfloat bt = uv * wu - uu * wv;
    return (s > tmin) & (s < tmax) & (bs >= 0.0f) & (bt >= 0.0f) & (bs + bt <= 1.0f);
}

#endif
