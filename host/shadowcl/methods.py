"""The shadow methods behind one interface, and :func:`shadow_mask`, the one-shot call over them.

A method is "prepare once, query many". Each is a class registered in :data:`METHODS`::

    class SomeMethod:
        name = "some"
        parameters = {"resolution": (None, "grid cells per side; None picks one from the scene")}
        def __init__(self, device: Device, **params): ...
        def prepare(self, mesh: Mesh, light, receiver_bounds: np.ndarray, eps: float) -> None: ...
        def classify(self, points: np.ndarray, normals: np.ndarray | None) -> np.ndarray: ...

``prepare`` builds the light-space structure for occluders ``mesh`` seen from ``light``, for receivers
inside ``receiver_bounds`` ((2, 3) float64 box); ``classify`` takes (N, 3) float64 points (and unit
normals) inside those bounds and returns a bool (N,) mask, True = in shadow, with the meaning of
``../shared/DESIGN.md``: the segment from the point (moved ``eps`` along its normal when normals are
given) to the light hits a triangle further than ``eps`` from the point; a normal facing away from the
light (``dot <= 0``) is in shadow.

Two optional parts of the protocol:

- ``scene_input = True`` on the class: ``prepare`` receives what the caller passed (a ``Scene``, or
  any object with a ``.mesh``, e.g. a subdivision surface) instead of its triangle mesh, for methods
  that work on more than triangles.
- ``classify_view(view, zbuffer, seen)``: :func:`shadowcl.render` calls it, when present, instead of
  ``classify`` with the camera's ``View``, its ``raster.ZBuffer`` and ``raster.Receivers``; it returns the
  bool mask of the covered pixels in ``seen``'s order, for methods that work in image space (a
  stencil, scan-line runs).
- ``render_report(scene, width, height, device=, eps=, **params)`` (a static method):
  :func:`shadowcl.render` hands the whole image to it, for methods that draw their own geometry (the
  voxel method's crack-free leaves, shaded 1/2^n per shadowed corner).
"""

from __future__ import annotations

import importlib

import numpy as np

from .checks import check_bounds, finite_array, non_negative_float
from .device import get_device
from .geometry import Mesh, bounds_diagonal
from .lights import check_light

# name -> "module:Class"; imported on first use so one method's dependencies never slow another.
METHODS = {
    "exact": "shadowcl.exact:ExactMethod",
    "shadow_map": "shadowcl.shadow_map:ShadowMapMethod",
    "angular": "shadowcl.angular:AngularMethod",
    "shadow_volume": "shadowcl.shadow_volume:ShadowVolumeMethod",
    "voxel": "shadowcl.voxel:VoxelMethod",
}

EPS_FRACTION = 1e-4  # default eps as a fraction of the scene's bounding-box diagonal (DESIGN.md)


def method_class(name: str):
    if not isinstance(name, str):
        raise TypeError(f"method: expected a method name, got {type(name).__name__}")
    if name not in METHODS:
        raise ValueError(f"method: unknown method {name!r}; available: {', '.join(sorted(METHODS))}")
    module, attribute = METHODS[name].split(":")
    return getattr(importlib.import_module(module), attribute)


def methods() -> dict[str, dict[str, tuple]]:
    """Every method's name and its parameters as ``{name: {parameter: (default, description)}}``."""
    return {name: dict(method_class(name).parameters) for name in METHODS}


def create_method(name: str, device=None, **params):
    """An unprepared instance of method ``name`` on ``device``; unknown parameters raise ``TypeError``."""
    cls = method_class(name)
    unknown = sorted(set(params) - set(cls.parameters))
    if unknown:
        raise TypeError(f"{', '.join(unknown)}: not a parameter of method {name!r}; it takes {sorted(cls.parameters)}")
    return cls(get_device(device), **params)


def with_receiver_count(name: str, params: dict, count: int) -> dict:
    """``params`` plus ``expected_receivers=count`` when method ``name`` sizes its grid by it and the caller
    did not say: the one-shot calls know how many receivers are coming before they prepare."""
    if "expected_receivers" in method_class(name).parameters and params.get("expected_receivers") is None:
        return {**params, "expected_receivers": max(int(count), 1)}
    return params


def occluders(cls, scene_or_mesh):
    """What ``cls.prepare`` takes from ``scene_or_mesh``: the object itself for ``scene_input`` methods, else its mesh."""
    mesh = as_mesh(scene_or_mesh)
    return scene_or_mesh if getattr(cls, "scene_input", False) else mesh


def as_mesh(scene_or_mesh) -> Mesh:
    """The occluding geometry of a :class:`Mesh` or a :class:`Scene`."""
    if isinstance(scene_or_mesh, Mesh):
        return scene_or_mesh
    mesh = getattr(scene_or_mesh, "mesh", None)
    if isinstance(mesh, Mesh):
        return mesh
    raise TypeError(f"scene_or_mesh: expected a Mesh or a Scene, got {type(scene_or_mesh).__name__}")


def default_eps(bounds: np.ndarray) -> float:
    return EPS_FRACTION * max(bounds_diagonal(bounds), np.finfo(np.float32).tiny)


def check_prepare(mesh, light, receiver_bounds, eps):
    """``prepare``'s arguments checked: ``(light, receiver box (2, 3) float64)``; named errors otherwise."""
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected a Mesh, got {type(mesh).__name__}")
    light = check_light(light)
    box = check_bounds("receiver_bounds", receiver_bounds)
    if not (np.isfinite(eps) and eps >= 0):
        raise ValueError(f"eps: must be a finite non-negative distance, got {eps!r}")
    return light, box


def check_points(points, normals) -> tuple[np.ndarray, np.ndarray | None]:
    points = finite_array("points", points, (3,))
    if normals is not None:
        normals = finite_array("normals", normals, (3,))
        if normals.shape != points.shape:
            raise ValueError(f"normals: expected shape {points.shape} to match points, got {normals.shape}")
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        if np.any(length == 0):
            raise ValueError(f"normals: zero-length normal at index {int(np.argmin(length[:, 0]))}")
        normals = normals / length
    return points, normals


def shadow_mask(scene_or_mesh, light, points, normals=None, method: str = "exact", device=None, eps=None, **params):
    """Which of ``points`` are in shadow: bool (N,), True = in shadow.

    ``scene_or_mesh`` holds the occluders, ``light`` is a :class:`PointLight` or
    :class:`DirectionalLight`, ``points`` is (N, 3) and ``normals`` optionally (N, 3). ``eps`` is
    absolute when given, else 1e-4 of the scene's bounding-box diagonal. ``method`` names one of
    :func:`methods`; ``params`` are that method's parameters.
    """
    mesh = as_mesh(scene_or_mesh)
    light = check_light(light)
    points, normals = check_points(points, normals)
    bounds = mesh.bounds
    eps = default_eps(bounds) if eps is None else non_negative_float("eps", eps)
    instance = create_method(method, device, **with_receiver_count(method, params, len(points)))
    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    receiver_bounds = np.stack([points.min(axis=0), points.max(axis=0)])
    instance.prepare(occluders(type(instance), scene_or_mesh), light, receiver_bounds, eps)
    return instance.classify(points, normals)
