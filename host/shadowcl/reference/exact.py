"""Float64 brute-force reference of exact shadows: every receiver against every triangle, in chunks.

Meaning (DESIGN.md): a point is in shadow when the segment from ``s`` to a point light (the ray from
``s`` against a directional light's travel direction) hits a triangle at a distance greater than ``eps``
from ``s`` and strictly before the light; ``s = p + eps n`` with normals, else ``p``; a normal facing
away from the light (``n . (light - p) <= 0``) is in shadow.

The test is Möller & Trumbore's (1997) in float64 with **inclusive edges**: barycentric ``u >= 0``,
``v >= 0``, ``u + v <= 1``, so a segment through an edge or a vertex hits every triangle there
(conservative, the same tie rule as the watertight kernel); a zero determinant (segment parallel to
the triangle's plane, or a degenerate triangle) is no hit. The distance interval is open at both ends.
This module never calls the kernels' host code.
"""

from __future__ import annotations

import numpy as np

from ..lights import DirectionalLight, PointLight

CHUNK_PAIRS = 1 << 21   # receiver x triangle pairs per chunk (about 50 MB per float64 temporary)


def _prepare(vertices, faces, light, points, normals, eps):
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tri = vertices[faces]
    if eps is None:
        used = vertices[np.unique(faces)]
        eps = 1e-4 * float(np.linalg.norm(used.max(axis=0) - used.min(axis=0)))
    if isinstance(light, PointLight):
        position = np.asarray(light.position, dtype=np.float64)
        to_light = position - points
    elif isinstance(light, DirectionalLight):
        position = None
        to_light = np.broadcast_to(-np.asarray(light.direction, dtype=np.float64), points.shape)
    else:
        raise TypeError(f"light: expected a PointLight or DirectionalLight, got {type(light).__name__}")
    facing_away = np.zeros(len(points), dtype=bool)
    start = points.copy()
    if normals is not None:
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        normals = normals / np.linalg.norm(normals, axis=1, keepdims=True)
        facing_away = np.einsum("ij,ij->i", normals, to_light) <= 0
        start = points + eps * normals
    if position is not None:
        direction = position - start
    else:
        direction = np.array(to_light, dtype=np.float64)
    return tri, float(eps), start, direction, position is not None, facing_away


def shadow_mask(vertices, faces, light, points, normals=None, eps=None, margin: float = 0.0):
    """Bool (N,) mask, True = in shadow, in float64 against every triangle.

    ``margin`` (scene units) moves the tie: positive counts hits up to ``margin`` beyond the interval
    ends (distance ``eps`` from the start, the light), negative requires them ``margin`` inside. The
    difference of the two is the band where float32 rounding may legitimately decide.
    """
    tri, eps, start, direction, is_point, facing_away = _prepare(vertices, faces, light, points, normals, eps)
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    length = np.linalg.norm(direction, axis=1)
    mask = facing_away.copy()
    chunk = max(1, CHUNK_PAIRS // max(len(tri), 1))
    for lo in range(0, len(start), chunk):
        hi = min(lo + chunk, len(start))
        todo = ~mask[lo:hi]
        if not np.any(todo):
            continue
        index = np.arange(lo, hi)[todo]
        s, d, ln = start[index], direction[index], length[index]
        pvec = np.cross(d[:, None, :], e2[None, :, :])
        det = np.einsum("fk,nfk->nf", e1, pvec)
        tvec = s[:, None, :] - v0[None, :, :]
        qvec = np.cross(tvec, e1[None, :, :])
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            u = np.einsum("nfk,nfk->nf", tvec, pvec) * inv
            v = np.einsum("nk,nfk->nf", d, qvec) * inv
            t = np.einsum("fk,nfk->nf", e2, qvec) * inv
            dist = t * ln[:, None]              # distance from the start along the segment or ray
            inside = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1)
        near = dist > eps - margin
        if is_point:
            far = dist < ln[:, None] + margin
        else:
            far = np.ones_like(near)
        mask[index] = np.any(inside & near & far, axis=1)
    return mask


def segment_edge_distance(vertices, faces, light, points, normals=None, eps=None, ray_length=None):
    """(N,) smallest distance between each receiver's tested segment and any triangle edge, float64.

    The segment runs from ``s`` to the light (to ``s + ray_length * direction`` for a directional light;
    ``ray_length`` defaults to 4x the distance from the points to the farthest vertex). Receivers whose
    segment passes this close to an edge are the ones float32 rounding may decide either way.
    """
    tri, eps, start, direction, is_point, facing_away = _prepare(vertices, faces, light, points, normals, eps)
    if not is_point:
        if ray_length is None:
            span = np.concatenate([tri.reshape(-1, 3), start])
            ray_length = 4 * float(np.linalg.norm(span.max(axis=0) - span.min(axis=0))) + 1.0
        direction = direction * ray_length
    edge_start = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    edge_vec = np.concatenate([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 1], tri[:, 0] - tri[:, 2]])
    out = np.full(len(start), np.inf)
    chunk = max(1, CHUNK_PAIRS // max(len(edge_start), 1))
    for lo in range(0, len(start), chunk):
        hi = min(lo + chunk, len(start))
        p, d = start[lo:hi, None, :], direction[lo:hi, None, :]
        q, e = edge_start[None], edge_vec[None]
        r = p - q
        dd = np.einsum("nik,nik->ni", d, d)
        ee = np.einsum("nfk,nfk->nf", e, e)
        de = np.einsum("nik,nfk->nf", d, e)
        dr = np.einsum("nik,nfk->nf", d, r)
        er = np.einsum("nfk,nfk->nf", e, r)
        denom = dd * ee - de * de
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(denom > 1e-300, (de * er - ee * dr) / denom, 0.0)
            s = np.clip(s, 0.0, 1.0)
            t = np.where(ee > 0, (de * s + er) / ee, 0.0)
            t = np.clip(t, 0.0, 1.0)
            # re-solve s for the clamped t, then clamp again (closest points of two segments)
            s = np.where(dd > 0, np.clip((de * t - dr) / dd, 0.0, 1.0), 0.0)
        gap = p + s[..., None] * d - (q + t[..., None] * e)
        out[lo:hi] = np.sqrt(np.einsum("nfk,nfk->nf", gap, gap)).min(axis=1)
    out[facing_away] = np.inf
    return out
