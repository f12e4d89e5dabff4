/* raster.cl: the one rasterizer of shadowcl (camera Z-buffer, light depth map), for any clip matrix.
 *
 * Pipeline, one launch each:
 *   raster_setup      per triangle: transform, clip in homogeneous space, snap corners to fixed point
 *   raster_pass       per triangle, one kernel for every pass (an argument says which, so that a
 *                     call compiles one kernel, not one per pass):
 *                       depth     nearest depth of every pixel (atomic_max on the float's bits)
 *                       triangle  smallest triangle id among the fragments at the stored depth
 *                       count     how many fragments each pixel received (overdraw, for tests)
 *                       stencil   shadow-volume stencil, +-1 per fragment by screen winding where
 *                                 the fragment passes the depth test against a Z-buffer (z-pass or z-fail)
 *   raster_receivers  per covered pixel: surface point and viewer-facing normal seen through it
 *
 * Conventions (host/shadowcl/views.py): clip = matrix * (relative position, 1); depth = z / w in
 * [0, 1], 1 nearest (reversed Z). Screen coordinates are fixed point with SUBPIXEL_BITS fraction
 * bits, x right and y down from the top-left image corner; pixel (row, col) samples its centre.
 * Fill rule: top-left, decided with exact integer edge functions, so two triangles sharing an edge
 * never both draw a pixel and never both drop one.
 *
 * The host (host/shadowcl/raster.py) defines the contract's constants with -D:
 *   SUBPIXEL_BITS  fraction bits of the fixed-point screen coordinates
 *   GUARD_BAND     pixels kept by clipping on each side of the image centre (2^21): corners stay
 *                  within 2^29 units of the centre, coordinate differences below 2^30, and edge
 *                  functions (a difference of two products of differences) below 2^61 in a long
 *   MAX_CORNERS    corners of a triangle clipped by the six planes (3 + one per plane)
 *   BIG_BOX        pixels in a triangle's bounding box above which several work-items draw it
 */

/* INLINE, dot3 and SC_ABS, SC_MIN, SC_SQRT: math that PoCL inlines */
#include "vecmath.h"

/* The depth and triangle passes recompute each fragment's depth and compare it bit for bit:
 * forbid the compiler to fuse multiply-adds differently in the two kernels (vecmath.h does too). */
#pragma OPENCL FP_CONTRACT OFF

#define ONE (1 << SUBPIXEL_BITS) /* fixed-point units per pixel */
#define HALF (ONE >> 1)

/* Rows and columns (col0, row0, col1, row1) of the pixels whose centres lie in the fixed-point
 * box [lo, hi], clamped to the image; empty when col0 > col1 or row0 > row1. */
INLINE int4 pixel_box(const int2 lo, const int2 hi, const int width, const int height)
{
    const int2 size = (int2)(width, height) * ONE;
    const int2 first = (clamp(lo, (int2)(0), size) + HALF - 1) >> SUBPIXEL_BITS; /* centre >= lo */
    const int2 last = ((clamp(hi, (int2)(0), size) + HALF) >> SUBPIXEL_BITS) - 1; /* centre <= hi */
    return (int4)(first, last);
}

/* The pixel box of a polygon's count corners. */
INLINE int4 polygon_box(global const int2 *xy, const int count, const int width, const int height)
{
    int2 lo = (int2)(INT_MAX), hi = (int2)(INT_MIN);
    for (int k = 0; k < count; ++k) {
        lo = min(lo, xy[k]);
        hi = max(hi, xy[k]);
    }
    return pixel_box(lo, hi, width, height);
}

INLINE bool is_empty(const int4 box)
{
    return box.s0 > box.s2 || box.s1 > box.s3;
}

/* Whether the raster passes share the polygon with this box among several work-items. */
INLINE bool is_big(const int4 box)
{
    return (long)(box.s2 - box.s0 + 1) * (box.s3 - box.s1 + 1) > BIG_BOX;
}

/* ---------------------------------------------------------------------------------------------- */
/* Triangle setup                                                                                  */
/* ---------------------------------------------------------------------------------------------- */

/* Signed distance of clip-space point v to clip plane k (inside when >= 0). The six planes keep
 * 0 <= depth <= 1 and |x|, |y| within the guard band: gx = GUARD_BAND / (width / 2) in NDC. */
INLINE float plane_distance(const int k, const float4 v, const float gx, const float gy)
{
    switch (k) {
    case 0: return v.w - v.z;       /* depth <= 1: the near plane */
    case 1: return v.z;             /* depth >= 0: the far plane (infinitely far in perspective) */
    case 2: return gx * v.w - v.x;
    case 3: return gx * v.w + v.x;
    case 4: return gy * v.w - v.y;
    default: return gy * v.w + v.y;
    }
}

/* The point where edge (inside, outside) crosses the plane, always interpolated from the inside
 * corner: a shared edge is walked in opposite directions by its two triangles, and this makes both
 * cut it at the bit-identical point. */
INLINE float4 cut(const float4 inside, const float d_inside, const float4 outside, const float d_outside)
{
    const float t = d_inside / (d_inside - d_outside);
    return inside + t * (outside - inside);
}

/* Sutherland-Hodgman: clip polygon `in` (n corners) by plane k into `out`; returns its corner count. */
INLINE int clip_polygon(const int k, const float4 *in, const int n, float4 *out, const float gx, const float gy)
{
    int m = 0;
    for (int i = 0; i < n; ++i) {
        const float4 a = in[i], b = in[i + 1 < n ? i + 1 : 0];
        const float da = plane_distance(k, a, gx, gy), db = plane_distance(k, b, gx, gy);
        if (da >= 0.0f)
            out[m++] = a;
        if (da >= 0.0f && db < 0.0f)
            out[m++] = cut(a, da, b, db);
        else if (da < 0.0f && db >= 0.0f)
            out[m++] = cut(b, db, a, da);
    }
    return m;
}

/* x rounded half to even, without PoCL's rint or convert_int_rte: those are calls that cost more
 * than the rest of the setup. Below 2^23, adding 2^23 leaves no fraction bits, so the addition
 * rounds to the nearest integer, ties to even; from 2^23 on floats are integers. */
INLINE int round_even(const float x)
{
    const float a = SC_ABS(x), rounded = a < 0x1p23f ? (a + 0x1p23f) - 0x1p23f : a;
    return (int)(x < 0.0f ? -rounded : rounded);
}

/* m * (x, y, z, 1) for a row-major 4x4 matrix m. */
INLINE float4 transform(constant float *m, const float x, const float y, const float z)
{
    return (float4)(m[0] * x + m[1] * y + m[2] * z + m[3], m[4] * x + m[5] * y + m[6] * z + m[7],
                    m[8] * x + m[9] * y + m[10] * z + m[11], m[12] * x + m[13] * y + m[14] * z + m[15]);
}

/* raster_setup: one work-item per triangle, n triangles.
 * In:  vertices (3 floats each, relative to the view origin), faces (3 ints each), matrix (row-major
 *      relative -> clip), image size.
 * Out: corner_count[i] = corners of triangle i after clipping (0: nothing to draw), and for each
 *      corner k < count, corner_xy[i * MAX_CORNERS + k] = fixed-point screen position and
 *      corner_depth[...] = depth clamped to [0, 1]. The polygon is drawn as the fan (0, k, k + 1).
 *      Triangles whose box holds more than BIG_BOX pixels are listed in big[], which *big_count
 *      (zero before) counts, at most n: the raster passes share them among several work-items.
 * Clip-space corners that are not finite, or with w <= 0 after clipping (a matrix whose clip volume
 * reaches w = 0), drop the triangle. */
/* raster_setup's work-item gid (NOINLINE: a kernel's body, vecmath.h) */
NOINLINE void setup_triangle(const int gid, global const float *vertices, global const int *faces,
                             constant float *matrix, const int width, const int height, global int *corner_count,
                             global int2 *corner_xy, global float *corner_depth, global int *big,
                             volatile global int *big_count)
{
    /* Transform the corners to clip space */
    float4 clipped[MAX_CORNERS], scratch[MAX_CORNERS];
    for (int k = 0; k < 3; ++k) {
        global const float *p = vertices + 3 * faces[3 * gid + k];
        clipped[k] = transform(matrix, p[0], p[1], p[2]);
    }

    /* Clip against the six planes; most triangles are inside them all and skip the copies */
    const float gx = (float)GUARD_BAND / (0.5f * (float)width);
    const float gy = (float)GUARD_BAND / (0.5f * (float)height);
    int count = 3;
    for (int k = 0; k < 6 && count > 0; ++k) {
        bool inside = true;
        for (int i = 0; i < count; ++i)
            inside &= plane_distance(k, clipped[i], gx, gy) >= 0.0f;
        if (inside)
            continue;
        count = clip_polygon(k, clipped, count, scratch, gx, gy);
        for (int i = 0; i < count; ++i)
            clipped[i] = scratch[i];
    }

    /* Snap to fixed point: top-left origin, y down, ONE units per pixel */
    const float half_w = (float)(width * HALF), half_h = (float)(height * HALF);
    const float limit = 2.0f * GUARD_BAND * ONE; /* corners lie within the guard band, up to rounding */
    global int2 *xy = corner_xy + gid * MAX_CORNERS;
    global float *depth = corner_depth + gid * MAX_CORNERS;
    for (int k = 0; k < count; ++k) {
        const float4 v = clipped[k];
        const float sx = v.x / v.w * half_w, sy = -v.y / v.w * half_h, z = v.z / v.w;
        if (!(v.w > 0.0f && SC_ABS(sx) <= limit && SC_ABS(sy) <= limit && z == z)) {
            count = 0;
            break;
        }
        xy[k] = (int2)(round_even(sx) + width * HALF, round_even(sy) + height * HALF);
        depth[k] = z > 0.0f ? SC_MIN(z, 1.0f) : 0.0f; /* never -0.0: its bits would sort above 1.0 */
    }
    corner_count[gid] = count;

    if (count >= 3) {
        const int4 box = polygon_box(xy, count, width, height);
        if (!is_empty(box) && is_big(box))
            big[atomic_inc(big_count)] = gid;
    }
}

kernel void raster_setup(global const float *vertices, global const int *faces, constant float *matrix,
                         const int width, const int height, const int n, global int *corner_count,
                         global int2 *corner_xy, global float *corner_depth, global int *big,
                         volatile global int *big_count)
{
    const int gid = get_global_id(0);
    if (gid < n)
        setup_triangle(gid, vertices, faces, matrix, width, height, corner_count, corner_xy, corner_depth, big,
                       big_count);
}

/* ---------------------------------------------------------------------------------------------- */
/* Rasterization                                                                                   */
/* ---------------------------------------------------------------------------------------------- */

/* The values of raster_pass's pass argument (host/shadowcl/raster.py names them too) */
enum pass { DEPTH_PASS, TRIANGLE_PASS, COUNT_PASS, ZFAIL_STENCIL_PASS, ZPASS_STENCIL_PASS };

/* Edge function of edge a -> b at p: positive on the interior side of a positively ordered
 * triangle (y down: the interior is right of a -> b as seen on screen). Exact in 64 bits. */
INLINE long edge_function(const int2 a, const int2 b, const long px, const long py)
{
    return ((long)b.x - a.x) * (py - a.y) - ((long)b.y - a.y) * (px - a.x);
}

/* Top-left rule: a sample exactly on edge a -> b is inside when the edge is a top edge (horizontal,
 * interior below) or a left edge (interior right, the edge going up). Returns the smallest edge
 * function value that counts as inside. */
INLINE long edge_threshold(const int2 a, const int2 b)
{
    const int dx = b.x - a.x, dy = b.y - a.y;
    return (dy < 0 || (dy == 0 && dx > 0)) ? 0 : 1;
}

INLINE bool precedes(const int2 a, const int2 b)
{
    return a.y < b.y || (a.y == b.y && a.x < b.x);
}

/* One fragment: what the pass does with it. winding is +1 when the triangle's corners run positively
 * on screen (y down: clockwise as seen, so a triangle wound counter-clockwise around its outward
 * normal shows its back), -1 otherwise. */
INLINE void shade(const enum pass pass, const int pixel, const float depth, const uint id, const int winding,
                  global uint *target, global const uint *depth_bits)
{
    switch (pass) {
    case DEPTH_PASS: /* depth >= 0, so the uint order of its bits is the float order */
        atomic_max(target + pixel, as_uint(depth));
        break;
    case TRIANGLE_PASS: /* same depth, bit for bit, as the depth pass computed */
        if (as_uint(depth) == depth_bits[pixel])
            atomic_min(target + pixel, id);
        break;
    case COUNT_PASS:
        atomic_inc(target + pixel);
        break;
    /* Winding number of the surface point, seen as lying just in front of its own depth (a face
     * at the same depth, bit for bit, counts as behind it). z-fail: faces behind the point, +1
     * leaving the volume (back faces), -1 entering; z-pass: faces in front of it, +1 entering. */
    case ZFAIL_STENCIL_PASS:
        if (as_uint(depth) <= depth_bits[pixel])
            atomic_add(target + pixel, (uint)winding);
        break;
    case ZPASS_STENCIL_PASS:
        if (as_uint(depth) > depth_bits[pixel])
            atomic_sub(target + pixel, (uint)winding);
        break;
    }
}

/* Narrow the span [lo, hi] of a row to the columns inside one edge, where
 * e + (col - first) * step >= threshold: exact, as the inside of an edge along a row is an interval. */
INLINE void clip_span(const long e, const long step, const long threshold, const int first, int *lo, int *hi)
{
    const long need = threshold - e; /* inside where j * step >= need, j = col - first */
    if (step > 0 && need > 0)
        *lo = (int)max((long)*lo, min(first + (need + step - 1) / step, (long)*hi + 1));
    else if (step < 0)
        *hi = need > 0 ? first - 1 : (int)min((long)*hi, first + need / step);
    else if (step == 0 && need > 0)
        *hi = first - 1;
}

/* Draw triangle (a, b, c) with corner depths (za, zb, zc): every pixel centre inside by the
 * top-left rule gets a fragment whose depth is interpolated linearly in screen space. Draws rows
 * band, band + bands, ... of the triangle's bounding box, so that several work-items can share a
 * big triangle. */
INLINE void draw_triangle(const enum pass pass, int2 a, int2 b, int2 c, float za, float zb, float zc,
                          const int width, const int height, const int band, const int bands, const uint id,
                          global uint *target, global const uint *depth_bits)
{
    /* Order the corners positively and start from the least (y, x) corner, so that the same
     * triangle given in any corner order computes bit-identical depths (exact depth ties) */
    long area = edge_function(a, b, c.x, c.y);
    if (area == 0)
        return;
    const int winding = area > 0 ? 1 : -1;
    if (area < 0) {
        const int2 t = b; b = c; c = t;
        const float s = zb; zb = zc; zc = s;
        area = -area;
    }
    if (precedes(b, a) && !precedes(c, b)) { /* b is least: rotate (a, b, c) -> (b, c, a) */
        const int2 t = a; a = b; b = c; c = t;
        const float s = za; za = zb; zb = zc; zc = s;
    } else if (precedes(c, a) && precedes(c, b)) { /* c is least: rotate -> (c, a, b) */
        const int2 t = c; c = b; b = a; a = t;
        const float s = zc; zc = zb; zb = za; za = s;
    }

    /* Pixels whose centres lie in the bounding box, clamped to the image */
    const int4 box = pixel_box(min(a, min(b, c)), max(a, max(b, c)), width, height);
    const int col0 = box.s0, row0 = box.s1, col1 = box.s2, row1 = box.s3;

    /* Edge functions at the box's first pixel centre and their steps per pixel; e_a weighs a */
    const long px = (long)col0 * ONE + HALF, py = (long)row0 * ONE + HALF;
    const long e_a = edge_function(b, c, px, py), e_b = edge_function(c, a, px, py), e_c = edge_function(a, b, px, py);
    const long min_a = edge_threshold(b, c), min_b = edge_threshold(c, a), min_c = edge_threshold(a, b);
    const long dx_a = -((long)c.y - b.y) * ONE, dx_b = -((long)a.y - c.y) * ONE, dx_c = -((long)b.y - a.y) * ONE;
    const long dy_a = ((long)c.x - b.x) * ONE, dy_b = ((long)a.x - c.x) * ONE, dy_c = ((long)b.x - a.x) * ONE;
    const float inv_area = 1.0f / (float)area;

    for (int row = row0 + band; row <= row1; row += bands) {
        /* The row's span inside all three edges */
        const long r = row - row0;
        const long row_a = e_a + r * dy_a, row_b = e_b + r * dy_b, row_c = e_c + r * dy_c;
        int lo = col0, hi = col1;
        clip_span(row_a, dx_a, min_a, col0, &lo, &hi);
        clip_span(row_b, dx_b, min_b, col0, &lo, &hi);
        clip_span(row_c, dx_c, min_c, col0, &lo, &hi);

        for (int col = lo; col <= hi; ++col) {
            const long j = col - col0;
            /* Weights are >= 0 inside, so the sum has no cancellation: a few ulp of the depth */
            const float depth = ((float)(row_a + j * dx_a) * za + (float)(row_b + j * dx_b) * zb +
                                 (float)(row_c + j * dx_c) * zc) * inv_area;
            shade(pass, row * width + col, depth, id, winding, target, depth_bits);
        }
    }
}

/* Draw one clipped triangle as the fan of its corners. One launch of n + big_count * bands
 * work-items (a 1D range, so that every launch has one local size and PoCL compiles the kernel once):
 * work-item k < n draws triangle k whole, unless its box is empty or big; the rest draw rows band,
 * band + bands, ... of big triangle big[j], (j, band) numbered band-major from n on, so that a
 * work-group holds bands of many big triangles and each big triangle spreads over work-groups. This is
 * work-item k of raster_pass (NOINLINE: a kernel's body, vecmath.h). */
NOINLINE void draw_polygon(const long k, const enum pass pass, global const int *big, const int n,
                           const int big_count, const int bands, global const int *corner_count,
                           global const int2 *corner_xy, global const float *corner_depth, const int width,
                           const int height, global uint *target, global const uint *depth_bits)
{
    const bool whole = k < n;
    const int i = whole ? (int)k : big[(k - n) % max(big_count, 1)], band = whole ? 0 : (int)((k - n) / big_count);
    const int count = corner_count[i];
    global const int2 *xy = corner_xy + i * MAX_CORNERS;
    global const float *depth = corner_depth + i * MAX_CORNERS;
    if (whole && count >= 3) {
        const int4 box = polygon_box(xy, count, width, height);
        if (is_empty(box) || is_big(box))
            return;
    }
    for (int c = 1; c + 1 < count; ++c)
        draw_triangle(pass, xy[0], xy[c], xy[c + 1], depth[0], depth[c], depth[c + 1], width, height, band,
                      whole ? 1 : bands, (uint)i, target, depth_bits);
}

/* raster_pass, after raster_setup: draws the n triangles (big_count of them, listed in big, shared by
 * bands work-items each, see draw_polygon) with pass (enum pass):
 *   DEPTH_PASS     In/out: target = depth bits (H * W, row-major), the float depth's bits, 0 (= 0.0,
 *                  infinitely far) before the first triangle; each fragment does atomic_max: the
 *                  nearest depth wins.
 *   TRIANGLE_PASS  After DEPTH_PASS. In: depth_bits. In/out: target = triangle (H * W), 0xFFFFFFFF (no
 *                  triangle) before the first one; a fragment whose depth equals the stored depth does
 *                  atomic_min of its triangle id, so equal depths resolve to the smallest id whatever
 *                  the scheduling.
 *   COUNT_PASS     In/out: target = count (H * W), zero before; every fragment increments its pixel. A
 *                  watertight surface crossed once by each pixel's ray gives exactly 1 inside its
 *                  outline: this makes "drawn twice" and "dropped" observable.
 *   ZFAIL_STENCIL_PASS, ZPASS_STENCIL_PASS: the shadow-volume stencil of closed, consistently wound
 *                  volumes (outward faces counter-clockwise). In: depth_bits, a Z-buffer of the
 *                  receivers (DEPTH_PASS's output). In/out: target = stencil (H * W, two's-complement
 *                  int32), set by the host before the first triangle; every fragment passing the depth
 *                  test adds its winding, so a covered pixel ends with the winding number of its surface
 *                  point (z-pass: counted from the eye's, which the host puts in first).
 * depth_bits is not read by DEPTH_PASS and COUNT_PASS (pass target). */
kernel void raster_pass(global const int *big, const int n, const int big_count, const int bands,
                        global const int *corner_count, global const int2 *corner_xy,
                        global const float *corner_depth, const int width, const int height, const int pass,
                        global uint *target, global const uint *depth_bits)
{
    const long k = get_global_id(0);
    if (k < n + (long)big_count * bands)
        draw_polygon(k, (enum pass)pass, big, n, big_count, bands, corner_count, corner_xy, corner_depth, width,
                     height, target, depth_bits);
}

/* ---------------------------------------------------------------------------------------------- */
/* Receivers                                                                                       */
/* ---------------------------------------------------------------------------------------------- */

/* Plain arithmetic rather than the built-in geometric functions, which PoCL does not inline: with
 * them this kernel took about twice as long. */
INLINE float vdot(const float3 a, const float3 b)
{
    return dot3(a.x, a.y, a.z, b.x, b.y, b.z);
}

INLINE float3 vcross(const float3 a, const float3 b)
{
    return (float3)(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}

INLINE float3 vunit(const float3 a)
{
    return a * (1.0f / SC_SQRT(vdot(a, a)));
}

INLINE float3 load3(global const float *p)
{
    return (float3)(p[0], p[1], p[2]);
}

INLINE void store3(const float3 a, global float *p)
{
    p[0] = a.x;
    p[1] = a.y;
    p[2] = a.z;
}

INLINE float3 unproject(constant float *inverse, const float x, const float y, const float depth)
{
    const float4 p = transform(inverse, x, y, depth);
    return p.xyz * (1.0f / p.w);
}

/* raster_receivers: one work-item per covered pixel, m pixels.
 * In:  pixel[i] = flat row-major index of a pixel with a triangle; triangle and depth_bits = the
 *      Z-buffer; vertices (relative) and faces of the mesh drawn; inverse = inverse of the view
 *      matrix (row-major, clip -> relative).
 * Out: points[3 i..] = where the pixel centre's ray meets its triangle's plane (relative to the view
 *      origin); normals[3 i..] = the triangle's unit geometric normal, turned to face the viewer.
 * The ray starts at the pixel centre unprojected at depth 1 and points towards depth 0.5 (as
 * View.pixel_rays). If the plane is parallel to the ray in float32, the point is the pixel centre
 * unprojected at its stored depth instead. */
/* raster_receivers' work-item gid (NOINLINE: a kernel's body, vecmath.h) */
NOINLINE void receiver(const int gid, global const int *pixel, global const uint *triangle,
                       global const uint *depth_bits, global const float *vertices, global const int *faces,
                       constant float *inverse, const int width, const int height, global float *points,
                       global float *normals)
{
    /* The pixel centre's ray */
    const int p = pixel[gid], row = p / width, col = p - row * width;
    const float x = (2.0f * col + 1.0f) / width - 1.0f, y = 1.0f - (2.0f * row + 1.0f) / height;
    const float3 start = unproject(inverse, x, y, 1.0f);
    const float3 direction = vunit(unproject(inverse, x, y, 0.5f) - start);

    /* Its triangle's plane */
    global const int *face = faces + 3 * triangle[p];
    const float3 v0 = load3(vertices + 3 * face[0]);
    const float3 cross = vcross(load3(vertices + 3 * face[1]) - v0, load3(vertices + 3 * face[2]) - v0);
    const float area2 = vdot(cross, cross);
    /* A sliver can be drawn (its snapped screen corners span pixels) while its float32 cross product
     * is zero or underflows: it has no plane, so it faces the viewer and keeps its stored depth. */
    const bool has_plane = area2 > 0.0f && area2 <= FLT_MAX;
    const float3 normal = has_plane ? cross * (1.0f / SC_SQRT(area2)) : -direction;
    const float facing = vdot(normal, direction);

    /* Intersect, or fall back on the stored depth */
    const float t = vdot(normal, v0 - start) / facing;
    const bool finite = has_plane && SC_ABS(t) <= FLT_MAX; /* false for inf and NaN */
    store3(finite ? start + t * direction : unproject(inverse, x, y, as_float(depth_bits[p])), points + 3 * gid);
    store3(facing > 0.0f ? -normal : normal, normals + 3 * gid);
}

kernel void raster_receivers(global const int *pixel, global const uint *triangle,
                             global const uint *depth_bits, global const float *vertices, global const int *faces,
                             constant float *inverse, const int width, const int height, const int m,
                             global float *points, global float *normals)
{
    const int gid = get_global_id(0);
    if (gid < m)
        receiver(gid, pixel, triangle, depth_bits, vertices, faces, inverse, width, height, points, normals);
}
