"""method="auto" against the exact method and against the sweep's oracle, at budgets 1e-2, 1e-3, 1e-4.

    python bench/auto.py            # own shapes, bench models and hard scenes, 1.2 M receivers, with and without normals
    python bench/auto.py --quick    # two own shapes, 100 k receivers: for development

Per scene and normals: the exact mask is the truth; the sweep times every candidate of
``shadowcl.auto.CANDIDATES`` one-shot (``sc.shadow_mask``), interleaved with exact, and measures its error
on all receivers; the oracle of a budget is the fastest setting of the sweep (exact included) within
it. Per budget, ``method="auto"`` and exact are timed interleaved (median of repeats after a warm-up):
the choice (the most frequent over the calls; each call's is kept), its error on all receivers (the
worst call's), auto/exact, and auto/oracle = (auto/exact) / (oracle/exact),
each ratio from its own interleaved rounds. A budget is broken when auto's error on all receivers
exceeds it. Writes ``results/auto.json`` and ``results/auto.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import shadowcl as sc
from shadowcl import auto
from shadowcl.points import check_points

from receivers import PROJECT, load_scene, model_scene, receivers
from timing import interleaved

RESULTS = Path(__file__).resolve().parent / "results"
BUDGETS = (1e-2, 1e-3, 1e-4)
MODELS = ("bunny", "ogre", "teapot")
HARD = ("light_inside", "thin_occluder")
OWN = ("torus", "csg_box", "bumpy")


def own_shapes() -> dict:
    """Shapes made here (not in ../shared): (name, Mesh) before ``model_scene`` puts them on a ground."""
    import manifold3d as mf
    import trimesh

    def from_manifold(solid):
        m = solid.to_mesh()
        return sc.Mesh(m.vert_properties[:, :3], m.tri_verts)

    torus = trimesh.creation.torus(1.0, 0.3, major_sections=96, minor_sections=48)
    rng = np.random.default_rng(5)
    bumpy = trimesh.creation.icosphere(5)
    bumpy.vertices *= (1 + 0.08 * rng.standard_normal(len(bumpy.vertices)))[:, None]   # perturbed sphere
    return {
        "torus": sc.Mesh(torus.vertices, torus.faces),
        "csg_box": from_manifold(mf.Manifold.cube([1.5, 1.0, 1.5], True) - mf.Manifold.sphere(0.8, 96)),
        "bumpy": sc.Mesh(bumpy.vertices, bumpy.faces),
    }


def cases(quick: bool):
    """(name, mesh, light, points, normals) of every bench scene."""
    count = 100_000 if quick else 1_200_000
    shapes = own_shapes()
    names = ["torus", "csg_box"] if quick else OWN
    for name in names:
        scene = model_scene(name, shapes[name])
        points, normals = receivers(scene, int(0.85 * count), count - int(0.85 * count), seed=1)
        yield name, scene.mesh, scene.lights[0], points, normals
    if quick:
        return
    for name in MODELS:
        scene = load_scene(name)
        points, normals = receivers(scene, int(0.85 * count), count - int(0.85 * count), seed=1)
        yield name, scene.mesh, scene.lights[0], points, normals
    for name in HARD:
        scene = load_scene(str(PROJECT / "scenes" / "hard" / f"{name}.toml"))
        points, normals = receivers(scene, count, 0, seed=1)
        yield name, scene.mesh, scene.lights[0], points, normals


def label(method: str, params: dict) -> str:
    return method + "".join(f" {k}={v}" for k, v in params.items())


def measure(name, mesh, light, points, normals, repeats: int, device) -> list[dict]:
    truth = sc.shadow_mask(mesh, light, points, normals, device=device)
    one_shot = lambda method, **params: (lambda: sc.shadow_mask(mesh, light, points, normals, method=method,  # noqa: E731
                                                                device=device, **params))
    sweep = {"exact": one_shot("exact")}
    for method, params, *_ in auto.CANDIDATES:
        sweep[label(method, params)] = one_shot(method, **params)
    timings = interleaved(sweep, repeats=1)
    exact_s = timings["exact"].median
    settings = {key: {"time_vs_exact": t.median / exact_s, "error": float(np.mean(t.result != truth))}
                for key, t in timings.items()}
    rows = []
    for budget in BUDGETS:
        calls = []      # every auto call's (Shadows, mask): its choice can differ between calls (measured costs)

        def auto_call():
            # sc.shadow_mask(method="auto") step by step, to keep the Shadows that says what was chosen
            receivers = check_points(points, normals)
            shadows = sc.prepare(mesh, light, "auto", receivers.bounds, device, max_error=budget, receivers=receivers,
                                 expected_receivers=len(receivers))
            calls.append((shadows, shadows.mask(receivers)))

        runs = interleaved({"exact": one_shot("exact"), "auto": auto_call}, repeats)
        within = {key: s["time_vs_exact"] for key, s in settings.items() if s["error"] <= budget}
        oracle = min(within, key=within.get)
        errors = [float(np.mean(mask != truth)) for _, mask in calls]
        chosen = [label(**_split(shadows.params["chosen"])) for shadows, _ in calls]
        shadows = calls[-1][0]
        calibration = shadows.stats["calibration"]
        ratio = runs["auto"].median / runs["exact"].median
        error = max(errors)
        lod_auto = sc.prepare(mesh, light, "shadow_volume", bounds=np.array([points.min(0), points.max(0)]),
                              device=device, lod="auto", max_error=budget, receivers=(points, normals))
        lod_error = float(np.mean(lod_auto.mask(points, normals) != truth))
        rows.append({
            "scene": name, "triangles": len(mesh.faces), "receivers": len(points), "normals": normals is not None,
            "budget": budget, "chosen": max(set(chosen), key=chosen.count), "chosen_runs": chosen, "error": error,
            "errors_runs": errors, "broken": error > budget, "auto_s": runs["auto"].median, "exact_s": runs["exact"].median,
            "auto_vs_exact": ratio, "oracle": oracle, "oracle_vs_exact": within[oracle],
            "auto_vs_oracle": ratio / within[oracle], "sample": calibration["sample"],
            "calibration_s": calibration["seconds"], "auto_runs": runs["auto"].runs, "exact_runs": runs["exact"].runs,
            "tried": [r for r in calibration["tried"] if "skipped" not in r],
            "lod_auto": {"error": lod_error, "broken": lod_error > budget, "triangles": lod_auto.stats["occluder_triangles"],
                         "lod_s": lod_auto.stats["lod_s"]},
        })
        print(f"{name:14s} {'n' if normals is not None else '-'} {budget:g}: {rows[-1]['chosen']:28s} error "
              f"{error:.2e} auto/exact {ratio:.2f} oracle {oracle} ({within[oracle]:.2f}) "
              f"auto/oracle {ratio / within[oracle]:.2f}; lod=auto {lod_auto.stats['occluder_triangles']} of "
              f"{len(mesh.faces)} triangles, error {lod_error:.2e}", flush=True)
    for row in rows:
        row["sweep"] = settings
    return rows


def _split(chosen: dict) -> dict:
    """The chosen method and only the settings the candidates vary (the rest are the method's defaults)."""
    varied = {key for _, params, *_ in auto.CANDIDATES for key in params}
    return {"method": chosen["method"], "params": {k: v for k, v in chosen.items() if k in varied}}


def markdown(rows: list[dict]) -> str:
    lines = ["| scene | normals | budget | chosen | error on all | auto / exact | oracle (time / exact) | auto / oracle "
             "| lod=auto triangles, error |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {'yes' if r['normals'] else 'no'} | {r['budget']:g} | {r['chosen']} | "
                     f"{r['error']:.2e}{' **broken**' if r['broken'] else ''} | {r['auto_vs_exact']:.2f} | "
                     f"{r['oracle']} ({r['oracle_vs_exact']:.2f}) | {r['auto_vs_oracle']:.2f} | "
                     f"{r['lod_auto']['triangles']:,} of {r['triangles']:,}, {r['lod_auto']['error']:.2e}"
                     f"{' **broken**' if r['lod_auto']['broken'] else ''} |")
    broken = sum(r["broken"] for r in rows)
    lod_broken = sum(r["lod_auto"]["broken"] for r in rows)
    lines.append(f"\nBudget broken in {broken} of {len(rows)} cases by method=\"auto\", in {lod_broken} of {len(rows)} "
                 f"by shadow_volume with lod=\"auto\".")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--scenes", nargs="*", help="only these scenes (written as auto-SCENES.json)")
    args = parser.parse_args(argv)
    device = sc.get_device()
    started = time.perf_counter()
    rows = []
    for name, mesh, light, points, normals in cases(args.quick):
        if args.scenes and name not in args.scenes:
            continue
        for with_normals in (False, True):
            rows += measure(name, mesh, light, points, normals if with_normals else None,
                            3 if args.quick else args.repeats, device)
    stem = "auto-quick" if args.quick else "-".join(["auto", *(args.scenes or [])])
    args.out.mkdir(parents=True, exist_ok=True)
    doc = {"settings": {"quick": args.quick, "repeats": args.repeats, "budgets": BUDGETS,
                        "seconds": time.perf_counter() - started, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())},
           "rows": rows}
    (args.out / f"{stem}.json").write_text(json.dumps(doc, indent=1, default=float))
    (args.out / f"{stem}.md").write_text(markdown(rows))
    print(markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
