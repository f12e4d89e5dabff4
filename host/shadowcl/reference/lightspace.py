"""Float64 reference of the light-space lists (kernels/lightspace.cl), written from the definitions.

Given the views (eye, axes right/up/forward, windows, domains) and ``nx[v]`` x ``ny[v]`` cells per view,
a primitive is listed in cell (i, j) of view v when the projection of its part in front of the view
(``W >= 0``) intersects the cell's rectangle ``[i - delta, i + 1 + delta] x [j - delta, j + 1 + delta]``
(closed; in cell units), where the outermost rows and columns reach the edge of the view's domain (the
whole plane for a single view, the face's square for a cube face). A point belongs to the view of its
dominant axis (cube) and to the cell of its projection, clamped to the grid. The coarse level has the
same definition with cells of ``coarse`` x ``coarse`` fine cells (``level=1``). The projection of a clipped
primitive is a convex polygon, unbounded when clipping put vertices on the light's plane (they become
directions); the test is the separating-axis test of two convex sets, in float64, with no tolerance
beyond ``delta``. This never calls the kernels' host code.
"""

from __future__ import annotations

import numpy as np

INF = np.inf


def view_matrix(eye, axes, window, nx, ny, perspective):
    """(3, 3) matrix M and (3,) offset c with (X, Y, W) = M (v - eye) + c for one view, float64."""
    right, up, forward = (np.asarray(a, dtype=np.float64) for a in axes)
    u0, u1, v0, v1 = window
    sx, sy = nx / (u1 - u0), ny / (v1 - v0)
    if perspective:
        return np.stack([sx * (right - u0 * forward), sy * (up - v0 * forward), forward]), np.zeros(3)
    return np.stack([sx * right, sy * up, np.zeros(3)]), np.array([-sx * u0, -sy * v0, 1.0])


def project(points, eye, axes, window, nx, ny, perspective):
    """Homogeneous cell coordinates (N, 3) of ``points`` in one view."""
    M, c = view_matrix(eye, axes, window, nx, ny, perspective)
    return (np.asarray(points, dtype=np.float64) - (eye if perspective else 0.0)) @ M.T + c


def _bases(nx, ny):
    sizes = np.asarray(nx, dtype=np.int64) * np.asarray(ny, dtype=np.int64)
    return np.concatenate([[0], np.cumsum(sizes)[:-1]]), int(sizes.sum())


def point_cells(points, kind, eye, axes, windows, nx, ny):
    """Cell index (over all views) and W of each point; cube faces by the dominant axis of ``p - eye``."""
    points = np.asarray(points, dtype=np.float64)
    perspective = kind != "orthographic"
    base, _ = _bases(nx, ny)
    if kind == "cube":
        d = points - eye
        axis = np.argmax(np.abs(d), axis=1)
        face = 2 * axis + (d[np.arange(len(d)), axis] < 0)
    else:
        face = np.zeros(len(points), dtype=np.int64)
    cells = np.zeros(len(points), dtype=np.int64)
    ws = np.zeros(len(points))
    for f in np.unique(face):
        sel = face == f
        H = project(points[sel], eye, axes[f], windows[f], nx[f], ny[f], perspective)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.nan_to_num(np.floor(H[:, 0] / H[:, 2]), nan=0.0, posinf=nx[f], neginf=-1)
            y = np.nan_to_num(np.floor(H[:, 1] / H[:, 2]), nan=0.0, posinf=ny[f], neginf=-1)
        i = np.clip(x, 0, nx[f] - 1).astype(np.int64)
        j = np.clip(y, 0, ny[f] - 1).astype(np.int64)
        cells[sel] = base[f] + j * nx[f] + i
        ws[sel] = H[:, 2]
    return cells, ws


def clip_front(H):
    """Clip a homogeneous polygon (K, 3) to W >= 0; new vertices get W = 0 exactly."""
    out = []
    K = len(H)
    for k in range(K):
        a, b = H[k], H[(k + 1) % K]
        if a[2] >= 0:
            out.append(a)
        if (a[2] > 0 and b[2] < 0) or (a[2] < 0 and b[2] > 0):
            t = a[2] / (a[2] - b[2])
            p = a + t * (b - a)
            p[2] = 0.0
            out.append(p)
    return np.array(out).reshape(-1, 3)


def _range(g, a, lo, hi):
    """Min and max of g * (q - a) over q in [lo, hi] (arrays over cells; lo/hi may be infinite)."""
    if g == 0:
        return np.zeros_like(lo), np.zeros_like(lo)
    t0, t1 = g * (lo - a), g * (hi - a)
    return np.minimum(t0, t1), np.maximum(t0, t1)


def domain_cells(window, domain, nx, ny):
    """A view's domain (u0, u1, v0, v1 in projected units, maybe infinite) in its cell units."""
    u0, u1, v0, v1 = window
    sx, sy = nx / (u1 - u0), ny / (v1 - v0)
    du0, du1, dv0, dv1 = domain
    return (du0 - u0) * sx, (du1 - u0) * sx, (dv0 - v0) * sy, (dv1 - v0) * sy


def polygon_cells(H, nx, ny, domain, delta, scale=1):
    """Cells (i, j) of one view touched by the front part of homogeneous polygon H (K, 3).

    H is in fine-cell units; the cells are ``scale`` x ``scale`` fine cells (a grid of
    ceil(nx / scale) x ceil(ny / scale)); ``domain`` is (x0, x1, y0, y1) in fine cells: the border
    cells extend to it.
    """
    empty = np.zeros((0, 2), dtype=np.int64)
    C = clip_front(H)
    if len(C) == 0 or not np.any(C[:, 2] > 0):
        return empty
    finite = C[:, 2] > 0
    pts = np.zeros((len(C), 2))
    pts[finite] = C[finite, :2] / C[finite, 2:3]
    dirs = C[:, :2].copy()
    dx0, dx1, dy0, dy1 = domain
    mx, my = (nx - 1) // scale + 1, (ny - 1) // scale + 1
    if np.any(~finite & ~np.any(dirs != 0, axis=1)):            # touches the light: everywhere
        lo, hi = np.array([-INF, -INF]), np.array([INF, INF])
        everywhere = True
    else:
        everywhere = False
        lo = pts[finite].min(axis=0)
        hi = pts[finite].max(axis=0)
        for d in dirs[~finite]:
            lo = np.where(d < 0, -INF, lo)
            hi = np.where(d > 0, INF, hi)
    # the polygon's bounding box, enlarged, against the domain and the grid
    blo = np.maximum(lo - delta, [dx0 - delta, dy0 - delta])
    bhi = np.minimum(hi + delta, [dx1 + delta, dy1 + delta])
    if np.any(blo > bhi):
        return empty
    i0, j0 = np.clip(np.floor(blo / scale), 0, [mx - 1, my - 1]).astype(np.int64)
    i1, j1 = np.clip(np.floor(bhi / scale), 0, [mx - 1, my - 1]).astype(np.int64)
    ii, jj = np.meshgrid(np.arange(i0, i1 + 1), np.arange(j0, j1 + 1))
    ii, jj = ii.ravel(), jj.ravel()
    if everywhere:
        return np.stack([ii, jj], axis=1)
    lx = np.where(ii == 0, dx0, ii * scale) - delta
    hx = np.where(ii == mx - 1, dx1, (ii + 1) * scale) + delta
    ly = np.where(jj == 0, dy0, jj * scale) - delta
    hy = np.where(jj == my - 1, dy1, (jj + 1) * scale) + delta
    keep = np.ones(len(ii), dtype=bool)
    n = len(C)
    for k in range(n):
        a, b = k, (k + 1) % n
        if not finite[a] and not finite[b]:
            continue
        if finite[a] and finite[b]:
            anchor, e = pts[a], pts[b] - pts[a]
        elif finite[a]:
            anchor, e = pts[a], dirs[b]
        else:
            anchor, e = pts[b], -dirs[a]
        if not np.any(e != 0):
            continue
        g = np.array([-e[1], e[0]]) / np.hypot(*e)
        others = [m for m in range(n) if m not in (a, b)]
        vals = np.array([g @ (pts[m] - anchor) if finite[m] else g @ dirs[m] for m in others])
        scale = 1e-12 * (1 + np.abs(anchor).max())
        # a finite vertex on the line may lie on either side (the polygon is thin there: both sides); a
        # direction along it leads to a side its sign cannot tell, without bound (neither side)
        direction = np.array([not finite[m] for m in others], dtype=bool)
        pos = np.all(np.where(direction, vals > scale, vals >= -scale))
        neg = np.all(np.where(direction, vals < -scale, vals <= scale))
        mnx, mxx = _range(g[0], anchor[0], lx, hx)
        mny, mxy = _range(g[1], anchor[1], ly, hy)
        with np.errstate(invalid="ignore"):
            separated = (pos & (mxx + mxy < 0)) | (neg & (mnx + mny > 0))
        keep &= ~separated
    return np.stack([ii[keep], jj[keep]], axis=1)


def cell_lists(corners, kind, eye, axes, windows, domains, nx, ny, delta, level=0, coarse=16):
    """Dense (cells, P) bool: primitive p ((P, K, 3) corners, relative frame) listed in cell c.

    ``level=0``: the fine cells of all views (numbered view by view); ``level=1``: the coarse cells
    (``coarse`` x ``coarse`` fine cells each), numbered the same way from 0.
    """
    corners = np.asarray(corners, dtype=np.float64)
    perspective = kind != "orthographic"
    scale = coarse if level else 1
    mx = (np.asarray(nx) - 1) // scale + 1
    my = (np.asarray(ny) - 1) // scale + 1
    base, total = _bases(mx, my)
    listed = np.zeros((total, len(corners)), dtype=bool)
    for view in range(len(axes)):
        domain = domain_cells(windows[view], domains[view], nx[view], ny[view])
        for p, prim in enumerate(corners):
            H = project(prim, eye, axes[view], windows[view], nx[view], ny[view], perspective)
            ij = polygon_cells(H, nx[view], ny[view], domain, delta, scale)
            listed[base[view] + ij[:, 1] * mx[view] + ij[:, 0], p] = True
    return listed
