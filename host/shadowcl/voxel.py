"""The "voxel" method: Lai & Cheng's shadows for Catmull-Clark subdivision surfaces (sections 3-5).

prepare: voxelize every subdivision surface of the scene into one cubic frame buffer
(host/shadowcl/voxelize.py), then decide for every *sample* (a leaf subpatch's corner, a point of the
limit surface with its normal) whether it is lit, and store the states in the frame buffer (0 empty,
1 lit, 2 shadowed: section 5.2; a voxel with lit and shadowed samples is lit). classify: a point's
state is its voxel's (when its own is empty, the nearest occupied voxel within 2 voxels, nearest by
offset; farther points are called lit and counted in ``stats["unplaced"]``, or refused with
``unplaced="raise"``), looked up on the device in the frame buffer (kernels/voxel.cl locate_states).

Determination (``determination``):

- ``"topology"`` (section 4.2): the leaves' corner quads are binned by their projection onto the
  light's view, cells of about a voxel (:func:`projection_side`), with THE light-space list module (lightspace.ListBuilder,
  4-corner primitives), each cell's list sorted nearest the light first (kernels/voxel.cl
  sort_lists); a sample is shadowed when its ray to the light hits one of the two triangles (Badouel's
  5-dot-product test, kernels/ray_triangle.h) of a listed leaf that is not *near* it: a leaf with a
  corner voxel within one voxel of the sample's voxel (its own leaf and the leaves around it, which the
  voxelization cannot tell from its own surface: the paper's "not its own or adjacent").
- ``"offset"`` (section 4.1): the projection plane keeps the nearest sample distance per cell; the
  sample A moves sqrt(2) r along its normal to A', A' is projected along the beam through A, and A is
  shadowed when A' is farther from the light than its cell's nearest sample. No bias: the paper's rule
  as written (its self-shadow error is what the bench measures).

Both call a sample whose normal faces away from the light shadowed (N . (L - A) <= 0: the paper's
"definitely in shadow", and DESIGN.md's meaning with normals). Normals are du x dv of the patches:
outward for counter-clockwise control faces (host/shadowcl/subdivision/).

Frame buffer or not (``frame_buffer``): with it (section 5.2) prepare runs everything once and
classify only reads the states, so another view of the same light costs a lookup; without it
(section 5.1, automatic when the 2-bit buffer does not fit one device buffer) prepare keeps nothing and
every classify voxelizes and determines again, which is what the paper says that mode costs.

Scenes: only subdivision surfaces are voxelized (``scene.surfaces``; the ground too must be one). A
scene with plain triangle objects is refused with a ValueError naming them (the voxel method cannot
see triangles; use the exact or shadow_map method there) rather than missing their shadows.

Measured (bench/results/voxel.md: four scenes, 100 k receivers, against exact on a finer tessellation;
2 shared cores): at 256^3 the topology rule is wrong on 0.27-0.50 % of receivers, the offset rule on
0.77-1.78 %; self-shadow error (each surface alone) topology 0.23 % / 0.37 % against offset 1.31 % /
1.31 % on the concave toroidal_tet / suzanne, a tie on the convex cube and torus; with the frame buffer
a second view of the same light classifies 6-19x faster than recomputing (section 5.1).

Shading (:meth:`VoxelMethod.visibility`, section 5): a point takes the leaf subpatch with a corner in
its voxel; with n of its four corner voxels shadowed the reflection is scaled by 1/2^n (0 for n = 4).

Section 5's own rendering (:func:`render_leaves`): instead of the scene's tessellation, the
voxelization's leaves, tessellated without cracks (voxelize.tessellate), are drawn with THE raster
kernel, and each leaf is shaded ambient + 1/2^n of its Lambert reflection (no highlight), the states
fetched from the frame buffer per corner voxel (:func:`shade_leaves`). render(scene, method="voxel")
still draws the scene's tessellation with :meth:`VoxelMethod.visibility`; measured on the torus scene
(192 x 108, 64^3) the two images' shadow masks differ only within 2 pixels of the shadow boundary.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pyopencl as cl

from . import lightspace
from . import voxelize as vz
from .checks import check_bounds, choice, flag, optional_int
from .geometry import Mesh
from .lights import PointLight, check_light
from .methods import Method
from .points import check_points

DETERMINATIONS = ("topology", "offset")
UNPLACED = ("lit", "raise")
DOT5_FLOATS = 16                 # kernels/ray_triangle.h
DEFAULT_VOXELS_ACROSS_RECEIVERS = 256   # the paper's "acceptable" resolution, across the receivers' box
MIN_RESOLUTION, MAX_AUTO_RESOLUTION = 64, 1024
SEARCH = 2                       # voxels: how far classify looks for an occupied voxel around a point
NEIGHBOURS = np.array(sorted(((a, b, c) for a in range(-SEARCH, SEARCH + 1) for b in range(-SEARCH, SEARCH + 1)
                              for c in range(-SEARCH, SEARCH + 1) if (a, b, c) != (0, 0, 0)),
                             key=lambda o: (max(map(abs, o)), sum(x * x for x in o))))   # ring 1 (26) first


def scene_patches(device, scene_or_surface):
    """The patch table of everything the method voxelizes, refusing triangle objects (see module doc);
    errors name the public calls' argument, ``scene_or_mesh``."""
    surfaces = getattr(scene_or_surface, "surfaces", None)
    if surfaces is not None and hasattr(scene_or_surface, "objects"):
        names = {name for name, _ in surfaces}
        plain = [name for name, _ in scene_or_surface.objects if name not in names]
        if plain:
            raise ValueError(f"scene_or_mesh: the voxel method only sees subdivision surfaces; objects {plain} are "
                             "triangle meshes (use method 'exact' or 'shadow_map' for them)")
        if not surfaces:
            raise ValueError("scene_or_mesh: no subdivision surfaces to voxelize")
        return vz.merge_tables([surface.patch_table(device) for _, surface in surfaces])
    if isinstance(scene_or_surface, Mesh):
        raise TypeError("scene_or_mesh: the voxel method voxelizes subdivision surfaces, got a Mesh (use method "
                        "'exact' or 'shadow_map' for triangle meshes)")
    return vz.patch_table_of(device, scene_or_surface)


# The method computes in world coordinates (float32; Badouel's 5-dot test forms products of four and
# five lengths), so only scenes of moderate size near the origin are answered. Measured on
# scenes/subdivision torus and cube scaled and moved (400 ground receivers, against the same scene at
# scale 1; bench/redteam.py): 0-1 differ from a patch box diagonal of 8e-7 to 8e9 and at offsets up to
# 3e3 diagonals; 46 of 400 at 8e-9, 354 of 400 at 8e12 (all silently).
WORLD_SIZES = (1e-6, 1e9)     # accepted patch box diagonals, world units
WORLD_OFFSET = 1e3            # accepted distance of the patch box centre from the origin, in diagonals


def check_world_range(points: np.ndarray) -> None:
    """``ValueError`` (``scene_or_mesh:``) when the patch points' box is outside the sizes and offsets
    the method answers right in world coordinates (:data:`WORLD_SIZES`, :data:`WORLD_OFFSET`)."""
    lo, hi = points.min(axis=0).astype(np.float64), points.max(axis=0).astype(np.float64)
    diagonal = float(np.linalg.norm(hi - lo))
    offset = float(np.linalg.norm(0.5 * (lo + hi)))
    if not WORLD_SIZES[0] <= diagonal <= WORLD_SIZES[1] or offset > WORLD_OFFSET * diagonal:
        raise ValueError(f"scene_or_mesh: the voxel method computes in world coordinates and answers surfaces whose "
                         f"box diagonal is {WORLD_SIZES[0]:.0e} to {WORLD_SIZES[1]:.0e} and whose centre lies within "
                         f"{WORLD_OFFSET:.0e} diagonals of the origin; these have a diagonal of {diagonal:.3g} and "
                         f"their centre {offset:.3g} from the origin: scale or move the scene (or use another method)")


def control_points(scene_or_surface) -> "np.ndarray | None":
    """The control-mesh vertices of what :func:`scene_patches` voxelizes (None for a bare patch table)."""
    surfaces = getattr(scene_or_surface, "surfaces", None)
    if surfaces and hasattr(scene_or_surface, "objects"):
        return np.vstack([surface.vertices for _, surface in surfaces])
    vertices = getattr(scene_or_surface, "vertices", None)
    return vertices if isinstance(vertices, np.ndarray) else None


class VoxelMethod(Method):
    """Lai & Cheng's voxel-based shadows (module docstring). After :meth:`prepare`, :attr:`stats` holds
    the voxelization (leaves, levels, subpatches, bytes), list entries and each stage's time in seconds
    (``lists_s``: the light-space lists for topology, the depth plane for offset); :attr:`vox` is the
    :class:`~shadowcl.voxelize.Voxelization`, :attr:`sample_states` the per-sample states (1 lit, 2
    shadowed; sample s is corner s % 4 of leaf s // 4), :attr:`grid` the projection plane and, for
    topology, :attr:`lists` its light-space lists of leaves."""

    name = "voxel"
    scene_input = True
    own_renderer = True
    eps_meaning = None   # a sample's state is its voxel's: the voxel size, not eps, sets the offset
    # Measured against exact on scenes/subdivision cube and toroidal_tet (3,000 ground receivers, light along
    # (0.3, 1, 0.2)): 2-6 differ at 1e3-1e4 scene sizes as at 10, 9-50 at 1e5-1e6 (not in bench/range.py)
    point_light_reach = 2.0 ** 14
    parameters = {
        "resolution": (None, "voxels per side of the cubic frame buffer (<= 1024); None: 256 across the "
                             "receivers' box, clamped to 64..1024"),
        "determination": ("topology", "'topology' (section 4.2: listed subpatches, dot5 ray test) or 'offset' "
                                      "(section 4.1: sqrt(2) voxel offset along the normal, nearest depth)"),
        "connectivity": (26, "N-adjacency of a leaf subpatch's corner voxels: 6, 18 or 26"),
        "frame_buffer": (None, "True: keep states in a 2-bit cubic frame buffer (section 5.2); False: "
                               "recompute per classify (5.1); None: True when it fits the device"),
        "grid_bounds": (None, "(2, 3) world box the cubic grid spans (must hold every control point); None: "
                              "the control points' box"),
        "unplaced": ("lit", "points farther than 2 voxels from every voxelized surface (no voxel state to read): "
                            "'lit' calls them lit and counts them in stats['unplaced'], 'raise' raises ValueError"),
    }

    def __init__(self, device, **params):
        super().__init__(device, **params)
        p = self.params
        self.resolution = optional_int("resolution", p["resolution"], 1, vz.MAX_RESOLUTION)
        self.determination = choice("determination", p["determination"], DETERMINATIONS)
        self.connectivity = choice("connectivity", p["connectivity"], vz.CONNECTIVITIES)
        self.frame_buffer = None if p["frame_buffer"] is None else flag("frame_buffer", p["frame_buffer"])
        self.grid_bounds = None if p["grid_bounds"] is None else check_bounds("grid_bounds", p["grid_bounds"])
        self.unplaced = choice("unplaced", p["unplaced"], UNPLACED)
        self._builder = lightspace.ListBuilder(device, corners=4)
        self._prepared = False
        self._leaf_mesh = None           # (voxelization, its leaf tessellation): made once per voxelization
        self._placeholder = self._neighbours_dev = None      # device buffers made on first use

    def resolved_params(self) -> dict:
        params = dict(self.params)
        if self._prepared:
            params.update(resolution=self.resolution_used, frame_buffer=self.frame_buffer_used)
        return params

    # prepare -------------------------------------------------------------------------------------------
    @classmethod
    def render_frame(cls, scene, view, prepared):
        """Section 5's rendering of the leaves (:func:`render_leaves`) for a :class:`shadowcl.Renderer`."""
        return render_leaves(scene, view, prepared)

    def prepare(self, scene_or_surface, light, receiver_bounds, eps: float) -> None:
        """Voxelize the subdivision surfaces of ``scene_or_surface`` (a Scene, a SubdivisionSurface or a
        patch table) and, with a frame buffer, determine every voxel's state for ``light``."""
        light = check_light(light)
        box = check_bounds("receiver_bounds", receiver_bounds)
        table = scene_patches(self.device, scene_or_surface)
        points, _, _ = vz.check_table(table)
        check_world_range(points)
        resolution = self.resolution or self._auto_resolution(points, box)
        frame_bytes = 4 * vz.frame_word_count(resolution)
        frame_buffer = self.frame_buffer if self.frame_buffer is not None else frame_bytes <= self.device.max_alloc_bytes
        self.table, self.light, self.eps = table, light, float(eps)
        self._control_points = control_points(scene_or_surface)
        self.light_vec = (np.asarray(light.position if isinstance(light, PointLight) else light.direction,
                                     dtype=np.float32))
        self.resolution_used, self.frame_buffer_used = resolution, bool(frame_buffer)
        self.stats = {}
        self._prepared = True
        self._leaf_of_voxel = None
        if frame_buffer:
            self._run()

    def _auto_resolution(self, points: np.ndarray, box: np.ndarray) -> int:
        lo, hi = (points.min(axis=0), points.max(axis=0)) if self.grid_bounds is None else self.grid_bounds
        extent = float(np.max(hi - lo))
        across = float(np.max(box[1] - box[0]))
        if across <= 0:
            return DEFAULT_VOXELS_ACROSS_RECEIVERS
        wanted = DEFAULT_VOXELS_ACROSS_RECEIVERS * extent / across
        return int(np.clip(round(wanted), MIN_RESOLUTION, MAX_AUTO_RESOLUTION))

    def _run(self) -> None:
        """Voxelize, determine every sample's state and write the voxel states (the whole of section 3-4)."""
        dev, queue = self.device, self.device.queue
        t0 = time.perf_counter()
        vox = vz.voxelize(dev, self.table, self.resolution_used, self.connectivity, frame_buffer=self.frame_buffer_used,
                          grid_bounds=self.grid_bounds, control_points=self._control_points)
        t1 = time.perf_counter()
        n = vox.nleaves
        nsamples = 4 * n
        table_dev = [dev.to_device(a) for a in (np.ascontiguousarray(self.table.points, np.float32),
                                                np.ascontiguousarray(self.table.first, np.uint32),
                                                np.ascontiguousarray(self.table.levels, np.uint32))]
        options = (f"-DLIGHT_POINT={int(isinstance(self.light, PointLight))}",)
        quads = dev.empty(48 * n, "leaf quads")
        tris = dev.empty(72 * n, "leaf triangles")
        normals = dev.empty(48 * n, "sample normals")
        keys = dev.empty(4 * n, "leaf keys")
        packed = dev.empty(16 * n, "packed corner voxels")
        lx, ly, lz = (np.float32(c) for c in self.light_vec)
        # The paper's projection plane: views over the voxel grid's box, cells of about a voxel
        lo = vox.origin
        hi = vox.origin + vox.voxel_size * vox.resolution
        views = lightspace.fit_views(self.light, np.stack([lo, hi]), np.zeros(3), float(np.linalg.norm(hi - lo)))
        grid = lightspace.make_grid(views, resolution=projection_side(views, vox))
        options = options + grid.options

        def kernel(name):
            return dev.kernel("voxel.cl", name, options)

        kernel("leaf_geometry")(queue, (max(n, 1),), None, vox.leaves_dev, np.int32(n), *table_dev, lx, ly, lz,
                                np.int32(vox.resolution), quads, tris, normals, keys, packed)
        views_dev = dev.to_device(grid.params)
        states = dev.empty(max(nsamples, 1), "sample states")
        queue.finish()
        t2 = time.perf_counter()
        stats = dict(vox.stats)
        if self.determination == "topology":
            lists = self._builder.build(grid, quads, n)
            t3 = time.perf_counter()
            kernel("sort_lists")(queue, (grid.cells,), None, lists.offsets, lists.items, np.int32(grid.cells), keys)
            dot5 = dev.empty(4 * DOT5_FLOATS * 2 * n, "leaf dot5 records")
            dev.kernel("exact.cl", "dot5_records")(queue, (max(2 * n, 1),), None, tris, np.int32(2 * n), dot5)
            queue.finish()
            t4 = time.perf_counter()
            kernel("topology_shadow")(queue, (max(nsamples, 1),), None, vox.leaves_dev, np.int32(nsamples), normals,
                                      packed, dot5, views_dev, lists.offsets, lists.items, lx, ly, lz, states)
            self.lists = lists
            stats.update(list_entries=lists.entries, cells=grid.cells, lists_s=t3 - t2, sort_s=t4 - t3,
                         list_bytes=4 * (lists.entries + grid.cells + 1), dot5_bytes=4 * DOT5_FLOATS * 2 * n)
        else:
            depth = dev.empty(4 * grid.fine_cells, "offset depth plane")
            cl.enqueue_fill_buffer(queue, depth, np.int32(0x7F7FFFFF), 0, 4 * grid.fine_cells)
            # directional light: distances along the beam can be negative; shift them positive
            corners = lightspace.box_corners(np.stack([lo, hi]))
            depth_offset = 0.0 if isinstance(self.light, PointLight) else float(-np.min(corners @ self.light_vec) + vox.voxel_size)
            kernel("offset_depth")(queue, (max(nsamples, 1),), None, vox.leaves_dev, np.int32(nsamples), views_dev,
                                   lx, ly, lz, np.float32(depth_offset), depth)
            t4 = time.perf_counter()
            kernel("offset_shadow")(queue, (max(nsamples, 1),), None, vox.leaves_dev, np.int32(nsamples), normals,
                                    views_dev, lx, ly, lz, np.float32(depth_offset),
                                    np.float32(np.sqrt(2.0) * vox.voxel_size), depth, states)
            stats.update(cells=grid.fine_cells, lists_s=t4 - t2, sort_s=0.0, list_bytes=4 * grid.fine_cells)
        sample_states = dev.from_device(states, nsamples, np.uint8)
        t5 = time.perf_counter()
        if np.any(sample_states == 3):
            raise RuntimeError(f"voxel: {int(np.sum(sample_states == 3))} samples lie behind the light's view; "
                               "this is a bug in the view fitting")
        if vox.frame_dev is not None:
            for phase in (0, 1):
                kernel("write_states")(queue, (max(nsamples, 1),), None, vox.leaves_dev, np.int32(nsamples), states,
                                       np.int32(phase), vox.frame_dev)
            self._states_dev = (vox.frame_dev, *self._placeholders()[1:], 0, ("-DSPARSE=0",))
        else:                               # section 5.1: sorted voxel ids and their states, searched
            keys, values = sparse_states(vox.corner_voxels.ravel(), sample_states)
            self._states_dev = (self._placeholders()[0], dev.to_device(keys.astype(np.uint32)),
                                dev.to_device(np.ascontiguousarray(values)), len(keys), ("-DSPARSE=1",))
        t6 = time.perf_counter()
        stats.update(determination=self.determination, samples=nsamples, shadowed_samples=int(np.sum(sample_states == 2)),
                     voxelize_s=t1 - t0, geometry_s=t2 - t1, determine_s=t5 - t4, states_s=t6 - t5,
                     prepare_s=t6 - t0, device_bytes=int(stats["frame_bytes"] + stats["leaf_bytes"] + 192 * n
                                                         + stats["list_bytes"] + stats.get("dot5_bytes", 0)))
        self.vox, self.sample_states, self._normals_dev, self.grid = vox, sample_states, normals, grid
        self.stats.update(stats)

    def leaf_mesh(self) -> vz.LeafMesh:
        """The crack-free tessellation of this voxelization's leaves (made once per voxelization)."""
        if self._leaf_mesh is None or self._leaf_mesh[0] is not self.vox:
            self._leaf_mesh = (self.vox, self.vox.tessellate())
        return self._leaf_mesh[1]

    @property
    def sample_normals(self) -> np.ndarray:
        """(S, 3) float32 unit normals of the samples (leaf corners in order), read from the device."""
        return self.device.from_device(self._normals_dev, (4 * self.vox.nleaves, 3), np.float32)

    # classify ------------------------------------------------------------------------------------------
    def _placeholders(self) -> tuple:
        """(frame, keys, values) placeholder buffers for the arguments a build of voxel.cl does not read."""
        if self._placeholder is None:
            self._placeholder = tuple(self.device.empty(4, what) for what in ("no frame buffer", "no voxel ids",
                                                                               "no voxel states"))
        return self._placeholder

    def _states_of(self, ids: np.ndarray) -> np.ndarray:
        """uint8 states (0 empty, 1 lit, 2 shadowed) of linear voxel ids (any shape), looked up on the device."""
        shape = np.shape(ids)
        ids = np.ascontiguousarray(np.ravel(ids), dtype=np.uint32)
        frame, keys, values, nkeys, options = self._states_dev
        out = self.device.empty(max(len(ids), 1), "voxel states")
        if len(ids):
            self.device.kernel("voxel.cl", "lookup_states", options)(
                self.device.queue, (len(ids),), None, self.device.to_device(ids), np.int32(len(ids)), frame, keys,
                values, np.int32(nkeys), out)
        return self.device.from_device(out, len(ids), np.uint8).reshape(shape)

    def _locate(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(linear voxel id or -1, state) per point, on the device (kernels/voxel.cl locate_states): its
        voxel, else the first occupied voxel within SEARCH voxels, nearest offsets first (points of a
        tessellation lie off the limit surface by its chord error). Voxel coordinates come from the host in
        float64, clipped to just outside the search's reach (farther is as far)."""
        vox, dev, n = self.vox, self.device, len(points)
        x = np.floor((np.asarray(points, dtype=np.float64) - vox.origin) / vox.voxel_size)
        ijk = np.clip(x, -SEARCH - 1, vox.resolution + SEARCH).astype(np.int32)
        frame, keys, values, nkeys, options = self._states_dev
        if self._neighbours_dev is None:
            self._neighbours_dev = dev.to_device(NEIGHBOURS.astype(np.int32))
        ids_g, states_g = dev.empty(4 * max(n, 1), "located voxels"), dev.empty(max(n, 1), "located states")
        if n:
            dev.kernel("voxel.cl", "locate_states", options)(
                dev.queue, (n,), None, dev.to_device(ijk), np.int32(n), np.int32(vox.resolution), self._neighbours_dev,
                np.int32(len(NEIGHBOURS)), frame, keys, values, np.int32(nkeys), ids_g, states_g)
        return dev.from_device(ids_g, n, np.int32).astype(np.int64), dev.from_device(states_g, n, np.uint8)

    def _begin_classify(self, points, normals):
        if not self._prepared:
            raise RuntimeError("voxel: classify before prepare")
        receivers = check_points(points, normals)
        points = receivers.positions
        if not self.frame_buffer_used:
            self._run()                     # section 5.1: no frame buffer, so determine again
        ids, states = self._locate(points)
        unplaced = np.flatnonzero(ids < 0)
        self.stats["unplaced"] = len(unplaced)
        if len(unplaced) and self.unplaced == "raise":
            raise ValueError(f"points: {len(unplaced)} of {len(points)} are more than {SEARCH} voxels from every "
                             f"voxelized surface (first: index {unplaced[0]}, {points[unplaced[0]].tolist()}), so the "
                             "voxel method has no state for them; unplaced='lit' calls them lit")
        return ids, states, receivers.facing_away(self.light)

    def classify(self, points, normals=None) -> np.ndarray:
        """bool (N,), True = in shadow: each point's voxel state (module docstring)."""
        t0 = time.perf_counter()
        _, states, backfacing = self._begin_classify(points, normals)
        self.stats["classify_s"] = time.perf_counter() - t0
        return (states == 2) | backfacing

    def visibility(self, points, normals=None) -> np.ndarray:
        """float32 (N,) share of the reflection: 1/2^n for n shadowed corner voxels of the leaf subpatch at
        the point's voxel, 0 when all four are (section 5); 0 for back-facing normals."""
        ids, states, backfacing = self._begin_classify(points, normals)
        if self._leaf_of_voxel is None or not self.frame_buffer_used:
            corner = self.vox.corner_voxels.ravel()
            order = np.argsort(corner, kind="stable")
            keys, first = np.unique(corner[order], return_index=True)
            self._leaf_of_voxel = (keys, order[first] // 4)
        keys, leaf_of = self._leaf_of_voxel
        at = np.clip(np.searchsorted(keys, np.maximum(ids, 0)), 0, len(keys) - 1)
        leaf = leaf_of[at]
        shadowed = np.sum(self._states_of(self.vox.corner_voxels[leaf]) == 2, axis=1)
        vis = np.where(shadowed >= 4, 0.0, 0.5 ** shadowed)
        vis = np.where(ids < 0, 1.0, vis)
        return np.where(backfacing, 0.0, vis).astype(np.float32)


def projection_side(views, vox) -> int:
    """Cells on the longer side of each light view so that a cell's footprint is about one voxel at the
    voxel grid's centre (section 4: "very close to the resolution of the voxelization"; coarser cells
    put several depth layers of a grazing surface in one cell, which the offset rule reads as shadow),
    at most 2 R (memory) and at least 16. Measured on the bench's lit ground plane under a point light
    at 64^3: R cells across the window (about 2.5 voxels per cell) made the offset rule call 8-37 % of
    the plane shadowed; voxel-sized cells 0-0.4 % (bench/results/voxel.md, Figure 1)."""
    width = float(np.max(np.maximum(views.windows[:, 1] - views.windows[:, 0], views.windows[:, 3] - views.windows[:, 2])))
    if views.perspective:
        centre = vox.origin + 0.5 * vox.voxel_size * vox.resolution
        width *= float(np.linalg.norm(centre - views.eye))
    return int(np.clip(np.ceil(width / vox.voxel_size), 16, 2 * vox.resolution))


def sparse_states(voxel_ids: np.ndarray, sample_states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(sorted unique voxel ids, state) from per-sample states, a voxel lit when any of its samples is."""
    order = np.argsort(voxel_ids, kind="stable")
    ids = voxel_ids[order]
    keys, start = np.unique(ids, return_index=True)
    values = np.minimum.reduceat(sample_states[order], start) if len(ids) else np.zeros(0, np.uint8)
    return keys, values.astype(np.uint8)


# Section 5: rendering the leaves ---------------------------------------------------------------------

@dataclass(frozen=True)
class ShadedLeaves:
    """The leaf mesh of a prepared :class:`VoxelMethod` with its shadow states (section 5.2: fetched from
    the frame buffer per corner voxel). ``leaves``: the :class:`~shadowcl.voxelize.LeafMesh`;
    ``vertex_state`` (V,) uint8: the state of each vertex's voxel (1 lit, 2 shadowed; 0 for the centre
    vertices of crack-eliminated polygons, which are no voxel's sample); ``face_visibility`` (F,) float32:
    the share of the reflection of each triangle's leaf, 1/2^n for n shadowed corner voxels, 0 for n = 4."""

    leaves: vz.LeafMesh
    vertex_state: np.ndarray
    face_visibility: np.ndarray


def leaf_visibility(corner_states: np.ndarray) -> np.ndarray:
    """float32 (n,) section 5's share of the reflection for leaves with (n, 4) corner voxel states."""
    shadowed = np.sum(np.asarray(corner_states) == 2, axis=1)
    return np.where(shadowed >= 4, 0.0, 0.5 ** shadowed).astype(np.float32)


def shade_leaves(method: "VoxelMethod", leaves: vz.LeafMesh | None = None) -> ShadedLeaves:
    """The crack-free leaf mesh of a prepared ``method`` (tessellated here unless ``leaves`` is given, e.g.
    the same voxelization under another light) with its states for the method's light."""
    if not method._prepared:
        raise RuntimeError("voxel: shade_leaves before prepare")
    if not method.frame_buffer_used:
        method._run()                       # section 5.1: determine again
    leaves = method.vox.tessellate() if leaves is None else leaves
    if not np.array_equal(leaves.leaves, method.vox.leaves):
        raise ValueError("leaves: not a tessellation of this method's voxelization")
    states = method._states_of(method.vox.corner_voxels)                  # (n, 4)
    sample = leaves.vertex_sample
    vertex_state = np.where(sample >= 0, states.ravel()[np.maximum(sample, 0)], 0).astype(np.uint8)
    return ShadedLeaves(leaves, vertex_state, leaf_visibility(states)[leaves.face_leaf])


def render_leaves(scene, view, prepared: list) -> "RenderResult":
    """Section 5's rendering of a subdivision-surface ``scene`` through ``view``: the voxelization's leaves
    tessellated without cracks (:func:`shadowcl.voxelize.tessellate`), drawn with THE raster kernel, each
    leaf shaded with ambient + 1/2^n of its Lambert reflection per light for n shadowed corner voxels (no
    highlight). ``prepared``: one prepared :class:`VoxelMethod` per light (a :class:`shadowcl.Renderer`'s:
    ``render(scene, method="voxel")`` comes here). Returns a :class:`shadowcl.render.RenderResult` whose
    ``receivers`` are the leaf mesh's pixels (``triangle`` indexes the leaf mesh) and ``shadow`` is
    visibility < 1/2."""
    from . import raster
    from .render import RenderResult, shade

    timings: dict = {}
    shaded, leaves = [], None
    t0 = time.perf_counter()
    for method in prepared:
        # the voxelization does not depend on the light: tessellate once unless it changed
        if leaves is None or not np.array_equal(method.vox.leaves, leaves.leaves):
            leaves = method.leaf_mesh()
        shaded.append(shade_leaves(method, leaves))
    t1 = time.perf_counter()
    zbuffer = raster.rasterize(method.device, leaves.mesh, view)
    seen = raster.receivers(method.device, leaves.mesh, view, zbuffer)
    t2 = time.perf_counter()
    visibility = np.stack([s.face_visibility[seen.triangle] for s in shaded]).astype(np.float32)
    # colour of each triangle: its leaf's patch -> the surface (tables are merged in scene.surfaces order)
    counts = [len(surface.patch_table(method.device).first) for _, surface in scene.surfaces]
    names = [name for name, _ in scene.objects]
    object_of_patch = np.repeat([names.index(name) for name, _ in scene.surfaces], counts)
    colors = scene.colors[object_of_patch[method.vox.patch[leaves.face_leaf]]]
    image = shade(colors, [method.light for method in prepared], view, seen, visibility)
    timings.update(tessellate=t1 - t0, raster=t2 - t1, shading=time.perf_counter() - t2)
    return RenderResult(image=image, receivers=seen, shadow=visibility < 0.5, visibility=visibility,
                        timings=timings)


