"""Mesh topology, one answer per question: edge adjacency, connected components, closedness and
orientation, concave edges, and whether a point lies inside a closed solid. Every method asks here.

Policies (the callers rely on these meanings; tests/test_topology.py checks them):

- **Edge adjacency** (:class:`EdgeAdjacency`, cached per mesh by :func:`edge_adjacency`): the mesh's
  unique undirected edges, the faces around each and the way each runs along it. Faces with a
  repeated vertex index have no edges (``collapsed_faces``). Vertices are not welded.
- **Components** (:func:`components`): connected components of any undirected graph given as node
  pairs, by scipy's ``connected_components`` (labels 0.. in order of each component's least node).
  :attr:`EdgeAdjacency.components` joins faces through shared edges.
- **Closed** (:attr:`EdgeAdjacency.closed_faces`): a component is closed when every edge in it has
  exactly two faces and they run opposite ways along it. A border edge, a non-manifold edge (three or
  more faces) or an inconsistently wound edge makes its whole component open. This is the meaning
  that matters to shadows: only in a closed, consistently wound component does a blocked ray always
  cross a light-facing face (angular keeps only those faces; shadow volumes keep those one-sided).
  Shadow volumes first detach the faces of non-manifold and misoriented edges; the pieces round
  them then have border edges, so the same components come out open either way.
- **Concave edges** (:func:`concave_edges`): a two-face edge folds inwards when the second face's far
  corner lies above the first face's plane by more than :data:`CONCAVE_SINE` of its distance (the sine
  of the fold): float32 vertices make flat edges look folded by ~1e-7, which is neither a valley for a
  chord nor a place where silhouette loops are born.
- **A point inside a closed solid** (:meth:`EdgeAdjacency.enclosing_faces`): the winding number of a
  closed component round the point, summed from the faces' signed solid angles (Van Oosterom &
  Strackee), is more than 1/2 in size. Chosen over ray parity: it needs no random direction redrawn
  when the ray grazes an edge, is the same in both windings, and away from the surface it is an
  integer to rounding. Per component, as both methods need it: a cavity's wall is a closed component
  of its own (wound inwards), so a point in a cavity counts as enclosed. What a method does with a light
  inside is its own: angular refuses, shadow volumes go two-sided.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .geometry import Mesh, per_mesh

CONCAVE_SINE = 1e-6     # concave_edges: smallest fold (sine) that counts; see the module doc

NO_FACE = -1            # EdgeAdjacency.edge_faces: the missing face of a border edge (kernels/silhouette.cl too)

_CACHE: "weakref.WeakKeyDictionary[Mesh, EdgeAdjacency]" = weakref.WeakKeyDictionary()


@dataclass(frozen=True, eq=False)
class EdgeAdjacency:
    """The unique undirected edges of a mesh and the faces around each.

    ``vertices`` and ``faces`` are the mesh's own (read-only) arrays; the table keeps them rather than
    the mesh so that the per-mesh cache, weakly keyed on the mesh, does not keep it alive.
    ``edges`` (E, 2) int32 vertex ids, first < second, sorted; ``face_offsets`` (E + 1,) and
    ``face_items`` list every edge's faces (CSR, face ids ascending) and ``face_senses`` whether each
    runs along the edge (+1, first vertex to second) or against it (-1); ``edge_faces`` (E, 2) holds
    the first two faces (-1 where a border edge has none). ``collapsed_faces``: faces with a repeated
    vertex index, left out of the table.
    """

    vertices: np.ndarray
    faces: np.ndarray
    edges: np.ndarray
    face_offsets: np.ndarray
    face_items: np.ndarray
    face_senses: np.ndarray
    collapsed_faces: np.ndarray
    _device_buffers: dict = field(default_factory=dict, repr=False)   # silhouette.classify's copies, per device

    @cached_property
    def face_count(self) -> np.ndarray:
        """(E,) number of faces on each edge."""
        return np.diff(self.face_offsets).astype(np.int32)

    @cached_property
    def edge_faces(self) -> np.ndarray:
        """(E, 2) int32: each edge's first two faces, -1 for the missing face of a border edge."""
        return self._first_two(self.face_items, NO_FACE).astype(np.int32)

    @cached_property
    def edge_senses(self) -> np.ndarray:
        """(E, 2) int8: the senses of :attr:`edge_faces` (0 for a missing face)."""
        return self._first_two(self.face_senses, 0).astype(np.int8)

    def _first_two(self, items: np.ndarray, missing) -> np.ndarray:
        """(E, 2): the first two CSR ``items`` of each edge, ``missing`` where an edge has one."""
        first = self.face_offsets[:-1]
        second = items[np.minimum(first + 1, len(items) - 1)]       # clamped: a last edge with one face
        return np.stack([items[first], np.where(self.face_count > 1, second, missing)], axis=1)

    @cached_property
    def border_edges(self) -> np.ndarray:
        """Indices of edges with one face."""
        return np.flatnonzero(self.face_count == 1)

    @cached_property
    def nonmanifold_edges(self) -> np.ndarray:
        """Indices of edges with three or more faces."""
        return np.flatnonzero(self.face_count > 2)

    @cached_property
    def misoriented_edges(self) -> np.ndarray:
        """Indices of two-face edges whose faces run the same way along them (inconsistent winding)."""
        senses = self.edge_senses
        return np.flatnonzero((self.face_count == 2) & (senses[:, 0] == senses[:, 1]))

    @property
    def is_closed_manifold(self) -> bool:
        """Every edge has exactly two faces."""
        return bool(np.all(self.face_count == 2))

    def require_manifold(self, what: str = "mesh") -> None:
        """Raise ``ValueError`` naming ``what`` if an edge has three or more faces or the winding is
        inconsistent: consumers that orient edges (loops, shadow volumes) call this first."""
        if len(self.nonmanifold_edges):
            e = self.nonmanifold_edges[0]
            raise ValueError(
                f"{what}: {len(self.nonmanifold_edges)} non-manifold edges (three or more faces), first "
                f"{self.edges[e].tolist()} with faces {self.faces_of(e).tolist()}; silhouettes need one or two "
                "faces per edge")
        if len(self.misoriented_edges):
            e = self.misoriented_edges[0]
            raise ValueError(
                f"{what}: {len(self.misoriented_edges)} edges whose two faces are wound the same way, first "
                f"{self.edges[e].tolist()} with faces {self.faces_of(e).tolist()}; orient the faces consistently")

    @cached_property
    def components(self) -> np.ndarray:
        """(F,) int: each face's connected component, faces joined through shared edges (any number of
        faces on the edge); a collapsed face is a component of its own."""
        owner = np.repeat(np.arange(len(self.edges)), self.face_count)       # edge of each CSR face item
        first = self.face_items[self.face_offsets[:-1]][owner]               # every face joined to its edge's first
        return components(len(self.faces), np.stack([first, self.face_items], axis=1))

    @cached_property
    def closed_faces(self) -> np.ndarray:
        """(F,) bool: faces of closed components (see the module doc: every edge of the component has
        exactly two faces wound opposite ways along it)."""
        bad = np.ones(len(self.edges), dtype=bool)
        bad[self.face_count == 2] = False
        bad[self.misoriented_edges] = True
        label = self.components
        owner = np.repeat(np.arange(len(self.edges)), self.face_count)
        open_label = np.zeros(label.max(initial=-1) + 1, dtype=bool)
        open_label[label[self.face_items[bad[owner]]]] = True
        return ~open_label[label]

    @cached_property
    def _closed_boxes(self) -> tuple:
        """The closed faces grouped by component: (face ids, group sizes, per group low and high corner)."""
        label = self.components
        closed = np.flatnonzero(self.closed_faces)
        closed = closed[np.argsort(label[closed], kind="stable")]
        corners = self.vertices[self.faces[closed]]
        starts = np.flatnonzero(np.r_[True, np.diff(label[closed]) != 0]) if len(closed) else np.zeros(0, np.int64)
        sizes = np.diff(np.r_[starts, len(closed)])
        if not len(closed):
            return closed, sizes, corners[:0, 0], corners[:0, 0]
        return (closed, sizes, np.minimum.reduceat(corners.min(axis=1), starts),
                np.maximum.reduceat(corners.max(axis=1), starts))

    def enclosing_faces(self, point) -> np.ndarray:
        """Face ids of the closed components that enclose ``point`` ((3,)): whose winding number round it
        (:func:`winding_number`) is more than 1/2 in size, either winding. Only components whose bounding
        box holds the point are summed (the box test is cached; 1.1 s for 1.2 M faces otherwise)."""
        point = np.asarray(point, dtype=np.float64)
        closed, sizes, low, high = self._closed_boxes
        closed = closed[np.repeat(np.all((low <= point) & (point <= high), axis=1), sizes)]
        if not len(closed):
            return closed
        group = np.unique(self.components[closed], return_inverse=True)[1]
        windings = np.bincount(group, weights=solid_angles(self.vertices[self.faces[closed]], point)) / (4 * np.pi)
        return closed[np.abs(windings[group]) > 0.5]

    def faces_of(self, edge: int) -> np.ndarray:
        """The faces around ``edge``."""
        return self.face_items[self.face_offsets[edge]:self.face_offsets[edge + 1]]


def _half_edges(faces: np.ndarray, face_ids: np.ndarray):
    """The three directed edges of each face, face by face: (tails, heads, face ids)."""
    return faces.reshape(-1), faces[:, [1, 2, 0]].reshape(-1), np.repeat(face_ids, 3)


def edge_adjacency(mesh: Mesh) -> EdgeAdjacency:
    """The :class:`EdgeAdjacency` of ``mesh``, built once per mesh (sort-based, vectorised)."""
    return per_mesh(_CACHE, mesh, _build_adjacency)


def _build_adjacency(mesh: Mesh) -> EdgeAdjacency:
    faces = mesh.faces.astype(np.int64)
    collapsed = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    kept = np.flatnonzero(~collapsed)
    tails, heads, owners = _half_edges(faces[kept], kept)
    low, high = np.minimum(tails, heads), np.maximum(tails, heads)
    # Sort half-edges by (low, high, face): equal keys are one edge, its faces ascending.
    order = np.lexsort((owners, high, low))
    low, high, owners = low[order], high[order], owners[order]
    senses = np.where(tails[order] < heads[order], 1, -1).astype(np.int8)
    first = np.ones(len(low), dtype=bool)
    first[1:] = (low[1:] != low[:-1]) | (high[1:] != high[:-1])
    starts = np.flatnonzero(first)
    return EdgeAdjacency(
        vertices=mesh.vertices,
        faces=mesh.faces,
        edges=np.stack([low[starts], high[starts]], axis=1).astype(np.int32),
        face_offsets=np.r_[starts, len(low)].astype(np.int64),
        face_items=owners.astype(np.int32),
        face_senses=senses,
        collapsed_faces=np.flatnonzero(collapsed),
    )


def components(count: int, pairs) -> np.ndarray:
    """(count,) int: connected-component label of each of ``count`` nodes for undirected edges ``pairs``
    ((E, 2) node ids), labels 0.. in order of each component's least node."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(pairs), dtype=np.int8), (pairs[:, 0], pairs[:, 1])), shape=(count, count))
    return connected_components(graph, directed=False)[1]


def solid_angles(triangles: np.ndarray, point: np.ndarray) -> np.ndarray:
    """(T,) float64 signed solid angle of each triangle ((T, 3, 3)) seen from ``point`` (Van Oosterom &
    Strackee): positive when the triangle winds counter-clockwise seen from outside (point behind it)."""
    a, b, d = (np.asarray(triangles[:, i], dtype=np.float64) - point for i in range(3))
    la, lb, ld = (np.linalg.norm(x, axis=1) for x in (a, b, d))
    det = np.einsum("ij,ij->i", a, np.cross(b, d))
    den = la * lb * ld + np.einsum("ij,ij->i", a, b) * ld + np.einsum("ij,ij->i", a, d) * lb \
        + np.einsum("ij,ij->i", b, d) * la
    return 2 * np.arctan2(det, den)


def winding_number(triangles: np.ndarray, point) -> float:
    """The winding number of the surface ``triangles`` ((T, 3, 3)) round ``point``: +1 inside a closed
    surface wound outwards, -1 wound inwards, 0 outside (fractional near an open surface)."""
    return float(solid_angles(triangles, np.asarray(point, dtype=np.float64)).sum() / (4 * np.pi))


def concave_edges(adjacency: EdgeAdjacency, edges=None, min_degrees: float = 0.0) -> np.ndarray:
    """Ascending ids of the two-face edges among ``edges`` (default: every edge) that fold inwards
    (the surface makes a valley there: see the module doc) by at least ``min_degrees`` (the angle
    between the two face normals)."""
    ids = np.flatnonzero(adjacency.face_count == 2) if edges is None else np.asarray(edges, dtype=np.int64)
    ids = ids[adjacency.face_count[ids] == 2]
    f = adjacency.edge_faces[ids]
    v = np.asarray(adjacency.vertices, dtype=np.float64)
    tri = v[adjacency.faces[f[:, 0]]]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ends = adjacency.edges[ids]
    far = adjacency.faces[f[:, 1]].astype(np.int64).sum(axis=1) - ends.sum(axis=1)    # face 2's corner off the edge
    out = v[far] - v[ends[:, 0]]
    length = np.linalg.norm(normal, axis=1)
    rise = np.einsum("ij,ij->i", normal, out)
    concave = rise > CONCAVE_SINE * length * np.linalg.norm(out, axis=1)
    if min_degrees > 0:
        other = v[adjacency.faces[f[:, 1]]]
        normal1 = np.cross(other[:, 1] - other[:, 0], other[:, 2] - other[:, 0])
        cosine = np.einsum("ij,ij->i", normal, normal1) / np.maximum(length * np.linalg.norm(normal1, axis=1), 1e-300)
        concave &= np.degrees(np.arccos(np.clip(cosine, -1, 1))) >= min_degrees
    return np.sort(ids[concave])
