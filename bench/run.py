"""The bench harness: speed against error of every shadow method, with Embree as peer, in one run.

    python bench/run.py [--quick] [--scenes bunny ogre] [--methods exact embreex] [--repeats 5]
                        [--out bench/results] [--compare OLD.json]

For each scene, light, method and parameter setting (:data:`SWEEP`), a shadowcl method is measured
through the public calls a user makes: a cold ``sc.shadow_mask`` whose mask is checked against the
ground truth (``sc.shadow_mask(..., method="exact")``), one warm-up (also the memory measurement),
the median of ``repeats`` one-shot calls, then ``sc.prepare`` and ``Shadows.mask`` timed apart, and
the one-shot call's host share (:func:`host_share`). A peer (Embree) keeps its own ``prepare`` /
``classify`` protocol. Timing statistics come from ``timing.py``, shared by every bench. Writes
``OUT/STEM.json`` (machine, settings, one row per setting), ``STEM.md`` (table) and ``STEM.png``
(speed against error).
"""

from __future__ import annotations

import argparse
import cProfile
import ctypes
import gc
import itertools
import json
import os
import platform
import pstats
import re
import resource
import sys
from contextlib import contextmanager
from dataclasses import asdict, dataclass, is_dataclass
from functools import cached_property
from datetime import datetime, timezone
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np
import pyopencl as cl
from tqdm import tqdm

import receivers as rx
import report
from peers import PEER, PEERS
import shadowcl as sc
from shadowcl.methods import default_eps, method_class, with_receiver_count
from timing import Timing, clock, interleaved, timed
from shadowcl.geometry import bounds_diagonal
from shadowcl.metrics import mask_error
from shadowcl.reference import exact as reference

# Method name -> {parameter: [values]}; every combination is one row. Peers (peers.PEERS) take part
# like methods. A method with a parameter sweep is one entry, e.g.
#   "shadow_map": {"resolution": [256, 1024, 4096, 8192], "bias": ["constant", "slope", "normal"],
#                  "filter": ["nearest", "bilinear", "pcf"]},
SWEEP = {
    "exact": {},
    "embreex": {"workers": [1, 2]},
    "open3d": {},
    "mitsuba": {},
    # the default settings across resolutions; the full grid (bias x filter at every resolution, 8192
    # included: ~3 GB for a cube) is FULL_SWEEP, run with --full-sweep
    "shadow_map": {"resolution": [256, 1024, 2048, 4096]},
}
FULL_SWEEP = {**SWEEP, "shadow_map": {"resolution": [256, 1024, 2048, 4096, 8192],
                                      "bias": ["constant", "slope", "normal"], "filter": ["nearest", "bilinear", "pcf"]}}
FULL = {"ground": 1_000_000, "model": 200_000}
QUICK = {"ground": 80_000, "model": 20_000}
RESULTS = Path(__file__).resolve().parent / "results"
# Receivers where a peer and the exact truth differ that are judged by the float64 reference (a seeded
# sample beyond this many: the reference's brute force costs ~1 s per 1,000 receivers at 10 k triangles)
MAX_JUDGED = 2000
# Scene diagonals: the band of float32 rounding in which no float32 tool's answer is wrong (the
# reference's tie margin, and how close a segment may pass to a triangle edge)
ROUNDING_BAND = 1e-6
# Seconds slept before each interleaved one-shot call. Mitsuba runs in this process, and its threads keep
# the cores busy for a while after its call returns: measured on the default scene (medians of 9),
# shadowcl's one-shot right after Mitsuba's took 55.2 ms, 0.2 s later 41.6, after its own call 43.5;
# Mitsuba right after shadowcl's 27.5, 0.2 s later 26.6.
SETTLE_S = 0.2
PACKAGES = ("shadowcl", "numpy", "pyopencl", "pocl-binary-distribution", "embreex")  # versions in the report


@dataclass
class Case:
    """One scene under one light with its receivers: what every method of the sweep is run on."""

    scene: rx.BenchScene
    light_index: int
    points: np.ndarray
    normals: np.ndarray
    eps: float

    @property
    def light(self):
        return self.scene.lights[self.light_index]

    @cached_property
    def receiver_bounds(self) -> np.ndarray:
        return np.stack([self.points.min(axis=0), self.points.max(axis=0)])


def settings(grid: dict) -> list[dict]:
    """Every combination of a ``{parameter: [values]}`` grid, as parameter dicts (``{}`` gives ``[{}]``)."""
    names = list(grid)
    return [dict(zip(names, values)) for values in itertools.product(*(grid[n] for n in names))]


def label(method: str, params: dict) -> str:
    """Short name of a setting for tables and plots: ``shadow_map resolution=1024 bias=slope``."""
    return " ".join([method] + [f"{k}={v}" for k, v in params.items()])


def make_peer(name: str, params: dict, peers: dict = PEERS):
    """An unprepared instance of peer ``name`` (a class of ``peers``) with ``params``."""
    return peers[name](**params)


def close(instance) -> None:
    if hasattr(instance, "close"):
        instance.close()


def available(name: str, peers: dict = PEERS) -> str | None:
    """None when method or peer ``name`` can be used, else why not (an import error)."""
    try:
        if name in peers:
            peers[name]()      # a peer imports its library when made
        else:
            method_class(name)
    except ImportError as error:
        return f"{type(error).__name__}: {error}"
    return None


def ground_truth() -> tuple[str, str]:
    """The method whose mask is the truth: ``exact`` once it imports, else Embree; and why."""
    problem = available("exact")
    if problem is None:
        return "exact", "exact method (sc.shadow_mask(..., method='exact'), default parameters)"
    if available(PEER) is not None:
        raise RuntimeError(f"no ground truth: the exact method is not available ({problem}) and neither is embreex")
    return PEER, f"embreex (shadowcl.exact is not available yet: {problem})"


# The public calls, exactly as a user makes them: nothing precomputed but the receivers and eps.
def one_shot(case: Case, method: str, params: dict, device) -> np.ndarray:
    return sc.shadow_mask(case.scene.mesh, case.light, case.points, case.normals, method=method, device=device,
                          eps=case.eps, **params)


def prepared(case: Case, method: str, params: dict, device) -> sc.Shadows:
    # A user who prepares for a known number of receivers says so (the method's expected_receivers), as
    # the one-shot call does for itself: the same grid, so prepare + query is comparable with one-shot.
    params = with_receiver_count(method, params, len(case.points))
    return sc.prepare(case.scene.mesh, case.light, method, bounds=case.receiver_bounds, device=device,
                      eps=case.eps, **params)


def public_steps(occluders, light, method: str, bounds, points, normals=None, device=None, eps=None,
                 **params) -> dict:
    """The steps of a user's prepare-once call for ``timing.timed_steps``: ``sc.prepare`` fitted to
    ``bounds``, then ``Shadows.mask``. The per-paper benches time methods through it."""
    params = with_receiver_count(method, params, len(points))
    return {"prepare": lambda _: sc.prepare(occluders, light, method, bounds=bounds, device=device, eps=eps, **params),
            "query": lambda shadows: shadows.mask(points, normals)}


def peer_run(instance, case: Case, stages: list) -> np.ndarray:
    """The peer's own protocol: ``prepare`` then ``classify``; appends their seconds to ``stages``."""
    prepare_s, _ = clock(lambda: instance.prepare(case.scene.mesh, case.light, case.receiver_bounds, case.eps))
    classify_s, mask = clock(lambda: instance.classify(case.points, case.normals))
    stages.append((prepare_s, classify_s))
    return mask


def truth_mask(case: Case, name: str, device) -> np.ndarray:
    if name != PEER:
        return one_shot(case, name, {}, device)
    instance = make_peer(name, {})
    try:
        return peer_run(instance, case, [])
    finally:
        close(instance)


def _status_kib(field: str) -> int:
    return int(re.search(rf"^{field}:\s+(\d+) kB", Path("/proc/self/status").read_text(), re.MULTILINE).group(1))


@contextmanager
def peak_rss(result: dict):
    """Put the host's peak resident memory above the start of the block, in MiB, into ``result``.

    Freed heap memory is first handed back to the system (glibc's ``malloc_trim``), so that reusing it
    still counts. Linux: the kernel's high-water mark is reset on entry (``/proc/self/clear_refs``) and
    read on exit (``VmHWM``), so native allocations (OpenCL buffers, Embree's BVH) count. Elsewhere:
    the growth of ``ru_maxrss``, a lower bound.
    """
    gc.collect()
    malloc_trim = getattr(ctypes.CDLL(None), "malloc_trim", None)
    if malloc_trim is not None:
        malloc_trim(0)
    try:
        Path("/proc/self/clear_refs").write_text("5")
        base, read = _status_kib("VmRSS"), lambda: _status_kib("VmHWM")
        result["memory_method"] = "VmHWM after reset - VmRSS at start (/proc/self), after malloc_trim"
    except OSError:
        base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        read = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # noqa: E731
        result["memory_method"] = "ru_maxrss growth (lower bound)"
    yield
    result["host_peak_mib"] = max(read() - base, 0) / 1024


# cProfile sees pyopencl's Python wrappers (enqueue_copy, the kernel invokers) but not nanobind's C
# functions called from shadowcl's own code: queue.finish() and Buffer construction. These wrappers give
# them a Python frame of their own while the host share is measured.
_FINISH, _BUFFER = cl.CommandQueue.finish, cl.Buffer


def _finish(queue):
    return _FINISH(queue)


def _buffer(*args, **kwargs):
    return _BUFFER(*args, **kwargs)


_WRAPPERS = {(f.__code__.co_filename, f.__code__.co_firstlineno, f.__code__.co_name) for f in (_finish, _buffer)}


def host_share(call) -> dict:
    """How much of one ``call``'s wall time is spent outside OpenCL calls, by cProfile.

    OpenCL time ("device and driver") is the ``tottime`` of every function of pyopencl (its Python
    wrappers and the generated kernel invokers, whose own time is the C call they make: enqueue, copy,
    wait, build) and of :data:`_WRAPPERS`; host = wall - that. The profiler's own overhead lands in
    host time, so the share is an upper bound.
    """
    profile = cProfile.Profile()
    cl.CommandQueue.finish, cl.Buffer = _finish, _buffer
    try:
        wall, _ = clock(lambda: profile.runcall(call))
    finally:
        cl.CommandQueue.finish, cl.Buffer = _FINISH, _BUFFER
    opencl = sum(tottime for key, (_, _, tottime, _, _) in pstats.Stats(profile).stats.items()
                 if "pyopencl" in key[0] or key in _WRAPPERS)
    return {"host_s": wall - opencl, "host_share": (wall - opencl) / wall, "host_profiled_wall_s": wall}


def method_stats(instance) -> dict | None:
    """What a peer reports about its last run (attribute ``stats``: a dict or a dataclass)."""
    stats = getattr(instance, "stats", None)
    if is_dataclass(stats):
        return asdict(stats)
    return dict(stats) if stats else None


def check_mask(mask, truth: np.ndarray, what: str) -> None:
    if not (isinstance(mask, np.ndarray) and mask.dtype == bool and mask.shape == truth.shape):
        raise TypeError(f"{what} returned {type(mask).__name__} {getattr(mask, 'dtype', '')} "
                        f"{getattr(mask, 'shape', '')}, expected bool {truth.shape}")


def measure_method(case: Case, method: str, params: dict, truth: np.ndarray, repeats: int, device) -> dict:
    """A shadowcl method through the public calls: the one-shot ``sc.shadow_mask`` (cold run checked
    against the truth, a warm-up that measures memory, ``repeats`` timed), then ``sc.prepare`` and
    ``Shadows.mask`` timed apart; the one-shot call's host share."""
    what = f"sc.shadow_mask(method={method!r}, {params})"
    cold_s, mask = clock(lambda: one_shot(case, method, params, device))
    check_mask(mask, truth, what)
    row = {"memory_method": None, "host_peak_mib": None}
    with peak_rss(row):
        one_shot(case, method, params, device)
    oneshot = timed(lambda: one_shot(case, method, params, device), repeats, warmup=0)
    prepare = timed(lambda: prepared(case, method, params, device), repeats)
    shadows = prepare.result
    query = timed(lambda: shadows.mask(case.points, case.normals), repeats)
    check_mask(query.result, truth, f"sc.prepare(method={method!r}, {params}).mask")
    row.update(host_share(lambda: one_shot(case, method, params, device)))
    stats = shadows.stats
    return {"oneshot": oneshot, "prepare": prepare, "query": query, "cold_s": cold_s, "mask": mask,
            "prepared_wrong": int(np.count_nonzero(query.result != truth)), "resolved_params": shadows.params,
            "stats": stats, "device_bytes": stats["device_bytes"], **row}


def measure_peer(case: Case, name: str, params: dict, truth: np.ndarray, repeats: int, peers: dict) -> dict:
    """A peer by its own protocol: cold ``prepare`` + ``classify`` checked, a warm-up that measures memory,
    then ``repeats`` timed runs; its one-shot time is prepare + classify."""
    cold = []
    instance = make_peer(name, params, peers)
    try:
        mask = peer_run(instance, case, cold)
    finally:
        close(instance)
    check_mask(mask, truth, f"{name} {params}: classify")
    row, stages = {"memory_method": None, "host_peak_mib": None}, []
    instance = make_peer(name, params, peers)
    try:
        with peak_rss(row):
            peer_run(instance, case, [])
        for _ in range(repeats):
            peer_run(instance, case, stages)
        stats = method_stats(instance)
    finally:
        close(instance)
    return {"oneshot": Timing([p + c for p, c in stages]), "prepare": Timing([p for p, _ in stages]),
            "query": Timing([c for _, c in stages]), "cold_s": sum(cold[0]), "mask": mask,
            "prepared_wrong": None, "resolved_params": None, "stats": stats,
            "device_bytes": (stats or {}).get("device_bytes"), "host_s": None, "host_share": None,
            "host_profiled_wall_s": None, **row}


def judge_disputes(case: Case, mask: np.ndarray, truth: np.ndarray) -> dict:
    """Where ``mask`` (a peer's) and the exact ``truth`` differ, which one the float64 reference backs.

    A receiver is decided when the reference gives the same answer with its tie moved
    :data:`ROUNDING_BAND` scene sizes either way and the receiver's segment passes farther than that
    from every triangle edge; otherwise it is within float32 rounding, where either answer is right.
    At most :data:`MAX_JUDGED` receivers (a seeded sample) are judged.
    """
    disputed = np.flatnonzero(mask != truth)
    if len(disputed) > MAX_JUDGED:
        disputed = np.sort(np.random.default_rng(0).choice(disputed, MAX_JUDGED, replace=False))
    mesh, band = case.scene.mesh, ROUNDING_BAND * bounds_diagonal(case.scene.mesh.bounds)
    args = (mesh.vertices, mesh.faces, case.light, case.points[disputed],
            None if case.normals is None else case.normals[disputed])
    low = reference.shadow_mask(*args, eps=case.eps, margin=-band)
    high = reference.shadow_mask(*args, eps=case.eps, margin=band)
    decided = (low == high) & (reference.segment_edge_distance(*args, eps=case.eps) > band)
    return {"judged": int(len(disputed)), "truth_right": int(np.sum(decided & (low == truth[disputed]))),
            "row_right": int(np.sum(decided & (low == mask[disputed]))), "within_rounding": int(np.sum(~decided))}


def measure(case: Case, method: str, params: dict, truth: np.ndarray, repeats: int, device,
            peers: dict = PEERS) -> dict:
    """One row of the results document (see bench/README.md)."""
    if method in peers:
        m = measure_peer(case, method, params, truth, repeats, peers)
    else:
        m = measure_method(case, method, params, truth, repeats, device)
    error = mask_error(m["mask"], truth)
    oneshot, prepare, query = m["oneshot"], m["prepare"], m["query"]
    n = len(case.points)
    return {
        "scene": case.scene.name,
        "light": case.light_index,
        "normals": case.normals is not None,
        "method": method,
        "params": params,
        "label": label(method, params),
        "receivers": n,
        "triangles": len(case.scene.mesh.faces),
        "oneshot_s": oneshot.median,
        "prepare_s": prepare.median,
        "query_s": query.median,
        "oneshot_cold_s": m["cold_s"],
        "oneshot_runs_s": oneshot.runs,
        "prepare_runs_s": prepare.runs,
        "query_runs_s": query.runs,
        "receivers_per_s": n / oneshot.median,
        "receivers_per_s_query": n / query.median,
        "false_shadow": error.false_shadow,
        "false_light": error.false_light,
        "wrong": error.wrong,
        "error_percent": 100 * error.fraction,
        "prepared_wrong": m["prepared_wrong"],
        # a peer's disagreements with exact, judged by the float64 reference (None: none, or not a peer)
        "disputes": judge_disputes(case, m["mask"], truth) if method in peers and error.wrong else None,
        "in_shadow": int(truth.sum()),
        "vs_peer": None,
        "host_s": m["host_s"],
        "host_share": m["host_share"],
        "host_profiled_wall_s": m["host_profiled_wall_s"],
        "memory_method": m["memory_method"],
        "host_peak_mib": m["host_peak_mib"],
        "device_mib": m["device_bytes"] / 2**20 if m["device_bytes"] is not None else None,
        "resolved_params": m["resolved_params"],
        "method_stats": m["stats"],
    }


def interleave_oneshots(case: Case, rows: list[dict], repeats: int, device, peers: dict = PEERS) -> None:
    """Each of a case's ``rows`` timed again one-shot (a shadowcl method: ``sc.shadow_mask``; a peer: its
    prepare + classify), in rounds that call every tool once (timing.interleaved, SETTLE_S before each
    call), so that the load drift of a shared machine hits them alike: ``oneshot_interleaved_s``, the time
    ``vs_peer`` compares."""
    fns, instances = {}, []
    try:
        for row in rows:
            name, params = row["method"], row["params"]
            if name in peers:
                instances.append(make_peer(name, params, peers))
                fns[row["label"]] = lambda instance=instances[-1]: peer_run(instance, case, [])
            else:
                fns[row["label"]] = lambda name=name, params=params: one_shot(case, name, params, device)
        timings = interleaved(fns, repeats, settle=SETTLE_S)
    finally:
        for instance in instances:
            close(instance)
    for row in rows:
        row["oneshot_interleaved_s"] = timings[row["label"]].median
        row["oneshot_interleaved_runs_s"] = timings[row["label"]].runs


def add_peer_ratios(rows: list[dict], peers: dict = PEERS) -> None:
    """``vs_peer``: each row's one-shot throughput over the fastest peer row's (prepare + classify) of its
    case, from the interleaved one-shot times (run_bench takes them for every case with a peer);
    ``fastest_peer`` names that row."""
    def speed(row):
        return 1.0 / row["oneshot_interleaved_s"]

    for _, group in itertools.groupby(rows, key=report.case_key):
        group = list(group)
        fastest = max((r for r in group if r["method"] in peers), key=speed, default=None)
        for row in group:
            row["vs_peer"] = speed(row) / speed(fastest) if fastest else None
            row["fastest_peer"] = fastest["label"] if fastest else None


def describe_light(light) -> str:
    if hasattr(light, "position"):
        return "point at " + ", ".join(f"{x:.3g}" for x in light.position)
    return "directional along " + ", ".join(f"{x:.3g}" for x in light.direction)


def package_version(name: str) -> str | None:
    try:
        return version(name)
    except PackageNotFoundError:
        return None


def machine(device) -> dict:
    """The machine a run was measured on: CPU, cores, OpenCL device, package versions."""
    cpuinfo = Path("/proc/cpuinfo")
    model = re.search(r"^model name\s*:\s*(.+)$", cpuinfo.read_text(), re.MULTILINE) if cpuinfo.exists() else None
    cl = device.cl_device
    return {
        "cpu": model.group(1) if model else platform.processor(),
        "cores": os.cpu_count(),
        "system": platform.platform(),
        "python": platform.python_version(),
        "opencl_device": cl.name,
        "opencl_version": cl.version,
        "opencl_driver": cl.driver_version,
        "opencl_platform": f"{cl.platform.name} {cl.platform.version}",
        "compute_units": cl.max_compute_units,
        "versions": {p: package_version(p) for p in PACKAGES},
    }


def run_bench(scenes, sweep: dict, counts: dict, repeats: int = 5, seed: int = 0, device=None,
              peers: dict = PEERS, progress: bool = True, normals_modes=(True,)) -> dict:
    """Run ``sweep`` on ``scenes`` (:class:`receivers.BenchScene`) and return the results document.

    ``counts`` gives ``ground`` and ``model`` receiver counts; ``peers`` maps names to classes with
    the method protocol that are not shadowcl methods (tests add stand-ins). ``normals_modes``: run each
    case with the receivers' normals (True), without (False) or both. The truth is :func:`ground_truth`'s method.
    """
    device = sc.get_device(device)
    truth_name, truth_note = ground_truth()
    skipped = {name: why for name in sweep if (why := available(name, peers)) is not None}
    jobs = [(name, params) for name, grid in sweep.items() if name not in skipped for params in settings(grid)]
    cases = []
    for scene in scenes:
        points, normals = rx.receivers(scene, counts["ground"], counts["model"], seed)
        eps = default_eps(scene.mesh.bounds)
        cases += [Case(scene, i, points, normals if given else None, eps)
                  for i in range(len(scene.lights)) for given in normals_modes]
    rows, notes, failed = [], [], []
    load_start = os.getloadavg()  # the 2 cores are shared: a busy machine shows here
    bar = tqdm(total=len(cases) * (len(jobs) + 1), disable=not progress, unit="run")
    for case in cases:
        bar.set_description(f"{case.scene.name} truth")
        truth = truth_mask(case, truth_name, device)
        bar.update()
        notes.append(f"{case.scene.name} light {case.light_index} {'with' if case.normals is not None else 'without'} "
                     f"normals: {describe_light(case.light)}; "
                     f"{len(case.points)} receivers, {len(case.scene.mesh.faces)} triangles, eps {case.eps:.3g}, "
                     f"{int(truth.sum())} in shadow; scene {case.scene.source}")
        case_rows = []
        for name, params in jobs:
            bar.set_description(f"{case.scene.name} {label(name, params)}")
            try:
                case_rows.append(measure(case, name, params, truth, repeats, device, peers))
            except Exception as error:  # one failing setting (say, a resolution too large) must not end the run
                failed.append({"scene": case.scene.name, "light": case.light_index, "label": label(name, params),
                               "error": f"{type(error).__name__}: {error}"})
                bar.write(f"FAILED {case.scene.name} {label(name, params)}: {failed[-1]['error']}")
            bar.update()
        if any(r["method"] in peers for r in case_rows):
            bar.set_description(f"{case.scene.name} interleaved")
            interleave_oneshots(case, case_rows, repeats, device, peers)
        rows += case_rows
    bar.close()
    add_peer_ratios(rows, peers)
    return {
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "machine": machine(device),
        "settings": {"receivers": counts, "seed": seed, "repeats": repeats, "sweep": sweep,
                     "truth": truth_note, "truth_method": truth_name, "skipped": skipped,
                     "timing": "public calls, median of repeats after a cold run (checked) and a warm-up: "
                               "one-shot sc.shadow_mask; sc.prepare (ends with the device queue drained) and "
                               ".mask timed apart; a peer's one-shot time is its prepare + classify; host share: "
                               "one one-shot call under cProfile, wall minus the tottime of pyopencl's calls; "
                               "vs fastest peer: one-shot times again with every tool called once per round "
                               "(interleaved), medians",
                     "load_average": {"start": load_start, "end": os.getloadavg()},
                     "peer": "embreex run(): tnear emulated by starting rays eps along their direction; "
                             "workers = processes"},
        "cases": notes,
        "rows": rows,
        "failed": failed,
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description="Speed against error of shadowcl's methods, Embree as peer.")
    parser.add_argument("--quick", action="store_true",
                        help=f"{sum(QUICK.values())} receivers instead of {sum(FULL.values())}, 3 repeats")
    parser.add_argument("--scenes", nargs="+", default=["bunny", "ogre"],
                        help="model names (bunny, ogre, teapot) or .toml scene files")
    parser.add_argument("--methods", nargs="+", default=list(SWEEP),
                        help="methods and peers to run (their SWEEP grid, else defaults)")
    parser.add_argument("--full-sweep", action="store_true", help="every setting of FULL_SWEEP, not SWEEP's subset")
    parser.add_argument("--repeats", type=int, help="timed runs per setting (default 5, 3 with --quick)")
    parser.add_argument("--normals", nargs="+", choices=["with", "without"], default=["with", "without"],
                        help="receivers with their normals, without, or both (default)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=RESULTS, help="folder for STEM.json, .md and .png")
    parser.add_argument("--compare", type=Path, help="an earlier run's JSON: print new/old ratios")
    parser.add_argument("--sweep", type=json.loads, default={},
                        help='JSON {method: {parameter: [values]}} replacing those grids (A/B in one run), '
                             'e.g. \'{"exact": {"split": [false, true]}}\'')
    args = parser.parse_args(argv)

    counts = QUICK if args.quick else FULL
    repeats = args.repeats or (3 if args.quick else 5)
    sweep = {**(FULL_SWEEP if args.full_sweep else SWEEP), **args.sweep}
    doc = run_bench([rx.load_scene(s) for s in args.scenes], {m: sweep.get(m, {}) for m in args.methods},
                    counts, repeats, args.seed, normals_modes=[mode == "with" for mode in args.normals])
    doc["settings"]["quick"] = args.quick
    stem = ("quick-" if args.quick else "run-") + datetime.now().strftime("%Y%m%d-%H%M%S")
    table = report.markdown(doc, plot_name=f"{stem}.png")
    report.save(args.out, stem, doc, table, report.plot)
    print(table)
    if args.compare:
        print(report.compare(doc, json.loads(args.compare.read_text())))
    print(f"wrote {args.out / stem}.json, .md, .png", file=sys.stderr)


if __name__ == "__main__":
    main()
