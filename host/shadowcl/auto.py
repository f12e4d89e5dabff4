"""``method="auto"``: the cheapest method and settings whose error meets a budget, on the caller's receivers.

>>> mask = sc.shadow_mask(mesh, light, points, normals, method="auto", max_error=1e-3)
>>> shadows = sc.prepare(mesh, light, "auto", bounds=box, receivers=points)
>>> shadows.params["chosen"], shadows.stats["calibration"]

How the choice is made (:meth:`AutoMethod.prepare`):

1. The exact method is prepared once for the whole receiver box: it is the ruler, and the answer when
   nothing cheaper qualifies (so "auto" never prepares exact twice).
2. The calibration sample (:func:`calibration_sample`): a seeded sample of the caller's own receivers
   (``receivers=``: points, with their normals or their absence), stratified by their index order, one
   draw per equal slice. Its size comes from the budget (:func:`shadowcl.lod.sample_size`); when that is
   more than :data:`SAMPLE_SHARE` of the receivers (few receivers, or a tight budget: 1e-4 needs 174 k),
   the calibration would cost more than any candidate can save, and exact is chosen at once. Without
   ``receivers`` (``sc.prepare`` with bounds only) the sample is uniform in the bounds, and ``params``
   says so.
3. Costs are predicted before anything is tried, as ratios to exact's: :data:`COST_PRIORS` gives each
   candidate's prepare and query time over exact's, by triangle count, light kind and normals, and
   exact's own prepare over its query; with the receiver count these give each candidate's trial and
   its query of all receivers as shares of exact's one-shot time (:func:`predicted_costs`). The
   priors were measured by ``bench/auto.py --costs`` on perturbed spheres on a ground quad (1.3 k to
   328 k triangles, made in code, none of them from ../shared), 1.2 M receivers, this project's PoCL CPU
   device (``bench/results/auto-costs.md``); on another device the ratios may differ.
4. Exact classifies the sample (the truth); candidates (:data:`CANDIDATES`) are tried in order of their
   predicted trial plus query, each prepared for the receiver box and measured on the sample. A
   candidate is skipped, untried, when auto's predicted whole time with it (exact's prepare, the
   calibration so far, its trial, its query) is not below :data:`CHOICE_MARGIN` of exact's, or when its
   trial would take the calibration's predicted spending past :data:`OVERHEAD_SHARE` of exact's time
   (or past ``max_time``). A tried candidate is chosen when the
   one-sided 99 % Clopper-Pearson upper bound of its sample error (:func:`shadowcl.lod.upper_bound`) is
   within ``max_error``; the search stops at the first chosen.

The choice depends only on the scene, the light, the receivers and the budget: the predictions are
shares of exact's time (this device's speed cancels out) and the sample is seeded, so the same call
chooses the same in a fresh process and after any other calls. Only ``max_time``, a budget in seconds,
reads the clock: it is converted to a share of exact's time through exact's prepare time on this very
call. The measured times of every trial are reported beside their predictions (``stats["calibration"]``:
``seconds``, ``tried``). A candidate that refuses the query (a method that cannot take the light) is
skipped and listed so.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .checks import non_negative_float, positive_float, positive_int
from .frame import check_clearance, is_distant, union
from .lights import DirectionalLight
from .methods import Method, method_class, with_receiver_count
from .points import BOUNDS_SLACK, Points, check_points

DEFAULT_MAX_ERROR = 1e-3
PASS_SHARE = 0.5            # sample sized so that a candidate at half the budget passes (lod.sample_size)
OVERHEAD_SHARE = 0.15       # predicted calibration (exact on the sample, trials) within this share of exact's
                            # time: half the 1.3x bar's margin, the other half for the predictions' errors
SAMPLE_SHARE = 0.05         # a sample above this share of the receivers costs more than a candidate can save
BOUNDS_RECEIVERS = 1_000_000  # receivers assumed by a prepare without receivers or expected_receivers
SAMPLE_SEED = 20261202
MIN_SAMPLE = 4000           # at 1e-2 a candidate at half the budget (20 of 4 k wrong) passes, bound 0.83 %;
                            # lod's 20 k floor cost 4-8 % of exact's time here
CHOICE_MARGIN = 0.7         # a candidate is tried only when auto's whole time with it is predicted below
                            # this share of exact's: measured queries were up to 1.4x their priors
SAMPLE_RATE = 0.5           # a query's time per receiver on the calibration sample over that on all 1.2 M
                            # (the full query also checks and moves 1.2 M points): exact's measured 0.20-1.33,
                            # median 0.58, one 5.7 on 4 k (bench/auto.py --costs, auto-costs-3.md, load 12-15);
                            # the sample is 0.1-2 % of exact's time at any of these rates

# (method, settings) of every candidate, and their cost priors. COST_PRIORS[(light kind, normals)] holds
# per triangle count of COST_TRIANGLES exact's prepare / exact's query, then per candidate (prepare /
# exact's prepare, query / exact's query), medians of 2 interleaved rounds at 1.2 M receivers measured by
# `bench/auto.py --costs` (perturbed spheres on a ground quad, not in ../shared; run 2026-12-02 07:34-07:47
# UTC, load rising from 2 to 10 on 2 cores: a rerun of the smallest sphere, auto-costs-3.md, differed by up
# to 2x). Between the counts the ratios are interpolated in log(triangles), beyond them held at the ends.
CANDIDATES = (
    ("shadow_volume", {}),
    ("shadow_map", {"resolution": 512}),
    ("angular", {}),
    ("shadow_map", {"resolution": 1024}),
    ("shadow_map", {"resolution": 2048}),
    ("shadow_map", {"resolution": 4096}),
)
PRIORS_RECEIVERS = 1_200_000
COST_TRIANGLES = (1_282, 5_122, 20_482, 81_922, 327_682)
COST_PRIORS = {
    ("point", False): {
        "exact": (0.0389, 0.0498, 0.134, 0.163, 0.238),
        "shadow_volume": ((0.08, 0.86), (0.09, 0.85), (0.12, 0.75), (0.48, 0.70), (0.43, 0.68)),
        "shadow_map resolution=512": ((0.38, 0.81), (1.65, 1.06), (0.81, 0.74), (1.07, 0.51), (1.60, 0.34)),
        "angular": ((0.60, 0.67), (1.88, 0.97), (1.54, 1.16), (3.37, 1.37), (4.13, 1.36)),
        "shadow_map resolution=1024": ((2.34, 1.68), (2.32, 1.71), (1.78, 1.27), (1.85, 0.79), (1.75, 0.50)),
        "shadow_map resolution=2048": ((7.66, 2.74), (5.64, 2.70), (2.35, 1.60), (2.46, 1.23), (2.29, 0.54)),
        "shadow_map resolution=4096": ((62.33, 3.39), (42.12, 3.85), (11.05, 2.36), (12.31, 1.46), (7.58, 0.66)),
    },
    ("point", True): {
        "exact": (0.0442, 0.0758, 0.181, 0.208, 0.297),
        "shadow_volume": ((0.04, 0.85), (0.17, 0.98), (0.09, 0.66), (0.42, 0.74), (0.52, 0.83)),
        "shadow_map resolution=512": ((1.26, 1.25), (1.01, 1.27), (0.63, 0.93), (1.12, 0.69), (1.69, 0.54)),
        "angular": ((0.92, 1.02), (1.38, 1.28), (1.65, 1.54), (2.27, 1.10), (4.47, 1.80)),
        "shadow_map resolution=1024": ((1.69, 2.10), (1.63, 2.22), (0.99, 1.81), (1.18, 0.79), (2.06, 0.63)),
        "shadow_map resolution=2048": ((6.00, 3.50), (4.45, 3.22), (2.27, 2.64), (1.77, 1.24), (2.61, 0.92)),
        "shadow_map resolution=4096": ((56.54, 3.45), (44.14, 4.09), (12.48, 3.16), (9.18, 1.49), (9.24, 1.08)),
    },
    ("directional", False): {
        "exact": (0.0197, 0.0546, 0.231, 0.163, 0.216),
        "shadow_volume": ((0.07, 0.81), (0.01, 0.83), (0.00, 1.03), (0.00, 0.75), (0.00, 0.83)),
        "shadow_map resolution=512": ((1.05, 0.90), (0.43, 0.91), (0.19, 1.16), (0.32, 0.64), (0.52, 0.42)),
        "angular": ((1.33, 0.51), (0.85, 0.58), (0.37, 0.69), (1.04, 0.66), (2.03, 0.78)),
        "shadow_map resolution=1024": ((3.80, 1.92), (1.16, 1.71), (0.29, 1.92), (0.63, 1.02), (0.79, 0.56)),
        "shadow_map resolution=2048": ((8.32, 2.56), (3.11, 3.35), (0.87, 2.46), (1.47, 1.33), (1.16, 0.60)),
        "shadow_map resolution=4096": ((56.39, 3.17), (14.53, 3.65), (7.21, 4.71), (4.70, 1.61), (3.97, 0.70)),
    },
    ("directional", True): {
        "exact": (0.0551, 0.0507, 0.127, 0.271, 0.321),
        "shadow_volume": ((0.04, 0.78), (0.02, 0.60), (0.00, 0.68), (0.02, 1.09), (0.00, 0.94)),
        "shadow_map resolution=512": ((0.64, 1.28), (0.50, 0.99), (0.33, 0.81), (0.48, 1.17), (0.53, 0.63)),
        "angular": ((0.56, 0.86), (1.00, 0.76), (0.53, 0.95), (1.40, 1.07), (1.73, 1.09)),
        "shadow_map resolution=1024": ((1.44, 2.22), (1.22, 2.36), (0.70, 1.47), (0.51, 1.39), (0.68, 0.87)),
        "shadow_map resolution=2048": ((4.24, 3.79), (3.99, 3.12), (1.36, 2.35), (1.19, 2.03), (1.24, 0.93)),
        "shadow_map resolution=4096": ((23.52, 5.29), (21.27, 4.53), (8.18, 2.78), (7.95, 3.03), (4.21, 1.12)),
    },
}


def candidate_label(name: str, settings: dict) -> str:
    """``"shadow_map resolution=512"``: a candidate's name in :data:`COST_PRIORS` and in reports."""
    return name + "".join(f" {key}={value}" for key, value in settings.items())


def _interpolated(values, triangles: int) -> float:
    return float(np.interp(np.log(triangles), np.log(COST_TRIANGLES), values))


def predicted_costs(triangles: int, light_kind: str, normals: bool, receivers: int, sample: int) -> dict:
    """Shares of exact's one-shot time on ``receivers`` predicted from :data:`COST_PRIORS`: ``exact_prepare``
    (its prepare's share), ``exact_sample`` (exact classifying the calibration sample of ``sample``
    receivers) and per candidate label ``(trial, query)``: its trial (its prepare and its query of the
    sample) and its query of all receivers. A query's time is taken as proportional to its receivers (the
    priors' were 1.2 M), times :data:`SAMPLE_RATE` on a sample. (A shadow volume builds its cap lists in
    its first query, so its trial is predicted short of them; but its answer is exact's, so a tried volume
    is always chosen and the lists serve its full query, predicted with them.)"""
    priors = COST_PRIORS[(light_kind, bool(normals))]
    ratio = _interpolated(priors["exact"], triangles) * PRIORS_RECEIVERS / receivers   # exact's prepare / query
    prepare_share = ratio / (1 + ratio)
    query_share = 1 - prepare_share
    sample_query = SAMPLE_RATE * sample / receivers        # a sample query over the query of all receivers
    costs = {"exact_prepare": prepare_share, "exact_sample": query_share * sample_query}
    for name, settings in CANDIDATES:
        key = candidate_label(name, settings)
        prepare, query = (_interpolated(values, triangles) for values in zip(*priors[key]))
        costs[key] = (prepare_share * prepare + query_share * query * sample_query, query_share * query)
    return costs


def calibration_receivers(given) -> Points | None:
    """The ``receivers=`` parameter checked: None, a ``Points``, points (N, 3) or ``(points, normals)``."""
    if given is None or isinstance(given, (Points, FramedReceivers)):
        return given
    return check_points(*given) if isinstance(given, tuple) and len(given) == 2 else check_points(given)


def sample_indices(total: int, count: int, seed: int = SAMPLE_SEED) -> np.ndarray:
    """``count`` indices into ``total`` receivers, the k-th uniform in the k-th of ``count`` equal slices of
    [0, total) (jittered systematic sampling): O(count), increasing, seeded.

    Strata are slices of the caller's index order because that costs nothing (keying 1.2 M receivers by a
    spatial cell and sorting them took 0.24-0.54 s, 35-75 % of exact's call) and callers' orders are
    spatially coherent (a camera's pixels in scanlines, points per surface, ground then model): each
    slice is a patch of the scene, so no patch is left out by chance; in a random order it is no worse
    than a uniform sample. Each receiver gets probability count / total in all (proportional allocation,
    a slice edge splitting a receiver's share), so the wrong count's mean is count times the error rate
    over all receivers. The draws are independent Bernoullis of their slices' rates: a Poisson binomial,
    whose tails below its mean are lighter than the binomial's of the same mean (Hoeffding 1956, Thm 4),
    so the Clopper-Pearson bound computed as for a binomial stays conservative (its coverage >= 99 %).
    """
    rng = np.random.default_rng(seed)
    position = (np.arange(count) + rng.random(count)) * (total / count)
    return np.minimum(position.astype(np.int64), total - 1)       # float rounding at the top end


def calibration_sample(receivers: Points, count: int, seed: int = SAMPLE_SEED) -> Points:
    """``count`` of ``receivers`` stratified by index (:func:`sample_indices`), their normals with them."""
    return receivers.subset(sample_indices(len(receivers), count, seed))


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


class AutoMethod(Method):
    """The cheapest candidate within ``max_error`` on the caller's receivers (module docstring)."""

    name = "auto"
    point_light_reach = method_class("exact").point_light_reach   # the ruler's and fallback's limits
    min_light_clearance = method_class("exact").min_light_clearance
    parameters = {
        "max_error": (DEFAULT_MAX_ERROR, "largest fraction of receivers that may be classified unlike the exact "
                                         "method, with 99 % confidence"),
        "max_time": (None, "seconds the calibration's trials may take, as predicted (converted to a share of "
                           "exact's time through exact's prepare on this call; None: OVERHEAD_SHARE of it)"),
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

    # choice --------------------------------------------------------------------------------------------
    def prepare(self, occluders, light, receiver_bounds, eps: float) -> None:
        from .lod import sample_size

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
                       "exact_prepare_s": exact_prepare, "tried": tried}
        self.chosen, self._chosen_params = self._exact, {"method": "exact"}
        normals = self.receivers is not None and self.receivers.normals is not None
        kind = "directional" if isinstance(light, DirectionalLight) else "point"
        costs = predicted_costs(len(occluders.faces), kind, normals, total, needed)
        allowance = OVERHEAD_SHARE
        if self.max_time is not None:           # seconds to a share of exact's time, by its prepare on this call
            allowance = min(allowance, self.max_time * costs["exact_prepare"] / max(exact_prepare, 1e-9))
        calibration.update(allowance=allowance, predicted=0.0)
        if needed > SAMPLE_SHARE * total:
            calibration["source"] = (f"none: the budget needs {needed:,} sample receivers, more than "
                                     f"{SAMPLE_SHARE:.0%} of {total:,}, so exact answers")
        else:
            calibration["source"] = "none: no candidate is predicted to save time here, so exact answers"
            sample = truth = None             # drawn for the first candidate tried
            spent = costs["exact_sample"]
            for name, settings in sorted(CANDIDATES, key=lambda candidate: sum(costs[candidate_label(*candidate)])):
                label = candidate_label(name, settings)
                trial = costs[label][0]
                record = {"method": name, **settings, "predicted": self._predicted(costs, label, spent),
                          "predicted_trial": trial}
                tried.append(record)
                skipped = self._skipped(costs, label, spent, allowance)
                if skipped:
                    record["skipped"] = skipped
                    continue
                if sample is None:
                    sample, calibration["source"] = self._sample(box, needed)
                    clock = time.perf_counter()
                    truth = self._exact.classify(sample)
                    calibration.update(sample=len(sample), exact_sample_s=time.perf_counter() - clock)
                spent += trial
                instance = self._trial(record, settings, occluders, light, box, eps, sample, truth, total)
                if instance is not None and record["passes"]:
                    self.chosen, self._chosen_params = instance, {"method": name, **instance.resolved_params()}
                    calibration.update(error=record["error"], upper_bound=record["upper_bound"])
                    break
            calibration["predicted"] = spent if sample is not None else 0.0
        if self.chosen is self._exact:
            calibration.update(error=0.0, upper_bound=0.0)
        calibration["seconds"] = time.perf_counter() - start
        self.stats = {"chosen": self._chosen_params["method"], "calibration": calibration,
                      "device_bytes": self.chosen.stats.get("device_bytes", 0)}

    def _sample(self, box, count: int) -> tuple[Points, str]:
        """The calibration sample of ``count`` receivers and where it came from."""
        if self.receivers is None:
            return bounds_sample(box, count), "uniform in the receiver bounds (no receivers given), no normals"
        sample = calibration_sample(self.receivers, count)
        return sample, (f"stratified sample of the caller's {len(self.receivers):,} receivers, "
                        f"{'with' if sample.normals is not None else 'without'} normals")

    @staticmethod
    def _predicted(costs: dict, label: str, spent: float) -> float:
        """auto's whole time, as a share of exact's, if candidate ``label`` is tried and chosen after
        ``spent``: exact's prepare (the ruler), the calibration so far, its trial, its query of all."""
        return costs["exact_prepare"] + spent + sum(costs[label])

    def _skipped(self, costs: dict, label: str, spent: float, allowance: float) -> str | None:
        """Why candidate ``label`` is not tried after ``spent`` of the calibration, or None."""
        predicted, trial = self._predicted(costs, label, spent), costs[label][0]
        if predicted >= CHOICE_MARGIN:
            return f"auto would take {predicted:.2f} of exact's time with it, not below {CHOICE_MARGIN}"
        if spent + trial > allowance:
            return f"its trial ({trial:.3f} of exact's time) would take the calibration past {allowance:.3f}"
        return None

    def _trial(self, record, settings, occluders, light, box, eps, sample, truth, total):
        """Prepare candidate ``record["method"]`` with ``settings`` and measure it on ``sample`` against
        ``truth``: its wrong count, error, 99 % bound and whether it passes, and its times, go in ``record``;
        returns the prepared instance, or None when the method refused the query."""
        from .lod import upper_bound

        name = record["method"]
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
            return None
        record["prepare_s"] = time.perf_counter() - start
        answer = instance.classify(sample)
        wrong = int(np.count_nonzero(answer != truth))
        bound = upper_bound(wrong, len(sample))
        record.update(wrong=wrong, error=wrong / len(sample), upper_bound=bound, passes=bound <= self.max_error,
                      trial_s=time.perf_counter() - start)
        return instance

    # queries -------------------------------------------------------------------------------------------
    def classify(self, points, normals=None) -> np.ndarray:
        receivers = check_points(points, normals)
        if not self.chosen.bounded:
            return self.chosen.classify(receivers)
        # a bounded candidate (one shadow-map view) is right inside the prepared box only: exact answers the rest
        slack = BOUNDS_SLACK * float(np.linalg.norm(self._bounds[1] - self._bounds[0]))
        p = receivers.positions
        outside = np.any((p < self._bounds[0] - slack) | (p > self._bounds[1] + slack), axis=1)
        if not outside.any():
            return self.chosen.classify(receivers)
        answer = self._exact.classify(receivers) if outside.all() else np.empty(len(receivers), dtype=bool)
        if not outside.all():
            answer[~outside] = self.chosen.classify(receivers.subset(~outside))
            answer[outside] = self._exact.classify(receivers.subset(outside))
        return answer

    def resolved_params(self) -> dict:
        """The budget and the choice: ``chosen`` is the method and its parameters as used."""
        source = None if self.receivers is None else f"{len(self.receivers):,} receivers"
        return {"max_error": self.max_error, "max_time": self.max_time, "receivers": source,
                "expected_receivers": self.expected, "chosen": dict(self._chosen_params)}
