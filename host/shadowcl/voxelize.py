"""Voxelization of Catmull-Clark limit surfaces by parameter-space subdivision (Lai & Cheng, section 3).

Each patch of the patch table (host/shadowcl/subdivision/patches.py's contract: ``points``, ``first``,
``levels``) is split at parameter midpoints, breadth first on the device (kernels/voxelize.cl), until
its four corner voxels fit in a 2 x 2 x 2 block and the corner voxels of each of its edges are
N-adjacent (N = ``connectivity``: 6, 18 or 26). Such a subpatch is a *leaf*: its corners' voxels go
into the cubic frame buffer and the leaf is recorded (patch, level, iu, iv, corner positions, corner
voxels) for the shadow step (host/shadowcl/voxel.py).

**The grid.** A cube of ``resolution``^3 voxels around the control points (B-spline patches lie in
the convex hull of their control points, so the limit surface is inside), centred on their box.

**The paper's rule and where it leaks.** The paper splits until "the four corner voxels are
N-adjacent". Read as edges only, a leaf can have four corners a diagonal step apart around an empty
voxel its surface passes through: measured, 26- and 18-connectivity voxelizations of a torus and the
cube then leak to a 6-connected flood fill. Read as all pairs, N = 6 can never stop (three voxels
cannot be pairwise face-adjacent): at 32^3 it reached the depth limit on 7 k leaves. Hence the rule
above: the block bounds the leaf (its surface deviates from its corners by a fraction of a voxel,
second order in the leaf size), the edges carry the connectivity. A leaf that stays unsplittable
(every edge shorter than 1/64 voxel yet skipping a voxel diagonally, where a curve runs along a voxel
edge, or at depth 24) is kept and counted in ``stats["forced_leaves"]``. Shared corners of leaves of
a patch are evaluated from bit-identical parameters, so they land in the same voxel; across patches a
shared corner comes from two control-point sets and rounding can move it one voxel.

**Separability** (tests/test_voxelize.py, closed surfaces: a torus, the cube with extraordinary
vertices): N = 26 and N = 18 voxelizations block 6-connected flood fills from outside; N = 6 blocks
18-connected fills, but not always 26-connected ones (measured: a 26-path slips through a voxel
vertex between leaves). Every occupied voxel holds a leaf corner, a limit-surface point, so its centre
is within sqrt(3)/2 voxel of the surface; every surface sample lies in an occupied voxel or next to
one (Chebyshev distance 1).

**Frame buffer.** 2 bits per voxel packed 16 to a 32-bit word (1024^3 = 256 MiB): 0 empty, 3
occupied (voxel.cl later rewrites occupied voxels to 1 = lit or 2 = shadowed). When it does not fit
the device (``frame_buffer=None`` decides) the leaves alone are kept (the paper's section 5.1 mode)
and :attr:`Voxelization.occupied` is rebuilt from them.

**Crack-free tessellation** (section 5.3, :func:`tessellate`, ``vox.tessellate()``): the leaves as a
triangle mesh for rendering, two triangles per leaf, or where neighbouring leaves are deeper (inside a
patch, or across patches, including patches refined further than their neighbours) the polygon through
every evaluated point on its boundary, fanned from its centre. Closed surfaces give closed, consistently
oriented meshes (tests/test_voxelize.py: torus, cube, pyramid; measured on every ccss model and suzanne
at 32^3 and 128^3: edges with one face only along the table's boundary sides).

**Fixed capacities.** Each level's child queue and the leaf array have a capacity; the kernel counts
what it wanted, the host grows the buffer to the counted size and reruns the level.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from .checks import check_bounds, choice, positive_int
from .geometry import Mesh
from .subdivision.patches import PatchTable
from .topology import components

CONNECTIVITIES = (6, 18, 26)
MAX_RESOLUTION = 1024      # linear voxel indices (i * R + j) * R + k are 32-bit (kernels/voxelize.cl)
MAX_DEPTH = 24             # kernels/voxelize.cl: subdivision levels (parameters exact in float32)
LEAF_WORDS = 20            # kernels/voxelize.cl: leaf record
GROWTH = 1.25              # capacity headroom over a counted overflow
COUNTER_MAX = 2**31 - 1    # kernels/voxelize.cl's int slot counters: a level that could pass it is refused


@dataclass
class Voxelization:
    """The voxels of a patch table at ``resolution``^3 and the leaf subpatches that made them.

    ``origin`` (3,) float64 is the grid's lower corner and ``voxel_size`` its cube side, so voxel (i, j, k)
    covers ``origin + voxel_size * [i, i + 1) x [j, j + 1) x [k, k + 1)``. ``leaves`` is the (n, 20)
    uint32 record array of kernels/voxelize.cl; :attr:`patch`, :attr:`corners`, :attr:`corner_voxels`
    read it. ``frame_dev`` is the packed 2-bit frame buffer on the device (None in section 5.1 mode).
    """

    resolution: int
    connectivity: int
    origin: np.ndarray
    voxel_size: float
    leaves: np.ndarray
    leaves_dev: cl.Buffer = field(repr=False)
    frame_dev: cl.Buffer | None = field(repr=False)
    device: object = field(repr=False)
    stats: dict = field(default_factory=dict)
    table_dev: tuple = field(default=(), repr=False)     # the patch table's points, first, levels on the device
    npatches: int = 0
    neighbors: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.int32), repr=False)  # the table's

    @property
    def nleaves(self) -> int:
        return len(self.leaves)

    @property
    def patch(self) -> np.ndarray:
        return self.leaves[:, 0]

    @property
    def level(self) -> np.ndarray:
        return self.leaves[:, 1]

    @property
    def rect(self) -> np.ndarray:
        """(n, 4) float64 parameter rectangles (u0, v0, du, dv) of the leaves."""
        step = np.ldexp(1.0, -self.leaves[:, 1].astype(np.int64))
        return np.stack([self.leaves[:, 2] * step, self.leaves[:, 3] * step, step, step], axis=1)

    @property
    def corners(self) -> np.ndarray:
        """(n, 4, 3) float32 corner positions, ordered (u0, v0), (u1, v0), (u1, v1), (u0, v1)."""
        return self.leaves[:, 4:16].view(np.float32).reshape(-1, 4, 3)

    @property
    def corner_voxels(self) -> np.ndarray:
        """(n, 4) int64 linear voxel indices (i * R + j) * R + k of the corners."""
        return self.leaves[:, 16:20].astype(np.int64)

    @property
    def frame_words(self) -> np.ndarray | None:
        """The packed frame buffer copied to the host (uint32, 16 voxels per word), or None without one."""
        if self.frame_dev is None:
            return None
        return self.device.from_device(self.frame_dev, frame_word_count(self.resolution), np.uint32)

    @property
    def occupied(self) -> np.ndarray:
        """bool (R, R, R) indexed [i, j, k]: the voxels holding a leaf corner (unpacked on request)."""
        R = self.resolution
        words = self.frame_words
        if words is None:
            flat = np.zeros(R ** 3, dtype=bool)
            flat[self.corner_voxels.ravel()] = True
            return flat.reshape(R, R, R)
        return (unpack_states(words, R ** 3) != 0).reshape(R, R, R)

    def evaluate(self, patch, u, v) -> np.ndarray:
        """(N, 3) float32 limit positions of patches ``patch`` at parameters (``u``, ``v``) in [0, 1]
        (kernels/voxelize.cl eval_points on the voxelized table)."""
        patch = np.ascontiguousarray(patch, dtype=np.int64).ravel()
        uv = np.ascontiguousarray(np.stack(np.broadcast_arrays(np.ravel(u), np.ravel(v)), axis=1), dtype=np.float32)
        if len(patch) != len(uv):
            raise ValueError(f"patch: {len(patch)} ids for {len(uv)} parameters")
        if len(patch) and (patch.min() < 0 or patch.max() >= self.npatches):
            raise ValueError(f"patch: ids must be in [0, {self.npatches})")
        if not np.all((uv >= 0) & (uv <= 1)):
            raise ValueError("u, v: parameters must be in [0, 1]")
        if len(patch) == 0:
            return np.zeros((0, 3), np.float32)
        dev = self.device
        out = dev.empty(12 * len(patch), "evaluated points")
        dev.kernel("voxelize.cl", "eval_points")(dev.queue, (len(patch),), None, *self.table_dev,
                                                 dev.to_device(patch.astype(np.uint32)), dev.to_device(uv),
                                                 np.int32(len(patch)), out)
        return dev.from_device(out, (len(patch), 3), np.float32)

    def tessellate(self) -> "LeafMesh":
        """The leaves as a crack-free triangle mesh (section 5.3, :func:`tessellate`)."""
        return tessellate(self)

    def voxel_of(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) int64 voxel coordinates of world ``points`` and a bool (N,) "inside the grid" mask."""
        ijk = np.floor((np.asarray(points, dtype=np.float64) - self.origin) / self.voxel_size).astype(np.int64)
        inside = np.all((ijk >= 0) & (ijk < self.resolution), axis=1)
        return ijk, inside


def frame_word_count(resolution: int) -> int:
    return -(-resolution ** 3 // 16)


def unpack_states(words: np.ndarray, count: int) -> np.ndarray:
    """uint8 (count,) 2-bit voxel states from packed words."""
    shifts = (2 * np.arange(16, dtype=np.uint32))
    return ((words[:, None] >> shifts) & 3).astype(np.uint8).ravel()[:count]


def grid_frame(points: np.ndarray, resolution: int, bounds=None, control_points=None) -> tuple[np.ndarray, float]:
    """(origin, voxel_size) of a cube of ``resolution`` voxels centred on ``bounds`` ((2, 3) box; None: the
    box of ``points``), a hair larger than the box's longest side. ``bounds`` must hold ``control_points``
    (the control mesh's vertices, whose hull holds the limit surface; None: ``points``): the patch
    table's extrapolated boundary points may lie outside it, and the kernel only maps limit points."""
    if bounds is None:
        lo, hi = points.min(axis=0).astype(np.float64), points.max(axis=0).astype(np.float64)
    else:
        lo, hi = check_bounds("grid_bounds", bounds)
        held = points if control_points is None else control_points
        if np.any(held.min(axis=0) < lo) or np.any(held.max(axis=0) > hi):
            raise ValueError("grid_bounds: the box must contain every control point of the surfaces")
    extent = float(np.max(hi - lo))
    if not np.isfinite(extent):
        raise ValueError("surface: control points are not finite")
    if extent == 0.0:
        extent = max(float(np.max(np.abs(lo))), 1.0) * 1e-3
    # a hair larger than the box so the largest coordinate falls inside the last voxel
    size = extent * (1.0 + 2.0 ** -12) / resolution
    return 0.5 * (lo + hi) - 0.5 * size * resolution, size


def patch_table_of(device, surface_or_table) -> PatchTable:
    """The patch table of a surface (``.patch_table(device)``) or a table itself."""
    if hasattr(surface_or_table, "patch_table"):
        return surface_or_table.patch_table(device)
    if isinstance(surface_or_table, PatchTable):
        return surface_or_table
    raise TypeError(f"surface: expected a SubdivisionSurface or a PatchTable, got {type(surface_or_table).__name__}")


def check_table(table) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    points = np.ascontiguousarray(table.points, dtype=np.float32)
    first = np.ascontiguousarray(table.first, dtype=np.uint32)
    levels = np.ascontiguousarray(table.levels, dtype=np.uint32)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise ValueError(f"surface: patch table points must be (P, 3) with P > 0, got {points.shape}")
    if first.shape != levels.shape or first.ndim != 1 or len(first) == 0:
        raise ValueError("surface: patch table needs matching non-empty first and levels")
    needed = first.astype(np.int64) + np.where(levels == 0, 16, 48 * levels.astype(np.int64) + 1)
    if np.any(needed > len(points)):
        raise ValueError("surface: patch table refers to control points beyond its points array")
    if not np.all(np.isfinite(points)):
        raise ValueError("surface: control points are not finite")
    return points, first, levels


def voxelize(device, surface_or_table, resolution: int, connectivity: int = 26,
             frame_buffer: bool | None = None, initial_capacity: int | None = None, grid_bounds=None,
             control_points=None) -> Voxelization:
    """Voxelize a subdivision surface (or its patch table) into a ``resolution``^3 cubic frame buffer.

    ``connectivity`` (6, 18, 26) is the N of N-adjacency a leaf's corner voxels must satisfy.
    ``frame_buffer``: True keeps the packed 2-bit buffer on the device (raises if it does not fit), False
    keeps only the leaves (section 5.1), None keeps it when it fits in one device buffer.
    ``initial_capacity`` sizes the first queue and leaf buffers (tests use a tiny one to force regrowth).
    ``grid_bounds`` ((2, 3) world box holding every control point) fixes the cube the grid spans, so
    different surfaces can share one voxel grid; None: the control points' box. ``control_points``
    (default: the surface's vertices, else the table's points) are what ``grid_bounds`` must hold.
    """
    resolution = positive_int("resolution", resolution, 1, MAX_RESOLUTION)
    connectivity = choice("connectivity", connectivity, CONNECTIVITIES)
    table = patch_table_of(device, surface_or_table)
    points, first, levels = check_table(table)
    if control_points is None and isinstance(getattr(surface_or_table, "vertices", None), np.ndarray):
        control_points = surface_or_table.vertices    # a SubdivisionSurface's control mesh
    origin, size = grid_frame(points, resolution, grid_bounds, control_points)
    frame_bytes = 4 * frame_word_count(resolution)
    if frame_buffer is None:
        frame_buffer = frame_bytes <= device.max_alloc_bytes
    dev, queue = device, device.queue
    t0 = time.perf_counter()
    frame_dev = None
    if frame_buffer:
        frame_dev = dev.empty(frame_bytes, f"frame buffer of {resolution}^3 voxels")
        cl.enqueue_fill_buffer(queue, frame_dev, np.uint32(0), 0, frame_bytes)
    kernel = dev.kernel("voxelize.cl", "voxelize_level",
                        (f"-DCONNECTIVITY={connectivity}", f"-DFRAME_BUFFER={int(bool(frame_buffer))}"))
    points_g, first_g, levels_g = dev.to_device(points), dev.to_device(first), dev.to_device(levels)
    npatch = len(first)
    items = np.zeros((npatch, 4), dtype=np.uint32)
    items[:, 0] = np.arange(npatch)
    items_in, n_in = dev.to_device(items), npatch
    # a guess (about two leaves per voxel of a surface across the grid), grown on overflow
    guess = min(2 * resolution * resolution, device.max_alloc_bytes // (16 * LEAF_WORDS))
    start = int(initial_capacity) if initial_capacity else max(4 * npatch, guess, 1024)
    out_cap = leaf_cap = start
    items_out = dev.empty(16 * out_cap, "voxelization queue")
    leaves_g = dev.empty(4 * LEAF_WORDS * leaf_cap, "voxelization leaves")
    counters = dev.empty(12, "voxelization counters")
    dummy = frame_dev if frame_dev is not None else dev.empty(4, "no frame buffer")
    nleaves = forced = reruns = 0
    per_level = []
    level = 0
    while n_in > 0:
        # A level adds at most 4 queue slots and one leaf per item: refused before a counter could wrap
        if 4 * n_in > COUNTER_MAX or nleaves + n_in > COUNTER_MAX:
            raise ValueError(f"resolution: {resolution} needs {n_in} subpatches at level {level} after {nleaves} "
                             f"leaves, more than the voxelizer's 32-bit counters hold ({COUNTER_MAX}); use a lower one")
        while True:
            cl.enqueue_copy(queue, counters, np.array([0, nleaves, forced], dtype=np.int32))
            kernel(queue, (n_in,), None, points_g, first_g, levels_g, items_in, np.int32(n_in), items_out,
                   np.int32(out_cap), leaves_g, np.int32(leaf_cap), counters, dummy,
                   *(np.float32(c) for c in origin), np.float32(1.0 / size), np.int32(resolution))
            wanted_out, wanted_leaves, new_forced = (int(c) for c in dev.from_device(counters, 3, np.int32))
            if wanted_out <= out_cap and wanted_leaves <= leaf_cap:
                break
            # Overflow: grow what ran out (leaves keep their prefix) and rerun the level
            reruns += 1
            if wanted_out > out_cap:
                out_cap = min(int(wanted_out * GROWTH), COUNTER_MAX)
                items_out = dev.empty(16 * out_cap, "voxelization queue")
            if wanted_leaves > leaf_cap:
                leaf_cap = min(int(wanted_leaves * GROWTH), COUNTER_MAX)
                grown = dev.empty(4 * LEAF_WORDS * leaf_cap, "voxelization leaves")
                if nleaves:
                    cl.enqueue_copy(queue, grown, leaves_g, byte_count=4 * LEAF_WORDS * nleaves)
                leaves_g = grown
        per_level.append((level, n_in, wanted_leaves - nleaves))
        nleaves, forced = wanted_leaves, new_forced
        # the output queue becomes the next input; the old input buffer is the next output
        items_in, items_out = items_out, items_in
        in_cap = out_cap
        out_cap = (items_out.size // 16)
        n_in = wanted_out
        if out_cap < 4 * n_in:
            out_cap = max(4 * n_in, in_cap)
            items_out = dev.empty(16 * out_cap, "voxelization queue")
        level += 1
    leaves = dev.from_device(leaves_g, (nleaves, LEAF_WORDS), np.uint32)
    # Work-items append leaves through an atomic counter, so their order varies from run to run: sort them
    # by (patch, level, iu, iv) so a voxelization, its leaf ids and its tessellation are reproducible.
    order = np.lexsort(leaves[:, 3::-1].T)
    if np.any(order != np.arange(nleaves)):
        leaves = np.ascontiguousarray(leaves[order])
        cl.enqueue_copy(queue, leaves_g, leaves)
    queue.finish()
    elapsed = time.perf_counter() - t0
    stats = dict(resolution=resolution, connectivity=connectivity, patches=npatch, leaves=nleaves,
                 forced_leaves=forced, levels=level, reruns=reruns, per_level=per_level, voxelize_s=elapsed,
                 frame_buffer=bool(frame_buffer), frame_bytes=frame_bytes if frame_buffer else 0,
                 leaf_bytes=4 * LEAF_WORDS * nleaves, subpatches=int(sum(n for _, n, _ in per_level)))
    return Voxelization(resolution, connectivity, origin, size, leaves, leaves_g, frame_dev, dev, stats,
                        (points_g, first_g, levels_g), npatch, table.neighbors)


def merge_tables(tables) -> PatchTable:
    """One table holding every patch of ``tables`` in order (patch, point and face ids offset, neighbours
    renumbered)."""
    tables = list(tables)
    if not tables:
        raise ValueError("surfaces: nothing to voxelize")
    parts = {name: [] for name in ("points", "first", "levels", "face", "domain", "rotation", "neighbors")}
    point_base = patch_base = face_base = 0
    for table in tables:
        nb = np.asarray(table.neighbors, dtype=np.int64)
        for name, value in (("points", table.points), ("first", np.asarray(table.first, np.int64) + point_base),
                            ("levels", table.levels), ("face", np.asarray(table.face, np.int64) + face_base),
                            ("domain", table.domain), ("rotation", table.rotation),
                            ("neighbors", np.where(nb >= 0, nb + patch_base, -1))):
            parts[name].append(value)
        point_base += len(table.points)
        patch_base += len(table.first)
        face_base += int(np.max(table.face, initial=-1)) + 1
    return PatchTable(**{name: np.concatenate(arrays) for name, arrays in parts.items()})


# Crack-free tessellation of the leaves (section 5.3) ------------------------------------------------

# Side s of a patch runs from corner SIDE_ENDS[s][0] to SIDE_ENDS[s][1] as its parameter t grows (corners
# 0..3 at (u, v) = (0, 0), (1, 0), (1, 1), (0, 1); side 0: v = 0, 1: u = 1, 2: v = 1, 3: u = 0, t = u on
# sides 0 and 2, t = v on sides 1 and 3).
SIDE_ENDS = np.array([(0, 1), (1, 2), (3, 2), (0, 3)])
# voxels: two patch sides are one curve when their samples are this close. Two evaluations of one limit
# point by different patches differ by float32 rounding (measured <= 7e-5 voxel up to 128^3 on the
# ccss models and suzanne); distinct corners are at least a leaf apart (leaves shorter than 1/64 voxel
# are forced, stats["forced_leaves"]).
SIDE_MATCH = 1e-2
# Patches may be refined further than their neighbours (the table's ``domain``): a side can be a piece of
# a neighbour's side. Sides are sampled at 2^SIDE_LOG + 1 points; pieces down to 2^-SIDE_LOG are found.
SIDE_LOG = 4
SIDE_CHUNK = 1 << 16       # side pairs compared at once (~27 MiB of sample gaps)


def side_samples(vox: Voxelization) -> np.ndarray:
    """(4 P, 2^SIDE_LOG + 1, 3) float64: each patch side (4 patch + side) evaluated at evenly spaced t."""
    npatch, count = vox.npatches, (1 << SIDE_LOG) + 1
    t = np.linspace(0.0, 1.0, count)
    side_u = np.stack([t, np.ones(count), t, np.zeros(count)])             # (4, count): side s at sample j
    side_v = np.stack([np.zeros(count), t, np.ones(count), t])
    patch = np.repeat(np.arange(npatch), 4 * count)
    points = vox.evaluate(patch, np.tile(side_u.ravel(), npatch), np.tile(side_v.ravel(), npatch))
    return points.astype(np.float64).reshape(4 * npatch, count, 3)


def matching_sides(vox: Voxelization) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pairs of patch sides that are one curve: side ``a`` (4 patch + side) is the piece of side ``b``
    from t = ``start`` / 2^SIDE_LOG, running ``span`` / 2^SIDE_LOG (negative: against b's direction) as a's
    parameter goes 0 -> 1. Returned int64 arrays.

    Which patch a side meets is the table's (``neighbors``: topology, subdivision/patches.py; where the
    patch across is coarser, the coarser one, whose side holds a's as a piece); which of that patch's
    sides, and which piece of it, the sides' samples say: a's end corners lie on b's samples (within
    SIDE_MATCH voxels, the nearest sample each) and so do a's samples that fall on b's (every sample when
    the sides are equal, every other one for a half, ...); ``span`` is a power of two, positive or
    negative."""
    count = (1 << SIDE_LOG) + 1
    points = side_samples(vox)
    tol = SIDE_MATCH * vox.voxel_size
    across = np.asarray(vox.neighbors, dtype=np.int64).reshape(-1)
    sides = np.flatnonzero(across >= 0)
    a = np.repeat(sides, 4)                                                # each side against the 4 across
    b = 4 * across[a] + np.tile(np.arange(4), len(sides))
    j0, j1 = np.zeros(len(a), np.int64), np.zeros(len(a), np.int64)
    near0, near1 = np.zeros(len(a), bool), np.zeros(len(a), bool)
    for lo in range(0, len(a), SIDE_CHUNK):        # b's sample nearest to a's start, to a's end
        part = slice(lo, lo + SIDE_CHUNK)
        for j, nearest, near in ((0, j0, near0), (count - 1, j1, near1)):
            gap = np.linalg.norm(points[b[part]] - points[a[part], j][:, None], axis=2)
            nearest[part] = np.argmin(gap, axis=1)
            near[part] = gap[np.arange(len(gap)), nearest[part]] <= tol
    span = j1 - j0
    power = near0 & near1 & (span != 0) & ((np.abs(span) & (np.abs(span) - 1)) == 0) & (a != b)
    a, b, j0, span = a[power], b[power], j0[power], span[power]
    # a's samples that land on b's samples must coincide with them
    i = np.arange(count)
    num = j0[:, None] * (count - 1) + i[None] * span[:, None]              # b's t in units of 2^-2 SIDE_LOG
    on = num % (count - 1) == 0
    jb = np.where(on, num // (count - 1), 0)
    gap = np.linalg.norm(points[a][:, i] - points[b[:, None], jb], axis=2)
    ok = np.all(~on | (gap <= tol), axis=1)
    return a[ok], b[ok], j0[ok], span[ok]


@dataclass(frozen=True)
class LeafMesh:
    """The leaf subpatches as one triangle mesh (:func:`tessellate`).

    ``mesh``: vertices are the leaves' corners (one per point of the surface: shared corners and the
    corners of a patch's neighbours are one vertex) followed by one centre vertex per leaf that needed
    crack elimination. ``face_leaf`` (F,) int64: the leaf each triangle belongs to. ``vertex_sample`` (V,)
    int64: the sample (4 * leaf + corner, :attr:`Voxelization.corners` flattened) a vertex's position
    came from, -1 for centre vertices. ``stats``: ``polygons`` (leaves with inserted points),
    ``inserted`` (points inserted into leaf boundaries), ``weld_spread`` (voxels: the largest distance
    between the evaluations of one surface point by different patches, which are one vertex here),
    ``side_pairs`` (side pieces found to be one curve, :func:`matching_sides`), ``open_sides`` (patch
    sides matched with none: the surface's boundary), ``vertices``, ``triangles``.
    """

    mesh: Mesh
    face_leaf: np.ndarray
    vertex_sample: np.ndarray
    stats: dict
    leaves: np.ndarray = field(repr=False)      # the voxelization's leaf records it tessellates


def tessellate(vox: Voxelization) -> LeafMesh:
    """Tessellate the leaves of ``vox`` without cracks (Lai & Cheng section 5.3).

    A leaf is two triangles when no other leaf has a corner on its boundary; otherwise its boundary is
    the polyline through every evaluated point on it (the paper's polygon A1 A2 C4 B4 A5 A6) and the
    polygon is fanned from its centre (the mean of its four corners), which leaves no sliver triangles.
    Points on a leaf's side are found exactly in integer parameter coordinates: inside a patch directly,
    across patches through the side pieces that are one curve (:func:`matching_sides`: equal sides
    either way round, or a side that is a dyadic piece of a larger neighbour's side), which map a side
    parameter to the neighbour's. Every evaluation of one surface point (a corner shared by leaves of
    several patches) becomes one vertex, at the position of the lowest-numbered sample. Raises
    ValueError when the parameter keys (patches x (2^(depth + SIDE_LOG) + 1)^2) overflow 62 bits.
    """
    n = vox.nleaves
    if n == 0:
        raise ValueError("vox: no leaves to tessellate")
    leaves = vox.leaves.astype(np.int64)
    patch, level, iu, iv = leaves[:, 0], leaves[:, 1], leaves[:, 2], leaves[:, 3]
    npatch = vox.npatches
    depth = int(level.max()) + SIDE_LOG           # sub-sides of 2^-SIDE_LOG map to integers too
    S = 1 << depth                                # integer parameter coordinates: [0, S] per patch
    W = S + 1
    if npatch * W * W >= 2 ** 62:
        raise ValueError(f"vox: {npatch} patches at depth {depth} overflow 64-bit parameter keys")
    step = S >> level
    u0, v0 = iu * step, iv * step
    cu = np.stack([u0, u0 + step, u0 + step, u0], axis=1).ravel()          # corner order of the leaf record
    cv = np.stack([v0, v0, v0 + step, v0 + step], axis=1).ravel()
    cp = np.repeat(patch, 4)
    positions = vox.corners.reshape(-1, 3).astype(np.float64)
    a, b, start, span = matching_sides(vox)
    tstart, tspan = start * (S >> SIDE_LOG), span                  # side b's t = tstart + t_a * span / 2^SIDE_LOG

    # Leaf corners on a patch side, carried to the same point on every side piece matched with it:
    # forward (a's point onto b) and back (b's points within a's piece onto a)
    sample, side = np.nonzero(np.stack([cv == 0, cu == S, cv == S, cu == 0], axis=1))
    t = np.where(side % 2 == 0, cu[sample], cv[sample])
    flat = 4 * cp[sample] + side
    order = np.argsort(flat, kind="stable")
    sample, side, t, flat = sample[order], side[order], t[order], flat[order]
    into_s, into_side, into_t = [], [], []
    for src, dst, forward in ((a, b, True), (b, a, False)):
        lo, hi = np.searchsorted(flat, src, "left"), np.searchsorted(flat, src, "right")
        pair = np.repeat(np.arange(len(src)), hi - lo)
        at = np.arange(len(pair)) - np.repeat(np.cumsum(hi - lo) - (hi - lo), hi - lo) + lo[pair]
        if forward:
            mapped = tstart[pair] + ((t[at] * tspan[pair]) >> SIDE_LOG)
        else:
            mapped = ((t[at] - tstart[pair]) << SIDE_LOG) // tspan[pair]
        keep = (mapped >= 0) & (mapped <= S)
        into_s.append(sample[at][keep])
        into_side.append(dst[pair][keep])
        into_t.append(mapped[keep])
    linked = np.concatenate(into_s)
    q, s2, t = np.concatenate(into_side) // 4, np.concatenate(into_side) % 4, np.concatenate(into_t)
    mu = np.choose(s2, [t, np.full_like(t, S), t, np.zeros_like(t)])
    mv = np.choose(s2, [np.zeros_like(t), t, np.full_like(t, S), t])

    # Points = unique (patch, u, v) keys; one vertex per connected set of keys naming one surface point
    def vkey(p, u, v):
        return (p * W + u) * W + v

    keys, inverse = np.unique(np.concatenate([vkey(cp, cu, cv), vkey(q, mu, mv)]), return_inverse=True)
    label = components(len(keys), np.stack([inverse[linked], inverse[4 * n:]], axis=1))
    count = int(label.max(initial=-1)) + 1
    first_sample = np.full(count, 4 * n, np.int64)
    np.minimum.at(first_sample, label[inverse[:4 * n]], np.arange(4 * n))
    vertices = positions[first_sample]
    spread = np.linalg.norm(positions - vertices[label[inverse[:4 * n]]], axis=1).max() / vox.voxel_size

    # The points strictly inside each leaf side, in polygon order (sides 2 and 3 run backwards)
    kp, ku, kv = keys // (W * W), keys // W % W, keys % W
    horizontal = np.argsort((kp * W + kv) * W + ku)
    vertical = np.arange(len(keys))                       # keys are sorted by (patch, u, v) already
    hsorted = ((kp * W + kv) * W + ku)[horizontal]
    order = np.concatenate([label[horizontal], label[vertical]])
    u1, v1 = u0 + step, v0 + step
    lo = np.stack([np.searchsorted(hsorted, (patch * W + v0) * W + u0, "right"),
                   len(keys) + np.searchsorted(keys, vkey(patch, u1, v0), "right"),
                   np.searchsorted(hsorted, (patch * W + v1) * W + u0, "right"),
                   len(keys) + np.searchsorted(keys, vkey(patch, u0, v0), "right")], axis=1)
    hi = np.stack([np.searchsorted(hsorted, (patch * W + v0) * W + u1, "left"),
                   len(keys) + np.searchsorted(keys, vkey(patch, u1, v1), "left"),
                   np.searchsorted(hsorted, (patch * W + v1) * W + u1, "left"),
                   len(keys) + np.searchsorted(keys, vkey(patch, u0, v1), "left")], axis=1)
    inserted = hi - lo                                                    # (n, 4)
    corner_vertex = label[inverse[:4 * n]].reshape(n, 4)
    plain = inserted.sum(axis=1) == 0
    faces = [corner_vertex[plain][:, [0, 1, 2]], corner_vertex[plain][:, [0, 2, 3]]]
    face_leaf = [np.flatnonzero(plain)] * 2

    poly = np.flatnonzero(~plain)
    if len(poly):
        ins = inserted[poly]                                              # (m, 4)
        size = 4 + ins.sum(axis=1)
        start = np.concatenate([[0], np.cumsum(size)[:-1]])
        side_start = start[:, None] + np.arange(4)[None] + np.concatenate(
            [np.zeros((len(poly), 1), np.int64), np.cumsum(ins, axis=1)[:, :-1]], axis=1)
        ring = np.empty(int(size.sum()), np.int64)
        ring[side_start.ravel()] = corner_vertex[poly].ravel()
        c = ins.ravel()
        edge = np.repeat(np.arange(len(c)), c)
        j = np.arange(int(c.sum())) - np.repeat(np.cumsum(c) - c, c)
        forward = edge % 4 < 2
        slot = np.where(forward, j, c[edge] - 1 - j)
        ring[side_start.ravel()[edge] + 1 + slot] = order[lo[poly].ravel()[edge] + j]
        owner = np.repeat(np.arange(len(poly)), size)
        nxt = np.arange(len(ring)) + 1
        nxt[np.cumsum(size) - 1] = start
        centre = len(vertices) + owner
        faces.append(np.stack([centre, ring, ring[nxt]], axis=1))
        face_leaf.append(poly[owner])
        vertices = np.concatenate([vertices, vox.corners[poly].astype(np.float64).mean(axis=1)])
    vertex_sample = np.concatenate([first_sample, np.full(len(poly), -1, np.int64)])
    mesh = Mesh(vertices, np.concatenate(faces))
    stats = dict(polygons=len(poly), inserted=int(inserted.sum()), weld_spread=float(spread),
                 side_pairs=len(a), open_sides=4 * npatch - len(np.union1d(a, b)),
                 vertices=len(vertices), triangles=len(mesh.faces))
    return LeafMesh(mesh, np.concatenate(face_leaf), vertex_sample, stats, vox.leaves)
