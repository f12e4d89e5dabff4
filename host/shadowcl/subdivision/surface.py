"""The public :class:`SubdivisionSurface`: input checks, OBJ loading, evaluation on the device,
limit normals, tessellation and voxelization of one control mesh."""

from __future__ import annotations

import os
from functools import cached_property
from pathlib import Path

import numpy as np

from ..checks import finite_array, integer_array, positive_int, vertex_indices
from ..device import get_device
from ..geometry import Mesh
from ..meshio import read_polygons
from .patches import PatchTable, _bspline_basis, _build_patches, _ptex_sizes
from .tessellation import tessellation

#: Most cells (two triangles each) an explicit tessellation may have: 1.5 million cells (a cube cage at
#: 512 segments) took 2.3 s and 730 MB here, so the limit keeps a tessellation within a few GB.
MAX_TESSELLATION_CELLS = 1 << 21
#: Below this patch parameter (max(u, v)) next to an EV, normals come from float64 host derivatives.
NEAR_EV = 2.0**-10
#: Default tessellation: chord error at most this fraction of the control mesh's bounding-box diagonal.
TESSELLATION_TOLERANCE = 1e-3


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
    array = integer_array(name, value, empty=True)
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
        array = integer_array(f"faces: face {i}", row)
        if array.ndim != 1 or len(array) < 3:
            raise ValueError(f"faces: face {i} must list at least 3 vertex indices, got shape {array.shape}")
        out.append(array.astype(np.int64))
    vertex_indices("faces", np.concatenate(out), n_vertices, sizes=[len(f) for f in out])
    for i, array in enumerate(out):
        if len(np.unique(array)) != len(array):
            raise ValueError(f"faces: face {i} repeats a vertex ({array.tolist()})")
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
        self._table, self._lookup = _build_patches(self.vertices, self.faces)

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
                f"{len(self._table)} patches)")

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
        return len(self._table)

    def voxelize(self, resolution: int, connectivity: int = 26, device=None):
        """This surface voxelized into a ``resolution``^3 cubic frame buffer with N-adjacency ``connectivity``
        (6, 18 or 26): a :class:`shadowcl.voxelize.Voxelization` (``.occupied``, ``.origin``, ``.voxel_size``)."""
        from .. import voxelize  # voxelize builds on the patch table

        return voxelize.voxelize(get_device(device), self, resolution, connectivity)

    def patch_table(self, device=None) -> PatchTable:
        """The :class:`PatchTable` (world coordinates), its buffers uploaded to ``device``."""
        self._table.buffers(get_device(device))
        return self._table

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
        p, table = self._lookup, self._table
        res = p.cell_res[face]
        width = self._units[face] * res
        i = np.clip(np.floor(u * res).astype(np.int64), 0, width - 1)
        j = np.clip(np.floor(v * res).astype(np.int64), 0, res - 1)
        patch = p.cells[p.cell_start[face] + j * width + i]
        u0, v0, du, dv = table.domain[patch].T
        s = np.clip((u - u0) / du, 0.0, 1.0)
        t = np.clip((v - v0) / dv, 0.0, 1.0)
        rot = table.rotation[patch]
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
                dev.queue, (n,), None, *table.buffers(dev),
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
        levels = self._table.levels[patch]
        near = (levels > 0) & (np.maximum(pu, pv) < NEAR_EV)
        if near.any():
            d_u[near], d_v[near] = self._stam_derivatives(patch[near], pu[near], pv[near])
        normal = np.cross(d_u, d_v)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        # At the EV itself (where patch_eval returns its limit position): the closed-form limit normal.
        ev_normal = self._lookup.ev_normals[patch]
        at_ev = (levels > 0) & (np.maximum(pu, pv) < 2.0 ** -levels.astype(np.float64)) & np.isfinite(ev_normal[:, 0])
        normal[at_ev] = ev_normal[at_ev]
        return normal.astype(np.float32)

    def _stam_derivatives(self, patch, u, v) -> tuple[np.ndarray, np.ndarray]:
        """float64 (dP/du, dP/dv) on Stam patches (host version of patch_eval's sub-domain choice)."""
        table, p = self._table, self._lookup
        levels = table.levels[patch].astype(np.int64)
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
        first = table.first[patch].astype(np.int64) + ((n - 1) * 3 + k) * 16
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
        face, u, v, triangles, _ = tessellation(self.faces, segments)
        centred, centre = self._centred
        return Mesh(centred.evaluate(face, u, v, device=device).astype(np.float64) + centre, triangles)

    @cached_property
    def _centred(self) -> "tuple[SubdivisionSurface, np.ndarray]":
        """(this surface moved to its control box's centre, that centre): the device evaluates in float32,
        so a surface far from the origin is evaluated there and moved back in float64. Without it the
        limit points of a surface 3e3 diagonals off the origin carried the offset's rounding (1e-3 of
        its size), the chord error never fell below the tolerance and the default tessellation went to
        256 segments (4 M triangles, 136 of 400 receivers' shadows changed; bench/redteam.py)."""
        centre = 0.5 * (self.vertices.min(axis=0) + self.vertices.max(axis=0)).astype(np.float64)
        if np.linalg.norm(centre) <= np.linalg.norm(self.vertices.max(axis=0) - self.vertices.min(axis=0)):
            return self, np.zeros(3)
        move = np.eye(4)
        move[:3, 3] = -centre
        return self.transformed(move), centre

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
        face, u, v, triangles, centres = tessellation(self.faces, segments)
        surface = self._centred[0]     # the error does not move with the surface; float32 rounding does
        corners = surface.evaluate(face, u, v, device=device).astype(np.float64)
        centre = surface.evaluate(*centres, device=device).astype(np.float64)
        normal = surface.limit_normals(*centres, device=device).astype(np.float64)
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
