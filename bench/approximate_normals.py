"""The other approximate methods with and without normals: angular, shadow_volume and voxel against exact.

    python bench/approximate_normals.py [--quick]

angular and shadow_volume run on bench/run.py's scenes (bunny, ogre, default, light_inside; 1 M ground +
200 k model receivers, receivers.py), voxel on its own subdivision scenes (bench/voxel.py: the
receivers on the fine tessellation that is its truth, 100 k). Each method at its default parameters,
through the public calls (``sc.prepare(..., bounds=<the receivers' box>).mask(points, normals or None)``),
against ``sc.shadow_mask(..., method="exact")`` with the same normals (or none). One call each: the
time is a rough figure. Writes ``bench/results/approximate-normals.{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import receivers as rx
import shadowcl as sc
import voxel as voxel_bench
from shadowcl.metrics import mask_error

RESULTS = Path(__file__).resolve().parent / "results"
BENCH_SCENES = ("bunny", "ogre", "scenes/default.toml", "scenes/hard/light_inside.toml")
FULL = {"ground": 1_000_000, "model": 200_000, "voxel": 100_000}
QUICK = {"ground": 40_000, "model": 10_000, "voxel": 10_000}


def cases(counts: dict):
    """(method, scene name, what the method is prepared on, light, points, normals, truth mesh)."""
    for name in BENCH_SCENES:
        scene = rx.load_scene(name if "/" not in name else str(rx.PROJECT / name))
        points, normals = rx.receivers(scene, counts["ground"], counts["model"])
        for method in ("angular", "shadow_volume"):
            yield method, scene.name, scene.mesh, scene.lights[0], points, normals, scene.mesh
    for name in voxel_bench.SCENES:
        fine = voxel_bench.fine_scene(name)
        points, normals, _ = voxel_bench.scene_receivers(fine, counts["voxel"], seed=1)
        yield "voxel", name, fine, fine.light, points, normals, fine.mesh


def measure(counts: dict) -> list[dict]:
    rows = []
    for method, scene, occluders, light, points, normals, truth_mesh in cases(counts):
        bounds = np.stack([points.min(0), points.max(0)])
        for given in (True, False):
            n = normals if given else None
            truth = sc.shadow_mask(truth_mesh, light, points, n, method="exact")
            start = time.perf_counter()
            mask = sc.prepare(occluders, light, method, bounds=bounds).mask(points, n)
            seconds = time.perf_counter() - start
            error = mask_error(mask, truth)
            rows.append(dict(method=method, scene=scene, normals=given, receivers=len(points),
                             false_shadow=error.false_shadow, false_light=error.false_light,
                             error_pct=100 * error.fraction, seconds=seconds))
            print(f"{method:13s} {scene:14s} normals={given!s:5s} {100 * error.fraction:8.4f} % "
                  f"({error.false_shadow} fs, {error.false_light} fl) {seconds:.2f} s", flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    counts = QUICK if args.quick else FULL
    rows = measure(counts)
    stem = "approximate-normals" + ("-quick" if args.quick else "")
    (RESULTS / f"{stem}.json").write_text(json.dumps(dict(settings=dict(counts=counts), rows=rows), indent=1))
    lines = ["# angular, shadow_volume and voxel with and without normals (default parameters, vs exact)", "",
             "| method | scene | normals | receivers | false shadow | false light | error % | one call s |",
             "|---|---|---|---:|---:|---:|---:|---:|"]
    lines += [f"| {r['method']} | {r['scene']} | {'yes' if r['normals'] else 'no'} | {r['receivers']} | "
              f"{r['false_shadow']} | {r['false_light']} | {r['error_pct']:.4f} | {r['seconds']:.2f} |" for r in rows]
    (RESULTS / f"{stem}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
