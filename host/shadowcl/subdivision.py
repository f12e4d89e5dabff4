"""Catmull-Clark subdivision surfaces: control meshes, exact limit evaluation, the patch table, tessellation.

A :class:`SubdivisionSurface` is a polygon control mesh (any polygons, boundaries allowed) whose limit
surface is evaluated exactly:

- Boundaries follow OpenSubdiv's "edge and corner" rule: boundary edges are B-spline curves of the
  boundary vertices, and a boundary vertex with a single face (valence 2) is a sharp corner.
- The surface is cut into quad patches that each carry at most one extraordinary vertex (EV): a control
  quad is a patch if every face at its corners is a quad and at most one corner is extraordinary; any
  other face is Catmull-Clark refined once (its children are the patches), and children with more than
  one EV once more. Refinement runs on the whole mesh in float64 NumPy (it is exact, and cheap).
- A regular patch is the 16-point uniform bicubic B-spline of its 4x4 control net; on a boundary the
  missing points are phantoms reflected through the boundary (P_-1 = 2 P_0 - P_1), which reproduces the
  boundary rules exactly. A patch with an EV is evaluated exactly by Stam's sub-domains: the local
  control net is subdivided L times in float64 (A^n C) and each level contributes three 16-point B-spline
  sub-patches; L is chosen so the level-L net lies within 2^-21 of its size from the EV's limit position
  (that position is used below 2^-L).

Parameters of a control face (``evaluate(face, u, v)``): a quad (v0, v1, v2, v3) in input order has
(0, 0) at v0, (1, 0) at v1, (1, 1) at v2 and (0, 1) at v3. An n-gon (n != 4) is split Ptex-style into n
sub-faces with ``u`` in [0, n]: sub-face j = floor(u) (u = n belongs to sub-face n - 1), local
(u - j, v) with (0, 0) at v_j, (1, 0) at the midpoint of edge (v_j, v_j+1), (1, 1) at the face centre and
(0, 1) at the midpoint of edge (v_j-1, v_j) (midpoints and centre on the limit surface, i.e. of the
once-refined mesh).

OpenSubdiv ``t`` tag lines in OBJ files (crease, corner, interpolateboundary, smoothtriangles, ...) are
ignored: every surface uses the rules above.
"""

from __future__ import annotations

import os
import weakref
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np

from .checks import finite_array, positive_int
from .device import get_device
from .meshio import read_polygons
from .geometry import Mesh

#: Most cells (two triangles each) an explicit tessellation may have: 1.5 million cells (a cube cage at
#: 512 segments) took 2.3 s and 730 MB here, so the limit keeps a tessellation within a few GB.
MAX_TESSELLATION_CELLS = 1 << 21

#: Stam levels stop once every point of the level-L control net is within this fraction of the net's
#: size from the EV's limit position (float32 resolution), so using that position below 2^-L is exact
#: to float32 precision.
STAM_TOLERANCE = 2.0**-21
#: Hard cap on Stam levels (valence 64 needs about 40).
MAX_STAM_LEVELS = 64
#: Refinement steps on the whole mesh are at most 2: after one step every face is a quad, after two no
#: quad has two extraordinary corners.
_MAX_REFINE = 2
#: Below this patch parameter (max(u, v)) next to an EV, normals come from float64 host derivatives.
NEAR_EV = 2.0**-10
#: Default tessellation: chord error at most this fraction of the control mesh's bounding-box diagonal.
TESSELLATION_TOLERANCE = 1e-3

_UNIT_SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
_ROTATIONS = [np.roll(np.arange(4), -rot) for rot in range(4)]  # corner order starting at corner rot


# -------------------------------------------------------------------------------------------------
# Polygon-mesh topology (half-edges as "corners") and one Catmull-Clark step
# -------------------------------------------------------------------------------------------------
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


# -------------------------------------------------------------------------------------------------
# Control nets of patches
# -------------------------------------------------------------------------------------------------
_INNER = ((1, 1), (2, 1), (2, 2), (1, 2))  # (i, j) of corner k in the 4x4 grid
_A_AXIS = ((1, 0), (0, 1), (-1, 0), (0, -1))  # from corner k towards corner k + 1
_B_AXIS = ((0, 1), (-1, 0), (0, -1), (1, 0))  # from corner k towards corner k - 1


def _quad_corners(topo: _Topology, face: int, rot: int) -> list[int]:
    start = topo.face_start[face]
    return [int(start + (rot + k) % 4) for k in range(4)]


def _gather_regular(topo: _Topology, points: np.ndarray, face: int, rot: int) -> np.ndarray:
    """The (16, d) B-spline control net of a regular quad, row-major (i along u), corner ``rot`` at (0, 0).

    All four corners must be regular (interior valence 4, boundary with 2 faces, or a corner with 1 face);
    missing points beyond a boundary are phantoms reflected through it.
    """
    vert, nxt, twin, prev = topo.vert, topo.next, topo.twin, topo.prev
    grid: list[list] = [[None] * 4 for _ in range(4)]  # grid[j][i]
    real = np.zeros((4, 4), dtype=bool)

    def put(i, j, corner):
        grid[j][i] = points[vert[corner]]
        real[j, i] = True

    for k, ck in enumerate(_quad_corners(topo, face, rot)):
        (pi, pj), (ai, aj), (bi, bj) = _INNER[k], _A_AXIS[k], _B_AXIS[k]
        put(pi, pj, ck)
        t = twin[ck]  # the face across edge k
        if t >= 0:
            x = nxt[nxt[t]]
            put(pi - bi, pj - bj, x)
            put(pi + ai - bi, pj + aj - bj, nxt[x])
            d = twin[nxt[t]]  # the diagonal face at corner k
            if d >= 0:
                put(pi - ai - bi, pj - aj - bj, nxt[nxt[nxt[d]]])
        t = twin[prev[ck]]  # the face across edge k - 1
        if t >= 0:
            put(pi - ai, pj - aj, nxt[nxt[nxt[t]]])
            put(pi - ai + bi, pj - aj + bj, nxt[nxt[t]])
    # Phantom points: sides first (reflection through the boundary row/column), then grid corners.
    inward = {0: (1, 2), 3: (2, 1)}
    for j in range(4):
        for i in range(4):
            if real[j, i] or (i in (0, 3) and j in (0, 3)):
                continue
            if i in inward:
                a, b = inward[i]
                grid[j][i] = 2.0 * grid[j][a] - grid[j][b]
            else:
                a, b = inward[j]
                grid[j][i] = 2.0 * grid[a][i] - grid[b][i]
    for j in (0, 3):
        for i in (0, 3):
            if real[j, i]:
                continue
            ja, jb = inward[j]
            ia, ib = inward[i]
            if real[ja, i]:
                grid[j][i] = 2.0 * grid[ja][i] - grid[jb][i]
            else:
                grid[j][i] = 2.0 * grid[j][ia] - grid[j][ib]
    return np.array([grid[j][i] for j in range(4) for i in range(4)])


def _local_mesh(topo: _Topology, face: int, rot: int) -> tuple[tuple, np.ndarray]:
    """The faces touching the four corners of quad ``face`` (corner ``rot`` first), canonically relabelled.

    Returns (signature, global vertex ids in local order): the signature is the tuple of local faces, so
    equal signatures mean identical local topology with identical labels. Local face 0 is the quad itself
    as (0, 1, 2, 3) starting at corner ``rot``.
    """
    seen_faces: dict[int, int] = {}
    order: list[int] = []
    for ck in _quad_corners(topo, face, rot):
        for c in topo.fan(ck):
            f = int(topo.face_of[c])
            if f not in seen_faces:
                seen_faces[f] = len(order)
                order.append(int(c))
    labels: dict[int, int] = {}
    local_faces = []
    for start in order:
        f = topo.face_of[start]
        base, size = topo.face_start[f], topo.sizes[f]
        local = []
        for k in range(size):
            v = int(topo.vert[base + (start - base + k) % size])
            local.append(labels.setdefault(v, len(labels)))
        local_faces.append(tuple(local))
    ids = np.fromiter(labels.keys(), dtype=np.int64, count=len(labels))
    return tuple(local_faces), ids


@lru_cache(maxsize=64)  # bounded: one valence-360 entry is 11 MB
def _stam_weights(signature: tuple) -> np.ndarray:
    """(48 L + 3, m) weights: Stam's sub-patch control nets, the EV limit, then two limit tangents at the
    EV (zero rows where :func:`_limit_tangent_weights_of` has none), from the m local points.

    Built by subdividing the local net with coefficient vectors (identity rows) as points, so the rows
    are exactly the entries of (picking matrix) A^n; cached per local topology (read-only).
    """
    m = 1 + max(max(f) for f in signature)
    faces = np.array(signature, dtype=np.int64)
    coefficients = np.eye(m)
    topo = _Topology.from_faces(faces, m)
    ids, weights = _limit_weights_of(topo, 0)
    limit = np.zeros(m)
    np.add.at(limit, ids, weights)
    tangents = np.zeros((2, m))
    tangent_weights = _limit_tangent_weights_of(topo, 0)
    if tangent_weights is not None:
        for row, row_weights in zip(tangents, tangent_weights[1]):
            np.add.at(row, tangent_weights[0], row_weights)
    rows = []
    for _ in range(MAX_STAM_LEVELS):
        child_points, child_faces = _cc_step(coefficients, topo)
        child_topo = _Topology.from_faces(child_faces, len(child_points))
        # Child (k + 1) of the patch quad, started at its corner 3 - k, is sub-patch k in the patch frame.
        for k in range(3):
            rows.append(_gather_regular(child_topo, child_points, k + 1, 3 - k))
        local_faces, local_ids = _local_mesh(child_topo, 0, 0)
        coefficients = child_points[local_ids]
        topo = _Topology.from_faces(np.array(local_faces, dtype=np.int64), len(local_ids))
        if np.abs(coefficients - limit).sum(axis=1).max() <= STAM_TOLERANCE:
            break
    else:
        raise RuntimeError(f"Stam levels did not converge within {MAX_STAM_LEVELS} levels")
    table = np.concatenate(rows + [limit[None, :], tangents])
    table.flags.writeable = False
    return table


# -------------------------------------------------------------------------------------------------
# The patch table
# -------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class PatchTable:
    """Limit-surface patches in world coordinates (the patch-table contract; see kernels/subdivision.h).

    - ``points`` (P, 3) float32 control points; ``first`` (n,) uint32 index of patch i's first point;
      ``levels`` (n,) uint32: 0 = regular 16-point bicubic B-spline (row-major, i along u), L > 0 = one
      extraordinary vertex at (0, 0) evaluated by Stam's sub-domains (48 L points, then its limit).
    - ``face`` (n,) int32 control face; ``domain`` (n, 4) float64 (u0, v0, du, dv) in the face's
      parameters (for n-gons, u in [0, n]); ``rotation`` (n,) uint8: patch corner (0, 0) sits at domain
      corner ``rotation`` (corners (u0, v0), (u1, v0), (u1, v1), (u0, v1)), the patch's u axis towards
      the next corner.
    - ``neighbors`` (n, 4) int32: the patch across side 0 (v = 0), 1 (u = 1), 2 (v = 1), 3 (u = 0), -1 on
      a boundary; where the neighbour is refined further, the one touching the side's corner at the
      start of the side in the neighbour's own order.
    - ``points_dev``, ``first_dev``, ``levels_dev``: device copies (on the device the table was built for).
    """

    points: np.ndarray
    first: np.ndarray
    levels: np.ndarray
    face: np.ndarray
    domain: np.ndarray
    rotation: np.ndarray
    neighbors: np.ndarray
    points_dev: object = field(repr=False)
    first_dev: object = field(repr=False)
    levels_dev: object = field(repr=False)

    def __len__(self) -> int:
        return len(self.first)


@dataclass
class _Patches:
    """Host-side (float64) patches of a surface, independent of any device."""

    points: np.ndarray  # (P, 3) float64
    ev_normals: np.ndarray  # (n, 3) float64 unit limit normal at a Stam patch's EV; NaN where none is known
    first: np.ndarray
    levels: np.ndarray
    face: np.ndarray
    domain: np.ndarray
    rotation: np.ndarray
    neighbors: np.ndarray
    cell_start: np.ndarray  # per control face: start in `cells`
    cell_res: np.ndarray  # per control face: cells per unit of u and of v
    cells: np.ndarray  # patch id per cell, row-major (v rows, u columns)


def _bspline_basis(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Uniform cubic B-spline basis (N, 4) at t and its derivative (as in kernels/subdivision.h)."""
    s = 1.0 - t
    basis = np.stack([s**3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3], 1) / 6.0
    derivative = np.stack([-0.5 * s**2, 1.5 * t**2 - 2 * t, -1.5 * t**2 + t + 0.5, 0.5 * t**2], 1)
    return basis, derivative


def _ptex_sizes(sizes: np.ndarray) -> np.ndarray:
    """Units of u per control face: 1 for quads, n for n-gons."""
    return np.where(sizes == 4, 1, sizes)


def _build_patches(vertices: np.ndarray, faces: list[np.ndarray]) -> _Patches:
    points = [vertices]
    topos = [_Topology.from_faces(faces, len(vertices))]
    topos[0].check_manifold_vertices()
    t0 = topos[0]
    nonquad_corner = t0.sizes[t0.face_of] != 4
    touches_nonquad = np.bincount(t0.vert[nonquad_corner], minlength=t0.n_vertices) > 0
    # Work items: (level, face at that level, its corners in the control face's (u, v) (4, 2), control
    # face, split?). A control quad is a patch when every face at its corners is a quad and at most one
    # corner is an EV; split=None means "split if it has more than one EV" (all faces are quads there).
    pending = []
    for f in range(len(t0.sizes)):
        corner_v = t0.vert[t0.face_start[f]:t0.face_start[f + 1]]
        if t0.sizes[f] == 4:
            patch = not touches_nonquad[corner_v].any() and (~t0.regular[corner_v]).sum() <= 1
            pending.append((0, f, _UNIT_SQUARE, f, not patch))
        else:
            for j in range(t0.sizes[f]):  # Ptex sub-face j is the n-gon's child j
                corners_uv = np.array([[j, 0.0], [j + 1, 0.0], [j + 1, 1.0], [j, 1.0]])
                pending.append((1, int(t0.face_start[f] + j), corners_uv, f, None))
    records = []  # (level, face, rot, corners_uv in patch order, control face)
    level = 0
    while pending:
        if level > _MAX_REFINE:
            raise RuntimeError("subdivision: faces with more than one extraordinary vertex after refinement")
        if level > 0:
            new_points, child = _cc_step(points[-1], topos[-1])
            points.append(new_points)
            topos.append(_Topology.from_faces(child, len(new_points)))
        topo = topos[level]
        later = []
        for item in pending:
            if item[0] != level:
                later.append(item)
                continue
            _, g, corners_uv, f, split = item
            irregular = np.flatnonzero(~topo.regular[topo.vert[topo.face_start[g]:topo.face_start[g] + 4]])
            if not (len(irregular) > 1 if split is None else split):
                rot = int(irregular[0]) if len(irregular) else 0  # the EV goes to the patch's (0, 0)
                records.append((level, g, rot, corners_uv[_ROTATIONS[rot]], f))
                continue
            centre = corners_uv.mean(axis=0)
            for j in range(4):  # child j: (corner j, edge midpoint, centre, previous edge midpoint)
                child_uv = np.array([corners_uv[j], (corners_uv[j] + corners_uv[(j + 1) % 4]) / 2, centre,
                                     (corners_uv[j] + corners_uv[j - 1]) / 2])
                later.append((level + 1, int(topo.face_start[g] + j), child_uv, f, None))
        pending = later
        level += 1
    return _assemble(points, topos, records, t0)


def _assemble(points, topos, records, t0: _Topology) -> _Patches:
    n = len(records)
    nets: list = [None] * n
    levels = np.zeros(n, dtype=np.uint32)
    groups: dict[tuple, list[tuple[int, np.ndarray]]] = {}
    for p, (level, g, rot, _, _) in enumerate(records):
        topo = topos[level]
        corner_v = topo.vert[_quad_corners(topo, g, rot)]
        if topo.regular[corner_v].all():
            nets[p] = _gather_regular(topo, points[level], g, rot)
        else:
            signature, ids = _local_mesh(topo, g, rot)
            groups.setdefault(signature, []).append((p, points[level][ids]))
    ev_normals = np.full((n, 3), np.nan)
    for signature, members in groups.items():
        weights = _stam_weights(signature)
        local = np.stack([m[1] for m in members], axis=1).reshape(len(weights[0]), -1)  # (m, G * 3)
        # One GEMM for the whole group (a batched (G, m, 3) matmul is ~10x slower at valence 360).
        result = (weights @ local).reshape(len(weights), len(members), 3).transpose(1, 0, 2)  # (G, 48 L + 3, 3)
        stam_levels = (len(weights) - 3) // 48
        normal = np.cross(result[:, -2], result[:, -1])
        with np.errstate(invalid="ignore"):  # zero tangent rows (boundary, valence 2): 0 / 0 = NaN, none known
            normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        for (p, _), net, ev_normal in zip(members, result, normal):
            nets[p] = net[:-2]
            levels[p] = stam_levels
            ev_normals[p] = ev_normal
    sizes = np.array([len(net) for net in nets])
    first = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.uint32)
    corners_uv = np.array([r[3] for r in records])  # (n, 4, 2), patch order
    low, high = corners_uv.min(axis=1), corners_uv.max(axis=1)
    domain = np.concatenate([low, high - low], axis=1)
    box = np.stack([low, np.stack([high[:, 0], low[:, 1]], 1), high, np.stack([low[:, 0], high[:, 1]], 1)], 1)
    rotation = np.argmin(np.abs(box - corners_uv[:, :1, :]).sum(axis=2), axis=1).astype(np.uint8)
    face = np.array([r[4] for r in records], dtype=np.int32)
    # Face lookup cells: res x res cells per unit square of every control face (res = 2^deepest level).
    units = _ptex_sizes(t0.sizes)
    res = np.ones(len(t0.sizes), dtype=np.int64)
    np.maximum.at(res, face, np.round(1.0 / domain[:, 3]).astype(np.int64))
    counts = units * res * res
    cell_start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    cells = np.full(int(counts.sum()), -1, dtype=np.int64)
    for p in range(n):
        f = face[p]
        r = res[f]
        i0, j0 = np.round(domain[p, :2] * r).astype(np.int64)
        i1, j1 = np.round((domain[p, :2] + domain[p, 2:]) * r).astype(np.int64)
        width = units[f] * r
        for j in range(j0, j1):
            cells[cell_start[f] + j * width + i0:cell_start[f] + j * width + i1] = p
    assert (cells >= 0).all(), "subdivision: patch domains do not cover every face"
    return _Patches(
        points=np.concatenate(nets), ev_normals=ev_normals, first=first, levels=levels, face=face, domain=domain,
        rotation=rotation,
        neighbors=_neighbors(topos, records), cell_start=cell_start, cell_res=res, cells=cells,
    )


def _neighbors(topos, records) -> np.ndarray:
    """(n, 4) patch across each side of each patch (see PatchTable)."""
    state = [np.full(len(t.sizes), -1, dtype=np.int64) for t in topos]  # -1: refined or coarser
    for p, (level, g, *_rest) in enumerate(records):
        state[level][g] = p
    covered = [np.zeros(len(t.sizes), dtype=bool) for t in topos]  # a coarser patch covers it
    for level in range(1, len(topos)):
        parent = topos[level - 1].face_of  # child face id == parent corner id
        covered[level] = (state[level - 1][parent] >= 0) | covered[level - 1][parent]

    def resolve(level: int, corner: int) -> int:
        g = topos[level].face_of[corner]
        while covered[level][g]:
            g = topos[level - 1].face_of[g]
            level -= 1
        while state[level][g] < 0:
            # Refined: descend into the child at this corner, keeping to the shared side.
            corner = topos[level + 1].face_start[corner]
            level += 1
            g = topos[level].face_of[corner]
        return int(state[level][g])

    out = np.full((len(records), 4), -1, dtype=np.int32)
    for p, (level, g, rot, _, _) in enumerate(records):
        topo = topos[level]
        for side, c in enumerate(_quad_corners(topo, g, rot)):
            t = topo.twin[c]
            if t >= 0:
                out[p, side] = resolve(level, int(t))
    return out


# -------------------------------------------------------------------------------------------------
# The public surface
# -------------------------------------------------------------------------------------------------
def _checked_uv(u, v) -> tuple[np.ndarray, np.ndarray]:
    """Parameters ``u`` and ``v`` as finite float64 arrays of one (N,) shape (a scalar is one point)."""
    u = finite_array("u", np.atleast_1d(u), ())
    v = finite_array("v", np.atleast_1d(v), ())
    if u.shape != v.shape:
        raise ValueError(f"v: expected the shape of u {u.shape}, got {v.shape}")
    return u, v


def _indices(name: str, value, shape: tuple, count: int) -> np.ndarray:
    """``value`` as int64 indices below ``count``: a scalar (broadcast to ``shape``) or of ``shape``; an
    empty sequence of any dtype is no indices."""
    try:
        array = np.asarray(value)
    except Exception as error:
        raise TypeError(f"{name}: cannot be read as indices ({error})") from None
    if array.size == 0 and array.ndim == 1:
        array = array.astype(np.int64)
    if array.dtype == bool or not np.issubdtype(array.dtype, np.integer):
        raise TypeError(f"{name}: expected integer indices, got dtype {array.dtype}")
    array = np.broadcast_to(array, shape) if array.ndim == 0 else array
    if array.shape != shape:
        raise ValueError(f"{name}: expected a scalar or shape {shape}, got {array.shape}")
    if array.size and (array.min() < 0 or array.max() >= count):
        raise ValueError(f"{name}: index out of range (0 to {count - 1})")
    return array.astype(np.int64)


def _checked_faces(faces, n_vertices: int) -> list[np.ndarray]:
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        rows = list(faces)
    else:
        try:
            rows = list(faces)
        except TypeError:
            raise TypeError(f"faces: expected a sequence of polygons, got {type(faces).__name__}") from None
    if not rows:
        raise ValueError("faces: the control mesh is empty (no faces)")
    out = []
    for i, row in enumerate(rows):
        try:
            array = np.asarray(row)
        except Exception as error:
            raise TypeError(f"faces: face {i} cannot be read as indices ({error})") from None
        if array.dtype == bool or not np.issubdtype(array.dtype, np.integer):
            raise TypeError(f"faces: face {i} must hold integer vertex indices, got dtype {array.dtype}")
        if array.ndim != 1 or len(array) < 3:
            raise ValueError(f"faces: face {i} must list at least 3 vertex indices, got shape {array.shape}")
        if array.min() < 0 or array.max() >= n_vertices:
            bad = int(array.min() if array.min() < 0 else array.max())
            raise ValueError(f"faces: face {i} has vertex index {bad} out of range for {n_vertices} vertices")
        if len(np.unique(array)) != len(array):
            raise ValueError(f"faces: face {i} repeats a vertex ({array.tolist()})")
        out.append(array.astype(np.int64))
    return out


class SubdivisionSurface:
    """The Catmull-Clark limit surface of a polygon control mesh (see the module docstring for rules).

    ``vertices`` (V, 3) float; ``faces`` a sequence of polygons (each a sequence of >= 3 distinct vertex
    indices, consistently oriented; edges shared by at most two faces). Bad input raises ValueError or
    TypeError naming the argument. Surfaces are immutable; :meth:`transformed` makes a new one.
    """

    def __init__(self, vertices, faces):
        vertices = finite_array("vertices", vertices, (3,))
        if len(vertices) == 0:
            raise ValueError("vertices: the control mesh has no vertices")
        self.vertices = vertices.copy()
        self.vertices.flags.writeable = False
        self.faces = _checked_faces(faces, len(vertices))
        for f in self.faces:
            f.flags.writeable = False
        self._units = _ptex_sizes(np.array([len(f) for f in self.faces]))  # u range of each face
        self._patches = _build_patches(self.vertices, self.faces)
        self._tables: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # Device -> PatchTable

    @classmethod
    def load(cls, path) -> "SubdivisionSurface":
        """Read an OBJ control mesh (``v`` and ``f`` lines; texture/normal indices and ``t`` tags ignored);
        a malformed file raises ValueError naming the file and line (see :mod:`shadowcl.meshio`)."""
        if isinstance(path, (str, os.PathLike)) and Path(path).suffix.lower() != ".obj":
            raise ValueError(f"path: expected an .obj control mesh, got {Path(path).suffix!r}")
        polygons = read_polygons(path, suffixes=(".obj",), what="control mesh")
        return cls(polygons.vertices, polygons.polygon_list())

    def __repr__(self) -> str:
        return (f"SubdivisionSurface({len(self.vertices)} vertices, {len(self.faces)} faces, "
                f"{len(self._patches.first)} patches)")

    def transformed(self, matrix) -> "SubdivisionSurface":
        """This surface under a 4x4 affine ``matrix`` (limit surfaces are affine invariant)."""
        matrix = np.asarray(matrix, dtype=np.float64)
        if matrix.shape != (4, 4) or not np.all(np.isfinite(matrix)):
            raise ValueError(f"matrix: expected a finite 4x4 affine matrix, got shape {matrix.shape}")
        vertices = self.vertices @ matrix[:3, :3].T + matrix[:3, 3]
        faces = self.faces if np.linalg.det(matrix[:3, :3]) >= 0 else [f[::-1] for f in self.faces]
        return SubdivisionSurface(vertices, faces)

    @cached_property
    def mesh(self) -> Mesh:
        """The default tessellation (:meth:`tessellate` with :meth:`default_segments`), made on first use,
        so a surface can stand wherever a scene or mesh is expected (``shadow_mask(surface, ...)``)."""
        return self.tessellate()

    @property
    def patch_count(self) -> int:
        """Number of patches in the patch table."""
        return len(self._patches.first)

    def voxelize(self, resolution: int, connectivity: int = 26, device=None):
        """This surface voxelized into a ``resolution``^3 cubic frame buffer with N-adjacency ``connectivity``
        (6, 18 or 26): a :class:`shadowcl.voxelize.Voxelization` (``.occupied``, ``.origin``, ``.voxel_size``)."""
        from . import voxelize  # voxelize builds on this module's patch table

        return voxelize.voxelize(get_device(device), self, resolution, connectivity)

    def patch_table(self, device=None) -> PatchTable:
        """The :class:`PatchTable` (world coordinates) with device buffers on ``device``; cached per device."""
        device = get_device(device)
        table = self._tables.get(device)
        if table is None:
            p = self._patches
            points = np.ascontiguousarray(p.points, dtype=np.float32)
            first = np.ascontiguousarray(p.first, dtype=np.uint32)
            levels = np.ascontiguousarray(p.levels, dtype=np.uint32)
            for array in (points, first, levels):
                array.flags.writeable = False
            table = PatchTable(
                points=points, first=first, levels=levels, face=p.face.copy(), domain=p.domain.copy(),
                rotation=p.rotation.copy(), neighbors=p.neighbors.copy(),
                points_dev=device.to_device(points), first_dev=device.to_device(first),
                levels_dev=device.to_device(levels),
            )
            self._tables[device] = table
        return table

    # Evaluation ------------------------------------------------------------------------------------
    def _parameters(self, face, u, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        u, v = _checked_uv(u, v)
        face = _indices("face", face, u.shape, len(self.faces))
        units = self._units[face]
        if np.any(u < 0) or np.any(u > units) or np.any(v < 0) or np.any(v > 1):
            raise ValueError("u, v: must lie in [0, 1] (u in [0, n] on an n-gon face)")
        return face, u, v

    def locate(self, face, u, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(patch ids, patch u, patch v) of points given by control ``face`` and its (u, v)."""
        face, u, v = self._parameters(face, u, v)
        return self._locate(face, u, v)[:3]

    def _locate(self, face, u, v):
        p = self._patches
        res = p.cell_res[face]
        width = self._units[face] * res
        i = np.clip(np.floor(u * res).astype(np.int64), 0, width - 1)
        j = np.clip(np.floor(v * res).astype(np.int64), 0, res - 1)
        patch = p.cells[p.cell_start[face] + j * width + i]
        u0, v0, du, dv = p.domain[patch].T
        s = np.clip((u - u0) / du, 0.0, 1.0)
        t = np.clip((v - v0) / dv, 0.0, 1.0)
        rot = p.rotation[patch]
        pu = np.choose(rot, [s, t, 1.0 - s, 1.0 - t])
        pv = np.choose(rot, [t, 1.0 - s, 1.0 - t, s])
        return patch, pu, pv, rot, du, dv

    def evaluate_patches(self, patch, u, v, device=None, derivatives: bool = True):
        """Run the ``evaluate`` kernel in patch parameters: (positions, d/du, d/dv), each (N, 3) float32,
        or positions only with ``derivatives=False``."""
        dev = get_device(device)
        table = self.patch_table(dev)
        u, v = _checked_uv(u, v)
        if np.any(u < 0) or np.any(u > 1) or np.any(v < 0) or np.any(v > 1):
            raise ValueError("u, v: patch parameters must lie in [0, 1]")
        patch = np.ascontiguousarray(_indices("patch", patch, u.shape, len(table)), dtype=np.int32)
        u, v = np.ascontiguousarray(u, dtype=np.float32), np.ascontiguousarray(v, dtype=np.float32)
        n = len(patch)
        outs = [dev.empty(12 * n if derivatives or i == 0 else 4, "evaluate output") for i in range(3)]
        if n:
            options = ("-DDERIVATIVES",) if derivatives else ()
            dev.kernel("subdivision.cl", "evaluate", options)(
                dev.queue, (n,), None, table.points_dev, table.first_dev, table.levels_dev,
                dev.to_device(patch), dev.to_device(u), dev.to_device(v), np.int32(n), *outs)
        position = dev.from_device(outs[0], (n, 3), np.float32)
        if not derivatives:
            return position
        return position, dev.from_device(outs[1], (n, 3), np.float32), dev.from_device(outs[2], (n, 3), np.float32)

    def evaluate(self, face, u, v, derivatives: bool = False, device=None):
        """Limit positions (N, 3) float32 at control ``face`` (int or (N,) ints) and parameters u, v (N,).

        With ``derivatives=True``, returns (positions, dP/du, dP/dv) in the face's parameters (zero
        derivatives exactly at an extraordinary vertex). Runs the OpenCL ``evaluate`` kernel.
        """
        face, u, v = self._parameters(face, u, v)
        patch, pu, pv, rot, du, dv = self._locate(face, u, v)
        if not derivatives:
            return self.evaluate_patches(patch, pu, pv, device, derivatives=False)
        position, d_u, d_v = self.evaluate_patches(patch, pu, pv, device)
        # Chain rule through the patch's rotation and its domain's size.
        d_s = np.choose(rot[:, None], [d_u, -d_v, -d_u, d_v]) / du[:, None]
        d_t = np.choose(rot[:, None], [d_v, d_u, -d_v, -d_u]) / dv[:, None]
        return position, d_s.astype(np.float32), d_t.astype(np.float32)

    def limit_normals(self, face, u, v, device=None) -> np.ndarray:
        """Unit limit normals (N, 3) float32, dP/du x dP/dv (outward for counter-clockwise faces).

        Within 2^-10 of an extraordinary vertex (in patch parameters) the float32 sub-patch points
        differ by little more than their rounding, so the derivatives there are taken on the host in
        float64 from the same Stam sub-patches. At an interior EV itself (below 2^-L) the closed-form
        limit normal (tangent masks); at a boundary or valence-2 EV, the normal at (2^-L, 2^-L) of each
        patch (a valence-2 vertex has no single tangent plane: its two patches' normals may differ).
        """
        face, u, v = self._parameters(face, u, v)
        patch, pu, pv, rot, du, dv = self._locate(face, u, v)
        _, d_u, d_v = self.evaluate_patches(patch, pu, pv, device)
        d_u, d_v = d_u.astype(np.float64), d_v.astype(np.float64)
        levels = self._patches.levels[patch]
        near = (levels > 0) & (np.maximum(pu, pv) < NEAR_EV)
        if near.any():
            d_u[near], d_v[near] = self._stam_derivatives(patch[near], pu[near], pv[near])
        normal = np.cross(d_u, d_v)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        # At the EV itself (where patch_eval returns its limit position): the closed-form limit normal.
        ev_normal = self._patches.ev_normals[patch]
        at_ev = (levels > 0) & (np.maximum(pu, pv) < 2.0 ** -levels.astype(np.float64)) & np.isfinite(ev_normal[:, 0])
        normal[at_ev] = ev_normal[at_ev]
        return normal.astype(np.float32)

    def _stam_derivatives(self, patch, u, v) -> tuple[np.ndarray, np.ndarray]:
        """float64 (dP/du, dP/dv) on Stam patches (host version of patch_eval's sub-domain choice)."""
        p = self._patches
        levels = p.levels[patch].astype(np.int64)
        floor = 2.0 ** -levels
        inside = np.maximum(u, v) < floor
        u, v = np.where(inside, floor, u), np.where(inside, floor, v)
        _, exponent = np.frexp(np.maximum(u, v))  # max(u, v) in [2^(e-1), 2^e)
        n = np.clip(1 - exponent, 1, levels)
        scale = 2.0 ** n
        uu, vv = u * scale, v * scale
        k = np.where(vv < 1.0, 0, np.where(uu >= 1.0, 1, 2))
        uu = np.where(k < 2, uu - 1.0, uu)
        vv = np.where(k > 0, vv - 1.0, vv)
        first = p.first[patch].astype(np.int64) + ((n - 1) * 3 + k) * 16
        net = p.points[first[:, None] + np.arange(16)].reshape(-1, 4, 4, 3)  # [point, j, i, xyz]
        bu, bu_d = _bspline_basis(uu)
        bv, bv_d = _bspline_basis(vv)
        d_u = np.einsum("pj,pi,pjix->px", bv, bu_d, net) * scale[:, None]
        d_v = np.einsum("pj,pi,pjix->px", bv_d, bu, net) * scale[:, None]
        return d_u, d_v

    # Tessellation ----------------------------------------------------------------------------------
    def tessellate(self, level: "int | None" = None, segments: "int | None" = None, device=None) -> Mesh:
        """A triangle :class:`Mesh` of points on the limit surface: ``segments`` (or 2^``level``) per
        control edge, each quad a segments x segments grid of cells, each n-gon sub-face
        (segments / 2)^2 cells (segments must then be even); each cell is two triangles.

        Crack-free by construction: a point on a control vertex or edge is evaluated once and shared by
        every face around it. Without ``level`` and ``segments``, :meth:`default_segments` is used.
        """
        segments = self._checked_segments(level, segments)
        if segments is None:
            segments = self.default_segments(device=device)
        face, u, v, triangles, _ = self._tessellation(segments)
        return Mesh(self.evaluate(face, u, v, device=device), triangles)

    def default_segments(self, tolerance: float = TESSELLATION_TOLERANCE, device=None) -> int:
        """The smallest power of two of segments per control edge whose :meth:`chord_error` is within
        ``tolerance`` x (control mesh bounding-box diagonal), capped at 256."""
        diagonal = float(np.linalg.norm(self.vertices.max(axis=0) - self.vertices.min(axis=0)))
        segments = 2
        while segments < 256 and self.chord_error(segments, device) > tolerance * diagonal:
            segments *= 2
        return segments

    def chord_error(self, segments: int, device=None) -> float:
        """Largest distance, along the limit normal, between the limit surface at a tessellation cell's
        centre and the midpoint of that cell's triangle diagonal, for ``segments`` per control edge.

        Along the normal only: near an extraordinary vertex uniform parameters give curved cells whose
        centre moves sideways within the tangent plane; that moves no surface and casts no shadow.
        """
        face, u, v, triangles, centres = self._tessellation(segments)
        corners = self.evaluate(face, u, v, device=device).astype(np.float64)
        centre = self.evaluate(*centres, device=device).astype(np.float64)
        normal = self.limit_normals(*centres, device=device).astype(np.float64)
        # Cells are triangle pairs (p00, p10, p11), (p00, p11, p01): p00-p11 is the cell's diagonal.
        first = triangles[0::2]
        midpoint = (corners[first[:, 0]] + corners[first[:, 2]]) / 2.0
        return float(np.abs(np.einsum("ij,ij->i", centre - midpoint, normal)).max())

    def _checked_segments(self, level, segments) -> "int | None":
        if level is not None and segments is not None:
            raise ValueError("level, segments: give one of them, not both")
        if level is not None:
            segments = 2 ** positive_int("level", level, minimum=0, maximum=10)
        elif segments is not None:
            segments = positive_int("segments", segments, maximum=1024)
        else:
            return None
        if segments % 2 and any(len(f) != 4 for f in self.faces):
            raise ValueError(f"segments: must be even on a control mesh with non-quad faces, got {segments}")
        cells = sum(segments ** 2 if len(f) == 4 else len(f) * (segments // 2) ** 2 for f in self.faces)
        if cells > MAX_TESSELLATION_CELLS:
            raise ValueError(f"segments: {segments} per control edge make {cells:,} cells on this control mesh; "
                             f"at most {MAX_TESSELLATION_CELLS:,} are allowed (tessellation memory and time)")
        return segments

    def _tessellation(self, segments: int):
        """(face, u, v) of every tessellation vertex (shared points once), the (T, 3) triangles (two per
        cell, cells in order) and (face, u, v) of every cell's centre."""
        keys: dict[tuple, int] = {}
        face_of, us, vs = [], [], []
        triangles, centres = [], []

        def edge_key(x, y, t):
            if t == 0:
                return ("v", x)
            if t == segments:
                return ("v", y)
            return ("e", x, y, t) if x < y else ("e", y, x, segments - t)

        for f, corners in enumerate(self.faces):
            corners = corners.tolist()
            n = len(corners)
            size = segments if n == 4 else segments // 2
            for j in range(1 if n == 4 else n):
                grid = np.empty((size + 1, size + 1), dtype=np.int64)
                for b in range(size + 1):
                    for a in range(size + 1):
                        if n == 4:
                            key = self._quad_key(f, corners, a, b, segments, edge_key)
                        else:
                            key = self._ngon_key(f, corners, j, a, b, size, segments, edge_key)
                        index = keys.get(key)
                        if index is None:
                            index = keys[key] = len(face_of)
                            face_of.append(f)
                            if n != 4 and a == size:
                                # u = j + 1 would select sub-face j + 1: name the point from there.
                                u_, v_ = (n, 1.0) if b == size else ((j + 1) % n + b / size, 1.0)
                            else:
                                u_, v_ = j + a / size, b / size
                            us.append(u_)
                            vs.append(v_)
                        grid[b, a] = index
                p00, p10 = grid[:-1, :-1].ravel(), grid[:-1, 1:].ravel()
                p01, p11 = grid[1:, :-1].ravel(), grid[1:, 1:].ravel()
                pair = np.stack([np.stack([p00, p10, p11], 1), np.stack([p00, p11, p01], 1)], 1)
                triangles.append(pair.reshape(-1, 3))
                cu, cv = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(size) + 0.5) / size)
                centres.append(np.stack([np.full(cu.size, f), j + cu.ravel(), cv.ravel()]))
        centres = np.concatenate(centres, axis=1)
        return (np.array(face_of), np.array(us, dtype=np.float64), np.array(vs, dtype=np.float64),
                np.concatenate(triangles), (centres[0].astype(np.int64), centres[1], centres[2]))

    @staticmethod
    def _quad_key(f, c, a, b, s, edge_key) -> tuple:
        if b == 0:
            return edge_key(c[0], c[1], a)
        if a == s:
            return edge_key(c[1], c[2], b)
        if b == s:
            return edge_key(c[2], c[3], s - a)
        if a == 0:
            return edge_key(c[3], c[0], s - b)
        return ("f", f, a, b)

    @staticmethod
    def _ngon_key(f, c, j, a, b, h, s, edge_key) -> tuple:
        n = len(c)
        if b == 0:
            return edge_key(c[j], c[(j + 1) % n], a)
        if a == 0:
            return edge_key(c[j - 1], c[j], s - b)
        if a == h and b == h:
            return ("c", f)
        if a == h:
            return ("l", f, j, b)
        if b == h:
            return ("l", f, (j - 1) % n, a)
        return ("f", f, j, a, b)
