"""Polygon-mesh topology (half-edges as "corners") and one Catmull-Clark refinement step, with the
limit-position and limit-tangent weights of a vertex."""

from __future__ import annotations

import numpy as np


class _Topology:
    """Corners of a polygon mesh: corner c is vertex ``vert[c]`` of face ``face_of[c]``; its edge runs to
    ``vert[next[c]]``; ``twin[c]`` is the corner of the neighbouring face on the same edge (-1 on a
    boundary)."""

    def __init__(self, vert: np.ndarray, face_start: np.ndarray, n_vertices: int):
        self.vert = vert
        self.face_start = face_start
        self.n_vertices = n_vertices
        sizes = np.diff(face_start)
        self.sizes = sizes
        n_corners = len(vert)
        self.face_of = np.repeat(np.arange(len(sizes)), sizes)
        base = face_start[self.face_of]
        pos = np.arange(n_corners) - base
        self.next = base + (pos + 1) % sizes[self.face_of]
        self.prev = base + (pos - 1) % sizes[self.face_of]
        head = vert[self.next]
        key = vert.astype(np.int64) * n_vertices + head
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        duplicate = np.flatnonzero(sorted_key[1:] == sorted_key[:-1])
        if len(duplicate):
            c = order[duplicate[0]]
            raise ValueError(
                f"faces: edge ({vert[c]}, {head[c]}) is used twice in the same direction "
                "(non-manifold edge or inconsistently oriented faces)"
            )
        twin_key = head.astype(np.int64) * n_vertices + vert
        where = np.searchsorted(sorted_key, twin_key)
        where = np.minimum(where, n_corners - 1)
        found = sorted_key[where] == twin_key
        self.twin = np.where(found, order[where], -1)
        self.face_count = np.bincount(vert, minlength=n_vertices)
        boundary_out = self.twin < 0
        self.boundary = np.bincount(vert[boundary_out], minlength=n_vertices) > 0
        self.corner = self.boundary & (self.face_count == 1)
        self.regular = np.where(self.boundary, self.face_count <= 2, self.face_count == 4)
        # Corners grouped by vertex (CSR) for fan walks.
        self.vertex_corners = np.argsort(vert, kind="stable")
        self.vertex_start = np.concatenate([[0], np.cumsum(self.face_count)])

    @classmethod
    def from_faces(cls, faces: "list[np.ndarray] | np.ndarray", n_vertices: int) -> "_Topology":
        """From a list of polygons or an (F, k) array of equal-sized ones."""
        if isinstance(faces, np.ndarray):
            vert = faces.reshape(-1).astype(np.int64)
            face_start = np.arange(0, len(vert) + 1, faces.shape[1])
        else:
            vert = np.concatenate(faces).astype(np.int64)
            face_start = np.concatenate([[0], np.cumsum([len(f) for f in faces])])
        return cls(vert, face_start, n_vertices)

    def check_manifold_vertices(self) -> None:
        """Raise ValueError if a vertex has more than one fan of faces (a non-manifold vertex)."""
        out_boundary = np.bincount(self.vert[self.twin < 0], minlength=self.n_vertices)
        bad = np.flatnonzero(out_boundary > 1)
        if len(bad) == 0:
            fan = self.fan_sizes()
            bad = np.flatnonzero(fan != self.face_count)
        if len(bad):
            raise ValueError(f"faces: vertex {bad[0]} is non-manifold (its faces form more than one fan)")

    def fan_sizes(self) -> np.ndarray:
        """Number of faces reached by walking around each vertex from its first corner."""
        sizes = np.zeros(self.n_vertices, dtype=np.int64)
        for v in np.flatnonzero(self.face_count):
            start = self.vertex_corners[self.vertex_start[v]]
            sizes[v] = len(self.fan(start))
        return sizes

    def fan(self, start: int) -> list[int]:
        """Corners around vert[start], from ``start`` one way round, then (at a boundary) the other way."""
        corners = [int(start)]
        c = self.twin[self.prev[start]]
        while c >= 0 and c != start:
            corners.append(int(c))
            c = self.twin[self.prev[c]]
        if c < 0:
            t = self.twin[start]
            while t >= 0:
                c = self.next[t]
                corners.append(int(c))
                t = self.twin[c]
        return corners


def _cc_step(points: np.ndarray, topo: _Topology) -> tuple[np.ndarray, np.ndarray]:
    """One Catmull-Clark step with "edge and corner" boundaries: (new points, (C, 4) child quads).

    ``points`` is (V, d) for any d (positions, or coefficient vectors to build subdivision matrices).
    New points are [vertex points (V), edge points (E), face points (F)]; child quad c (one per corner
    of the old mesh, so face f's children are its corners in order) is
    (vertex point, edge point of the corner's edge, face point, edge point of the previous edge).
    """
    v_count = topo.n_vertices
    vert, nxt, prev, twin, face_of = topo.vert, topo.next, topo.prev, topo.twin, topo.face_of
    corners = np.arange(len(vert))
    face_points = np.add.reduceat(points[vert], topo.face_start[:-1], axis=0) / topo.sizes[:, None]
    # Edges: one per interior twin pair, one per boundary corner.
    owner = (twin < 0) | (corners < twin)
    edge_id = np.full(len(vert), -1, dtype=np.int64)
    edge_id[owner] = np.arange(np.count_nonzero(owner))
    edge_id[~owner] = edge_id[twin[~owner]]
    owners = corners[owner]
    ends = points[vert[owners]] + points[vert[nxt[owners]]]
    interior_edge = twin[owners] >= 0
    edge_points = ends / 2.0
    inner = owners[interior_edge]
    edge_points[interior_edge] = (ends[interior_edge] + face_points[face_of[inner]]
                                  + face_points[face_of[twin[inner]]]) / 4.0
    # Interior vertices: (F + 2R + (n - 3) V) / n, F = mean face point, R = mean edge midpoint.
    n = np.maximum(topo.face_count, 1).astype(np.float64)[:, None]
    face_sum = np.zeros_like(points, dtype=np.float64)
    np.add.at(face_sum, vert, face_points[face_of])
    mid_sum = np.zeros_like(face_sum)
    np.add.at(mid_sum, vert, (points[vert] + points[vert[nxt]]) / 2.0)
    vertex_points = (face_sum / n + 2.0 * mid_sum / n + (n - 3.0) * points) / n
    # Boundary vertices: (a + 6 v + b) / 8 along the boundary; sharp corners and isolated vertices stay.
    out_c = corners[twin < 0]
    neighbour_sum = np.zeros_like(face_sum)
    np.add.at(neighbour_sum, vert[out_c], points[vert[nxt[out_c]]])
    np.add.at(neighbour_sum, vert[nxt[out_c]], points[vert[out_c]])
    smooth_boundary = topo.boundary & ~topo.corner
    vertex_points[smooth_boundary] = (neighbour_sum[smooth_boundary] + 6.0 * points[smooth_boundary]) / 8.0
    fixed = topo.corner | (topo.face_count == 0)
    vertex_points[fixed] = points[fixed]
    new_points = np.concatenate([vertex_points, edge_points, face_points])
    e_count = len(edge_points)
    child = np.stack([vert, v_count + edge_id, v_count + e_count + face_of, v_count + edge_id[prev]], axis=1)
    return new_points, child


def _limit_weights_of(topo: _Topology, v: int) -> tuple[np.ndarray, np.ndarray]:
    """(vertex ids, weights) of the limit position of vertex v; its faces must be quads."""
    ring = topo.fan(topo.vertex_corners[topo.vertex_start[v]])
    if topo.corner[v]:
        return np.array([v]), np.array([1.0])
    if topo.boundary[v]:
        out_c = [c for c in ring if topo.twin[c] < 0][0]
        in_c = [c for c in ring if topo.twin[topo.prev[c]] < 0][0]
        a, b = topo.vert[topo.next[out_c]], topo.vert[topo.prev[in_c]]
        return np.array([a, v, b]), np.array([1.0, 4.0, 1.0]) / 6.0
    n = len(ring)
    edges = topo.vert[topo.next[ring]]
    diagonals = topo.vert[topo.next[topo.next[ring]]]
    ids = np.concatenate([[v], edges, diagonals])
    weights = np.concatenate([[n * n], np.full(n, 4.0), np.ones(n)]) / (n * (n + 5.0))
    return ids, weights


def _limit_tangent_weights_of(topo: _Topology, v: int) -> "tuple[np.ndarray, np.ndarray] | None":
    """(vertex ids, (2, k) weights) of two limit tangents at interior vertex v of valence >= 3 (its faces
    quads), whose cross product is the outward limit normal (counter-clockwise faces); None elsewhere.

    The closed-form masks (Halstead et al. 1993, as in OpenSubdiv): with edge neighbours e_i and face
    diagonals f_i (between e_i and e_i+1) in fan order, t = sum(A c_i e_i + (c_i + c_i+1) f_i) with
    c_i = cos(2 pi i / n) for the first and sin(2 pi i / n) for the second, A = 1 + cos(2 pi / n) +
    cos(pi / n) sqrt(2 (9 + cos(2 pi / n))). Needed because near a high-valence EV the surface's normal
    converges slowly (eigenvalue ratio ~1 - 1/n^2 a level): at valence 64 and a non-symmetric ring the
    normals of the patches at (2^-L, 2^-L) still differ by degrees.
    """
    if topo.boundary[v] or topo.face_count[v] < 3:
        return None
    ring = np.array(topo.fan(topo.vertex_corners[topo.vertex_start[v]]))
    n = len(ring)
    edges, diagonals = topo.vert[topo.next[ring]], topo.vert[topo.next[topo.next[ring]]]
    angle = 2.0 * np.pi * np.arange(n) / n
    a = 1.0 + np.cos(2.0 * np.pi / n) + np.cos(np.pi / n) * np.sqrt(2.0 * (9.0 + np.cos(2.0 * np.pi / n)))
    weights = []
    for c in (np.cos(angle), np.sin(angle)):
        weights.append(np.concatenate([[0.0], a * c, c + np.roll(c, -1)]))
    return np.concatenate([[v], edges, diagonals]), np.array(weights)
