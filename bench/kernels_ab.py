"""Kernel variants side by side: per-kernel device times of the public one-shot call, interleaved.

    python bench/kernels_ab.py SCENE DIR [DIR ...] [--no-normals] [--rounds 9] [--coherent]

Each DIR is a kernels folder (a copy of ``kernels/`` with one change in it). Each variant gets its own
``Device(kernel_dir=DIR)`` on a profiling queue, and the variants' one-shot ``sc.shadow_mask(...,
method="exact")`` calls alternate round by round (after a warm-up round that compiles), so this VM's
drift hits them alike. Printed: per kernel, the median and the minimum of its summed device time per
call in ms; the one-shot call's median; and on how many receivers each variant's mask differs from the
first's. The host code is this checkout's, so a variant may change what kernels do, not their
arguments. Every A/B figure of docs/exact-speed.md was taken this way.

SCENE: a bench scene (``bunny``, ``ogre``, ``teapot`` or a .toml file, as ``run.py --scenes``) or
``city:N:S``, scale.py's city of N x N icospheres of S subdivisions. ``--coherent`` sorts the
receivers on a 512-cell grid (a sensor grid's or an image's order) instead of the bench's random order.
"""

from __future__ import annotations

import argparse
import collections
import statistics
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

import receivers as rx
import shadowcl as sc
from shadowcl.methods import default_eps


def load(scene: str) -> rx.BenchScene:
    if scene.startswith("city:"):
        import scale
        _, n, subdivisions = scene.split(":")
        return scale.city(int(n), int(subdivisions))
    return rx.load_scene(scene)


def coherent(points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The receivers ordered row by row on a 512-cell grid over their box."""
    cell = np.floor((points - points.min(0)) / (np.ptp(points, axis=0).max() / 512)).astype(np.int64)
    order = np.lexsort((cell[:, 2], cell[:, 0], cell[:, 1]))
    return np.ascontiguousarray(points[order]), np.ascontiguousarray(normals[order])


class Variant:
    """One kernels folder: its device on a profiling queue and what its calls took."""

    def __init__(self, kernel_dir: Path):
        self.name = str(kernel_dir)
        self.device = sc.Device(kernel_dir=kernel_dir)
        self.device.queue = cl.CommandQueue(self.device.context,
                                            properties=cl.command_queue_properties.PROFILING_ENABLE)
        self.kernel_ms = collections.defaultdict(list)   # kernel -> summed device ms per call
        self.call_ms = []
        self.mask = None


def run(scene, variants: list[Variant], points, normals, rounds: int) -> None:
    """Alternate the variants' one-shot calls; round 0 (compiles) is not timed, only its mask kept."""
    events = []
    launch = cl.Kernel.__call__

    def recorded(kernel, *args, **kwargs):
        event = launch(kernel, *args, **kwargs)
        events.append((kernel.function_name, event))
        return event

    eps = default_eps(scene.mesh.bounds)
    cl.Kernel.__call__ = recorded
    try:
        for round_ in range(rounds + 1):
            for variant in variants:
                events.clear()
                time.sleep(0.1)                       # let the previous call's threads settle
                start = time.perf_counter()
                mask = sc.shadow_mask(scene.mesh, scene.lights[0], points, normals, method="exact",
                                      device=variant.device, eps=eps)
                elapsed = time.perf_counter() - start
                variant.device.queue.finish()
                if round_ == 0:
                    variant.mask = mask
                    continue
                variant.call_ms.append(1e3 * elapsed)
                per_kernel = collections.defaultdict(float)
                for name, event in events:
                    per_kernel[name] += 1e-6 * (event.profile.end - event.profile.start)
                for name, ms in per_kernel.items():
                    variant.kernel_ms[name].append(ms)
    finally:
        cl.Kernel.__call__ = launch


def report(variants: list[Variant]) -> str:
    names = sorted({name for v in variants for name in v.kernel_ms})
    width = max(24, *(len(v.name[-30:]) + 2 for v in variants))
    lines = ["kernel, ms: median (min)".ljust(26) + "".join(v.name[-30:].rjust(width) for v in variants)]
    for name in names:
        cells = [f"{statistics.median(v.kernel_ms[name]):.2f} ({min(v.kernel_ms[name]):.2f})"
                 if v.kernel_ms[name] else "-" for v in variants]
        lines.append(name.ljust(26) + "".join(c.rjust(width) for c in cells))
    lines.append("one-shot call".ljust(26) + "".join(f"{statistics.median(v.call_ms):.2f}".rjust(width)
                                                     for v in variants))
    lines += [f"{v.name}: differs from the first on {int(np.count_nonzero(v.mask != variants[0].mask))} receivers"
              for v in variants[1:]]
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description="Per-kernel times of kernel-folder variants, interleaved.")
    parser.add_argument("scene")
    parser.add_argument("dirs", nargs="+", type=Path, help="kernels folders, the first one the baseline")
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--no-normals", action="store_true", help="receivers without normals")
    parser.add_argument("--coherent", action="store_true", help="receivers in a grid's order, not at random")
    parser.add_argument("--ground", type=int, default=1_000_000, help="receivers on the ground (model scenes)")
    parser.add_argument("--model", type=int, default=200_000, help="receivers on the model")
    args = parser.parse_args(argv)
    for folder in args.dirs:
        if not (folder / "exact.cl").is_file():
            parser.error(f"dirs: {folder} holds no exact.cl (expected a copy of kernels/)")
    scene = load(args.scene)
    points, normals = rx.receivers(scene, args.ground, args.model, 0)
    if args.coherent:
        points, normals = coherent(points, normals)
    variants = [Variant(folder) for folder in args.dirs]
    run(scene, variants, points, None if args.no_normals else normals, args.rounds)
    print(f"{scene.name}, {len(points)} receivers {'without' if args.no_normals else 'with'} normals"
          f"{', coherent order' if args.coherent else ''}, {args.rounds} rounds")
    print(report(variants))


if __name__ == "__main__":
    main()
