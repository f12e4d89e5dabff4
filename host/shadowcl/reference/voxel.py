"""NumPy float64 reference of the voxel method's shadow determination (Lai & Cheng, section 4).

Input: the leaves (patch ids, parameter squares, corner positions, corner voxels) of a voxelization and
per-sample unit normals, the light, and for the offset rule the light's view (its cells come from
reference/lightspace.py). Independent of kernels/voxel.cl and host/shadowcl/voxel.py:

- topology: brute force over *every* leaf (no lists): sample A is shadowed when its segment (ray) to the
  light hits a triangle (0, 1, 2) or (0, 2, 3) of a leaf none of whose corner voxels is within one voxel
  of A's voxel;
- offset: per cell the nearest sample distance; A' = A + offset N projected along A's beam; shadowed
  when A' is farther than its cell's nearest sample.

Both: a normal facing away from the light (N . (L - A) <= 0) is shadowed. ``margin`` flags samples
whose decision rounding could flip (a hit within 1e-4 of a triangle's edge or of the segment's ends;
a depth within 1e-5 relative; A'' within 1e-4 cell of a cell border), which a test must not demand.
"""

from __future__ import annotations

import numpy as np

from . import lightspace as ref_ls


def _beams(points, light_point, light_vec):
    if light_point:
        d = light_vec[None] - points
        dist = np.linalg.norm(d, axis=1)
        return d / np.maximum(dist, 1e-300)[:, None], dist
    return np.broadcast_to(-light_vec, points.shape), points @ light_vec


def topology(corners, voxels, normals, light_point: bool, light_vec, resolution: int):
    """(states (S,) uint8 1 lit / 2 shadowed, unsure (S,) bool) for the samples = leaf corners in order."""
    corners = np.asarray(corners, dtype=np.float64)
    A = corners.reshape(-1, 3)
    N = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    light_vec = np.asarray(light_vec, dtype=np.float64)
    b, _ = _beams(A, light_point, light_vec)
    states = np.where(np.einsum("ij,ij->i", N, b) <= 0, 2, 1).astype(np.uint8)
    unsure = np.zeros(len(A), dtype=bool)
    vox = np.stack([voxels // resolution ** 2, (voxels // resolution) % resolution, voxels % resolution], axis=-1)  # (n, 4, 3)
    tris = np.concatenate([corners[:, [0, 1, 2]], corners[:, [0, 2, 3]]])    # (2n, 3, 3): leaf t % n
    V0 = tris[:, 0]
    u, v = tris[:, 1] - V0, tris[:, 2] - V0
    nrm = np.cross(u, v)
    uu, uv, vv = np.einsum("ij,ij->i", u, u), np.einsum("ij,ij->i", u, v), np.einsum("ij,ij->i", v, v)
    den = uv * uv - uu * vv
    sample_vox = vox.reshape(-1, 3)
    for s in np.flatnonzero(states == 1):
        o = A[s]
        D = (light_vec - o) if light_point else -light_vec
        tmax = 1.0 if light_point else np.inf
        near_leaf = np.any(np.all(np.abs(vox - sample_vox[s]) <= 1, axis=2), axis=1)   # (n,)
        keep = ~np.concatenate([near_leaf, near_leaf])
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.einsum("ij,ij->i", nrm, V0 - o) / (nrm @ D)
            w = o + t[:, None] * D - V0
            wu, wv = np.einsum("ij,ij->i", w, u), np.einsum("ij,ij->i", w, v)
            bs = (uv * wv - vv * wu) / den
            bt = (uv * wu - uu * wv) / den
        valid = keep & np.isfinite(t) & np.isfinite(bs) & np.isfinite(bt)
        hit = valid & (t > 0) & (t < tmax) & (bs >= 0) & (bt >= 0) & (bs + bt <= 1)
        close = valid & (t > -1e-4) & (t < tmax + 1e-4) & (bs >= -1e-4) & (bt >= -1e-4) & (bs + bt <= 1 + 1e-4)
        edge = close & ((np.abs(bs) < 1e-4) | (np.abs(bt) < 1e-4) | (np.abs(bs + bt - 1) < 1e-4)
                        | (np.abs(t) < 1e-4) | (np.abs(t - tmax) < 1e-4))
        states[s] = 2 if hit.any() else 1
        unsure[s] = bool(np.any(edge))
    return states, unsure


def offset(corners, normals, light_point: bool, light_vec, views, nx, ny, offset_distance: float):
    """(states, unsure) of the offset rule; ``views`` a lightspace.LightViews (one view or a cube)."""
    A = np.asarray(corners, dtype=np.float64).reshape(-1, 3)
    N = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    light_vec = np.asarray(light_vec, dtype=np.float64)
    b, dist = _beams(A, light_point, light_vec)
    args = (views.kind, views.eye, views.axes, views.windows, nx, ny)
    cells, _ = ref_ls.point_cells(A, *args)
    nx, ny = np.asarray(nx, dtype=np.int64), np.asarray(ny, dtype=np.int64)
    ambiguous = _border_distance(A, views, nx, ny) < 1e-4
    # depth bounds: samples near a cell border (float32 may put them in the next cell) are left out of
    # `depth_hi` and spread over their 3 x 3 neighbourhood in `depth_lo`
    depth_hi = np.full(int(np.sum(nx * ny)), np.inf)
    np.minimum.at(depth_hi, cells[~ambiguous], dist[~ambiguous])
    depth_lo = depth_hi.copy()
    bases = np.concatenate([[0], np.cumsum(nx * ny)[:-1]])
    c = cells[ambiguous]
    f = np.searchsorted(bases, c, side="right") - 1
    i, j = (c - bases[f]) % nx[f], (c - bases[f]) // nx[f]
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            ii, jj = np.clip(i + di, 0, nx[f] - 1), np.clip(j + dj, 0, ny[f] - 1)
            np.minimum.at(depth_lo, bases[f] + jj * nx[f] + ii, dist[ambiguous])
    facing = np.einsum("ij,ij->i", N, b)
    along = offset_distance * facing
    Q = A + offset_distance * N - along[:, None] * b
    qcells, _ = ref_ls.point_cells(Q, *args)
    d = dist - along
    depth = np.full(len(depth_hi), np.inf)
    np.minimum.at(depth, cells, dist)
    states = np.where((facing <= 0) | (d > depth[qcells]), 2, 1).astype(np.uint8)
    # unsure: A'' near a cell border, depth bounds that disagree, near-equal depths, grazing normals
    border = _border_distance(Q, views, nx, ny) < 1e-4
    split = (d > depth_lo[qcells]) != (d > depth_hi[qcells])
    near_depth = np.abs(d - depth_hi[qcells]) <= 1e-5 * np.maximum(np.abs(d), 1.0)
    unsure = (facing > 0) & (border | split | near_depth | (np.abs(facing) < 1e-5))
    return states, unsure


def _border_distance(points, views, nx, ny):
    """Distance, in cells, of each point's projection to the nearest cell border of its view."""
    out = np.zeros(len(points))
    if views.kind == "cube":
        d = points - views.eye
        axis = np.argmax(np.abs(d), axis=1)
        face = 2 * axis + (d[np.arange(len(d)), axis] < 0)
    else:
        face = np.zeros(len(points), dtype=np.int64)
    for f in np.unique(face):
        sel = face == f
        P = ref_ls.project(points[sel], views.eye, views.axes[f], views.windows[f], nx[f], ny[f], views.kind != "orthographic")
        G = P[:, :2] / P[:, 2:3]
        out[sel] = np.min(np.abs(G - np.round(G)), axis=1)
    return out


def locate(states, points, origin, voxel_size: float, search: int = 2):
    """(id or -1, state) per point from the dense (R, R, R) ``states`` (0 empty, 1 lit, 2 shadowed): the
    point's voxel when occupied, else the occupied voxel within ``search`` voxels (per axis) at the
    smallest Chebyshev ring, then the smallest squared offset, then the lexicographically least offset."""
    R = states.shape[0]
    offsets = [(a, b, c) for a in range(-search, search + 1) for b in range(-search, search + 1)
               for c in range(-search, search + 1)]
    offsets.sort(key=lambda o: (max(map(abs, o)), sum(x * x for x in o), o))
    ids, found = np.full(len(points), -1, dtype=np.int64), np.zeros(len(points), dtype=np.uint8)
    for p, point in enumerate(np.asarray(points, dtype=np.float64)):
        base = np.floor((point - origin) / voxel_size)
        if np.any(np.abs(base) > 4 * R):
            continue
        for o in offsets:
            i, j, k = (int(x) for x in base + o)
            if 0 <= i < R and 0 <= j < R and 0 <= k < R and states[i, j, k]:
                ids[p], found[p] = (i * R + j) * R + k, states[i, j, k]
                break
    return ids, found
