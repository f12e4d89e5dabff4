"""NumPy float64 reference of the parameter-space voxelization (Lai & Cheng, section 3).

Written from the paper and the patch-table contract, independent of kernels/voxelize.cl and
host/shadowcl/voxelize.py: its own B-spline / Stam sub-domain evaluation, its own voxel mapping, the
same subdivision rule (split until the corner voxels fit in a 2 x 2 x 2 block and those of each edge are N-adjacent). Besides the leaves
it reports, per visited subpatch, how close any corner came to a voxel face (``margin``, in voxels):
float32 and float64 may put a corner that close to a face in different voxels, so a test may only
demand exact agreement away from such corners.
"""

from __future__ import annotations

import numpy as np

MAX_DEPTH = 24
MIN_EDGE = 1.0 / 64.0   # voxels: shorter leaves are forced (kernels/voxelize.cl)


def bspline_basis(t: np.ndarray) -> np.ndarray:
    """(N, 4) uniform cubic B-spline basis at t in [0, 1]."""
    s = 1.0 - t
    return np.stack([s ** 3, 3 * t ** 3 - 6 * t ** 2 + 4, -3 * t ** 3 + 3 * t ** 2 + 3 * t + 1, t ** 3], axis=1) / 6.0


def bspline_eval(points: np.ndarray, base: np.ndarray, u: np.ndarray, v: np.ndarray,
                 with_derivatives: bool = False):
    """Positions (N, 3) of 16-point bicubic B-spline patches starting at points[base] (row-major, i along u)."""
    cp = points[base[:, None] + np.arange(16)].reshape(-1, 4, 4, 3)   # [n, j, i, xyz]
    bu, bv = bspline_basis(u), bspline_basis(v)
    p = np.einsum("nj,ni,njix->nx", bv, bu, cp)
    if not with_derivatives:
        return p
    s, t = 1.0 - u, u
    du = np.stack([-0.5 * s * s, 1.5 * t * t - 2 * t, -1.5 * t * t + t + 0.5, 0.5 * t * t], axis=1)
    s, t = 1.0 - v, v
    dv = np.stack([-0.5 * s * s, 1.5 * t * t - 2 * t, -1.5 * t * t + t + 0.5, 0.5 * t * t], axis=1)
    return p, np.einsum("nj,ni,njix->nx", bv, du, cp), np.einsum("nj,ni,njix->nx", dv, bu, cp)


def patch_eval(points, first, levels, patch: np.ndarray, u: np.ndarray, v: np.ndarray,
               with_derivatives: bool = False):
    """Limit positions (N, 3) (and du, dv) of patches ``patch`` at (u, v), per the patch-table contract."""
    points = np.asarray(points, dtype=np.float64)
    f = np.asarray(first, dtype=np.int64)[patch]
    L = np.asarray(levels, dtype=np.int64)[patch]
    u, v = np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64)
    m = np.maximum(u, v)
    with np.errstate(divide="ignore"):
        n = np.clip(-np.floor(np.log2(np.where(m > 0, m, 1.0))).astype(np.int64), 1, np.maximum(L, 1))
    scale = np.ldexp(1.0, n)
    uu, vv = u * scale, v * scale
    k = np.where(vv < 1.0, 0, np.where(uu >= 1.0, 1, 2))
    uu = np.where(k <= 1, uu - 1.0, uu)
    vv = np.where(k >= 1, vv - 1.0, vv)
    irregular = L > 0
    base = np.where(irregular, f + ((n - 1) * 3 + k) * 16, f)
    uu, vv = np.where(irregular, uu, u), np.where(irregular, vv, v)
    sc = np.where(irregular, scale, 1.0)[:, None]
    out = bspline_eval(points, base, uu, vv, with_derivatives)
    p, du, dv = out if with_derivatives else (out, None, None)
    corner = irregular & (m < np.ldexp(1.0, -L))
    if np.any(corner):
        p = p.copy()
        p[corner] = points[f[corner] + 48 * L[corner]]
    if not with_derivatives:
        return p
    du, dv = du * sc, dv * sc
    du[corner] = 0.0
    dv[corner] = 0.0
    return p, du, dv


def adjacent(a: np.ndarray, b: np.ndarray, connectivity: int) -> np.ndarray:
    d = np.abs(a - b)
    near = np.all(d <= 1, axis=-1)
    if connectivity == 26:
        return near
    return near & (d.sum(axis=-1) <= (2 if connectivity == 18 else 1))


def voxelize(points, first, levels, resolution: int, connectivity: int, origin, voxel_size: float):
    """Leaves of the parameter-space subdivision.

    Returns a dict: ``leaves`` (n, 4) int64 (patch, level, iu, iv); ``corners`` (n, 4, 3) float64;
    ``voxels`` (n, 4, 3) int64; ``margin`` (n,) the smallest distance, in voxels, of any corner of the
    leaf or of its ancestors to a voxel face (where float32 may decide differently); ``occupied`` the
    set of linear voxel indices (i * R + j) * R + k of all leaf corners.
    """
    npatch = len(first)
    items = np.stack([np.arange(npatch), np.zeros(npatch, int), np.zeros(npatch, int), np.zeros(npatch, int)], axis=1)
    margins = np.full(npatch, np.inf)
    origin = np.asarray(origin, dtype=np.float64)
    out_leaves, out_corners, out_voxels, out_margin = [], [], [], []
    cu = np.array([0, 1, 1, 0])
    cv = np.array([0, 0, 1, 1])
    while len(items):
        patch, level, iu, iv = items.T
        step = np.ldexp(1.0, -level)
        u = ((iu[:, None] + cu) * step[:, None]).ravel()
        v = ((iv[:, None] + cv) * step[:, None]).ravel()
        p = patch_eval(points, first, levels, np.repeat(patch, 4), u, v).reshape(-1, 4, 3)
        x = (p - origin) / voxel_size
        vox = np.clip(np.floor(x), 0, resolution - 1).astype(np.int64)
        frac = x - np.floor(x)
        interior = (x > 0) & (x < resolution)
        face = np.where(interior, np.minimum(frac, 1.0 - frac), np.inf)
        margin = np.minimum(margins, face.reshape(len(items), -1).min(axis=1))
        small = np.ones(len(items), dtype=bool)
        for a in range(4):
            small &= adjacent(vox[:, a], vox[:, (a + 1) % 4], connectivity)
            small &= adjacent(vox[:, a], vox[:, (a + 2) % 4], 26)
        longest = np.max(np.linalg.norm(p - np.roll(p, -1, axis=1), axis=2), axis=1) / voxel_size
        leaf = small | (level >= MAX_DEPTH) | (longest < MIN_EDGE)
        out_leaves.append(items[leaf])
        out_corners.append(p[leaf])
        out_voxels.append(vox[leaf])
        out_margin.append(margin[leaf])
        split = items[~leaf]
        children = np.repeat(split, 4, axis=0)
        children[:, 1] += 1
        children[:, 2] = 2 * children[:, 2] + np.tile([0, 1, 0, 1], len(split))
        children[:, 3] = 2 * children[:, 3] + np.tile([0, 0, 1, 1], len(split))
        items, margins = children, np.repeat(margin[~leaf], 4)
    voxels = np.concatenate(out_voxels)
    linear = (voxels[..., 0] * resolution + voxels[..., 1]) * resolution + voxels[..., 2]
    return dict(leaves=np.concatenate(out_leaves), corners=np.concatenate(out_corners), voxels=voxels,
                margin=np.concatenate(out_margin), occupied=set(np.unique(linear).tolist()))
