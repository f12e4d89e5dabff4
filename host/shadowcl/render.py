"""``render``: the camera's view of a scene, shadowed by any method, shaded ambient + Lambert.

Pipeline: raster kernel (camera Z-buffer) → receivers (world position and normal per covered pixel)
→ the method's mask per light → shading. A shadowed point gets ambient light only from that light.
A method with fractional visibility (``visibility(points, normals)``, e.g. the shadow map's
percentage-closer filter) shades with it; ``post_filter`` low-passes each light's visibility over the
image, Williams' post-filter of the shadow image.
"""

from __future__ import annotations

import copy
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from . import raster
from .checks import available_host_bytes, check_memory, positive_int
from .device import get_device
from .geometry import bounds_diagonal
from .lights import check_light, same_light
from .methods import method_class, resolve_eps, with_receiver_count, with_receivers
from .points import check_points
from .scene import MAX_RENDER_SIDE, Scene
from .shadows import Shadows
from .views import Camera

AMBIENT = 0.18
BACKGROUND_TOP = np.array([0.60, 0.70, 0.85])
BACKGROUND_BOTTOM = np.array([0.92, 0.93, 0.95])
DEFAULT_SIZE = (960, 540)
MAX_SIDE = MAX_RENDER_SIDE
# Peak memory a frame takes per pixel, checked before anything is allocated. Host: the peak RSS slope
# between 512^2 and 1536^2 frames of the default scene was 235-262 bytes a pixel (exact, shadow_map,
# shadow_volume, angular; PoCL's buffers included, they live in host memory) plus ~5.5 per extra light.
# Device: the raster's depth, triangle, point and normal images (32) and the method's copy of the
# receivers, counted from the buffer sizes, not measured on a GPU.
HOST_BYTES_PER_PIXEL = 300
HOST_BYTES_PER_PIXEL_PER_LIGHT = 8
DEVICE_BYTES_PER_PIXEL = 64


@dataclass
class RenderResult:
    """An image and what went into it: per-light shadow masks of the covered pixels and stage times."""

    image: np.ndarray  # (H, W, 3) uint8
    receivers: raster.Receivers  # covered pixels: mask (H, W), points, normals, triangle ids
    shadow: np.ndarray  # (L, M) bool: per light, per covered pixel in row-major order
    visibility: np.ndarray  # (L, M) float32 in [0, 1], what shading used (1 - shadow for boolean methods)
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage
    reused: dict = field(default_factory=dict)  # what a Renderer kept from its last frame (see Renderer)
    shadows: list = field(default_factory=list)  # per light, the prepared Shadows (params, stats: what "auto" chose)

    @property
    def covered(self) -> np.ndarray:
        """(H, W) bool: pixels that see the scene."""
        return self.receivers.mask


@contextmanager
def _timed(timings: dict[str, float], stage: str, progress):
    """Add the time spent in the block to ``timings[stage]``; tell ``progress`` the stage started."""
    if progress is not None:
        progress(stage)
    start = time.perf_counter()
    try:
        yield
    finally:
        timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - start


def render_size(scene, width, height) -> tuple[int, int]:
    default = getattr(scene, "render_size", None) or DEFAULT_SIZE
    width = positive_int("width", default[0] if width is None else width, maximum=MAX_SIDE)
    height = positive_int("height", default[1] if height is None else height, maximum=MAX_SIDE)
    return width, height


def check_frame_memory(width: int, height: int, lights: int, device) -> None:
    """ValueError when a ``width`` x ``height`` frame with ``lights`` lights does not fit the host's or
    the device's free memory (estimates above), before anything is allocated."""
    pixels = width * height
    what = f"a {width} x {height} frame with {lights} light(s)"
    host = pixels * (HOST_BYTES_PER_PIXEL + HOST_BYTES_PER_PIXEL_PER_LIGHT * lights)
    check_memory("width, height", what, host, available_host_bytes(), "the host")
    check_memory("width, height", what, pixels * DEVICE_BYTES_PER_PIXEL, int(device.cl_device.global_mem_size),
                 f"device {device.name}")


def camera_view(scene, width: int, height: int, camera=None):
    """The view of ``camera`` (the scene's by default); the near plane at 1e-3 of the scene's size
    (reversed Z keeps depth precise)."""
    camera = scene.camera if camera is None else camera
    return camera.view(width, height, near=1e-3 * bounds_diagonal(scene.bounds))


class Renderer:
    """Renders ``scene``'s camera view with shadows by ``method``, keeping its prepared methods between frames.

    One method instance per light slot lives as long as the renderer: :meth:`render` prepares a slot
    again only when its light changed (on the same instance, so silhouette tracking has the last frame),
    and a frame whose camera is unchanged reuses the camera's Z-buffer and receivers. So a moving light
    re-prepares and reclassifies, a moving camera only reclassifies (the voxel frame buffer, the angular
    table of an unchanged view and the exact lists are kept). ``report`` is the last frame's
    :class:`RenderResult`; its ``reused`` says what was kept: ``camera`` (bool) and ``prepared`` (one
    bool per light).

    ``width`` x ``height`` default to the scene's ``[render]`` size, else 960 x 540; ``eps`` and
    ``params`` go to the method (:func:`shadowcl.methods`); ``post_filter`` (pixels) box-filters each
    light's visibility over a (2k + 1)^2 window of covered pixels before shading (``shadow`` stays the
    method's own mask); ``progress``, if given, is called with the name of each stage as it starts.
    """

    def __init__(self, scene, method: str = "exact", width=None, height=None, device=None, eps=None,
                 post_filter: int = 0, progress=None, **params):
        if not isinstance(scene, Scene):
            raise TypeError(f"scene: expected a shadowcl.Scene, got {type(scene).__name__}")
        self.scene = scene
        self.method_class = method_class(method)
        self.method = self.method_class.name
        self.width, self.height = render_size(scene, width, height)
        self.post_filter = positive_int("post_filter", post_filter, minimum=0, maximum=MAX_SIDE)
        if self.post_filter and self.method_class.own_renderer:
            raise ValueError(f"post_filter: method {method!r} renders its own geometry and has no post-filter")
        self.eps = resolve_eps(self.method_class, eps, scene.bounds)
        self._eps_given = eps        # passed on as given: Shadows resolves it the same way (scene.bounds is the mesh's)
        self.device = get_device(device)
        check_frame_memory(self.width, self.height, len(scene.lights), self.device)
        self.method_class(self.device, **params)          # bad parameters raise here, not at the first frame
        self._params = copy.deepcopy(params)   # kept for later slots: never the caller's arrays
        self._progress = progress
        self._slots: list[Shadows] = []
        self._camera = None                               # (view, zbuffer, seen, receiver points) of the last camera
        self.report: RenderResult | None = None

    def __repr__(self) -> str:
        return f"Renderer({self.scene.name!r}, method={self.method!r}, {self.width}x{self.height})"

    def render(self, light=None, camera=None) -> np.ndarray:
        """The (H, W, 3) uint8 image under ``light`` (a light or a list of lights; None: the scene's)
        through ``camera`` (a :class:`Camera`; None: the scene's)."""
        lights = self.scene.lights if light is None else (list(light) if isinstance(light, (list, tuple)) else [light])
        if not lights:
            raise ValueError("light: expected a light or a non-empty list of lights")
        lights = [check_light(one) for one in lights]
        check_frame_memory(self.width, self.height, len(lights), self.device)
        if camera is not None and not isinstance(camera, Camera):
            raise TypeError(f"camera: expected a shadowcl.Camera or None, got {type(camera).__name__}")
        timings: dict[str, float] = {}

        def stage(name):
            return _timed(timings, name, self._progress)

        view = camera_view(self.scene, self.width, self.height, camera)
        own = self.method_class.own_renderer
        reused_camera = self._camera is not None and _same_view(self._camera[0], view)
        if not (own or reused_camera):
            with stage("raster"):
                zbuffer = raster.rasterize(self.device, self.scene.mesh, view)
            with stage("receivers"):
                seen = raster.receivers(self.device, self.scene.mesh, view, zbuffer)
                points = check_points(seen.points, seen.normals)
            self._camera = (view, zbuffer, seen, points)
        prepared = [self._prepare_slot(index, one, stage) for index, one in enumerate(lights)]
        slots = self._slots[:len(lights)]
        if own:
            result = self.method_class.render_frame(self.scene, view, [slot._instance for slot in slots])
            result.timings = {**timings, **result.timings}
        else:
            _, zbuffer, seen, points = self._camera
            shadow = np.zeros((len(lights), len(points)), dtype=bool)
            visibility = np.ones(shadow.shape, dtype=np.float32)
            for index, slot in enumerate(slots):
                with stage("classify"):
                    if self.method_class.image_space:
                        shadow[index] = slot.classify_view(view, zbuffer, seen)
                        visibility[index] = ~shadow[index]
                    else:     # binary methods give 0 or 1, so the threshold is their own mask
                        visibility[index] = slot.visibility(points)
                        shadow[index] = visibility[index] < 0.5
            with stage("shading"):
                if self.post_filter:
                    visibility = np.stack([_box_filter(seen, v, self.post_filter) for v in visibility])
                image = shade(self.scene.triangle_colors, lights, view, seen, visibility)
            result = RenderResult(image=image, receivers=seen, shadow=shadow, visibility=visibility, timings=timings)
        result.shadows = list(slots)
        result.reused = {"camera": bool(reused_camera and not own),
                         "prepared": [not fresh for fresh in prepared]}
        self.report = result
        return result.image

    def _prepare_slot(self, index: int, light, stage) -> bool:
        """Make slot ``index`` ready for ``light``; True when it had to (re)prepare."""
        if index < len(self._slots) and same_light(self._slots[index].light, light):
            return False
        with stage("prepare"):
            if index < len(self._slots):
                self._slots[index].relight(light)
            else:
                count = self.width * self.height if self._camera is None else len(self._camera[3])
                params = with_receiver_count(self.method, self._params, count)   # sized by the first frame
                if self._camera is not None:                                       # "auto" calibrates on them
                    params = with_receivers(self.method, params, self._camera[3])
                self._slots.append(Shadows(self.scene, light, self.method, self.scene.bounds, self.device, self._eps_given,
                                           **params))
        return True


def _same_view(a, b) -> bool:
    return a.width == b.width and a.height == b.height and np.array_equal(a.origin, b.origin) \
        and np.array_equal(a.matrix, b.matrix)


def render_report(scene, method: str = "exact", width=None, height=None, device=None, eps=None, progress=None,
                  post_filter: int = 0, **params) -> RenderResult:
    """One frame of a :class:`Renderer` of ``scene``: the image with masks and stage timings."""
    renderer = Renderer(scene, method, width, height, device, eps, post_filter, progress, **params)
    renderer.render()
    return renderer.report


def render(scene, method: str = "exact", width=None, height=None, device=None, eps=None, **params) -> np.ndarray:
    """The camera's view of ``scene`` as an (H, W, 3) uint8 image with shadows by ``method``: one frame
    of a :class:`Renderer` (which see for the arguments).

    Every light of the scene contributes Lambert shading where the method says it is not shadowed;
    ambient light is everywhere.
    """
    return render_report(scene, method, width, height, device, eps, **params).image


def _box_filter(seen, values: np.ndarray, k: int) -> np.ndarray:
    """Mean of ``values`` (one per covered pixel) over the covered pixels of each (2k + 1)^2 window:
    the background does not bleed into the shadow image."""
    def window_sums(image: np.ndarray) -> np.ndarray:
        padded = np.pad(image, k + 1)[:-1, :-1].cumsum(0).cumsum(1)   # summed-area table, zero row/col first
        n = 2 * k + 1
        return padded[n:, n:] - padded[:-n, n:] - padded[n:, :-n] + padded[:-n, :-n]

    image = np.zeros(seen.mask.shape)
    image.ravel()[seen.pixel_index] = values
    sums, counts = window_sums(image), window_sums(seen.mask.astype(np.float64))
    return (sums.ravel()[seen.pixel_index] / counts.ravel()[seen.pixel_index]).astype(np.float32)


def shade(triangle_colors: np.ndarray, lights, view, seen, visibility: np.ndarray) -> np.ndarray:
    """The image: each covered pixel of ``seen`` coloured ``triangle_colors[its triangle]`` (linear RGB) times
    ambient + Lambert per light scaled by ``visibility`` ((L, M), one row per light), over the background."""
    colors = triangle_colors[seen.triangle]
    light_sum = np.zeros(len(seen.points))
    for light, lit in zip(lights, visibility):
        to_light = light.direction_to_light(seen.points)
        to_light /= np.linalg.norm(to_light, axis=1, keepdims=True)
        lambert = np.clip(np.einsum("ij,ij->i", seen.normals, to_light), 0.0, None)
        light_sum += lit * lambert
    radiance = colors * (AMBIENT + (1.0 - AMBIENT) * np.clip(light_sum, 0.0, 1.0))[:, None]

    rows = np.linspace(0.0, 1.0, view.height)[:, None, None]
    image = np.broadcast_to(BACKGROUND_TOP * (1 - rows) + BACKGROUND_BOTTOM * rows, (view.height, view.width, 3)).copy()
    image.reshape(-1, 3)[seen.pixel_index] = radiance
    return to_srgb8(image)


def _srgb8_table(levels: int = 1 << 14) -> np.ndarray:
    c = np.linspace(0.0, 1.0, levels)
    srgb = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return np.round(srgb * 255).astype(np.uint8)


# Linear -> sRGB through a table: a pow per pixel cost ~0.1 s at 1280 x 720. 2^14 levels keep every
# 8-bit code within one of the exact conversion (the steepest slope, 12.92 * 255, is 0.2 code a level).
_SRGB8 = _srgb8_table()


def to_srgb8(linear: np.ndarray) -> np.ndarray:
    """Linear [0, 1] colours to 8-bit sRGB."""
    index = np.clip(np.nan_to_num(linear), 0.0, 1.0) * (len(_SRGB8) - 1) + 0.5
    return _SRGB8[index.astype(np.intp)]
