"""Shadow volumes (Fawad, Wang & Wu; Everitt & Kilgard's z-fail): the ``"shadow_volume"`` method.

**Volume.** From the light-facing faces of the occluders and their oriented silhouette edges
(:mod:`shadowcl.silhouette`, brute force or a :class:`~shadowcl.silhouette.SilhouetteTracker`): the
front cap is the light-facing faces as they are, the back cap the same faces pushed away from the
light and wound the other way, and every silhouette edge ``a -> b`` (its light-facing face on its
left) becomes the side quad ``b, a, a', b'``. Every face then winds counter-clockwise around its
outward normal and the volume is closed: its winding number is, at any point, the number of
light-facing faces the segment from the point to the light crosses (within the extrusion).

**Silhouettes.** The caps need every face's facing, which gives the number of silhouette edges for
one gather per edge; a frame whose tracked or randomized silhouette falls short (the randomized
search may miss whole loops, and the volume would be open) is redone by brute force and the shortfall
counted in ``stats["silhouettes_missed"]``: the paper's artefacts of missed loops are measured, not drawn.

**Far plane: a finite extrusion, provably past every receiver** (rather than w = 0 vertices): it
runs through the one raster kernel's triangle setup unchanged (float (x, y, z) corners), and the
camera's projection already has its far plane at infinity. For a point light every vertex goes to
``L + k (v - L)`` with one factor ``k = 2 R / d``: ``R`` is the largest distance from the light to a
corner of the receiver bounds, ``d`` a lower bound on the distance from the light to every
light-facing face (the larger of its plane's and its bounding box's distance). The back cap is the front cap scaled by ``k`` about the light, so each of its
points is at least ``k d = 2 R`` from the light, and a receiver ``p = L + s (q - L)`` shadowed by cap
point ``q`` (``s > 1``) has ``s |q - L| <= R < k |q - L|``: it lies inside the truncated volume. The
factor 2 leaves room for float32 rounding of the far corners. For a directional light along ``d``
every vertex moves by ``D d`` with ``D`` twice the depth range (along ``d``) from the nearest
light-facing vertex to the farthest receiver corner, by the same argument.

**Open meshes.** A connected component with a border edge casts shadows from both sides of its
faces (the exact method does: a segment to the light may cross only a face turned away from it). Such
a component gets a flipped copy of itself on vertices of its own (:func:`two_sided`); the border rule
of :mod:`shadowcl.silhouette` closes the volume of each copy, and the winding numbers add up to the
number of faces crossed, whichever way they face. Closed components stay one-sided (half the faces):
with the light outside a closed surface, the last face a segment crosses before the light faces the
light. **A point light inside a closed component** breaks that (the last face crossed turns away: a
light in a closed ball would cast no shadow at all), so when the light's winding number with respect
to any closed component is nonzero (:meth:`shadowcl.topology.EdgeAdjacency.enclosing_faces`), every component is made
two-sided for that frame (``stats["light_inside_closed"]``).

**Non-manifold meshes** (an edge with three or more faces: fins, duplicated triangles, overlapping
coplanar boxes) and **inconsistent winding** (an edge whose two faces run the same way along it) are
handled, not refused: every face on such an edge is detached onto vertices of its own (same
coordinates), which leaves a manifold, consistently wound mesh whose pieces around the detached faces
are open, hence two-sided as above. A two-sided piece counts every face its segment crosses, which is
the exact method's meaning for any triangle soup; the price is more volume faces where the mesh is
broken (``stats["detached_faces"]``). Never a silent wrong shadow: the tests compare those scenes with
the exact answer.

**render: the camera-view stencil** (:meth:`ShadowVolumeMethod.classify_view`). The volume faces are
drawn by ``kernels/raster.cl``'s ``raster_stencil`` against the camera's Z-buffer
(:func:`shadowcl.raster.stencil`): z-fail (default) adds +1 / -1 for back / front faces behind the
visible surface, z-pass +1 / -1 for front / back faces in front of it, starting from the eye's own
winding number (computed here in float64), so a camera inside a volume is handled. z-pass is still
wrong where the near plane cuts a volume face (the cut-off part is not counted): it is detected
conservatively (a volume face within the near rectangle's bounding sphere of the eye) and refused
with a ``ValueError`` that points to z-fail. A face at exactly the surface's depth counts as behind
the surface, so a light-facing surface, which is its own front cap, is lit. The depth test is made
against the Z-buffer moved towards the eye by the receiver's ``eps`` offset (``_moved_depths``), the
stencil's version of DESIGN.md's "start eps along the normal": without it, receivers at contacts
and near terminators, whose segment meets an occluder within eps, came out shadowed (bunny scene at
960 x 540: 530 pixels differed from the exact method, 179 with it). A covered pixel is in shadow when
its count is nonzero or its (viewer-facing) normal faces away from the light, the normal rule of
:func:`shadowcl.shadow_mask`. What remains is screen-space: the stencil decides on the pixel's ray,
the exact method at a point up to eps off it, and eps (1e-4 of the scene) is about half a pixel's
footprint at 960 x 540 on the model scenes, so pixels along shadow edges may differ (measured
3e-4 to 8e-4 of the covered pixels there, all within 0.3 pixel footprints of a silhouette).

**shadow_mask: the per-point count along the segment to the light** (:meth:`classify`). Every side
quad lies in a plane through the light, so the segment from a receiver to the light crosses none;
the back cap is beyond every receiver (above). The signed count of volume faces crossed by the
segment is therefore the number of front-cap faces it crosses, all with the same sign (each faces
the light), and the point is inside the volume exactly when the segment crosses one at all. That
is counted by the exact method's device machinery (light-space lists, watertight test, ``eps``
rules; :mod:`shadowcl.exact`) run on the front cap alone: half the triangles of a closed occluder
(all of an open one: the bench's bunny, teapot and ogre are open). Measured on those three scenes
with 1.2 M receivers each: no receiver differs from the exact method, at about its speed.
The float64 reference (``reference/shadow_volume.py``) counts instead the signed crossings of *all*
volume faces along a ray in an arbitrary direction, the volume's winding number, and the tests
check the two agree, so the closure and the orientation of the volume are tested, not assumed.

>>> method = ShadowVolumeMethod(device, silhouettes="tracking")
>>> method.prepare(mesh, light, receiver_bounds, eps)     # volume (one tracker across frames)
>>> method.classify(points, normals)                      # per-point count != 0
>>> method.classify_view(view, zbuffer, seen)             # stencil, as render() calls it
"""

from __future__ import annotations

import time
import weakref
from dataclasses import dataclass

import numpy as np

from . import raster
from .checks import check_bounds, choice, non_negative_float, optional_int
from .exact import ExactMethod
from .geometry import Mesh, bounds_diagonal
from .lightspace import box_corners
from .lights import PointLight, check_light
from .methods import Method, check_prepare
from .points import check_points
from .silhouette import (TRACKER_METHODS, Silhouette, SilhouetteTracker, edge_adjacency, face_facing,
                         silhouette_edges)
from .topology import winding_number

STENCILS = ("zfail", "zpass")
EXTRUSION_MARGIN = 2.0   # the back cap is this many times farther than the farthest receiver (see module doc)
FLOAT32_SAFE = 1e30      # far corners must stay well inside float32 range for the raster's clip space

_TWO_SIDED: "weakref.WeakKeyDictionary[Mesh, dict]" = weakref.WeakKeyDictionary()


@dataclass(frozen=True, eq=False)
class TwoSided:
    """An occluder mesh made ready for volumes: ``mesh`` holds the original faces first (those on
    non-manifold or misoriented edges re-indexed onto copies of their vertices, appended), then a
    flipped copy (faces ``(v0, v2, v1)``, on vertices of its own appended after those) of every face of
    a connected component that has a border edge (of every component with ``everywhere``).
    ``open_faces``: original face indices of those components; ``detached_faces``: original face
    indices of the detached faces."""

    mesh: Mesh
    open_faces: np.ndarray
    detached_faces: np.ndarray


def two_sided(mesh: Mesh, everywhere: bool = False) -> TwoSided:
    """``mesh`` with its faces on non-manifold or misoriented edges detached and its open components
    (all of them with ``everywhere``: a point light inside a closed one) made two-sided (see
    :class:`TwoSided` and the module doc), cached per mesh."""
    cached = _TWO_SIDED.setdefault(mesh, {}).get(everywhere)
    if cached is not None:
        prepared, *rest = cached
        return TwoSided(mesh if prepared is None else prepared, *rest)
    vertices, faces = mesh.vertices, mesh.faces
    adjacency = edge_adjacency(mesh)
    broken = np.union1d(adjacency.nonmanifold_edges, adjacency.misoriented_edges)
    starts, counts = adjacency.face_offsets[broken], np.diff(adjacency.face_offsets)[broken]
    within = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    detached = np.unique(adjacency.face_items[np.repeat(starts, counts) + within])     # the faces of those edges
    if len(detached):                  # three fresh vertices per detached face: it joins no other face
        faces = faces.copy()
        faces[detached] = len(vertices) + np.arange(3 * len(detached)).reshape(-1, 3)
        vertices = np.concatenate([vertices, mesh.vertices[mesh.faces[detached].reshape(-1)]])
        adjacency = edge_adjacency(Mesh(vertices, faces))
    # Detached, every edge has one face or two wound opposite ways: open components are those with a border
    open_faces = np.arange(len(faces)) if everywhere else np.flatnonzero(~adjacency.closed_faces)
    prepared = None                 # cached as None for a mesh used as it is: the cache must not keep its key alive
    if len(open_faces) or len(detached):
        used, local = np.unique(faces[open_faces], return_inverse=True)
        flipped = (local.reshape(-1, 3) + len(vertices))[:, [0, 2, 1]]   # v0 kept: its facing is -s exactly
        prepared = Mesh(np.concatenate([vertices, vertices[used]]), np.concatenate([faces, flipped]))
    _TWO_SIDED[mesh][everywhere] = (prepared, open_faces, detached)
    return TwoSided(mesh if prepared is None else prepared, open_faces, detached)


@dataclass(frozen=True, eq=False)
class Volume:
    """The closed shadow volume of one occluder mesh against one light.

    ``mesh``: its triangles (None when no face faces the light), vertices = the occluder's vertices
    then their extruded copies (same order), faces = front cap, back cap, side quads (two triangles
    each), counter-clockwise around outward normals. ``cap`` (C,) the light-facing faces (indices into
    the occluder mesh), ``silhouette`` (S, 2) the oriented silhouette edges, ``extrusion`` the factor
    ``k`` (point light) or distance ``D`` (directional light) of the module doc, ``reach`` how far the
    truncated volume holds every shadowed point: the distance from a point light (``k d``), the depth
    along a directional light's direction (the nearest cap vertex's plus ``D``).
    """

    mesh: Mesh | None
    cap: np.ndarray
    silhouette: np.ndarray
    extrusion: float
    reach: float = np.inf

    def reaches(self, light, points: np.ndarray) -> bool:
        """Whether every one of ``points`` ((N, 3)) lies within :attr:`reach` of ``light``."""
        if isinstance(light, PointLight):
            return bool(np.all(np.linalg.norm(points - light.position, axis=1) < self.reach))
        return bool(np.all(points @ (light.direction / np.linalg.norm(light.direction)) < self.reach))

    @property
    def cap_triangles(self) -> int:
        return len(self.cap)


def build_volume(occluders: Mesh, silhouette: Silhouette, light, receiver_bounds) -> Volume:
    """The closed volume of ``occluders`` (a manifold, consistently wound mesh, e.g. from
    :func:`two_sided`) from its ``silhouette`` against ``light``, extruded past ``receiver_bounds``
    ((2, 3) box) as the module doc proves. Raises ``ValueError`` when the light lies so close to the
    plane of a light-facing face that the far corners would leave float32's safe range."""
    light = check_light(light)
    box = check_bounds("receiver_bounds", receiver_bounds)
    cap = np.flatnonzero(silhouette.facing)
    edges = silhouette.oriented.astype(np.int64)
    if len(cap) == 0:
        return Volume(None, cap, edges, 0.0)
    vertices = occluders.vertices.astype(np.float64)
    faces = occluders.faces[cap].astype(np.int64)
    corners = box_corners(box)
    if isinstance(light, PointLight):
        position = light.position
        # Corner by corner, relative to the light: NumPy's reductions over short rows (axis=1 of (C, 3))
        # made this step ~50 ms on the bunny instead of a few.
        p0, p1, p2 = (vertices[faces[:, i]] - position for i in range(3))
        normal = np.cross(p1 - p0, p2 - p0)
        length = np.sqrt(np.einsum("ij,ij->i", normal, normal))
        with np.errstate(divide="ignore", invalid="ignore"):
            plane = np.abs(np.einsum("ij,ij->i", normal, p0) / length)
        # A lower bound on each face's distance to the light: its plane's, or its bounding box's (a face
        # lying almost edge-on has a tiny plane distance and may be far away all the same).
        outside = np.maximum(np.minimum(np.minimum(p0, p1), p2), 0) - np.minimum(np.maximum(np.maximum(p0, p1), p2), 0)
        box_distance = np.sqrt(np.einsum("ij,ij->i", outside, outside))
        nearest = float(np.min(np.maximum(np.nan_to_num(plane), box_distance)))
        farthest = float(np.max(np.linalg.norm(corners - position, axis=1)))
        k = max(EXTRUSION_MARGIN * farthest / nearest if nearest > 0 else np.inf, EXTRUSION_MARGIN)
        with np.errstate(over="ignore", invalid="ignore"):
            far = position + k * (vertices - position)
        extrusion, reach = k, k * nearest
    else:
        direction = light.direction / np.linalg.norm(light.direction)
        nearest = float(np.min(vertices[np.unique(faces)] @ direction))
        depth = float(np.max(corners @ direction)) - nearest
        extrusion = EXTRUSION_MARGIN * max(depth, bounds_diagonal(box), bounds_diagonal(occluders.bounds))
        far = vertices + extrusion * direction
        reach = nearest + extrusion
    if not (np.isfinite(extrusion) and np.all(np.abs(far) < FLOAT32_SAFE)):
        size = bounds_diagonal(occluders.bounds)
        if isinstance(light, PointLight) and nearest < 1e-6 * size:
            cause = (f"light: lies (almost) in the plane of a light-facing face ({nearest:.3g} from it, the "
                     f"occluders are {size:.3g} across)")
        else:
            cause = (f"receiver_bounds: the receivers reach {max(depth if not isinstance(light, PointLight) else farthest, 0):.3g} "
                     f"from the light, too far beyond occluders {size:.3g} across")
        raise ValueError(f"{cause}; the shadow volume's far cap cannot be placed past the receivers in float32 "
                         f"(extrusion {extrusion:.3g})")
    nv = len(vertices)
    a, b = edges[:, 0], edges[:, 1]
    volume_faces = np.concatenate([
        faces,                                               # front cap: outward towards the light
        faces[:, ::-1] + nv,                                 # back cap: outward away from it
        np.stack([b, a, a + nv], axis=1),                    # side quad b, a, a', b': outward away
        np.stack([b, a + nv, b + nv], axis=1),               # from the light-facing face, on a -> b's left
    ])
    mesh = Mesh(np.concatenate([occluders.vertices, far.astype(np.float32)]), volume_faces)
    return Volume(mesh, cap, edges, float(extrusion), float(reach))


def _missing_silhouettes(silhouette: Silhouette) -> int:
    """How many silhouette edges ``silhouette`` lacks: edges with exactly one light-facing face (a border
    edge's missing face counts as not light-facing) minus those it reports. A tracker or the randomized
    search may miss whole loops (it never reports a wrong edge), and a volume without them is open."""
    facing, faces = silhouette.facing, silhouette.adjacency.edge_faces
    second = faces[:, 1]
    lit_second = np.where(second >= 0, facing[np.maximum(second, 0)], False)
    return int(np.count_nonzero(facing[faces[:, 0]] != lit_second)) - len(silhouette.indices)


class ShadowVolumeMethod(Method):
    """Shadow volumes: closed volumes from silhouette edges, a stencil for render, a per-point count for
    shadow_mask (see the module doc). ``prepare`` only readies the occluders (LOD level, two-sided copy,
    light-inside test); the silhouette and the volume are built on the first :meth:`classify_view` of a
    frame, the point query's cap lists on the first :meth:`classify`: a caller who queries points never
    pays for a volume. One silhouette tracker is kept across :meth:`prepare` calls on the same occluder
    mesh, so ``"tracking"`` and ``"random"`` use the last frame's silhouette. After classify_view:
    ``volume`` (:class:`Volume`), ``tracked_silhouette`` (the tracker's own answer, before any brute-force
    completion: what a recall measurement wants); ``stats`` (occluder and volume sizes,
    ``silhouettes_missed``, stage times)."""

    name = "shadow_volume"
    point_light_reach = 2.0 ** 12   # measured (bench/range.py): wrong from ~3e4 sizes
    min_light_clearance = 1e-4      # measured (bench/range.py): right from 1e-5 off a surface, not at 1e-6
    image_space = True
    parameters = {
        "lod": (None, "occluder level of detail: None (full mesh), a level index of shadowcl.lod.levels, or 'auto' "
                      "(the coarsest level within max_error, measured against the exact method)"),
        "silhouettes": ("brute", "silhouette edges per frame: 'brute' (every edge on the device), 'tracking' (face "
                                 "walks from last frame's silhouette) or 'random' (Markosian's randomized search)"),
        "max_error": (0.001, "lod='auto': largest fraction of receivers whose shadow may change"),
        "receivers": (None, "lod='auto': the receivers to calibrate on (points, (points, normals) or a Points); "
                            "shadow_mask and render pass theirs; None: points on the mesh in the bounds"),
        "stencil": ("zfail", "render's stencil: 'zfail' (Everitt-Kilgard, robust to the near plane) or 'zpass' "
                             "(refused when the near plane cuts a volume face)"),
        "expected_receivers": (None, "about how many receivers classify will see, sizing its cap lists' grid "
                                     "(None: the first query's count; method='auto' queries a small sample first)"),
    }

    def __init__(self, device, **params):
        super().__init__(device, **params)
        p = self.params
        lod = p["lod"]
        if lod is not None and not (lod == "auto" if isinstance(lod, str) else
                                    isinstance(lod, (int, np.integer)) and not isinstance(lod, bool)):
            raise TypeError(f"lod: expected None, a level index (int) or 'auto', got {lod!r}")
        self.lod = lod
        self.silhouettes = choice("silhouettes", p["silhouettes"], TRACKER_METHODS)
        self.stencil = choice("stencil", p["stencil"], STENCILS)
        self.max_error = non_negative_float("max_error", p["max_error"])
        self.expected_receivers = optional_int("expected_receivers", p["expected_receivers"])
        from .auto import calibration_receivers
        self.receivers = calibration_receivers(p["receivers"])
        self._tracker: SilhouetteTracker | None = None
        self._tracked: Mesh | None = None
        self._prepared = False

    def prepare(self, mesh: Mesh, light, receiver_bounds, eps: float) -> None:
        """Ready the occluders ``mesh`` (or its LOD level) for ``light`` and receivers in ``receiver_bounds``;
        ``eps`` is the absolute offset of DESIGN.md. The volume itself waits for :meth:`classify_view`."""
        light, box = check_prepare(mesh, light, receiver_bounds, eps)
        t0 = time.perf_counter()
        if self.lod is None:
            occluders = mesh
        else:
            from . import lod as lod_module              # imported on use: fast-simplification is optional
            occluders = lod_module.resolve(self.device, mesh, light, box, eps, self.lod, self.max_error,
                                           self.receivers)
        t1 = time.perf_counter()
        prepared = two_sided(occluders)
        # the flipped copies are open components, so the prepared mesh's closed ones are the original's
        inside = isinstance(light, PointLight) and len(edge_adjacency(prepared.mesh).enclosing_faces(light.position)) > 0
        if inside:
            prepared = two_sided(occluders, everywhere=True)
        self.mesh, self.occluders, self.light, self.eps, self.bounds = mesh, prepared.mesh, light, float(eps), box
        self._volume = self._exact = None                 # built on first use (volume, classify)
        self._prepared = True
        self.stats = dict(
            occluder_triangles=len(occluders.faces), two_sided_triangles=len(prepared.mesh.faces),
            detached_faces=len(prepared.detached_faces), light_inside_closed=inside,
            lod_s=t1 - t0, prepare_s=time.perf_counter() - t0)

    def resolved_params(self) -> dict:
        """The parameters as used, ``receivers`` as their count (not the points)."""
        return {**self.params, "receivers": None if self.receivers is None else f"{len(self.receivers):,} receivers"}

    def _require_prepared(self, what: str) -> None:
        if not self._prepared:
            raise RuntimeError(f"{what}: call prepare(mesh, light, receiver_bounds, eps) first")

    @property
    def volume(self) -> Volume:
        """This frame's closed volume (:class:`Volume`), built on first use after each prepare."""
        self._require_prepared("volume")
        if self._volume is None:
            self._volume = self._build_volume()
        return self._volume

    @property
    def tracked_silhouette(self) -> Silhouette:
        """The tracker's own silhouette of this frame, before any brute-force completion."""
        self.volume                                       # the tracker runs when the volume is built
        return self._tracked_silhouette

    def _build_volume(self) -> Volume:
        """This frame's silhouette (tracked or not) and closed volume."""
        t0 = time.perf_counter()
        if self._tracked is not self.occluders:           # one tracker per occluder mesh, kept across frames
            self._tracker = SilhouetteTracker(self.device, self.occluders, method=self.silhouettes)
            self._tracked = self.occluders
        silhouette = self._tracked_silhouette = self._tracker.update(self.light)
        missed = _missing_silhouettes(silhouette)
        if missed:      # the volume would not close: a silent wrong shadow; redo the frame by brute force
            silhouette = silhouette_edges(self.device, silhouette.adjacency, self.light)
        t1 = time.perf_counter()
        volume = build_volume(self.occluders, silhouette, self.light, self.bounds)
        self.stats.update(
            cap_triangles=volume.cap_triangles, silhouette_edges=len(volume.silhouette),
            volume_triangles=0 if volume.mesh is None else len(volume.mesh.faces),
            tracker=dict(self._tracker.stats), silhouettes_missed=missed,
            silhouette_s=t1 - t0, volume_s=time.perf_counter() - t1)
        return volume

    # shadow_mask: the per-point count ------------------------------------------------------------------
    def classify(self, points, normals=None) -> np.ndarray:
        """Bool (N,): True where the segment from the point (moved ``eps`` along its normal) to the light
        crosses the front cap, i.e. the point is inside the volume, or the normal faces away.

        This is, by construction (module doc), the exact method run on the light-facing faces: equal to
        the exact answer, not an approximation of it. No silhouette or volume is built for it."""
        self._require_prepared("classify")
        t0 = time.perf_counter()
        receivers = check_points(points, normals)
        if self._exact is None:
            cap = np.flatnonzero(face_facing(self.device, self.occluders, self.light))
            self.stats["cap_triangles"] = len(cap)
            if len(cap):
                expected = self.expected_receivers or max(len(receivers), 1)
                self._exact = ExactMethod(self.device, expected_receivers=expected)
                self._exact.prepare(Mesh(self.occluders.vertices, self.occluders.faces[cap]), self.light,
                                    self.bounds, self.eps)
                self.stats.update(count_lists_s=self._exact.stats["prepare_s"],
                                  device_bytes=self._exact.stats["device_bytes"])
            else:
                self._exact = False                       # nothing faces the light: only the normal rule
        mask = self._exact.classify(receivers) if self._exact else receivers.facing_away(self.light)
        self.stats.update(classify_s=time.perf_counter() - t0)
        return mask

    # render: the camera-view stencil ---------------------------------------------------------------------
    def classify_view(self, view, zbuffer, seen) -> np.ndarray:
        """Bool mask of ``seen``'s covered pixels (row-major order): the stencil of the volume over the
        camera's ``zbuffer`` is nonzero, or the pixel's normal faces away from the light. Raises
        ``ValueError`` when a covered pixel lies beyond the volume's reach (prepared with receiver_bounds
        that miss it): the truncated volume would leave it lit whatever it should be."""
        self._require_prepared("classify_view")
        t0 = time.perf_counter()
        shadow = check_points(seen.points, seen.normals).facing_away(self.light)
        if self.volume.mesh is not None:
            if not self.volume.reaches(self.light, seen.points):
                raise ValueError("seen: pixels lie beyond the shadow volume's far cap (outside the receiver_bounds "
                                 "given to prepare, by more than the extrusion's margin); prepare with bounds "
                                 "that hold every visible receiver")
            initial = 0 if self.stencil == "zfail" else self._eye_winding(view)
            count = raster.stencil(self.device, self.volume.mesh, view, zbuffer, self.stencil == "zfail", initial,
                                   surface=self._moved_depths(view, seen, zbuffer))
            shadow |= count.ravel()[seen.pixel_index] != 0
        self.stats.update(stencil_s=time.perf_counter() - t0)
        return shadow

    def _moved_depths(self, view, seen, zbuffer) -> np.ndarray:
        """(H, W) float32: the Z-buffer's depths moved towards the eye by the receivers' ``eps`` offset.

        DESIGN.md's segment starts at ``s = p + eps n`` (``n`` the viewer-facing normal), off the pixel's
        ray; the stencil can only count along the ray, so it is evaluated at the point of the ray nearest
        to ``s``, ``p + eps (n . u) u`` (``u`` towards the eye, ``n . u > 0``): at most ``eps`` from ``s``.
        That keeps a receiver at a contact or near the terminator lit when the exact answer ignores the
        hit within eps of it. The depth change is computed in float64 and added to the rasterized depth
        (not replacing it): the surface's own front cap, drawn with the rasterized depth, stays behind.
        """
        relative = seen.points - view.origin
        # The shift eps (n . u) u is g * relative, g = eps (n . r) / (r . r) with r = relative (u = -r / |r|).
        g = self.eps * np.einsum("ij,ij->i", seen.normals, relative) / np.einsum("ij,ij->i", relative, relative)
        # Clip z and w are affine: the moved point's are p's plus g times their linear part. Column by
        # column: a (M, 3) @ (3, 2) matmul took NumPy ~0.4 s for 350 k points.
        zl, wl = (sum(relative[:, i] * row[i] for i in range(3)) for row in view.matrix[2:4])
        z, w = zl + view.matrix[2, 3], wl + view.matrix[3, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            change = np.nan_to_num((z + g * zl) / (w + g * wl) - z / w)
        surface = zbuffer.depth.copy()
        flat = surface.reshape(-1)
        flat[seen.pixel_index] = np.clip(flat[seen.pixel_index] + np.maximum(change, 0.0), 0.0, 1.0)
        return surface

    def _eye_winding(self, view) -> int:
        """z-pass's starting count: the winding number of the eye (:func:`shadowcl.topology.winding_number`).
        Raises ``ValueError`` when the near plane may cut a volume face (z-pass would miscount)."""
        eye = np.asarray(view.origin, dtype=np.float64)
        inverse = np.linalg.inv(view.matrix)
        near = np.array([[x, y, 1.0, 1.0] for x in (-1, 1) for y in (-1, 1)]) @ inverse.T
        radius = float(np.max(np.linalg.norm(near[:, :3] / near[:, 3:], axis=1)))
        vertices = self.volume.mesh.vertices.astype(np.float64) - eye
        p0, p1, p2 = (vertices[self.volume.mesh.faces[:, i]] for i in range(3))     # corner by corner (fast)
        normal = np.cross(p1 - p0, p2 - p0)
        plane = np.abs(np.einsum("ij,ij->i", normal, p0))
        near_plane = plane <= radius * np.sqrt(np.einsum("ij,ij->i", normal, normal))
        low, high = np.minimum(np.minimum(p0, p1), p2), np.maximum(np.maximum(p0, p1), p2)
        in_box = np.all((low <= radius) & (high >= -radius), axis=1)
        close = np.flatnonzero(near_plane & in_box)
        if len(close):
            raise ValueError(f"stencil='zpass': the camera's near plane may cut {len(close)} shadow-volume faces "
                             "(the eye is within the near rectangle's reach of them), so z-pass would miscount; "
                             "use stencil='zfail'")
        # Of the whole closed volume (an integer to rounding: the eye is off its faces, checked above),
        # not a count along the segment to the light, which may pass through an edge two cap faces share.
        return int(round(winding_number(self.volume.mesh.triangles, eye)))
