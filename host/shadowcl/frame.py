"""The working frame and the working range: every public query is computed relative to the occluders.

The kernels work in float32. A scene far from the world origin, very large or very small, or lit by a
point light many scene sizes away, would lose its precision (or overflow) if its world coordinates went
to the device as they are. :class:`Frame` moves everything a method sees (occluders, light, receivers,
bounds, eps, the camera's view) in float64 to the occluders' box centre and divides by a power of two
near their box diagonal, before any method sees it. A power of two scales exactly, so a scene scaled
by 2^k gives bit-identical masks; any uniform scale or translation gives the same masks up to the
rounding of the inputs themselves.

The working range (checked by :func:`frame_for` and :meth:`Frame.receivers`, where the public calls
enter; README "Working range"):

- coordinates: vertices and receivers finite and within float32's range (``Mesh`` and
  ``check_points``); light positions any finite float64, directions any finite non-zero vector
  (normalised without overflow, :func:`shadowcl.lights.unit_vector`);
- occluders: a bounding-box diagonal of at least :data:`MIN_EXTENT` (so float32 still holds their
  vertices as normal numbers, with room for the products the kernels form);
- receivers: within :data:`MAX_RECEIVER_DISTANCE` scene sizes of the occluders' centre (the kernels
  square and multiply such lengths in float32); farther ones are refused, naming the first;
- point lights: at any distance. Beyond :data:`DIRECTIONAL_DISTANCE` sizes of the scene (occluders
  and receivers' box) the light is used as the directional light from the scene's centre: the rays
  from two scene points to the light then differ in angle by less than size / distance < 2^-24, below
  what a float32 direction resolves (its relative rounding is 2^-24), so a point light there and
  that directional light are the same light to every float32 method. A method whose float32
  perspective arithmetic gives out sooner says so in its ``point_light_reach`` (measured; see
  :class:`shadowcl.methods.Method`): beyond it the same substitution is made, and the shadows' edges
  move by at most size / reach of the scene's size;
- point lights near the occluders: a method that needs clearance says so in its
  ``min_light_clearance`` (a fraction of the occluders' box diagonal); a light closer to a triangle is
  refused (:func:`check_clearance`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .geometry import Mesh, bounds_diagonal
from .lights import DirectionalLight, PointLight
from .points import MovedPoints, Points

MIN_EXTENT = 1e-30               # smallest occluder box diagonal accepted (float32 normals end at 1.2e-38)
MAX_RECEIVER_DISTANCE = 2.0 ** 30   # scene sizes: squares (2^60) and cubes (2^90) stay far below float32's 2^128
DIRECTIONAL_DISTANCE = 2.0 ** 24    # scene sizes: beyond it a point light's rays are parallel in float32


@dataclasses.dataclass(frozen=True)
class Frame:
    """World -> working coordinates: ``(x - centre) / scale`` in float64, ``scale`` a power of two;
    ``extent`` is the occluders' box diagonal (world units). Made by :func:`frame_for`."""

    centre: np.ndarray
    scale: float
    extent: float

    def points(self, positions: np.ndarray) -> np.ndarray:
        return (np.asarray(positions, dtype=np.float64) - self.centre) / self.scale

    def world_points(self, positions: np.ndarray) -> np.ndarray:
        """Working coordinates back to the world (float64): the inverse of :meth:`points`."""
        return np.asarray(positions, dtype=np.float64) * self.scale + self.centre

    def length(self, distance: float) -> float:
        return float(distance) / self.scale

    def mesh(self, mesh: Mesh) -> Mesh:
        return mesh.moved(self.centre, self.scale)

    def view(self, view):
        """A camera :class:`~shadowcl.views.View` in the frame: the same clip coordinates for the same points."""
        matrix = view.matrix @ np.diag([self.scale, self.scale, self.scale, 1.0])
        return dataclasses.replace(view, origin=self.points(view.origin), matrix=matrix)

    def receivers(self, receivers: Points, range_checked_later: bool = False) -> Points:
        """``receivers`` in the frame; ``ValueError`` naming the first beyond :data:`MAX_RECEIVER_DISTANCE`.
        ``range_checked_later``: the caller has every receiver beyond the occluders' near box flagged on
        the device and runs this check on them then (the box is not computed here)."""
        if len(receivers) == 0:
            return receivers
        if range_checked_later:
            return MovedPoints(receivers, self.centre, self.scale, None)
        limit = MAX_RECEIVER_DISTANCE * self.extent
        if np.abs(receivers.bounds - self.centre).max() > limit:
            far = np.abs(receivers.positions - self.centre).max(axis=1) > limit
            first = int(np.argmax(far))
            raise ValueError(
                f"points: {int(far.sum())} receiver(s) lie more than {MAX_RECEIVER_DISTANCE:.3g} scene sizes "
                f"({self.extent:.3g}) from the occluders' centre, outside the working range (first at index "
                f"{first}: {receivers.positions[first].tolist()})")
        # The box moved rather than recomputed: x -> (x - c) / 2^k is monotonic, so it maps the bounds
        # onto the moved points' bounds exactly; the points themselves are moved when first read (or on
        # the device, by a method that fuses the move into its first pass).
        return MovedPoints(receivers, self.centre, self.scale, self.points(receivers.bounds))

    def light(self, light, reach: np.ndarray, limit: float = DIRECTIONAL_DISTANCE):
        """``light`` as the methods get it, for receivers in the world box ``reach`` (which must hold the
        occluders): in the frame, or the directional light from ``reach``'s centre when it is a point
        light beyond ``limit`` sizes of ``reach`` (at most :data:`DIRECTIONAL_DISTANCE`; ``limit=np.inf``: never)."""
        if isinstance(light, PointLight):
            if is_distant(light, reach, limit):
                return DirectionalLight(0.5 * (reach[0] + reach[1]) - light.position)
            return PointLight((light.position - self.centre) / self.scale)
        return light


def check_clearance(mesh: Mesh, light, clearance: float, method: str) -> None:
    """``ValueError`` when point ``light`` lies within ``clearance`` (a fraction of ``mesh``'s box diagonal)
    of one of its triangles: ``method`` cannot answer for a light that close (float64, exact distances
    to the triangles whose boxes come that close)."""
    if clearance <= 0 or not isinstance(light, PointLight):
        return
    reach = clearance * bounds_diagonal(mesh.bounds)
    tri = mesh.triangles.astype(np.float64)
    x = light.position
    near = np.all((tri.min(axis=1) <= x + reach) & (tri.max(axis=1) >= x - reach), axis=1)
    if np.any(near) and triangle_distances(tri[near], x).min() < reach:
        raise ValueError(f"light: the point light at {x.tolist()} lies within {clearance:.0e} of the scene's size "
                         f"({reach:.3g}) of an occluding triangle, too close for the {method} method to answer; "
                         f"move it off the surface or use method='exact' or 'shadow_map'")


def triangle_distances(tri: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(T,) distances from point ``x`` to triangles ``tri`` (T, 3, 3): the plane's where ``x`` projects
    inside the triangle, else the nearest edge's."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    normal = np.cross(b - a, c - a)
    area2 = np.einsum("ij,ij->i", normal, normal)
    with np.errstate(divide="ignore", invalid="ignore"):
        height = np.einsum("ij,ij->i", x - a, normal) / np.sqrt(area2)
        inside = np.all([np.einsum("ij,ij->i", np.cross(q - p, x - p), normal) >= 0
                         for p, q in ((a, b), (b, c), (c, a))], axis=0) & (area2 > 0)

    def segment(p, q):
        d = q - p
        length2 = np.einsum("ij,ij->i", d, d)
        t = np.clip(np.einsum("ij,ij->i", x - p, d) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
        return np.linalg.norm(x - (p + t[:, None] * d), axis=1)

    edges = np.minimum(np.minimum(segment(a, b), segment(b, c)), segment(c, a))
    return np.where(inside, np.abs(height), edges)


def frame_for(mesh: Mesh, move: bool = True) -> Frame:
    """The frame of ``mesh``'s occluders; ``move=False`` keeps world coordinates (centre 0, scale 1) for
    a method that takes the caller's scene as it is, with the same range checks and distant-light rule.
    ``ValueError`` when the occluders are below :data:`MIN_EXTENT`."""
    occluders = mesh.bounds
    extent = bounds_diagonal(occluders)
    if not extent >= MIN_EXTENT:
        raise ValueError(f"scene_or_mesh: the occluders' bounding box diagonal is {extent:.3g}, below the working "
                         f"range's {MIN_EXTENT:.3g}")
    if not move:
        return Frame(np.zeros(3), 1.0, extent)
    return Frame(0.5 * (occluders[0] + occluders[1]), 2.0 ** round(math.log2(extent)), extent)


def is_distant(light, reach: np.ndarray, limit: float = DIRECTIONAL_DISTANCE) -> bool:
    """Whether ``light`` is a point light beyond ``limit`` sizes of the world box ``reach``."""
    if not isinstance(light, PointLight):
        return False
    offset = 0.5 * (reach[0] + reach[1]) - light.position
    largest = float(np.abs(offset).max())
    distance = largest * float(np.linalg.norm(offset / largest)) if largest > 0 else 0.0   # no overflow at 1e300
    return distance > (limit if math.isinf(limit) else min(limit, DIRECTIONAL_DISTANCE)) * bounds_diagonal(reach)


def union(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The (2, 3) box holding boxes ``a`` and ``b``."""
    return np.stack([np.minimum(a[0], b[0]), np.maximum(a[1], b[1])])
