"""The public shadow queries: :func:`prepare` once, then :meth:`Shadows.mask` any number of times;
:func:`shadow_mask` is the one-shot call over them.

>>> shadows = sc.prepare(mesh, light, method="exact", bounds=box)   # the light-space structure, once
>>> mask = shadows.mask(points, normals)                            # bool (N,), True = in shadow
>>> shadows.stats["prepare_s"], shadows.stats["classify_s"]         # seconds, one schema for every method
"""

from __future__ import annotations

import copy
import dataclasses
import time

import numpy as np

from .checks import check_bounds
from .device import get_device
from .frame import check_clearance, frame_for, is_distant, union
from .geometry import bounds_diagonal
from .lights import PointLight, check_light
from .methods import as_mesh, method_class, occluders, resolve_eps, with_receiver_count, with_receivers
from .points import BOUNDS_SLACK, Points, check_points

NEAR = 1.0   # occluder box diagonals round the occluders' box: a bounded method's structure covers them,
             # and receivers beyond them are answered from where their segment enters the box (_answer_far)
CLIP_PAD = 2.0 ** -10   # of the occluders' diagonal, outside their box, where a far receiver's segment is clipped
ANSWER_DTYPES = {"classify": bool, "visibility": np.float32}   # of Shadows.mask and Shadows.visibility


class Shadows:
    """One method prepared for one scene and light: query it with :meth:`mask` and :meth:`visibility`.

    Made by :func:`prepare`. Attributes: ``method`` (its name), ``light``, ``eps`` (absolute),
    ``bounds`` ((2, 3) the receivers' box the structure is fitted to), ``params`` (every parameter as resolved from the
    scene: what a None default became), ``stats`` (``prepare_s``, ``classify_s`` of the last query,
    ``check_s`` its receiver check, ``device_bytes``, ``receivers``, ``outside_bounds`` (None when the
    receivers were checked on the device, as in ``shadow_mask``'s exact call: uncounted), then the
    method's own keys). Points outside ``bounds`` are answered correctly too: a method that cannot
    (a shadow map's single view) answers them from a second structure fitted to them. Such a method's
    structure is fitted to ``bounds`` cut to :data:`NEAR` occluder sizes round the occluders, so that a
    few far receivers never coarsen everyone's map; of the receivers beyond, those whose segment to the
    light misses the occluders' box are lit (nothing can block it), the others get the second structure.

    The method works in the occluders' frame (:mod:`shadowcl.frame`): everything it sees is moved and
    scaled there first, and inputs outside the working range are refused there.
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
        self._mesh = mesh
        self._frame = frame_for(mesh, move=not cls.scene_input)
        self._occluders = occluders(cls, scene_or_mesh) if cls.scene_input else self._frame.mesh(mesh)
        self._params = self._copied(params)   # kept for _fitted_to: never the caller's arrays
        self._instance = cls(self._device, **self._params)
        self._prepare_s = self._classify_s = self._check_s = 0.0
        self._outside = 0
        self._receivers = 0
        self._last_framed: tuple[Points, Points] | None = None   # (world, framed): see _framed
        self.relight(self.light)

    def _copied(self, params: dict) -> dict:
        """``params`` deep-copied, with ``receivers`` (what method="auto" and lod="auto" calibrate on)
        moved to the frame like every query's receivers (:class:`shadowcl.points.MovedPoints`: moved as
        they are drawn from, and not copied)."""
        receivers = params.get("receivers")
        copied = copy.deepcopy({key: value for key, value in params.items() if key != "receivers"})
        if receivers is None:
            return copied
        from .auto import calibration_receivers
        return {**copied, "receivers": self._frame.receivers(calibration_receivers(receivers))}

    def relight(self, light) -> None:
        """Build the structure again for another ``light``, on the same method instance: what does not
        depend on the light is kept, and a silhouette tracker has the last light's frame."""
        self.light = check_light(light)
        check_clearance(self._mesh, self.light, self._instance.min_light_clearance, self.method)
        start = time.perf_counter()
        frame = self._frame
        self._fitted_box = self._fit(self.light)
        self._reach = union(self._mesh.bounds, self._fitted_box)   # the box the light is judged distant for
        # Receivers outside the fitted box go to a second structure where the method's own is not meant
        # for them: a bounded method's, or one given the point light as directional for this box.
        self._split = self._instance.bounded or is_distant(self.light, self._reach, self._instance.point_light_reach)
        self._frame_light = self._method_light(self._reach)
        self._true_light = frame.light(self.light, self._reach, limit=np.inf)   # never substituted
        self._instance.prepare(self._occluders, self._frame_light, frame.points(self._fitted_box), frame.length(self.eps))
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
        if kind == "classify" and receivers.box is None and self._checks_on_device():
            return self._mask_checked_on_device(receivers, start)
        framed = self._framed(receivers, receivers is points)
        far = self._far(receivers)
        checked = time.perf_counter()
        if len(far):
            receivers.checked_normals()     # a bad normal named by its index in the caller's array, not a part's
            near = np.ones(len(receivers), dtype=bool)
            near[far] = False
            answer = np.empty(len(receivers), dtype=ANSWER_DTYPES[kind])
            answer[near], outside = self._answer(kind, receivers.subset(near), framed.subset(near))
            answer[far], outside_far = self._answer_far(kind, framed.subset(far))
            outside += outside_far
        else:
            answer, outside = self._answer(kind, receivers, framed)
        if not self._instance.answers_at_the_light:
            answer[self._at_the_light(framed)] = True if kind == "visibility" else False
        self._check_s, self._classify_s = checked - start, time.perf_counter() - start
        self._outside, self._receivers = outside, len(receivers)
        return answer

    def _checks_on_device(self) -> bool:
        """Whether the method answers every receiver it is given and checks their values on the device
        (:meth:`shadowcl.methods.Method.classify_near`), so that a mask needs no host pass over them."""
        instance = self._instance
        return instance.checks_receivers and instance.answers_at_the_light and not self._split

    def _mask_checked_on_device(self, receivers: Points, start: float) -> np.ndarray:
        """:meth:`mask` of receivers whose values the host has not read (``shadow_mask``'s one-shot call)
        by a method that reads them first on the device: the near ones answered there, the ones beyond
        :meth:`_far`'s box returned and answered as :meth:`_query` answers them, after the host checks
        (which then name any bad value with the caller's index). ``outside_bounds`` is not counted (None):
        that needs the receivers' box."""
        frame = self._frame
        answer, far = self._instance.classify_near(frame.receivers(receivers, range_checked_later=True),
                                                   frame.points(self._near_box()))
        checked = time.perf_counter()
        if len(far):
            receivers.bounds                 # the host checks of the values, naming the caller's indices
            receivers.checked_normals()
            answer[far] = self._answer_far("classify", frame.receivers(receivers).subset(far))[0]
        self._check_s, self._classify_s = checked - start, time.perf_counter() - start
        self._outside, self._receivers = None, len(receivers)
        return answer

    def _answer(self, kind: str, world: Points, framed: Points) -> tuple[np.ndarray, int]:
        """The method's answers for receivers near the occluders (``world``, the same ``framed``), and how
        many lay outside the fitted box."""
        outside = self._outside_bounds(world)
        if not (self._split and len(outside)):
            return getattr(self._instance, kind)(framed), len(outside)
        world.checked_normals()             # a bad normal named by its index here, not in a part
        inside = np.ones(len(framed), dtype=bool)
        inside[outside] = False
        beyond = framed.subset(outside)
        answer = np.empty(len(framed), dtype=ANSWER_DTYPES[kind])
        answer[inside] = getattr(self._instance, kind)(framed.subset(inside))
        # Beyond: a segment that misses the occluders' box is lit, unless its normal faces away.
        reaching = self._entry(beyond, self._frame.length(1e-6 * self._frame.extent))[1]
        answer[outside] = self._unreached(kind, beyond.facing_away(self._true_light))
        if np.any(reaching):
            candidates = beyond.subset(reaching)
            far = world.subset(outside[reaching]).bounds
            answer[outside[reaching]] = getattr(self._fitted_to(candidates, far), kind)(candidates)
        return answer, len(outside)

    def _answer_far(self, kind: str, framed: Points) -> tuple[np.ndarray, int]:
        """The answers for (framed) receivers beyond :data:`NEAR` of the occluders: lit where the tested
        segment misses the occluders' box, in shadow where the normal faces away, else the method's answer for the segment's part from where it enters the box padded
        by :meth:`_clip_pad` (the same hits: nothing lies outside the box, and its eps stays outside).
        The float32 methods then start near the occluders: from 3e4 scene sizes on, a start's rounding
        and the sheared coordinates relative to it had lost the triangles' size (docs/known-defects.md)."""
        facing = framed.facing_away(self._true_light)
        answer = self._unreached(kind, facing)
        starts, reaching = self._entry(framed, self._frame.length(self._clip_pad()))
        clipped = np.flatnonzero(reaching & ~facing)
        if len(clipped) == 0:
            return answer, 0
        # back to the world: _answer judges the fitted box (world) as for any receivers
        world = check_points(self._frame.world_points(starts[clipped]))
        answer[clipped], outside = self._answer(kind, world, self._frame.receivers(world))
        return answer, outside

    @staticmethod
    def _unreached(kind: str, facing: np.ndarray) -> np.ndarray:
        """The answers of receivers whose segment meets no occluder: in shadow only where ``facing`` away."""
        return facing if kind == "classify" else (~facing).astype(np.float32)

    def _framed(self, receivers: Points, keep: bool) -> Points:
        """``receivers`` in the frame (which does not change with the light). ``keep``: the caller passed
        checked :class:`Points` (fixed once made: their bounds are computed once), so the framed copy is
        kept and reused while the same object comes back, as from a :class:`~shadowcl.counts.LightLoop`
        relighting for one set of receivers (1.26 M receivers: a float64 N x 3 copy per light saved)."""
        if self._last_framed is not None and self._last_framed[0] is receivers:
            return self._last_framed[1]
        framed = self._frame.receivers(receivers)
        self._last_framed = (receivers, framed) if keep else None
        return framed

    def classify_view(self, view, zbuffer, seen) -> np.ndarray:
        """An ``image_space`` method's mask of the camera's covered pixels (:meth:`Method.classify_view`),
        with the camera's view and receivers moved to the method's frame."""
        frame = self._frame
        self._check_reach(check_points(seen.points))
        framed = frame.view(view)
        return self._instance.classify_view(framed, dataclasses.replace(zbuffer, view=framed),
                                            dataclasses.replace(seen, points=frame.points(seen.points)))

    def _fit(self, light) -> np.ndarray:
        """The (world) box the structure is fitted to. A point light beyond the method's
        ``point_light_reach`` from the occluders, which it cannot resolve, is given to it as directional
        (:mod:`shadowcl.frame`) only for receivers near enough for that to hold; the others get a second
        structure, fitted to them, for which the light is within reach. The near part is the receivers' box
        cut per axis to a margin round the occluders' box, joined to the box where far receivers'
        segments are clipped (:meth:`_answer_far`); while the light is not distant for it, the margin
        of its longest axis is halved (a receiver plane just under the occluders stays in, its wide
        sides are cut)."""
        occluders, limit = self._mesh.bounds, self._instance.point_light_reach
        box = near_box(self.bounds, occluders) if self._instance.bounded else self.bounds
        if not is_distant(light, occluders, limit) or is_distant(light, union(occluders, box), limit):
            return box
        pad = self._clip_pad()
        clipped = occluders + np.array([[-1.0], [1.0]]) * pad
        centre = 0.5 * (occluders[0] + occluders[1])
        margin = np.full(3, np.linalg.norm(light.position - centre) / limit)
        while True:
            cut = np.stack([np.maximum(box[0], occluders[0] - margin), np.minimum(box[1], occluders[1] + margin)])
            fitted = union(clipped, cut) if np.all(cut[0] <= cut[1]) else clipped
            if is_distant(light, fitted, limit):
                return fitted
            wider = np.ptp(fitted, axis=0) - np.ptp(clipped, axis=0)
            if not np.any((wider > 0) & (margin > pad)):
                break
            margin[np.argmax(np.where(margin > pad, wider, -np.inf))] *= 0.5
        return clipped if is_distant(light, clipped, limit) else occluders

    def _method_light(self, reach: np.ndarray):
        """The light as the method gets it (:meth:`shadowcl.frame.Frame.light`) for receivers in ``reach``."""
        return self._frame.light(self.light, reach, self._instance.point_light_reach)

    def _at_the_light(self, receivers: Points) -> np.ndarray:
        """Indices of the (framed) receivers whose tested segment is at most eps long and whose normal (if
        any) faces the light: lit by DESIGN.md's meaning (no hit lies beyond eps), whatever a method's
        projection makes of a point at its eye. Cheap when the light is outside the receivers' box."""
        light, eps = self._true_light, self._frame.length(self.eps)
        if not isinstance(light, PointLight) or len(receivers) == 0 or \
                np.any(light.position < receivers.bounds[0] - 2 * eps) or np.any(light.position > receivers.bounds[1] + 2 * eps):
            return np.zeros(0, dtype=np.int64)
        # Only receivers within 2 eps of the light per axis can qualify (the start is eps from the
        # point): narrowed axis by axis, so the light inside a crowd of receivers costs one column
        # pass, not norms and facing tests of them all (1.2 M receivers: 113 -> ~5 ms).
        near = receivers.near(light.position, 2.0 * eps * (1.0 + 1e-6))
        if len(near) == 0:
            return near
        candidates = receivers.subset(near)
        start = candidates.positions
        if candidates.normals is not None:
            start = start + eps * candidates.unit_normals()
        short = np.linalg.norm(light.position - start, axis=1) <= eps
        return near[short & ~candidates.facing_away(light)]

    def _entry(self, receivers: Points, pad: float) -> tuple[np.ndarray, np.ndarray]:
        """Where the tested segment (ray) of each framed receiver enters the occluders' box widened by
        ``pad`` (frame units), (N, 3), and bool (N,) whether it meets that box at all (slab test in
        float64)."""
        box = self._frame.points(self._mesh.bounds) + np.array([[-1.0], [1.0]]) * pad
        start = receivers.positions
        if receivers.normals is not None:
            start = start + self._frame.length(self.eps) * receivers.unit_normals()
        light = self._true_light
        if isinstance(light, PointLight):
            direction, end = light.position - start, 1.0
        else:
            direction, end = np.broadcast_to(-light.direction, start.shape), np.inf
        with np.errstate(divide="ignore", invalid="ignore"):
            t0, t1 = (box[0] - start) / direction, (box[1] - start) / direction
        low, high = np.fmin(t0, t1), np.fmax(t0, t1)
        # a zero component: inside that slab for every t (nan -> ignored by fmax/fmin) or never
        parallel = direction == 0
        outside_slab = parallel & ((start < box[0]) | (start > box[1]))
        enter = np.fmax(np.max(np.where(parallel, -np.inf, low), axis=1), 0.0)
        leave = np.fmin(np.min(np.where(parallel, np.inf, high), axis=1), end)
        return start + enter[:, None] * direction, (enter <= leave) & ~np.any(outside_slab, axis=1)

    def _clip_pad(self) -> float:
        """How far outside the occluders' box a far receiver's segment is clipped (world units): more than
        eps, so that the clipped start's eps never reaches a triangle, plus :data:`CLIP_PAD` of the box."""
        return 2.0 * self.eps + CLIP_PAD * self._frame.extent

    def _far(self, receivers: Points) -> np.ndarray:
        """Indices of the (world) receivers outside :meth:`_near_box`."""
        return outside_box(receivers, *self._near_box())

    def _near_box(self) -> np.ndarray:
        """The occluders' box widened by :data:`NEAR` occluder diagonals (plus 3 eps), world: a receiver
        beyond it is far, its start outside the box widened by :meth:`_clip_pad`."""
        margin = NEAR * self._frame.extent + 3.0 * self.eps
        return self._mesh.bounds + np.array([[-1.0], [1.0]]) * margin

    def _check_reach(self, receivers: Points) -> None:
        """A point light used as directional for ``bounds`` must stay distant for these receivers too (the
        camera's receivers of an image-space method, which has one structure: no second one for them)."""
        limit = self._instance.point_light_reach
        if len(receivers) and is_distant(self.light, self._reach, limit) \
                and not is_distant(self.light, union(self._reach, receivers.bounds), limit):
            raise ValueError(f"points: the light was used as a directional light for receivers in {self.bounds.tolist()}; "
                             f"these reach {receivers.bounds.tolist()}, where it is not parallel enough: "
                             f"prepare with bounds covering them")

    def _outside_bounds(self, receivers: Points) -> np.ndarray:
        """Indices of the receivers outside the box the structure is fitted to (with :data:`BOUNDS_SLACK`)."""
        box = self._fitted_box
        slack = BOUNDS_SLACK * max(bounds_diagonal(box), np.finfo(np.float32).tiny)
        return outside_box(receivers, box[0] - slack, box[1] + slack)

    def _fitted_to(self, receivers: Points, world_box: np.ndarray):
        """A second instance of the method, prepared for the box of (framed) ``receivers`` (outside the
        fitted box; ``world_box`` theirs in the world, for the light's judgement)."""
        instance = type(self._instance)(self._device, **self._params)
        instance.prepare(self._occluders, self._method_light(union(self._mesh.bounds, world_box)), receivers.bounds,
                         self._frame.length(self.eps))
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


def outside_box(receivers: Points, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Indices of ``receivers`` outside the box (``low``, ``high``); cheap (their bounds) when none is."""
    if len(receivers) == 0 or (np.all(receivers.bounds[0] >= low) and np.all(receivers.bounds[1] <= high)):
        return np.zeros(0, dtype=np.int64)
    p = receivers.positions
    return np.flatnonzero(np.any((p < low) | (p > high), axis=1))


def near_box(bounds: np.ndarray, occluders: np.ndarray) -> np.ndarray:
    """``bounds`` cut to :data:`NEAR` diagonals round the box ``occluders``; ``bounds`` itself when they
    do not meet (every receiver is then answered by the second structure or as lit)."""
    margin = NEAR * bounds_diagonal(occluders)
    low, high = np.maximum(bounds[0], occluders[0] - margin), np.minimum(bounds[1], occluders[1] + margin)
    return np.stack([low, high]) if np.all(low <= high) else bounds


def prepare(scene_or_mesh, light, method: str = "exact", bounds=None, device=None, eps=None, **params) -> Shadows:
    """Build ``method``'s structure for the occluders of ``scene_or_mesh`` (a :class:`Mesh`, a
    :class:`Scene` or a subdivision surface) seen from ``light``, once; query it with
    :meth:`Shadows.mask` / :meth:`Shadows.visibility`.

    ``bounds`` ((2, 3) low and high corners) is the receivers' box the structure is fitted to; None
    means the scene's bounds. ``eps`` is absolute when given, else 1e-4 of the scene's bounding-box
    diagonal. ``device`` is a :class:`Device`, a selector string or None (the default device).
    ``params`` are the method's parameters (:func:`shadowcl.methods`). ``method="auto"``
    (:mod:`shadowcl.auto`) picks the cheapest method within ``max_error`` of the exact one, calibrated on
    ``receivers=`` (:func:`shadow_mask` and the renderer pass theirs; without them, on the bounds).
    """
    return Shadows(scene_or_mesh, light, method, bounds, device, eps, **params)


def shadow_mask(scene_or_mesh, light, points, normals=None, method: str = "exact", device=None, eps=None,
                **params) -> np.ndarray:
    """Which of ``points`` are in shadow: bool (N,), True = in shadow.

    Exactly ``prepare(scene_or_mesh, light, method, bounds=<the points' box>, ...).mask(points, normals)``
    (and the receiver count sizes the method's grid). ``normals`` (N, 3) of any non-zero length: a point
    whose normal faces away from the light is in shadow, and its segment starts ``eps`` along it.
    A method that checks the points on the device (the exact one, with doubles) is fitted to the
    occluders' box instead when the light is not distant from it: its answers do not depend on the box,
    and the points' box is a host pass over them (1.2 M points: 3-5 ms) that the call then never makes.
    """
    receivers = check_points(points, normals, box=False)
    if len(receivers) == 0:
        check_light(light)
        as_mesh(scene_or_mesh)
        method_class(method)(get_device(device), **params)   # bad parameters still raise
        return np.zeros(0, dtype=bool)
    params = with_receivers(method, with_receiver_count(method, params, len(receivers)), receivers)
    bounds = None if _fits_to_occluders(scene_or_mesh, light, method, device) else receivers.bounds
    return prepare(scene_or_mesh, light, method, bounds, device, eps, **params).mask(receivers)


def _fits_to_occluders(scene_or_mesh, light, method: str, device) -> bool:
    """Whether ``shadow_mask`` can fit ``method``'s structure to the occluders' box rather than the points':
    the method checks the points on the device (their box is then never computed), answers every point
    the same whatever box it was fitted to (unless a point light is so distant that the box decides where
    it is taken as directional: :meth:`Shadows._fit`), and places any point as cheaply."""
    cls = method_class(method)
    if not cls.checks_receivers_on(get_device(device)) or cls.bounded:
        return False
    light, box = check_light(light), as_mesh(scene_or_mesh).bounds
    return not is_distant(light, box, cls.point_light_reach) and cls.places_any_point(light, box)
