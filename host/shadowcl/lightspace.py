"""Light-space lists: occluding primitives binned by their projection onto the light's view(s).

This is an irregular Z-buffer's bookkeeping (Lai & Cheng, section 4.2, on the original primitives):
project every occluder onto a grid of cells in the light's view, keep a list per cell of the primitives
whose projection touches it, and test each receiver only against its own cell's list. It is generic
over primitives: it takes (P, K, 3) corners (K = 3 triangles; K = 4 planar convex quads) and knows
nothing about the test a method runs on the lists.

**Why one cell is enough.** Every point of a receiver's segment to a point light (its ray towards a
directional light) projects to the same point of the light's view as the receiver itself, so a
primitive that blocks the segment covers the receiver's projection, hence its cell.

**Views** (:func:`fit_views`), fitted to the receivers' bounds:

- directional light: one orthographic view along the light's direction, its window the bounding
  rectangle of the 8 projected corners of the receiver box;
- point light outside the receiver box, with every box corner in front of it within a cone of
  ``max_fov`` degrees: one perspective view (``u = d.right / d.forward``, ``v = d.up / d.forward``,
  ``d = p - light``) looking at the box centre, its window the projected corners' bounding rectangle;
- otherwise a cube of six perspective faces, faces ordered +x, -x, +y, -y, +z, -z; a point goes to the
  face of the dominant axis of ``d``.

Then (:func:`fit_to_footprint`, on the device) each window is cut to the bounding box of the *small*
primitives projecting into it, so the cells go where the occluders are dense: a bunny on a large
ground quad gets its cells over the bunny, not over the ground (measured on the bench's bunny scene:
lists of up to 460 triangles with the receivers' window, 69 with the fitted one); given the grid's
cell count, it is then grown back evenly until the cells over the footprint hold PRIMS_PER_CELL small
primitives each, so that the receivers around it get cells of their own, not the border's. The cells
are split between views in proportion to their small primitives, at least MIN_VIEW_CELLS each.

**Cells, levels and the border.** Each view has ``nx`` x ``ny`` fine cells and a coarse grid of
:data:`COARSE` x :data:`COARSE` fine cells per cell. A primitive with more candidate cells than a coarse
cell holds (a ground quad, a wall) is listed in the coarse grid only: a few entries instead of thousands
(the bench's ground quad, measured with 16 x 16 coarse cells: ~300 instead of ~600 k). A receiver walks
its fine and its coarse cell's lists. CSR lists built with ``fine_masks`` also give each coarse entry the
fine cells of its coarse cell that the primitive may touch (a 64-bit mask, the fine level's own test),
so a walk skips the coarse entries that touch none of its fine cells: the fine level's short walks at
the coarse level's build (a light inside a room, 1.2 M receivers, classify 23.9 -> 15.6 ms with normals,
46.6 -> 34.3 without; the default scene's build ~1 ms longer for a walk ~1.4 ms shorter). The outermost rows and columns of cells extend to the edge of the view's
*domain* (the whole plane for a single view, the face's square for a cube face): a primitive
projecting beyond the window is listed in the border cells it reaches, and a point projecting outside
the window (outside the prepared receiver bounds) falls into the nearest border cell, so
classification stays correct for any point the view covers. (A point *behind* a single perspective
view has no cell: the kernels report ``W <= 0`` and the method must handle it.)

**Conservative lists.** Primitives are clipped to the half-space in front of each perspective view
(``W >= 0``; parts behind a point light cannot block a receiver in front of it, whose segment lies in
front), projected, and listed in every cell whose rectangle enlarged by :data:`DELTA` cells (plus a
relative float32 rounding allowance per edge) the projected polygon touches: candidate cells from the
polygon's bounding box, then the separating-axis test on the polygon's edges. Clipping can make
vertices on the light's plane: they are points at infinity, kept as directions.

**Lists on the device.** ``lists="csr"`` (the default): count (atomic increments per cell; each
primitive also records its cells as a 64-bit mask over its candidate cells), exclusive prefix sum
(two launches of serial blocks, no local memory: :func:`lists.prefix_sum`), fill (atomic decrements give each entry its slot;
the mask spares re-projecting). The order within a cell is whatever the atomics give: the exact test
does not depend on it (sorting by distance would only shorten walks of lit receivers, which the exact
method's plane cull already makes cheap). ``lists="linked"``: one pass, nodes taken from an atomic
counter with a fixed capacity and pushed on per-cell heads with ``atomic_xchg``; a build that runs out
keeps counting but writes nothing, and the host grows the buffer to the counted size and reruns.
Measured on the bench's bunny scene: linked builds in one pass but its walk chases pointers through
interleaved nodes; CSR's classify is faster by more than linked saves in the build (see
host/shadowcl/exact.py).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from . import lists
from .checks import positive_int
from .lights import DirectionalLight, PointLight
from .lists import check_filled

DELTA = 1.0 / 64.0          # cell enlargement in cells (kernels/lightspace.cl: LS_DELTA)
VIEW_FLOATS = 32            # floats per view record (kernels/lightspace.h)
COARSE = 8                 # fine cells per coarse cell side (kernels/lightspace.h: LS_COARSE)
BIG = 1.0e30                # "infinite" domain side (kernels/vecmath.h: SC_BIG)
MAX_SIDE = 1 << 15          # cells per side of one view
MAX_CELLS = 1 << 24         # cells picked automatically at most
MIN_VIEW_CELLS = 4096       # cells of a view with few or no small primitives (docs/exact-speed.md)
SMALL_FRACTION = 1.0 / 16   # a primitive projecting wider than this share of the window is "large"
PRIMS_PER_CELL = 2.0        # small primitives per fine cell a grown window leaves its footprint (fit_to_footprint)
CELLS_PER_PRIM = 2          # cells per primitive (measured: pick_cell_count)
RECEIVERS_PER_CELL = 16     # receivers per cell (measured: pick_cell_count)
RECEIVER_CELLS = 1 << 17    # at most this many cells for the receivers' sake (measured: pick_cell_count)
MAX_FOV_DEGREES = 120.0     # widest single perspective view before the cube is used
CUBE_FACES = ((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0), (2, 1.0), (2, -1.0))   # (axis, sign) +x -x +y -y +z -z


def orthonormal_basis(forward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit ``right`` and ``up`` completing unit ``forward`` to an orthonormal frame (float64)."""
    helper = np.eye(3)[int(np.argmin(np.abs(forward)))]
    right = np.cross(helper, forward)
    right /= np.linalg.norm(right)
    return right, np.cross(forward, right)


def box_corners(bounds: np.ndarray) -> np.ndarray:
    lo, hi = bounds
    return np.array([[(lo, hi)[i >> k & 1][k] for k in range(3)] for i in range(8)], dtype=np.float64)


def _padded(low: float, high: float, minimum: float) -> tuple[float, float]:
    """[low, high] widened by 1e-3 of its extent (at least ``minimum`` wide) so boundary points are inside."""
    centre, half = 0.5 * (low + high), 0.5 * (high - low)
    half = max(half * (1 + 1e-3), 0.5 * minimum)
    return centre - half, centre + half


@dataclass(frozen=True)
class LightViews:
    """The light's view(s), in the scene's local frame (positions relative to ``origin``).

    ``axes[v]`` holds the rows right, up, forward of view ``v``; ``windows[v]`` the (u0, u1, v0, v1) its
    grid covers and ``domains[v]`` the part of the plane it answers for (infinite for a single view, the
    face's square [-1, 1]^2 for a cube face), both in projected units (tangents for perspective views,
    scene units for orthographic ones); ``eye`` is the light's position for perspective views, else
    zero. ``weights[v]`` is the number of small primitives whose projection fitted the window (it splits
    the cells between views).
    """

    kind: str                # "orthographic" | "perspective" | "cube"
    eye: np.ndarray          # (3,) float64
    axes: np.ndarray         # (V, 3, 3) float64
    windows: np.ndarray      # (V, 4) float64
    domains: np.ndarray      # (V, 4) float64, may be infinite
    weights: np.ndarray      # (V,) float64

    @property
    def nviews(self) -> int:
        return len(self.axes)

    @property
    def perspective(self) -> bool:
        return self.kind != "orthographic"

    @property
    def options(self) -> tuple[str, ...]:
        """Build options shared by every kernel that reads a grid over these views."""
        return (f"-DNVIEWS={self.nviews}", f"-DPERSPECTIVE={int(self.perspective)}")


def fit_views(light, receiver_bounds: np.ndarray, origin: np.ndarray, scale: float,
              max_fov: float = MAX_FOV_DEGREES) -> LightViews:
    """The light's view(s) for receivers in ``receiver_bounds`` ((2, 3) world box), in the frame at ``origin``.

    Each window covers the receivers (the projected corners of their box); :func:`fit_to_footprint`
    then cuts it to where the occluders are. ``scale`` (the scene's size) sets the smallest window when
    the receivers are a single point.
    """
    bounds = np.asarray(receiver_bounds, dtype=np.float64) - origin
    corners = box_corners(bounds)
    scale = max(float(scale), float(np.linalg.norm(bounds[1] - bounds[0])), 1e-30)
    infinite = np.array([[-np.inf, np.inf, -np.inf, np.inf]])
    if isinstance(light, DirectionalLight):
        forward = np.asarray(light.direction, dtype=np.float64)
        right, up = orthonormal_basis(forward)
        u, v = corners @ right, corners @ up
        window = (*_padded(u.min(), u.max(), 1e-6 * scale), *_padded(v.min(), v.max(), 1e-6 * scale))
        return LightViews("orthographic", np.zeros(3), np.stack([right, up, forward])[None], np.array([window]),
                          infinite, np.ones(1))
    if not isinstance(light, PointLight):
        raise TypeError(f"light: expected a PointLight or DirectionalLight, got {type(light).__name__}")
    eye = np.asarray(light.position, dtype=np.float64) - origin
    margin = 1e-6 * scale
    inside = bool(np.all(eye >= bounds[0] - margin) and np.all(eye <= bounds[1] + margin))
    if not inside:
        forward = 0.5 * (bounds[0] + bounds[1]) - eye
        forward /= np.linalg.norm(forward)
        right, up = orthonormal_basis(forward)
        d = corners - eye
        w = d @ forward
        if np.all(w > 1e-6 * np.linalg.norm(d, axis=1)):
            u, v = (d @ right) / w, (d @ up) / w
            if np.max(np.hypot(u, v)) <= math.tan(math.radians(max_fov / 2)):
                window = (*_padded(u.min(), u.max(), 1e-6), *_padded(v.min(), v.max(), 1e-6))
                return LightViews("perspective", eye, np.stack([right, up, forward])[None], np.array([window]),
                                  infinite, np.ones(1))
    axes = []
    for axis, sign in CUBE_FACES:
        forward = sign * np.eye(3)[axis]
        axes.append(np.stack([np.eye(3)[(axis + 1) % 3], np.eye(3)[(axis + 2) % 3], forward]))
    square = np.tile([-1.0, 1.0, -1.0, 1.0], (6, 1))
    return LightViews("cube", eye, np.array(axes), square, square.copy(), np.ones(6))


def fit_to_footprint(device, views: LightViews, prims, nprims: int, corners: int = 3,
                     small: float = SMALL_FRACTION, cells: int | None = None) -> LightViews:
    """``views`` with each window cut to the footprint of its *small* primitives (on the device), then,
    given the grid's ``cells``, grown back as far as the footprint keeps its resolution.

    ``prims`` is the device buffer of (P, K, 3) float32 corners. A primitive is small when its
    projection is at most ``small`` of the window wide and high: cells then go where occluders are
    dense. Large primitives (a ground plane, walls) need no cells of their own: outside the window they
    are listed in the border cells, which extend to the view's domain. A view without small primitives
    keeps its window with weight 0 (it gets MIN_VIEW_CELLS cells).

    The cut alone left the receivers outside the footprint to the border cells: cells reaching a cube
    face's edge, past the ground and into the sky, with long lists of the walls and ground, which no
    triangle covers (the exact method's planes decide none of their receivers). So each cut window is
    grown evenly on every side, within its first window, until the fine cells over its footprint hold
    PRIMS_PER_CELL small primitives each (the cell count's CELLS_PER_PRIM gives them about 1 / 2), so
    that cells go where the receivers are too. Measured one-shot (exact, 1.2 M receivers, medians of 11
    interleaved), against the cut alone: default 26.5 -> 18.6 ms with normals, 30.1 -> 21.4 without;
    light_inside 32.0 -> 24.9, 35.3 -> 26.2; teapot 35.5 -> 24.6, 36.0 -> 31.4; ogre 70.2 -> 67.4, 77.2 ->
    61.0; bunny 70.6 -> 58.6, 72.1 -> 61.0; city_block level; a directional and a far point light on
    bunny, default and city_block level or faster. 1 to 4 primitives a cell gave alike; the whole first
    window made bunny's and ogre's walks twice as long without normals (docs/exact-speed.md).
    """
    if nprims == 0:
        return views
    probe = make_grid(views, resolution=1)                  # 1 x 1 cell per view: window-relative units
    chunk = max(256, -(-nprims // 256))
    groups = -(-nprims // chunk)
    out = device.empty(4 * 5 * views.nviews * groups, "footprint partials")
    kernel = device.kernel("lightspace.cl", "ls_footprint", (f"-DCORNERS={corners}",) + probe.options)
    kernel(device.queue, (groups,), None, prims, np.int32(nprims), device.to_device(probe.params),
           np.float32(small), np.int32(chunk), out)
    part = device.from_device(out, (groups, views.nviews, 5), np.float32).astype(np.float64)
    windows, weights = views.windows.copy(), np.zeros(views.nviews)
    for k in range(views.nviews):
        count = part[:, k, 4].sum()
        if count == 0:
            continue
        x0, x1 = max(part[:, k, 0].min(), 0.0), min(part[:, k, 1].max(), 1.0)
        y0, y1 = max(part[:, k, 2].min(), 0.0), min(part[:, k, 3].max(), 1.0)
        u0, u1, v0, v1 = views.windows[k]
        minimum = 1e-6 * max(u1 - u0, v1 - v0)
        windows[k] = (*_padded(u0 + x0 * (u1 - u0), u0 + x1 * (u1 - u0), minimum),
                      *_padded(v0 + y0 * (v1 - v0), v0 + y1 * (v1 - v0), minimum))
        weights[k] = count
    if cells is not None:
        windows = _grown(windows, views.windows, weights, view_cells(weights, cells))
    return LightViews(views.kind, views.eye, views.axes, windows, views.domains, weights)


def _grown(windows: np.ndarray, bounds: np.ndarray, weights: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Each window with a small primitive grown by one margin on every side, within ``bounds``, to the area
    whose ``cells`` leave its footprint (the window itself) PRIMS_PER_CELL small primitives a cell."""
    out = windows.copy()
    for k in np.flatnonzero(weights > 0):
        u0, u1, v0, v1 = windows[k]
        b0, b1, c0, c1 = bounds[k]
        target = cells[k] * (u1 - u0) * (v1 - v0) * PRIMS_PER_CELL / weights[k]

        def area(m):
            return (min(u1 + m, b1) - max(u0 - m, b0)) * (min(v1 + m, c1) - max(v0 - m, c0))

        low, high = 0.0, max(b1 - b0, c1 - c0)          # area(high) is the bounds' whole area
        if area(high) <= target:
            out[k] = bounds[k]
            continue
        for _ in range(32):                             # area(m) grows with m: bisection
            middle = 0.5 * (low + high)
            low, high = (middle, high) if area(middle) < target else (low, middle)
        out[k] = (max(u0 - low, b0), min(u1 + low, b1), max(v0 - low, c0), min(v1 + low, c1))
    return out


def view_cells(weights: np.ndarray, cells: int) -> np.ndarray:
    """Fine cells of each view for about ``cells`` in all: shared in proportion to ``weights`` (evenly when
    all are 0), at least MIN_VIEW_CELLS each."""
    weights = weights if weights.sum() > 0 else np.ones(len(weights))
    return np.maximum(MIN_VIEW_CELLS, (cells * weights / weights.sum()).astype(np.int64))


def pick_cell_count(nprims: int, nreceivers: int | None) -> int:
    """Total cells for ``nprims`` occluders and about ``nreceivers`` receivers.

    The rule takes the larger of ``CELLS_PER_PRIM * P`` and ``N / RECEIVERS_PER_CELL`` (at most
    RECEIVER_CELLS), clamped.
    Measured on the bunny on a ground quad (69 k triangles, 1.2 M receivers, point and directional
    light), prepare + classify in ms for 0.5, 1, 2 and 4 cells per triangle: 66, 71, 62, 66 (point)
    and 56, 53, 58, 78 (directional): flat between 1 and 2, the build growing beyond (entries grow
    with cells while lists stop shrinking below ~5 triangles, the depth of the model). The receiver
    term only matters for many more receivers than triangles, and stops at RECEIVER_CELLS: beyond, the
    exact method's binning (an atomic count per receiver, a scatter into its cell) leaves the caches.
    Measured at 10 M receivers, one-shot ms, medians of 5 interleaved, uncapped (625 k cells) against
    2^17: bunny 947 -> 732, light_inside 997 -> 761, default 547 -> 485 (ogre, 2 x 124 k cells from its
    triangles anyway: 951 -> 896); bunny at 3 M 298 -> 258. At 1.2 M receivers (75 k cells) it does not bind.
    """
    wanted = CELLS_PER_PRIM * nprims
    if nreceivers:
        wanted = max(wanted, min(nreceivers // RECEIVERS_PER_CELL, RECEIVER_CELLS))
    return int(min(max(wanted, 64 * 64), MAX_CELLS))


@dataclass(frozen=True)
class Grid:
    """Views and their cells: view ``v`` has ``nx[v]`` x ``ny[v]`` fine cells numbered from ``base0[v]``
    and ``nx1[v]`` x ``ny1[v]`` coarse cells (COARSE x COARSE fine cells each) numbered from ``base1[v]``;
    fine cells of all views come first. ``params`` is the (V, VIEW_FLOATS) float32 view table of the
    kernels (kernels/lightspace.h).
    """

    views: LightViews
    nx: np.ndarray
    ny: np.ndarray
    base0: np.ndarray
    nx1: np.ndarray
    ny1: np.ndarray
    base1: np.ndarray
    params: np.ndarray = field(repr=False)

    @property
    def fine_cells(self) -> int:
        return int(np.sum(self.nx * self.ny))

    @property
    def cells(self) -> int:
        """Fine and coarse cells of every view."""
        return int(self.fine_cells + np.sum(self.nx1 * self.ny1))

    @property
    def options(self) -> tuple[str, ...]:
        """Build options shared by every kernel that reads this grid."""
        return self.views.options


def _sides(cells: int, aspect: float) -> tuple[int, int]:
    nx = min(max(int(round(math.sqrt(cells * aspect))), 1), MAX_SIDE)
    return nx, min(max(int(round(cells / nx)), 1), MAX_SIDE)


def make_grid(views: LightViews, cells: int | None = None, resolution: int | None = None) -> Grid:
    """A grid over ``views``: about ``cells`` cells in all, or ``resolution`` cells on each window's longer side.

    Cells are shared between views in proportion to their weights (at least MIN_VIEW_CELLS each); each
    window's aspect decides its ``nx`` / ``ny`` so cells are square-ish.
    """
    V = views.nviews
    aspects = (views.windows[:, 1] - views.windows[:, 0]) / (views.windows[:, 3] - views.windows[:, 2])
    if resolution is not None:
        resolution = positive_int("resolution", resolution, 1, MAX_SIDE)
        sides = [(resolution, max(1, round(resolution / a))) if a >= 1 else (max(1, round(resolution * a)), resolution)
                 for a in aspects]
    else:
        per_view = view_cells(views.weights, positive_int("cells", int(cells), 1))
        sides = [_sides(int(per_view[k]), aspects[k]) for k in range(V)]
    nx = np.array([s[0] for s in sides], dtype=np.int64)
    ny = np.array([s[1] for s in sides], dtype=np.int64)
    nx1, ny1 = (nx - 1) // COARSE + 1, (ny - 1) // COARSE + 1
    base0 = np.concatenate([[0], np.cumsum(nx * ny)[:-1]])
    base1 = int(np.sum(nx * ny)) + np.concatenate([[0], np.cumsum(nx1 * ny1)[:-1]])
    total = int(np.sum(nx * ny) + np.sum(nx1 * ny1))
    if total >= 2**31 - 1:
        raise ValueError(f"resolution: {total} cells do not fit 32-bit indices; lower it")
    # The views' records (kernels/lightspace.h), all views at once: a loop over them cost ~0.6 ms of
    # NumPy calls per grid, and a one-shot call makes two grids.
    u0, u1, v0, v1 = views.windows.T
    sx, sy = nx / (u1 - u0), ny / (v1 - v0)
    right, up, forward = views.axes[:, 0], views.axes[:, 1], views.axes[:, 2]
    rows = np.zeros((V, 16))
    if views.perspective:
        # The rows act on p - anchor. A single view's anchor is the local origin (near the scene), its
        # eye folded into the constant column in float64: p - eye in float32 would round by ulp(|eye|),
        # and for a light 3e3 scene sizes away that moved points by several cells of a fine grid (a
        # shadowing triangle missing from a receiver's fine cell: docs/known-defects.md). The cube's
        # anchor is its eye (inside the scene), which ls_point_view needs, with no constant column.
        anchor = views.eye if views.kind == "cube" else np.zeros(3)
        rows[:, 0:3] = anchor
        rows[:, 4:7] = sx[:, None] * (right - u0[:, None] * forward)
        rows[:, 8:11] = sy[:, None] * (up - v0[:, None] * forward)
        rows[:, 12:15] = forward
        offset = anchor - views.eye
        for column, block in ((7, rows[:, 4:7]), (11, rows[:, 8:11]), (15, rows[:, 12:15])):
            rows[:, column] = np.einsum("vk,k->v", block, offset)
    else:
        rows[:, 4:7], rows[:, 7] = sx[:, None] * right, -sx * u0
        rows[:, 8:11], rows[:, 11] = sy[:, None] * up, -sy * v0
        rows[:, 15] = 1.0
    params = np.zeros((V, VIEW_FLOATS), dtype=np.float32)
    params[:, :16] = rows
    ints = params.view(np.int32)
    ints[:, 16:20] = np.stack([nx, ny, base0, base1], axis=1)
    ints[:, 24:26] = np.stack([nx1, ny1], axis=1)
    du0, du1, dv0, dv1 = views.domains.T
    domain = np.stack([(du0 - u0) * sx, (du1 - u0) * sx, (dv0 - v0) * sy, (dv1 - v0) * sy], axis=1)
    params[:, 20:24] = np.clip(np.nan_to_num(domain, posinf=BIG, neginf=-BIG), -BIG, BIG)
    return Grid(views, nx, ny, base0, nx1, ny1, base1, params)


@dataclass
class Lists:
    """Per-cell primitive lists on the device, and what building them cost.

    CSR: ``offsets`` (cells + 1 ints) and ``items`` (entries ints); built with ``fine_masks``, also
    ``fine_masks`` (one uint64 per coarse entry, in the items' order from the first coarse cell's: bit
    ``(i % COARSE) + COARSE * (j % COARSE)`` set for each fine cell (i, j) the entry's primitive may touch).
    Linked: ``heads`` (cells ints, -1 = empty) and ``nodes`` (2 ints per node: primitive, next).
    ``stats`` holds counts and stage times (s).
    """

    kind: str
    grid: Grid
    nprims: int
    entries: int
    offsets: cl.Buffer | None = None
    items: cl.Buffer | None = None
    heads: cl.Buffer | None = None
    nodes: cl.Buffer | None = None
    capacity: int = 0
    coarse_entries: int = -1          # entries in coarse cells (-1: unknown, linked lists)
    fine_masks: cl.Buffer | None = None
    params: cl.Buffer | None = None
    stats: dict = field(default_factory=dict)

    def buffers(self) -> tuple[cl.Buffer, cl.Buffer]:
        """The two list buffers the kernels take: (offsets, items) or (heads, nodes)."""
        return (self.offsets, self.items) if self.kind == "csr" else (self.heads, self.nodes)

    def to_host(self, device) -> tuple[np.ndarray, np.ndarray]:
        """The lists as CSR (offsets (cells + 1,), items (entries,)); cells of linked lists in node order."""
        cells = self.grid.cells
        if self.kind == "csr":
            offsets = device.from_device(self.offsets, cells + 1, np.int32)
            return offsets.astype(np.int64), device.from_device(self.items, self.entries, np.int32)
        heads = device.from_device(self.heads, cells, np.int32)
        nodes = device.from_device(self.nodes, (max(self.capacity, 1), 2), np.int32)
        per_cell = []
        for head in heads:
            found, node = [], int(head)
            while node >= 0:
                found.append(nodes[node, 0])
                node = int(nodes[node, 1])
            per_cell.append(found)
        lengths = np.array([len(c) for c in per_cell], dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(lengths)])
        items = np.array([p for c in per_cell for p in c], dtype=np.int32)
        return offsets, items


class ListBuilder:
    """Builds :class:`Lists` for one grid and primitive buffer; keeps its scratch buffers between builds."""

    def __init__(self, device, corners: int = 3):
        if corners not in (3, 4):
            raise ValueError(f"corners: primitives have 3 or 4 corners, got {corners}")
        self.device = device
        self.corners = corners
        self._counts = None       # (cells,) int, reused between builds of the same size
        self._counts_cells = 0

    def _kernel(self, grid: Grid, name: str):
        return self.device.kernel("lightspace.cl", name, (f"-DCORNERS={self.corners}",) + grid.options)

    def build(self, grid: Grid, prims: cl.Buffer, nprims: int, kind: str = "csr",
              initial_capacity: int | None = None, fine_masks: bool = False) -> Lists:
        """Lists of the ``nprims`` primitives in ``prims`` ((P, K, 3) float32 on the device) over ``grid``;
        ``fine_masks`` (CSR): each coarse entry's fine cells too (:class:`Lists`)."""
        if kind not in ("csr", "linked"):
            raise ValueError(f"lists: expected 'csr' or 'linked', got {kind!r}")
        dev, queue = self.device, self.device.queue
        cells = grid.cells
        params = dev.to_device(grid.params)
        lists = Lists(kind, grid, nprims, 0)
        lists.stats.update(cells=cells, nx=grid.nx.tolist(), ny=grid.ny.tolist(), views=grid.views.nviews,
                           view_kind=grid.views.kind)
        gsize = (max(nprims, 1),)
        if kind == "csr":
            t0 = time.perf_counter()
            if self._counts is None or self._counts_cells != cells:
                self._counts = dev.empty(4 * cells, "light-space cell counts")
                self._counts_cells = cells
            # Zeroed on every build, not trusted to the previous fill: a build interrupted between count
            # and fill would leave slots that the next fill writes past their cell.
            cl.enqueue_fill_buffer(queue, self._counts, np.int32(0), 0, 4 * cells)
            records = dev.empty(16 * max(nprims, 1), "light-space count records")
            dropped = dev.scratch("lightspace: dropped entries", 4)
            cl.enqueue_fill_buffer(queue, dropped, np.int32(0), 0, 4)
            csr = self._kernel(grid, "ls_csr")
            masks_flag = np.int32(bool(fine_masks))
            csr(queue, gsize, None, prims, np.int32(nprims), params, self._counts, records, np.int32(0), dropped,
                dropped, dropped, masks_flag, None)  # count: the fill's buffers unused
            queue.finish()
            t1 = time.perf_counter()
            offsets = dev.empty(4 * (cells + 1), "light-space offsets")
            total = self.prefix_sum(grid, self._counts, cells, offsets)
            t2 = time.perf_counter()
            limit = min(dev.max_alloc_bytes // 4, 2**31 - 1)
            if total > limit:
                raise ValueError(f"resolution: the lists need {total} entries, more than {dev.name} holds in one "
                                 f"buffer ({limit}); lower the resolution")
            items = dev.empty(4 * max(total, 1), "light-space lists")
            fine = np.empty(1, np.int32)
            cl.enqueue_copy(queue, fine, offsets, src_offset=4 * grid.fine_cells)
            lists.coarse_entries = total - int(fine[0])
            if fine_masks:
                lists.fine_masks = dev.empty(8 * max(lists.coarse_entries, 1), "light-space coarse entries' fine cells")
            csr(queue, gsize, None, prims, np.int32(nprims), params, self._counts, records, np.int32(1), offsets,
                items, dropped, masks_flag, lists.fine_masks)
            check_filled(dev, dropped, "lightspace: the lists' fill")
            t3 = time.perf_counter()
            lists.offsets, lists.items, lists.entries, lists.capacity = offsets, items, total, total
            lists.stats.update(project_count_s=t1 - t0, scan_s=t2 - t1, fill_s=t3 - t2, rebuilds=0)
        else:
            capacity = int(initial_capacity) if initial_capacity is not None else max(1024, 8 * nprims)
            heads = dev.empty(4 * cells, "light-space list heads")
            counter = dev.empty(4, "light-space node counter")
            rebuilds = 0
            t0 = time.perf_counter()
            while True:
                nodes = dev.empty(8 * max(capacity, 1), "light-space list nodes")
                cl.enqueue_fill_buffer(queue, heads, np.int32(-1), 0, 4 * cells)
                cl.enqueue_fill_buffer(queue, counter, np.int32(0), 0, 4)
                self._kernel(grid, "ls_fill_linked")(queue, gsize, None, prims, np.int32(nprims), params,
                                                     heads, nodes, np.int32(capacity), counter)
                used = int(dev.from_device(counter, 1, np.int32)[0])
                if used < 0:
                    raise ValueError("resolution: the linked lists overflowed a 32-bit node counter; lower it")
                if used <= capacity:
                    break
                capacity = used          # the counter kept counting: exactly what a rerun needs
                rebuilds += 1
            t1 = time.perf_counter()
            lists.heads, lists.nodes, lists.entries, lists.capacity = heads, nodes, used, capacity
            lists.stats.update(project_count_s=0.0, scan_s=0.0, fill_s=t1 - t0, rebuilds=rebuilds)
        lists.stats.update(entries=lists.entries, coarse_entries=lists.coarse_entries, build_s=sum(lists.stats[k] for k in ("project_count_s", "scan_s", "fill_s")))
        lists.params = params
        return lists

    def prefix_sum(self, grid: Grid, counts: cl.Buffer, n: int, offsets: cl.Buffer, second_row: int = 0) -> int:
        """offsets = exclusive prefix sum of counts (n + 1 entries); returns the total (:func:`lists.prefix_sum`)."""
        return lists.prefix_sum(self.device, lambda name: self._kernel(grid, name), counts, n, offsets, second_row)


def point_cells(device, grid: Grid, points_rel: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fine cell, coarse cell and W of each point ((N, 3), relative to the grid's origin), as the kernels
    compute them (W <= 0: behind a single perspective view, no cell)."""
    points32 = np.ascontiguousarray(points_rel, dtype=np.float32)
    n = len(points32)
    fine, coarse, w = device.empty(4 * n, "cells"), device.empty(4 * n, "cells"), device.empty(4 * n, "w")
    kernel = device.kernel("lightspace.cl", "ls_points", ("-DCORNERS=3",) + grid.options)
    if n:
        kernel(device.queue, (n,), None, device.to_device(points32), np.int32(n), device.to_device(grid.params),
               fine, coarse, w)
    return (device.from_device(fine, n, np.int32), device.from_device(coarse, n, np.int32),
            device.from_device(w, n, np.float32))
