"""The angular method (:class:`AngularMethod`): prepare builds a light's frame and table, classify and
classify_view look receivers up in it (section 7; scan-line runs in render); and the light-inside check."""

from __future__ import annotations

import time

import numpy as np

from ..checks import choice, flag, optional_int, positive_int, vector3
from ..geometry import Mesh
from ..lights import PointLight
from ..methods import Method, check_prepare
from ..points import check_points
from ..lightspace import box_corners
from ..silhouette import edge_adjacency, silhouette_edges, silhouette_loops
from .frame import (ANGLE_PAD, LENGTH_PAD, MAX_ROWS, MIN_ROWS, PIECES, POLE_CLEARANCE, S_PAD, Frame, _pole_clearance,
                    _unit_directions, angular_frame, around_pole, row_coordinate, rows_from_receivers)
from .loops import LoopSet, check_even_count, concave_creases, edge_regions, lit_regions, pole_hits
from .table import Table, build_table, frame_options, table_entries

FULL_CIRCLE_SPAN = np.radians(170.0)  # occluders spanning more theta than this get the whole circle
ROWS_PER_LINE = 2              # render's default rows per scan line (view_rows): on the hard scenes at 160 x 90 the
                               # sphere terminator's wrong pixels went 385 / 183 / 67 at 1 / 2 / 4 per line
TABLES = ("faces", "loops")
RUN_PIECE = 64                 # classify_lines: receivers per work-item at most (a run never crosses a piece)
SAMPLE = 20000                 # occluder vertices sampled for the frame choice


class AngularMethod(Method):
    """Shadows from a per-light table of angular spans (see the docstring of :mod:`shadowcl.angular`).

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
                           "between a pair's ends (see the docstring of shadowcl.angular for the choice)"),
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
    return bool(np.any(around_pole(local[:, 1][faces], local[:, 2][faces])))
