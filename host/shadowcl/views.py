"""Views: where an image is seen from. One :class:`View` serves the camera and the light's view.

Conventions (the raster kernel relies on them):

- Geometry is moved into the view's frame on the host in float64 (``relative = world - origin``)
  before it is uploaded as float32, so a scene far from the world origin keeps its precision.
- ``matrix`` (4x4) maps a relative position to clip space ``(x, y, z, w)``. ``x/w`` and ``y/w`` are in
  [-1, 1] on screen, y up. ``z/w`` is the depth in [0, 1] with **1 nearest** (reversed Z: float32
  depth is most precise far away, where perspective needs it; an infinite far plane is depth 0).
- Pixel (row, col) has its centre at screen ``((col + 0.5), (row + 0.5))`` with row 0 at the top:
  ``x_ndc = 2 (col + 0.5) / width - 1``, ``y_ndc = 1 - 2 (row + 0.5) / height``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .checks import positive_float, positive_int, vector3


def look_at_rotation(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """3x3 world-to-view rotation: rows are right, up and backward (the view looks along -z)."""
    forward = target - eye
    if not np.linalg.norm(forward) > 0:
        raise ValueError("target: must differ from the eye position")
    forward = forward / np.linalg.norm(forward)
    right = np.cross(forward, up)
    if not np.linalg.norm(right) > 1e-9:
        raise ValueError("up: must not be parallel to the viewing direction")
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    return np.stack([right, true_up, -forward])


def perspective_reversed_infinite(fov_y_degrees: float, aspect: float, near: float) -> np.ndarray:
    """Projection with depth = near / distance along the view axis (1 at ``near``, 0 at infinity)."""
    f = 1.0 / np.tan(np.radians(fov_y_degrees) / 2)
    return np.array([[f / aspect, 0, 0, 0], [0, f, 0, 0], [0, 0, 0, near], [0, 0, -1, 0]], dtype=np.float64)


def orthographic_reversed(half_width: float, half_height: float, near: float, far: float) -> np.ndarray:
    """Projection with depth 1 at ``near`` and 0 at ``far`` along the view axis (-z)."""
    axes = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]])
    return window_orthographic(axes, (-half_width, half_width, -half_height, half_height), near, far)


def window_orthographic(axes: np.ndarray, window, near: float, far: float) -> np.ndarray:
    """Orthographic projection of the ``window`` (u0, u1, v0, v1) seen along ``axes``.

    ``axes`` rows are right, up and forward; u = p.right, v = p.up and t = p.forward for a position p,
    all in scene units. Screen x = (2 u - (u0 + u1)) / (u1 - u0), likewise y; depth = (far - t) /
    (far - near), 1 at ``near`` and 0 at ``far``.
    """
    right, up, forward = axes
    u0, u1, v0, v1 = window
    matrix = np.zeros((4, 4))
    matrix[0, :3], matrix[0, 3] = 2 * right / (u1 - u0), -(u0 + u1) / (u1 - u0)
    matrix[1, :3], matrix[1, 3] = 2 * up / (v1 - v0), -(v0 + v1) / (v1 - v0)
    matrix[2, :3], matrix[2, 3] = -forward / (far - near), far / (far - near)
    matrix[3, 3] = 1.0
    return matrix


def window_perspective(axes: np.ndarray, window, eye: np.ndarray, near: float,
                       far_ahead: float | None = None) -> np.ndarray:
    """Perspective projection from ``eye`` of the ``window`` (u0, u1, v0, v1) in tangent units.

    ``axes`` rows are right, up and forward; for d = p - eye, u = d.right / d.forward, likewise v with
    up, and w = d.forward the distance along the axis. Screen x = (2 u - (u0 + u1)) / (u1 - u0), likewise
    y. Without ``far_ahead`` depth = near / w (0 at infinity). With it (``far_ahead`` = far +
    forward.eye) depth = near (far - w) / (w (far - near)), 1 at near and 0 at far, where far - w =
    far_ahead - forward.p is a difference of scene-sized numbers: a light 1e6 scene sizes away still
    ranks the scene's surfaces (near / w alone would put them all within 1e-6 of 1, a few float32 steps).
    """
    right, up, forward = axes
    u0, u1, v0, v1 = window
    matrix = np.zeros((4, 4))
    matrix[0, :3] = (2 * right - (u0 + u1) * forward) / (u1 - u0)
    matrix[1, :3] = (2 * up - (v0 + v1) * forward) / (v1 - v0)
    matrix[3, :3] = forward
    matrix[:, 3] = -matrix[:, :3] @ eye
    if far_ahead is None:
        matrix[2, 3] = near
    else:
        k = near / (far_ahead - float(forward @ eye) - near)
        matrix[2, :3], matrix[2, 3] = -k * forward, k * far_ahead
    return matrix


@dataclass(frozen=True)
class View:
    """An image of ``width`` x ``height`` pixels seen through ``matrix`` from ``origin`` (see module doc)."""

    origin: np.ndarray  # (3,) float64, world position the geometry is made relative to
    matrix: np.ndarray  # (4, 4) float64, relative position -> clip space
    width: int
    height: int

    def pixel_ndc(self) -> tuple[np.ndarray, np.ndarray]:
        """(H, W) x and y of every pixel centre in normalised device coordinates."""
        cols = (np.arange(self.width) + 0.5) * (2.0 / self.width) - 1.0
        rows = 1.0 - (np.arange(self.height) + 0.5) * (2.0 / self.height)
        return np.meshgrid(cols, rows)

    def pixel_rays(self) -> tuple[np.ndarray, np.ndarray]:
        """(H, W, 3) start and unit direction of each pixel's ray, relative to ``origin``.

        Found by unprojecting each pixel centre at depths 1 (near) and 0.5, so it holds for any matrix.
        """
        x, y = self.pixel_ndc()
        inverse = np.linalg.inv(self.matrix)

        def unproject(depth: float) -> np.ndarray:
            clip = np.stack([x, y, np.full_like(x, depth), np.ones_like(x)], axis=-1)
            p = clip @ inverse.T
            return p[..., :3] / p[..., 3:]

        start, further = unproject(1.0), unproject(0.5)
        direction = further - start
        return start, direction / np.linalg.norm(direction, axis=-1, keepdims=True)


class Camera:
    """A look-at pinhole camera: ``position``, ``target``, ``up`` and vertical field of view in degrees."""

    def __init__(self, position, target, up=(0.0, 1.0, 0.0), fov=45.0):
        self.position = vector3("position", position)
        self.target = vector3("target", target)
        self.up = vector3("up", up, nonzero=True)
        self.fov = positive_float("fov", fov)
        if not self.fov < 180:
            raise ValueError(f"fov: must be below 180 degrees, got {fov}")
        self.rotation = look_at_rotation(self.position, self.target, self.up)

    def __repr__(self) -> str:
        return f"Camera(position={self.position.tolist()}, target={self.target.tolist()}, fov={self.fov})"

    def view(self, width: int, height: int, near: float) -> View:
        """The camera's view at ``width`` x ``height`` pixels with near plane ``near`` (scene units)."""
        width, height = positive_int("width", width), positive_int("height", height)
        projection = perspective_reversed_infinite(self.fov, width / height, positive_float("near", near))
        matrix = np.eye(4)
        matrix[:3, :3] = self.rotation
        return View(self.position.copy(), projection @ matrix, width, height)
