"""The one check of receivers: what every method and every entry point accepts as points and normals.

:func:`check_points` turns the caller's ``points`` (and optional ``normals``) into :class:`Points` once;
every method's ``classify`` and ``visibility`` calls it, and passing a :class:`Points` back in costs
nothing, so a point set is checked once however many layers it goes through (``shadow_mask`` ->
``Shadows.mask`` -> the method).

The contract: ``points`` is (N, 3) of real numbers, all finite and inside float32's range (the
device's precision); ``normals`` is None or the same shape, finite, each of non-zero length. Normals
need not be unit: every method uses them as directions. A zero normal is refused with its index, never
read as "facing away".

Cheap by construction, since it runs on every public call. The points are checked at once: the bounds
come from wide reductions (:func:`_bounds`), and finiteness is read off them (NaN propagates through
``min``, inf is a bound). ``check_points(..., box=False)`` defers that pass to the first read of
:attr:`Points.bounds`, which then raises the same errors: for a method that checks the values on the
device in its own first pass over them (the exact method in ``shadow_mask``'s one-shot call, which never
reads the box). The normals' values are checked where they are first used, once:
:meth:`Points.checked_normals` (and :meth:`~Points.unit_normals`, :meth:`~Points.facing_away` over it)
on the host, or on the device by a method that normalises them there in double (the exact method),
which reports a bad row through :meth:`Points.checked_normals` so that the error is the same. The slow
search for the first bad index runs only when a check fails. At 1.2 M receivers: ~3 ms for the points;
the host check of the normals ~7 ms more where it runs.
"""

from __future__ import annotations

import functools
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property

import numpy as np

FLOAT32_MAX = float(np.finfo(np.float32).max)
WIDE = 64             # points per row of _bounds' reductions
PARALLEL_BOUNDS = 1 << 18   # points from which _bounds splits the work between threads
BOUNDS_THREADS = max(1, min(os.cpu_count() or 1, 8))
BOUNDS_SLACK = 1e-6   # relative to a box's diagonal: a point this close outside the box counts as inside


@dataclass(frozen=True, eq=False)
class Points:
    """Receivers that passed :func:`check_points`.

    ``positions`` (N, 3) float64 C-contiguous; ``normals`` None or (N, 3) float64 C-contiguous, as given
    (their values checked on first use, see the module docstring); ``box`` the (2, 3) box of the
    positions (zeros when N = 0), or None when it is still to be computed (``check_points(..., box=False)``:
    the positions' values are then unchecked until :attr:`bounds` is read).
    """

    positions: np.ndarray
    normals: np.ndarray | None
    box: np.ndarray | None

    def __len__(self) -> int:
        return len(self.positions)

    @cached_property
    def bounds(self) -> np.ndarray:
        """The (2, 3) box of the positions; computed on first read when it was deferred, with the check of
        their values (``ValueError`` naming the first bad index)."""
        return self.box if self.box is not None else _checked_bounds(self.positions)

    def checked_normals(self) -> np.ndarray | None:
        """The normals once checked on the host (finite, non-zero; rescaled where their squared length
        overflows), or None; raises the named ``ValueError`` for a bad row."""
        return self._checked[0]

    def unit_normals(self) -> np.ndarray | None:
        """(N, 3) float64 unit normals (computed once, after :meth:`checked_normals`), or None."""
        return self._unit_normals

    # A frozen dataclass still takes cached properties: the cache writes the instance's __dict__.
    @cached_property
    def _checked(self) -> tuple:
        if self.normals is None:
            return None, None
        if len(self) == 0:
            return self.normals, np.ones(0)
        length2 = _squared_lengths(self.normals)
        if not (length2.min() > 0 and np.isfinite(length2.max())):
            return _bad_normals(self.normals, length2)
        return self.normals, length2

    @cached_property
    def _unit_normals(self) -> np.ndarray | None:
        normals, length2 = self._checked
        return None if normals is None else normals / np.sqrt(length2)[:, None]

    def facing_away(self, light) -> np.ndarray:
        """bool (N,): the normal faces away from ``light`` (``dot <= 0``, DESIGN.md's "in shadow");
        all False without normals."""
        if self.normals is None:
            return np.zeros(len(self), dtype=bool)
        to_light = light.direction_to_light(self.positions)
        return np.einsum("ij,ij->i", self.checked_normals(), to_light) <= 0

    def near(self, point: np.ndarray, reach: float) -> np.ndarray:
        """Indices of the receivers within ``reach`` of ``point`` on every axis (a box), narrowed axis by
        axis: one column pass over them all, the other axes over the few left."""
        positions = self.positions
        near = np.flatnonzero(np.abs(positions[:, 0] - point[0]) <= reach)
        for axis in (1, 2):
            near = near[np.abs(positions[near, axis] - point[axis]) <= reach]
        return near

    def subset(self, index) -> "Points":
        """The receivers at ``index`` (an integer array or a bool mask), checked already."""
        positions = np.ascontiguousarray(self.positions[index])
        normals = None if self.normals is None else np.ascontiguousarray(self.normals[index])
        return Points(positions, normals, _bounds(positions))


class MovedPoints(Points):
    """Checked receivers ``world`` moved by x -> (x - centre) / scale, ``scale`` a power of two (exact),
    with the moved ``bounds`` given; the moved positions are computed when first read.

    A method that moves its receivers on the device, fused into its first pass over them, reads
    :attr:`world` and (:attr:`centre`, :attr:`scale`) instead and never pays the host pass over N x 3
    float64 (the exact method: ~10 ms at 1.2 M receivers); every other reader gets the same bits as
    the host move: ``(x - centre) * (1 / scale)`` in float64.
    """

    def __init__(self, world: Points, centre: np.ndarray, scale: float, bounds: np.ndarray | None):
        for name, value in (("world", world), ("centre", np.asarray(centre, dtype=np.float64)),
                            ("scale", float(scale)), ("normals", world.normals), ("box", bounds)):
            object.__setattr__(self, name, value)

    @cached_property
    def bounds(self) -> np.ndarray:
        """The moved box: given, or the world's box moved when first read (the move is monotonic)."""
        return self.box if self.box is not None else self._move(self.world.bounds)

    @cached_property
    def positions(self) -> np.ndarray:
        return self._move(self.world.positions)

    def __len__(self) -> int:
        return len(self.world)

    def _move(self, world: np.ndarray) -> np.ndarray:
        moved = np.subtract(world, self.centre)
        moved *= 1.0 / self.scale
        return moved

    def subset(self, index) -> Points:
        moved = self._move(self.world.positions[index])
        normals = None if self.normals is None else np.ascontiguousarray(self.normals[index])
        return Points(moved, normals, _bounds(moved))

    def near(self, point: np.ndarray, reach: float) -> np.ndarray:
        # narrowed in the world first (a column pass over the caller's array, no move of them all), then
        # decided on the moved subset exactly as Points.near would
        centre = np.asarray(point, dtype=np.float64) * self.scale + self.centre
        rounding = 8 * np.finfo(np.float64).eps * (np.abs(self.centre).max() + np.abs(centre).max())
        candidates = self.world.near(centre, reach * self.scale * (1.0 + 1e-9) + rounding)
        moved = self._move(self.world.positions[candidates])
        return candidates[np.all(np.abs(moved - point) <= reach, axis=1)]


def check_points(points, normals=None, box: bool = True) -> Points:
    """``points`` (N, 3) and optional ``normals`` (N, 3) checked once (module docstring), as :class:`Points`.

    A :class:`Points` is returned as it is (``normals`` must then be None). Raises ``TypeError`` for
    non-numeric input and ``ValueError`` naming the argument and the first bad index otherwise; with
    ``box=False`` the values (not the shapes) are checked when :attr:`Points.bounds` is first read.
    """
    if isinstance(points, Points):
        if normals is not None:
            raise TypeError("normals: the points are checked Points already, which carry their own normals")
        return points
    positions = _real_array("points", points)
    bounds = _checked_bounds(positions) if box else None
    if normals is not None:
        normals = _real_array("normals", normals)
        if normals.shape != positions.shape:
            raise ValueError(f"normals: expected shape {positions.shape} to match points, got {normals.shape}")
    return Points(positions, normals, bounds)


def _checked_bounds(positions: np.ndarray) -> np.ndarray:
    """The box of (N, 3) float64 ``positions``; ``ValueError`` for a value outside the contract."""
    bounds = _bounds(positions)
    if not np.all(np.isfinite(bounds)):
        raise ValueError(f"points: contains NaN or inf (first at index {_first_bad_row(positions)})")
    largest = float(np.abs(bounds).max(initial=0.0))
    if largest >= FLOAT32_MAX:
        raise ValueError(f"points: coordinates overflow float32 (largest magnitude {largest:.3g})")
    return bounds


def _real_array(name: str, value) -> np.ndarray:
    """``value`` as an (N, 3) C-contiguous float64 array (no copy when it is one already)."""
    try:
        array = np.asarray(value)
    except Exception as error:  # ragged lists and the like
        raise TypeError(f"{name}: cannot be read as an array ({error})") from None
    if array.dtype == object or not (np.issubdtype(array.dtype, np.number) or array.dtype == bool) \
            or np.issubdtype(array.dtype, np.complexfloating):
        raise TypeError(f"{name}: expected a real numeric array, got dtype {array.dtype}")
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (N, 3), got {array.shape}")
    return np.ascontiguousarray(array, dtype=np.float64)


def _bounds(positions: np.ndarray) -> np.ndarray:
    """(2, 3) float64 box (NaN and inf propagate into it). Reduced over rows of ``WIDE`` points at once:
    an axis-0 reduction over (N, 3) runs along short rows (~30 ms at 1.2 M points), over (N / 64, 192)
    it vectorises (~3 ms, against ~5 ms column by column). Large arrays are reduced in parts on the
    host's cores (NumPy's reductions release the GIL): 1.2 M points 5.9 -> 3.6 ms on 2 cores."""
    if len(positions) >= PARALLEL_BOUNDS:
        step = -(-len(positions) // BOUNDS_THREADS // WIDE) * WIDE
        parts = list(_pool().map(_bounds_serial, [positions[k:k + step] for k in range(0, len(positions), step)]))
        return np.array([np.min([p[0] for p in parts], axis=0), np.max([p[1] for p in parts], axis=0)])
    return _bounds_serial(positions)


@functools.cache
def _pool() -> ThreadPoolExecutor:
    """The threads of :func:`_bounds` (one per core, at most 8), made on first use."""
    return ThreadPoolExecutor(max_workers=BOUNDS_THREADS, thread_name_prefix="shadowcl-bounds")


def _bounds_serial(positions: np.ndarray) -> np.ndarray:
    if len(positions) == 0:
        return np.zeros((2, 3))
    whole = len(positions) // WIDE * WIDE
    low, high = [positions[whole:]], [positions[whole:]]
    if whole:
        wide = positions[:whole].reshape(-1, 3 * WIDE)
        low.append(wide.min(axis=0).reshape(-1, 3))
        high.append(wide.max(axis=0).reshape(-1, 3))
    return np.array([np.concatenate(low).min(axis=0), np.concatenate(high).max(axis=0)])


def _first_bad_row(array: np.ndarray) -> int:
    return int(np.flatnonzero(~np.isfinite(array).all(axis=1))[0])


def _squared_lengths(normals: np.ndarray) -> np.ndarray:
    with np.errstate(over="ignore", invalid="ignore"):      # found and handled by _bad_normals
        return np.einsum("ij,ij->i", normals, normals)


def _bad_normals(normals: np.ndarray, length2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The slow path: raise for a non-finite or zero normal; rescale normals whose squared length
    overflowed (finite components beyond 1e154) so that they can be made unit."""
    if not np.isfinite(normals).all():
        raise ValueError(f"normals: contains NaN or inf (first at index {_first_bad_row(normals)})")
    scaled = normals / np.maximum(np.abs(normals).max(axis=1, keepdims=True), np.finfo(np.float64).tiny)
    length2 = _squared_lengths(scaled)
    zero = np.flatnonzero(~(length2 > 0))
    if len(zero):
        raise ValueError(f"normals: zero-length normal at index {int(zero[0])}")
    return np.ascontiguousarray(scaled), length2
