"""Shadow maps (Williams 1978): the light's depth map(s) from the raster kernel, then a depth test per receiver.

``prepare`` fits the light's view(s) to the receivers exactly as the exact method does
(:func:`shadowcl.lightspace.fit_views`: orthographic for a directional light, one perspective view
for a point light outside the receivers' box whose frustum stays within 120 degrees, else a cube of six
faces), cuts a single view's window to the occluders' projection (a receiver beyond it is lit:
:func:`_cut_to_occluders`), makes each window square, and draws each view's depth map with :func:`shadowcl.raster.depth_map`
(one rasterizer, two views; the maps stay on the device; with the default bias "plane" each texel also
keeps the id of the triangle the light sees there). ``classify`` runs ``kernels/shadow_map.cl``: each
receiver is transformed into light space and compared with what the map stored there.

The default bias, "plane", needs no normals. Dou, Yan, Kerzner, Dai & Wyman (adaptive depth bias,
I3D 2014 / JCGT 3(4)) observe that acne comes from comparing the receiver with a depth sampled at the
texel's centre, not at the receiver's own position: they intersect the light's ray through the texel
centre with the receiver's tangent plane (the "potential shadow caster") and bias by the depth
difference, plus an epsilon for depth precision. That needs the receiver's normal. Receiver-plane
depth bias (Isidoro 2006; Schüler 2005) moves the comparison to the receiver's exact position by
extrapolating the depth over a plane. "plane" does both with the plane the map itself holds: the
raster pass resolves a triangle id per texel, so the comparison is made against the plane of the
texel's own triangle, continued to the receiver's exact ray, in the scene's frame (plane distances
are differences of positions near the maps' origin, and the map's perspective depth runs to a finite
far plane: a point light 1e6 scene sizes away still ranks the surfaces). A receiver on the occluding
surface is then on the plane, lit at any angle: only curvature within the texel needs a bias
(:data:`PLANE_CURVATURE` texels per texel of the filter's reach, plus 0.5 texel, plus eps and float32
rounding). Because the triangle is known, the test can be exact as well: near a silhouette the
texel's triangle may not be the one above the receiver, so nearest lookup tests the receiver's ray
exactly (the watertight test of ``kernels/ray_triangle.h``) against the triangles of the 3 x 3 texels
around, which removes most edge aliasing; the plane only stands for the surface where the ray passes
beside the stored triangle (triangles smaller than a texel are not all in the map). When a texel's
triangle is met by the ray at the receiver's own position (without normals; with normals, facing the
light, at or behind it), the light sees the receiver's surface there, and the plane is not used: a
plane continued across a convex edge (a box's top over its side) would shadow the side. What was left
out: the paper's epsilon for depth precision (no depth is compared), and the normal offset with this
bias (it moved shadow edges: on a sphere on a floor, 105 against 42 wrong of 250 k with normals).
Details and the measurement against the other biases: "Defaults" below.

Cube faces: a face whose frustum the receiver bounds do not meet is not drawn by ``prepare`` (a light
above a floor skips at least its upward face). The rule that keeps ``classify`` right for any point:
before testing, it draws every face its points' bounds reach that is not drawn yet (those points lie
outside the prepared bounds), so each point is tested against the map all six faces would give. Both
decisions use :func:`reached_faces`, widened by :data:`FACE_MARGIN` so that float32 rounding in the
kernel's choice of face cannot pick a face left out.

The paper's remedies, as parameters:

- ``bias``: how far behind the stored surface a receiver may lie and still be lit, in units of the
  texel footprint ``T`` at the receiver (the widest extent of one texel across the light's ray there:
  the texel size orthographically; in perspective the texel size in tangent units times the receiver's
  distance along the view axis. Off the axis by alpha a texel is that wide across the ray sideways and
  cos(alpha) narrower radially; the former ``|d|^2 / (d . axis)`` over-estimated it by 1 / cos^2(alpha),
  up to 3x in a cube face's corner, and the larger bias meant more peter-panning; the fix cut the
  wrong receivers of five point-light scenes with nearest lookup by 9 % at 256 and 8 % at 2048, +2 % at
  4096, bench/results/shadow-map-defaults.md):
  ``"constant"`` ``T * bias_scale * (0.5 + 2 r)``; ``"slope"`` ``T * bias_scale * (0.5 + r tan(theta))``
  (theta the angle between normal and light, tan capped at 16); ``"normal"``: the receiver is first
  lifted ``T * bias_scale * r sin(theta)`` along its normal, then compared with ``T * bias_scale * 0.5``.
  ``r`` is how far (in texels) the filter's samples reach from the receiver's exact projection, where a
  lit plane's stored depth differs from the receiver's: the nearest texel's centre is up to 0.71
  texels away, bilinear interpolation reproduces a plane (0.5 covers curvature), a k x k
  percentage-closer filter reaches 0.71 k; the dither adds 0.71. Without normals, slope and normal
  offset fall back to the constant term ``0.5 T``. ``"plane"`` (default, above): a texel's triangle
  shadows the receiver when the exact test hits it, or when its plane crosses the receiver's ray more
  than ``T * bias_scale * (0.5 + PLANE_CURVATURE r)`` in front of it; normals give the facing test
  and eps start, no lift.
- ``filter``: ``"nearest"``; ``"bilinear"`` (Williams: interpolate the light's depths at the exact
  transformed X, Y, then compare); ``"pcf"`` (percentage-closer filtering of ``pcf_size`` squared texels:
  fractional visibility).
- ``dither``: Williams' noise of +-0.5 texel added to the transformed X and Y, a hash of ``seed`` and the
  receiver's index in the ``classify`` call (reproducible).

:meth:`ShadowMapMethod.visibility` gives the fractional visibility in [0, 1]; ``classify`` thresholds it:
in shadow below 0.5. A normal facing away from the light is in shadow (visibility 0).

Default bias, "plane" (bench/shadow_map_bias.py, results in bench/results/shadow-map-bias*.md; 1.2 M
receivers per scene and light, against the exact method with the same normals or none). On 16 scenes x
lights built for it (torus knot, CSG bracket, icosphere, box stack on a 40 x 40 ground; low, close,
high point lights, directional light), worst case misclassified at 512 / 2048 / 4096 with nearest:
without normals plane 1.33 / 0.23 / 0.11 % against the normal offset's 26.6 / 21.2 / 16.8 % (slope
the same, constant 11.4 / 9.2 / 7.5 %); with normals plane 0.55 / 0.067 / 0.055 %, normal offset
1.31 / 0.25 / 0.12 %, slope 0.52 / 0.13 / 0.065 %. The error falls from 512 to 4096 in all 32 cases
(scene x light x normals). Caveat: the rule for BEHIND with normals (any surface at or behind the
receiver, not only its own) was chosen on a 100 k-receiver probe of these scenes at 2048 (mean 0.021
against 0.026 %). On bench/run.py's scenes, which it was not tuned on (bunny, ogre, default,
light_inside), the mean at 2048 / 4096 is 0.052 / 0.019 % with normals (normal offset 0.082 / 0.043 %)
and 0.13 / 0.053 % without (normal offset 3.3 / 2.1 %); at 512 with normals it is worse (0.48 against
0.28 %): at a texel wider than the models' triangles the exact tests miss triangles the map does not
hold. It costs time: at 2048 the query is 2.3-3.5x the normal offset's and 2.3-3.2x the exact
method's (torus knot, bunny; 1.2 M receivers, interleaved medians): up to 9 distinct triangles tested
per receiver instead of one depth read. Pass bias="normal" with normals where speed matters more. PCF with "plane" is worse than
nearest (2048: 0.082 against 0.021 % mean with normals), as with the other biases.

Filters, measured with the former default bias "normal" (filter "nearest", 2048 texels) side by side in
one run against the exact method, 1.2 M receivers per scene (bench/results/shadow-map-defaults.md):
misclassified at 2048 with nearest / bilinear, bunny 0.072 / 0.157 %, ogre 0.098 / 0.176 %, teapot 0.020 / 0.044 %,
grazing_plane 0.022 / 0.044 %, contact 0.0036 / 0.0165 %, thin_occluder 0.0056 / 0.0123 %; nearest is
lower at 23 of the 24 scene x resolution pairs (256 to 4096; the exception, grazing_plane at 256, is
0.142 against 0.141 %), at no clear difference in time. Why: bilinear interpolation across a depth
edge (an occluder's silhouette) gives depths between occluder and floor, nearer than a receiver just
outside the shadow for most of the texel, so bilinear grows every shadow by up to a texel (its errors
are mostly false shadow); a nearest texel moves the edge by at most half a texel either way. What
nearest gives up: its errors lean to false light (light leaks) at low resolution (bunny at 256: 6163
false light against bilinear's 2538). The normal offset keeps a lit plane clean with either filter at
every elevation tested (0.5, 3 and 30 degrees: see the tests). The slope bias with nearest lookup
self-shadows a plane below about 5 degrees of elevation; pcf filtering trades false shadow for light
leaks (its bias grows with its reach).

Which form of the paper: the method transforms whatever points it is given. ``render`` gives it only
the camera-visible surface points (the paper's post-process form); the bench gives it points as
generated, visible or not (the paper's "correct" form). The test of a given point is the same in both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import lightspace, raster
from .checks import check_bounds, choice, optional_int, positive_float, positive_int
from .geometry import Mesh, bounds_diagonal
from .lights import check_light
from .methods import Method
from .points import BOUNDS_SLACK, check_points
from .views import View, window_orthographic, window_perspective

BIASES = ("constant", "slope", "normal", "plane")
FILTERS = ("nearest", "bilinear", "pcf")
DEFAULT_RESOLUTION = 2048
MAX_RESOLUTION = raster.MAX_SIDE
VIEW_FLOATS = 20            # kernels/shadow_map.cl
CONSTANT_TEXELS = 0.5       # the constant term of every bias, in texels: rounding and curvature
CONSTANT_TAN = 2.0          # tan(theta) the "constant" bias covers (~63 degrees)
PLANE_CURVATURE = 1.0       # "plane": texels the surface may curve away from a stored plane per texel of reach
NEAREST_REACH = math.sqrt(0.5)   # farthest a nearest texel's centre lies from the projection, in texels
BILINEAR_REACH = 0.5
EDGE_TEXELS = 2                  # empty texels round the occluders' projection, beyond the filter's reach
FACE_MARGIN = 1e-5          # widening of the cube-face test, relative to the coordinates' size (float32: 6e-8)
_GROUP = 64


@dataclass(frozen=True, eq=False)
class LightMaps:
    """What ``prepare`` built: the light's views and their depth maps, in the frame at ``origin``.

    ``views`` (V, VIEW_FLOATS) float32 is the kernel's view table: row-major clip matrix of positions
    relative to ``origin``, then texels' size (tangent units in perspective, scene units orthographic),
    near and far distance; ``raster_views`` the V raster views. ``depth`` holds V (R, R) reversed-Z maps
    (1 nearest, 0 empty) on the device, :class:`shadowcl.raster.DepthMap`; ``None`` for a cube face not
    drawn (yet): no receiver reached it.
    """

    kind: str                 # "orthographic" | "perspective" | "cube"
    origin: np.ndarray        # (3,) float64 world position the views are relative to
    to_light: np.ndarray      # (3,) float64: the eye (relative) for perspective, else unit direction to the light
    views: np.ndarray
    raster_views: tuple
    depth: list
    resolution: int           # texels per side of every map


class ShadowMapMethod(Method):
    """Williams' shadow map: prepare draws the light's depth map(s), classify compares receivers with them.
    ``bounded``: a single view covers the prepared receiver bounds only (:class:`shadowcl.Shadows` answers
    points beyond them from maps fitted to them); :meth:`visibility` is the filtered answer."""

    name = "shadow_map"
    point_light_reach = 2.0 ** 21   # measured (bench/range.py): right to 3e6 scene sizes, 2 of 1,500 wrong at 1e7
    min_light_clearance = 3e-4      # measured on an icosphere over a ground (12 lights 1.1e-7..1.1e-4 of the diagonal off a face): 3-4 of 12 wrong from 3.4e-7 to 3.4e-5, all right at 1.1e-4
    bounded = True
    parameters = {
        "resolution": (None, f"texels per side of each (square) depth map; None picks {DEFAULT_RESOLUTION}"),
        "bias": ("plane", "depth bias: 'plane' (the stored triangles' planes and exact tests at the receiver; "
                          "needs no normals), 'constant', 'slope' (slope-scaled) or 'normal' (normal offset)"),
        "bias_scale": (1.0, "multiplies the default bias, which is derived from the texel footprint"),
        "filter": ("nearest", "'nearest', 'bilinear' (Williams' interpolated depth) or 'pcf' (percentage closer)"),
        "pcf_size": (3, "texels per side of the percentage-closer filter (odd)"),
        "dither": (0, "1: Williams' +-0.5 texel noise on the transformed coordinates"),
        "seed": (0, "seed of the dither's hash"),
    }

    def __init__(self, device, **params):
        super().__init__(device, **params)
        p = self.params
        self.resolution = optional_int("resolution", p["resolution"], 1, MAX_RESOLUTION)
        self.bias = choice("bias", p["bias"], BIASES)
        self.bias_scale = positive_float("bias_scale", p["bias_scale"])
        self.filter = choice("filter", p["filter"], FILTERS)
        self.pcf_size = positive_int("pcf_size", p["pcf_size"], 1, 15)
        if self.pcf_size % 2 == 0:
            raise ValueError(f"pcf_size: must be odd (centred on the receiver's texel), got {self.pcf_size}")
        self.dither = choice("dither", p["dither"], (0, 1))
        self.seed = positive_int("seed", p["seed"], 0, 2**32 - 1)
        self.maps: LightMaps | None = None
        self._mesh = self._views_dev = None   # what classify needs to draw a face late; the view table
        self._receiver_bounds = None

    def resolved_params(self) -> dict:
        return {**self.params, "resolution": self.resolution or DEFAULT_RESOLUTION}

    # Prepare ------------------------------------------------------------------------------------
    def prepare(self, mesh: Mesh, light, receiver_bounds: np.ndarray, eps: float) -> None:
        """Fit the light's view(s) to ``receiver_bounds`` and draw ``mesh``'s depth map in each the receivers reach.

        ``eps`` is DESIGN.md's offset, honoured as the exact method does: a receiver with a normal
        starts ``eps`` along it, and a surface within ``eps`` of the start along the ray does not shadow
        it (on top of the bias, which covers the map's sampling).
        Raises ``ValueError`` when a map of ``resolution`` texels does not fit in one device buffer.
        """
        if not isinstance(mesh, Mesh):
            raise TypeError(f"mesh: expected a shadowcl.Mesh, got {type(mesh).__name__}")
        light = check_light(light)
        receiver_bounds = check_bounds("receiver_bounds", receiver_bounds)
        box = np.stack([np.minimum(mesh.bounds[0], receiver_bounds[0]), np.maximum(mesh.bounds[1], receiver_bounds[1])])
        # The frame is the occluders' centre: far receivers must not cost the depth maps their precision.
        origin = 0.5 * (mesh.bounds[0] + mesh.bounds[1])
        scale = max(bounds_diagonal(box), 1e-30)
        resolution = self.resolution or DEFAULT_RESOLUTION
        fitted = lightspace.fit_views(light, receiver_bounds, origin, scale)
        _check_fits(self.device, resolution)
        corners = lightspace.box_corners(box - origin)
        # the near plane floor scales with the occluders: far receivers must not clip a light's close surroundings
        near = _cube_near(mesh, fitted.eye + origin, bounds_diagonal(mesh.bounds)) if fitted.kind == "cube" else None
        occluder_corners = lightspace.box_corners(mesh.bounds - origin)
        pad = math.ceil(self.reach()) + EDGE_TEXELS
        views = [_view(fitted, k, origin, corners, near, scale, resolution, occluder_corners, pad)
                 for k in range(fitted.nviews)]
        to_light = fitted.eye if fitted.perspective else -np.asarray(light.direction, dtype=np.float64)
        records = np.stack([record for _, record in views])
        self.maps = LightMaps(fitted.kind, origin, to_light, records, tuple(view for view, _ in views),
                              [None] * fitted.nviews, resolution)
        self._mesh, self._views_dev = mesh, self.device.to_device(records)
        self._extent = float(np.abs(mesh.vertices.astype(np.float64) - origin).max(initial=0.0))
        self._receiver_bounds = receiver_bounds
        self.eps = float(eps)
        self._draw(receiver_bounds - origin)

    def _draw(self, bounds: np.ndarray) -> None:
        """Draw the depth map of every view that points in ``bounds`` (relative to the maps' origin) use
        and that is not drawn yet: all of a single view, the reached faces of a cube."""
        maps = self.maps
        faces = reached_faces(bounds, maps.to_light) if maps.kind == "cube" else [True]
        for k in np.flatnonzero(faces):
            if maps.depth[k] is None:
                maps.depth[k] = raster.depth_map(self.device, self._mesh, maps.raster_views[k],
                                                 triangles=self.bias == "plane")
        self._count_maps()

    # Classify -----------------------------------------------------------------------------------
    def visibility(self, points, normals=None) -> np.ndarray:
        """(N,) float32 in [0, 1]: the filtered fraction of the light's depth samples not occluding each point."""
        if self.maps is None:
            raise RuntimeError("shadow_map: call prepare() before classify() or visibility()")
        maps, device = self.maps, self.device
        receivers = check_points(points, normals)
        points, normals = receivers.positions, receivers.unit_normals()
        n = len(points)
        if n == 0:
            return np.zeros(0, dtype=np.float32)
        if maps.kind != "cube":
            self._check_inside(receivers.bounds)
        visibility_dev = device.empty(4 * n, "visibility")
        relative = np.ascontiguousarray(points - maps.origin, dtype=np.float32)
        if maps.kind == "cube":   # faces these points reach that prepare's bounds did not
            self._draw(receivers.bounds - maps.origin)
        normals_np = np.zeros(1, np.float32) if normals is None else np.ascontiguousarray(normals, dtype=np.float32)
        vertices_dev, faces_dev = raster.mesh_buffers(device, self._mesh, maps.origin)   # what the maps drew
        kernel = device.kernel("shadow_map.cl", "shadow_visibility", self._options(normals is not None))
        kernel(device.queue, (-(-n // _GROUP) * _GROUP,), (_GROUP,),
               device.to_device(relative), device.to_device(normals_np),
               np.array([*maps.to_light, 0.0], dtype=np.float32), self._views_dev,
               *self._map_buffers(), *self._map_buffers("triangle"), vertices_dev, faces_dev,
               np.float32(self._extent), self.bias_texels(), np.float32(self.eps), np.uint32(self.seed), np.int32(n),
               visibility_dev)
        return device.from_device(visibility_dev, n, np.float32)

    def _check_inside(self, box: np.ndarray) -> None:
        """A single view covers the prepared receiver bounds only (beyond them: behind a point light, or
        off the map's window), so points outside (whose ``box`` leaves them) are refused rather than
        answered wrongly; :class:`shadowcl.Shadows` sends such points to maps fitted to them instead."""
        low, high = self._receiver_bounds
        slack = BOUNDS_SLACK * max(bounds_diagonal(self._receiver_bounds), 1e-30)
        if np.any(box[0] < low - slack) or np.any(box[1] > high + slack):
            raise ValueError("points: outside the receiver_bounds this shadow map was prepared for; "
                             "prepare again with bounds that cover them")

    def _map_buffers(self, kind: str = "buffer") -> list:
        """The kernel's six map arguments: face k's depth map (``kind="buffer"``) or triangle ids
        (``"triangle"``; the depths stand in when the bias reads no ids), a single view's repeated; a face
        not drawn (no point of the call uses it) passes another face's buffer."""
        drawn = [depth for depth in self.maps.depth if depth is not None]
        maps = [self.maps.depth[k % len(self.maps.depth)] or drawn[0] for k in range(6)]
        return [getattr(m, kind) if getattr(m, kind) is not None else m.buffer for m in maps]

    def classify(self, points, normals=None) -> np.ndarray:
        """bool (N,): True = in shadow, where the visibility is below 0.5."""
        return self.visibility(points, normals) < 0.5

    def bias_texels(self) -> np.ndarray:
        """(constant, slope or lift) coefficients of the bias in texel footprints (see the module docstring)."""
        extra = {"constant": CONSTANT_TAN * self.reach(), "plane": PLANE_CURVATURE * self.reach()}
        constant = CONSTANT_TEXELS + extra.get(self.bias, 0.0)
        slope = 0.0 if self.bias == "plane" else self.reach()   # "plane" lifts nothing: it shifted shadow edges
        return np.array([constant, slope], dtype=np.float32) * np.float32(self.bias_scale)

    def reach(self) -> float:
        """How far, in texels, the filter's samples lie from a receiver's exact projection (sets the bias)."""
        reach = {"nearest": NEAREST_REACH, "bilinear": BILINEAR_REACH,
                 "pcf": NEAREST_REACH * self.pcf_size}[self.filter]
        return reach + NEAREST_REACH * self.dither

    def _count_maps(self) -> None:
        maps = self.maps
        drawn = sum(depth is not None for depth in maps.depth)
        layers = 2 if self.bias == "plane" else 1   # depths, and triangle ids for "plane"
        self.stats.update(kind=maps.kind, views=len(maps.depth), drawn=drawn, resolution=maps.resolution,
                          device_bytes=4 * layers * drawn * maps.resolution**2)

    def _options(self, has_normals: bool) -> tuple[str, ...]:
        maps = self.maps
        return (f"-DPERSPECTIVE={int(maps.kind != 'orthographic')}", f"-DCUBE={int(maps.kind == 'cube')}",
                f"-DRES={maps.resolution}", f"-DFILTER={FILTERS.index(self.filter)}",
                f"-DPCF_K={self.pcf_size}", f"-DBIAS={BIASES.index(self.bias)}", f"-DNORMALS={int(has_normals)}",
                f"-DDITHER={self.dither}")


# Views --------------------------------------------------------------------------------------------


def _check_fits(device, resolution: int) -> None:
    """A clear error before drawing when one map does not fit in a device buffer."""
    nbytes = 4 * resolution * resolution
    if nbytes > device.max_alloc_bytes:
        raise ValueError(f"resolution: a {resolution} x {resolution} depth map needs {nbytes / 2**20:.0f} MiB in one "
                         f"buffer but {device.name} allows {device.max_alloc_bytes / 2**20:.0f} MiB; lower it")


def _square(window: np.ndarray) -> np.ndarray:
    """The window (u0, u1, v0, v1) widened about its centre to a square (square texels in a square map)."""
    u0, u1, v0, v1 = window
    half = 0.5 * max(u1 - u0, v1 - v0)
    cu, cv = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
    return np.array([cu - half, cu + half, cv - half, cv + half])


def reached_faces(bounds: np.ndarray, eye: np.ndarray) -> np.ndarray:
    """(6,) bool: the cube faces (+x -x +y -y +z -z) a point in the box ``bounds`` ((2, 3)) may use.

    ``bounds`` and the light's ``eye`` are relative to the same origin. A point uses the face of the
    dominant axis of ``d = point - eye``, so face (a, s) is reached when ``s d_a`` can be as large as
    both other ``|d_b|``: its largest value in the box against their smallest (the coordinates are
    independent), with :data:`FACE_MARGIN` to spare.
    """
    low, high = np.asarray(bounds, dtype=np.float64) - eye
    margin = FACE_MARGIN * (np.abs(bounds).max() + np.abs(eye).max())
    nearest = np.where((low <= 0) & (high >= 0), 0.0, np.minimum(np.abs(low), np.abs(high)))
    return np.array([max(sign * low[axis], sign * high[axis]) + margin
                     >= max(nearest[(axis + 1) % 3], nearest[(axis + 2) % 3])
                     for axis, sign in lightspace.CUBE_FACES])


def _cube_near(mesh: Mesh, eye: np.ndarray, scale: float) -> float:
    """The largest near plane that clips no occluder from any cube face of a light at ``eye`` (world).

    A point at distance r from the eye lies at least r / sqrt(3) along its face's axis, and no
    triangle is nearer than both its plane and its bounding box. The near plane matters for
    precision: depth error is absolute (float32 interpolation of corner depths up to 1), so distance
    error grows as distance / near.
    """
    triangles = mesh.triangles.astype(np.float64) - eye
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    length = np.linalg.norm(normals, axis=1)
    plane = np.abs(np.einsum("ij,ij->i", normals, triangles[:, 0])) / np.where(length > 0, length, np.inf)
    outside = np.maximum(np.maximum(triangles.min(axis=1), -triangles.max(axis=1)), 0.0)
    nearest = np.maximum(plane, np.linalg.norm(outside, axis=1)).min(initial=scale)
    return max(0.99 * nearest / math.sqrt(3), 1e-6 * scale)


def _cut_to_occluders(fitted: lightspace.LightViews, k: int, occluder_corners: np.ndarray, resolution: int,
                      pad: int) -> np.ndarray:
    """Single view ``k``'s window (fitted to the receivers) cut to the projection of the occluders' box
    (``occluder_corners``, relative to the maps' origin) widened by ``pad`` texels. A receiver projecting
    beyond it is lit: its ray (segment to the eye) projects to that one point, which no occluder covers;
    the kernel clamps it to an edge texel, which the pad keeps empty. Without the cut, receivers far
    from the occluders (a second map for far receivers) spread the texels over their box and a
    scene-sized occluder falls between texel centres (redteam: receivers 3 .. 1e4 sizes downstream of
    a directional light all lost their shadow)."""
    right, up, forward = fitted.axes[k]
    if fitted.perspective:
        d = occluder_corners - fitted.eye
        w = d @ forward
        if np.any(w <= 0):
            # the box reaches behind the eye: its corners there project mirrored, and the occluders in
            # front may project anywhere in the window, so it is not cut (a room round the light)
            return fitted.windows[k]
        u, v = (d @ right) / w, (d @ up) / w
    else:
        u, v = occluder_corners @ right, occluder_corners @ up
    window = fitted.windows[k]
    occluders = np.array([u.min(), u.max(), v.min(), v.max()])
    cut = np.array([max(window[0], occluders[0]), min(window[1], occluders[1]),
                    max(window[2], occluders[2]), min(window[3], occluders[3])])
    if cut[0] > cut[1] or cut[2] > cut[3]:
        return window          # no occluder in front of the receivers: every one is lit in any window
    side = max(cut[1] - cut[0], cut[3] - cut[2], 1e-6 * max(window[1] - window[0], window[3] - window[2]))
    margin = pad * side / (resolution - 2 * pad) if resolution > 4 * pad else side
    # Only a side the occluders bound moves (padded); a side the receivers bound stays where it was.
    padded = occluders + np.array([-margin, margin, -margin, margin])
    return np.array([max(window[0], padded[0]), min(window[1], padded[1]), max(window[2], padded[2]), min(window[3], padded[3])])


def _view(fitted: lightspace.LightViews, k: int, origin: np.ndarray, corners: np.ndarray, near: float | None,
          scale: float, resolution: int, occluder_corners: np.ndarray, pad: int) -> tuple[View, np.ndarray]:
    """View ``k`` of ``fitted`` as a raster :class:`View` and the kernel's view record.

    ``corners`` (relative to ``origin``) bound every occluder and receiver: they set the depth range,
    and the near plane of a single perspective view; ``near`` is the cube's. A single view's window is
    cut to the occluders (:func:`_cut_to_occluders`).
    """
    forward = fitted.axes[k][2]
    window = fitted.windows[k] if fitted.kind == "cube" else _cut_to_occluders(fitted, k, occluder_corners, resolution, pad)
    u0, u1, v0, v1 = _square(window)
    size = u1 - u0
    if fitted.perspective:
        far_ahead = None
        if near is None:   # the box is in front of a single view: its corners bound every occluder
            t = corners @ forward
            margin = 1e-3 * max(float(t.max() - t.min()), 1e-6 * scale)
            near = max(0.99 * float((t - forward @ fitted.eye).min()), 1e-6 * scale)
            far_ahead = float(t.max()) + margin                # far + forward.eye: scene-sized
        far = math.inf if far_ahead is None else far_ahead - float(forward @ fitted.eye)
        matrix = window_perspective(fitted.axes[k], (u0, u1, v0, v1), fitted.eye, near, far_ahead)
    else:
        t = corners @ forward
        margin = 1e-3 * max(float(t.max() - t.min()), 1e-6 * scale)
        near, far = float(t.min()) - margin, float(t.max()) + margin
        matrix = window_orthographic(fitted.axes[k], (u0, u1, v0, v1), near, far)
    record = np.zeros(VIEW_FLOATS, dtype=np.float32)
    record[:16] = matrix.ravel()
    record[16:20] = size / resolution, near, min(far, np.finfo(np.float32).max), near / far if fitted.perspective else 0
    return View(origin.copy(), matrix, resolution, resolution), record
