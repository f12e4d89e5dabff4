"""Levels of detail: triangles, simplification time, shadow error and exact-method time per level.

    python bench/lod.py [--quick] [--scenes bunny teapot ogre] [--path-lights 4] [--repeats 5] [--out DIR]

For each scene (scenes/models/NAME.toml, receivers from receivers.py: 1 M on the ground around the
model + 200 k on it, seeded) and each level of ``shadowcl.lod.levels``: triangles (and the model's
share, the ground box being kept verbatim), the seconds fast-simplification took, and the shadow error
the level causes against the exact method on the full mesh (the level occludes, the full-resolution
receivers receive; false shadow, false light, % of receivers), under the scene's light and
``--path-lights`` more on a circle around the model (the light path of bench/table2.py). Then the exact
method's time with that level as occluder (prepare + classify, median of ``repeats`` after a cold run
and a warm-up; the ratio to level 0 in the same run is the figure to quote: the machine is shared).
Table I's reductions (teapot 6,320 -> 3,160, bunny 69,451 -> 6,945 triangles) are levels 0.5 and 0.1;
``lod="auto"`` at ``max_error=0.001`` is calibrated per light and its pick scored on the bench's own
receivers against issue 6's bar (within 0.1 % error with fewer triangles).
Writes OUT/lod.json, lod.md and lod.png (error and time against triangles).
"""

from __future__ import annotations

import argparse
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

import receivers as rx
from report import save
from run import machine, public_steps
from timing import clock, timed_steps
import shadowcl as sc
from shadowcl import get_device
from shadowcl import lod
from shadowcl.methods import default_eps

RESULTS = Path(__file__).resolve().parent / "results"
FULL = {"ground": 1_000_000, "model": 200_000}
QUICK = {"ground": 40_000, "model": 10_000}
TABLE_I = {"teapot": (6320, 3160, 0.5), "bunny": (69451, 6945, 0.1)}   # model: original, simplified, fraction
MAX_ERROR = 1e-3                                                      # issue 6's bar for lod="auto"


def light_path(scene: rx.BenchScene, frames: int) -> list:
    """``frames`` point lights on a horizontal circle around the model, at the scene light's height and
    horizontal distance, starting at the scene light (or above the model's front when it has none)."""
    centre = scene.model.bounds.mean(axis=0) if scene.model is not None else scene.mesh.bounds.mean(axis=0)
    start = np.asarray(scene.lights[0].position, dtype=np.float64)
    offset = start - centre
    radius, start_angle = np.hypot(offset[0], offset[2]), np.arctan2(offset[2], offset[0])
    angles = start_angle + 2 * np.pi * np.arange(frames) / frames
    return [sc.PointLight((centre[0] + radius * np.cos(a), start[1], centre[2] + radius * np.sin(a))) for a in angles]


def exact_time(device, occluder, light, points, normals, box, eps, repeats: int) -> dict:
    """The exact method with ``occluder`` through the public calls: a cold run and a warm-up, then the
    median of ``repeats``."""
    steps = timed_steps(public_steps(occluder, light, "exact", box, points, normals, device, eps,
                                     expected_receivers=len(points)), repeats, warmup=2)
    return {"prepare_s": steps["prepare"].median, "classify_s": steps["query"].median,
            "exact_s": steps["total"].median}


def measure_scene(device, name: str, counts: dict, path_lights: int, repeats: int, seed: int) -> dict:
    scene = rx.load_scene(name)
    mesh = scene.mesh
    levels_s, meshes = clock(lambda: lod.levels(mesh))
    simplify_s = lod.level_times(mesh)
    ground = len(mesh.faces) - len(scene.model.faces)
    points, normals = rx.receivers(scene, counts["ground"], counts["model"], seed)
    box = np.stack([points.min(axis=0), points.max(axis=0)])
    eps = default_eps(mesh.bounds)
    lights = [scene.lights[0]] + light_path(scene, path_lights + 1)[1:]
    per_light = []
    for index, light in enumerate(lights):
        errors = lod.level_errors(device, mesh, light, points, normals, eps, meshes)
        calibration = lod.calibrate(device, mesh, light, box, eps, MAX_ERROR)
        auto_error = errors[calibration.level]
        per_light.append({
            "light": index, "position": light.position.tolist(), "errors": [e.as_dict() for e in errors],
            "auto": {"level": calibration.level, "triangles": len(meshes[calibration.level].faces),
                     "calibration_receivers": calibration.receivers, "calibration_seconds": calibration.seconds,
                     "calibration_percent": [100 * e.fraction for e in calibration.errors],
                     "calibration_upper_percent": [100 * b for b in calibration.upper_bounds],
                     "bench_error": auto_error.as_dict(),
                     "bar_met": auto_error.fraction <= MAX_ERROR and calibration.level > 0},
        })
    timing = [exact_time(device, level, lights[0], points, normals, box, eps, repeats) for level in meshes]
    rows = []
    for i, (fraction, level) in enumerate(zip(lod.DEFAULT_FRACTIONS, meshes)):
        percents = [light["errors"][i]["percent"] for light in per_light]
        rows.append({
            "scene": name, "level": i, "fraction": fraction, "triangles": len(level.faces),
            "model_triangles": len(level.faces) - ground, "vertices": len(level.vertices),
            "simplify_s": simplify_s[i], **per_light[0]["errors"][i],
            "percent_mean_lights": float(np.mean(percents)), "percent_max_lights": float(np.max(percents)),
            **timing[i], "exact_vs_level0": timing[0]["exact_s"] / timing[i]["exact_s"],
        })
    table_i = None
    if name in TABLE_I:
        original, simplified, fraction = TABLE_I[name]
        row = rows[lod.DEFAULT_FRACTIONS.index(fraction)]
        table_i = {"paper_original": original, "paper_simplified": simplified, "fraction": fraction,
                   "model_triangles": len(scene.model.faces), "level": row["level"],
                   "simplified_model_triangles": row["model_triangles"], "percent": row["percent"],
                   "false_shadow": row["false_shadow"], "false_light": row["false_light"],
                   "percent_max_lights": row["percent_max_lights"]}
    return {"scene": name, "source": scene.source, "triangles": len(mesh.faces), "ground_triangles": ground,
            "receivers": len(points), "eps": eps, "levels_s": levels_s, "rows": rows, "lights": per_light,
            "table_i": table_i}


def markdown(doc: dict, plot_name: str | None) -> str:
    m, s = doc["machine"], doc["settings"]
    lines = [f"# LOD occluders: shadow error and exact-method time per level, {doc['date']}", "",
             f"- Machine: {m['cpu']}, {m['cores']} cores (shared with other jobs: times are noisy, compare ratios); "
             f"OpenCL {m['opencl_device']}",
             f"- Receivers: {s['receivers']['ground']} on the ground + {s['receivers']['model']} on the model "
             f"(seed {s['seed']}); error = exact method with the level occluding vs with the full mesh",
             f"- Lights: the scene's light (light 0) + {s['path_lights']} on a circle around the model "
             f"(bench/lod.py light_path); time: {s['timing']}",
             f"- Fractions: {', '.join(f'{f:g}' for f in s['fractions'])} of each component's triangles; components "
             f"of <= {s['keep_component']} triangles (the ground box) kept verbatim", ""]
    lines += ["| scene | level | fraction | triangles | model tris | simplify ms | false shadow | false light | error % "
              "(light 0) | error % max over lights | exact ms | x faster than level 0 |", "|---|" + "---:|" * 11]
    for scene in doc["scenes"]:
        for r in scene["rows"]:
            lines.append(f"| {r['scene']} | {r['level']} | {r['fraction']:g} | {r['triangles']} | {r['model_triangles']} | "
                         f"{1e3 * r['simplify_s']:.0f} | {r['false_shadow']} | {r['false_light']} | {r['percent']:.4f} | "
                         f"{r['percent_max_lights']:.4f} | {1e3 * r['exact_s']:.1f} | {r['exact_vs_level0']:.2f} |")
    lines += ["", "## Table I's reductions", ""]
    for scene in doc["scenes"]:
        t = scene["table_i"]
        if t:
            lines.append(f"- {scene['scene']}: paper {t['paper_original']} -> {t['paper_simplified']} triangles; here "
                         f"{t['model_triangles']} -> {t['simplified_model_triangles']} (level {t['level']}, fraction "
                         f"{t['fraction']:g}); shadow error {t['percent']:.4f} % of receivers under the scene light "
                         f"({t['false_shadow']} false shadow, {t['false_light']} false light), at most "
                         f"{t['percent_max_lights']:.4f} % over the {len(scene['lights'])} lights")
    lines += ["", f"## lod=\"auto\" at max_error={MAX_ERROR:g}", "",
              "| scene | light | level | triangles | calibration receivers | calibration error % | bench error % | "
              "bar (<= 0.1 %, fewer triangles) |", "|---|---:|---:|---:|---:|---:|---:|---|"]
    for scene in doc["scenes"]:
        for light in scene["lights"]:
            a = light["auto"]
            lines.append(f"| {scene['scene']} | {light['light']} | {a['level']} | {a['triangles']} | "
                         f"{a['calibration_receivers']} | {a['calibration_percent'][a['level']]:.4f} | "
                         f"{a['bench_error']['percent']:.4f} | {'met' if a['bar_met'] else 'MISSED'} |")
    if plot_name:
        lines += ["", f"![error and time against triangles]({plot_name})"]
    return "\n".join(lines) + "\n"


def plot(doc: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for scene in doc["scenes"]:
        rows = scene["rows"][1:]                         # level 0 has no error: off a log axis
        tris = [r["triangles"] for r in rows]
        line, = left.plot(tris, [r["percent"] for r in rows], "o-", label=scene["scene"])
        left.fill_between(tris, [r["percent"] for r in rows], [r["percent_max_lights"] for r in rows],
                          color=line.get_color(), alpha=0.15)
        auto = scene["lights"][0]["auto"]
        if auto["level"] > 0:
            left.plot(auto["triangles"], auto["bench_error"]["percent"], "*", ms=14, color=line.get_color())
        if scene["table_i"]:
            r = scene["rows"][scene["table_i"]["level"]]
            left.plot(r["triangles"], r["percent"], "s", ms=11, mfc="none", color=line.get_color())
        right.plot([r["triangles"] for r in scene["rows"]], [1e3 * r["exact_s"] for r in scene["rows"]], "o-",
                   label=scene["scene"])
    left.axhline(100 * MAX_ERROR, color="grey", ls="--", lw=1)
    left.set(xscale="log", yscale="log", xlabel="occluder triangles", ylabel="receivers wrong, % (light 0; band: max over lights)",
             title="shadow error vs exact on the full mesh\n* auto pick at 0.1 %, square Table I level")
    right.set(xscale="log", xlabel="occluder triangles", ylabel="exact method, prepare + classify (ms)",
              title="exact-method time with the level as occluder")
    left.legend(), right.legend()
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="teapot only, 50 k receivers, 1 path light, 1 repeat")
    parser.add_argument("--scenes", nargs="+", default=None)
    parser.add_argument("--path-lights", type=int, default=None, help="lights on the circle besides the scene's (default 4)")
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    scenes = args.scenes or (["teapot"] if args.quick else ["teapot", "bunny", "ogre"])
    counts = QUICK if args.quick else FULL
    path_lights = args.path_lights if args.path_lights is not None else (1 if args.quick else 4)
    repeats = args.repeats or (1 if args.quick else 5)
    device = get_device()
    doc = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "machine": machine(device),
           "settings": {"receivers": counts, "seed": args.seed, "path_lights": path_lights, "repeats": repeats,
                        "fractions": list(lod.DEFAULT_FRACTIONS), "keep_component": lod.KEEP_COMPONENT,
                        "max_error": MAX_ERROR, "timing": f"median of {repeats} after a cold run and a warm-up"},
           "scenes": [measure_scene(device, name, counts, path_lights, repeats, args.seed) for name in scenes]}
    stem = "lod-quick" if args.quick else "lod"
    text = markdown(doc, f"{stem}.png")
    save(args.out, stem, doc, text, plot)
    print(text)
    return doc


if __name__ == "__main__":
    main()
