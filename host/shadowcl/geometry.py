"""Triangle meshes: validation, loading, and the derived quantities methods need (bounds, normals)."""

from __future__ import annotations

from functools import cached_property

import numpy as np

from .checks import finite_array, integer_array, vertex_indices
from .meshio import read_polygons


class Mesh:
    """A triangle mesh: ``vertices`` (V, 3) float32 and ``faces`` (F, 3) int32.

    Inputs are validated (finite coordinates, integer indices within range, the right shapes, at least
    one triangle). Degenerate triangles (zero area, repeated indices) are allowed: they cast no shadow,
    and :attr:`degenerate_count` says how many there are. The mesh keeps read-only copies of its
    inputs: the caller's arrays are neither shared nor changed.
    """

    def __init__(self, vertices, faces):
        vertices = finite_array("vertices", vertices, (3,))
        faces_in = integer_array("faces", faces)
        if faces_in.ndim != 2 or faces_in.shape[1] != 3:
            raise ValueError(f"faces: expected shape (F, 3), got {faces_in.shape}")
        if len(faces_in) == 0:
            raise ValueError("faces: the mesh is empty (no triangles)")
        if len(vertices) == 0:
            raise ValueError("vertices: the mesh has faces but no vertices")
        vertex_indices("faces", faces_in, len(vertices))
        high = int(faces_in.max())
        if high > np.iinfo(np.int32).max:   # faces are stored int32: a larger index would wrap silently
            raise ValueError(f"faces: vertex index {high} does not fit int32; at most 2^31 vertices are used")
        if np.abs(vertices).max() >= np.finfo(np.float32).max:
            raise ValueError("vertices: coordinates overflow float32")
        self.vertices = np.array(vertices, dtype=np.float32, order="C")   # copies: never the caller's buffer
        self.faces = np.array(faces_in, dtype=np.int32, order="C")
        for array in (self.vertices, self.faces):
            array.flags.writeable = False
        self._moved: tuple | None = None   # (centre, scale) and the mesh :meth:`moved` made for them

    @classmethod
    def load(cls, path) -> "Mesh":
        """Read an OBJ, PLY (ASCII or binary), STL (ASCII or binary) or OFF file, kept as written (no
        merging, no removal of degenerates); polygons are fan-triangulated. A malformed file raises
        ValueError naming the file and, for text, the line (see :mod:`shadowcl.meshio`)."""
        polygons = read_polygons(path)
        return cls(polygons.vertices, polygons.triangles())

    def __repr__(self) -> str:
        return f"Mesh({len(self.vertices)} vertices, {len(self.faces)} triangles)"

    @property
    def triangles(self) -> np.ndarray:
        """(F, 3, 3) float64 corner positions."""
        return self.vertices.astype(np.float64)[self.faces]

    @cached_property
    def face_normals(self) -> np.ndarray:
        """(F, 3) float64 unit normals by the right-hand rule; zero for degenerate triangles."""
        tri = self.triangles
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(normal, axis=1, keepdims=True)
        return np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)

    @cached_property
    def degenerate_count(self) -> int:
        """Number of triangles with zero area (repeated indices or collinear corners)."""
        return int(np.count_nonzero(~np.any(self.face_normals, axis=1)))

    @cached_property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64: lowest and highest corner of the bounding box of the referenced vertices."""
        used = self.vertices[np.unique(self.faces)].astype(np.float64)
        return np.stack([used.min(axis=0), used.max(axis=0)])

    def moved(self, centre: np.ndarray, scale: float) -> "Mesh":
        """This mesh under ``x -> (x - centre) / scale`` (``scale`` a power of two, so exact), computed in
        float64. The last result is kept: a mesh is immutable and every public query of the same scene
        moves it the same way (ogre: ~35 ms a call). Its box is moved, not recomputed: the map and the
        rounding to float32 are monotonic per axis, so the moved bounds are the new mesh's bounds."""
        key = (tuple(float(c) for c in centre), float(scale))
        if self._moved is not None and self._moved[0] == key:
            return self._moved[1]
        mesh = Mesh((self.vertices.astype(np.float64) - centre) / scale, self.faces)
        mesh.__dict__["bounds"] = ((self.bounds - centre) / scale).astype(np.float32).astype(np.float64)
        self._moved = (key, mesh)
        return mesh

    def transformed(self, matrix: np.ndarray) -> "Mesh":
        """This mesh under a 4x4 affine ``matrix`` (computed in float64)."""
        v = self.vertices.astype(np.float64) @ matrix[:3, :3].T + matrix[:3, 3]
        faces = self.faces if np.linalg.det(matrix[:3, :3]) >= 0 else self.faces[:, ::-1]
        return Mesh(v, faces)

    @staticmethod
    def concatenate(meshes: "list[Mesh]") -> "Mesh":
        """One mesh holding all of ``meshes``; face ids follow the list order."""
        if not meshes:
            raise ValueError("meshes: nothing to concatenate")
        offsets = np.cumsum([0] + [len(m.vertices) for m in meshes[:-1]])
        vertices = np.concatenate([m.vertices for m in meshes])
        faces = np.concatenate([m.faces.astype(np.int64) + o for m, o in zip(meshes, offsets)])
        return Mesh(vertices, faces)


def per_mesh(cache, mesh: Mesh, build):
    """``cache[mesh]`` (a ``weakref.WeakKeyDictionary``), made by ``build(mesh)`` on first use: what is
    derived from a mesh once (a :class:`Mesh` is immutable) and dropped with it."""
    value = cache.get(mesh)
    if value is None:
        value = build(mesh)
        cache[mesh] = value
    return value


def bounds_diagonal(bounds: np.ndarray) -> float:
    return float(np.linalg.norm(bounds[1] - bounds[0]))
