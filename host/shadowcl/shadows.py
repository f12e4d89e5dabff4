"""The public shadow queries: :func:`prepare` once, then :meth:`Shadows.mask` any number of times;
:func:`shadow_mask` is the one-shot call over them.

>>> shadows = sc.prepare(mesh, light, method="exact", bounds=box)   # the light-space structure, once
>>> mask = shadows.mask(points, normals)                            # bool (N,), True = in shadow
>>> shadows.stats["prepare_s"], shadows.stats["classify_s"]         # seconds, one schema for every method
"""

from __future__ import annotations

import copy
import time

import numpy as np

from .checks import check_bounds
from .device import get_device
from .geometry import bounds_diagonal
from .lights import check_light
from .methods import as_mesh, method_class, occluders, resolve_eps, with_receiver_count
from .points import BOUNDS_SLACK, Points, check_points


class Shadows:
    """One method prepared for one scene and light: query it with :meth:`mask` and :meth:`visibility`.

    Made by :func:`prepare`. Attributes: ``method`` (its name), ``light``, ``eps`` (absolute),
    ``bounds`` ((2, 3) box the structure is fitted to), ``params`` (every parameter as resolved from the
    scene: what a None default became), ``stats`` (``prepare_s``, ``classify_s`` of the last query,
    ``check_s`` its receiver check, ``device_bytes``, ``receivers``, ``outside_bounds``, then the
    method's own keys). Points outside ``bounds`` are answered correctly too: a method that cannot
    (a shadow map's single view) answers them from a second structure fitted to them.
    """

    def __init__(self, scene_or_mesh, light, method: str = "exact", bounds=None, device=None, eps=None,
                 **params):
        mesh = as_mesh(scene_or_mesh)
        self.light = check_light(light)
        cls = method_class(method)
        self.method = cls.name
        self.eps = resolve_eps(cls, eps, mesh.bounds)
        self.bounds = mesh.bounds.astype(np.float64) if bounds is None else check_bounds("bounds", bounds)
        self._device = get_device(device)
        self._occluders = occluders(cls, scene_or_mesh)
        self._params = copy.deepcopy(params)   # kept for _fitted_to: never the caller's arrays
        self._instance = cls(self._device, **self._params)
        self._prepare_s = self._classify_s = self._check_s = 0.0
        self._outside = 0
        self._receivers = 0
        self.relight(self.light)

    def relight(self, light) -> None:
        """Build the structure again for another ``light``, on the same method instance: what does not
        depend on the light is kept, and a silhouette tracker has the last light's frame."""
        self.light = check_light(light)
        start = time.perf_counter()
        self._instance.prepare(self._occluders, self.light, self.bounds, self.eps)
        self._device.queue.finish()
        self._prepare_s = time.perf_counter() - start

    def __repr__(self) -> str:
        return f"Shadows(method={self.method!r}, light={self.light}, eps={self.eps:.3g})"

    # queries -------------------------------------------------------------------------------------------
    def mask(self, points, normals=None) -> np.ndarray:
        """bool (N,), True = in shadow, for ``points`` (N, 3) and optional ``normals`` (N, 3, any non-zero
        length), with the meaning of DESIGN.md."""
        return self._query("classify", points, normals)

    def visibility(self, points, normals=None) -> np.ndarray:
        """float32 (N,) in [0, 1], 1 = lit: the filtered or fractional answer where the method has one
        (a percentage-closer filter, 1/2^n of the voxel method), else 0 or 1."""
        return self._query("visibility", points, normals)

    def _query(self, kind: str, points, normals) -> np.ndarray:
        start = time.perf_counter()
        receivers = check_points(points, normals)
        checked = time.perf_counter()
        outside = self._outside_bounds(receivers)
        if self._instance.bounded and len(outside):
            inside = np.ones(len(receivers), dtype=bool)
            inside[outside] = False
            beyond = receivers.subset(outside)
            answer = np.empty(len(receivers), dtype=bool if kind == "classify" else np.float32)
            answer[inside] = getattr(self._instance, kind)(receivers.subset(inside))
            answer[outside] = getattr(self._fitted_to(beyond), kind)(beyond)
        else:
            answer = getattr(self._instance, kind)(receivers)
        self._check_s, self._classify_s = checked - start, time.perf_counter() - start
        self._outside, self._receivers = len(outside), len(receivers)
        return answer

    def _outside_bounds(self, receivers: Points) -> np.ndarray:
        """Indices of the receivers outside ``bounds`` (with :data:`BOUNDS_SLACK`); cheap when none is."""
        slack = BOUNDS_SLACK * max(bounds_diagonal(self.bounds), np.finfo(np.float32).tiny)
        low, high = self.bounds[0] - slack, self.bounds[1] + slack
        if len(receivers) == 0 or (np.all(receivers.bounds[0] >= low) and np.all(receivers.bounds[1] <= high)):
            return np.zeros(0, dtype=np.int64)
        p = receivers.positions
        return np.flatnonzero(np.any((p < low) | (p > high), axis=1))

    def _fitted_to(self, receivers: Points):
        """A second instance of the method, prepared for the box of ``receivers`` (outside ``bounds``)."""
        instance = type(self._instance)(self._device, **self._params)
        instance.prepare(self._occluders, self.light, receivers.bounds, self.eps)
        return instance

    # what was built ------------------------------------------------------------------------------------
    @property
    def params(self) -> dict:
        """The method's parameters as used, and ``eps``."""
        return {**self._instance.resolved_params(), "eps": self.eps}

    @property
    def stats(self) -> dict:
        own = dict(self._instance.stats)
        return {"method": self.method, "prepare_s": self._prepare_s, "classify_s": self._classify_s,
                "check_s": self._check_s, "device_bytes": int(own.pop("device_bytes", 0)),
                "receivers": self._receivers, "outside_bounds": self._outside,
                **{k: v for k, v in own.items() if k not in ("prepare_s", "classify_s", "receivers")}}


def prepare(scene_or_mesh, light, method: str = "exact", bounds=None, device=None, eps=None, **params) -> Shadows:
    """Build ``method``'s structure for the occluders of ``scene_or_mesh`` (a :class:`Mesh`, a
    :class:`Scene` or a subdivision surface) seen from ``light``, once; query it with
    :meth:`Shadows.mask` / :meth:`Shadows.visibility`.

    ``bounds`` ((2, 3) low and high corners) is the receivers' box the structure is fitted to; None
    means the scene's bounds. ``eps`` is absolute when given, else 1e-4 of the scene's bounding-box
    diagonal. ``device`` is a :class:`Device`, a selector string or None (the default device).
    ``params`` are the method's parameters (:func:`shadowcl.methods`).
    """
    return Shadows(scene_or_mesh, light, method, bounds, device, eps, **params)


def shadow_mask(scene_or_mesh, light, points, normals=None, method: str = "exact", device=None, eps=None,
                **params) -> np.ndarray:
    """Which of ``points`` are in shadow: bool (N,), True = in shadow.

    Exactly ``prepare(scene_or_mesh, light, method, bounds=<the points' box>, ...).mask(points, normals)``
    (and the receiver count sizes the method's grid). ``normals`` (N, 3) of any non-zero length: a point
    whose normal faces away from the light is in shadow, and its segment starts ``eps`` along it.
    """
    receivers = check_points(points, normals)
    if len(receivers) == 0:
        check_light(light)
        as_mesh(scene_or_mesh)
        method_class(method)(get_device(device), **params)   # bad parameters still raise
        return np.zeros(0, dtype=bool)
    params = with_receiver_count(method, params, len(receivers))
    return prepare(scene_or_mesh, light, method, receivers.bounds, device, eps, **params).mask(receivers)
