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
far from the world origin keeps its float32 precision.

Choices, measured on the bench's scenes (bench/receivers.py: bunny or ogre on a ground quad, 1 M
receivers on the ground + 200 k on the model, random order, PoCL on 2 cores; ranges are run-to-run):

- CSR lists (default) over linked lists: the linked build's single pass costs more than count + scan
  + fill (every entry takes a node from one global atomic counter: 36-65 ms against 15-25 ms) and its
  walk chases pointers (classify 1.4-1.5x slower).
- Triangle records of 64 bytes (the 9 corner floats, then the unit normal and the light's side of the
  plane): the kernel first skips a triangle whose plane the segment cannot reach (plane cull, exact:
  it never removes a crossing), which rejects ~3/4 of the visited entries before the watertight test.
  With coherent receivers it cut classify by ~25%; with random ones it pays for its larger records.
- Lists are not sorted by distance: with the cull, lit receivers' walks are cheap, and shadowed ones
  stop at the first hit; a sort would cost a pass.
- Receivers are not sorted by cell: sorting on the device and gathering them back cost more (97 ms
  for the gather alone) than the cache misses it saves (49 ms random against 33 ms sorted).
- Watertight against dot5: the same speed within noise (the cull does most of the rejecting); dot5
  leaks on 6-8% of rays aimed at shared edges and vertices, watertight on none.

Where the time goes (bunny, point light, 1.2 M receivers; ~80 ms in all, ~14 M receivers/s, 1.7-2.3x
the fastest embreex in the same bench run): prepare ~19 ms (count pass ~10: projection ~3-4, cell tests
~4, atomics ~3; fill ~3-5 from the count pass's cell masks; footprint fit ~2; scan 0.4; gather and
records ~1), classify ~60 ms, of which ~12 ms per-receiver set-up and ~45 ms walking lists: with every
receiver sent to one cached cell the same kernel takes ~26 ms, so most of classify is the latency of
reaching lists and records (L3-resident, in random receiver order). Receivers in a coherent order (a
camera's raster) run ~1.5x faster.

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
from .checks import check_bounds, finite_array, positive_int
from .geometry import Mesh, bounds_diagonal
from .lights import PointLight, check_light

TESTS = ("watertight", "dot5")
LISTS = ("csr", "linked")
DOT5_FLOATS = 16          # kernels/ray_triangle.h
WT_FLOATS = 16


def _optional_int(name, value, minimum=1, maximum=None):
    return None if value is None else positive_int(name, value, minimum, maximum)


def _as_points(name: str, value) -> np.ndarray:
    """(N, 3) C-contiguous float64 (shape and type checked here; finiteness on the device)."""
    try:
        array = np.asarray(value)
    except Exception as error:
        raise TypeError(f"{name}: cannot be read as an array ({error})") from None
    if array.dtype == object or not (np.issubdtype(array.dtype, np.number) or array.dtype == bool) \
            or np.issubdtype(array.dtype, np.complexfloating):
        raise TypeError(f"{name}: expected a real numeric array, got dtype {array.dtype}")
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (N, 3), got {array.shape}")
    return np.ascontiguousarray(array, dtype=np.float64)


def _host_buffer(device, array: np.ndarray):
    """A read-only device view of ``array`` without a copy where the device allows (CL_MEM_USE_HOST_PTR)."""
    array = np.ascontiguousarray(array)
    if array.nbytes == 0:
        return device.to_device(array)
    return cl.Buffer(device.context, cl.mem_flags.READ_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=array)


class ExactMethod:
    """Exact shadows: light-space lists built on the device, then one list walk per receiver.

    Parameters are those of :attr:`parameters`. After :meth:`prepare`, :attr:`stats` holds the grid
    (views, cells, ``nx`` x ``ny``), the list entries and mean length, and the time of each stage in
    seconds; :meth:`list_statistics` adds the longest list and the share of empty cells (it reads the
    lists back, so it is kept out of :meth:`prepare`'s timing). :meth:`classify` adds its own time.
    """

    name = "exact"
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
        "chunk": (1 << 22, "receivers per classify launch (bounds device memory)"),
    }

    def __init__(self, device, resolution=None, expected_receivers=None, test="watertight", lists="csr",
                 initial_capacity=None, chunk=1 << 22):
        self.device = device
        self.resolution = _optional_int("resolution", resolution, 1, lightspace.MAX_SIDE)
        self.expected_receivers = _optional_int("expected_receivers", expected_receivers, 0)
        if test not in TESTS:
            raise ValueError(f"test: expected one of {TESTS}, got {test!r}")
        if lists not in LISTS:
            raise ValueError(f"lists: expected one of {LISTS}, got {lists!r}")
        self.test, self.lists_kind = test, lists
        self.initial_capacity = _optional_int("initial_capacity", initial_capacity, 1)
        self.chunk = positive_int("chunk", chunk)
        self._builder = lightspace.ListBuilder(device, corners=3)
        # float64 points go to the device as they are when it has doubles (cheaper than converting here)
        self._fp64 = "cl_khr_fp64" in device.cl_device.extensions
        self._prepared = False
        self.stats: dict = {}

    def __repr__(self) -> str:
        return f"ExactMethod(test={self.test!r}, lists={self.lists_kind!r}, resolution={self.resolution})"

    # prepare -------------------------------------------------------------------------------------------
    def prepare(self, mesh: Mesh, light, receiver_bounds, eps: float) -> None:
        """Build the light-space lists of ``mesh`` seen from ``light`` for receivers in ``receiver_bounds``.

        ``receiver_bounds`` is a (2, 3) world box; ``eps`` the absolute offset of DESIGN.md.
        """
        if not isinstance(mesh, Mesh):
            raise TypeError(f"mesh: expected a Mesh, got {type(mesh).__name__}")
        light = check_light(light)
        box = check_bounds("receiver_bounds", receiver_bounds)
        if not (np.isfinite(eps) and eps >= 0):
            raise ValueError(f"eps: must be a finite non-negative distance, got {eps!r}")
        dev = self.device
        t0 = time.perf_counter()
        # Local frame: the centre of the occluders, in float64. Not of the receivers too: one receiver far
        # away would move the frame and cost the occluders their float32 precision.
        union = np.stack([np.minimum(mesh.bounds[0], box[0]), np.maximum(mesh.bounds[1], box[1])])
        origin = 0.5 * (mesh.bounds[0] + mesh.bounds[1])
        scale = bounds_diagonal(union)
        vertices = (mesh.vertices.astype(np.float64) - origin).astype(np.float32)
        ntris = len(mesh.faces)
        tris_dev = dev.empty(36 * ntris, "triangles")                # (F, 3, 3) float32, gathered on the device
        dev.kernel("exact.cl", "gather_triangles")(dev.queue, (ntris,), None, dev.to_device(vertices),
                                                   dev.to_device(mesh.faces), np.int32(ntris), tris_dev)
        if isinstance(light, PointLight):
            light_vec = (light.position - origin).astype(np.float32)
        else:
            light_vec = np.asarray(light.direction, dtype=np.float32)
        t1 = time.perf_counter()
        # Views and grid
        views = lightspace.fit_views(light, box, origin, scale)
        views = lightspace.fit_to_footprint(dev, views, tris_dev, ntris)
        cells = lightspace.pick_cell_count(ntris, self.expected_receivers)
        grid = lightspace.make_grid(views, cells=cells, resolution=self.resolution)
        t2 = time.perf_counter()
        lists = self._builder.build(grid, tris_dev, ntris, self.lists_kind, self.initial_capacity)
        t3 = time.perf_counter()
        if self.test == "dot5":
            records = dev.empty(4 * DOT5_FLOATS * ntris, "dot5 triangle records")
            dev.kernel("exact.cl", "dot5_records")(dev.queue, (ntris,), None, tris_dev, np.int32(ntris), records)
        else:
            records = dev.empty(4 * WT_FLOATS * ntris, "watertight triangle records")
            options = (f"-DLIGHT_POINT={int(isinstance(light, PointLight))}",)
            dev.kernel("exact.cl", "wt_records", options)(dev.queue, (ntris,), None, tris_dev, np.int32(ntris),
                                                          *(np.float32(c) for c in light_vec), records)
        dev.queue.finish()
        t4 = time.perf_counter()

        self.mesh, self.light, self.eps, self.origin = mesh, light, float(eps), origin
        self.grid, self.lists, self._tris_dev, self._records = grid, lists, tris_dev, records
        self._light_vec = light_vec
        self._ntris = ntris
        self._prepared = True
        self.stats = dict(lists.stats)
        device_bytes = sum(b.size for b in (tris_dev, records, *lists.buffers(), lists.params) if b is not None)
        self.stats.update(
            triangles=ntris, lists=self.lists_kind, test=self.test, device_bytes=int(device_bytes),
            # entries per fine cell; linked lists do not know their coarse share, so it is counted in there
            mean_list=(lists.entries - max(lists.coarse_entries, 0)) / grid.fine_cells,
            upload_s=t1 - t0, views_s=t2 - t1, lists_s=t3 - t2, records_s=t4 - t3, prepare_s=t4 - t0,
        )

    def _options(self, normals: bool, brute: bool = False) -> tuple[str, ...]:
        return self.grid.options + (
            f"-DLIGHT_POINT={int(isinstance(self.light, PointLight))}",
            f"-DNORMALS={int(normals)}",
            f"-DTEST_DOT5={int(self.test == 'dot5')}",
            f"-DLISTS_LINKED={int(self.lists_kind == 'linked')}",
            f"-DBRUTE={int(brute)}",
            f"-DINPUT_F64={int(self._fp64)}",
            f"-DCOARSE={int(self.lists.coarse_entries != 0)}",
        )

    # classify ------------------------------------------------------------------------------------------
    def classify(self, points, normals=None) -> np.ndarray:
        """Bool (N,) mask of ``points`` ((N, 3) world positions; optional ``normals``), True = in shadow.

        Normals need not be unit length (they are normalised in float64 on the device when it has
        doubles, else on the host). Any point works, inside the prepared receiver bounds or not: outside
        the window it is looked up in the border cells, which extend to the view's domain; a point behind
        a single perspective view (only possible outside the prepared bounds) is tested against every
        triangle instead. NaN or inf coordinates and zero normals raise ``ValueError``.
        """
        if not self._prepared:
            raise RuntimeError("classify: call prepare(mesh, light, receiver_bounds, eps) first")
        t0 = time.perf_counter()
        points = _as_points("points", points)
        if normals is not None:
            normals = _as_points("normals", normals)
            if normals.shape != points.shape:
                raise ValueError(f"normals: expected shape {points.shape} to match points, got {normals.shape}")
        n = len(points)
        out = np.empty(n, dtype=np.uint8)
        for lo in range(0, n, self.chunk):
            hi = min(n, lo + self.chunk)
            out[lo:hi] = self._run(points[lo:hi], None if normals is None else normals[lo:hi])
        for code, name in ((3, "points"), (4, "normals")):
            bad = np.flatnonzero(out == code)
            if len(bad):
                what = "contains NaN or inf" if code == 3 else "has a zero-length or non-finite normal"
                raise ValueError(f"{name}: {what} (first at index {int(bad[0])})")
        fallback = np.flatnonzero(out == 2)
        if len(fallback):
            sub_normals = None if normals is None else normals[fallback]
            out[fallback] = self._run(points[fallback], sub_normals, brute=True)
        self.stats.update(classify_s=time.perf_counter() - t0, receivers=n, brute_fallback=len(fallback))
        return out.view(bool)

    def _run(self, points: np.ndarray, normals: np.ndarray | None, brute: bool = False) -> np.ndarray:
        """Codes (0 lit, 1 shadow, 2 no cell, 3 bad point, 4 bad normal) of one chunk."""
        dev = self.device
        n = len(points)
        f64 = self._fp64
        if f64:
            # world float64 in; the kernel subtracts the origin in double and rounds, as the host would
            origin = [np.float64(c) for c in self.origin]
            points_dev = _host_buffer(dev, points)
            normals_dev = _host_buffer(dev, normals) if normals is not None else points_dev
        else:
            origin = [np.float32(0)] * 3
            rel = np.subtract(points, self.origin).astype(np.float32)
            points_dev = _host_buffer(dev, rel)
            if normals is not None:
                length = np.linalg.norm(normals, axis=1, keepdims=True)
                with np.errstate(divide="ignore", invalid="ignore"):
                    unit = (normals / length).astype(np.float32)
                normals_dev = _host_buffer(dev, np.where(length > 0, unit, np.float32(0)))
            else:
                normals_dev = points_dev
        out_dev = dev.empty(n, "classify output")
        kernel = dev.kernel("exact.cl", "exact_classify", self._options(normals is not None, brute))
        lists_a, lists_b = self.lists.buffers()
        lx, ly, lz = (np.float32(c) for c in self._light_vec)
        kernel(dev.queue, (max(n, 1),), None, points_dev, normals_dev, np.int32(n), *origin, self._records,
               np.int32(self._ntris), self.lists.params, lists_a, lists_b, lx, ly, lz, np.float32(self.eps), out_dev)
        return dev.from_device(out_dev, n, np.uint8)

    # statistics ----------------------------------------------------------------------------------------
    def list_statistics(self) -> dict:
        """Longest list, empty-cell share, mean over non-empty cells (reads the lists back)."""
        offsets, _ = self.lists.to_host(self.device) if self.lists_kind == "linked" else (
            self.device.from_device(self.lists.offsets, self.grid.cells + 1, np.int32), None)
        lengths = np.diff(offsets.astype(np.int64))
        nonempty = lengths[lengths > 0]
        extra = dict(max_list=int(lengths.max(initial=0)), empty_cells=float(np.mean(lengths == 0)),
                     mean_list_nonempty=float(nonempty.mean()) if len(nonempty) else 0.0)
        self.stats.update(extra)
        return extra
