"""Many lights: per point, how many lights shadow it (:func:`shadow_counts`), or every light's mask
bit-packed (:func:`shadow_matrix`).

>>> hours = sc.shadow_counts(scene, suns, sensors, weights=np.full(len(suns), 1.0))   # float64 (N,)
>>> bits = sc.shadow_matrix(scene, suns, sensors)          # uint8 (L, ceil(N / 8)), np.packbits order
>>> np.unpackbits(bits, axis=1, count=len(sensors)).astype(bool)[k]   # light k's mask

The one per-light loop of the package is :class:`LightLoop`: what does not depend on the light is done
once (the receivers checked once; the method and its device-side mesh prepared once through
:func:`shadowcl.prepare`), then each light is one :meth:`Shadows.relight` and one query. Lights go in
batches of ``batch`` (:data:`BATCH`); a batch's counts are summed in light order and the batches' sums
in a fixed binary tree (:class:`PairwiseSum`), so the local run and a Dask run (:mod:`shadowcl.distributed`,
``client=``, where the tree's sums are tasks on the workers) add the same numbers in the same order and
agree bit for bit, whatever worker ran a batch.
"""

from __future__ import annotations

import operator

import numpy as np

from .checks import positive_int
from .device import get_device
from .lights import DirectionalLight, PointLight, check_light
from .methods import as_mesh, method_class, resolve_eps, with_light_count, with_receiver_count
from .points import Points, check_points
from .shadows import Shadows

BATCH = 16   # lights per batch: a Dask task's unit of work and of loss when a worker dies


class PairwiseSum:
    """Parts added in a fixed binary tree, fed one at a time: parts 0+1, 2+3, ..., then those sums in
    pairs, an odd one carried up; at most log2(parts) partial sums are held. ``add`` makes the sum of
    two items: ``operator.add`` on arrays here, a task on a cluster (``distributed.py``), the same tree."""

    def __init__(self, add=operator.add):
        self._add = add
        self._stack: list[tuple[int, object]] = []     # (parts summed, their sum), sizes decreasing

    def add(self, part) -> None:
        size = 1
        while self._stack and self._stack[-1][0] == size:
            _, left = self._stack.pop()
            part, size = self._add(left, part), 2 * size
        self._stack.append((size, part))

    def total(self):
        """The sum of every part so far (the pending partial sums joined from the right)."""
        if not self._stack:
            raise ValueError("PairwiseSum: no parts")
        total = self._stack[-1][1]
        for _, left in reversed(self._stack[:-1]):
            total = self._add(left, total)
        return total


class LightLoop:
    """One method prepared once for a scene and a fixed set of receivers, then relit light by light.

    ``receivers`` is a checked :class:`~shadowcl.points.Points`; ``eps`` as the caller gave it (None: the
    default of the scene's bounds, the same in every process). :meth:`masks` yields each
    light's bool mask; :meth:`counts` sums them, weighted, as float64.
    """

    def __init__(self, scene_or_mesh, receivers: Points, method: str, eps: float | None, device=None, **params):
        self.scene_or_mesh, self.receivers, self.method = scene_or_mesh, receivers, method
        self.eps, self.device = eps, device
        self.params = with_receiver_count(method, params, len(receivers))
        self._shadows: Shadows | None = None

    def masks(self, lights):
        """bool (N,) per light of ``lights``, in order (the structure built for the first light, then relit)."""
        for light in lights:
            if self._shadows is None:
                self._shadows = Shadows(self.scene_or_mesh, light, self.method, self.receivers.bounds,
                                        self.device, self.eps, **self.params)
            else:
                self._shadows.relight(light)
            yield self._shadows.mask(self.receivers)

    def counts(self, lights, weights: np.ndarray) -> np.ndarray:
        """float64 (N,): the sum over ``lights`` of ``weights[k]`` where light k shadows the point."""
        total = np.zeros(len(self.receivers))
        for mask, weight in zip(self.masks(lights), weights):
            total[mask] += weight
        return total

    def packed(self, lights) -> np.ndarray:
        """uint8 (L, ceil(N / 8)): each light's mask, ``np.packbits`` along the points."""
        rows = [np.packbits(mask) for mask in self.masks(lights)]
        return np.array(rows, dtype=np.uint8).reshape(len(rows), -(-len(self.receivers) // 8))


def shadow_counts(scene_or_mesh, lights, points, normals=None, method: str = "exact", weights=None, client=None,
                  progress: bool = False, device=None, eps=None, batch: int = BATCH, **params) -> np.ndarray:
    """Per point, how many of ``lights`` shadow it (or the sum of their ``weights``): float64 (N,).

    ``lights`` is a non-empty sequence of lights of one kind (all :class:`PointLight` or all
    :class:`DirectionalLight`); ``weights`` None (each light counts 1) or one finite number per light
    (e.g. the hours a sun position stands for). ``points``, ``normals``, ``method``, ``device``, ``eps``
    and ``params`` mean what they mean in :func:`shadowcl.shadow_mask`; each light's mask is exactly
    ``sc.shadow_mask``'s. The method is prepared once and relit per light (:class:`LightLoop`).

    ``client``: a ``dask.distributed.Client`` or a scheduler address (extra ``distributed``): the scene
    and receivers are scattered to every worker once and the lights go in batches of ``batch``
    (:mod:`shadowcl.distributed`); the result is the same bit for bit. ``progress`` shows a tqdm bar
    over the lights.
    """
    job = LightJob(scene_or_mesh, lights, points, normals, method, weights, device, eps, batch, params, client)
    return job.run("counts", client, progress)


def shadow_matrix(scene_or_mesh, lights, points, normals=None, method: str = "exact", client=None,
                  progress: bool = False, device=None, eps=None, batch: int = BATCH, **params) -> np.ndarray:
    """Every light's shadow mask, bit-packed: uint8 (L, ceil(N / 8)), row k is
    ``np.packbits(sc.shadow_mask(scene_or_mesh, lights[k], points, normals, ...))``.

    Arguments as :func:`shadow_counts` (without ``weights``). ``np.unpackbits(matrix, axis=1,
    count=N).astype(bool)`` gives the (L, N) masks back.
    """
    job = LightJob(scene_or_mesh, lights, points, normals, method, None, device, eps, batch, params, client)
    return job.run("packed", client, progress)


class LightJob:
    """The arguments of a many-lights call, checked once, and its batches run here or on a cluster."""

    def __init__(self, scene_or_mesh, lights, points, normals, method, weights, device, eps, batch, params,
                 client=None):
        self.lights = check_lights(lights)
        self.weights = check_weights(weights, len(self.lights))
        self.receivers = check_points(points, normals)
        mesh = as_mesh(scene_or_mesh)
        cls = method_class(method)
        # bad parameters raise here, before any work: names always; values need an instance (exact's and
        # angular's constructors read their device), so for a cluster run the workers' first batch checks
        # them, and no device (all of PoCL's threads) is made in the client's process
        if client is None:
            cls(get_device(device), **params)
        else:
            cls.check_parameter_names(params)
        self.scene_or_mesh, self.method, self.device = scene_or_mesh, cls.name, device
        self.params = with_light_count(cls.name, params, len(self.lights))
        resolve_eps(cls, eps, mesh.bounds)                     # a bad eps raises here; None stays None, so
        self.eps = eps                                         # that a method refusing an eps gets none
        self.batch = positive_int("batch", batch)

    def batches(self) -> list[slice]:
        return [slice(lo, min(lo + self.batch, len(self.lights))) for lo in range(0, len(self.lights), self.batch)]

    def empty(self, kind: str) -> np.ndarray:
        if kind == "counts":
            return np.zeros(len(self.receivers))
        return np.zeros((len(self.lights), -(-len(self.receivers) // 8)), dtype=np.uint8)

    def run(self, kind: str, client, progress: bool) -> np.ndarray:
        result = self.empty(kind)
        if len(self.receivers) == 0:
            return result
        if client is not None:
            from .distributed import run_on_cluster
            return run_on_cluster(self, kind, client, progress)
        loop = LightLoop(self.scene_or_mesh, self.receivers, self.method, self.eps, self.device, **self.params)
        tree = PairwiseSum()
        with _bar(progress, len(self.lights)) as bar:
            for span in self.batches():
                part = run_batch(loop, kind, self.lights[span], self.weights[span])
                if kind == "counts":
                    tree.add(part)
                else:
                    result[span] = part
                bar.update(span.stop - span.start)
        return tree.total() if kind == "counts" else result


def run_batch(loop: LightLoop, kind: str, lights, weights) -> np.ndarray:
    """One batch of lights on ``loop``: its weighted counts or its packed masks."""
    return loop.counts(lights, weights) if kind == "counts" else loop.packed(lights)


def check_lights(lights) -> list:
    """``lights`` as a non-empty list of lights of one kind; named errors otherwise."""
    if isinstance(lights, (PointLight, DirectionalLight)):
        raise TypeError("lights: expected a sequence of lights, got a single light (wrap it in a list)")
    try:
        lights = list(lights)
    except TypeError:
        raise TypeError(f"lights: expected a sequence of lights, got {type(lights).__name__}") from None
    if not lights:
        raise ValueError("lights: expected at least one light, got none")
    for index, light in enumerate(lights):
        try:
            check_light(light)
        except TypeError as error:
            raise TypeError(f"lights[{index}]: {error}") from None
    kinds = {type(light).__name__ for light in lights}
    if len(kinds) > 1:
        raise ValueError(f"lights: expected lights of one kind, got a mix of {', '.join(sorted(kinds))}")
    return lights


def check_weights(weights, count: int) -> np.ndarray:
    """float64 (count,) weights, ones when None; named errors for a wrong length or non-finite values."""
    if weights is None:
        return np.ones(count)
    try:
        array = np.asarray(weights, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"weights: expected one number per light, got {type(weights).__name__}") from None
    if array.shape != (count,):
        raise ValueError(f"weights: expected shape ({count},), one per light, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"weights: must be finite (first bad at index {int(np.flatnonzero(~np.isfinite(array))[0])})")
    return array


def _bar(progress: bool, total: int):
    from tqdm import tqdm
    return tqdm(total=total, desc="lights", unit="light", disable=not progress, leave=False)
