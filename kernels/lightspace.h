/* lightspace.h: the light's views and their grids of cells, shared by the list builder (lightspace.cl)
 * and every method that looks a receiver's cell up (exact.cl).
 *
 * A view is VIEW_FLOATS floats (built by host/shadowcl/lightspace.py; ints stored as their bits):
 *     [ 0.. 3] ex ey ez _            the eye (light) or zero
 *     [ 4.. 7] Mx0 Mx1 Mx2 cx        X row
 *     [ 8..11] My0 My1 My2 cy        Y row
 *     [12..15] Mw0 Mw1 Mw2 cw        W row
 *     [16..19] nx ny base0 base1     fine grid, index of its first fine and first coarse cell
 *     [20..23] dx0 dx1 dy0 dy1       the view's domain in fine cells
 *     [24..25] nx1 ny1               coarse grid (LS_COARSE x LS_COARSE fine cells per coarse cell)
 * A point v (relative to the scene's local origin) has homogeneous cell coordinates
 *     d = v - e,   X = Mx.d + cx,   Y = My.d + cy,   W = Mw.d + cw,
 * and lies in fine cell (i, j) = (floor(X/W), floor(Y/W)) of the view's nx x ny grid (numbered from
 * base0) and in coarse cell (i >> LS_COARSE_SHIFT, j >> LS_COARSE_SHIFT) of its nx1 x ny1 grid
 * (numbered from base1). Orthographic views have Mw = 0, cw = 1 (W = 1); perspective views have
 * e = the light and W = the distance along the view axis.
 *
 * Two levels: a primitive with more candidate cells than a coarse cell holds (LS_COARSE^2: a ground
 * plane, a wall) is listed in the coarse grid only, so it costs a few entries instead of thousands; a
 * receiver walks the list of its fine cell and the list of its coarse cell.
 *
 * Border cells: the view's *domain* [dx0, dx1] x [dy0, dy1] (in cells) is the part of its plane the
 * view answers for: everything (+-SC_BIG) for a single view, the face's square for a cube face. The
 * outermost rows and columns of cells extend to the domain's edge, so a point projecting outside the
 * grid's window (but inside the domain) belongs to the nearest border cell, and a primitive projecting
 * there is listed in it: classification stays correct for any point the view covers.
 *
 * Key fact: every point of a receiver's segment to the light (its ray, for a directional light) has
 * the same (X/W, Y/W) as the receiver, so only primitives whose projection covers the receiver's cell
 * can block it, and the receiver needs only that cell's list.
 *
 * Build options:
 *   NVIEWS       1 (one view) or 6 (a cube of perspective views around a point light)
 *   PERSPECTIVE  0: orthographic; 1: perspective (primitives are clipped to W >= 0)
 */
#ifndef SHADOWCL_LIGHTSPACE_H
#define SHADOWCL_LIGHTSPACE_H

#include "vecmath.h"

#ifndef NVIEWS
#define NVIEWS 1
#endif
#ifndef PERSPECTIVE
#define PERSPECTIVE 0
#endif

#define VIEW_FLOATS 32
#define VIEW_NX(v) as_int((v)[16])
#define VIEW_NY(v) as_int((v)[17])
#define VIEW_BASE0(v) as_int((v)[18])
#define VIEW_BASE1(v) as_int((v)[19])
#define VIEW_NX1(v) as_int((v)[24])
#define VIEW_NY1(v) as_int((v)[25])
/* 8 x 8 fine cells per coarse cell. Against 16 x 16 (1.2 M receivers, with normals, ms, alternating
 * processes, medians of 5, two rounds): the build (ls_csr) default 5.4, 5.0 -> 2.8, 3.2, light_inside 3.3,
 * 3.7 -> 1.6, 1.4, ogre 24.8, 31.9 -> 19.5, 20.3 (no primitive listed fine has more candidate cells
 * than a count record's mask holds); the walk light_inside 38.9, 29.7 -> 24.0, 24.9, default 14.9, 14.5
 * -> 11.7, 11.7, ogre 32.7, 38.2 -> 34.4, 35.0; one-shot default 58.5, 61.4 -> 49.2, 49.9 ms. */
#define LS_COARSE_SHIFT 3
#define LS_COARSE (1 << LS_COARSE_SHIFT)
/* The coarse cell of fine cell (i, j) of view v */
#define LS_COARSE_OF(v, i, j) (VIEW_BASE1(v) + ((j) >> LS_COARSE_SHIFT) * VIEW_NX1(v) + ((i) >> LS_COARSE_SHIFT))

/* The view of a point: for the cube, the face of the dominant axis of (point - light), faces ordered
 * +x, -x, +y, -y, +z, -z. */
INLINE int ls_point_view(__constant const float *views, float px, float py, float pz)
{
#if NVIEWS == 6
    const float dx = px - views[0], dy = py - views[1], dz = pz - views[2];
    const float ax = SC_ABS(dx), ay = SC_ABS(dy), az = SC_ABS(dz);
    const int axis = (ax >= ay && ax >= az) ? 0 : ((ay >= az) ? 1 : 2);
    const float da = (axis == 0) ? dx : ((axis == 1) ? dy : dz);
    return 2 * axis + (da < 0.0f ? 1 : 0);
#else
    return 0;
#endif
}

/* A point's fine cell index (over all views) and, in *coarse, its coarse cell index; *w gets W (a
 * single perspective view cannot place a point with W <= 0: the caller must handle it). */
INLINE int ls_point_cells(__constant const float *views, float px, float py, float pz, float *w, int *coarse)
{
    __constant const float *v = views + VIEW_FLOATS * ls_point_view(views, px, py, pz);
    const float dx = px - v[0], dy = py - v[1], dz = pz - v[2];
    const float X = v[4] * dx + v[5] * dy + v[6] * dz + v[7];
    const float Y = v[8] * dx + v[9] * dy + v[10] * dz + v[11];
    const float W = v[12] * dx + v[13] * dy + v[14] * dz + v[15];
    const int nx = VIEW_NX(v), ny = VIEW_NY(v);
    *w = W;
    /* clamp in float first: any X/W, even inf or NaN, ends in a valid cell */
    const int i = (int)SC_MIN(SC_MAX(SC_FLOOR(X / W), 0.0f), (float)(nx - 1));
    const int j = (int)SC_MIN(SC_MAX(SC_FLOOR(Y / W), 0.0f), (float)(ny - 1));
    *coarse = LS_COARSE_OF(v, i, j);
    return VIEW_BASE0(v) + j * nx + i;
}

/* The coarse cell of fine cell `cell` (numbered over all views, as ls_point_cells gives it): its view is
 * the last whose fine cells start at or before it. */
INLINE int ls_coarse_cell(__constant const float *views, int cell)
{
    int k = 0;
    for (int m = 1; m < NVIEWS; ++m)
        k = (cell >= VIEW_BASE0(views + VIEW_FLOATS * m)) ? m : k;
    __constant const float *v = views + VIEW_FLOATS * k;
    const int k_cell = cell - VIEW_BASE0(v), j = k_cell / VIEW_NX(v), i = k_cell - j * VIEW_NX(v);
    return LS_COARSE_OF(v, i, j);
}

#endif
