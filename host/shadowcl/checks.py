"""Argument checks shared by the public API: each raises TypeError/ValueError naming the argument."""

from __future__ import annotations

import os

import numpy as np


def finite_array(name: str, value, shape_tail: tuple[int, ...], dtype=np.float64) -> np.ndarray:
    """``value`` as a float array of shape ``(N, *shape_tail)`` with only finite entries."""
    try:
        array = np.asarray(value)
    except Exception as error:  # ragged lists and the like
        raise TypeError(f"{name}: cannot be read as an array ({error})") from None
    if array.dtype == object or not (np.issubdtype(array.dtype, np.number) or array.dtype == bool):
        raise TypeError(f"{name}: expected a numeric array, got dtype {array.dtype}")
    if np.issubdtype(array.dtype, np.complexfloating):
        raise TypeError(f"{name}: expected real numbers, got dtype {array.dtype}")
    expected = "(N, " + ", ".join(map(str, shape_tail)) + ")"
    if array.ndim != 1 + len(shape_tail) or array.shape[1:] != shape_tail:
        raise ValueError(f"{name}: expected shape {expected}, got {array.shape}")
    array = array.astype(dtype, copy=False)
    if not np.all(np.isfinite(array)):
        bad = np.argwhere(~np.isfinite(array))[0]
        raise ValueError(f"{name}: contains NaN or inf (first at index {tuple(int(i) for i in bad)})")
    if array.size and np.abs(array).max() >= np.finfo(np.float32).max:
        raise ValueError(f"{name}: coordinates overflow float32 (largest magnitude {np.abs(array).max():.3g})")
    return array


def integer_array(name: str, value, empty: bool = False) -> np.ndarray:
    """``value`` as an integer NumPy array (bools refused), else a TypeError naming ``name``; with
    ``empty``, an empty 1-D sequence of any dtype (``[]`` is float to NumPy) is no indices (int64)."""
    try:
        array = np.asarray(value)
    except Exception as error:  # ragged lists and the like
        raise TypeError(f"{name}: cannot be read as indices ({error})") from None
    if empty and array.ndim == 1 and array.size == 0:
        array = array.astype(np.int64)
    if array.dtype == bool or not np.issubdtype(array.dtype, np.integer):
        raise TypeError(f"{name}: expected integer indices, got dtype {array.dtype}")
    return array


class VertexIndexError(ValueError):
    """A face refers to a vertex that does not exist; ``face`` is that face (a file reader finds its line)."""

    def __init__(self, message: str, face: int):
        super().__init__(message)
        self.face = face


def vertex_indices(name: str, corners: np.ndarray, n_vertices: int, sizes=None, base: int = 0) -> None:
    """Raise :class:`VertexIndexError` (a ValueError) naming ``name`` at the first vertex index in
    ``corners`` outside [0, ``n_vertices``): its face, the index as the caller wrote it (counted from
    ``base``) and the vertex count. ``corners`` is (F, K) integers, a row per face, or with ``sizes`` the
    corners of faces of ``sizes`` corners each, one face after another."""
    corners = np.asarray(corners)
    if corners.size == 0 or (corners.min() >= 0 and corners.max() < n_vertices):
        return
    flat = corners.ravel()
    at = int(np.flatnonzero((flat < 0) | (flat >= n_vertices))[0])
    face = at // corners.shape[1] if sizes is None else int(np.searchsorted(np.cumsum(sizes), at, side="right"))
    counted = f" (numbered from {base})" if base else ""
    raise VertexIndexError(f"{name}: face {face} has vertex index {int(flat[at]) + base} out of range for "
                           f"{n_vertices} vertices{counted}", face)


def vector3(name: str, value, nonzero: bool = False) -> np.ndarray:
    """``value`` as a finite float64 3-vector (non-zero length if asked); booleans and strings are not numbers."""
    items = value if isinstance(value, (list, tuple)) else [value]
    kind = getattr(value, "dtype", np.dtype(float)).kind
    if kind in "bUSV" or any(isinstance(x, (bool, np.bool_, str, bytes)) for x in items):
        raise TypeError(f"{name}: expected three numbers, got {value!r}")
    try:
        array = np.array(value, dtype=np.float64)   # a copy: stored vectors never share the caller's buffer
    except OverflowError:
        raise ValueError(f"{name}: {value!r} is beyond the floating-point range") from None
    except (TypeError, ValueError):
        raise TypeError(f"{name}: expected three numbers, got {value!r}") from None
    if array.shape != (3,):
        raise ValueError(f"{name}: expected three numbers, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: must be finite, got {array.tolist()}")
    if nonzero and not np.linalg.norm(array) > 0:
        raise ValueError(f"{name}: must have non-zero length, got {array.tolist()}")
    return array


def positive_int(name: str, value, minimum: int = 1, maximum: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name}: expected an integer, got {type(value).__name__}")
    if value < minimum or (maximum is not None and value > maximum):
        bound = f"between {minimum} and {maximum}" if maximum is not None else f"at least {minimum}"
        raise ValueError(f"{name}: must be {bound}, got {value}")
    return int(value)


def non_negative_float(name: str, value) -> float:
    """``value`` as a finite float >= 0 (numbers only: strings are refused, not parsed)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name}: expected a number, got {type(value).__name__}")
    number = _as_float(name, value)
    if not (np.isfinite(number) and number >= 0):
        raise ValueError(f"{name}: must be a finite non-negative number, got {value!r}")
    return number


def _as_float(name: str, value) -> float:
    """A number as a float; an integer beyond the float range is a ValueError, not an OverflowError."""
    try:
        return float(value)
    except OverflowError:
        raise ValueError(f"{name}: {value} is beyond the floating-point range") from None


def positive_float(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name}: expected a number, got {value!r}")
    number = _as_float(name, value)
    if not (np.isfinite(number) and number > 0):
        raise ValueError(f"{name}: must be a finite positive number, got {value!r}")
    return number


def check_bounds(name: str, bounds) -> np.ndarray:
    """A (2, 3) finite float64 box with low <= high (a copy: boxes are stored)."""
    box = finite_array(name, bounds, (3,)).copy()
    if box.shape != (2, 3):
        raise ValueError(f"{name}: expected shape (2, 3) (low and high corners), got {box.shape}")
    if np.any(box[0] > box[1]):
        raise ValueError(f"{name}: low corner {box[0].tolist()} exceeds high corner {box[1].tolist()}")
    return box


def optional_int(name: str, value, minimum: int = 1, maximum: int | None = None) -> int | None:
    """None, or ``value`` checked by :func:`positive_int`."""
    return None if value is None else positive_int(name, value, minimum, maximum)


def choice(name: str, value, choices: tuple):
    """``value`` if it is one of ``choices`` and of the same type (1.0 == 1 would otherwise pass, and
    reach a kernel build as ``-DX=1.0``); a NumPy integer counts as the Python int it holds."""
    if isinstance(value, np.integer):
        value = int(value)
    if isinstance(value, (bool, np.bool_)) or type(value) not in {type(c) for c in choices} or value not in choices:
        raise ValueError(f"{name}: expected one of {', '.join(map(repr, choices))}, got {value!r}")
    return value


def flag(name: str, value) -> bool:
    """``value`` if it is a bool (NumPy's included)."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name}: expected a bool, got {type(value).__name__}")
    return bool(value)


def available_host_bytes() -> int | None:
    """Memory this process can still get: the least of the host's (Linux's MemAvailable, else free
    physical pages), its cgroup's room and its address-space limit's room; None where none is known."""
    figures = [_host_free(), _cgroup_room(), _address_space_room()]
    known = [figure for figure in figures if figure is not None]
    return max(min(known), 0) if known else None


def _host_free() -> int | None:
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def _cgroup_room() -> int | None:
    """A container's memory limit less its use (cgroup v2, else v1); None when unlimited or unknown."""
    for limit_file, usage_file in (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
                                   ("/sys/fs/cgroup/memory/memory.limit_in_bytes",
                                    "/sys/fs/cgroup/memory/memory.usage_in_bytes")):
        try:
            with open(limit_file) as limit, open(usage_file) as usage:
                text = limit.read().strip()
                if text == "max" or int(text) >= 1 << 60:
                    return None
                return int(text) - int(usage.read())
        except (OSError, ValueError):
            continue
    return None


def _address_space_room() -> int | None:
    """``ulimit -v`` less this process's virtual size; None when unlimited or unknown."""
    try:
        import resource

        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
        if limit == resource.RLIM_INFINITY:
            return None
        with open("/proc/self/statm") as statm:
            return limit - int(statm.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (ImportError, OSError, ValueError, IndexError):
        return None


def check_memory(name: str, what: str, needed: int, available: int | None, where: str) -> None:
    """ValueError naming ``name`` when ``what`` needs more than the ``available`` bytes of ``where``."""
    if available is not None and needed > available:
        raise ValueError(f"{name}: {what} needs about {needed / 2**30:.2f} GiB but {where} has "
                         f"{available / 2**30:.2f} GiB available; make it smaller")
