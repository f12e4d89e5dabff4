"""The method protocol every shadow method implements, and the registry of methods.

A method is "prepare once, query many": :meth:`Method.prepare` builds the light-space structure for
one set of occluders seen from one light, for receivers in a box; :meth:`Method.classify` then answers
any number of points. Users reach methods through :func:`shadowcl.prepare` (a :class:`shadowcl.Shadows`)
and :class:`shadowcl.Renderer`, which add defaults, timing and the bounds rule; this module is what a
method implements::

    class SomeMethod(Method):
        name = "some"
        parameters = {"resolution": (None, "grid cells per side; None picks one from the scene")}
        def __init__(self, device, **params):
            super().__init__(device, **params)          # self.params: every parameter, defaults filled
            self.resolution = check(self.params["resolution"])
        def prepare(self, occluders, light, receiver_bounds, eps): ...
        def classify(self, points, normals=None): ...   # bool (N,), True = in shadow

``classify`` takes what :func:`shadowcl.points.check_points` accepts (and a checked ``Points``, at no
cost) and answers with the meaning of ``../shared/DESIGN.md``: the segment from the point (moved
``eps`` along its unit normal when normals are given) to the light hits a triangle further than
``eps`` from the point; a normal facing away from the light (``dot <= 0``) is in shadow.

Optional capabilities are declared on the class, never found by ``hasattr``:

- ``scene_input``: ``prepare`` receives what the caller passed (a ``Scene``, or any object with a
  ``.mesh``, e.g. a subdivision surface) instead of its triangle mesh.
- ``image_space``: :meth:`Method.classify_view` answers the camera's covered pixels from the view, its
  Z-buffer and receivers (a stencil, scan-line runs); the renderer calls it instead of ``classify``.
- ``own_renderer``: the method draws its own geometry (:meth:`Method.render_frame`).
- ``bounded``: ``classify`` is right only inside the ``receiver_bounds`` given to ``prepare`` (a single
  shadow-map view); :class:`shadowcl.Shadows` then answers points outside by a second preparation.
- ``point_light_reach``: how many scene sizes away the method's float32 arithmetic still answers a
  point light right (measured, bench/range.py); :class:`shadowcl.Shadows` gives a point light
  farther than that the method as the directional light from the scene (:mod:`shadowcl.frame`).
- ``min_light_clearance``: the closest a point light may come to an occluding triangle, as a fraction
  of the occluders' box diagonal (measured there too); a closer light is refused.
- ``eps_meaning``: how the method honours ``eps``, or None when it cannot (its own resolution sets the
  offset): the public calls then refuse an ``eps`` other than None (:func:`resolve_eps`), and
  :func:`methods` lists it as the method's ``eps`` entry.
- ``answers_at_the_light``: the method itself answers a receiver whose tested segment is at most ``eps``
  long (lit, unless its normal faces away), whatever its projection makes of a point at its eye; else
  :class:`shadowcl.Shadows` finds such receivers on the host and sets them.
- ``checks_receivers`` (the instance's, for its device: :meth:`~Method.checks_receivers_on`):
  :meth:`~Method.classify_near` checks the points' values in the method's first pass over them and
  leaves those beyond a given box to the caller, so that ``shadow_mask``'s one-shot call makes no host
  pass over the points (no box, no finiteness check), where :meth:`~Method.places_any_point` allows.
"""

from __future__ import annotations

import abc
import importlib

import numpy as np

from .checks import check_bounds, non_negative_float
from .frame import MAX_RECEIVER_DISTANCE
from .geometry import Mesh, bounds_diagonal
from .lights import check_light

# name -> "module:Class"; imported on first use so one method's dependencies never slow another.
METHODS = {
    "exact": "shadowcl.exact:ExactMethod",
    "shadow_map": "shadowcl.shadow_map:ShadowMapMethod",
    "angular": "shadowcl.angular:AngularMethod",
    "shadow_volume": "shadowcl.shadow_volume:ShadowVolumeMethod",
    "voxel": "shadowcl.voxel:VoxelMethod",
    "auto": "shadowcl.auto:AutoMethod",
}

EPS_FRACTION = 1e-4  # default eps as a fraction of the scene's bounding-box diagonal (DESIGN.md)


class Method(abc.ABC):
    """The protocol (module docstring). Subclasses set :attr:`name` and :attr:`parameters`
    (``{parameter: (default, description)}``, the only place a default is written) and implement
    :meth:`prepare` and :meth:`classify`; ``stats`` is a dict of what the last calls measured."""

    name: str = ""
    parameters: dict[str, tuple] = {}
    scene_input = False
    image_space = False
    own_renderer = False
    bounded = False
    point_light_reach = 2.0 ** 24     # shadowcl.frame.DIRECTIONAL_DISTANCE: float32's own limit
    min_light_clearance = 0.0
    eps_meaning: str | None = "as DESIGN.md: the segment starts eps along the normal and ignores hits within eps"
    answers_at_the_light = False

    def __init__(self, device, **params):
        self.check_parameter_names(params)
        self.device = device
        self.checks_receivers = self.checks_receivers_on(device)
        self.params = {key: params.get(key, default) for key, (default, _) in self.parameters.items()}
        self.stats: dict = {}

    @classmethod
    def check_parameter_names(cls, params) -> None:
        """``TypeError`` naming the ``params`` the method does not take (no device needed; their values
        are checked by the constructor, which some methods give a device to read)."""
        unknown = sorted(set(params) - set(cls.parameters))
        if unknown:
            raise TypeError(f"{', '.join(unknown)}: not a parameter of method {cls.name!r}; "
                            f"it takes {sorted(cls.parameters)}")

    @abc.abstractmethod
    def prepare(self, occluders, light, receiver_bounds, eps: float) -> None:
        """Build the structure for ``occluders`` (a :class:`Mesh`; the caller's object when
        ``scene_input``) seen from ``light``, for receivers in the (2, 3) world box
        ``receiver_bounds``; ``eps`` is DESIGN.md's absolute offset."""

    @abc.abstractmethod
    def classify(self, points, normals=None) -> np.ndarray:
        """bool (N,): True = in shadow."""

    @classmethod
    def checks_receivers_on(cls, device) -> bool:
        """Whether the method on ``device`` (a :class:`shadowcl.Device`) has ``checks_receivers``."""
        return False

    @classmethod
    def places_any_point(cls, light, occluder_bounds: np.ndarray) -> bool:
        """Whether a structure prepared for the (world) box ``occluder_bounds`` answers a point anywhere
        (near) as cheaply as one prepared for the points' box: ``shadow_mask`` may then fit a
        ``checks_receivers`` method to the occluders and never read the points on the host."""
        return False

    def classify_near(self, points, near_box: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``checks_receivers`` methods: ``classify`` of the checked-shape ``points`` (a
        :class:`~shadowcl.points.Points` whose values the host has not read), except the points beyond
        the (2, 3) box ``near_box`` (the method's frame), which are left False and returned as indices
        for the caller to answer. A bad value raises the host check's own error."""
        raise NotImplementedError(f"method {self.name!r} does not check receivers on the device")

    def visibility(self, points, normals=None) -> np.ndarray:
        """float32 (N,) in [0, 1], 1 = lit: binary methods give 0 or 1 (this default), filtering ones
        (a percentage-closer filter, 1/2^n shading) override it; the renderer shades with it."""
        return (~self.classify(points, normals)).astype(np.float32)

    def classify_view(self, view, zbuffer, seen) -> np.ndarray:
        """``image_space`` methods: the bool mask of ``seen``'s covered pixels (row-major order)."""
        raise NotImplementedError(f"method {self.name!r} does not classify in image space")

    @classmethod
    def render_frame(cls, scene, view, prepared: list) -> "RenderResult":
        """``own_renderer`` methods: the :class:`shadowcl.render.RenderResult` of ``scene`` through ``view``,
        from ``prepared``, one prepared instance of the class per light (a Renderer's, kept between frames)."""
        raise NotImplementedError(f"method {cls.name!r} has no renderer of its own")

    def resolved_params(self) -> dict:
        """The parameters as used by the last ``prepare``: what a None default became."""
        return dict(self.params)

    def __repr__(self) -> str:
        changed = {k: v for k, v in self.params.items() if v is not self.parameters[k][0]}
        return f"{type(self).__name__}({', '.join(f'{k}={v!r}' for k, v in changed.items())})"


def method_class(name: str) -> type[Method]:
    if not isinstance(name, str):
        raise TypeError(f"method: expected a method name, got {type(name).__name__}")
    if name not in METHODS:
        raise ValueError(f"method: unknown method {name!r}; available: {', '.join(sorted(METHODS))}")
    module, attribute = METHODS[name].split(":")
    return getattr(importlib.import_module(module), attribute)


def methods() -> dict[str, dict[str, tuple]]:
    """Every method's name and its parameters as ``{name: {parameter: (default, description)}}``, with
    an ``eps`` entry last that says whether and how the method honours ``eps``."""
    listing = {}
    for name in METHODS:
        cls = method_class(name)
        eps = f"honoured: {cls.eps_meaning}" if cls.eps_meaning else "not honoured: only eps=None is accepted"
        listing[name] = {**cls.parameters, "eps": (None, eps)}
    return listing


def create_method(name: str, device=None, **params) -> Method:
    """An unprepared instance of method ``name`` on ``device``; unknown parameters raise ``TypeError``.
    For code inside the package and its tests; users call :func:`shadowcl.prepare`."""
    from .device import get_device
    return method_class(name)(get_device(device), **params)


def with_receiver_count(name: str, params: dict, count: int) -> dict:
    """``params`` plus ``expected_receivers=count`` when method ``name`` sizes its grid by it and the caller
    did not say: the one-shot calls know how many receivers are coming before they prepare."""
    if "expected_receivers" in method_class(name).parameters and params.get("expected_receivers") is None:
        return {**params, "expected_receivers": max(int(count), 1)}
    return params


def with_light_count(name: str, params: dict, count: int) -> dict:
    """``params`` plus ``cull=True`` when method ``name`` can cull the faces a light does not need (the
    exact method: :mod:`shadowcl.solids`), a many-lights call has at least its ``CULL_FROM_LIGHTS``
    lights and the caller did not say: the certificate, made once, then costs less than the lights save."""
    cls = method_class(name)
    if "cull" in cls.parameters and "cull" not in params and count >= cls.cull_from_lights:
        return {**params, "cull": True}
    return params


def with_receivers(name: str, params: dict, receivers) -> dict:
    """``params`` plus ``receivers=`` when method ``name`` calibrates on the caller's receivers ("auto") and
    the caller did not say: the one-shot calls and the renderer know them before they prepare."""
    if "receivers" in method_class(name).parameters and params.get("receivers") is None:
        return {**params, "receivers": receivers}
    return params


def occluders(cls, scene_or_mesh):
    """What ``cls.prepare`` takes from ``scene_or_mesh``: the object itself for ``scene_input`` methods, else its mesh."""
    mesh = as_mesh(scene_or_mesh)
    return scene_or_mesh if cls.scene_input else mesh


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


def resolve_eps(cls, eps, bounds: np.ndarray) -> float:
    """The absolute eps of a public call to method ``cls``: the caller's, checked, else the default of
    ``bounds``; ``ValueError`` when ``cls`` cannot honour an eps the caller gave, or when it is beyond
    the working range (more than :data:`~shadowcl.frame.MAX_RECEIVER_DISTANCE` scene sizes, the
    receivers' own limit: a start ``p + eps n`` is a receiver of the kernels' float32 arithmetic)."""
    if eps is None:
        return default_eps(bounds)
    if cls.eps_meaning is None:
        raise ValueError(f"eps: the {cls.name} method cannot honour eps (its resolution sets the offset); "
                         f"leave eps=None")
    eps = non_negative_float("eps", eps)
    limit = MAX_RECEIVER_DISTANCE * bounds_diagonal(bounds)
    if eps > limit:
        raise ValueError(f"eps: {eps:.3g} is more than {MAX_RECEIVER_DISTANCE:.3g} scene sizes ({limit:.3g}), "
                         f"outside the working range")
    return eps


def check_prepare(mesh, light, receiver_bounds, eps):
    """``prepare``'s arguments checked: ``(light, receiver box (2, 3) float64)``; named errors otherwise."""
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected a Mesh, got {type(mesh).__name__}")
    light = check_light(light)
    box = check_bounds("receiver_bounds", receiver_bounds)
    if not (np.isfinite(eps) and eps >= 0):
        raise ValueError(f"eps: must be a finite non-negative distance, got {eps!r}")
    return light, box
