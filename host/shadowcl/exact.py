"""The exact method: alias-free hard shadows from light-space lists and a watertight ray/triangle test.

Lai & Cheng's topology-based determination (section 4.2) applied to the original triangles, i.e. an
irregular Z-buffer: :mod:`shadowcl.lightspace` bins every triangle into the cells of the light's view
its projection touches (on the device, with atomics); each receiver then tests its segment to the light
against its own cells' lists only (kernels/exact.cl), with the watertight test of Woop, Benthin & Wald
(2013) or, as a variant, the paper's 5-dot-product test. The answer is the ground truth every other
method is measured against.

Local frame: all device geometry is relative to the centre of the union of the mesh's and the
receivers' bounds (computed in float64 on the host, then rounded to float32), and points are made
relative the same way (on the device in double when it has cl_khr_fp64, else on the host), so a scene
far from the world origin keeps its float32 precision. With doubles, the working frame's move of the
receivers (:class:`shadowcl.points.MovedPoints`) is done there too, in the first pass over them: the
caller's float64 array goes to the device as it is (1.2 M receivers: one host pass of ~10 ms saved).
That pass reads the points before the host does in ``shadow_mask``'s one-shot call (:meth:`classify_near`):
it codes a non-finite point 3 and one beyond the occluders' near box FAR, so that the host needs no box
of them and no finiteness pass (3-5 ms at 1.2 M receivers) unless one is coded.

Choices, measured on the bench's scenes (bench/receivers.py: bunny or ogre on a ground quad, 1 M
receivers on the ground + 200 k on the model, random order, PoCL on 2 cores; ranges are run-to-run):

- CSR lists (default) over linked lists: the linked build's single pass costs more than count + scan
  + fill (every entry takes a node from one global atomic counter: 36-65 ms against 15-25 ms) and its
  walk chases pointers (classify 1.4-1.5x slower).
- Triangle records of 128 bytes (the 9 corner floats, the unit normal and the light's side of the
  plane; then the triangle's three edge planes through the light, or along a directional light's
  travel, with their rounding bounds): the kernel first skips a triangle whose plane the segment
  cannot reach (plane cull, exact: it never removes a crossing), which rejects ~3/4 of the visited
  entries; then the edge planes settle the rest (a lane's line to the light certainly outside the
  triangle's cone: miss; certainly inside with the plane certainly crossed: hit), and only lanes
  within rounding of an edge, a vertex or the plane take the watertight test, which decides them as
  before (ray_triangle.h wt_cone; the bound makes the cone never contradict a certain answer, so it
  opens no leak). Against the watertight test for every lane past the cull (2026-12-07, bench/kernels_ab.py,
  interleaved, medians (minima) of 9, classify ms, with / without normals): default 7.3 (7.2) -> 6.5
  (6.1) / 19.6 (15.7) -> 16.8 (13.5), light_inside 18.1 (12.9) -> 11.7 (9.8) / 33.2 (28.4) -> 29.3
  (19.9), bunny 21.7 (20.6) -> 21.4 (17.6) / 34.3 (25.8) -> 32.2 (23.8), ogre 21.5 (21.4) -> 18.4 (18.1)
  / 32.9 (27.9) -> 25.0 (24.8), city_block 9.9 (9.6) -> 6.8 (6.6) / 27.0 (22.2) -> 13.2 (11.3), teapot
  14.6 (13.5) -> 13.9 (10.4) / 18.2 (16.1) -> 18.1 (13.6); the same masks on all 12.
- Lists are not sorted by distance: with the cull, lit receivers' walks are cheap, and shadowed ones
  stop at the first hit; a sort would cost a pass.
- Receivers are binned by cell on the device, then walked ``BIN_LANES`` (8) at a time (``order="cells"``,
  kernels/exact.cl): each triangle of a cell's list is loaded once and tested against all the packet's
  lanes in OpenCL vectors. Against the per-receiver walk in the caller's order (``order="caller"``,
  kept), one-shot ``shadow_mask`` at 1.2 M random-order receivers, alternating in one process, medians
  of 9 (2026-12-04), caller -> cells in ms, with / without normals: default 50.5 -> 30.5 / 80.3 -> 43.4,
  light_inside 65.5 -> 32.9 / 121.0 -> 44.4, bunny 91.3 -> 51.9 / 94.4 -> 56.7, ogre 124.5 -> 81.2 /
  129.1 -> 83.5, teapot 75.9 -> 37.2 / 71.8 -> 37.4, city_block 56.6 -> 34.1 / 72.3 -> 36.5: 1.5-2.7x,
  the same masks. (On 2026-12-01, with the binning passes of then, before the later changes below,
  cells lost on default with normals, 57 -> 92 ms, and won by the sum.) Lanes: 8 against 1
  on light_inside 95 / 169 ms with normals, 4 lanes 108; 16 crashes PoCL's LLVM 14 ("Do not know how
  to scalarize"), double8 arithmetic miscompiled there (ray_triangle.h's refinement is per lane).
- Binning without recomputing: pass 1 starts ``BIN_LANES`` receivers per work-item (their rows read
  as vectors and shuffled into lanes, the move, the normal, back-face and eps arithmetic over lanes;
  against loading and moving them one receiver at a time, interleaved in one process, medians of 11,
  the pass in ms with / without normals: default 20.2 -> 14.6 / 22.0 -> 17.4, bunny 14.4 -> 10.0 /
  13.4 -> 9.8, ogre 24.4 -> 17.6 / 21.1 -> 12.5, light_inside 19.0 -> 13.7 / 19.9 -> 15.4, the same
  masks), finds their cells over lanes too (kernels/lightspace.h ls_point_cells: then, the same way,
  default 15.6 -> 11.8 / 15.0 -> 9.9, light_inside 16.0 -> 12.1 / 12.9 -> 7.7, bunny 13.5 -> 9.9 / 10.1
  -> 7.6, ogre 13.1 -> 9.9 / 10.5 -> 7.7) and writes a
  16-byte record of its start and cell in the caller's order; pass 2 scatters that record with the
  receiver's index in place of the cell (one 16-byte store, one line, per receiver); the walk reads
  them in order and recomputes tmin (a square root per packet) and the cells from the start, over
  lanes. Against re-finding the cell from the start in pass 2 too (bunny bench with normals,
  alternating processes, medians of 5, three rounds): fill 13.0, 12.9, 12.8 -> 11.0, 7.0, 7.2 ms,
  one-shot 97.5, 92.6, 91.6 -> 100.4, 85.8, 84.5 ms. Against scattering the cell-tagged record and the
  index to two arrays (two lines per receiver; 2026-12-07, alternating processes, medians of 3 runs of
  7 calls, fill ms, with / without normals): bunny 9.7 -> 5.9 / 10.8 -> 8.0, default 7.7 -> 7.7 / 6.9
  -> 5.4, light_inside 9.5 -> 7.5 / 11.0 -> 9.5, city_block 9.2 -> 7.4 / 12.2 -> 8.5, teapot 7.0 -> 6.0 /
  7.2 -> 5.3; the walk within this VM's noise (+-2 ms both ways), the masks identical.
  The slots: on a CPU of up to 4 cores two work-items bin half the receivers each, serially, counting
  in rows of their own and filling the cells from both ends (no atomics: :func:`bins_from_both_ends`;
  default scene, alternating processes, medians of 4: the pass 10.3 -> 7.1 ms, the call 38.5 -> 34.5);
  the fill's two work-items replay the same halves, taking places from their rows down to zero, so no
  slot per receiver is stored (against the slot array and a fill per receiver, 2026-12-07, alternating
  processes, medians of 3 rounds of 5, count + fill ms with / without normals: default 16.5 -> 14.3 /
  11.6 -> 12.0, light_inside 14.9 -> 13.2 / 15.1 -> 12.2, bunny 14.2 -> 12.4 / 9.9 -> 11.4: the count
  1-2 ms cheaper everywhere, the serial fill up to 1.7 ms dearer without normals). Each end writes
  only its walkers' records, packed from its first receiver on, already tagged with their index, their
  cells beside (kernels/exact.cl ``pack_walkers``): with most receivers decided by their cell's plane,
  the fill reads nothing of the rest (against a record for every receiver, 2026-12-07, alternating
  processes, medians of 11, fill / count / call ms with normals: default 1.17 -> 0.10 / 8.3 -> 9.6 /
  18.0 -> 18.4, light_inside 2.7 -> 0.6 / 8.9 -> 10.1 / 21.6 -> 20.9, city_block 5.3 -> 1.7 / 9.5 ->
  10.5 / 26.5 -> 24.7; without normals the calls 20.7 -> 19.6, 26.0 -> 23.2, 26.2 -> 24.3; bunny, ogre
  and teapot within +-1.1; the same masks). Elsewhere
  atomic_inc per receiver, last and back to back: a locked operation drains the stores
  before it, and interleaved with the records' stores the pass took 20.5-21.4 ms against 15.0-15.4. (Earlier, 2026-12-02: scattering the start instead of re-reading float64 points and
  normals in pass 2 took the fill from 126-448 to 40-172 ms on a loaded machine; the walk gathering
  records through the index instead of a scatter pass cost what the scatter saved.) Tried and
  dropped: docs/exact-speed.md.
- Watertight against dot5: the same speed within noise (the cull does most of the rejecting); dot5
  leaks on 6-8% of rays aimed at shared edges and vertices, watertight on none.
- Slivers and long strips (aspect ratios to 1e-4): the float32 edge functions decide inside-ness
  watertightly, but the hit distance T / det is a sum of products of large sheared coordinates, and a
  31-unit strip met at 0.04 degrees 0.01 from the receiver came out behind it (leaks on two of the
  eight sliver-prism cases of the tests). With doubles on the device (``WT_REFINE_F64``), a triangle
  found inside gets its distance again in double from the same float32 inputs: no leak, the same masks
  on bunny, light_inside and the default scene. Only where float32 cannot be sure: ray_triangle.h's
  ``wt_certain`` bounds the rounding of T and det and refines the lanes whose comparisons lie within
  the bounds (slivers, grazing rays, hits at an end of the interval; no lane of the bench scenes).
  Refining every inside lane cost, in classify ms, interleaved medians of 9-15 (2026-12-02), refined
  -> filtered, with / without normals: city of 4 icospheres 24.6 -> 17.6 / -, default 11.7 -> 9.7 /
  33.9 -> 20.9, bunny - / 43.1 -> 33.2, light_inside - / 64.2 -> 54.2; masks identical. The plane cull's tolerance grows with how far a sliver's computed normal may lean
  (eps / sin of its angle, ``NORMAL_ULPS``); those cases did not need it, the bound says it can.
- Large triangles in long coarse lists are binned by pieces (``split``, CSR only; :meth:`ExactMethod._split_lists`).
  A light inside a room (scenes/hard/light_inside.toml, cube of six views) had its walls, floor and
  long pillar faces in the coarse lists: 46 coarse entries per receiver on average, 52 in all per
  walk (38 of them crossing the segment's plane, i.e. past the cull), classify at ~3x Embree's time.
  Binned by pieces (the walk still tests the original triangle): mean walk 18 entries (p99 84 -> 43),
  13 past the cull, same masks bit for bit. Split off and on alternating (loaded machine): classify
  0.44x, prepare + classify 0.48x, prepare 2.8 -> 12.3 ms (five more builds, the host's dedup); vs
  the fastest Embree 0.30 -> 0.65 and 0.57 -> 0.73 in bench runs (bench/results/exact-split-light-inside.md).
  Triggered only when the coarse lists hold more than SPLIT_PER_COARSE_CELL entries per coarse cell.
  **Off by default** since the public one-shot call was measured (2026-12-01, 1.2 M receivers, the
  16 shipped and model scenes, split off / on alternating, median of 5): it triggers on 5 of them and
  makes the one-shot ``shadow_mask`` slower on 4 (teapot 81 -> 102 ms, default 53 -> 119, contact 58 ->
  87, far_offset 53 -> 115) and 8 % faster on light_inside (164 -> 151): its build (five more list
  builds and the host's dedup, ~60 ms) costs more than one query saves. A caller who prepares once
  and queries many times with long coarse lists (light_inside: query 161 -> 71 ms) passed split=True.
  Measured again 2026-12-04 (light_inside, 1.2 M receivers, one structure of each, queries alternating,
  medians of 9, masks identical): the walk's bound halves (23.6 -> 10.8 entries), but the query is
  only 27.9 -> 26.4 ms with normals and 42.6 -> 41.9 without, for a prepare of 4.2 -> 57.3 ms. Since
  2026-12-02 the coarse entries carry their fine cells (lightspace.cl ls_fine_mask), and a packet skips
  the entries none of its fine cells needs: most of what the pieces removed. Kept for a structure
  queried very many times; the one-shot call and the bench leave it off.
- Receivers decided in the first pass (``planes``, on): each plane cell (4 x 4 fine cells) gets a plane with
  every triangle its receivers could walk on or behind it (a triangle's, picked by the cell's centroid), in
  exact arithmetic with float32 rounding bounds; a receiver whose tested segment stays in front of it is lit,
  and one whose segment crosses that triangle's slab where the triangle covers the whole cell (the cone
  test's planes at the cell's corners) is in shadow, neither binned, filled nor walked (kernels/exact.cl
  decided_by_plane). Default scene with normals: 592 k walking receivers -> 38 k; without: 1.2 M -> 565 k;
  bunny 1.10 M -> 229 k. One-shot, planes off -> on, interleaved in one process, medians of 7 (2026-12-07):
  default 1.20-1.35x faster with normals, 1.09-1.17x without; light_inside 1.03 / 1.06; city_block 1.01-1.12
  / 1.02-1.05; bunny 1.14 / 1.12, teapot 1.22 / 1.26; the same masks on all. Only where float32 places a
  receiver's cell well: not in a single perspective view, within an extent in an orthographic one
  (:meth:`ExactMethod._cell_planes`).
- Faces a light does not need (``cull``, off in a one-shot call): in a closed, embedded, consistently
  wound component every segment that meets it meets one of its faces turned towards a light outside
  it (away from one inside), so only those are listed (:mod:`shadowcl.solids`, whose certificate is
  made once per mesh). The views and grid are still fitted to every face (the listed faces come first
  in the triangle array, the rest after them, unlisted): fitted to the listed faces only, light_inside
  without normals went from 49 to 59 ms a light (views of 4 x 4 cells where receivers on culled faces
  lie); fitted to all, 43 -> 36. Its cost and saving per scene: bench/results/cull.md.

Where the time goes, per stage (``stats``: upload, views, lists, records; classify), and how fast the
public call is against Embree: bench/results (``python bench/run.py``; README's figures are generated
from those files by ``bench/figures.py``).

>>> method = ExactMethod(get_device())
>>> method.prepare(mesh, light, receiver_bounds, eps)      # lists on the device
>>> mask = method.classify(points, normals)                 # bool (N,), True = in shadow
>>> method.stats                                            # cells, entries, stage times
"""

from __future__ import annotations

import time

import numpy as np
import pyopencl as cl

from . import lightspace
from .checks import choice, flag, optional_int, positive_int
from .geometry import Mesh, bounds_diagonal
from .lights import PointLight
from .lists import check_filled
from .methods import Method, check_prepare
from .points import MovedPoints, check_points
from .solids import solids

TESTS = ("watertight", "dot5")
LISTS = ("csr", "linked")
ORDERS = ("cells", "caller")
CULL_FROM_LIGHTS = 64     # many-lights calls cull from this many lights (the certificate pays: docs/exact-speed.md)
BIN_LANES = 8             # receivers per packet in 'cells' order (kernels/vecmath.h LANES)
PLANE_SHIFT = 2           # a plane cell is 2 ** PLANE_SHIFT fine cells square (kernels/exact.cl decided_by_plane)
FAR = 5                   # the code of a point beyond the near box (kernels/exact.cl)
DOT5_FLOATS = 16          # kernels/ray_triangle.h
WT_FLOATS = 32
SPLIT_PER_COARSE_CELL = 8.0   # coarse entries per coarse cell above which large triangles are split
SPLIT_ROUNDS = 4              # rounds of two bisections at most: a piece keeps at least 1/256 of its triangle


def bisect_longest_edges(pieces: np.ndarray, owner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each (P, 3, 3) float32 triangle cut in two at the midpoint of its longest edge; ``owner`` follows.

    The midpoint of float32 corners a, b is (a + b) / 2 in float64 (exact), rounded once to float32,
    so two pieces that cut the same edge get the same bits whatever the order of its corners.
    """
    corners = pieces.astype(np.float64)
    lengths = np.linalg.norm(corners[:, [1, 2, 0]] - corners, axis=2)     # edge k runs corner k -> k + 1
    k = np.argmax(lengths, axis=1)
    rows = np.arange(len(pieces))
    a, b, c = (pieces[rows, (k + j) % 3] for j in range(3))
    mid = (0.5 * (corners[rows, k] + corners[rows, (k + 1) % 3])).astype(np.float32)
    halves = np.concatenate([np.stack([a, mid, c], axis=1), np.stack([mid, b, c], axis=1)])
    return np.ascontiguousarray(halves), np.concatenate([owner, owner])


def _sorted_unique(values: np.ndarray) -> np.ndarray:
    """np.unique by sorting (measured: NumPy 2.4's hashing np.unique is ~10x slower on 700 k int64 keys)."""
    values = np.sort(values)
    return values[np.concatenate([[True], values[1:] != values[:-1]])] if len(values) else values


def _coarse_of_fine(grid) -> np.ndarray:
    """The coarse cell of every fine cell of ``grid``, (fine cells,) int64 (kernels/lightspace.h)."""
    parts = []
    for k in range(grid.views.nviews):
        j, i = np.divmod(np.arange(grid.nx[k] * grid.ny[k], dtype=np.int64), grid.nx[k])
        parts.append(grid.base1[k] + (j // lightspace.COARSE) * grid.nx1[k] + i // lightspace.COARSE)
    return np.concatenate(parts)


def bins_from_both_ends(cl_device) -> bool:
    """Whether pass 1 of the receivers' binning (kernels/exact.cl) runs as two serial halves filling the cells
    from both ends (exact_bin_count_ends: no atomics) rather than as atomic_inc per receiver. A CPU with up
    to 4 compute units: on this 2-core machine the pass 8.6-10.4 -> 5.0-8.2 ms; with more, two work-items
    would leave cores idle (the cut at 4 is reasoned, not measured: atomics on 4 cores cost about what two
    serial halves do)."""
    return bool(cl_device.type & cl.device_type.CPU) and int(cl_device.max_compute_units) <= 4


class ExactMethod(Method):
    """Exact shadows: light-space lists built on the device, then the receivers' walks of their cells' lists.

    Parameters are those of :attr:`parameters`. After :meth:`prepare`, :attr:`stats` holds the grid
    (views, cells, ``nx`` x ``ny``), the list entries and mean length, and the time of each stage in
    seconds; :meth:`list_statistics` adds the longest list and the share of empty cells (it reads the
    lists back, so it is kept out of :meth:`prepare`'s timing). :meth:`classify` adds its own time.
    """

    name = "exact"
    point_light_reach = 2.0 ** 14   # measured (bench/range.py): list cells misbin from ~1e5 sizes
    # A start within eps of the light has tmin = eps / |light - s| >= 1, an empty interval (kernels/exact.cl
    # start_tmin), wherever it is binned: a point at the eye lands in a cell (ls_clamp_cell takes NaN to 0)
    # or, behind a single view, in brute_cell. Spares Shadows' host pass over the receivers when the light
    # is among them (1.2 M receivers: ~4 ms of a one-shot call on light_inside).
    answers_at_the_light = True
    cull_from_lights = CULL_FROM_LIGHTS
    parameters = {
        "resolution": (None, "cells on the longer side of each light view; None picks the grid from the "
                             "triangle count and expected_receivers"),
        "expected_receivers": (None, "about how many receivers classify will see, used to size the grid when "
                                     "resolution is None (None: from the triangle count only)"),
        "test": ("watertight", "ray/triangle test: 'watertight' (Woop, Benthin & Wald 2013, no leaks through "
                               "shared edges) or 'dot5' (Badouel's 5-dot-product test of the paper)"),
        "lists": ("csr", "list layout: 'csr' (count, prefix sum, fill) or 'linked' (atomic_xchg on per-cell "
                         "heads, capacity grown and the build rerun on overflow)"),
        "initial_capacity": (None, "linked lists: nodes allocated for the first build (None: 8 per triangle); "
                                   "an overflow grows the buffer to the counted size and rebuilds"),
        "chunk": (1 << 22, "receivers per classify launch (bounds device memory; at most 2 ** 29: the kernels' "
                           "slots are ints holding twice a rank)"),
        "order": ("cells", "receivers' traversal order: 'cells' (binned by light-space cell on the device, then "
                           "BIN_LANES receivers of a cell tested together against each triangle of its list) or "
                           "'caller' (one receiver per work-item as given, no binning; 1.5-2.7x slower on every "
                           "bench scene: see the module docstring)"),
        "split": (False, "csr lists: when the coarse lists are long (more than SPLIT_PER_COARSE_CELL entries "
                         "per coarse cell: walls round a light inside a room), bin the triangles listed there "
                         "by pieces small enough for the fine grid; the walk still tests the whole triangle. "
                         "Pays only when one prepared structure answers very many queries (its build costs "
                         "~50 ms more to save 2-5 % of a query on light_inside: see the module docstring)"),
        "cull": (False, "list only the faces of certified solids that every blocked segment crosses (shadowcl."
                        "solids: the faces turned towards a light outside a closed, embedded solid), about half of "
                        "them; the same answers (with test='watertight' only: dot5's leaks would show). The "
                        "certificate is made once per mesh, in NumPy (0.01-0.8 s on the "
                        "bench scenes: several one-shot calls), so it pays over many lights: shadow_counts and "
                        "shadow_matrix turn it on from CULL_FROM_LIGHTS lights unless told"),
        "planes": (True, "csr lists, watertight test: give each plane cell (4 x 4 fine cells) a plane with all "
                         "the triangles its receivers walk behind it (a triangle's: lit in front of it; in shadow "
                         "behind it when the triangle covers the cell) and answer such receivers in the binning's "
                         "first pass, "
                         "without binning or walking them (kernels/exact.cl decided_by_plane); the same "
                         "answers. Off: every receiver is walked"),
    }

    def __init__(self, device, **params):
        super().__init__(device, **params)
        p = self.params
        self.resolution = optional_int("resolution", p["resolution"], 1, lightspace.MAX_SIDE)
        self.expected_receivers = optional_int("expected_receivers", p["expected_receivers"], 0)
        self.test = choice("test", p["test"], TESTS)
        self.lists_kind = choice("lists", p["lists"], LISTS)
        self.initial_capacity = optional_int("initial_capacity", p["initial_capacity"], 1)
        self.chunk = positive_int("chunk", p["chunk"], maximum=1 << 29)
        self.order = choice("order", p["order"], ORDERS)
        self.split = flag("split", p["split"])
        self.cull = flag("cull", p["cull"])
        self.planes = flag("planes", p["planes"])
        self._builder = lightspace.ListBuilder(device, corners=3)
        # float64 points go to the device as they are when it has doubles (cheaper than converting here)
        self._fp64 = "cl_khr_fp64" in device.cl_device.extensions
        self._both_ends = bins_from_both_ends(device.cl_device)
        self._prepared = False

    @classmethod
    def checks_receivers_on(cls, device) -> bool:
        """With doubles the points' first read is on the device (the frame's move), which checks them."""
        return "cl_khr_fp64" in device.cl_device.extensions

    @classmethod
    def places_any_point(cls, light, occluder_bounds: np.ndarray) -> bool:
        """Unless the views fitted to the box are a single perspective view: a point behind it (possible
        only outside the box) is tested against every triangle. Decided in the world, prepare decides in
        its frame: the two can differ only for a light within 1e-6 of the box or of the widest view."""
        centre = 0.5 * (occluder_bounds[0] + occluder_bounds[1])
        views = lightspace.fit_views(light, occluder_bounds, centre, bounds_diagonal(occluder_bounds))
        return views.kind != "perspective"

    # prepare -------------------------------------------------------------------------------------------
    def prepare(self, mesh: Mesh, light, receiver_bounds, eps: float) -> None:
        """Build the light-space lists of ``mesh`` seen from ``light`` for receivers in ``receiver_bounds``.

        ``receiver_bounds`` is a (2, 3) world box; ``eps`` the absolute offset of DESIGN.md.
        """
        light, box = check_prepare(mesh, light, receiver_bounds, eps)
        dev = self.device
        t0 = time.perf_counter()
        # Local frame: the centre of the occluders, in float64. Not of the receivers too: one receiver far
        # away would move the frame and cost the occluders their float32 precision.
        union = np.stack([np.minimum(mesh.bounds[0], box[0]), np.maximum(mesh.bounds[1], box[1])])
        origin = 0.5 * (mesh.bounds[0] + mesh.bounds[1])
        scale = bounds_diagonal(union)
        vertices = (mesh.vertices.astype(np.float64) - origin).astype(np.float32)
        faces, ntris = self._faces_to_list(mesh, light, box)  # the views see every face, the lists ntris
        views = lightspace.fit_views(light, box, origin, scale)
        # One program for every kernel of this method (its options are known once the views' kind is)
        options = views.options + (
            f"-DLIGHT_POINT={int(isinstance(light, PointLight))}",
            f"-DTEST_DOT5={int(self.test == 'dot5')}",
            f"-DLISTS_LINKED={int(self.lists_kind == 'linked')}",
            f"-DINPUT_F64={int(self._fp64)}",
            f"-DWT_REFINE_F64={int(self._fp64)}",
            f"-DLANES={BIN_LANES if self.order == 'cells' else 1}",
            f"-DPLANE_SHIFT={PLANE_SHIFT}",
        )
        if isinstance(light, PointLight):
            light_vec = (light.position - origin).astype(np.float32)
        else:
            light_vec = np.asarray(light.direction, dtype=np.float32)
        # (F, 3, 3) float32 triangles gathered on the device, and in the same launch the test's records
        tris_dev = dev.empty(36 * len(faces), "triangles")
        floats, kind = (DOT5_FLOATS, "dot5") if self.test == "dot5" else (WT_FLOATS, "watertight")
        records = dev.empty(4 * floats * len(faces), f"{kind} triangle records")
        dev.kernel("exact.cl", "triangle_records", options)(
            dev.queue, (len(faces),), None, dev.to_device(vertices), dev.to_device(faces), np.int32(len(faces)),
            *(np.float32(c) for c in light_vec), tris_dev, records)
        t1 = time.perf_counter()
        # Views and grid, fitted to every face: receivers lie on the culled ones too (measured on light_inside
        # without normals, fitted to the listed faces only: 49 -> 59 ms a light, some views 4 x 4 cells)
        cells = lightspace.pick_cell_count(len(faces), self.expected_receivers)
        views = lightspace.fit_to_footprint(dev, views, tris_dev, len(faces),
                                            cells=cells if self.resolution is None else None)
        grid = lightspace.make_grid(views, cells=cells, resolution=self.resolution)
        t2 = time.perf_counter()
        lists = self._builder.build(grid, tris_dev, ntris, self.lists_kind, self.initial_capacity,
                                    fine_masks=self.lists_kind == "csr")
        split = dict(split_triangles=0, split_pieces=0, split_rounds=0)
        if self.split and self.lists_kind == "csr" and \
                lists.coarse_entries > SPLIT_PER_COARSE_CELL * (grid.cells - grid.fine_cells):
            lists, split = self._split_lists(grid, lists, vertices, faces[:ntris])
        planes = self._cell_planes(grid, lists, records, light_vec, eps, options)
        dev.queue.finish()
        t3 = time.perf_counter()

        self.mesh, self.light, self.eps, self.origin = mesh, light, float(eps), origin
        self.grid, self.lists, self._tris_dev, self._records = grid, lists, tris_dev, records
        self._light_vec = light_vec
        self._planes = planes
        self._ntris = ntris
        self._program = options
        self._prepared = True
        self.stats = dict(lists.stats)
        device_bytes = sum(b.size for b in (tris_dev, records, *lists.buffers(), lists.fine_masks, lists.params)
                           if b is not None)
        self.stats.update(
            triangles=len(mesh.faces), listed_triangles=ntris, lists=self.lists_kind, test=self.test,
            device_bytes=int(device_bytes), **split,
            # entries per fine cell; linked lists do not know their coarse share, so it is counted in there
            mean_list=(lists.entries - max(lists.coarse_entries, 0)) / grid.fine_cells,
            upload_s=t1 - t0, views_s=t2 - t1, lists_s=t3 - t2, prepare_s=t3 - t0,
        )

    def _cell_planes(self, grid, lists, records: cl.Buffer, light_vec: np.ndarray, eps: float,
                     options) -> tuple[cl.Buffer, float] | None:
        """The plane cells' planes for the first pass's decided receivers (kernels/exact.cl exact_cell_planes) and
        the extent (local coordinates) within which a receiver may be decided by them, or None when off: with
        linked lists (no list per cell to read as a range), with dot5 (the paper's test, whose leaks and false
        hits through shared edges are its own answers to compare) and in a single perspective view (its rows
        carry the far eye in their constants, so a cell is found only to ~1e-7 of |eye| (red team, 2026-12-07:
        a local origin 1e6 away put receivers a cell off)).

        The extent: a cube face finds a point's cell from p - light, correct to a few ulps of itself wherever p
        is; an orthographic view from Mx p + cx, off by up to 2^-22 (|Mx|_1 |p|_inf + |cx|) cells, which stays
        below 1/64 of a cell (the lists' own allowance) for |p|_inf up to the extent. A ray to a directional
        light is decided in shadow only when it meets the covering triangle within the extent too."""
        if not (self.planes and self.lists_kind == "csr" and self.test == "watertight"):
            return None
        views = grid.views
        if views.kind == "perspective":
            return None
        extent = np.inf
        if not views.perspective:
            rows = np.abs(grid.params[:, [4, 5, 6, 8, 9, 10]]).reshape(-1, 2, 3).sum(axis=2).max()
            consts = np.abs(grid.params[:, [7, 11]]).max()
            extent = max(0.0, (2.0 ** 16 - float(consts)) / max(float(rows), 1e-30))
        ncoarse = grid.cells - grid.fine_cells
        nplanes = ncoarse * (lightspace.COARSE >> PLANE_SHIFT) ** 2
        planes = self.device.empty(32 * nplanes, "exact: the plane cells' planes")
        offsets, items = lists.buffers()
        self.device.kernel("exact.cl", "exact_cell_planes", options)(
            self.device.queue, (nplanes,), None, lists.params, offsets, items, lists.fine_masks, records,
            *(np.float32(c) for c in light_vec), np.float32(eps), np.float32(extent), np.int32(grid.fine_cells),
            np.int32(ncoarse), planes)
        return planes, extent

    def _faces_to_list(self, mesh: Mesh, light, receiver_bounds) -> tuple[np.ndarray, int]:
        """``mesh.faces`` reordered so that those to list for ``light`` come first, and how many they are:
        every face, or with ``cull``, those the light needs of the certified solids for receivers in
        ``receiver_bounds`` (:meth:`shadowcl.solids.Solids.faces_for`) and every other face."""
        # dot5 leaks through shared edges (module doc), and an entry face it would have hit is not listed
        cull = self.cull and self.test == "watertight"
        listed = solids(mesh).faces_for(light, receiver_bounds) if cull else None
        if listed is None:
            return mesh.faces, len(mesh.faces)
        culled = np.ones(len(mesh.faces), dtype=bool)
        culled[listed] = False
        return mesh.faces[np.concatenate([listed, np.flatnonzero(culled)])], len(listed)

    def resolved_params(self) -> dict:
        """The parameters, with the grid resolution picked (cells on the longer side of the largest view)."""
        params = dict(self.params)
        if self._prepared and params["resolution"] is None:
            params["resolution"] = int(max(self.grid.nx.max(), self.grid.ny.max()))
        return params

    def _split_lists(self, grid, lists, vertices: np.ndarray, faces: np.ndarray):
        """CSR lists binned by pieces of the triangles in ``lists``' coarse cells, entries naming triangles.

        A triangle whose projection covers more fine cells than a coarse cell holds goes to the coarse grid, whose
        cells are few and large: with walls and long pillars round a light inside a room, every
        receiver walks dozens of them. Each such triangle is cut in four (two bisections at the longest
        edge), the pieces binned on their own, and those still coarse cut again (SPLIT_ROUNDS at most;
        the builder decides, so no projection is repeated here). The lists are then built over the
        other triangles and the final pieces, and each entry rewritten to its piece's triangle.

        Same answers: the walk tests the original corners (its record), so an answer could only change
        if a cell the triangle's projection touches were missing from every piece's cells. Pieces
        sharing an edge share its corners' bits; a new corner is off the original triangle by at most
        half a float32 ulp of its coordinates, the order of the rounding the builder already makes on
        every corner (d = v - light), far inside its allowance (DELTA = 1/64 cell plus LS_REL_TOL,
        ~170 ulps of the magnitudes involved). A missing cell would also be a leak, which the tests
        look for (rays aimed through shared edges of split triangles).

        Shorter walks, never longer: entries are made unique per cell (neighbouring pieces share
        cells: ~30% repeats on light_inside), and a fine entry is dropped when the fine cell's coarse
        cell lists the same triangle (a triangle with pieces left coarse after the last round), so a
        receiver meets each triangle at most once, and only if it met it before the split. Done on the
        host, only when splitting; only the pieces' entries are sorted. Returns the lists and split
        statistics.
        """
        dev = self.device
        large = _sorted_unique(self._coarse_items(lists))
        triangles = vertices[faces]                                   # (F, 3, 3) float32, as triangle_records
        pieces, owner = triangles[large], large.astype(np.int32)
        done_pieces, done_owner, rounds = [], [], 0
        while len(pieces) and rounds < SPLIT_ROUNDS:
            # two bisections a round: half the builds of one, for a few more pieces
            pieces, owner = bisect_longest_edges(*bisect_longest_edges(pieces, owner))
            rounds += 1
            trial = self._builder.build(grid, dev.to_device(pieces), len(pieces))
            fine = np.ones(len(pieces), dtype=bool)
            fine[self._coarse_items(trial)] = False
            done_pieces.append(pieces[fine])
            done_owner.append(owner[fine])
            pieces, owner = pieces[~fine], owner[~fine]
        whole = np.ones(len(faces), dtype=bool)
        whole[large] = False
        prims = np.ascontiguousarray(np.concatenate([triangles[whole], *done_pieces, pieces]))
        owners = np.concatenate([np.flatnonzero(whole).astype(np.int32), *done_owner, owner])
        built = self._builder.build(grid, dev.to_device(prims), len(prims))
        # Entries of pieces name their triangle, once per cell (sorted (cell, triangle) keys, repeats
        # dropped) and once per walk (a fine entry goes when its coarse cell lists the triangle too).
        # Entries of whole triangles are unique already (one level, once per cell): they keep their
        # slots' order, and each cell gets them first, then its pieces' triangles: no sort of them.
        offsets, items = built.to_host(dev)
        ntris, nwhole = len(faces), int(whole.sum())
        cell = np.repeat(np.arange(grid.cells, dtype=np.int64), np.diff(offsets))
        piece = items >= nwhole
        keys = _sorted_unique(cell[piece] * ntris + owners[items[piece]])
        fine = keys < grid.fine_cells * ntris
        above = _coarse_of_fine(grid)[keys[fine] // ntris] * ntris + keys[fine] % ntris
        listed = keys[~fine]                                          # sorted, few: look up by bisection
        at = np.minimum(np.searchsorted(listed, above), max(len(listed) - 1, 0))
        repeat = listed[at] == above if len(listed) else np.zeros(len(above), dtype=bool)
        keys = np.concatenate([keys[fine][~repeat], listed])
        parts = [(cell[~piece], owners[items[~piece]]), (keys // ntris, (keys % ntris).astype(np.int32))]
        counts = [np.bincount(c, minlength=grid.cells) for c, _ in parts]
        offsets = np.concatenate([[0], np.cumsum(counts[0] + counts[1])])
        items = np.empty(int(offsets[-1]), np.int32)
        slot = offsets[:-1].copy()                                    # next free slot of each cell
        for (c, t), n in zip(parts, counts):                          # c is sorted: rank within its cell
            items[slot[c] + np.arange(len(c)) - (np.cumsum(n) - n)[c]] = t
            slot += n
        offsets = offsets.astype(np.int32)
        coarse_entries = int(offsets[-1] - offsets[grid.fine_cells])
        split_lists = lightspace.Lists("csr", grid, ntris, len(items), offsets=dev.to_device(offsets),
                                       items=dev.to_device(items if len(items) else np.zeros(1, np.int32)),
                                       capacity=len(items), coarse_entries=coarse_entries, params=built.params,
                                       stats=dict(built.stats, entries=len(items), coarse_entries=coarse_entries,
                                                  split_entries=built.entries))
        return split_lists, dict(split_triangles=len(large), split_pieces=len(prims) - nwhole,
                                 split_rounds=rounds)

    def _coarse_items(self, lists) -> np.ndarray:
        """The entries of the coarse cells of CSR ``lists`` (primitive indices), read back."""
        items = np.empty(lists.coarse_entries, np.int32)
        if len(items):
            cl.enqueue_copy(self.device.queue, items, lists.items, src_offset=4 * (lists.entries - len(items)))
        return items

    # classify ------------------------------------------------------------------------------------------
    def classify(self, points, normals=None) -> np.ndarray:
        """Bool (N,) mask of ``points`` ((N, 3) world positions; optional ``normals``), True = in shadow.

        Normals need not be unit length: they are checked and normalised on the device in double when it
        has doubles (a bad row is then reported by the host check, :meth:`Points.checked_normals`, with
        its message), else on the host. Any point works, inside the prepared receiver bounds or not: outside
        the window it is looked up in the border cells, which extend to the view's domain; a point behind
        a single perspective view (only possible outside the prepared bounds) is tested against every
        triangle instead. Receivers are checked by :func:`shadowcl.points.check_points`.
        """
        return self._classify(check_points(points, normals), None)[0]

    def classify_near(self, points, near_box: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`shadowcl.methods.Method.classify_near`: the points' values are read first on the device,
        which codes a point beyond ``near_box`` FAR (5: not walked) and a non-finite one 3 (kernels/exact.cl
        receiver_point); only then does the host read them, to raise its check's error."""
        if not self.checks_receivers:
            raise RuntimeError("classify_near: this device has no doubles, the points are moved on the host")
        return self._classify(check_points(points, box=False), np.asarray(near_box, dtype=np.float64))

    def _classify(self, receivers, near_box: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The mask and the indices of the points coded FAR (beyond ``near_box``; None: none is)."""
        if not self._prepared:
            raise RuntimeError("classify: call prepare(mesh, light, receiver_bounds, eps) first")
        t0 = time.perf_counter()
        if self._fp64 and isinstance(receivers, MovedPoints):
            # the frame's move fused into the first pass (kernels/exact.cl receiver_point): no host pass
            points, move = receivers.world.positions, (*receivers.centre, 1.0 / receivers.scale)
        else:
            points, move = receivers.positions, (0.0, 0.0, 0.0, 1.0)
        normals = receivers.normals if self._fp64 else receivers.unit_normals()
        # the near box in the kernel's coordinates (the move's, relative to the origin): monotonic, so a
        # point is beyond it there exactly when it is beyond near_box
        near = np.array([[-np.inf] * 3, [np.inf] * 3]) if near_box is None else near_box - self.origin
        n = len(points)
        out = np.empty(n, dtype=np.uint8)
        brute = walked = 0
        for lo in range(0, n, self.chunk):
            hi = min(n, lo + self.chunk)
            out[lo:hi], behind, binned = self._run(points[lo:hi], None if normals is None else normals[lo:hi], move,
                                                   near)
            brute += behind
            walked += binned
        far = np.zeros(0, dtype=np.int64)
        if n and out.max() > 1:     # one pass over the codes; the search only when one is bad
            bad = np.flatnonzero((out == 3) | (out == 4))
            if len(bad):
                receivers.bounds                     # the host check of the values: raises its own error
                overflow = bad[out[bad] == 3]        # finite, but beyond float32 once moved into the local frame
                if len(overflow):
                    raise ValueError(f"points: overflow float32 relative to the occluders (first at index {int(overflow[0])})")
                receivers.checked_normals()          # raises the check's own error for the bad row (code 4)
                raise RuntimeError("exact: the device refused normals the host check accepts (a bug)")
            far = np.flatnonzero(out == FAR)
            out[far] = 0
        self.stats.update(classify_s=time.perf_counter() - t0, receivers=n, brute_fallback=brute, walked=walked)
        return out.view(bool), far

    def _run(self, points: np.ndarray, normals: np.ndarray | None, move: tuple,
             near: np.ndarray) -> tuple[np.ndarray, int, int]:
        """Codes (0 lit, 1 shadow, 3 bad point, 4 bad normal, FAR beyond ``near``) of one chunk, how many of
        its points were tested against every triangle (behind a single perspective view), and how many
        were walked (the rest answered in the first pass: facing away, lit by their cell's plane, or bad).
        ``move``: (cx, cy, cz, 1 / scale) of the frame the points are still to be moved into (float64
        input only); ``near``: (2, 3) box relative to the origin."""
        dev, queue = self.device, self.device.queue
        n = len(points)
        if n == 0:
            return np.empty(0, np.uint8), 0, 0
        if self._fp64:
            # float64 in; the kernel moves the points, subtracts the origin in double and rounds, as the
            # host would
            origin = [np.float64(c) for c in (*move, *self.origin, *near.ravel())]
            points_dev = dev.input_view(points)
            normals_dev = dev.input_view(normals) if normals is not None else points_dev
        else:
            origin = [np.float32(c) for c in (0, 0, 0, 1, 0, 0, 0, *near.ravel())]
            points_dev = dev.input_view(np.subtract(points, self.origin).astype(np.float32))
            normals_dev = points_dev if normals is None else dev.input_view(normals.astype(np.float32))
        binned = self.order == "cells"
        options = self._program
        brute_cell = self.grid.cells                   # one cell more: the points no view places
        light = [np.float32(c) for c in self._light_vec]
        bin_args = (points_dev, normals_dev, np.int32(n), *origin, self.lists.params, np.int32(brute_cell),
                    *light, np.float32(self.eps), np.int32(normals is not None))
        # the first pass's decided receivers (None: every receiver walks; the buffer then is never read)
        planes = (self._planes[0], np.int32(self.grid.fine_cells), np.float32(self._planes[1])) \
            if self._planes is not None else (self.lists.params, np.int32(-1), np.float32(0))
        walk_coarse = np.int32(self.lists.coarse_entries != 0)
        lists_a, lists_b = self.lists.buffers()
        out_dev = dev.scratch("exact: classify output", n)
        if not binned:
            behind = dev.scratch("exact: points behind the view", 4)
            cl.enqueue_fill_buffer(queue, behind, np.int32(0), 0, 4)
            dev.kernel("exact.cl", "exact_classify_points", options)(
                queue, (n,), None, *bin_args, self._records, np.int32(self._ntris), lists_a, lists_b,
                self.lists.fine_masks, walk_coarse, behind, out_dev)
            return dev.from_device(out_dev, n, np.uint8), int(dev.from_device(behind, 1, np.int32)[0]), n
        rows = 2 if self._both_ends else 1
        row = brute_cell + 2 + BIN_LANES    # a row of counts: every cell, the non-walkers by lane, the walkers
        counts = dev.scratch("exact: receiver cell counts", 4 * row * rows)
        cl.enqueue_fill_buffer(queue, counts, np.int32(0), 0, 4 * row * rows)
        start = dev.scratch("exact: receiver starts", 16 * n)          # kernels/exact.cl Start
        packets = -(-n // BIN_LANES)
        per_end = np.int32(-(-packets // 2))
        if self._both_ends:
            cell_of = dev.scratch("exact: walkers' cells", 4 * n)
            dev.kernel("exact.cl", "exact_bin_count_ends", options)(
                queue, (2,), (1,), *bin_args, *planes, per_end, counts, out_dev, start, cell_of)
        else:
            slot = dev.scratch("exact: receiver slots", 4 * n)
            dev.kernel("exact.cl", "exact_bin_count", options)(queue, (packets,), None, *bin_args, *planes, counts, slot,
                                                               out_dev, start)
        offsets = dev.scratch("exact: receiver cell offsets", 4 * (brute_cell + 2))
        # The host waits for the total and for the fill's check: a kernel enqueued behind running ones ran
        # slower on PoCL (the fill 5.7 -> 10.8 ms, the walk 7.1 -> 11-15, default scene), not faster.
        second_row = row if self._both_ends else 0
        binned_count = self._builder.prefix_sum(self.grid, counts, brute_cell + 1, offsets, second_row)
        if binned_count:
            by_cell = dev.scratch("exact: receiver starts by cell", 16 * binned_count)   # tagged with their index
            dropped = dev.scratch("exact: dropped receivers", 4)
            cl.enqueue_fill_buffer(queue, dropped, np.int32(0), 0, 4)
            if self._both_ends:
                dev.kernel("exact.cl", "exact_bin_fill_ends", options)(
                    queue, (2,), (1,), per_end, start, cell_of, counts, np.int32(row), offsets, by_cell, dropped)
            else:
                dev.kernel("exact.cl", "exact_bin_fill", options)(queue, (n,), None, np.int32(n), start, slot, counts,
                                                                  offsets, by_cell, dropped)
            check_filled(dev, dropped, "exact: the receivers' binning")
            dev.kernel("exact.cl", "exact_classify", options)(
                queue, (-(-binned_count // BIN_LANES),), None, by_cell, np.int32(binned_count),
                self.lists.params, self._records, np.int32(self._ntris), np.int32(brute_cell), lists_a, lists_b,
                self.lists.fine_masks, *light, np.float32(self.eps), walk_coarse, np.int32(n), out_dev)
        brute = np.empty(2, np.int32)                    # the brute cell's bounds
        cl.enqueue_copy(queue, brute, offsets, src_offset=4 * brute_cell)
        return dev.from_device(out_dev, n, np.uint8), int(brute[1] - brute[0]), binned_count

    # statistics ----------------------------------------------------------------------------------------
    def _list_lengths(self) -> np.ndarray:
        """Entries of every cell's list, (cells,) int64 (reads the lists back)."""
        offsets, _ = self.lists.to_host(self.device) if self.lists_kind == "linked" else (
            self.device.from_device(self.lists.offsets, self.grid.cells + 1, np.int32), None)
        return np.diff(offsets.astype(np.int64))

    def walk_lengths(self, points) -> np.ndarray:
        """Entries each point's walk can visit: its fine plus its coarse cell's list, (N,) int64.

        The bound on the triangle tests classify runs for a receiver at ``points`` ((N, 3) world; the
        cells of the points themselves, not moved along a normal). Reads the lists back: for tests
        and profiles, not for speed.
        """
        if not self._prepared:
            raise RuntimeError("walk_lengths: call prepare(mesh, light, receiver_bounds, eps) first")
        rel = check_points(points).positions - self.origin
        fine, coarse, _ = lightspace.point_cells(self.device, self.grid, rel)
        lengths = self._list_lengths()
        return lengths[fine] + (lengths[coarse] if self.lists.coarse_entries != 0 else 0)

    def list_statistics(self) -> dict:
        """Longest list, empty-cell share, mean over non-empty cells (reads the lists back)."""
        lengths = self._list_lengths()
        nonempty = lengths[lengths > 0]
        extra = dict(max_list=int(lengths.max(initial=0)), empty_cells=float(np.mean(lengths == 0)),
                     mean_list_nonempty=float(nonempty.mean()) if len(nonempty) else 0.0)
        self.stats.update(extra)
        return extra
