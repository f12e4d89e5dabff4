"""Silhouette (ridge) edges of a mesh against a light: the edge adjacency table, brute-force
classification on the device (kernels/silhouette.cl), and ordered loops.

One module serves the shadow-volume method (issue 6: extrude the oriented edges) and the angular
span table (issue 7: ridge-edge loops). Fawad, Wang & Wu, section III.B: an edge is a silhouette edge
when exactly one of its two faces faces the light.

Rules (the kernel, the reference and the tests share them):

- **Facing**: n = (v1 - v0) x (v2 - v0), s = n . (L - v0) for a point light, s = -n . d for a
  directional light travelling along d; light-facing means s > 0 strictly. A zero-area face and a face
  whose plane contains the light face no light.
- **Border edges** (one face) are silhouette edges when their face is light-facing: the missing face
  counts as not light-facing. The silhouettes are then the boundary of the light-facing region, so a
  shadow volume made of the light-facing faces, their silhouettes extruded and the same faces at
  infinity is closed for an open mesh too.
- **Degenerate faces**: a face with a repeated vertex index has no edges of its own (its "edges" are
  a point and a doubled segment, which would make a manifold edge look non-manifold); it is left out
  of the table and listed in :attr:`EdgeAdjacency.collapsed_faces`. A zero-area face with three
  distinct vertices (a sliver closing a T-junction) stays in the table and faces no light, so its
  edges next to light-facing faces are silhouettes of opposite sense that cancel in a volume.
- **Non-manifold edges** (three or more faces) are kept in the table, listed in
  :attr:`EdgeAdjacency.nonmanifold_edges`, given the code :data:`NONMANIFOLD` by the classifier (never
  dropped), and refused by :func:`silhouette_loops` and :meth:`EdgeAdjacency.require_manifold`.
- **Orientation**: a silhouette edge is oriented as its light-facing face runs along it, so with
  consistently wound faces the light-facing side is always on the same side of the oriented edge.
- **Ties**: the device decides in float32; faces whose plane passes within a rounding band of the
  light may differ from the float64 reference (see ``reference/silhouette.py``: ``tie_faces``).

Tables follow the mesh's vertex indices: vertices repeated at texture seams are not welded, so a
seam is a pair of border edges.

>>> adjacency = edge_adjacency(mesh)                     # cached per mesh
>>> sil = silhouette_edges(device, adjacency, light)     # codes, mask, oriented edges
>>> loops = silhouette_loops(sil)                        # closed vertex chains
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .device import get_device
from .geometry import Mesh
from .lights import Light, PointLight, check_light

NONMANIFOLD = 2         # kernels/silhouette.cl: SIL_NONMANIFOLD
NO_FACE = -1            # kernels/silhouette.cl
MANY_FACES = -2

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
    _device_buffers: dict = field(default_factory=dict, repr=False)

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

    def faces_of(self, edge: int) -> np.ndarray:
        """The faces around ``edge``."""
        return self.face_items[self.face_offsets[edge]:self.face_offsets[edge + 1]]

    def device_buffers(self, device) -> tuple:
        """(vertices, faces, kernel edge faces, edge senses) on ``device``, uploaded once per device."""
        buffers = self._device_buffers.get(device)
        if buffers is None:
            kernel_faces = self.edge_faces.copy()
            kernel_faces[self.face_count > 2, 1] = MANY_FACES
            buffers = tuple(device.to_device(a) for a in (self.vertices, self.faces, kernel_faces, self.edge_senses))
            self._device_buffers[device] = buffers
        return buffers


def _half_edges(faces: np.ndarray, face_ids: np.ndarray):
    """The three directed edges of each face, face by face: (tails, heads, face ids)."""
    return faces.reshape(-1), faces[:, [1, 2, 0]].reshape(-1), np.repeat(face_ids, 3)


def edge_adjacency(mesh: Mesh) -> EdgeAdjacency:
    """The :class:`EdgeAdjacency` of ``mesh``, built once per mesh (sort-based, vectorised)."""
    cached = _CACHE.get(mesh)
    if cached is None:
        cached = _build_adjacency(mesh)
        _CACHE[mesh] = cached
    return cached


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


@dataclass(frozen=True, eq=False)
class Silhouette:
    """Silhouette edges of one mesh against one light.

    ``codes`` (E,) int8 per edge of ``adjacency``: 0 none; +1 silhouette whose light-facing face runs
    from the edge's first vertex to its second; -1 the other way; :data:`NONMANIFOLD` not classified.
    ``facing`` (F,) bool: light-facing faces.
    """

    adjacency: EdgeAdjacency
    light: Light
    codes: np.ndarray
    facing: np.ndarray

    @cached_property
    def mask(self) -> np.ndarray:
        """(E,) bool: silhouette edges."""
        return np.abs(self.codes) == 1

    @cached_property
    def indices(self) -> np.ndarray:
        """Edge indices of the silhouette edges."""
        return np.flatnonzero(self.mask)

    @cached_property
    def oriented(self) -> np.ndarray:
        """(S, 2) int32 vertex ids of the silhouette edges, in :attr:`indices` order, each running as its
        light-facing face does."""
        index = self.indices
        pairs = self.adjacency.edges[index]
        return np.where((self.codes[index] > 0)[:, None], pairs, pairs[:, ::-1])

    @property
    def nonmanifold(self) -> np.ndarray:
        """Edge indices left unclassified because they have three or more faces."""
        return np.flatnonzero(self.codes == NONMANIFOLD)


def silhouette_edges(device, adjacency: "EdgeAdjacency | Mesh", light) -> Silhouette:
    """Classify every edge of ``adjacency`` against ``light`` on ``device`` (brute force, two kernels).

    ``device``: a :class:`~shadowcl.Device`, a selector, or None for the default device.
    ``adjacency``: an :class:`EdgeAdjacency` or a :class:`~shadowcl.Mesh` (its cached table).
    ``light``: a :class:`~shadowcl.PointLight` or :class:`~shadowcl.DirectionalLight`. The module
    docstring gives the rules for facing, border, degenerate and non-manifold edges.
    """
    device = get_device(device)
    if isinstance(adjacency, Mesh):
        adjacency = edge_adjacency(adjacency)
    elif not isinstance(adjacency, EdgeAdjacency):
        raise TypeError(f"adjacency: expected an EdgeAdjacency or a Mesh, got {type(adjacency).__name__}")
    light = check_light(light)
    point = isinstance(light, PointLight)
    vector = light.position if point else light.direction
    options = (f"-DLIGHT_POINT={int(point)}",)
    vertices_g, faces_g, edge_faces_g, edge_senses_g = adjacency.device_buffers(device)
    nfaces, nedges = len(adjacency.faces), len(adjacency.edges)
    facing_g = device.empty(nfaces, "face facing")
    codes_g = device.empty(nedges, "edge codes")
    queue = device.queue
    device.kernel("silhouette.cl", "face_facing", options)(
        queue, (nfaces,), None, vertices_g, faces_g, np.int32(nfaces), *(np.float32(c) for c in vector), facing_g)
    device.kernel("silhouette.cl", "classify_edges", options)(
        queue, (max(nedges, 1),), None, edge_faces_g, edge_senses_g, np.int32(nedges), facing_g, codes_g)
    return Silhouette(adjacency, light,
                      codes=device.from_device(codes_g, nedges, np.int8),
                      facing=device.from_device(facing_g, nfaces, np.uint8).astype(bool))


@dataclass(frozen=True)
class Loop:
    """One closed chain of oriented silhouette edges: ``vertices[i] -> vertices[i + 1]`` (wrapping
    around) is the edge ``edges[i]`` of the adjacency table."""

    vertices: np.ndarray
    edges: np.ndarray


def silhouette_loops(silhouette: Silhouette) -> list[Loop]:
    """The silhouette edges chained into closed loops, each edge followed by one leaving its head.

    Every vertex has as many silhouette edges arriving as leaving when the winding is consistent and
    every edge has one or two faces (the silhouettes bound the light-facing region), so the loops
    close; a vertex where several loops touch pairs its arriving and leaving edges in edge order.
    Raises ``ValueError`` for non-manifold or inconsistently wound meshes, and if a vertex is
    unbalanced.
    """
    silhouette.adjacency.require_manifold("silhouette_loops: mesh")
    index = silhouette.indices
    tails, heads = silhouette.oriented.T
    unbalanced = np.flatnonzero(vertex_balance(silhouette))
    if len(unbalanced):
        raise ValueError(f"silhouette_loops: {len(unbalanced)} vertices with unequal arriving and leaving "
                         f"silhouette edges, first {unbalanced[:5].tolist()}; the loops cannot close")
    # Sorted by vertex, the k-th edge arriving at v is followed by the k-th edge leaving v.
    leaving = np.argsort(tails, kind="stable")
    arriving = np.argsort(heads, kind="stable")
    successor = np.empty(len(index), dtype=np.int64)
    successor[arriving] = leaving
    return [Loop(vertices=tails[chain], edges=index[chain]) for chain in _cycles(successor)]


def vertex_balance(silhouette: Silhouette) -> np.ndarray:
    """(V,) silhouette edges leaving minus arriving at each vertex: zero everywhere when loops close."""
    tails, heads = silhouette.oriented.T
    nvertices = len(silhouette.adjacency.vertices)
    return np.bincount(tails, minlength=nvertices) - np.bincount(heads, minlength=nvertices)


def _cycles(successor: np.ndarray) -> list[np.ndarray]:
    """The cycles of the permutation ``successor``, each from its lowest member, lowest first.

    Vectorised by pointer doubling (log2 of the length rounds) rather than a Python walk per edge:
    first each member learns its cycle's lowest member, then its distance to the member before it.
    """
    n = len(successor)
    rounds = max(int(np.ceil(np.log2(max(n, 1)))), 1)
    lowest, jump = np.arange(n), successor
    for _ in range(rounds):                       # after k rounds: the minimum over 2**k steps ahead
        lowest, jump = np.minimum(lowest, lowest[jump]), jump[jump]
    last = successor == lowest                    # the member whose successor starts the cycle
    jump = np.where(last, np.arange(n), successor)
    to_last = (~last).astype(np.int64)
    for _ in range(rounds):                       # list ranking: steps to the cycle's last member
        to_last, jump = to_last + to_last[jump], jump[jump]
    order = np.lexsort((-to_last, lowest))
    return np.split(order, np.flatnonzero(np.diff(lowest[order])) + 1) if n else []
