"""Brute-force silhouette classification: light-facing faces (on the device, and bit for bit on the
host) and the code of every edge against one light (kernels/silhouette.cl). Rules: the package doc."""

from __future__ import annotations

from functools import cached_property

import numpy as np

from ..device import get_device
from ..geometry import Mesh
from ..lights import Light, PointLight, check_light
from ..topology import EdgeAdjacency, edge_adjacency


NONMANIFOLD = 2         # kernels/silhouette.cl: SIL_NONMANIFOLD
MANY_FACES = -2         # kernels/silhouette.cl: an edge's second face when it has three or more
class Silhouette:
    """Silhouette edges of one mesh against one light.

    ``codes`` (E,) int8 per edge of ``adjacency``: 0 none; +1 silhouette whose light-facing face runs
    from the edge's first vertex to its second; -1 the other way; :data:`NONMANIFOLD` not classified.
    ``facing`` (F,) bool: light-facing faces. When not given (a :class:`SilhouetteTracker` tests only
    some faces), it is computed for every face on first use: by the ``face_facing`` kernel on
    ``device`` if one is given, else by :func:`host_facing` (the same bits).
    """

    def __init__(self, adjacency: EdgeAdjacency, light: Light, codes: np.ndarray, facing: "np.ndarray | None" = None,
                 device=None):
        self.adjacency, self.light, self.codes, self._device = adjacency, light, codes, device
        if facing is not None:
            self.__dict__["facing"] = facing            # the cached_property's slot

    def __repr__(self) -> str:
        return f"Silhouette({len(self.indices)} of {len(self.codes)} edges, light={self.light!r})"

    @cached_property
    def facing(self) -> np.ndarray:
        """(F,) bool: light-facing faces."""
        if self._device is None:
            return host_facing(self.adjacency.vertices, self.adjacency.faces, self.light)
        return face_facing(self._device, self.adjacency, self.light)

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
    facing_g, options = _facing_on_device(device, adjacency, light)
    _, _, edge_faces_g, edge_senses_g = adjacency_buffers(device, adjacency)
    nfaces, nedges = len(adjacency.faces), len(adjacency.edges)
    codes_g = device.empty(nedges, "edge codes")
    device.kernel("silhouette.cl", "classify_edges", options)(
        device.queue, _global_size(nedges), None, edge_faces_g, edge_senses_g, np.int32(nedges), facing_g, codes_g)
    return Silhouette(adjacency, light,
                      codes=device.from_device(codes_g, nedges, np.int8),
                      facing=device.from_device(facing_g, nfaces, np.uint8).astype(bool))


def face_facing(device, adjacency: "EdgeAdjacency | Mesh", light) -> np.ndarray:
    """(F,) bool: the light-facing faces of ``adjacency`` (or a mesh's cached table), on the device
    (one kernel, no edges classified)."""
    if not isinstance(adjacency, EdgeAdjacency):
        adjacency = edge_adjacency(adjacency)
    facing_g, _ = _facing_on_device(device, adjacency, check_light(light))
    return device.from_device(facing_g, len(adjacency.faces), np.uint8).astype(bool)


def _facing_on_device(device, adjacency: EdgeAdjacency, light) -> tuple:
    """Launch ``face_facing`` for every face: (the facing buffer, the build options)."""
    point = isinstance(light, PointLight)
    vector = light.position if point else light.direction
    options = (f"-DLIGHT_POINT={int(point)}",)
    vertices_g, faces_g, _, _ = adjacency_buffers(device, adjacency)
    nfaces = len(adjacency.faces)
    facing_g = device.empty(nfaces, "face facing")
    device.kernel("silhouette.cl", "face_facing", options)(
        device.queue, _global_size(nfaces), None, vertices_g, faces_g, np.int32(nfaces),
        *(np.float32(c) for c in vector), facing_g)
    return facing_g, options


def host_facing(vertices: np.ndarray, faces: np.ndarray, light, which: "np.ndarray | None" = None) -> np.ndarray:
    """Light-facing faces computed on the host, bit for bit as ``face_facing`` computes them.

    float32 throughout, the kernel's operations in the kernel's order and no fused multiply-add
    (vecmath.h turns contraction off), so every product and sum rounds as on the device. ``which``:
    the face indices to test (default every face). The tracker tests a few faces per walk step this
    way, cheaper than a kernel launch and read-back (bench/silhouettes.py measures both).
    """
    light = check_light(light)
    tri = np.asarray(vertices, dtype=np.float32)[faces if which is None else faces[which]]
    v0 = tri[:, 0]
    a, b = tri[:, 1] - v0, tri[:, 2] - v0
    nx = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    ny = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    nz = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    if isinstance(light, PointLight):
        d = light.position.astype(np.float32) - v0
        return nx * d[:, 0] + ny * d[:, 1] + nz * d[:, 2] > 0
    lx, ly, lz = light.direction.astype(np.float32)
    return nx * lx + ny * ly + nz * lz < 0           # the kernel's -(n . d) > 0


def _global_size(n: int, group: int = 64) -> tuple:
    """A 1-D global size of at least ``n`` work-items (kernels guard the excess), a multiple of ``group``:
    PoCL otherwise picks a work-group size that divides ``n`` (1 for a prime ``n``), one task each."""
    return (max(-(-n // group), 1) * group,)


def adjacency_buffers(device, adjacency: EdgeAdjacency) -> tuple:
    """(vertices, faces, kernel edge faces, edge senses) of ``adjacency`` on ``device``, uploaded once per
    device (kept in the table's cache slot); an edge with three or more faces has second face MANY_FACES."""
    buffers = adjacency._device_buffers.get(device)
    if buffers is None:
        kernel_faces = adjacency.edge_faces.copy()
        kernel_faces[adjacency.face_count > 2, 1] = MANY_FACES
        buffers = tuple(device.to_device(a) for a in (adjacency.vertices, adjacency.faces, kernel_faces,
                                                      adjacency.edge_senses))
        adjacency._device_buffers[device] = buffers
    return buffers
