"""``method="auto"``: the cheapest method and settings whose error meets a budget, on the caller's receivers.

>>> mask = sc.shadow_mask(mesh, light, points, normals, method="auto", max_error=1e-3)
>>> shadows = sc.prepare(mesh, light, method="auto", bounds=box, receivers=points)
>>> shadows.params["chosen"], shadows.stats["calibration"]

How the choice is made (:meth:`AutoMethod.prepare`):

1. The exact method is prepared once for the whole receiver box: it is the ruler, and the answer when
   nothing cheaper qualifies (so "auto" never prepares exact twice).
2. The calibration sample: a seeded uniform random sample, with replacement, of the caller's own
   receivers (``receivers=``: points, with their normals or their absence) -- every receiver has the
   same weight, so the sample's error rate estimates the error over all of them. Its size comes from
   the budget (:func:`shadowcl.lod.sample_size`); when that is more than :data:`SAMPLE_SHARE` of the
   receivers (few receivers, or a tight budget: 1e-4 needs 174 k), the calibration would cost more than
   any candidate can save, and exact is chosen at once. Without ``receivers``
   (``sc.prepare`` with bounds only) the sample is uniform in the bounds, and ``params`` says so.
   A spatially stratified sample was measured too costly for the 1.3x bar: keying and sorting 1.2 M
   receivers by cell took 0.24-0.54 s, 35-75 % of exact's whole call on the loaded test machine.
3. Exact classifies the sample (the truth) and its time per receiver is measured; candidates
   (:data:`CANDIDATES`) are tried in order of their predicted cost, each prepared for the receiver box,
   timed and measured on the sample. A candidate passes when the one-sided 99 % Clopper-Pearson upper
   bound of its error rate (:func:`shadowcl.lod.upper_bound`) is within ``max_error``, and it is chosen
   when its predicted time on all receivers is also below :data:`CHOICE_MARGIN` of exact's (the
   prediction scales the sample's time by N / n and by how that scaling held on this device before,
   :data:`_SCALING`). The search stops at the first chosen, and skips any trial predicted to push the
   calibration's spending past :data:`OVERHEAD_SHARE` of exact's predicted time (or past ``max_time``)
   or unable to beat exact: exact answers then, so the overhead over exact is bounded by about that
   share plus one trial, and reported (``stats["calibration"]``: ``seconds``, ``trials_s``).

A candidate that refuses the query (a method that cannot take the light) is skipped and listed so.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .checks import non_negative_float, positive_float, positive_int
from .frame import check_clearance, is_distant, union
from .methods import Method, method_class, with_receiver_count
from .points import BOUNDS_SLACK, Points, check_points

DEFAULT_MAX_ERROR = 1e-3
PASS_SHARE = 0.5            # sample sized so that a candidate at half the budget passes (lod.sample_size)
OVERHEAD_SHARE = 0.1        # calibration may spend this share of exact's predicted time on trials
SAMPLE_SHARE = 0.05         # a sample above this share of the receivers costs more than a candidate can save
BOUNDS_RECEIVERS = 1_000_000  # receivers assumed by a prepare without receivers or expected_receivers
SAMPLE_SEED = 20261202
MIN_SAMPLE = 4000           # at 1e-2 a candidate at half the budget (20 of 4 k wrong) passes, bound 0.83 %;
                            # lod's 20 k floor cost 4-8 % of exact's time here
SCALING_RECEIVERS = 200_000  # a query this large measures how the sample's time extrapolates
CHOICE_MARGIN = 0.7         # a candidate is chosen only when predicted below this share of exact's time
# A method's time on all N receivers over its sample time scaled by N / n, as last measured on a device
# ({(device id, method): factor}); 1 until measured. Measured at 1.2 M vs 20 k receivers: exact 0.75
# (its cell binning amortises), shadow maps with the plane bias 1.3-2 (their sample was 2x optimistic).
_SCALING: dict = {}
# A candidate's measured (prepare / exact's prepare, time on all / exact's) on a device, by (device id,
# method, settings): it replaces the priors of CANDIDATES for the next calls. The priors alone let a
# shadow-volume trial on the 69 k-triangle bunny cost 1-2x exact's whole call (auto/exact 2.3-3.1).
_COSTS: dict = {}

# (method, parameters, prior prepare cost / exact's, prior per-receiver cost / exact's). The priors only
# order the trials and gate them before they are measured; they are medians measured on this project's
# test machine (torus, spheres, CSG box on a ground quad, 1.2 M receivers; shadow maps with the plane bias
# of main), rounded, not tuned to any result.
CANDIDATES = (
    ("shadow_volume", {}, 0.2, 0.7),
    ("shadow_map", {"resolution": 512}, 1.0, 1.0),
    ("angular", {}, 2.5, 0.8),
    ("shadow_map", {"resolution": 1024}, 1.5, 1.5),
    ("shadow_map", {"resolution": 2048}, 3.0, 2.0),
    ("shadow_map", {"resolution": 4096}, 15.0, 2.5),
)


def calibration_receivers(given) -> Points | None:
    """The ``receivers=`` parameter checked: None, a ``Points``, points (N, 3) or ``(points, normals)``."""
    if given is None or isinstance(given, (Points, FramedReceivers)):
        return given
    return check_points(*given) if isinstance(given, tuple) and len(given) == 2 else check_points(given)


def calibration_sample(receivers: Points, count: int, seed: int = SAMPLE_SEED) -> Points:
    """``count`` of ``receivers`` drawn uniformly with replacement (seeded: independent draws, so the
    wrong ones are binomial, as Clopper-Pearson assumes; 2 ms where drawing 174 k of 1.2 M without
    replacement took 60 ms), their normals with them."""
    rng = np.random.default_rng(seed)
    return receivers.subset(np.sort(rng.integers(0, len(receivers), size=count)))


@dataclass(frozen=True, eq=False)
class FramedReceivers:
    """The caller's receivers (``world``, a ``Points``) as a method in the working ``frame`` sees them
    (:class:`shadowcl.Shadows` hands them so), moved there only as they are drawn from: moving all
    1.2 M took 40 ms, ~13 % of exact's call, for a sample of a few thousand."""

    world: Points
    frame: object

    def __len__(self) -> int:
        return len(self.world)

    @property
    def normals(self):
        return self.world.normals

    @property
    def bounds(self) -> np.ndarray:
        return self.frame.points(self.world.bounds)

    @property
    def positions(self) -> np.ndarray:
        return self.frame.receivers(self.world).positions

    def subset(self, index) -> Points:
        return self.frame.receivers(self.world.subset(index))


def bounds_sample(bounds: np.ndarray, count: int, seed: int = SAMPLE_SEED) -> Points:
    """``count`` points uniform in the box ``bounds``, without normals (seeded)."""
    rng = np.random.default_rng(seed)
    return check_points(bounds[0] + rng.random((count, 3)) * (bounds[1] - bounds[0]))


def _timed_classify(instance: Method, sample: Points) -> tuple[np.ndarray, float]:
    """``instance``'s answer on ``sample`` and the faster of two timed runs: one 20 k-receiver run on
    the loaded 2-core test machine varied 3x between calls (a first run after prepare pays set-up)."""
    seconds = []
    for _ in range(2):
        clock = time.perf_counter()
        answer = instance.classify(sample)
        seconds.append(time.perf_counter() - clock)
    return answer, min(seconds)


class AutoMethod(Method):
    """The cheapest candidate within ``max_error`` on the caller's receivers (module docstring)."""

    name = "auto"
    point_light_reach = method_class("exact").point_light_reach   # the ruler's and fallback's limits
    min_light_clearance = method_class("exact").min_light_clearance
    parameters = {
        "max_error": (DEFAULT_MAX_ERROR, "largest fraction of receivers that may be classified unlike the exact "
                                         "method, with 99 % confidence"),
        "max_time": (None, "seconds the calibration may spend trying candidates (None: bounded by exact's "
                           "predicted time only)"),
        "receivers": (None, "the receivers to calibrate on: points (N, 3), (points, normals) or a Points; "
                            "shadow_mask and render pass theirs; None: a sample of the receiver bounds"),
        "expected_receivers": (None, "how many receivers the answers will cover (None: len(receivers))"),
    }

    def __init__(self, device, **params):
        super().__init__(device, **params)
        p = self.params
        self.max_error = non_negative_float("max_error", p["max_error"])
        if self.max_error >= 1:
            raise ValueError(f"max_error: must be below 1 (a fraction of receivers), got {self.max_error!r}")
        self.max_time = None if p["max_time"] is None else positive_float("max_time", p["max_time"])
        self.receivers = calibration_receivers(p["receivers"])
        expected = p["expected_receivers"]
        self.expected = None if expected is None else positive_int("expected_receivers", expected)
        self.chosen: Method | None = None
        self._exact: Method | None = None
        self._chosen_params: dict = {}
        self._bounds = None
        self._sample_rate = None     # the chosen method's seconds per receiver on the calibration sample

    # choice --------------------------------------------------------------------------------------------
    def prepare(self, occluders, light, receiver_bounds, eps: float) -> None:
        from .lod import sample_size, upper_bound

        start = time.perf_counter()
        box = np.asarray(receiver_bounds, dtype=np.float64)
        self._bounds = box
        total = self.expected or (len(self.receivers) if self.receivers is not None else BOUNDS_RECEIVERS)
        needed = sample_size(self.max_error, PASS_SHARE, MIN_SAMPLE)
        exact_cls = method_class("exact")
        self._exact = exact_cls(self.device, **with_receiver_count("exact", {}, total))
        clock = time.perf_counter()
        self._exact.prepare(occluders, light, box, eps)
        self.device.queue.finish()
        exact_prepare = time.perf_counter() - clock
        tried = []
        calibration = {"max_error": self.max_error, "receivers": total, "sample": 0, "source": None,
                       "exact_prepare_s": exact_prepare, "trials_s": 0.0, "tried": tried}
        self.chosen, self._chosen_params = self._exact, {"method": "exact"}
        if needed > SAMPLE_SHARE * total:
            calibration["source"] = (f"none: the budget needs {needed:,} sample receivers, more than "
                                     f"{SAMPLE_SHARE:.0%} of {total:,}, so exact answers")
        else:
            if self.receivers is None:
                sample = bounds_sample(box, needed)
                calibration["source"] = "uniform in the receiver bounds (no receivers given), no normals"
            else:
                sample = calibration_sample(self.receivers, needed)
                calibration["source"] = (f"uniform sample of the caller's {len(self.receivers):,} receivers, "
                                         f"{'with' if sample.normals is not None else 'without'} normals")
            calibration["sample"] = len(sample)
            truth, exact_seconds = _timed_classify(self._exact, sample)
            self._sample_rate = exact_seconds / len(sample)
            exact_rate = exact_seconds / len(sample) * self._scaling("exact")
            exact_remaining = total * exact_rate             # exact's cost still to pay on all receivers
            allowance = OVERHEAD_SHARE * (exact_prepare + exact_remaining)
            if self.max_time is not None:
                allowance = min(allowance, self.max_time)
            calibration["exact_predicted_s"] = exact_prepare + exact_remaining
            spent = 0.0
            candidates = [(name, settings, *_COSTS.get(self._cost_key(name, settings), priors))
                          for name, settings, *priors in CANDIDATES]
            order = sorted(candidates, key=lambda c: c[2] * exact_prepare + total * c[3] * exact_rate)
            for name, settings, prior_prepare, prior_rate in order:
                trial = prior_prepare * exact_prepare + len(sample) * prior_rate * exact_rate
                if spent + trial > allowance or trial + total * prior_rate * exact_rate >= exact_remaining:
                    tried.append({"method": name, **settings, "skipped": "predicted too slow to beat exact"})
                    continue
                record, instance = self._trial(name, settings, occluders, light, box, eps, sample, truth, total)
                spent += record["trial_s"]
                tried.append(record)
                if "error" not in record:
                    continue
                _COSTS[self._cost_key(name, settings)] = (record["prepare_s"] / max(exact_prepare, 1e-9),
                                                         record["predicted_s"] / max(exact_remaining, 1e-12))
                record["upper_bound"] = upper_bound(record["wrong"], len(sample))
                record["passes"] = record["upper_bound"] <= self.max_error
                if record["passes"] and record["predicted_s"] < CHOICE_MARGIN * exact_remaining:
                    self.chosen, self._chosen_params = instance, {"method": name, **instance.resolved_params()}
                    self._sample_rate = record["sample_s"] / len(sample)
                    calibration.update(error=record["error"], upper_bound=record["upper_bound"])
                    break
            if self.chosen is self._exact:
                calibration.update(error=0.0, upper_bound=0.0)
            calibration["trials_s"] = spent
        calibration["seconds"] = time.perf_counter() - start
        self.stats = {"chosen": self._chosen_params["method"], "calibration": calibration,
                      "device_bytes": self.chosen.stats.get("device_bytes", 0)}

    def _trial(self, name, settings, occluders, light, box, eps, sample, truth, total):
        """Prepare candidate ``name`` with ``settings``, classify the sample: (record, instance or None)."""
        record = {"method": name, **settings}
        cls = method_class(name)
        instance = cls(self.device, **with_receiver_count(name, settings, total))
        start = time.perf_counter()
        try:
            # the light as the public calls would judge it for this method (Shadows did it for exact's)
            check_clearance(occluders, light, cls.min_light_clearance, name)
            if is_distant(light, union(occluders.bounds, box), cls.point_light_reach):
                raise ValueError(f"light: beyond the {name} method's point_light_reach")
            instance.prepare(occluders, light, box, eps)
            self.device.queue.finish()
        except ValueError as error:          # the method cannot answer this query (e.g. refuses the light)
            record.update(refused=str(error), trial_s=time.perf_counter() - start)
            return record, None
        record["prepare_s"] = time.perf_counter() - start
        answer, record["sample_s"] = _timed_classify(instance, sample)
        wrong = int(np.count_nonzero(answer != truth))
        record.update(wrong=wrong, error=wrong / len(sample),
                      predicted_s=total * record["sample_s"] / len(sample) * self._scaling(name),
                      trial_s=time.perf_counter() - start)
        return record, instance

    def _cost_key(self, name: str, settings: dict) -> tuple:
        return id(self.device), name, tuple(sorted(settings.items()))

    def _scaling(self, method: str) -> float:
        return _SCALING.get((id(self.device), method), 1.0)

    # queries -------------------------------------------------------------------------------------------
    def classify(self, points, normals=None) -> np.ndarray:
        start = time.perf_counter()
        answer = self._classify(check_points(points, normals))
        if self._sample_rate and len(answer) >= SCALING_RECEIVERS:     # learn how the sample's rate extrapolates
            measured = (time.perf_counter() - start) / (len(answer) * self._sample_rate)
            _SCALING[(id(self.device), self._chosen_params["method"])] = measured
        return answer

    def _classify(self, receivers: Points) -> np.ndarray:
        if not self.chosen.bounded:
            return self.chosen.classify(receivers)
        # a bounded candidate (one shadow-map view) is right inside the prepared box only: exact answers the rest
        slack = BOUNDS_SLACK * float(np.linalg.norm(self._bounds[1] - self._bounds[0]))
        p = receivers.positions
        outside = np.any((p < self._bounds[0] - slack) | (p > self._bounds[1] + slack), axis=1)
        if not outside.any():
            return self.chosen.classify(receivers)
        answer = self._exact.classify(receivers) if outside.all() else np.empty(len(receivers), dtype=bool)
        if not outside.all():      # (an empty subset with normals trips Points.unit_normals: not asked)
            answer[~outside] = self.chosen.classify(receivers.subset(~outside))
            answer[outside] = self._exact.classify(receivers.subset(outside))
        return answer

    def resolved_params(self) -> dict:
        """The budget and the choice: ``chosen`` is the method and its parameters as used."""
        source = None if self.receivers is None else f"{len(self.receivers):,} receivers"
        return {"max_error": self.max_error, "max_time": self.max_time, "receivers": source,
                "expected_receivers": self.expected, "chosen": dict(self._chosen_params)}
