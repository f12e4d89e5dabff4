"""method="auto" against the exact method and against the sweep's oracle, at budgets 1e-2, 1e-3, 1e-4.

    python bench/auto.py            # own shapes (torus, csg_box also in sunlight), bench models and hard scenes,
                                    # 1.2 M receivers, with and without normals
    python bench/auto.py --quick    # two own shapes, 100 k receivers: for development
    python bench/auto.py --costs    # the cost priors: each candidate's prepare and query time over exact's,
                                    # on perturbed spheres of 1.3 k-328 k triangles (not in ../shared)

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
import os
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
SUN = ("torus", "csg_box")


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
        if name in SUN:         # in sunlight along the point light's line: where the priors let candidates be tried
            yield f"{name}_sun", scene.mesh, sc.DirectionalLight(-np.asarray(scene.lights[0].position)), points, normals
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


COST_SUBDIVISIONS = (3, 4, 5, 6, 7)     # icosphere levels: 1,280 to 327,680 triangles (plus the ground's 2)
COST_RECEIVERS = 1_200_000


def cost_cases(levels=COST_SUBDIVISIONS):
    """(name, mesh, light, points, normals): a perturbed sphere of each of :data:`COST_SUBDIVISIONS` on a
    ground quad, under the bench's point light and under a directional light along the same line."""
    import trimesh

    for level in levels:
        sphere = trimesh.creation.icosphere(level)
        rng = np.random.default_rng(level)
        sphere.vertices *= (1 + 0.08 * rng.standard_normal(len(sphere.vertices)))[:, None]
        scene = model_scene(f"bumpy{level}", sc.Mesh(sphere.vertices, sphere.faces))
        points, normals = receivers(scene, int(0.85 * COST_RECEIVERS), COST_RECEIVERS - int(0.85 * COST_RECEIVERS),
                                    seed=1)
        point = scene.lights[0]
        for light in (point, sc.DirectionalLight(-np.asarray(point.position))):
            yield scene.name, scene.mesh, light, points, normals


def measure_costs(name, mesh, light, points, normals, repeats: int, device) -> dict:
    """Each candidate's prepare and query seconds (``sc.prepare`` then ``.mask`` on all points, medians of
    interleaved rounds) and their ratios to exact's."""
    from shadowcl.methods import with_receiver_count
    from timing import clock

    box = np.array([points.min(0), points.max(0)])
    settings = {"exact": ("exact", {})}
    settings.update({label(method, params): (method, params) for method, params, *_ in auto.CANDIDATES})
    runs = {key: {"prepare": [], "query": []} for key in settings}
    for round_ in range(repeats + 1):                  # the first round warms up
        for key, (method, params) in settings.items():
            params = with_receiver_count(method, params, len(points))
            prepare_s, shadows = clock(lambda: sc.prepare(mesh, light, method, box, device, **params))
            query_s, _ = clock(lambda: shadows.mask(points, normals))
            if round_:
                runs[key]["prepare"].append(prepare_s)
                runs[key]["query"].append(query_s)
    median = {key: {step: float(np.median(r[step])) for step in r} for key, r in runs.items()}
    exact = median["exact"]
    # exact's time per receiver on a calibration sample over its time per receiver on all (auto.SAMPLE_RATE)
    shadows = sc.prepare(mesh, light, "exact", box, device, **with_receiver_count("exact", {}, len(points)))
    sample_rate = {}
    for count in (auto.MIN_SAMPLE, 17_476):
        sample = auto.calibration_sample(check_points(points, normals), count)
        seconds = [clock(lambda: shadows.mask(sample))[0] for _ in range(repeats + 1)][1:]
        sample_rate[count] = float(np.median(seconds)) / count / (exact["query"] / len(points))
    return {"scene": name, "triangles": len(mesh.faces), "receivers": len(points), "normals": normals is not None,
            "light": type(light).__name__, "exact_prepare_s": exact["prepare"], "exact_query_s": exact["query"],
            "sample_rate": sample_rate,
            "ratios": {key: {"prepare": m["prepare"] / exact["prepare"], "query": m["query"] / exact["query"]}
                       for key, m in median.items() if key != "exact"}}


def costs_markdown(rows: list[dict]) -> str:
    keys = list(rows[0]["ratios"])
    lines = ["| scene | triangles | light | normals | exact prepare, query (s) | " + " | ".join(keys) + " |",
             "|---|---|---|---|---|" + "---|" * len(keys)]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['triangles']:,} | {r['light']} | {'yes' if r['normals'] else 'no'} | "
                     f"{r['exact_prepare_s']:.3f}, {r['exact_query_s']:.3f} | "
                     + " | ".join(f"{r['ratios'][k]['prepare']:.2f}, {r['ratios'][k]['query']:.2f}" for k in keys) + " |")
    rates = [rate for r in rows for rate in r.get("sample_rate", {}).values()]
    note = (f"\n\nExact's time per receiver on a 4 k or 17 k calibration sample over its time per receiver on all: "
            f"median {np.median(rates):.2f}, max {max(rates):.2f}.") if rates else ""
    return ("Each candidate's (prepare / exact's prepare, query / exact's query), 1.2 M receivers.\n\n"
            + "\n".join(lines) + note + "\n")


def priors_literal(rows: list[dict]) -> str:
    """``shadowcl.auto``'s COST_TRIANGLES and COST_PRIORS from the --costs rows, rounded to 2 digits."""
    triangles = sorted({r["triangles"] for r in rows})
    text = [f"COST_TRIANGLES = ({', '.join(f'{t:_}' for t in triangles)})", "COST_PRIORS = {"]
    for kind in ("point", "directional"):
        for normals in (False, True):
            case = sorted((r for r in rows if r["light"].lower().startswith(kind) and r["normals"] == normals),
                          key=lambda r: r["triangles"])
            text.append(f"    ({kind!r}, {normals}): {{")
            text.append("        \"exact\": (" + ", ".join(f"{r['exact_prepare_s'] / r['exact_query_s']:.3g}"
                                                    for r in case) + "),")
            for key in case[0]["ratios"]:
                text.append(f"        {key!r}: (" + ", ".join(
                    f"({r['ratios'][key]['prepare']:.2f}, {r['ratios'][key]['query']:.2f})" for r in case) + "),")
            text.append("    },")
    return "\n".join(text + ["}"])


def label(method: str, params: dict) -> str:
    return auto.candidate_label(method, params)


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
            "calibration_s": calibration["seconds"],
            "overhead_s": calibration["seconds"] - calibration["exact_prepare_s"],     # beyond exact's own prepare "auto_runs": runs["auto"].runs, "exact_runs": runs["exact"].runs,
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
    lines = ["| scene | normals | budget | chosen | error on all | auto / exact | calibration beyond exact's prepare, "
             "exact's time | oracle (time / exact) | auto / oracle | lod=auto triangles, error |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {'yes' if r['normals'] else 'no'} | {r['budget']:g} | {r['chosen']} | "
                     f"{r['error']:.2e}{' **broken**' if r['broken'] else ''} | {r['auto_vs_exact']:.2f} | "
                     f"{1e3 * r['overhead_s']:.1f} ms, {1e3 * r['exact_s']:.0f} ms | "
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
    parser.add_argument("--costs", action="store_true", help="measure the cost priors (results/auto-costs.*)")
    parser.add_argument("--levels", type=int, nargs="*", help="--costs: only these sphere levels (auto-costs-LEVELS)")
    parser.add_argument("--scenes", nargs="*", help="only these scenes (written as auto-SCENES.json)")
    args = parser.parse_args(argv)
    device = sc.get_device()
    started, load = time.perf_counter(), os.getloadavg()
    rows = []
    if args.costs:
        for name, mesh, light, points, normals in cost_cases(args.levels or COST_SUBDIVISIONS):
            for with_normals in (False, True):
                rows.append(measure_costs(name, mesh, light, points, normals if with_normals else None, 2, device))
                print(costs_markdown(rows[-1:]).splitlines()[4], flush=True)
        args.out.mkdir(parents=True, exist_ok=True)
        doc = {"settings": {"repeats": 2, "load": [load, os.getloadavg()], "seconds": time.perf_counter() - started,
                            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}, "rows": rows}
        stem = "-".join(["auto-costs", *map(str, args.levels or [])])
        (args.out / f"{stem}.json").write_text(json.dumps(doc, indent=1, default=float))
        (args.out / f"{stem}.md").write_text(costs_markdown(rows) + f"\nLoad average (1, 5, 15 min) at the start "
                                              f"{', '.join(f'{x:.1f}' for x in load)} (2 cores).\n")
        print(priors_literal(rows))
        return 0
    for name, mesh, light, points, normals in cases(args.quick):
        if args.scenes and name not in args.scenes:
            continue
        for with_normals in (False, True):
            rows += measure(name, mesh, light, points, normals if with_normals else None,
                            3 if args.quick else args.repeats, device)
    stem = "auto-quick" if args.quick else "-".join(["auto", *(args.scenes or [])])
    args.out.mkdir(parents=True, exist_ok=True)
    load = [load, os.getloadavg()]
    doc = {"settings": {"quick": args.quick, "repeats": args.repeats, "budgets": BUDGETS, "load": load,
                        "seconds": time.perf_counter() - started, "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())},
           "rows": rows}
    (args.out / f"{stem}.json").write_text(json.dumps(doc, indent=1, default=float))
    text = markdown(rows) + (f"\nLoad average (1, 5, 15 min) at the start {', '.join(f'{x:.1f}' for x in load[0])}, "
                             f"at the end {', '.join(f'{x:.1f}' for x in load[1])} (2 cores).\n")
    (args.out / f"{stem}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
