"""The angular frame (section 3, eq. 2; see the package docstring): the light at the origin, rows as
half-planes round the pole axis X (parallel planes for a directional light), the pole kept clear of the
occluders, and the rows a receiver set needs (eq. 4)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..lights import PointLight
from ..lightspace import orthonormal_basis

MIN_ROWS, MAX_ROWS = 16, 1 << 16
DEFAULT_ROWS = 600             # the paper's highest resolution, when nothing says how dense receivers are
POLE_CLEARANCE = np.radians(5.0)   # a preferred pole axis is kept when this far from every occluder direction (a face
                                   # round the pole only spans every row; receivers near it stay exact)
ANGLE_PAD = 1e-5               # a face is listed in the rows its theta range meets widened by this times the
                               # occluders' theta size (at most 1 radian) and r / rho (a corner's distance from the light
                               # over that from the pole axis): a receiver's float32 theta rounds by ~1e-7 of its size
                               # times r / rho (atan2 a few ulp): 10-100 x margin
S_PAD = 1e-5                   # spans widened by this times the occluders' s size (point light: a receiver's float32
                               # s = x / |p| is ~1e-7 of it off)
LENGTH_PAD = 1e-5              # directional light: rows and spans (lengths) widened by this times the occluders'
                               # extent from the frame's origin (float32 coordinates round by ~6e-8 of it)
PIECES = 16                    # a face's span is cut in pieces of at most 1 / PIECES of the s range (point: 2;
                               # directional: twice the occluders' extent), so a ground's row-wide span cannot
                               # keep lookups from ending early (kernels/angular.cl face_rows); not more: a
                               # scan-line run ends at every piece's end (64: the runs' lookups went up 30 %)



@dataclass(frozen=True)
class Frame:
    """World -> angular frame: ``local = rotation @ (world - origin)``; the light at the origin for a
    point light; rows over ``[t0, t0 + rows * dt)``; ``full_circle`` rows wrap round. ``centre`` (world)
    is the occluders' box centre: the kernels hold receivers and face planes relative to it
    (:attr:`anchor`), so that a distant point light costs the depth test no precision. ``pad_t`` and
    ``pad_s`` widen a face's row range and spans against float32 rounding (:data:`ANGLE_PAD` and
    :data:`S_PAD` times the occluders' angular size for a point light; :data:`LENGTH_PAD` times their
    extent for a directional light);
    ``piece_width`` is the widest span piece (:data:`PIECES`)."""

    origin: np.ndarray
    rotation: np.ndarray
    point: bool
    t0: float
    dt: float
    rows: int
    full_circle: bool
    centre: np.ndarray
    pad_t: float
    pad_s: float
    piece_width: float

    @property
    def anchor(self) -> np.ndarray:
        """(3,) frame coordinates of :attr:`centre`, rounded to float32: the kernels get it as floats, and
        host and kernels must subtract the very same point."""
        return self.to_local(self.centre[None])[0].astype(np.float32).astype(np.float64)

    def to_local(self, world: np.ndarray) -> np.ndarray:
        """(N, 3) float64 frame coordinates of world positions."""
        return (np.asarray(world, dtype=np.float64) - self.origin) @ self.rotation.T

    @property
    def row_centres(self) -> np.ndarray:
        """(rows,) row coordinate of each row's centre: the plane the loops table's spans are cut with."""
        return self.t0 + (np.arange(self.rows) + 0.5) * self.dt


def _pole_clearance(axis: np.ndarray, directions: np.ndarray) -> float:
    """Smallest angle between the line ``axis`` and any of the unit ``directions``."""
    if len(directions) == 0:
        return np.pi / 2
    return float(np.arccos(min(np.abs(directions @ axis).max(), 1.0)))


def angular_frame(light, occluder_points: np.ndarray, prefer_x=None) -> tuple[np.ndarray, np.ndarray]:
    """(origin, rotation) of the angular frame for ``light`` and the occluder points (world, (N, 3)).

    Point light: the pole axis X is ``prefer_x`` itself when it clears every occluder direction by
    :data:`POLE_CLEARANCE`, else the axis orthogonal to their mean direction that clears them most (the
    least spread direction of their scatter); -Z is the occluders' mean direction made orthogonal to X
    (theta = 0 at their centre, the wrap at +-pi behind the light). Directional light: Z towards the
    light, X = ``prefer_x`` made orthogonal to it when given; origin at the occluders' centre.
    """
    pts = np.asarray(occluder_points, dtype=np.float64)
    point = isinstance(light, PointLight)
    if point:
        origin = light.position.astype(np.float64)
        d = _unit_directions(light, pts)
        mean = d.sum(axis=0) if len(d) else np.zeros(3)
        z_axis = -mean / np.linalg.norm(mean) if np.linalg.norm(mean) > 1e-6 * max(len(d), 1) else np.array([0.0, 0, 1])
    else:
        origin = 0.5 * (pts.min(axis=0) + pts.max(axis=0)) if len(pts) else np.zeros(3)
        z_axis = -light.direction.astype(np.float64)
        d = np.zeros((0, 3))
    x_axis = None
    if prefer_x is not None:
        px = np.asarray(prefer_x, dtype=np.float64)
        if not point:
            px = px - (px @ z_axis) * z_axis
        if np.linalg.norm(px) > 1e-9 and (not point or _pole_clearance(px / np.linalg.norm(px), d) >= POLE_CLEARANCE):
            x_axis = px / np.linalg.norm(px)
    if x_axis is None:
        basis = np.stack(orthonormal_basis(z_axis))
        x_axis = basis[0]
        if point and len(d):
            proj = d @ basis[:2].T                                   # components in the plane orthogonal to z
            x_axis = np.linalg.eigh(proj.T @ proj)[1][:, 0] @ basis[:2]   # least spread: farthest from them
    if point:                                                        # -Z: the mean direction, orthogonal to X
        z_axis = z_axis - (z_axis @ x_axis) * x_axis
        z_axis = z_axis / np.linalg.norm(z_axis) if np.linalg.norm(z_axis) > 1e-9 else orthonormal_basis(x_axis)[0]
    y_axis = np.cross(z_axis, x_axis)
    return origin, np.stack([x_axis, y_axis, z_axis])


def around_pole(y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """bool (F,): triangles with corner coordinates ``y``, ``z`` ((F, 3) frame Y and Z) whose projection on
    the YZ plane holds the origin, i.e. the pole axis X crosses them (edge functions of one sign; on an
    edge counts)."""
    u, v = y, -z
    e = [u[:, i] * v[:, (i + 1) % 3] - v[:, i] * u[:, (i + 1) % 3] for i in range(3)]
    return ((e[0] >= 0) & (e[1] >= 0) & (e[2] >= 0)) | ((e[0] <= 0) & (e[1] <= 0) & (e[2] <= 0))


def row_coordinate(local: np.ndarray, point: bool) -> np.ndarray:
    """theta = atan2(Y, -Z) (point light) or Y (directional) of frame positions (float64)."""
    return np.arctan2(local[:, 1], -local[:, 2]) if point else local[:, 1].copy()


def rows_from_receivers(span: float, far: float, receiver_bounds: np.ndarray, expected_receivers, point: bool) -> int:
    """Eq. 4 in angle form: rows so that one row is about one receiver spacing wide at the farthest
    receiver (``far`` from the light; for a directional light rows are lengths and ``far`` is unused).
    The spacing is the square root of the receivers' box's largest face area over their count; with no
    count, :data:`DEFAULT_ROWS`."""
    if expected_receivers is None:
        return DEFAULT_ROWS
    ext = np.maximum(receiver_bounds[1] - receiver_bounds[0], 0.0)
    area = max(ext[0] * ext[1], ext[1] * ext[2], ext[0] * ext[2], 1e-300)
    spacing = np.sqrt(area / max(expected_receivers, 1))
    width = span * far if point else span
    return int(np.clip(np.ceil(width / spacing), MIN_ROWS, MAX_ROWS))



def _unit_directions(light, points: np.ndarray) -> np.ndarray:
    d = np.asarray(points, dtype=np.float64) - light.position
    length = np.linalg.norm(d, axis=1)
    return d[length > 0] / length[length > 0, None]
