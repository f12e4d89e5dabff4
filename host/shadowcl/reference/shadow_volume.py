"""Float64 reference of shadow volumes: the volume's triangles and the winding number of any point.

Written from the construction (Everitt & Kilgard; Fawad, Wang & Wu) without the method's host code:

- **Facing**: ``s = ((v1 - v0) x (v2 - v0)) . (L - v0)`` for a point light at ``L``, ``-n . d`` for a
  directional light travelling along ``d``; a face is light-facing when ``s > 0``.
- **Two-sided open parts**: every face of a connected component (faces joined through edges with two
  faces) that has a border edge also exists flipped, on copies of its vertices appended in ascending
  vertex order (:func:`two_sided`).
- **Silhouette** of the light-facing set: the directed half-edges ``a -> b`` of light-facing faces
  whose reverse ``b -> a`` belongs to no light-facing face (the boundary of the cap).
- **Volume**, vertex ``i`` extruded to vertex ``V + i`` at ``L + k (v - L)`` (point light) or
  ``v + D d`` (directional): front cap = light-facing faces, back cap = the same reversed on the
  extruded vertices, and per boundary half-edge ``a -> b`` the two triangles ``(b, a, a')``,
  ``(b, a', b')``: all counter-clockwise around outward normals.
- **Winding number** of a point: signed crossings (+1 leaving along the outward normal, -1 entering)
  of *every* volume triangle by a ray from the point in a given direction (Möller-Trumbore with
  inclusive edges: a ray through a shared edge or vertex would count it twice, so callers pick
  random directions, which miss edges almost surely). For a closed volume it does not depend on the
  direction; a point is in the volume's shadow when it is nonzero.
"""

from __future__ import annotations

import numpy as np

from ..lights import PointLight

CHUNK_PAIRS = 1 << 21


def facing(vertices, faces, light) -> np.ndarray:
    """(F,) bool light-facing faces, float64."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    if isinstance(light, PointLight):
        s = np.einsum("ij,ij->i", n, np.asarray(light.position, dtype=np.float64) - tri[:, 0])
    else:
        s = -n @ np.asarray(light.direction, dtype=np.float64)
    return s > 0


def _components(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per face its component label (faces joined through edges shared by two faces) and per face
    whether it has a border edge (an edge no other face shares). Label propagation to a fixed point."""
    nf = len(faces)
    keys = np.sort(np.stack([faces, np.roll(faces, -1, axis=1)], axis=2), axis=2).reshape(-1, 2)   # (3F, 2)
    owner = np.repeat(np.arange(nf), 3)
    _, edge_id, count = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    edge_id = edge_id.reshape(-1)
    border = np.zeros(nf, dtype=bool)
    np.logical_or.at(border, owner, count[edge_id] == 1)
    label = np.arange(nf)
    shared = count[edge_id] == 2
    while True:
        lowest = np.full(len(count), nf)
        np.minimum.at(lowest, edge_id[shared], label[owner[shared]])
        new = label.copy()
        np.minimum.at(new, owner[shared], lowest[edge_id[shared]])
        if np.array_equal(new, label):
            return label, border
        label = new


def two_sided(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) with every open component's faces also present flipped on its own vertex copies."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    label, border = _components(faces)
    open_labels = np.unique(label[border])
    open_faces = faces[np.isin(label, open_labels)]
    if len(open_faces) == 0:
        return vertices, faces
    used = np.unique(open_faces)
    new_index = np.full(len(vertices), -1)
    new_index[used] = len(vertices) + np.arange(len(used))
    flipped = new_index[open_faces][:, ::-1]
    return np.concatenate([vertices, vertices[used]]), np.concatenate([faces, flipped])


def volume(vertices, faces, light, extrusion: float) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (2V, 3) float64, faces (T, 3)) of the shadow volume of a manifold, consistently wound
    mesh; ``extrusion`` is ``k`` for a point light, ``D`` for a directional one (module doc)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    nv = len(vertices)
    cap = faces[facing(vertices, faces, light)]
    halves = {(int(a), int(b)) for f in cap for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))}
    boundary = np.array(sorted(h for h in halves if (h[1], h[0]) not in halves), dtype=np.int64).reshape(-1, 2)
    if isinstance(light, PointLight):
        position = np.asarray(light.position, dtype=np.float64)
        far = position + extrusion * (vertices - position)
    else:
        far = vertices + extrusion * np.asarray(light.direction, dtype=np.float64)
    a, b = boundary[:, 0], boundary[:, 1]
    tris = np.concatenate([cap, cap[:, [2, 1, 0]] + nv, np.stack([b, a, a + nv], 1), np.stack([b, a + nv, b + nv], 1)])
    return np.concatenate([vertices, far]), tris


def winding_numbers(triangles, points, direction) -> np.ndarray:
    """(N,) int: signed crossings of ``triangles`` ((T, 3, 3), counter-clockwise outward) by the rays
    from ``points`` along ``direction`` ((3,) or (N, 3)): +1 leaving, -1 entering."""
    tri = np.asarray(triangles, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    direction = np.broadcast_to(np.asarray(direction, dtype=np.float64), points.shape)
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    normal = np.cross(e1, e2)
    out = np.zeros(len(points), dtype=np.int64)
    step = max(1, CHUNK_PAIRS // max(len(tri), 1))
    for lo in range(0, len(points), step):
        o, d = points[lo:lo + step, None, :], direction[lo:lo + step, None, :]
        # Solve o + t d = v0 + u e1 + v e2 by Cramer's rule.
        p = np.cross(d, e2)
        det = np.einsum("tk,ntk->nt", e1, p)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = o - v0
            u = np.einsum("ntk,ntk->nt", s, p) / det
            q = np.cross(s, e1)
            v = np.einsum("ntk,ntk->nt", d, q) / det
            t = np.einsum("tk,ntk->nt", e2, q) / det
            hit = (det != 0) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        sign = np.sign(np.einsum("ntk,tk->nt", d, normal)).astype(np.int64)
        out[lo:lo + step] = np.sum(np.where(hit, sign, 0), axis=1)
    return out
