"""Voxelization of Catmull-Clark limit surfaces by parameter-space subdivision (Lai & Cheng, section 3).

Each patch of the patch table (host/shadowcl/subdivision.py's contract: ``points``, ``first``,
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

**Fixed capacities.** Each level's child queue and the leaf array have a capacity; the kernel counts
what it wanted, the host grows the buffer to the counted size and reruns the level.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from .checks import check_bounds, positive_int

CONNECTIVITIES = (6, 18, 26)
MAX_RESOLUTION = 1024      # linear voxel indices (i * R + j) * R + k are 32-bit (kernels/voxelize.cl)
MAX_DEPTH = 24             # kernels/voxelize.cl: subdivision levels (parameters exact in float32)
LEAF_WORDS = 20            # kernels/voxelize.cl: leaf record
GROWTH = 1.25              # capacity headroom over a counted overflow


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


def grid_frame(points: np.ndarray, resolution: int, bounds=None) -> tuple[np.ndarray, float]:
    """(origin, voxel_size) of a cube of ``resolution`` voxels centred on ``bounds`` ((2, 3) box; None: the
    box of ``points``), a hair larger than the box's longest side."""
    if bounds is None:
        lo, hi = points.min(axis=0).astype(np.float64), points.max(axis=0).astype(np.float64)
    else:
        lo, hi = check_bounds("grid_bounds", bounds)
        if np.any(points.min(axis=0) < lo) or np.any(points.max(axis=0) > hi):
            raise ValueError("grid_bounds: the box must contain every control point of the surfaces")
    extent = float(np.max(hi - lo))
    if not np.isfinite(extent):
        raise ValueError("surface: control points are not finite")
    if extent == 0.0:
        extent = max(float(np.max(np.abs(lo))), 1.0) * 1e-3
    # a hair larger than the box so the largest coordinate falls inside the last voxel
    size = extent * (1.0 + 2.0 ** -12) / resolution
    return 0.5 * (lo + hi) - 0.5 * size * resolution, size


def patch_table_of(device, surface_or_table):
    """The patch table of a surface (``.patch_table(device)``) or a table itself (``points``, ``first``, ``levels``)."""
    if hasattr(surface_or_table, "patch_table"):
        return surface_or_table.patch_table(device)
    if all(hasattr(surface_or_table, name) for name in ("points", "first", "levels")):
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
             frame_buffer: bool | None = None, initial_capacity: int | None = None, grid_bounds=None) -> Voxelization:
    """Voxelize a subdivision surface (or its patch table) into a ``resolution``^3 cubic frame buffer.

    ``connectivity`` (6, 18, 26) is the N of N-adjacency a leaf's corner voxels must satisfy.
    ``frame_buffer``: True keeps the packed 2-bit buffer on the device (raises if it does not fit), False
    keeps only the leaves (section 5.1), None keeps it when it fits in one device buffer.
    ``initial_capacity`` sizes the first queue and leaf buffers (tests use a tiny one to force regrowth).
    ``grid_bounds`` ((2, 3) world box holding every control point) fixes the cube the grid spans, so
    different surfaces can share one voxel grid; None: the control points' box.
    """
    resolution = positive_int("resolution", resolution, 1, MAX_RESOLUTION)
    if connectivity not in CONNECTIVITIES:
        raise ValueError(f"connectivity: expected one of {CONNECTIVITIES}, got {connectivity!r}")
    table = patch_table_of(device, surface_or_table)
    points, first, levels = check_table(table)
    origin, size = grid_frame(points, resolution, grid_bounds)
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
                out_cap = int(wanted_out * GROWTH)
                items_out = dev.empty(16 * out_cap, "voxelization queue")
            if wanted_leaves > leaf_cap:
                leaf_cap = int(wanted_leaves * GROWTH)
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
    queue.finish()
    elapsed = time.perf_counter() - t0
    stats = dict(resolution=resolution, connectivity=connectivity, patches=npatch, leaves=nleaves,
                 forced_leaves=forced, levels=level, reruns=reruns, per_level=per_level, voxelize_s=elapsed,
                 frame_buffer=bool(frame_buffer), frame_bytes=frame_bytes if frame_buffer else 0,
                 leaf_bytes=4 * LEAF_WORDS * nleaves, subpatches=int(sum(n for _, n, _ in per_level)))
    return Voxelization(resolution, connectivity, origin, size, leaves, leaves_g, frame_dev, dev, stats)


@dataclass(frozen=True)
class Patches:
    """A patch table with just what the voxelizer reads (the contract's ``points``, ``first``,
    ``levels``, ``neighbors``): built from a control grid (:func:`grid_patch_table`, no subdivision code:
    tests and benches) or from several surfaces' tables (:func:`merge_tables`, a scene)."""

    points: np.ndarray
    first: np.ndarray
    levels: np.ndarray
    neighbors: np.ndarray


def merge_tables(tables) -> Patches:
    """One table holding every patch of ``tables`` in order (patch ids offset, neighbours renumbered)."""
    tables = list(tables)
    if not tables:
        raise ValueError("surfaces: nothing to voxelize")
    points, first, levels, neighbors = [], [], [], []
    point_base = patch_base = 0
    for table in tables:
        points.append(np.asarray(table.points, dtype=np.float32))
        first.append(np.asarray(table.first, dtype=np.int64) + point_base)
        levels.append(np.asarray(table.levels, dtype=np.uint32))
        nb = np.asarray(table.neighbors, dtype=np.int64)
        neighbors.append(np.where(nb >= 0, nb + patch_base, -1))
        point_base += len(points[-1])
        patch_base += len(first[-1])
    return Patches(np.concatenate(points), np.concatenate(first).astype(np.uint32), np.concatenate(levels),
                   np.concatenate(neighbors).astype(np.int32))


def grid_patch_table(net, wrap_u: bool = False, wrap_v: bool = False) -> Patches:
    """Regular B-spline patches of the (m, n, 3) control grid ``net`` (u along the first axis, v along
    the second): one per interior span, or per span along a wrapped axis (a torus wraps both).

    Patch normals (du x dv) follow the grid's orientation: make it outward for closed surfaces.
    """
    net = np.asarray(net, dtype=np.float64)
    if net.ndim != 3 or net.shape[2] != 3:
        raise ValueError(f"net: expected an (m, n, 3) control grid, got shape {net.shape}")
    m, n = net.shape[:2]
    pu = m if wrap_u else m - 3
    pv = n if wrap_v else n - 3
    if pu < 1 or pv < 1:
        raise ValueError("net: too few control points for one patch (4 per open axis)")
    a0 = np.arange(pu) - (1 if wrap_u else 0)
    b0 = np.arange(pv) - (1 if wrap_v else 0)
    ii, jj = np.arange(4), np.arange(4)
    A = (a0[:, None, None, None] + ii[None, None, None, :]) % m          # [a, b, j, i]
    B = (b0[None, :, None, None] + jj[None, None, :, None]) % n
    A, B = np.broadcast_arrays(A, B)
    points = net[A, B].reshape(-1, 3).astype(np.float32)
    count = pu * pv
    a, b = np.meshgrid(np.arange(pu), np.arange(pv), indexing="ij")

    def index(x, y):
        ok = np.ones_like(x, dtype=bool)
        if wrap_u:
            x = x % pu
        else:
            ok &= (x >= 0) & (x < pu)
        if wrap_v:
            y = y % pv
        else:
            ok &= (y >= 0) & (y < pv)
        return np.where(ok, np.clip(x, 0, pu - 1) * pv + np.clip(y, 0, pv - 1), -1)

    neighbors = np.stack([index(a, b - 1), index(a + 1, b), index(a, b + 1), index(a - 1, b)], axis=-1)
    return Patches(points, (16 * np.arange(count)).astype(np.uint32), np.zeros(count, np.uint32),
                          neighbors.reshape(-1, 4).astype(np.int32))
