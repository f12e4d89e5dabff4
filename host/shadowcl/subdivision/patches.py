"""The patch table: a control mesh cut into patches with at most one extraordinary vertex each (refined
once or twice where needed), their control points, Ptex parameter domains and side neighbours."""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field

import numpy as np

from .refinement import _cc_step, _Topology
from .stam import _gather_regular, _local_mesh, _quad_corners, _stam_weights

#: Refinement steps on the whole mesh are at most 2: after one step every face is a quad, after two no
#: quad has two extraordinary corners.
_MAX_REFINE = 2
_UNIT_SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
_ROTATIONS = [np.roll(np.arange(4), -rot) for rot in range(4)]  # corner order starting at corner rot


@dataclass(frozen=True, eq=False)
class PatchTable:
    """Limit-surface patches in world coordinates (the patch-table contract; see kernels/subdivision.h).

    - ``points`` (P, 3) float32 control points; ``first`` (n,) uint32 index of patch i's first point;
      ``levels`` (n,) uint32: 0 = regular 16-point bicubic B-spline (row-major, i along u), L > 0 = one
      extraordinary vertex at (0, 0) evaluated by Stam's sub-domains (48 L points, then its limit).
    - ``face`` (n,) int32 control face; ``domain`` (n, 4) float64 (u0, v0, du, dv) in the face's
      parameters (for n-gons, u in [0, n]); ``rotation`` (n,) uint8: patch corner (0, 0) sits at domain
      corner ``rotation`` (corners (u0, v0), (u1, v0), (u1, v1), (u0, v1)), the patch's u axis towards
      the next corner. (A table made from a control grid, ``testing.grid_patch_table``, has a face per
      patch and unit domains; one merged from several, ``voxelize.merge_tables``, numbers faces on.)
    - ``neighbors`` (n, 4) int32: the patch across side 0 (v = 0), 1 (u = 1), 2 (v = 1), 3 (u = 0), -1 on
      a boundary; where the neighbour is refined further, the one touching the side's corner at the
      start of the side in the neighbour's own order.

    The arrays are read-only; :meth:`buffers` gives the device copies the kernels read.
    """

    points: np.ndarray
    first: np.ndarray
    levels: np.ndarray
    face: np.ndarray
    domain: np.ndarray
    rotation: np.ndarray
    neighbors: np.ndarray
    _buffers: weakref.WeakKeyDictionary = field(default_factory=weakref.WeakKeyDictionary, init=False, repr=False)

    def __post_init__(self):
        for name, dtype in (("points", np.float32), ("first", np.uint32), ("levels", np.uint32), ("face", np.int32),
                            ("domain", np.float64), ("rotation", np.uint8), ("neighbors", np.int32)):
            array = np.array(getattr(self, name), dtype=dtype, order="C")      # a copy: the table owns its arrays
            array.flags.writeable = False
            object.__setattr__(self, name, array)

    def __len__(self) -> int:
        return len(self.first)

    def buffers(self, device) -> tuple:
        """(points, first, levels) on ``device``, uploaded once per device."""
        found = self._buffers.get(device)
        if found is None:
            found = self._buffers[device] = tuple(device.to_device(a) for a in (self.points, self.first, self.levels))
        return found


@dataclass(frozen=True)
class _Lookup:
    """What evaluating a surface by control-face parameters needs beside its table (host, float64)."""

    points: np.ndarray  # (P, 3) float64: the table's control points before rounding (host derivatives near EVs)
    ev_normals: np.ndarray  # (n, 3) float64 unit limit normal at a Stam patch's EV; NaN where none is known
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


def _build_patches(vertices: np.ndarray, faces: list[np.ndarray]) -> tuple[PatchTable, _Lookup]:
    """The patch table of a checked control mesh and its host lookup."""
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


def _assemble(points, topos, records, t0: _Topology) -> tuple[PatchTable, _Lookup]:
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
    points = np.concatenate(nets)
    table = PatchTable(points, first, levels, face, domain, rotation, _neighbors(topos, records))
    return table, _Lookup(points, ev_normals, cell_start, res, cells)


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
