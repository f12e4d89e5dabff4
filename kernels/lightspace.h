/* lightspace.h: the light's views and their grids of cells, shared by the list builder (lightspace.cl)
 * and every method that looks a receiver's cell up (exact.cl).
 *
 * A view is VIEW_FLOATS floats (built by host/shadowcl/lightspace.py; ints stored as their bits):
 *     [ 0.. 3] ex ey ez _            the anchor: the cube's eye (the light), else zero
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
 * W = the distance along the view axis, with e = the light for the cube's six and e = 0 for a single
 * view, whose eye (far, for a distant light) is in the constant column, rounded once from float64:
 * d = v - light in float32 would lose ulp(|light|) of every point (host/shadowcl/lightspace.py).
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
/* The coarse cell of fine cell (i, j) of a view whose coarse cells start at base1, nx1 of them a row
 * (ints or lanes of ints) */
#define LS_COARSE_OF(base1, nx1, i, j) ((base1) + ((j) >> LS_COARSE_SHIFT) * (nx1) + ((i) >> LS_COARSE_SHIFT))
/* Fine cell (i, j)'s bit in a coarse entry's mask of the fine cells it touches (lightspace.cl ls_fine_mask) */
#define LS_SUB_OF(i, j) (((i) & (LS_COARSE - 1)) | (((j) & (LS_COARSE - 1)) << LS_COARSE_SHIFT))

/* floor(q) clamped to [0, n - 1], for any q (inf and NaN included: NaN gives 0). Clamped first, then
 * truncated: the same integer as floor then clamp (q >= 0 there), without a floor per lane. */
INLINE lint ls_clamp_cell(lfloat q, lint n)
{
    const lfloat top = LANE_TO_FLOAT(n - 1);
    const lfloat low = (q > 0.0f) ? q : (lfloat)0.0f;
    return LANE_TO_INT((low < top) ? low : top);
}

/* The view of a point (or of the lanes' points: vecmath.h): for the cube, the face of the dominant axis
 * of (point - light), faces ordered +x, -x, +y, -y, +z, -z. */
INLINE lint ls_point_view(__constant const float *views, lfloat px, lfloat py, lfloat pz)
{
#if NVIEWS == 6
    const lfloat dx = px - views[0], dy = py - views[1], dz = pz - views[2];
    const lfloat ax = SC_LABS(dx), ay = SC_LABS(dy), az = SC_LABS(dz);
    const lint x_axis = (ax >= ay) & (ax >= az), y_axis = !x_axis & (ay >= az);
    const lint axis = x_axis ? (lint)0 : (y_axis ? (lint)1 : (lint)2);
    const lfloat da = x_axis ? dx : (y_axis ? dy : dz);
    return 2 * axis + ((da < 0.0f) ? (lint)1 : (lint)0);
#else
    return (lint)0;
#endif
}

/* A point's fine cell index (over all views) and, in *coarse, its coarse cell index, in *sub the fine
 * cell's bit in it (LS_SUB_OF); *w gets W (a
 * single perspective view cannot place a point with W <= 0: the caller must handle it). Written over
 * lanes (vecmath.h). A cube's lanes take their face's parameters by a chain of selects, not by a load at
 * an index per lane (PoCL's LLVM 14 scalarised a whole pass over such gathers: docs/exact-speed.md),
 * and only those a face's rows need: a face looking along axis a (fit_views) has its X row non-zero at
 * a and a + 1 only, its Y row at a and a + 2, its W row (+-1) at a, and no constant column, so
 * X = Mx[a] d[a] + Mx[a+1] d[a+1] is the whole row's sum to the bit (its other terms are zeros). */
INLINE lint ls_point_cells_sub(__constant const float *views, lfloat px, lfloat py, lfloat pz, lfloat *w, lint *coarse,
                                lint *sub)
{
    const lfloat dx = px - views[0], dy = py - views[1], dz = pz - views[2];    /* the anchor: one for all views */
    lint nx = (lint)VIEW_NX(views), ny = (lint)VIEW_NY(views), base0 = (lint)VIEW_BASE0(views);
    lint base1 = (lint)VIEW_BASE1(views), nx1 = (lint)VIEW_NX1(views);
#if NVIEWS == 6
    const lint view = ls_point_view(views, px, py, pz), axis = view >> 1;
    const lfloat da = (axis == 0) ? dx : ((axis == 1) ? dy : dz);
    const lfloat du = (axis == 0) ? dy : ((axis == 1) ? dz : dx);
    const lfloat dv = (axis == 0) ? dz : ((axis == 1) ? dx : dy);
    lfloat xa = (lfloat)views[4], xu = (lfloat)views[5], ya = (lfloat)views[8], yv = (lfloat)views[10];
    lfloat wa = (lfloat)views[12];
    for (int v = 1; v < 6; ++v) {
        __constant const float *p = views + VIEW_FLOATS * v;
        const int a = v >> 1;
        const lint here = view == v;
        xa = here ? (lfloat)p[4 + a] : xa; xu = here ? (lfloat)p[4 + (a + 1) % 3] : xu;
        ya = here ? (lfloat)p[8 + a] : ya; yv = here ? (lfloat)p[8 + (a + 2) % 3] : yv;
        wa = here ? (lfloat)p[12 + a] : wa;
        nx = here ? (lint)VIEW_NX(p) : nx; ny = here ? (lint)VIEW_NY(p) : ny;
        base0 = here ? (lint)VIEW_BASE0(p) : base0; base1 = here ? (lint)VIEW_BASE1(p) : base1;
        nx1 = here ? (lint)VIEW_NX1(p) : nx1;
    }
    const lfloat X = xa * da + xu * du, Y = ya * da + yv * dv, W = wa * da;
#else
    const lfloat X = views[4] * dx + views[5] * dy + views[6] * dz + views[7];
    const lfloat Y = views[8] * dx + views[9] * dy + views[10] * dz + views[11];
    const lfloat W = views[12] * dx + views[13] * dy + views[14] * dz + views[15];
#endif
    *w = W;
    const lint i = ls_clamp_cell(X / W, nx), j = ls_clamp_cell(Y / W, ny);
    *coarse = LS_COARSE_OF(base1, nx1, i, j);
    *sub = LS_SUB_OF(i, j);
    return base0 + j * nx + i;
}

/* ls_point_cells_sub without the fine cell's bit */
INLINE lint ls_point_cells(__constant const float *views, lfloat px, lfloat py, lfloat pz, lfloat *w, lint *coarse)
{
    lint sub;
    return ls_point_cells_sub(views, px, py, pz, w, coarse, &sub);
}

#endif
