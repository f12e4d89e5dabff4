"""The angular method: discretized shadow volumes in angular coordinates (Thakur, Cheng & Miura).

Pipeline (kernels/angular.cl):

1. **Ridge-edge loops** (section 2): :func:`ridge_loops` chains the ridge edges of
   :mod:`shadowcl.silhouette` (edges with exactly one light-facing face) into closed loops and checks
   the paper's even-count property at every vertex. Open meshes close their loops through their border
   edges (the silhouette module counts the missing face as hidden); non-manifold meshes are refused.
2. **Frame** (:func:`angular_frame`): the light at the origin; a row is a half-plane through the X axis
   at ``theta = atan2(Y, -Z)`` (the paper's eq. 2 extended to the whole circle, so a light inside the
   scene needs no hemisphere split: rows wrap round at +-pi); inside a row a direction is keyed by
   ``s = X / r = sin(psi)``, monotone in the paper's ``phi = atan(X / -Z)``. The poles are +-X: the frame
   keeps them away from the occluder directions (for ``render``, on the camera's right axis when that
   clears them by :data:`POLE_CLEARANCE`, so that a scan line stays in one row). A directional light
   uses parallel rows (planes Y = const, s = X).
3. **Table** (sections 3-5, 7.1), built on the device: per table face, its plane and the rows whose
   band ``[t0 + k dt, t0 + (k + 1) dt]`` its row-coordinate range meets, widened by :data:`ANGLE_PAD`
   (first row, count); the records per row and their exclusive prefix sum on the host (a
   difference array over the faces' row intervals: per-row atomic counters on the device contended on a
   few hundred addresses, 0.45 s for 600 k faces); a fill pass writing one record per (face, row, piece) at its
   row's offset plus an atomic cursor, then a sort of each row by ``s_lo`` (kernels/lists.h)
   (the paper's pairwise sort). A record is the face's span ``[s_lo, s_hi]`` over the row's whole band
   (the face clipped to the band's wedge -- slab for a directional light --, s extreme at a corner or where
   an edge's great circle comes nearest the pole; widened by :data:`S_PAD`; a wide one cut into pieces of
   at most 1 / :data:`PIECES` of the s range, as a span across the row -- a ground under the occluders --
   kept the lookups' backward scan from stopping early: 100 000 cubes on a ground, 600 rows, 500 000
   receivers: 2.70 -> 0.59 s, the loop table 0.27 s) -- the paper's pair of
   crossings: a ridge-edge crossing where the face touches a loop, a visible-edge crossing otherwise, so
   visible edges enter "in duplicate" (section 5) -- plus the face plane for depth. Pairs therefore come
   from one face each: loops never need the local-peak pairing of section 4 to pair correctly, however
   they coil (the reference builds the paper's loop-only table with that pairing and the tests check both
   agree). A lookup tests the face itself: the plane (exact depth instead of r interpolated between the
   pair's ends), then the triangle's three edge functions (watertight: a shared edge's function is
   computed from its lower vertex index, the same bits for both faces). Since every direction the face
   covers in the band lies in its span, no face is missed, and since the hit must lie in the triangle, no
   plane counts past its face's edges: the table has no discretization error (see below).
   Table faces: the light-facing faces of each closed manifold component (a blocked ray always crosses
   one); every face of an open or non-manifold component (a ray can be stopped by a hidden face there).
3b. **The paper's table** (``table="loops"``, :func:`loop_pairs`): for the closed components, each ridge
   edge's crossings with the rows it spans are counted, prefix-summed and filled on the device like the
   face records (``edge_rows``, ``fill_edges``: s, the crossing point -- its r --, the way the loop goes in
   theta); one work-item per row (``pair_rows``) sorts its crossings and pairs them by section 4's rule
   (in s order a crossing going the way the group's first one goes waits, one going the other way closes
   the oldest waiting: the chains leaving a local theta peak bound one span, so coils pair correctly).
   The sort and pairing (``stats["pair_s"]``) took 6 ms / 49 ms for 57 k / 288 k crossings (10 000 /
   100 000 cubes, 600 rows, 4 % of the prepare): on the device it pays, as the FIFO is a sequential scan
   per row that NumPy cannot vectorise (a host version would be a Python loop over the crossings after
   a read-back; not written, so that side is an estimate). What costs is host-side: chaining the loops
   (silhouette_loops) and labelling regions and creases. Groups are *lit regions* (faces facing
   the light joined across edges whose faces both face it) rather than single loops: a region's outer loop
   and its holes' loops pair together, so a torus lit from above keeps its hole lit (loop by loop, the
   outer loop's pair spans the hole and shadowed it: 1006 of 2276 ground points under it). Depth
   (section 5): a pair's record holds the plane of its chord, the segment between its two crossing points,
   i.e. r interpolated between the pair's ends; off the row's centre plane the chord plane follows the mean
   of the two edges' directions (along the row plane's normal, receivers on the occluder's own lit cap fell
   behind it: half of a slab's top). A chord cuts off a valley of the lit cap, so the region's concave
   creases (edges between two lit faces folding inwards) enter "in duplicate" and cut the pairs they fall
   in (A h1, h1 h2, ..., hn B) -- the paper's "visible edges in duplicate", only where the depth needs
   them (convex creases lie in front of the chord). Hidden edges in duplicate (the paper's main form) were
   not used: the far surface's chords would need the hidden faces' own chaining, which is what a face
   record already is. A point light's rows end on the pole axis; a lit face it pierces adds a crossing
   at s = +-1 in every row (without it the pillars round the pole in the light-inside scene lost their
   shadows: 225 wrong pixels against 12). Open and non-manifold components keep face records in the same
   rows (their hidden faces can stop rays, and their loops need not close).
   Default ``table="faces"``: exact but for float32 ties, where the loop table keeps its half-row band
   (bench/results/angular_revisions.md: 0 of 500 000 receivers wrong on bunny, ogre and teapot at the
   default rows, 0.094 / 0.105 / 0.037 % before; angular_caps.md: no false shadow or light on any
   occluder or ground set). The row-centre spans it replaced (a face listed in the rows whose centre it
   spans, cut there, its plane tested without its edges: the paper's discretization) falsely shadowed
   15-22 % of the receivers lying on a sphere's, torus's or cylinder's lit cap under a directional light (a
   receiver up to half a row off the centre met a neighbouring face's plane extended past its edge);
   testing the triangle against those spans removed the caps' errors but missed the faces a row's centre
   does not cut (46-101 false lights per 1,500 ground receivers). Band spans list each face in about one
   more row than row-centre spans did (which left most small faces in no row at all), and wide ones in
   pieces: at the default rows 193 k -> 311 k records on the bunny, 133 k -> 263 k on the ogre, 65 k ->
   108 k on the teapot; the lookups test more candidates, and a plane hit also its edges (9-32 % of the
   lookup time, against a plane-only build): ``Shadows.mask`` took 1.23 / 1.37 / 1.13 x its old time on
   500 000 receivers, ``sc.prepare`` 1.35 / 1.35 / 1.39 x (medians of the interleaved rounds' ratios,
   load ~8.5 on 2 shared cores). The loop table keeps the paper's error and is slower to build (its loops are
   chained on the host).
4. **Lookups**: per receiver, its row and ``s``; a binary search finds the records starting at or
   before ``s``, a backward scan tests them (first hit wins) and stops where the row's running maximum
   of ``s_hi`` falls below ``s`` (section 7 step 2, without walking the whole entry). ``classify_view``
   walks each scan line (in pieces of :data:`RUN_PIECE` pixels, for parallelism) keeping the state and
   the interval of ``s`` it holds over (the paper's ``nextX``), so one lookup serves a run of pixels. The
   run is re-validated per pixel by its row and ``s`` (known from the Z-buffer's receivers) instead of
   eq. 7's maximum run length; that makes it exact: runs give the per-pixel answer bit for bit. For the
   rows to follow the scan lines, ``classify_view`` puts the pole on the camera's right axis (the
   paper's frame, XY parallel to the screen) and picks the rows from the image (:meth:`view_rows`).
5. **Several lights** (section 11.1): one table per light, ``sc.shadow_counts(..., method="angular")``. **Light inside the
   scene** (section 11.2): the rows are half-planes round the pole axis, so the whole sphere but the
   pole is covered by one table whose rows wrap round at +-pi; no hemisphere split is needed, and rows
   are uniform in theta (the paper's finer rows near +-pi/2 compensate its tan-based coordinates, which
   these rows do not use).

A point light inside a closed solid (winding number of a closed component round it >= 1/2) raises
``ValueError``: every point outside that solid is in its shadow, and no face of it turns to the light.

Error: with ``table="faces"`` a receiver differs from the exact method only by float32 rounding (a ray
within ~1e-6 of a face's size from its edge, or a hit within rounding of eps): rows and spans are widened
past the receivers' float32 row coordinate and s (:data:`ANGLE_PAD`, :data:`S_PAD`, :data:`LENGTH_PAD`),
so a receiver on a row boundary meets the same faces in either row. With ``table="loops"`` the pairs are
cut at the row's centre: a receiver can differ when its ray passes within half a row (in theta; in Y for
a directional light) of a loop edge, near shadow boundaries and terminators.

>>> method = AngularMethod(get_device(), theta_resolution=600)
>>> method.prepare(mesh, light, receiver_bounds, eps)
>>> mask = method.classify(points, normals)
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .checks import choice, flag, optional_int, positive_int, vector3
from .geometry import Mesh
from .lights import PointLight
from .methods import Method, check_prepare
from .points import check_points
from .lightspace import box_corners, orthonormal_basis
from .lists import check_filled
from .silhouette import edge_adjacency, silhouette_edges, silhouette_loops
from .topology import components, concave_edges

REC_FLOATS = 8                 # kernels/angular.cl: REC
MIN_ROWS, MAX_ROWS = 16, 1 << 16
DEFAULT_ROWS = 600             # the paper's highest resolution, when nothing says how dense receivers are
POLE_CLEARANCE = np.radians(5.0)   # a preferred pole axis is kept when this far from every occluder direction (a face
                                   # round the pole only spans every row; receivers near it stay exact)
FULL_CIRCLE_SPAN = np.radians(170.0)  # occluders spanning more theta than this get the whole circle
ROWS_PER_LINE = 2              # render's default rows per scan line (view_rows): on the hard scenes at 160 x 90 the
                               # sphere terminator's wrong pixels went 385 / 183 / 67 at 1 / 2 / 4 per line
TABLES = ("faces", "loops")
RUN_PIECE = 64                 # classify_lines: receivers per work-item at most (a run never crosses a piece)
SAMPLE = 20000                 # occluder vertices sampled for the frame choice
ANGLE_PAD = 1e-5               # a face is listed in the rows its theta range meets widened by this times the
                               # occluders' theta size (at most 1 radian) and r / rho (a corner's distance from the light
                               # over that from the pole axis): a receiver's float32 theta rounds by ~1e-7 of its size
                               # times r / rho (atan2 a few ulp): 10-100 x margin
S_PAD = 1e-5                   # spans widened by this times the occluders' s size (point light: a receiver's float32
                               # s = x / |p| is ~1e-7 of it off)
LENGTH_PAD = 1e-5              # directional light: rows and spans (lengths) widened by this times the occluders'
                               # extent from the frame's origin (float32 coordinates round by ~6e-8 of it)
PIECES = 16                    # a face's span is cut in pieces of at most 1 / PIECES of the s range (point: 2;
                               # directional: twice the occluders' extent), so a ground's row-wide span cannot
                               # keep lookups from ending early (kernels/angular.cl face_rows); not more: a
                               # scan-line run ends at every piece's end (64: the runs' lookups went up 30 %)


def ridge_loops(device, mesh: Mesh, light):
    """The ridge-edge (RE) loops of ``mesh`` against ``light``: a list of :class:`~shadowcl.silhouette.Loop`.

    Section 2: every vertex meets an even number of ridge edges, so they chain into closed loops
    (several per object, nested or coiled). Checked here: the RE count at every vertex is even (the
    paper's property) and as many leave as arrive (the oriented form :func:`silhouette_loops` needs).
    Open meshes close their loops through their border edges; non-manifold or inconsistently wound
    meshes raise ``ValueError``.
    """
    sil = silhouette_edges(device, mesh, light)
    check_even_count(sil)
    try:
        return silhouette_loops(sil)
    except ValueError as error:
        raise ValueError(f"mesh: ridge-edge loops need a manifold, consistently wound mesh ({error})") from None


def ridge_degree(sil) -> np.ndarray:
    """(V,) number of ridge edges at each vertex."""
    nv = len(sil.adjacency.vertices)
    ends = sil.adjacency.edges[sil.indices].ravel()
    return np.bincount(ends, minlength=nv)


def check_even_count(sil) -> None:
    """Raise ``ValueError`` unless every vertex meets an even number of ridge edges (section 2's proof;
    :func:`silhouette_loops` then checks the oriented form, as many arriving as leaving)."""
    odd = np.flatnonzero(ridge_degree(sil) % 2)
    if len(odd):
        raise ValueError(f"mesh: {len(odd)} vertices meet an odd number of ridge edges, first {odd[:5].tolist()}; "
                         "the ridge-edge loops cannot close (non-manifold edges are left unclassified)")


# Frame -----------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Frame:
    """World -> angular frame: ``local = rotation @ (world - origin)``; the light at the origin for a
    point light; rows over ``[t0, t0 + rows * dt)``; ``full_circle`` rows wrap round. ``centre`` (world)
    is the occluders' box centre: the kernels hold receivers and face planes relative to it
    (:attr:`anchor`), so that a distant point light costs the depth test no precision. ``pad_t`` and
    ``pad_s`` widen a face's row range and spans against float32 rounding (:data:`ANGLE_PAD` and
    :data:`S_PAD` times the occluders' angular size for a point light; :data:`LENGTH_PAD` times their
    extent for a directional light);
    ``piece_width`` is the widest span piece (:data:`PIECES`)."""

    origin: np.ndarray
    rotation: np.ndarray
    point: bool
    t0: float
    dt: float
    rows: int
    full_circle: bool
    centre: np.ndarray
    pad_t: float
    pad_s: float
    piece_width: float

    @property
    def anchor(self) -> np.ndarray:
        """(3,) frame coordinates of :attr:`centre`, rounded to float32: the kernels get it as floats, and
        host and kernels must subtract the very same point."""
        return self.to_local(self.centre[None])[0].astype(np.float32).astype(np.float64)

    def to_local(self, world: np.ndarray) -> np.ndarray:
        """(N, 3) float64 frame coordinates of world positions."""
        return (np.asarray(world, dtype=np.float64) - self.origin) @ self.rotation.T

    @property
    def row_centres(self) -> np.ndarray:
        """(rows,) row coordinate of each row's centre: the plane the loops table's spans are cut with."""
        return self.t0 + (np.arange(self.rows) + 0.5) * self.dt


def _pole_clearance(axis: np.ndarray, directions: np.ndarray) -> float:
    """Smallest angle between the line ``axis`` and any of the unit ``directions``."""
    if len(directions) == 0:
        return np.pi / 2
    return float(np.arccos(min(np.abs(directions @ axis).max(), 1.0)))


def angular_frame(light, occluder_points: np.ndarray, prefer_x=None) -> tuple[np.ndarray, np.ndarray]:
    """(origin, rotation) of the angular frame for ``light`` and the occluder points (world, (N, 3)).

    Point light: the pole axis X is ``prefer_x`` itself when it clears every occluder direction by
    :data:`POLE_CLEARANCE`, else the axis orthogonal to their mean direction that clears them most (the
    least spread direction of their scatter); -Z is the occluders' mean direction made orthogonal to X
    (theta = 0 at their centre, the wrap at +-pi behind the light). Directional light: Z towards the
    light, X = ``prefer_x`` made orthogonal to it when given; origin at the occluders' centre.
    """
    pts = np.asarray(occluder_points, dtype=np.float64)
    point = isinstance(light, PointLight)
    if point:
        origin = light.position.astype(np.float64)
        d = _unit_directions(light, pts)
        mean = d.sum(axis=0) if len(d) else np.zeros(3)
        z_axis = -mean / np.linalg.norm(mean) if np.linalg.norm(mean) > 1e-6 * max(len(d), 1) else np.array([0.0, 0, 1])
    else:
        origin = 0.5 * (pts.min(axis=0) + pts.max(axis=0)) if len(pts) else np.zeros(3)
        z_axis = -light.direction.astype(np.float64)
        d = np.zeros((0, 3))
    x_axis = None
    if prefer_x is not None:
        px = np.asarray(prefer_x, dtype=np.float64)
        if not point:
            px = px - (px @ z_axis) * z_axis
        if np.linalg.norm(px) > 1e-9 and (not point or _pole_clearance(px / np.linalg.norm(px), d) >= POLE_CLEARANCE):
            x_axis = px / np.linalg.norm(px)
    if x_axis is None:
        basis = np.stack(orthonormal_basis(z_axis))
        x_axis = basis[0]
        if point and len(d):
            proj = d @ basis[:2].T                                   # components in the plane orthogonal to z
            x_axis = np.linalg.eigh(proj.T @ proj)[1][:, 0] @ basis[:2]   # least spread: farthest from them
    if point:                                                        # -Z: the mean direction, orthogonal to X
        z_axis = z_axis - (z_axis @ x_axis) * x_axis
        z_axis = z_axis / np.linalg.norm(z_axis) if np.linalg.norm(z_axis) > 1e-9 else orthonormal_basis(x_axis)[0]
    y_axis = np.cross(z_axis, x_axis)
    return origin, np.stack([x_axis, y_axis, z_axis])


def row_coordinate(local: np.ndarray, point: bool) -> np.ndarray:
    """theta = atan2(Y, -Z) (point light) or Y (directional) of frame positions (float64)."""
    return np.arctan2(local[:, 1], -local[:, 2]) if point else local[:, 1].copy()


def rows_from_receivers(span: float, far: float, receiver_bounds: np.ndarray, expected_receivers, point: bool) -> int:
    """Eq. 4 in angle form: rows so that one row is about one receiver spacing wide at the farthest
    receiver (``far`` from the light; for a directional light rows are lengths and ``far`` is unused).
    The spacing is the square root of the receivers' box's largest face area over their count; with no
    count, :data:`DEFAULT_ROWS`."""
    if expected_receivers is None:
        return DEFAULT_ROWS
    ext = np.maximum(receiver_bounds[1] - receiver_bounds[0], 0.0)
    area = max(ext[0] * ext[1], ext[1] * ext[2], ext[0] * ext[2], 1e-300)
    spacing = np.sqrt(area / max(expected_receivers, 1))
    width = span * far if point else span
    return int(np.clip(np.ceil(width / spacing), MIN_ROWS, MAX_ROWS))


# Table -----------------------------------------------------------------------------------------------------

@dataclass
class LoopSet:
    """The paper's table input for the closed components: ridge-edge ``loops``, the lit region of each loop
    edge in loop order (``regions``), and the concave ``creases`` ((K, 2) vertex ids) with theirs
    (``crease_regions``); ``poles``: signed X of each point where the pole axis pierces a lit face (point
    light), with its region (``pole_regions``)."""

    loops: list
    regions: np.ndarray
    creases: np.ndarray
    crease_regions: np.ndarray
    poles: np.ndarray
    pole_regions: np.ndarray


@dataclass
class Table:
    """One light's lookup table on the device: ``offsets`` (rows + 1) int32 CSR and ``records``
    (entries x 8) float32 (``s_lo, s_hi, nx, ny, nz, d, face, running max of s_hi``; face as int32 bits),
    rows sorted by ``s_lo``; ``relative`` (anchor-relative float32 vertices) and ``faces``: the triangles a
    lookup tests a face record's hit against."""

    frame: Frame
    offsets: object
    records: object
    entries: int
    table_faces: np.ndarray
    relative: object
    faces: object

    @property
    def nbytes(self) -> int:
        return 4 * (self.frame.rows + 1) + 4 * REC_FLOATS * self.entries + self.relative.size + self.faces.size


def build_table(device, local_vertices: np.ndarray, faces: np.ndarray, table_faces: np.ndarray, frame: Frame,
                stats: dict | None = None, loops=None) -> Table:
    """The lookup table of ``table_faces`` (indices into ``faces``) with ``local_vertices`` in ``frame``, plus,
    when ``loops`` (a list of ridge-edge loops) is given, the pairs of the paper's loop table
    (:func:`loop_pairs`) in the same rows."""
    stats = {} if stats is None else stats
    dev, queue = device, device.queue
    t0 = time.perf_counter()
    n = len(table_faces)
    rows = frame.rows
    options = frame_options(frame)
    vertices_g = dev.to_device(np.ascontiguousarray(local_vertices, dtype=np.float32))
    relative_g = dev.to_device(np.ascontiguousarray(local_vertices - frame.anchor, dtype=np.float32))
    anchor = tuple(np.float32(c) for c in frame.anchor)
    faces_g = dev.to_device(np.ascontiguousarray(faces, dtype=np.int32))
    ids_g = dev.to_device(np.ascontiguousarray(table_faces, dtype=np.int32))
    planes_g = dev.empty(16 * max(n, 1), "face planes")
    first_g = dev.empty(4 * max(n, 1), "face first rows")
    nrows_g = dev.empty(4 * max(n, 1), "face row counts")
    pads_g = dev.empty(4 * max(n, 1), "face row pads")
    pieces_g = dev.empty(4 * max(n, 1), "face span pieces")
    scalars = (np.int32(n), np.float32(frame.t0), np.float32(frame.dt), np.int32(rows))
    if n:
        dev.kernel("angular.cl", "face_rows", options)(queue, (n,), None, vertices_g, relative_g, faces_g, ids_g,
                                                       *scalars, *anchor, np.float32(frame.pad_t),
                                                       np.float32(frame.piece_width), planes_g, first_g, nrows_g, pads_g,
                                                       pieces_g)
    counts = row_counts(dev.from_device(first_g, n, np.int32), dev.from_device(nrows_g, n, np.int32), rows,
                        dev.from_device(pieces_g, n, np.int32))
    pairs = None if loops is None else loop_pairs(dev, vertices_g, loops, frame, stats)
    npairs = np.zeros(rows, dtype=np.int64) if pairs is None else pairs[2]
    counts = counts + npairs
    t1 = time.perf_counter()
    # Exclusive prefix sum of one count per row: a few kB, cheaper on the host than a device scan's launches.
    offsets = np.zeros(rows + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    entries = int(offsets[-1])
    nbytes = 4 * REC_FLOATS * entries
    check_capacity(dev, entries, rows, "table records")
    offsets_g = dev.to_device(offsets.astype(np.int32))
    records_g = dev.empty(max(nbytes, 4 * REC_FLOATS), "angular table records")
    t2 = time.perf_counter()
    if entries:
        if pairs is not None:      # the loop pairs first in each row, the face records after them
            dev.kernel("angular.cl", "copy_pairs", options)(queue, (rows,), None, pairs[1], pairs[3], offsets_g,
                                                            np.int32(rows), np.int32(pairs[4]), pairs[0], records_g)
        cursor_g = dev.to_device(npairs.astype(np.int32))
        if n:
            dev.kernel("angular.cl", "fill_rows", options)(queue, (n,), None, vertices_g, faces_g, ids_g, *scalars,
                                                           np.float32(frame.pad_s), planes_g, first_g, nrows_g, pads_g,
                                                           pieces_g, offsets_g, cursor_g, records_g)
        check_filled(dev, cursor_g, "angular fill_rows", offsets)
        t2 = time.perf_counter()
        dev.kernel("angular.cl", "sort_rows", options)(queue, (rows,), None, offsets_g, np.int32(rows), records_g)
    queue.finish()
    t3 = time.perf_counter()
    stats.update(count_s=t1 - t0, fill_s=t2 - t1, sort_s=t3 - t2,
                 entries=entries, rows=rows, max_row=int(counts.max(initial=0)), table_bytes=4 * (rows + 1) + nbytes)
    return Table(frame, offsets_g, records_g, entries, np.asarray(table_faces, dtype=np.int32), relative_g, faces_g)


def loop_pairs(device, vertices_g, loops, frame: Frame, stats: dict):
    """The paper's loop table on the device (sections 3-4, 7.1 steps 1.3-1.5): every ridge edge's crossings
    with the rows it spans (counted, prefix-summed, filled: ``edge_rows``, ``fill_edges``), then per row
    the crossings sorted by (loop, s) and paired loop by loop with section 4's rule (``pair_rows``, one
    work-item per row: the pairing is a sequential scan per loop, cheap next to the fill). Returns
    (pairs buffer, its row offsets buffer, (rows,) pairs per row, that count's buffer); a pair record
    holds its span and the plane of its chord (depth interpolated between the pair's ends)."""
    dev, queue, rows = device, device.queue, frame.rows
    options = frame_options(frame)
    chains = [np.asarray(loop.vertices, dtype=np.int32) for loop in loops.loops]
    ridge = np.concatenate(chains) if chains else np.zeros(0, dtype=np.int32)
    length = np.array([len(c) for c in chains], dtype=np.int64)
    after = np.arange(1, len(ridge) + 1)
    after[np.cumsum(length) - 1] = np.cumsum(length) - length         # each chain's last edge closes it
    tails = np.concatenate([ridge, loops.creases[:, 0].astype(np.int32)])
    heads = np.concatenate([ridge[after] if len(ridge) else ridge, loops.creases[:, 1].astype(np.int32)])
    group = np.concatenate([loops.regions, loops.crease_regions]).astype(np.int32)
    ne, nridge = len(tails), len(tails) - len(loops.creases)
    tails_g, heads_g = dev.to_device(tails), dev.to_device(heads)
    first_g, count_g = dev.empty(4 * max(ne, 1), "edge first rows"), dev.empty(4 * max(ne, 1), "edge row counts")
    scalars = (np.int32(ne), np.float32(frame.t0), np.float32(frame.dt), np.int32(rows))
    if ne:
        dev.kernel("angular.cl", "edge_rows", options)(queue, (ne,), None, vertices_g, tails_g, heads_g, *scalars,
                                                       first_g, count_g)
    npoles = len(loops.poles)            # pole crossings: one per pierced lit face, in every row
    counts = row_counts(dev.from_device(first_g, ne, np.int32), dev.from_device(count_g, ne, np.int32), rows) + npoles
    offsets = np.zeros(rows + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    crossings = int(offsets[-1])
    check_capacity(dev, crossings, rows, "ridge-edge and crease crossings")
    offsets_g = dev.to_device(offsets.astype(np.int32))
    cross_g = dev.empty(4 * REC_FLOATS * max(crossings, 1), "ridge-edge crossings")
    queue_g = dev.empty(4 * max(crossings, 1), "pairing queue")
    npairs_g = dev.to_device(np.zeros(rows, dtype=np.int32))
    cap = 1                  # a row has fewer pairs than crossings unless a duplicate falls in several pairs (coils)
    if crossings:
        cursor_g = dev.to_device(np.full(rows, npoles, dtype=np.int32))
        if npoles:
            dev.kernel("angular.cl", "fill_poles", options)(
                queue, (rows,), None, dev.to_device(loops.poles.astype(np.float32)),
                dev.to_device(loops.pole_regions.astype(np.int32)), np.int32(npoles), np.int32(rows), offsets_g, cross_g)
        if ne:
            dev.kernel("angular.cl", "fill_edges", options)(
                queue, (ne,), None, vertices_g, tails_g, heads_g, dev.to_device(group), np.int32(ne), np.int32(nridge),
                *scalars[1:], first_g, count_g, offsets_g, cursor_g, cross_g)
        check_filled(dev, cursor_g, "angular fill_edges", offsets)
    queue.finish()
    t_pair = time.perf_counter()
    while True:
        check_capacity(dev, cap * crossings, rows, "loop pairs")
        pairs_g = dev.empty(4 * REC_FLOATS * max(cap * crossings, 1), "loop pairs")
        overflow_g = dev.to_device(np.zeros(1, dtype=np.int32))
        if crossings:
            dev.kernel("angular.cl", "pair_rows", options)(
                queue, (rows,), None, offsets_g, np.int32(rows), np.float32(frame.t0), np.float32(frame.dt),
                vertices_g, tails_g, heads_g, np.int32(cap), *(np.float32(c) for c in frame.anchor), cross_g, queue_g,
                pairs_g, npairs_g, overflow_g)
        if dev.from_device(overflow_g, 1, np.int32)[0] == 0:
            break
        cap *= 2
    npairs = dev.from_device(npairs_g, rows, np.int32).astype(np.int64)
    stats["pair_s"] = time.perf_counter() - t_pair          # the sort and section-4 pairing on the device
    stats.update(loops=len(chains), regions=len(np.unique(group)), ridge_edges=nridge, creases=ne - nridge, poles=npoles,
                 crossings=crossings, pairs=int(npairs.sum()), pair_capacity=cap)
    return pairs_g, offsets_g, npairs, npairs_g, cap


def lit_regions(adjacency, facing: np.ndarray) -> np.ndarray:
    """(F,) int: connected regions of light-facing faces (joined across edges with both faces facing the
    light), -1 for the others. The loops bounding one region (an outer loop and its holes) pair together."""
    pairs = adjacency.edge_faces[adjacency.face_count == 2]
    both = facing[pairs[:, 0]] & facing[pairs[:, 1]]
    return np.where(facing, components(len(facing), pairs[both]), -1)


def edge_regions(adjacency, facing: np.ndarray, edges: np.ndarray, regions: np.ndarray) -> np.ndarray:
    """(len(edges),) int32: the lit region (``regions``, per face) of each edge's (first) light-facing face."""
    two = adjacency.edge_faces[edges]
    lit = np.where(facing[two[:, 0]], two[:, 0], two[:, 1])
    return regions[lit].astype(np.int32)


def concave_creases(adjacency, facing: np.ndarray) -> np.ndarray:
    """Concave edges (:func:`shadowcl.topology.concave_edges`) between two light-facing faces: a valley
    seen from the light, which a chord between the loop's crossings would cut off. Section 5 inserts such
    edges in duplicate for depth; the convex ones lie in front of the chord and need none."""
    ids = np.flatnonzero(adjacency.face_count == 2)
    f = adjacency.edge_faces[ids]
    return concave_edges(adjacency, ids[facing[f[:, 0]] & facing[f[:, 1]]])


def pole_hits(adjacency, facing: np.ndarray, regions: np.ndarray, local) -> tuple[np.ndarray, np.ndarray]:
    """Where the pole axis (frame X, through a point light at the origin) pierces a light-facing face: (signed X
    of the hit, region). Every row's half-plane ends on that axis, so a lit region pierced there is cut in
    every row between a loop crossing and the pole: the pole enters the pairing as a crossing (s = +-1).
    None for a directional light (``local`` None: parallel rows)."""
    if local is None:
        return np.zeros(0), np.zeros(0, dtype=np.int32)
    lit = np.flatnonzero(facing)
    tri = np.asarray(local, dtype=np.float64)[adjacency.faces[lit]]
    u, v = tri[:, :, 1], -tri[:, :, 2]
    e = [u[:, i] * v[:, (i + 1) % 3] - v[:, i] * u[:, (i + 1) % 3] for i in range(3)]
    around = ((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)) | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0))
    tri = tri[around]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ok = np.abs(n[:, 0]) > 0
    x = np.einsum("ij,ij->i", n[ok], tri[ok, 0]) / n[ok, 0]           # the plane met on the axis
    return x, regions[lit[around][ok]].astype(np.int32)


def check_capacity(device, entries: int, rows: int, what: str) -> None:
    """Raise ``ValueError`` (naming theta_resolution) when ``entries`` records do not fit one device buffer."""
    nbytes = 4 * REC_FLOATS * entries
    if entries >= 2**31 or nbytes > device.max_alloc_bytes:
        raise ValueError(f"theta_resolution: {rows} rows give {entries} {what} ({nbytes >> 20} MiB), more than "
                         f"the device holds in one buffer ({device.max_alloc_bytes >> 20} MiB); use fewer rows")


def row_counts(first: np.ndarray, count: np.ndarray, rows: int, per_row=None) -> np.ndarray:
    """(rows,) records per row from each item's first row (unwrapped), row count and records in each of its
    rows (``per_row``, default 1), by a difference array: per-row atomic counters on the device serialised
    on ~600 addresses (0.45 s for 600 k faces)."""
    w = np.ones(len(first), dtype=np.int64) if per_row is None else np.asarray(per_row, dtype=np.int64)
    start = np.mod(first.astype(np.int64), rows)
    end = start + count
    inside = end <= rows                                      # intervals that do not wrap round
    diff = np.bincount(start, w, minlength=rows + 1)[:rows + 1].astype(np.int64)
    diff -= np.bincount(np.where(inside, end, rows), w, minlength=rows + 1)[:rows + 1].astype(np.int64)
    wrapped = ~inside
    diff[0] += w[wrapped].sum()
    diff -= np.bincount(end[wrapped] - rows, w[wrapped], minlength=rows + 1)[:rows + 1].astype(np.int64)
    return np.cumsum(diff[:rows]).astype(np.int64)


def frame_options(frame: Frame, normals: bool = False) -> tuple[str, ...]:
    return (f"-DLIGHT_POINT={int(frame.point)}", f"-DFULL_CIRCLE={int(frame.full_circle)}", f"-DNORMALS={int(normals)}")


def table_entries(device, table: Table) -> dict:
    """The table read back: ``offsets``, ``row`` (E,), ``face`` (a face record's face, -(region + 1) for a
    loop pair), ``region`` (a loop pair's lit region, -1 for face records), ``s_lo``, ``s_hi``, ``plane``
    (E, 4), rows in order, each sorted by s_lo."""
    rows = table.frame.rows
    offsets = device.from_device(table.offsets, rows + 1, np.int32)
    rec = device.from_device(table.records, (max(table.entries, 1), REC_FLOATS), np.float32)[:table.entries]
    ident = rec[:, 6].view(np.int32)
    plane = rec[:, 2:6].astype(np.float64)
    plane[:, 3] += plane[:, :3] @ table.frame.anchor          # the kernels' offsets are relative to the anchor
    return dict(offsets=offsets, row=np.repeat(np.arange(rows), np.diff(offsets)), face=ident,
                region=np.where(ident < 0, -ident - 1, -1), s_lo=rec[:, 0], s_hi=rec[:, 1], plane=plane)


# Method ----------------------------------------------------------------------------------------------------

class AngularMethod(Method):
    """Shadows from a per-light table of angular spans (see the module docstring).

    After :meth:`prepare`, :attr:`stats` holds the rows, records, table bytes and stage times;
    :meth:`classify` and :meth:`classify_view` add theirs (``classify_view``: ``lookups``, the full
    lookups made, against ``receivers``).
    """

    name = "angular"
    min_light_clearance = 1e-5      # measured (bench/range.py): right from 1e-7 off a surface, not on it
    image_space = True
    parameters = {
        "theta_resolution": (None, "rows of the table (theta steps; Y steps for a directional light); None picks "
                                   "them from the receivers (eq. 4: one row per receiver spacing at the farthest "
                                   "receiver; 600 when their number is unknown), and for render from the image "
                                   "(ROWS_PER_LINE rows per scan line)"),
        "expected_receivers": (None, "about how many receivers are coming, used to pick theta_resolution"),
        "table": ("faces", "'faces': one span record per (light-facing face, row band it meets), the hit tested on "
                           "the triangle: exact but for float32 ties; 'loops': the paper's table, the ridge-edge "
                           "loops' crossings paired per loop (section 4) at the row's centre, depth interpolated "
                           "between a pair's ends (see the module docstring for the choice)"),
        "runs": (True, "classify_view: one lookup serves a run of pixels on a scan line (False: one per pixel)"),
        "prefer_x": (None, "preferred pole axis (world vector); None: away from the occluders, and for render "
                           "the camera's right axis when it is clear of them (rows along the scan lines)"),
    }

    def __init__(self, device, **params):
        super().__init__(device, **params)
        p = self.params
        if not isinstance(p["table"], str):
            raise TypeError(f"table: expected 'faces' or 'loops', got {type(p['table']).__name__}")
        self.table_kind = choice("table", p["table"], TABLES)
        self.theta_resolution = optional_int("theta_resolution", p["theta_resolution"], 1, MAX_ROWS)
        self.expected_receivers = optional_int("expected_receivers", p["expected_receivers"], 0)
        self.runs = flag("runs", p["runs"])
        self.prefer_x = None if p["prefer_x"] is None else vector3("prefer_x", p["prefer_x"], nonzero=True)
        self.table: Table | None = None
        self._fp64 = "cl_khr_fp64" in device.cl_device.extensions   # receivers moved into the frame on the device

    def resolved_params(self) -> dict:
        params = dict(self.params)
        if self.table is not None:
            params["theta_resolution"] = self.frame.rows
        return params

    # prepare -------------------------------------------------------------------------------------------
    def prepare(self, mesh: Mesh, light, receiver_bounds, eps: float) -> None:
        """Build ``light``'s table for occluders ``mesh`` and receivers in ``receiver_bounds`` ((2, 3))."""
        light, box = check_prepare(mesh, light, receiver_bounds, eps)
        self._build(mesh, light, box, float(eps), self.prefer_x, None)
        self._prepared_table = (self.frame, self.table, self.stats)   # where every view's choice starts
        self._view_key = None            # the view classify_view last chose a table for (None: none yet)

    def _build(self, mesh: Mesh, light, box: np.ndarray, eps: float, prefer_x, rows) -> None:
        """The table with pole axis ``prefer_x`` (None: away from the occluders) and ``rows`` rows (None: the
        parameter or eq. 4); :meth:`classify_view` rebuilds with the camera's right axis and the image's own
        limit."""
        t0 = time.perf_counter()
        point = isinstance(light, PointLight)
        adjacency = edge_adjacency(mesh)
        sil = silhouette_edges(self.device, adjacency, light)
        closed = adjacency.closed_faces     # in a closed component a blocked ray always crosses a light-facing
        if point:                           # face, so only those enter the table; elsewhere every face does
            light_inside(adjacency, light)
        keep = np.where(closed, sil.facing, True)
        keep[adjacency.collapsed_faces] = False
        table_faces = np.flatnonzero(keep)
        used = np.zeros(len(mesh.vertices), dtype=bool)
        used[mesh.faces[table_faces]] = True                      # (np.unique hashes: 2 s at 1.8 M corners)
        used = np.flatnonzero(used)
        sample = used if len(used) <= SAMPLE else used[np.linspace(0, len(used) - 1, SAMPLE).astype(np.int64)]
        origin, rotation = angular_frame(light, mesh.vertices[sample], prefer_x)
        local = (mesh.vertices.astype(np.float64) - origin) @ rotation.T
        t1 = time.perf_counter()
        # Row range: the table faces' corners (for a closed mesh these span the RE loops' range, section 3)
        full = False
        if len(used):
            t = row_coordinate(local, point)                              # per vertex, gathered per face below
            lo, hi = float(t[used].min()), float(t[used].max())
            if point:
                tc = t[mesh.faces[table_faces]]
                straddles = np.any(tc.max(axis=1) - tc.min(axis=1) > np.pi)   # a face across the cut at +-pi
                full = bool(straddles or hi - lo > FULL_CIRCLE_SPAN or _around_pole(local, mesh.faces[table_faces]))
        else:
            lo, hi = 0.0, 1.0
        if full:
            lo, hi = -np.pi, np.pi
        span = max(hi - lo, 1e-12)
        if rows is not None:
            rows = positive_int("rows", rows, 1, MAX_ROWS)
        elif self.theta_resolution is not None:
            rows = self.theta_resolution
        else:
            far_pts = box_corners(box)
            far = float(np.linalg.norm(far_pts - light.position, axis=1).max()) if point else 0.0
            rows = rows_from_receivers(span, far, box, self.expected_receivers, point)
        if not full:                                   # pad half a row each side (the loops table cuts at row centres)
            pad = 0.5 * span / rows
            lo, hi = lo - pad, hi + pad
        centre = 0.5 * (mesh.vertices[used].min(axis=0) + mesh.vertices[used].max(axis=0)) if len(used) else origin
        if point:
            # Float32 rounding of a direction's theta and s is relative to their own size (-Z points at
            # the occluders' centre and coordinates are held relative to it), so the pads scale with
            # the occluders' angular size: a light 1e5 sizes away has rows and spans ~1e-5 wide, and
            # absolute pads listed every face in most rows (82 k triangles: 173 k -> 18.5 M entries).
            directions = local[used] / np.linalg.norm(local[used], axis=1, keepdims=True) if len(used) else np.ones((1, 3))
            angle_scale = min(1.0, max(abs(lo), abs(hi), hi - lo))
            s_scale = min(1.0, float(np.abs(directions[:, 0]).max()) + float(np.ptp(directions[:, 0])))
            pads = (ANGLE_PAD * max(angle_scale, 1e-12), S_PAD * max(s_scale, 1e-12), 2.0 / PIECES)
        else:
            extent = float(np.abs(local[used]).max()) if len(used) else 0.0
            extent = extent if extent > 0 else 1.0                 # (all corners at the origin: nothing blocks)
            pads = (LENGTH_PAD * extent, LENGTH_PAD * extent, 2.0 * extent / PIECES)
        frame = Frame(origin, rotation, point, lo, (hi - lo) / rows, rows, full, np.asarray(centre, dtype=np.float64),
                      *pads)
        loops = None
        if self.table_kind == "loops":
            # closed components by their loops (the row range above already covers them); open or
            # non-manifold ones keep a face record per face (a hidden face there can stop a ray)
            loops = self._closed_loops(mesh, adjacency, sil, closed, light, local if point else None)
            table_faces = table_faces[~closed[table_faces]]
        self.stats = dict(setup_s=t1 - t0, table_faces=len(table_faces), closed=bool(closed.all()), full_circle=full,
                          table=self.table_kind)
        self.table = build_table(self.device, local, mesh.faces, table_faces, frame, self.stats, loops)
        self.loops = loops
        self.stats["prepare_s"] = time.perf_counter() - t0
        self.mesh, self.light, self.eps, self.frame, self._box = mesh, light, float(eps), frame, box
        self._sample, self._built_prefer = sample, prefer_x
        self._directions = _unit_directions(light, mesh.vertices[sample]) if point else np.zeros((0, 3))

    def _closed_loops(self, mesh, adjacency, sil, closed, light, local):
        """(loops, region of each loop edge) of the closed components: the ridge-edge loops (checked as in
        :func:`ridge_loops`) and, per edge in loop order, the lit region (:func:`lit_regions`) it bounds."""
        if not closed.any():
            return LoopSet([], np.zeros(0, np.int32), np.zeros((0, 2), np.int32), np.zeros(0, np.int32), np.zeros(0),
                           np.zeros(0, np.int32))
        try:                      # the whole mesh's loops, those of the closed components kept
            check_even_count(sil)
            loops = [loop for loop in silhouette_loops(sil) if closed[adjacency.edge_faces[loop.edges[0], 0]]]
            lit = sil.facing & closed
        except ValueError:        # an open part is non-manifold or misoriented: the closed part's own loops
            part = closed.copy()
            part[adjacency.collapsed_faces] = False
            sil = silhouette_edges(self.device, edge_adjacency(Mesh(mesh.vertices, mesh.faces[part])), light)
            check_even_count(sil)
            loops = silhouette_loops(sil)
            lit = sil.facing
        edges = np.concatenate([loop.edges for loop in loops]) if loops else np.zeros(0, dtype=np.int64)
        adj = sil.adjacency
        regions = lit_regions(adj, lit)
        creases = concave_creases(adj, lit)
        poles, pole_regions = pole_hits(adj, lit, regions, local)
        return LoopSet(loops, edge_regions(adj, lit, edges, regions), adj.edges[creases],
                       edge_regions(adj, lit, creases, regions), poles, pole_regions)

    # classify ------------------------------------------------------------------------------------------
    def _inputs(self, points, normals):
        """Device buffers of the receivers, the frame arguments and the build options: world float64 moved
        into the frame on the device when it has doubles, else moved here and rounded to float32."""
        if self.table is None:
            raise RuntimeError("classify: call prepare(mesh, light, receiver_bounds, eps) first")
        receivers = check_points(points, normals)
        points, normals = receivers.positions, receivers.checked_normals()
        dev, frame = self.device, self.frame
        if self._fp64:
            rot, origin, dtype = frame.rotation, frame.origin, np.float64
            pts, nrm = points, normals
        else:
            rot, origin, dtype = frame.rotation, np.zeros(3), np.float32
            pts = frame.to_local(points) - frame.anchor
            nrm = None if normals is None else receivers.unit_normals() @ rot.T
        pts_g = dev.to_device(np.ascontiguousarray(pts, dtype=dtype))
        nrm_g = pts_g if nrm is None else dev.to_device(np.ascontiguousarray(nrm, dtype=dtype))
        args = (pts_g, nrm_g, dev.to_device(np.ascontiguousarray(rot, dtype=dtype)), *(dtype(c) for c in origin),
                *(np.float32(c) for c in frame.anchor))
        return len(points), args, frame_options(frame, normals is not None) + (f"-DINPUT_F64={int(self._fp64)}",)

    def _common_args(self):
        f = self.frame
        return (np.float32(f.t0), np.float32(1.0 / f.dt), np.int32(f.rows), np.float32(self.eps),
                self.table.offsets, self.table.records, self.table.relative, self.table.faces)

    def classify(self, points, normals=None) -> np.ndarray:
        """Bool (N,) mask of world ``points`` (optional ``normals``, any length), True = in shadow."""
        t0 = time.perf_counter()
        n, args, options = self._inputs(points, normals)
        dev = self.device
        out_g = dev.empty(max(n, 1), "angular output")
        if n:
            dev.kernel("angular.cl", "angular_classify", options)(
                dev.queue, (n,), None, args[0], args[1], np.int32(n), *args[2:], *self._common_args(), out_g)
        out = dev.from_device(out_g, n, np.uint8).astype(bool)
        self.stats.update(classify_s=time.perf_counter() - t0, receivers=n)
        return out

    def classify_view(self, view, zbuffer, seen) -> np.ndarray:
        """Bool mask of ``seen``'s covered pixels (row-major), by scan-line runs (``runs=True``) or per pixel."""
        key = (view.width, view.height, view.origin.tobytes(), view.matrix.tobytes())
        if key != self._view_key:       # a new view: choose its table from prepare's, build it at most once
            base = self._prepared_table[0]
            right = view.matrix[0, :3] / np.linalg.norm(view.matrix[0, :3])   # camera right, the scan-line direction
            prefer = self.prefer_x
            if prefer is None and abs(float(base.rotation[0] @ right)) < 0.999 and (
                    not base.point or _pole_clearance(right, self._directions) >= POLE_CLEARANCE):
                prefer = right      # rows along the scan lines (the paper's frame: XY parallel to the screen)
            rows = base.rows if self.theta_resolution is not None else self.view_rows(seen, view, prefer)
            if rows == base.rows and _same_axis(prefer, self.prefer_x):
                self.frame, self.table, self.stats = self._prepared_table
                self._built_prefer = self.prefer_x
            elif rows != self.frame.rows or not _same_axis(prefer, self._built_prefer):
                build_s = self._prepared_table[2].get("prepare_s", 0.0)
                self._build(self.mesh, self.light, self._box, self.eps, prefer, rows)
                self.stats["prepare_s"] += build_s
            self._view_key = key
        if not self.runs:
            mask = self.classify(seen.points, seen.normals)
            self.stats["lookups"] = len(mask)
            return mask
        return self.classify_lines(seen.points, seen.normals, seen.pixel_index // view.width, view.height)

    def view_rows(self, seen, view, prefer_x=None) -> int:
        """Rows at the image's own limit (section 3): one row per scan line, i.e. the table's row-coordinate
        span over the median row-coordinate step between vertically adjacent covered pixels, times
        :data:`ROWS_PER_LINE`."""
        frame = self._prepared_table[0]
        if len(seen.points) == 0:
            return frame.rows
        if not _same_axis(prefer_x, self.prefer_x):
            _, rotation = angular_frame(self.light, self.mesh.vertices[self._sample], prefer_x)
            frame = Frame(frame.origin, rotation, frame.point, frame.t0, frame.dt, frame.rows, frame.full_circle,
                          frame.centre, frame.pad_t, frame.pad_s, frame.piece_width)
        t = np.full(view.height * view.width, np.nan)
        t[seen.pixel_index] = row_coordinate(frame.to_local(seen.points), frame.point)
        step = np.abs(np.diff(t.reshape(view.height, view.width), axis=0))
        if frame.point:
            step = np.minimum(step, 2 * np.pi - step)
        step = step[np.isfinite(step) & (step > 0)]
        if len(step) == 0:
            return frame.rows
        span = 2 * np.pi if frame.full_circle else frame.rows * frame.dt
        return int(np.clip(np.ceil(ROWS_PER_LINE * span / np.median(step)), MIN_ROWS, MAX_ROWS))

    def classify_lines(self, points, normals, line, lines: int) -> np.ndarray:
        """Like :meth:`classify` for receivers in scan-line order (``line`` (N,) non-decreasing, < ``lines``),
        one work-item per line reusing each lookup over a run; :attr:`stats` ``lookups`` = full lookups."""
        t0 = time.perf_counter()
        n, args, options = self._inputs(points, normals)
        line = np.asarray(line, dtype=np.int64)
        if line.shape != (n,) or (n and (np.any(np.diff(line) < 0) or line[0] < 0 or line[-1] >= lines)):
            raise ValueError("line: expected a non-decreasing scan-line index per receiver, each below lines")
        dev = self.device
        # pieces of at most RUN_PIECE receivers, never across a scan line: one work-item per line left the
        # device's lanes and cores idle (540 lines on 2 cores, no vectorisation across them)
        start = np.union1d(np.searchsorted(line, np.arange(lines + 1)), np.arange(0, n, RUN_PIECE)).astype(np.int32)
        pieces = len(start) - 1
        out_g = dev.empty(max(n, 1), "angular output")
        lookups_g = dev.empty(4 * max(pieces, 1), "lookups per piece")
        if n:
            dev.kernel("angular.cl", "angular_runs", options)(
                dev.queue, (pieces,), None, *args, dev.to_device(start), np.int32(pieces), *self._common_args(),
                out_g, lookups_g)
        out = dev.from_device(out_g, n, np.uint8).astype(bool)
        lookups = int(dev.from_device(lookups_g, pieces, np.int32).sum()) if n else 0
        self.stats.update(classify_s=time.perf_counter() - t0, receivers=n, lookups=lookups)
        return out

    def entries(self) -> dict:
        """The table read back (see :func:`table_entries`)."""
        return table_entries(self.device, self.table)


def light_inside(adjacency, light) -> None:
    """Raise ``ValueError`` when point ``light`` is inside a closed component of the mesh of ``adjacency``
    (:meth:`shadowcl.topology.EdgeAdjacency.enclosing_faces`). There no face turns to the light (or all do,
    wound inwards), the table would be empty or the far wall's, and every receiver would come out lit; the
    shadow is everything outside the solid, not what this method models."""
    if not isinstance(light, PointLight):
        return
    enclosing = adjacency.enclosing_faces(light.position)
    if len(enclosing):
        raise ValueError(f"light: the point light is inside a closed solid "   # (its position here is the frame's)
                         f"({len(enclosing)} faces); everything outside that solid is in its shadow, which "
                         "the angular table cannot represent (no face of it turns to the light): move the "
                         "light out or open the mesh")


def _same_axis(a, b) -> bool:
    """Whether two optional pole axes (None or 3-vectors) are the same."""
    return (a is None) == (b is None) and (a is None or bool(np.array_equal(a, b)))


def _around_pole(local: np.ndarray, faces: np.ndarray) -> bool:
    """Whether any triangle's projection on the YZ plane contains the origin (the pole axis crosses it)."""
    u, v = local[:, 1][faces], -local[:, 2][faces]
    e = [u[:, i] * v[:, (i + 1) % 3] - v[:, i] * u[:, (i + 1) % 3] for i in range(3)]
    return bool(np.any(((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)) | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0))))


def _unit_directions(light, points: np.ndarray) -> np.ndarray:
    d = np.asarray(points, dtype=np.float64) - light.position
    length = np.linalg.norm(d, axis=1)
    return d[length > 0] / length[length > 0, None]
