"""The bench harness: speed against error of every shadow method, with Embree as peer, in one run.

    python bench/run.py [--quick] [--scenes bunny ogre] [--methods exact embreex] [--repeats 5]
                        [--out bench/results] [--compare OLD.json]

For each scene, light, method and parameter setting (:data:`SWEEP`): one cold run whose mask is
checked against the ground truth, one warm-up on a fresh instance (also the memory measurement),
then the median of ``repeats`` timed runs of ``prepare`` and ``classify``. Writes
``OUT/STEM.json`` (machine, settings, one row per setting), ``STEM.md`` (table) and ``STEM.png``
(speed against error).
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import itertools
import json
import os
import platform
import re
import resource
import statistics
import sys
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, is_dataclass
from functools import cached_property
from datetime import datetime, timezone
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import numpy as np
from tqdm import tqdm

import receivers as rx
import report
from peers import PEER, PEERS
from shadowcl import get_device
from shadowcl.methods import create_method, default_eps, method_class
from shadowcl.metrics import mask_error

# Method name -> {parameter: [values]}; every combination is one row. Peers (peers.PEERS) take part
# like methods. A method with a parameter sweep is one entry, e.g.
#   "shadow_map": {"resolution": [256, 1024, 4096, 8192], "bias": ["constant", "slope", "normal"],
#                  "filter": ["nearest", "bilinear", "pcf"]},
SWEEP = {
    "exact": {},
    "embreex": {"workers": [1, 2]},
    # the default settings across resolutions; the full grid (bias x filter at every resolution, 8192
    # included: ~3 GB for a cube) is FULL_SWEEP, run with --full-sweep
    "shadow_map": {"resolution": [256, 1024, 2048, 4096]},
}
FULL_SWEEP = {**SWEEP, "shadow_map": {"resolution": [256, 1024, 2048, 4096, 8192],
                                      "bias": ["constant", "slope", "normal"], "filter": ["nearest", "bilinear", "pcf"]}}
FULL = {"ground": 1_000_000, "model": 200_000}
QUICK = {"ground": 80_000, "model": 20_000}
RESULTS = Path(__file__).resolve().parent / "results"
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


def make(name: str, params: dict, device, peers: dict = PEERS):
    """An unprepared instance of ``name`` with ``params``: ``peers[name]`` (a class) or a shadowcl method."""
    if name in peers:
        return peers[name](**params)
    return create_method(name, device, **params)


def close(instance) -> None:
    if hasattr(instance, "close"):
        instance.close()


def available(name: str, peers: dict = PEERS) -> str | None:
    """None when method or peer ``name`` can be used, else why not (an import error)."""
    try:
        if name == PEER:
            import embreex  # noqa: F401
        elif name not in peers:
            method_class(name)
    except ImportError as error:
        return f"{type(error).__name__}: {error}"
    return None


def ground_truth() -> tuple[str, dict, str]:
    """The method whose mask is the truth: ``exact`` once it imports, else Embree; and why."""
    problem = available("exact")
    if problem is None:
        return "exact", {}, "exact method (shadowcl.exact, default parameters)"
    if available(PEER) is not None:
        raise RuntimeError(f"no ground truth: the exact method is not available ({problem}) and neither is embreex")
    return PEER, {}, f"embreex (shadowcl.exact is not available yet: {problem})"


def timed_run(instance, case: Case, device) -> tuple[float, float, np.ndarray]:
    """Seconds spent in ``prepare`` (device queue drained) and in ``classify``, and the mask."""
    start = time.perf_counter()
    instance.prepare(case.scene.mesh, case.light, case.receiver_bounds, case.eps)
    device.queue.finish()
    prepared = time.perf_counter()
    mask = instance.classify(case.points, case.normals)
    return prepared - start, time.perf_counter() - prepared, mask


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


def method_stats(instance) -> dict | None:
    """What a method reports about its last run (attribute ``stats``: a dict or a dataclass)."""
    stats = getattr(instance, "stats", None)
    if is_dataclass(stats):
        return asdict(stats)
    return dict(stats) if stats else None


def measure(case: Case, method: str, params: dict, truth: np.ndarray, repeats: int, device,
            peers: dict = PEERS) -> dict:
    """One row: correctness on a cold run, a warm-up with memory, then the median of ``repeats`` runs."""
    instance = make(method, params, device, peers)
    try:
        prepare_cold, classify_cold, mask = timed_run(instance, case, device)
    finally:
        close(instance)
    if not (isinstance(mask, np.ndarray) and mask.dtype == bool and mask.shape == truth.shape):
        raise TypeError(f"{label(method, params)}: classify returned {type(mask).__name__} "
                        f"{getattr(mask, 'dtype', '')} {getattr(mask, 'shape', '')}, expected bool {truth.shape}")
    error = mask_error(mask, truth)
    row = {"memory_method": None, "host_peak_mib": None}
    instance = make(method, params, device, peers)
    try:
        with peak_rss(row):
            timed_run(instance, case, device)
        runs = [timed_run(instance, case, device)[:2] for _ in range(repeats)]
        stats = method_stats(instance)
    finally:
        close(instance)
    prepare = [p for p, _ in runs]
    classify = [c for _, c in runs]
    total = statistics.median(p + c for p, c in runs)
    n = len(case.points)
    return {
        "scene": case.scene.name,
        "light": case.light_index,
        "method": method,
        "params": params,
        "label": label(method, params),
        "receivers": n,
        "triangles": len(case.scene.mesh.faces),
        "prepare_s": statistics.median(prepare),
        "classify_s": statistics.median(classify),
        "total_s": total,
        "prepare_cold_s": prepare_cold,
        "classify_cold_s": classify_cold,
        "prepare_runs_s": prepare,
        "classify_runs_s": classify,
        "receivers_per_s": n / total,
        "receivers_per_s_classify": n / statistics.median(classify),
        "false_shadow": error.false_shadow,
        "false_light": error.false_light,
        "wrong": error.wrong,
        "error_percent": 100 * error.fraction,
        "in_shadow": int(truth.sum()),
        "vs_peer": None,
        **row,
        "device_mib": stats["device_bytes"] / 2**20 if stats and "device_bytes" in stats else None,
        "method_stats": stats,
    }


def add_peer_ratios(rows: list[dict]) -> None:
    """``vs_peer``: each row's throughput (prepare included) over the fastest Embree row of its case."""
    for _, group in itertools.groupby(rows, key=lambda r: (r["scene"], r["light"])):
        group = list(group)
        peers = [r["receivers_per_s"] for r in group if r["method"] == PEER]
        for row in group:
            row["vs_peer"] = row["receivers_per_s"] / max(peers) if peers else None


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
              peers: dict = PEERS, progress: bool = True) -> dict:
    """Run ``sweep`` on ``scenes`` (:class:`receivers.BenchScene`) and return the results document.

    ``counts`` gives ``ground`` and ``model`` receiver counts; ``peers`` maps names to classes with
    the method protocol that are not shadowcl methods (tests add stand-ins). The truth is
    :func:`ground_truth`'s method.
    """
    device = get_device(device)
    truth_name, truth_params, truth_note = ground_truth()
    skipped = {name: why for name in sweep if (why := available(name, peers)) is not None}
    jobs = [(name, params) for name, grid in sweep.items() if name not in skipped for params in settings(grid)]
    cases = []
    for scene in scenes:
        points, normals = rx.receivers(scene, counts["ground"], counts["model"], seed)
        eps = default_eps(scene.mesh.bounds)
        cases += [Case(scene, i, points, normals, eps) for i in range(len(scene.lights))]
    rows, notes, failed = [], [], []
    bar = tqdm(total=len(cases) * (len(jobs) + 1), disable=not progress, unit="run")
    for case in cases:
        bar.set_description(f"{case.scene.name} truth")
        truth_instance = make(truth_name, truth_params, device)
        try:
            truth = timed_run(truth_instance, case, device)[2]
        finally:
            close(truth_instance)
        bar.update()
        notes.append(f"{case.scene.name} light {case.light_index}: {describe_light(case.light)}; "
                     f"{len(case.points)} receivers, {len(case.scene.mesh.faces)} triangles, eps {case.eps:.3g}, "
                     f"{int(truth.sum())} in shadow; scene {case.scene.source}")
        for name, params in jobs:
            bar.set_description(f"{case.scene.name} {label(name, params)}")
            try:
                rows.append(measure(case, name, params, truth, repeats, device, peers))
            except Exception as error:  # one failing setting (say, a resolution too large) must not end the run
                failed.append({"scene": case.scene.name, "light": case.light_index, "label": label(name, params),
                               "error": f"{type(error).__name__}: {error}"})
                bar.write(f"FAILED {case.scene.name} {label(name, params)}: {failed[-1]['error']}")
            bar.update()
    bar.close()
    add_peer_ratios(rows)
    return {
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "machine": machine(device),
        "settings": {"receivers": counts, "seed": seed, "repeats": repeats, "sweep": sweep,
                     "truth": truth_note, "truth_method": truth_name, "skipped": skipped,
                     "timing": "median of repeats after one cold run and one warm-up; "
                               "prepare ends with the device queue drained",
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
                    counts, repeats, args.seed)
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
