"""The rasterizer of every view: the camera's Z-buffer, the light's depth map, for any clip matrix.

``kernels/raster.cl`` states the contract; in short:

- Triangles are clipped in homogeneous space to ``0 <= depth <= 1`` and to a guard band of
  :data:`GUARD_BAND` pixels around the image centre, then their corners are snapped to fixed point
  with :data:`SUBPIXEL_BITS` fraction bits (x right, y down, from the image's top-left corner).
- A pixel is drawn by a triangle when its centre is inside by exact integer edge functions and the
  top-left fill rule: triangles sharing an edge never both draw a pixel and never both drop one.
  Both windings are drawn; zero-area (after snapping) and off-screen triangles draw nothing.
- Depth is interpolated linearly in screen space; the nearest (largest) depth wins, and equal depths
  resolve to the smallest triangle id. Empty pixels have depth 0 and triangle -1 (a fragment exactly
  on the far plane also has depth 0 but a triangle: coverage is ``triangle >= 0``).

Typical use::

    zbuffer = rasterize(device, mesh, view)
    found = receivers(device, mesh, view, zbuffer)   # world points and normals of covered pixels
    light = depth_map(device, mesh, light_view)      # depth only, left on the device (shadow maps)
    count = stencil(device, volumes, view, zbuffer)  # shadow-volume stencil over the camera's surface
"""

from __future__ import annotations

import weakref
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
import pyopencl as cl

from .device import Device
from .geometry import Mesh
from .views import View

SUBPIXEL_BITS = 8
"""Fraction bits of the fixed-point screen coordinates (1/256 pixel)."""

GUARD_BAND = 2**21
"""Pixels kept by clipping on each side of the image centre: snapped corners stay within 2^29 units
of it, so edge functions (a difference of two products of coordinate differences) fit in 64 bits."""

MAX_CORNERS = 9
"""Corners of a triangle after clipping by six planes: each plane adds at most one."""

BIG_BOX = 4096
"""Pixels in a triangle's bounding box above which the raster passes share it among work-items."""

BANDS = 64
"""Work-items sharing a big triangle, each drawing every BANDS-th row of its box."""

STENCIL_MIN_GROUPS = 64
"""The stencil's big triangles (a volume's long thin side quads, thousands of them) get _BAND_GROUP bands
each, and more only while their bands fill fewer than this many _BAND_GROUP-sized groups (balance over
cores that other jobs share). With BANDS per triangle the bunny's 16 k side quads at 960 x 540 ran 1 M
work-items, and their setup cost ~35 % of the stencil's fill (bench/stencil_profile.py); the camera
and light passes keep BANDS: their few big triangles vary widely in size and need the finer split."""

MAX_SIDE = GUARD_BAND
"""Largest width or height: the image must lie inside the guard band."""

_FILE = "raster.cl"
_OPTIONS = (f"-DSUBPIXEL_BITS={SUBPIXEL_BITS}", f"-DGUARD_BAND={GUARD_BAND}", f"-DMAX_CORNERS={MAX_CORNERS}",
            f"-DBIG_BOX={BIG_BOX}")
_GROUP = 64  # work-group size; global sizes are rounded up to it and kernels guard gid >= n
_BAND_GROUP = 8  # the stencil's bands of a big triangle come in multiples of this
# raster_pass's pass argument (kernels/raster.cl, enum pass)
_DEPTH_PASS, _TRIANGLE_PASS, _COUNT_PASS, _ZFAIL_STENCIL_PASS, _ZPASS_STENCIL_PASS = range(5)
_EMPTY = np.uint32(0xFFFFFFFF)  # no triangle; reads back as int32 -1


@dataclass(frozen=True, eq=False)
class ZBuffer:
    """What a view sees: ``depth`` (H, W) float32, 0 = empty, 1 = nearest; ``triangle`` (H, W) int32,
    the visible triangle's index in the mesh, -1 = empty."""

    depth: np.ndarray
    triangle: np.ndarray
    view: View
    mesh: Mesh = field(repr=False)
    # Kept on the device for receivers(): the same Z-buffer, not uploaded again.
    _depth_dev: cl.Buffer = field(repr=False, compare=False)
    _triangle_dev: cl.Buffer = field(repr=False, compare=False)

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool: pixels with a triangle."""
        return self.triangle >= 0


@dataclass(frozen=True, eq=False)
class DepthMap:
    """A view's nearest depths left on the device: ``buffer`` holds (H, W) float32 row-major, 0 = empty,
    1 = nearest, bit for bit what :func:`rasterize` reads back as ``ZBuffer.depth``; ``triangle``, when
    asked for, (H, W) int32 the visible triangle's index (-1 = empty), as ``ZBuffer.triangle``."""

    buffer: cl.Buffer = field(repr=False)
    view: View
    device: Device = field(repr=False)
    triangle: cl.Buffer | None = field(default=None, repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) texels."""
        return self.view.height, self.view.width

    def read(self) -> np.ndarray:
        """The depths read back to the host, (H, W) float32."""
        return self.device.from_device(self.buffer, self.shape, np.float32)


@dataclass(frozen=True, eq=False)
class Receivers:
    """The surface seen through each covered pixel, in row-major pixel order (M covered pixels)."""

    mask: np.ndarray  # (H, W) bool, pixel covered
    points: np.ndarray  # (M, 3) float64 world positions
    normals: np.ndarray  # (M, 3) float64 unit geometric normals facing the viewer
    triangle: np.ndarray  # (M,) int32 triangle index
    pixel_index: np.ndarray  # (M,) int64 flat index row * W + col


@dataclass(frozen=True, eq=False)
class ScreenPolygons:
    """The triangle setup's output: each triangle clipped and snapped, drawn as the fan (0, k, k+1).

    ``count`` (F,) int32 corners (0 = nothing drawn); ``xy`` (F, MAX_CORNERS, 2) int32 fixed-point
    screen positions (``xy / 2**SUBPIXEL_BITS`` in pixels from the top-left corner, y down);
    ``depth`` (F, MAX_CORNERS) float32. Entries past ``count`` are unspecified.
    """

    count: np.ndarray
    xy: np.ndarray
    depth: np.ndarray


@dataclass(frozen=True, eq=False)
class _Setup:
    """Device buffers of the triangle setup, ready for the raster passes."""

    count: cl.Buffer
    xy: cl.Buffer
    depth: cl.Buffer
    triangles: int
    big: cl.Buffer  # triangles with big boxes, drawn by BANDS work-items each
    big_count: int


# Public functions -------------------------------------------------------------------------------


def screen_polygons(device: Device, mesh: Mesh, view: View) -> ScreenPolygons:
    """Run only the triangle setup (clip, snap) of ``mesh`` seen by ``view`` and read it back."""
    _check(mesh, view)
    setup = _setup(device, mesh, view)
    n = setup.triangles
    return ScreenPolygons(
        device.from_device(setup.count, (n,), np.int32),
        device.from_device(setup.xy, (n, MAX_CORNERS, 2), np.int32),
        device.from_device(setup.depth, (n, MAX_CORNERS), np.float32),
    )


def rasterize(device: Device, mesh: Mesh, view: View) -> ZBuffer:
    """Draw ``mesh`` as seen by ``view``: the nearest depth and visible triangle of every pixel.

    Raises ``ValueError`` when the view's size is out of range or its buffers exceed what the
    device can allocate, ``TypeError`` for arguments of the wrong type.
    """
    _check(mesh, view)
    setup = _setup(device, mesh, view)
    depth = _depth_pass(device, setup, view)
    triangle_dev = _image(device, view, _EMPTY, "triangle buffer")
    _draw(device, _TRIANGLE_PASS, setup, view, triangle_dev, depth.buffer)
    return ZBuffer(depth.read(), device.from_device(triangle_dev, depth.shape, np.int32), view, mesh,
                   depth.buffer, triangle_dev)


def depth_map(device: Device, mesh: Mesh, view: View, triangles: bool = False) -> DepthMap:
    """The nearest depth of every pixel of ``mesh`` seen by ``view``, left on the device.

    The same triangle setup and depth pass as :func:`rasterize` (bit-identical depths) without reading
    anything back: what a light's shadow map needs. ``triangles=True`` adds :func:`rasterize`'s
    triangle-id pass (bit-identical ids, also left on the device). Raises as :func:`rasterize` does.
    """
    _check(mesh, view)
    setup = _setup(device, mesh, view)
    depth = _depth_pass(device, setup, view)
    if not triangles:
        return depth
    triangle_dev = _image(device, view, _EMPTY, "triangle buffer")
    _draw(device, _TRIANGLE_PASS, setup, view, triangle_dev, depth.buffer)
    return DepthMap(depth.buffer, view, device, triangle_dev)


def mesh_buffers(device: Device, mesh: Mesh, origin: np.ndarray) -> tuple[cl.Buffer, cl.Buffer]:
    """``mesh``'s vertices relative to ``origin`` (float32, 3 per vertex) and faces (int32, 3 per face) on
    the device: the buffers the raster passes drew from (uploaded once per mesh, device and origin)."""
    return _geometry(device, mesh, origin)


def coverage_count(device: Device, mesh: Mesh, view: View) -> np.ndarray:
    """(H, W) uint32: how many triangles of ``mesh`` draw each pixel of ``view`` (overdraw).

    A watertight surface crossed once by every pixel's ray gives exactly 1 inside its outline; a
    pixel drawn by both triangles of a shared edge, or by neither, shows up here.
    """
    _check(mesh, view)
    setup = _setup(device, mesh, view)
    count_dev = _image(device, view, 0, "count buffer")
    _draw(device, _COUNT_PASS, setup, view, count_dev)
    return device.from_device(count_dev, (view.height, view.width), np.uint32)


def stencil(device: Device, volumes: Mesh, view: View, zbuffer: ZBuffer, zfail: bool = True,
            initial: int = 0, surface: np.ndarray | None = None) -> np.ndarray:
    """(H, W) int32: the shadow-volume stencil of the closed ``volumes`` over the surface in ``zbuffer``.

    ``volumes`` are closed meshes whose faces wind counter-clockwise around their outward normals. Each
    fragment of a volume face that passes the depth test against ``zbuffer`` adds its screen winding:
    z-fail (``zfail=True``) counts the faces behind the visible surface (+1 leaving a volume, -1
    entering), z-pass those in front of it (+1 entering, -1 leaving), starting from ``initial``, the
    winding number of the eye. A face at exactly the surface's depth counts as behind it: the surface
    point is taken as lying just on the viewer's side of itself. A covered pixel ends with the winding
    number of its surface point, nonzero inside a volume. z-pass also needs the near plane to cut no
    volume face (the caller checks); z-fail needs none of that. Same setup and fill rule as
    :func:`rasterize`, so volume faces sharing an edge never both count a pixel nor both miss it.
    ``surface``, if given, is an (H, W) float32 depth image (0 = empty, 1 = nearest) the fragments are
    tested against instead of ``zbuffer.depth``, e.g. the receivers moved along their normals.
    """
    _check(volumes, view)
    if not isinstance(zbuffer, ZBuffer):
        raise TypeError(f"zbuffer: expected a ZBuffer from rasterize(), got {type(zbuffer).__name__}")
    if not _same_view(zbuffer.view, view):
        raise ValueError("zbuffer: was drawn with a different view")
    depth_dev = zbuffer._depth_dev
    if surface is not None:
        surface = np.asarray(surface)
        if surface.shape != (view.height, view.width) or surface.dtype != np.float32:
            raise ValueError(f"surface: expected a ({view.height}, {view.width}) float32 depth image, "
                             f"got {surface.shape} {surface.dtype}")
        if not np.all((surface >= 0) & (surface <= 1)):
            raise ValueError("surface: depths must lie in [0, 1]")
        depth_dev = device.to_device(np.ascontiguousarray(surface) + np.float32(0))   # + 0: no -0.0 bits
    setup = _setup(device, volumes, view)
    stencil_dev = _image(device, view, np.int32(initial).view(np.uint32), "stencil buffer")
    groups = min(-(-STENCIL_MIN_GROUPS // max(setup.big_count, 1)), BANDS // _BAND_GROUP)   # per big triangle
    _draw(device, _ZFAIL_STENCIL_PASS if zfail else _ZPASS_STENCIL_PASS, setup, view, stencil_dev, depth_dev,
          bands=groups * _BAND_GROUP)
    return device.from_device(stencil_dev, (view.height, view.width), np.int32)


def receivers(device: Device, mesh: Mesh, view: View, zbuffer: ZBuffer) -> Receivers:
    """The surface point and viewer-facing unit normal of every pixel covered in ``zbuffer``.

    A point is where the pixel centre's ray (as :meth:`View.pixel_rays`) meets the plane of the
    pixel's triangle: on the exact surface, not on the snapped, depth-interpolated one. ``zbuffer``
    must come from :func:`rasterize` with the same ``mesh`` and ``view``.
    """
    _check(mesh, view)
    if not isinstance(zbuffer, ZBuffer):
        raise TypeError(f"zbuffer: expected a ZBuffer from rasterize(), got {type(zbuffer).__name__}")
    if zbuffer.mesh is not mesh:
        raise ValueError("zbuffer: was drawn from a different mesh; its triangle ids do not index this one")
    if not _same_view(zbuffer.view, view):
        raise ValueError("zbuffer: was drawn with a different view")
    mask = zbuffer.mask
    pixel_index = np.flatnonzero(mask)
    m = len(pixel_index)
    vertices_dev, faces_dev = _geometry(device, mesh, view.origin)
    points_dev = device.empty(12 * m, "receiver points")
    normals_dev = device.empty(12 * m, "receiver normals")
    if m:
        inverse = _matrix(device, np.linalg.inv(view.matrix))
        device.kernel(_FILE, "raster_receivers", _OPTIONS)(
            device.queue, (_rounded(m),), (_GROUP,),
            device.to_device(pixel_index.astype(np.int32)), zbuffer._triangle_dev, zbuffer._depth_dev,
            vertices_dev, faces_dev, inverse, np.int32(view.width), np.int32(view.height), np.int32(m),
            points_dev, normals_dev,
        )
    points = device.from_device(points_dev, (m, 3), np.float32).astype(np.float64)
    for axis in range(3):  # per column: NumPy broadcasts a (3,) row over (M, 3) several times slower
        points[:, axis] += view.origin[axis]
    normals = device.from_device(normals_dev, (m, 3), np.float32).astype(np.float64)
    return Receivers(mask, points, normals, zbuffer.triangle.ravel()[pixel_index], pixel_index)


# Checks -----------------------------------------------------------------------------------------


def _check(mesh, view) -> None:
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected a shadowcl.Mesh, got {type(mesh).__name__}")
    if not isinstance(view, View):
        raise TypeError(f"view: expected a shadowcl.View, got {type(view).__name__}")
    for name in ("width", "height"):
        size = getattr(view, name)
        if isinstance(size, bool) or not isinstance(size, (int, np.integer)):
            raise TypeError(f"view.{name}: expected an integer, got {type(size).__name__}")
        if not 1 <= size <= MAX_SIDE:
            raise ValueError(f"view.{name}: must be between 1 and {MAX_SIDE} (the guard band), got {size}")
    if view.width * view.height >= 2**31:
        raise ValueError(f"view: {view.width} x {view.height} pixels exceed the 2^31 a 32-bit pixel index holds")
    matrix = np.asarray(view.matrix)
    if matrix.shape != (4, 4) or not np.all(np.isfinite(matrix)):
        raise ValueError("view.matrix: expected a finite 4x4 matrix")
    if not np.isfinite(np.linalg.cond(matrix)):
        raise ValueError("view.matrix: is singular; pixels cannot be unprojected")
    origin = np.asarray(view.origin)
    if origin.shape != (3,) or not np.all(np.isfinite(origin)):
        raise ValueError("view.origin: expected three finite numbers")


def _same_view(a: View, b: View) -> bool:
    same_size = (a.width, a.height) == (b.width, b.height)
    return same_size and np.array_equal(a.origin, b.origin) and np.array_equal(a.matrix, b.matrix)


# Device work ------------------------------------------------------------------------------------

@dataclass
class _Uploads:
    """One mesh on the devices: faces per device, vertices per (device, view origin), latest last."""

    faces: dict = field(default_factory=dict)
    vertices: OrderedDict = field(default_factory=OrderedDict)


# A mesh is immutable (read-only arrays), so its uploads stay valid while it lives. A few origins
# are kept per mesh: the camera's and a light or two.
_uploads: "weakref.WeakKeyDictionary[Mesh, _Uploads]" = weakref.WeakKeyDictionary()
_ORIGINS_KEPT = 4


def _geometry(device: Device, mesh: Mesh, origin: np.ndarray) -> tuple[cl.Buffer, cl.Buffer]:
    """Device buffers of ``mesh``'s vertices relative to ``origin`` (float32) and of its faces."""
    uploads = _uploads.setdefault(mesh, _Uploads())
    if device not in uploads.faces:
        uploads.faces[device] = device.to_device(mesh.faces)
    key = (device, np.asarray(origin, dtype=np.float64).tobytes())
    if key not in uploads.vertices:
        # Subtract in float64, then round: a scene far from the world origin keeps its precision.
        with np.errstate(over="ignore"):  # reported below
            relative = (mesh.vertices.astype(np.float64) - origin).astype(np.float32)
        if not np.all(np.isfinite(relative)):
            raise ValueError("mesh: vertices relative to view.origin overflow float32")
        uploads.vertices[key] = device.to_device(relative)
        if len(uploads.vertices) > _ORIGINS_KEPT:
            uploads.vertices.popitem(last=False)
    uploads.vertices.move_to_end(key)
    return uploads.vertices[key], uploads.faces[device]


def _setup(device: Device, mesh: Mesh, view: View) -> _Setup:
    n = len(mesh.faces)
    vertices_dev, faces_dev = _geometry(device, mesh, view.origin)
    count, big = (device.empty(4 * n, "clipped triangles") for _ in range(2))
    xy = device.empty(8 * MAX_CORNERS * n, "clipped triangles")
    depth = device.empty(4 * MAX_CORNERS * n, "clipped triangles")
    big_count = np.zeros(1, dtype=np.int32)
    big_count_dev = cl.Buffer(device.context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=big_count)
    device.kernel(_FILE, "raster_setup", _OPTIONS)(
        device.queue, (_rounded(n),), (_GROUP,),
        vertices_dev, faces_dev, _matrix(device, view.matrix), np.int32(view.width), np.int32(view.height),
        np.int32(n), count, xy, depth, big, big_count_dev,
    )
    cl.enqueue_copy(device.queue, big_count, big_count_dev)  # sizes the big triangles' launch
    return _Setup(count, xy, depth, n, big, int(big_count[0]))


def _depth_pass(device: Device, setup: _Setup, view: View) -> DepthMap:
    """The nearest depth of every pixel of ``view`` from the triangles of ``setup``."""
    buffer = _image(device, view, 0, "depth buffer")
    _draw(device, _DEPTH_PASS, setup, view, buffer)
    return DepthMap(buffer, view, device)


def _draw(device: Device, pass_: int, setup: _Setup, view: View, target: cl.Buffer,
          depth_bits: "cl.Buffer | None" = None, bands: int = BANDS) -> None:
    """Run raster pass ``pass_`` (one of the _*_PASS values) into ``target``, reading ``depth_bits``
    (the triangle and stencil passes): every triangle by one work-item, except big ones, shared by
    ``bands`` work-items so that they spread over the compute units. One launch of one kernel with one
    local size, so that PoCL compiles one work-group function for every pass. Which work-item draws
    a row changes nothing drawn: the passes' atomics commute."""
    work_items = setup.triangles + setup.big_count * bands
    device.kernel(_FILE, "raster_pass", _OPTIONS)(
        device.queue, (_rounded(work_items),), (_GROUP,),
        setup.big, np.int32(setup.triangles), np.int32(setup.big_count), np.int32(bands), setup.count,
        setup.xy, setup.depth, np.int32(view.width), np.int32(view.height), np.int32(pass_), target,
        target if depth_bits is None else depth_bits,
    )


def _image(device: Device, view: View, value, what: str) -> cl.Buffer:
    """A (H, W) buffer of 32-bit words, all set to ``value``."""
    nbytes = 4 * view.width * view.height
    buffer = device.empty(nbytes, f"{what} ({view.width} x {view.height})")
    cl.enqueue_fill_buffer(device.queue, buffer, np.uint32(value), 0, nbytes)
    return buffer


def _matrix(device: Device, matrix: np.ndarray) -> cl.Buffer:
    """A 4x4 matrix on the device as 16 row-major floats."""
    return device.to_device(np.asarray(matrix, dtype=np.float32))


def _rounded(n: int, group: int = _GROUP) -> int:
    """``n`` rounded up to a whole number of work-groups (at least one)."""
    return max(-(-n // group), 1) * group
