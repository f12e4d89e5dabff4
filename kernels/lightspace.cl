/* lightspace.cl: per-cell lists of primitives binned by their projection onto the light's view(s).
 *
 * Generic over primitives: a primitive is CORNERS corners (3: triangles, 4: planar convex quads),
 * stored as CORNERS*3 floats, relative to the scene's local origin. Views and cells: lightspace.h.
 *
 * Conservative listing. A primitive is listed in cell (i, j) of a view when the projection of its part
 * in front of the view (W >= 0) comes within DELTA cells of the cell's rectangle (border rectangles
 * extend to the view's domain: lightspace.h). The test is the separating-axis test of two convex
 * polygons: the cell axes through the primitive's bounding box, then every edge of the projected
 * polygon (for interior cells from precomputed edge functions: 2 multiply-adds per edge). Rounding is
 * covered by DELTA plus a relative tolerance per edge (LS_REL_TOL times the magnitudes involved), so
 * the float32 lists contain every cell the exact projection touches. Parts behind the light (W < 0)
 * cannot block a receiver in front of it: its segment to the light lies in W >= 0.
 *
 * Clipping at W >= 0 can create vertices on the light's plane (W = 0): they are points at infinity,
 * kept as directions. The polygon is then unbounded and reaches the border cells, where it is listed.
 *
 * Level: the candidate cells (the padded bounding box, clamped to the grid) decide it: more of them
 * than a coarse cell holds (LS_COARSE^2) puts the primitive in the coarse grid (lightspace.h).
 *
 * Build options: CORNERS, NVIEWS, PERSPECTIVE (lightspace.h).
 * Lists: CSR (ls_csr's count, which also records each primitive's cells as a bit mask, lists.h's scan, then
 * ls_csr's fill, which replays the masks instead of projecting again) or linked (ls_fill_linked).
 */
#include "lightspace.h"
#include "lists.h"        /* scan_blocks */

#ifndef CORNERS
#define CORNERS 3
#endif

#define MAXV (CORNERS + 1)            /* clipping one plane adds at most one vertex */
#define LS_DELTA (1.0f / 64.0f)       /* cell enlargement, in fine cells (host: lightspace.DELTA) */
#define LS_REL_TOL 1.0e-5f            /* ~170 float32 ulps: relative rounding allowance */
#define LS_DIR_W 1.0e-30f             /* W below this fraction of |(X, Y)| counts as a direction */
#define LS_MASK_CELLS 64              /* cells a count record can hold as a bit mask */

typedef struct {
    int nv;                                 /* polygon vertices */
    int ne;                                 /* edges kept for the separating-axis test */
    int all;                                /* 1: the primitive passes through the light: list everywhere */
    int shift;                              /* level: 0 fine, LS_COARSE_SHIFT coarse */
    int nx, ny, base;                       /* the level's grid in this view */
    int i0, i1, j0, j1;                     /* candidate fine cells, inclusive */
    float bx0, bx1, by0, by1;               /* bounding box padded by the tolerance, cut to the domain */
    float x[MAXV], y[MAXV];                 /* finite vertex (fine cells) or unit direction */
    int dir[MAXV];                          /* 1: a direction (a point on the light's plane) */
    float err[MAXV];                        /* magnitude that scales the rounding of x, y */
    float ax[MAXV], ay[MAXV];               /* edge anchor (finite vertex) */
    float gx[MAXV], gy[MAXV];               /* unit edge normal */
    float tol[MAXV];                        /* distance tolerance (fine cells) */
    float angtol[MAXV];                     /* |g| component below which an infinite side is ambiguous */
    int pos[MAXV], neg[MAXV];               /* polygon lies on the g >= 0 / g <= 0 side (0, 0: unused) */
    float c0[MAXV], di[MAXV], dj[MAXV];     /* g.(centre - a) at the first candidate cell, per-cell steps */
    float rad[MAXV];                        /* max of |g.(q - centre)| over a cell (enlarged by DELTA) */
} Poly;

/* Project primitive p on view v and prepare its separating-axis data. Returns 0 when nothing of the
 * primitive is in front of the view or its projection misses a bounded grid. NOINLINE: most of a list
 * kernel's code, compiled once instead of in each of PoCL's copies of the kernel (vecmath.h), for a call
 * per primitive and view (measured: as fast as inline; the kernels' whole bodies out of line were
 * 11-19% slower on bunny's lists). */
NOINLINE int ls_project(__global const float *prims, int p, __constant const float *v, Poly *P)
{
    const int nx = VIEW_NX(v), ny = VIEW_NY(v);
    float hx[CORNERS], hy[CORNERS], hw[CORNERS];
    /* Homogeneous cell coordinates of the corners */
    for (int k = 0; k < CORNERS; ++k) {
        const int b = (p * CORNERS + k) * 3;
        const float dx = prims[b] - v[0], dy = prims[b + 1] - v[1], dz = prims[b + 2] - v[2];
        hx[k] = v[4] * dx + v[5] * dy + v[6] * dz + v[7];
        hy[k] = v[8] * dx + v[9] * dy + v[10] * dz + v[11];
#if PERSPECTIVE
        hw[k] = v[12] * dx + v[13] * dy + v[14] * dz + v[15];
#else
        hw[k] = 1.0f;
#endif
    }

    /* Early out: every corner beyond the same side of the view's frustum (W >= 0, and the domain
     * dx0 W <= X <= dx1 W, dy0 W <= Y <= dy1 W where it is finite) means no part of it is seen */
    {
        int behind = 1, left = 1, right = 1, below = 1, above = 1;
        for (int k = 0; k < CORNERS; ++k) {
            behind &= hw[k] < 0.0f;
            left &= hx[k] < v[20] * hw[k];
            right &= hx[k] > v[21] * hw[k];
            below &= hy[k] < v[22] * hw[k];
            above &= hy[k] > v[23] * hw[k];
        }
        if (behind || ((left || right || below || above) && v[21] < 0.5f * SC_BIG))
            return 0;
    }

    /* Clip to W >= 0 (Sutherland-Hodgman, one plane); new vertices get W = 0 exactly */
    float cx[MAXV], cy[MAXV], cw[MAXV], cerr[MAXV];
    int n = 0, front = 0;
    for (int k = 0; k < CORNERS; ++k) {
        const int l = (k + 1 == CORNERS) ? 0 : k + 1;
        if (hw[k] >= 0.0f) {
            cx[n] = hx[k]; cy[n] = hy[k]; cw[n] = hw[k];
            cerr[n] = SC_ABS(hx[k]) + SC_ABS(hy[k]) + SC_ABS(hw[k]);
            front |= hw[k] > 0.0f;
            ++n;
        }
        if ((hw[k] > 0.0f && hw[l] < 0.0f) || (hw[k] < 0.0f && hw[l] > 0.0f)) {
            const float t = hw[k] / (hw[k] - hw[l]);
            cx[n] = hx[k] + t * (hx[l] - hx[k]);
            cy[n] = hy[k] + t * (hy[l] - hy[k]);
            cw[n] = 0.0f;
            cerr[n] = SC_ABS(hx[k]) + SC_ABS(hy[k]) + SC_ABS(hx[l]) + SC_ABS(hy[l]) + SC_ABS(hw[k]) + SC_ABS(hw[l]);
            ++n;
        }
    }
    if (!front)
        return 0;
    P->nv = n;
    P->all = 0;

    /* Finite vertices in cells, points on the light's plane as unit directions; bounding box */
    float bx0 = SC_BIG, bx1 = -SC_BIG, by0 = SC_BIG, by1 = -SC_BIG, mag = (float)(nx + ny);
    for (int k = 0; k < n; ++k) {
        const float a = SC_MAX(SC_ABS(cx[k]), SC_ABS(cy[k]));
        if (cw[k] > LS_DIR_W * a) {
            const float r = 1.0f / cw[k];
            const float x = cx[k] * r, y = cy[k] * r;
            P->x[k] = x; P->y[k] = y; P->dir[k] = 0;
            P->err[k] = SC_MAX(SC_ABS(x), SC_ABS(y));
            mag = SC_MAX(mag, P->err[k]);
            bx0 = SC_MIN(bx0, x); bx1 = SC_MAX(bx1, x);
            by0 = SC_MIN(by0, y); by1 = SC_MAX(by1, y);
        } else {
            if (a == 0.0f) {          /* the primitive touches the light itself */
                P->all = 1;
                P->x[k] = 0.0f; P->y[k] = 0.0f; P->dir[k] = 1; P->err[k] = 0.0f;
                continue;
            }
            const float x = cx[k] / a, y = cy[k] / a;   /* max-norm 1 */
            const float len = SC_SQRT(x * x + y * y);
            P->x[k] = x / len; P->y[k] = y / len; P->dir[k] = 1;
            P->err[k] = cerr[k] / a;                      /* relative error of the direction */
            if (x > 0.0f) bx1 = SC_BIG;
            if (x < 0.0f) bx0 = -SC_BIG;
            if (y > 0.0f) by1 = SC_BIG;
            if (y < 0.0f) by0 = -SC_BIG;
        }
    }

    /* Candidate cells: the bounding box enlarged by the tolerance, cut to the domain, clamped to the grid */
    const float pad = LS_DELTA + LS_REL_TOL * mag;
    bx0 = SC_MAX(bx0 - pad, v[20]); bx1 = SC_MIN(bx1 + pad, v[21]);
    by0 = SC_MAX(by0 - pad, v[22]); by1 = SC_MIN(by1 + pad, v[23]);
    if (P->all) {
        bx0 = v[20]; bx1 = v[21]; by0 = v[22]; by1 = v[23];
    }
    if (!(bx0 <= bx1 && by0 <= by1))
        return 0;                                   /* outside the domain this view answers for */
    P->bx0 = bx0; P->bx1 = bx1; P->by0 = by0; P->by1 = by1;
    P->i0 = (int)SC_MIN(SC_MAX(SC_FLOOR(bx0), 0.0f), (float)(nx - 1));
    P->i1 = (int)SC_MIN(SC_MAX(SC_FLOOR(bx1), 0.0f), (float)(nx - 1));
    P->j0 = (int)SC_MIN(SC_MAX(SC_FLOOR(by0), 0.0f), (float)(ny - 1));
    P->j1 = (int)SC_MIN(SC_MAX(SC_FLOOR(by1), 0.0f), (float)(ny - 1));
    /* Edge slots k = 0..MAXV-1 follow the vertices; unused slots never separate */
    P->ne = MAXV;
    for (int k = 0; k < MAXV; ++k) {
        P->pos[k] = 0; P->neg[k] = 0;
        P->ax[k] = 0.0f; P->ay[k] = 0.0f; P->gx[k] = 0.0f; P->gy[k] = 0.0f;
        P->tol[k] = 0.0f; P->angtol[k] = 0.0f;
        P->c0[k] = 0.0f; P->di[k] = 0.0f; P->dj[k] = 0.0f; P->rad[k] = 0.0f;
    }
    /* Level: fine cells, or coarse cells for a primitive whose candidate cells outnumber a coarse cell's:
     * a coarse entry is walked by the receivers of LS_COARSE^2 fine cells, so a thin primitive (a
     * pillar's face: 2 x 40 cells) costs less in its own cells than in its coarse cells' lists. Measured
     * against "more than LS_COARSE on either axis" (LS_COARSE 16, 1.2 M receivers, walk ms, interleaved
     * medians of 9, with / without normals): light_inside 43.2 -> 32.3 / 84.9 -> 71.8, default 13.8 ->
     * 12.9 / 36.8 -> 33.9, bunny 41.3 -> 43.7 / 51.2 -> 49.7, ogre 43.9 -> 42.8 / 83.2 -> 80.8; the build
     * within noise. LS_COARSE 8 (lightspace.h) keeps every fine primitive within a count record's mask
     * (LS_MASK_CELLS: the fill replays it instead of projecting again). */
    P->shift = ((P->i1 - P->i0 + 1) * (P->j1 - P->j0 + 1) > LS_COARSE * LS_COARSE || P->all) ? LS_COARSE_SHIFT : 0;
    P->nx = P->shift ? VIEW_NX1(v) : nx;
    P->ny = P->shift ? VIEW_NY1(v) : ny;
    P->base = P->shift ? VIEW_BASE1(v) : VIEW_BASE0(v);
    if (P->all || (P->i0 == P->i1 && P->j0 == P->j1))
        return 1;                                   /* one candidate cell: the box test decided */

    /* Edges: anchor at a finite end (the smaller one), unit normal, side of the polygon, tolerance */
    for (int k = 0; k < n; ++k) {
        const int a = k, b = (k + 1 == n) ? 0 : k + 1;
        if (P->dir[a] && P->dir[b])
            continue;                               /* an edge at infinity bounds nothing */
        float ex, ey, px, py, angle_err, anchor_err;
        if (!P->dir[a] && !P->dir[b]) {
            const int s = (P->err[a] <= P->err[b]) ? a : b;
            px = P->x[s]; py = P->y[s];
            ex = P->x[b] - P->x[a]; ey = P->y[b] - P->y[a];
            anchor_err = P->err[s];
            const float len = SC_SQRT(ex * ex + ey * ey);
            if (!(len > 0.0f))
                continue;                           /* coincident vertices: no axis */
            angle_err = (P->err[a] + P->err[b] + (float)(nx + ny)) / len;
        } else {
            const int f = P->dir[a] ? b : a, d = P->dir[a] ? a : b;
            px = P->x[f]; py = P->y[f];
            ex = P->dir[a] ? -P->x[d] : P->x[d];
            ey = P->dir[a] ? -P->y[d] : P->y[d];
            anchor_err = P->err[f];
            angle_err = P->err[d] + 1.0f;
        }
        const float len = SC_SQRT(ex * ex + ey * ey);
        const float gx = -ey / len, gy = ex / len;
        /* farthest finite point of the candidate cells (extended to the domain) from the anchor */
        const float qx0 = (P->i0 == 0) ? SC_MAX(bx0, -mag) : (float)P->i0;
        const float qx1 = (P->i1 == nx - 1) ? SC_MIN(bx1, mag) : (float)(P->i1 + 1);
        const float qy0 = (P->j0 == 0) ? SC_MAX(by0, -mag) : (float)P->j0;
        const float qy1 = (P->j1 == ny - 1) ? SC_MIN(by1, mag) : (float)(P->j1 + 1);
        const float dist_from = SC_MAX(SC_ABS(px - qx0), SC_ABS(px - qx1)) + SC_MAX(SC_ABS(py - qy0), SC_ABS(py - qy1));
        const float tol = LS_DELTA + LS_REL_TOL * (anchor_err + (float)(nx + ny) + angle_err * (dist_from + 2.0f));
        /* Which side the rest of the polygon is on (directions: the side they lead to). A finite vertex
         * within the rounding of the edge's line may be on either side: the polygon then lies within the
         * tolerance of that line there, and both sides are claimed (a thin polygon: a slab). A direction
         * within its rounding may not be: the polygon goes without bound to a side the sign cannot
         * tell, so it claims neither, and the edge separates nothing. (Claiming both had turned the
         * half-plane seen from a light 1e-6 off a triangle's plane into a slab along its front edge,
         * dropping most of its cells: docs/known-defects.md.) */
        int pos = 1, neg = 1;
        for (int m = 0; m < n; ++m) {
            if (m == a || m == b)
                continue;
            if (P->dir[m]) {
                const float f = gx * P->x[m] + gy * P->y[m];
                const float t = LS_REL_TOL * (angle_err + P->err[m]);
                pos &= f > t;
                neg &= f < -t;
            } else {
                const float rx = P->x[m] - px, ry = P->y[m] - py;
                const float f = gx * rx + gy * ry;
                const float t = LS_DELTA + LS_REL_TOL * (anchor_err + P->err[m] + (float)(nx + ny)
                                                         + angle_err * (SC_ABS(rx) + SC_ABS(ry)));
                pos &= f >= -t;
                neg &= f <= t;
            }
        }
        const int e = k;
        P->ax[e] = px; P->ay[e] = py; P->gx[e] = gx; P->gy[e] = gy;
        P->tol[e] = tol;
        P->angtol[e] = LS_REL_TOL * angle_err;
        P->pos[e] = pos; P->neg[e] = neg;
        /* Interior cells: the edge function at the centre of the first candidate cell, its steps */
        const float cs = (float)(1 << P->shift);
        P->c0[e] = gx * (((float)(P->i0 >> P->shift) + 0.5f) * cs - px) + gy * (((float)(P->j0 >> P->shift) + 0.5f) * cs - py);
        P->di[e] = gx * cs;
        P->dj[e] = gy * cs;
        P->rad[e] = (SC_ABS(gx) + SC_ABS(gy)) * (0.5f * cs + LS_DELTA);
    }
    return 1;
}

/* The candidate cells of P at its level */
INLINE void ls_level_range(const Poly *P, int *i0, int *i1, int *j0, int *j1)
{
    *i0 = P->i0 >> P->shift; *i1 = P->i1 >> P->shift;
    *j0 = P->j0 >> P->shift; *j1 = P->j1 >> P->shift;
}

/* Range of g * (q - a) over q in [lo, hi]; an infinite side with an ambiguous sign of g spans all. */
INLINE void ls_range(float g, float a, float lo, float hi, int inf_lo, int inf_hi, float angtol, float *mn, float *mx)
{
    const float t0 = g * (lo - a), t1 = g * (hi - a);
    *mn = SC_MIN(t0, t1);
    *mx = SC_MAX(t0, t1);
    if ((inf_lo | inf_hi) && SC_ABS(g) <= angtol) {
        *mn = -SC_BIG;
        *mx = SC_BIG;
    }
}

/* ls_overlaps for a cell on the border of its grid (NOINLINE: the rarer case, out of the kernels' loops) */
NOINLINE int ls_overlaps_border(const Poly *P, int i, int j, __constant const float *v)
{
    const float s = (float)(1 << P->shift);
    const float lx = SC_MAX((i == 0) ? v[20] : (float)i * s - LS_DELTA, P->bx0);
    const float hx = SC_MIN((i == P->nx - 1) ? v[21] : (float)(i + 1) * s + LS_DELTA, P->bx1);
    const float ly = SC_MAX((j == 0) ? v[22] : (float)j * s - LS_DELTA, P->by0);
    const float hy = SC_MIN((j == P->ny - 1) ? v[23] : (float)(j + 1) * s + LS_DELTA, P->by1);
    const int ilx = lx <= -0.5f * SC_BIG, ihx = hx >= 0.5f * SC_BIG;
    const int ily = ly <= -0.5f * SC_BIG, ihy = hy >= 0.5f * SC_BIG;
    int separated = 0;
    for (int e = 0; e < MAXV; ++e) {
        float mnx, mxx, mny, mxy;
        ls_range(P->gx[e], P->ax[e], lx, hx, ilx, ihx, P->angtol[e], &mnx, &mxx);
        ls_range(P->gy[e], P->ay[e], ly, hy, ily, ihy, P->angtol[e], &mny, &mxy);
        const float fmn = mnx + mny, fmx = mxx + mxy;
        separated |= (P->pos[e] & (fmx < -P->tol[e])) | (P->neg[e] & (fmn > P->tol[e]));
    }
    return !separated;
}

/* Does the polygon come within the tolerance of cell (i, j) of its level? The cell's rectangle (in fine
 * units) is enlarged by DELTA, extended to the domain on the border, and cut to the polygon's padded
 * bounding box (which changes nothing: the polygon lies inside it). Sides beyond SC_BIG / 2 are infinite.
 * Interior cells use the precomputed edge functions: 2 multiply-adds and a compare per edge. */
INLINE int ls_overlaps(const Poly *P, int i, int j, int ci0, int cj0, __constant const float *v)
{
    if (!(i > 0 && j > 0 && i < P->nx - 1 && j < P->ny - 1))
        return ls_overlaps_border(P, i, j, v);
    const float fi = (float)(i - ci0), fj = (float)(j - cj0);
    int separated = 0;
    for (int e = 0; e < MAXV; ++e) {
        const float f = P->c0[e] + fi * P->di[e] + fj * P->dj[e];
        separated |= (P->pos[e] & (f + P->rad[e] < -P->tol[e])) | (P->neg[e] & (f - P->rad[e] > P->tol[e]));
    }
    return !separated;
}

/* The fine cells of coarse cell (ci, cj) that coarse primitive P comes within the tolerance of, as bits
 * LS_SUB_OF(i, j): the fine level's own test (ls_overlaps' edge functions, at each fine cell's centre)
 * for the interior fine cells of P's candidate box, every fine cell on the grid's border (their test
 * needs the domain: kept, which is conservative), none outside the candidate box. A row of 8 fine cells
 * at a time, in a float8 (against one cell at a time, the default scene's ls_csr 5.4 -> 4.3 ms). The walk
 * skips a coarse entry for a packet none of whose fine cells it sets: a wall listed in a light's coarse
 * cells is then tested only by the packets under it. */
#if LS_COARSE != 8
#error "ls_fine_mask takes a coarse cell's row of fine cells as a float8"
#endif
INLINE ulong ls_fine_mask(const Poly *P, int ci, int cj, __constant const float *v)
{
    if (P->all)
        return ~(ulong)0;
    const int nx = VIEW_NX(v), ny = VIEW_NY(v);
    const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
    const int8 i = (ci << LS_COARSE_SHIFT) + lane;
    const float8 x = convert_float8(i) + 0.5f;
    const int8 in_box = (i >= P->i0) & (i <= P->i1);
    const int8 border = (i == 0) | (i == nx - 1);
    ulong mask = 0;
    for (int row = 0; row < LS_COARSE; ++row) {
        const int j = (cj << LS_COARSE_SHIFT) + row;
        if (j < P->j0 || j > P->j1)
            continue;
        const float y = (float)j + 0.5f;
        int8 separated = (int8)0;
        for (int e = 0; e < MAXV; ++e) {
            const float8 f = P->gx[e] * (x - P->ax[e]) + P->gy[e] * (y - P->ay[e]);
            const float rad = (SC_ABS(P->gx[e]) + SC_ABS(P->gy[e])) * (0.5f + LS_DELTA);
            separated |= ((f + rad < -P->tol[e]) & (int8)(-P->pos[e])) | ((f - rad > P->tol[e]) & (int8)(-P->neg[e]));
        }
        const int8 kept = in_box & (((j == 0) | (j == ny - 1)) ? (int8)(-1) : (border | ~separated));
        const int8 bits = kept & (int8)(1, 2, 4, 8, 16, 32, 64, 128);
        const int4 four = bits.lo | bits.hi;
        const int2 two = four.lo | four.hi;
        mask |= (ulong)(uint)(two.x | two.y) << (LS_COARSE * row);
    }
    return mask;
}

/* Walk every cell a primitive is listed in; BODY sees `view`, `cell` (index over all views and levels)
 * and the level's candidate range (ci0, ci1, cj0) with (i, j). */
#define LS_FOR_EACH_CELL(prims, p, views, ...)                                               \
    for (int view = 0; view < NVIEWS; ++view) {                                              \
        __constant const float *v_ = (views) + VIEW_FLOATS * view;                           \
        Poly P;                                                                              \
        if (!ls_project((prims), (p), v_, &P))                                               \
            continue;                                                                        \
        int ci0, ci1, cj0, cj1;                                                              \
        ls_level_range(&P, &ci0, &ci1, &cj0, &cj1);                                          \
        for (int j = cj0; j <= cj1; ++j)                                                     \
            for (int i = ci0; i <= ci1; ++i)                                                 \
                if (ls_overlaps(&P, i, j, ci0, cj0, v_)) {                                   \
                    const int cell = P.base + j * P.nx + i;                                  \
                    __VA_ARGS__                                                              \
                }                                                                            \
    }

/* The CSR lists' two passes in one kernel (one compile instead of two on PoCL, where each kernel's
 * first launch compiles it: the projection below is most of either pass's code). fill = 0 counts,
 * fill = 1 fills; between them the host takes the prefix sum of counts into offsets.
 *
 * Count: counts[cell] += 1 for every (primitive, cell) listing. counts: zeroed, one int per cell.
 * records[p] (int4) remembers the cells for the fill: (first cell, w | h << 8 | view << 16, mask low,
 * mask high) with bit (i - ci0) + (j - cj0) * w set for each listed cell, when the primitive is listed
 * in one view within w x h <= LS_MASK_CELLS candidate cells; x = -1 (fill recomputes) otherwise, and
 * x = -2 when it is listed nowhere.
 *
 * Fill: items[offsets[cell] + slot] = p, slot taken by decrementing counts[cell] (which the count
 * pass left at the cell's length, and which ends at zero, ready for the next count), replaying the
 * count's mask where it kept one. A listing past its cell's slots (a fill that disagrees with its
 * count: a bug) is not written but counted in *dropped, which the host checks. Order within a cell is
 * whatever the atomics give: the exact test does not depend on it.
 *
 * fine_masks (both passes; the buffer is the fill's): coarse entry k also gets its fine cells
 * (ls_fine_mask) in masks[k - offsets of the first coarse cell]; the count then keeps no record for a
 * primitive with coarse cells, so that the fill projects it again. */
INLINE int ls_put(int cell, int p, __global volatile int *counts, __global const int *offsets, __global int *items,
                  __global volatile int *dropped)
{
    const int slot = atomic_dec(counts + cell) - 1;
    if (slot < 0) {
        atomic_inc(dropped);
        return -1;
    }
    const int k = offsets[cell] + slot;
    items[k] = p;
    return k;
}
__kernel void ls_csr(__global const float *prims, int nprims, __constant const float *views,
                     __global volatile int *counts, __global int4 *records, int fill,
                     __global const int *offsets, __global int *items, __global volatile int *dropped,
                     int fine_masks, __global ulong *masks)
{
    const int p = get_global_id(0);
    if (p >= nprims)
        return;
    if (fill) {
        const int4 r = records[p];
        if (r.x == -2)
            return;
        if (r.x >= 0) {
            /* the count pass kept the cells: walk the mask */
            const int w = r.y & 255;
            __constant const float *v = views + VIEW_FLOATS * (r.y >> 16);
            const int row = (r.x >= VIEW_BASE1(v)) ? VIEW_NX1(v) : VIEW_NX(v);
            uint bits = (uint)r.z;
            for (int part = 0; part < 2; ++part) {
                while (bits) {
                    const int b = SC_CTZ(bits) + 32 * part;
                    bits &= bits - 1;
                    ls_put(r.x + (b % w) + (b / w) * row, p, counts, offsets, items, dropped);
                }
                bits = (uint)r.w;
            }
            return;
        }
    }
    int first = -2, shape = 0, seen_view = -1, coarse = 0;
    uint lo = 0, hi = 0;
    LS_FOR_EACH_CELL(prims, p, views, {
        if (fill) {
            const int k = ls_put(cell, p, counts, offsets, items, dropped);
            if (fine_masks && P.shift && k >= 0)
                masks[k - offsets[VIEW_BASE1(views)]] = ls_fine_mask(&P, i, j, v_);
        } else {
            coarse |= P.shift;
            atomic_inc(counts + cell);
            const int w = ci1 - ci0 + 1, h = cj1 - cj0 + 1;
            if (first == -2 || (first >= 0 && seen_view == view)) {
                if (w * h <= LS_MASK_CELLS) {
                    if (first == -2) {
                        first = P.base + cj0 * P.nx + ci0;
                        shape = w | (h << 8) | (view << 16);
                        seen_view = view;
                    }
                    const int bit = (i - ci0) + (j - cj0) * w;
                    if (bit < 32) lo |= 1u << bit; else hi |= 1u << (bit - 32);
                } else {
                    first = -1;
                }
            } else if (seen_view != view) {
                first = -1;
            }
        }
    })
    if (!fill)
        records[p] = (int4)((fine_masks && coarse && first != -2) ? -1 : first, shape, (int)lo, (int)hi);
}

/* Fill (linked lists): nodes from an atomic counter; node k is (primitive, next) in nodes[2k..2k+1]
 * and heads[cell] (initially -1) points at the newest node. A kernel that runs out of capacity keeps
 * counting and writes nothing: the host sees *counter > capacity, grows the buffer and reruns. */
__kernel void ls_fill_linked(__global const float *prims, int nprims, __constant const float *views,
                             __global volatile int *heads, __global int *nodes, int capacity,
                             __global volatile int *counter)
{
    const int p = get_global_id(0);
    if (p >= nprims)
        return;
    LS_FOR_EACH_CELL(prims, p, views, {
        const int node = atomic_inc(counter);
        if ((uint)node < (uint)capacity) {     /* unsigned: a counter wrapped past 2^31 never writes */
            nodes[2 * node] = p;
            nodes[2 * node + 1] = atomic_xchg(heads + cell, node);
        }
    })
}

/* Cells of each point (tests and tools): fine[i], coarse[i] cell indices; ws[i] = W (<= 0: behind a
 * single perspective view). */
__kernel void ls_points(__global const float *points, int n, __constant const float *views,
                        __global int *fine, __global int *coarse, __global float *ws)
{
    const int i = get_global_id(0);
    if (i >= n)
        return;
    float w;
    int c;
    fine[i] = ls_point_cells(views, points[3 * i], points[3 * i + 1], points[3 * i + 2], &w, &c);
    coarse[i] = c;
    ws[i] = w;
}

/* Footprint of the small primitives in each view, for fitting the windows. The views' grids here are
 * 1 x 1 over the receivers' windows, so cell coordinates are window-relative: [0, 1] spans the window.
 * A primitive counts in a view when all its corners are in front of it (and, for the cube, belong to
 * that face) and its projection is at most `small` wide and high and overlaps the window.
 * Work-item g reduces primitives [g * chunk, (g + 1) * chunk) serially into
 * out[(g * NVIEWS + v) * 5 + (min x, max x, min y, max y, count)] (no atomics, no local memory). */
NOINLINE void ls_footprint_item(int g, int start, int end, __global const float *prims,
                                __constant const float *views, float small, __global float *out)
{
    float lo_x[NVIEWS], hi_x[NVIEWS], lo_y[NVIEWS], hi_y[NVIEWS], count[NVIEWS];
    for (int v = 0; v < NVIEWS; ++v) {
        lo_x[v] = SC_BIG; hi_x[v] = -SC_BIG; lo_y[v] = SC_BIG; hi_y[v] = -SC_BIG; count[v] = 0.0f;
    }
    for (int p = start; p < end; ++p) {
        const int b = p * CORNERS * 3;
        const int view = ls_point_view(views, prims[b], prims[b + 1], prims[b + 2]);
        __constant const float *v = views + VIEW_FLOATS * view;
        float x0 = SC_BIG, x1 = -SC_BIG, y0 = SC_BIG, y1 = -SC_BIG;
        int ok = 1;
        for (int k = 0; k < CORNERS; ++k) {
            const float px = prims[b + 3 * k], py = prims[b + 3 * k + 1], pz = prims[b + 3 * k + 2];
            ok &= ls_point_view(views, px, py, pz) == view;
            const float dx = px - v[0], dy = py - v[1], dz = pz - v[2];
            const float X = v[4] * dx + v[5] * dy + v[6] * dz + v[7];
            const float Y = v[8] * dx + v[9] * dy + v[10] * dz + v[11];
            const float W = v[12] * dx + v[13] * dy + v[14] * dz + v[15];
            ok &= W > 1.0e-6f * (SC_ABS(dx) + SC_ABS(dy) + SC_ABS(dz));
            const float r = 1.0f / W;
            x0 = SC_MIN(x0, X * r); x1 = SC_MAX(x1, X * r);
            y0 = SC_MIN(y0, Y * r); y1 = SC_MAX(y1, Y * r);
        }
        ok &= (x1 - x0 <= small) & (y1 - y0 <= small) & (x1 >= 0.0f) & (x0 <= 1.0f) & (y1 >= 0.0f) & (y0 <= 1.0f);
        if (ok) {
            lo_x[view] = SC_MIN(lo_x[view], x0); hi_x[view] = SC_MAX(hi_x[view], x1);
            lo_y[view] = SC_MIN(lo_y[view], y0); hi_y[view] = SC_MAX(hi_y[view], y1);
            count[view] += 1.0f;
        }
    }
    for (int v = 0; v < NVIEWS; ++v) {
        __global float *o = out + (g * NVIEWS + v) * 5;
        o[0] = lo_x[v]; o[1] = hi_x[v]; o[2] = lo_y[v]; o[3] = hi_y[v]; o[4] = count[v];
    }
}

__kernel void ls_footprint(__global const float *prims, int nprims, __constant const float *views, float small,
                           int chunk, __global float *out)
{
    const int g = get_global_id(0);
    const int start = g * chunk;
    if (start < nprims)
        ls_footprint_item(g, start, min(nprims, start + chunk), prims, views, small, out);
}
