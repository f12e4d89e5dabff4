"""What the exact method's cull (``cull=True``: :mod:`shadowcl.solids`) costs once and saves per light.

    python bench/cull.py [--scenes default light_inside city_block ogre bunny teapot] [--lights 9]

Per scene, with the bench's 1.2 M receivers (bench/receivers.py):

- the certificate: its time on a fresh copy of the mesh (edge adjacency included; SciPy imported
  before), the faces and components it certifies, and the faces the scene's light lists;
- a study: two structures (``sc.prepare(..., cull=False)`` and ``cull=True``) relit light by light over
  ``--lights`` lights near the scene's own (moved 1 % of the scene's size, or turned ~1 degree), each
  light's relight + mask timed after WARMUP untimed ones, the two alternating with a 0.1 s settle;
  medians (minima), every light's masks compared;
- break-even: the certificate's time over the median saving per light, in lights ("never" where the
  cull does not save; "no cull" where the light lists every face, and the two columns differ by this
  VM's noise alone).

Writes bench/results/cull.json and .md (shadowcl.exact.CULL_FROM_LIGHTS is chosen from these).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

import receivers as rx
import report
import shadowcl as sc
from shadowcl import solids, topology
from shadowcl.methods import default_eps

SCENES = {"default": "scenes/default.toml", "light_inside": "scenes/hard/light_inside.toml",
          "city_block": "scenes/city_block.toml", "ogre": "ogre", "bunny": "bunny", "teapot": "teapot"}
PROJECT = Path(__file__).resolve().parents[1]
WARMUP = 2        # relights per structure not timed (this VM stalls ~0.3 s on some calls after the receivers are made)


def nearby_lights(light, size: float, count: int, rng) -> list:
    if isinstance(light, sc.PointLight):
        return [sc.PointLight(light.position + rng.normal(size=3) * 0.01 * size) for _ in range(count)]
    return [sc.DirectionalLight(light.direction + rng.normal(size=3) * 0.01) for _ in range(count)]


def certificate(mesh: sc.Mesh) -> dict:
    fresh = sc.Mesh(mesh.vertices, mesh.faces)            # no cached adjacency or certificate
    start = time.perf_counter()
    result = solids.solids(fresh)
    seconds = time.perf_counter() - start
    certified = np.unique(result.label[result.sigma != 0])
    return dict(certificate_s=seconds, faces=len(mesh.faces), certified_faces=result.certified_faces,
                components=int(result.label.max()) + 1, certified_components=len(certified))


def study(scene, points, normals, lights, eps) -> dict:
    structures = {cull: sc.prepare(scene.mesh, lights[0], method="exact", eps=eps, cull=cull,
                                   expected_receivers=len(points)) for cull in (False, True)}
    times = {cull: [] for cull in structures}
    differ = 0
    for index, light in enumerate(lights[1:]):
        masks = {}
        for cull, shadows in structures.items():
            time.sleep(0.1)
            start = time.perf_counter()
            shadows.relight(light)
            masks[cull] = shadows.mask(points, normals)
            if index >= WARMUP:
                times[cull].append(time.perf_counter() - start)
        differ += int(np.count_nonzero(masks[False] != masks[True]))
    return dict(light_s=statistics.median(times[False]), culled_light_s=statistics.median(times[True]),
                light_min_s=min(times[False]), culled_light_min_s=min(times[True]), differ=differ)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    parser.add_argument("--lights", type=int, default=9, help="lights per study (the first only prepares)")
    args = parser.parse_args(argv)
    topology.components(2, [[0, 1]])                       # SciPy's import, once, outside the timing
    rng = np.random.default_rng(0)
    rows = []
    for name in args.scenes:
        scene = rx.load_scene(str(PROJECT / SCENES[name]) if SCENES[name].endswith(".toml") else SCENES[name])
        points, normals = rx.receivers(scene, 1_000_000, 200_000, 0)
        eps = default_eps(scene.mesh.bounds)
        row = dict(scene=name, **certificate(scene.mesh))
        listed = solids.solids(scene.mesh).faces_for(scene.lights[0], np.stack([points.min(axis=0), points.max(axis=0)]))
        row["listed_faces"] = len(scene.mesh.faces) if listed is None else len(listed)
        lights = nearby_lights(scene.lights[0], float(np.linalg.norm(np.ptp(scene.mesh.bounds, axis=0))),
                               args.lights, rng)
        for with_normals in (True, False):
            result = study(scene, points, normals if with_normals else None, lights, eps)
            saving = result["light_s"] - result["culled_light_s"]
            culls = row["listed_faces"] < row["faces"]
            rows.append(dict(row, normals=with_normals, **result,
                             break_even_lights=row["certificate_s"] / saving if culls and saving > 0 else None))
            print(rows[-1], flush=True)
    doc = dict(lights=args.lights, receivers=1_200_000, rows=rows)
    lines = ["# The exact method's cull: the certificate once, the saving per light", "",
             f"bench/cull.py: 1.2 M receivers, {args.lights - 1 - WARMUP} timed relights per structure "
             "(after a prepare and {WARMUP} untimed), alternating; light times are medians (minima) of "
             "relight + mask.".replace("{WARMUP}", str(WARMUP)), "",
             "| scene | normals | faces | certified | listed | certificate ms | light ms | culled ms | "
             "break-even lights | masks differ |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        even = ("no cull" if r["listed_faces"] == r["faces"] else
                f"{r['break_even_lights']:.0f}" if r["break_even_lights"] else "never")
        lines.append(f"| {r['scene']} | {'with' if r['normals'] else 'without'} | {r['faces']} | "
                     f"{r['certified_faces']} | {r['listed_faces']} | {1e3 * r['certificate_s']:.0f} | "
                     f"{1e3 * r['light_s']:.1f} ({1e3 * r['light_min_s']:.1f}) | "
                     f"{1e3 * r['culled_light_s']:.1f} ({1e3 * r['culled_light_min_s']:.1f}) | {even} | {r['differ']} |")
    report.save(PROJECT / "bench" / "results", "cull", doc, "\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
