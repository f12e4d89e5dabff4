"""Reference rasterizer in NumPy float64: the oracle of ``tests/test_raster.py``.

This is an independent re-derivation of the raster contract stated in ``kernels/raster.cl`` and
``host/shadowcl/views.py``; it does not import or call the kernel's host code. The contract:

1. Clip each triangle (clip = matrix @ (relative position, 1)) by Sutherland-Hodgman against, in
   order, depth <= 1 (``z <= w``), depth >= 0 (``z >= 0``), and the guard band ``|x| <= gx w``,
   ``|y| <= gy w`` with ``gx = GUARD_PIXELS / (width / 2)`` (likewise ``gy``); corners on a plane
   are inside, and a cut edge gets its new corner interpolated from its inside end.
2. Snap every corner to fixed point: ``SUBPIXEL`` units per pixel, x right and y down from the
   top-left image corner, rounding half to even; its depth is ``z / w`` clamped to [0, 1]. A
   polygon with a corner at w <= 0 (possible only for a clip volume reaching w = 0) is dropped.
3. Draw the clipped polygon as the fan (0, k, k + 1). A pixel's sample is its centre; it is inside
   a triangle when it is inside after moving it by the infinitesimal (eps, eps^2) (right, then
   down). That is the top-left rule: a sample on an edge belongs to the triangle lying right of the
   edge, or below it when the edge is horizontal. Zero-area triangles draw nothing; both windings
   are drawn.
4. Depth is affine in screen space over each snapped triangle and does not depend on the order its
   corners are given in. The largest depth wins; equal depths go to the smallest triangle index.

Here the inside test is written as that perturbation (lexicographic signs), depth as a plane
gradient solved by Cramer's rule, and each triangle is evaluated vectorised over its bounding box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SUBPIXEL = 256
GUARD_PIXELS = 2**21


@dataclass(frozen=True, eq=False)
class Raster:
    """Reference Z-buffer. ``margin`` (H, W): how far (in depth) the runner-up fragment lies behind
    the visible one, 0 for exact ties, inf where one fragment or none was drawn. Where it is within
    float32 rounding, the kernel may legitimately pick the runner-up."""

    depth: np.ndarray  # (H, W) float64, 0 = empty
    triangle: np.ndarray  # (H, W) int64, -1 = empty
    margin: np.ndarray  # (H, W) float64


Polygon = tuple[np.ndarray, np.ndarray]  # (k, 2) int64 fixed-point corners, (k,) float64 depths


# Triangle setup -------------------------------------------------------------------------------


def clip_planes(width: int, height: int) -> np.ndarray:
    """(6, 4) planes p of the clip volume, inside where p . (x, y, z, w) >= 0, in clipping order."""
    gx, gy = GUARD_PIXELS / (width / 2), GUARD_PIXELS / (height / 2)
    return np.array([[0, 0, -1, 1], [0, 0, 1, 0], [-1, 0, 0, gx], [1, 0, 0, gx], [0, -1, 0, gy], [0, 1, 0, gy]], float)


def clip(corners: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman clipping of the (k, 4) homogeneous polygon ``corners``."""
    for plane in planes:
        if len(corners) == 0:
            break
        distance = corners @ plane
        kept = []
        for i in range(len(corners)):
            j = (i + 1) % len(corners)
            if distance[i] >= 0:
                kept.append(corners[i])
            if (distance[i] >= 0) != (distance[j] >= 0):
                inside, outside = (i, j) if distance[i] >= 0 else (j, i)
                t = distance[inside] / (distance[inside] - distance[outside])
                kept.append(corners[inside] + t * (corners[outside] - corners[inside]))
        corners = np.array(kept).reshape(-1, 4)
    return corners


def screen_polygons(vertices: np.ndarray, faces: np.ndarray, origin: np.ndarray, matrix: np.ndarray,
                    width: int, height: int) -> list[Polygon]:
    """Every triangle clipped and snapped; an empty polygon for triangles clipped away."""
    relative = np.asarray(vertices, dtype=np.float64) - origin
    clip_corners = np.concatenate([relative, np.ones((len(relative), 1))], axis=1) @ np.asarray(matrix, float).T
    planes = clip_planes(width, height)
    polygons = []
    for face in faces:
        corners = clip(clip_corners[face], planes)
        if np.any(corners[:, 3] <= 0):  # only a matrix whose clip volume reaches w = 0
            corners = corners[:0]
        ndc = corners[:, :3] / corners[:, 3:]
        xy = np.stack([(ndc[:, 0] + 1) * width / 2, (1 - ndc[:, 1]) * height / 2], axis=1)
        polygons.append((np.rint(xy * SUBPIXEL).astype(np.int64), np.clip(ndc[:, 2], 0.0, 1.0)))
    return polygons


# Rasterization --------------------------------------------------------------------------------


def _inside(p: np.ndarray, q: np.ndarray, sx: np.ndarray, sy: np.ndarray) -> np.ndarray:
    """Samples (sx, sy) inside edge p -> q of a positively ordered triangle (y down), moved by (eps, eps^2)."""
    ex, ey = q - p
    value = ex * (sy - p[1]) - ey * (sx - p[0])  # exact: int64
    slope_x, slope_y = -ey, ex  # d value / d sx, d value / d sy
    return (value > 0) | ((value == 0) & ((slope_x > 0) | ((slope_x == 0) & (slope_y > 0))))


def triangle_fragments(xy: np.ndarray, depth: np.ndarray, width: int, height: int):
    """Flat pixel indices drawn by the snapped triangle ``xy`` (3, 2) and their depths."""
    xy = np.asarray(xy, dtype=np.int64)  # products of coordinates need 64 bits
    order = np.lexsort((xy[:, 0], xy[:, 1]))  # the depth must not depend on the corner order
    (a, b, c), (za, zb, zc) = xy[order], np.asarray(depth, dtype=np.float64)[order]
    area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    if area == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    p, q, r = (a, b, c) if area > 0 else (a, c, b)  # positive order for the inside test
    centre_x = np.arange(width) * SUBPIXEL + SUBPIXEL // 2
    centre_y = np.arange(height) * SUBPIXEL + SUBPIXEL // 2
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    cols = np.flatnonzero((centre_x >= lo[0]) & (centre_x <= hi[0]))
    rows = np.flatnonzero((centre_y >= lo[1]) & (centre_y <= hi[1]))
    sx, sy = np.meshgrid(centre_x[cols], centre_y[rows])
    inside = _inside(p, q, sx, sy) & _inside(q, r, sx, sy) & _inside(r, p, sx, sy)
    # Depth = za + gradient . (s - a): the gradient solves gradient . (b - a) = zb - za and
    # gradient . (c - a) = zc - za (Cramer's rule; the determinant is the exact area).
    (ux, uy), (vx, vy), du, dv = b - a, c - a, zb - za, zc - za
    gradient_x, gradient_y = (du * vy - dv * uy) / area, (dv * ux - du * vx) / area
    depth_at = za + gradient_x * (sx[inside] - a[0]) + gradient_y * (sy[inside] - a[1])
    row_index, col_index = np.meshgrid(rows, cols, indexing="ij")
    return row_index[inside] * width + col_index[inside], depth_at


def fragments(polygons: list[Polygon], width: int, height: int):
    """Yield (triangle index, flat pixel indices, depths) for each fan triangle of each polygon."""
    for index, (xy, corner_depth) in enumerate(polygons):
        for k in range(1, len(xy) - 1):
            fan = [0, k, k + 1]
            yield (index, *triangle_fragments(xy[fan], corner_depth[fan], width, height))


def rasterize_polygons(polygons: list[Polygon], width: int, height: int) -> Raster:
    """Z-buffer of snapped polygons; polygon i is triangle i."""
    depth = np.zeros(width * height)
    runner_up = np.full(width * height, -np.inf)
    triangle = np.full(width * height, -1, dtype=np.int64)
    for index, pixels, fragment in fragments(polygons, width, height):
        current, drawn = depth[pixels], triangle[pixels] >= 0
        wins = ~drawn | (fragment > current)  # ascending ids: a tie keeps the smaller id
        runner_up[pixels] = np.where(wins, np.where(drawn, current, -np.inf), np.maximum(runner_up[pixels], fragment))
        depth[pixels] = np.where(wins, fragment, current)
        triangle[pixels] = np.where(wins, index, triangle[pixels])
    shape = (height, width)
    return Raster(depth.reshape(shape), triangle.reshape(shape), (depth - runner_up).reshape(shape))


def coverage_count_polygons(polygons: list[Polygon], width: int, height: int) -> np.ndarray:
    """(H, W) number of fragments per pixel."""
    count = np.zeros(width * height, dtype=np.int64)
    for _, pixels, _ in fragments(polygons, width, height):
        count[pixels] += 1
    return count.reshape(height, width)


def rasterize(mesh, view) -> Raster:
    """Reference Z-buffer of ``mesh`` seen by ``view``."""
    polygons = screen_polygons(mesh.vertices, mesh.faces, view.origin, view.matrix, view.width, view.height)
    return rasterize_polygons(polygons, view.width, view.height)


def coverage_count(mesh, view) -> np.ndarray:
    """Reference overdraw of ``mesh`` seen by ``view``."""
    polygons = screen_polygons(mesh.vertices, mesh.faces, view.origin, view.matrix, view.width, view.height)
    return coverage_count_polygons(polygons, view.width, view.height)


# Receivers ------------------------------------------------------------------------------------


def receivers(mesh, view, triangle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World points and viewer-facing normals of pixels with ``triangle >= 0``, row-major.

    A point is where the pixel centre's ray meets its triangle's plane, all in float64.
    """
    start, direction = view.pixel_rays()
    covered = triangle >= 0
    start, direction, ids = start[covered], direction[covered], triangle[covered]
    corner = mesh.vertices.astype(np.float64)[mesh.faces[ids, 0]] - view.origin
    normal = mesh.face_normals[ids]
    t = np.einsum("ij,ij->i", normal, corner - start) / np.einsum("ij,ij->i", normal, direction)
    facing = np.where(np.einsum("ij,ij->i", normal, direction) > 0, -1.0, 1.0)
    return view.origin + start + t[:, None] * direction, normal * facing[:, None]
