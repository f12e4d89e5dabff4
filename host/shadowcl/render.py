"""``render``: the camera's view of a scene, shadowed by any method, shaded ambient + Lambert.

Pipeline: raster kernel (camera Z-buffer) → receivers (world position and normal per covered pixel)
→ the method's mask per light → shading. A shadowed point gets ambient light only from that light.
A method with fractional visibility (``visibility(points, normals)``, e.g. the shadow map's
percentage-closer filter) shades with it; ``post_filter`` low-passes each light's visibility over the
image, Williams' post-filter of the shadow image.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from . import raster
from .checks import non_negative_float, positive_int
from .device import get_device
from .geometry import bounds_diagonal
from .methods import create_method, default_eps, method_class, occluders, with_receiver_count
from .scene import Scene

AMBIENT = 0.18
BACKGROUND_TOP = np.array([0.60, 0.70, 0.85])
BACKGROUND_BOTTOM = np.array([0.92, 0.93, 0.95])
DEFAULT_SIZE = (960, 540)
MAX_SIDE = 16384


@dataclass
class RenderResult:
    """An image and what went into it: per-light shadow masks of the covered pixels and stage times."""

    image: np.ndarray  # (H, W, 3) uint8
    receivers: raster.Receivers  # covered pixels: mask (H, W), points, normals, triangle ids
    shadow: np.ndarray  # (L, M) bool: per light, per covered pixel in row-major order
    visibility: np.ndarray  # (L, M) float32 in [0, 1], what shading used (1 - shadow for boolean methods)
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage

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
    width = default[0] if width is None else positive_int("width", width, maximum=MAX_SIDE)
    height = default[1] if height is None else positive_int("height", height, maximum=MAX_SIDE)
    return width, height


def camera_view(scene, width: int, height: int):
    """The scene camera's view; the near plane at 1e-3 of the scene's size (reversed Z keeps depth precise)."""
    return scene.camera.view(width, height, near=1e-3 * bounds_diagonal(scene.bounds))


def render_report(scene, method: str = "exact", width=None, height=None, device=None, eps=None, progress=None,
                  post_filter: int = 0, **params) -> RenderResult:
    """Render ``scene`` and return the image with masks and stage timings (see :func:`render`).

    ``progress``, if given, is called with the name of each stage as it starts. ``post_filter``
    (pixels) box-filters each light's visibility over a (2k + 1)^2 window of covered pixels before
    shading; ``shadow`` stays the method's own mask.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene: expected a shadowcl.Scene, got {type(scene).__name__}")
    post_filter = positive_int("post_filter", post_filter, minimum=0, maximum=MAX_SIDE)
    own_renderer = getattr(method_class(method), "render_report", None)
    if own_renderer is not None:   # a method that draws its own geometry (the voxel method's leaves)
        if post_filter:
            raise ValueError(f"post_filter: method {method!r} renders its own geometry and has no post-filter")
        return own_renderer(scene, width, height, device=device, eps=eps, **params)
    device = get_device(device)
    width, height = render_size(scene, width, height)
    timings: dict[str, float] = {}
    mesh = scene.mesh
    eps = default_eps(scene.bounds) if eps is None else non_negative_float("eps", eps)
    view = camera_view(scene, width, height)
    def stage(name):
        return _timed(timings, name, progress)

    with stage("raster"):
        zbuffer = raster.rasterize(device, mesh, view)
    with stage("receivers"):
        seen = raster.receivers(device, mesh, view, zbuffer)
    shadow = np.zeros((len(scene.lights), len(seen.points)), dtype=bool)
    visibility = np.ones(shadow.shape, dtype=np.float32)
    for index, light in enumerate(scene.lights):
        shadower = create_method(method, device, **with_receiver_count(method, params, len(seen.points)))
        with stage("prepare"):
            shadower.prepare(occluders(type(shadower), scene), light, scene.bounds, eps)
        with stage("classify"):
            if hasattr(shadower, "classify_view"):
                shadow[index] = shadower.classify_view(view, zbuffer, seen)
                visibility[index] = ~shadow[index]
            elif hasattr(shadower, "visibility"):
                visibility[index] = shadower.visibility(seen.points, seen.normals)
                shadow[index] = visibility[index] < 0.5
            else:
                shadow[index] = shadower.classify(seen.points, seen.normals)
                visibility[index] = ~shadow[index]
    with stage("shading"):
        if post_filter:
            visibility = np.stack([_box_filter(seen, v, post_filter) for v in visibility])
        image = shade(scene.triangle_colors, scene.lights, view, seen, visibility)
    return RenderResult(image=image, receivers=seen, shadow=shadow, visibility=visibility, timings=timings)


def render(scene, method: str = "exact", width=None, height=None, device=None, eps=None, **params) -> np.ndarray:
    """The camera's view of ``scene`` as an (H, W, 3) uint8 image with shadows by ``method``.

    ``width`` x ``height`` default to the scene's ``[render]`` size, else 960 x 540. Every light of
    the scene contributes Lambert shading where the method says it is not shadowed; ambient light is
    everywhere. ``eps`` and ``params`` go to the method (see :func:`shadowcl.methods`).
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
