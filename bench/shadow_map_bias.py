"""Shadow-map biases with and without normals, on scenes built here (none from ../shared) and on the bench scenes.

    python bench/shadow_map_bias.py                    # new scenes: 4 models x 4 lights, 1 M + 200 k receivers
    python bench/shadow_map_bias.py --bench-scenes     # bunny, ogre, default, light_inside (bench/run.py's scenes)
    python bench/shadow_map_bias.py --quick            # 80 k + 20 k receivers, two resolutions

Each scene x light x resolution x bias x filter is one ``sc.prepare(..., method="shadow_map", bounds=<the
receivers' box>)`` queried twice through ``Shadows.mask``, with the receivers' normals and without, and
compared with ``sc.shadow_mask(..., method="exact")`` given the same normals (or none). The new scenes
(:func:`new_scenes`) each stand on a 40 x 40 ground quad: a (2, 3) torus knot tube, a CSG bracket
(manifold3d), a subdivided, squashed icosphere and a stack of four perturbed boxes, each about 4 units
tall; receivers are 1 M points on the ground in a square 4 times the model's footprint and 200 k on the
model's surface (area-weighted, face normals). Lights: a low point light (long shadows), a close one
(severe perspective), a high one, and a directional light. Query times are one call each, for a
rough comparison; the speed ratio of the biases is :func:`speed_ratio` (interleaved medians).
Writes ``bench/results/shadow-map-bias[-bench].{json,md}``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import manifold3d as m3
import numpy as np
import trimesh

import receivers as rx
import shadowcl as sc
from shadowcl.metrics import mask_error
from timing import interleaved

RESULTS = Path(__file__).resolve().parent / "results"
RESOLUTIONS = (512, 1024, 2048, 4096)
BIASES = ("plane", "normal", "slope", "constant")
FILTERS = ("nearest", "pcf")
PCF_BIASES = ("plane", "normal")   # pcf is measured for the default and the former default only
FULL = {"ground": 1_000_000, "model": 200_000}
QUICK = {"ground": 80_000, "model": 20_000}
GROUND_SIDE = 40.0
MODEL_HEIGHT = 4.0


# New scenes -------------------------------------------------------------------------------------


def _from_manifold(manifold) -> sc.Mesh:
    mesh = manifold.to_mesh()
    return sc.Mesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts))


def torus_knot(p: int = 2, q: int = 3, segments: int = 600, sides: int = 24, tube: float = 0.35) -> sc.Mesh:
    """A closed tube of radius ``tube`` around the (p, q) torus knot, Frenet frames from finite differences."""
    u = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    r = 2 + np.cos(q * u)
    curve = np.column_stack([r * np.cos(p * u), np.sin(q * u), r * np.sin(p * u)])
    tangent = np.roll(curve, -1, axis=0) - np.roll(curve, 1, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.roll(tangent, -1, axis=0) - np.roll(tangent, 1, axis=0)
    normal -= np.einsum("ij,ij->i", normal, tangent)[:, None] * tangent
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    binormal = np.cross(tangent, normal)
    v = np.linspace(0, 2 * np.pi, sides, endpoint=False)
    ring = np.cos(v)[None, :, None] * normal[:, None] + np.sin(v)[None, :, None] * binormal[:, None]
    vertices = (curve[:, None] + tube * ring).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(segments), np.arange(sides), indexing="ij")
    a, b = i * sides + j, ((i + 1) % segments) * sides + j
    c, d = ((i + 1) % segments) * sides + (j + 1) % sides, i * sides + (j + 1) % sides
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return sc.Mesh(vertices, faces)


def bracket() -> sc.Mesh:
    """An L bracket with a gusset and four bolt holes: manifold3d CSG."""
    base = m3.Manifold.cube((3.0, 0.3, 1.6))
    upright = m3.Manifold.cube((0.3, 2.0, 1.6))
    gusset = m3.Manifold.extrude(m3.CrossSection([[(0.3, 0.3), (1.5, 0.3), (0.3, 1.5)]]), 0.2).translate((0, 0, 0.7))
    holes = [m3.Manifold.cylinder(1.0, 0.18, 0.18, 48).rotate((-90, 0, 0)).translate((x, -0.3, z)) for x in (1.2, 2.4) for z in (0.4, 1.2)]
    holes += [m3.Manifold.cylinder(1.0, 0.18, 0.18, 48).rotate((0, 90, 0)).translate((-0.3, y, 0.8)) for y in (0.9, 1.6)]
    shape = base + upright + gusset
    for hole in holes:
        shape = shape - hole
    return _from_manifold(shape)


def icosphere() -> sc.Mesh:
    """A subdivided icosphere (5,120 faces), squashed and tilted: smooth curvature at every light angle."""
    sphere = trimesh.creation.icosphere(subdivisions=4)
    vertices = sphere.vertices * [1.0, 0.7, 1.3]
    tilt = trimesh.transformations.rotation_matrix(0.4, [1, 0, 1])[:3, :3]
    return sc.Mesh(vertices @ tilt.T, sphere.faces)


def box_stack(seed: int = 3) -> sc.Mesh:
    """Four boxes stacked, each turned about the vertical and shifted a little, corners perturbed."""
    rng = np.random.default_rng(seed)
    boxes, y = [], 0.0
    for size in ((2.0, 0.8, 1.6), (1.6, 0.7, 1.2), (1.2, 0.9, 1.0), (0.8, 0.6, 0.7)):
        box = trimesh.creation.box(extents=size)
        box.vertices += rng.normal(scale=0.03, size=box.vertices.shape)
        turn = trimesh.transformations.rotation_matrix(rng.uniform(-0.6, 0.6), [0, 1, 0])
        box.apply_transform(turn)
        box.apply_translation((rng.uniform(-0.15, 0.15), y + size[1] / 2 - box.vertices[:, 1].min() - size[1] / 2,
                               rng.uniform(-0.15, 0.15)))
        y = box.vertices[:, 1].max() - 0.02   # the next box rests slightly sunk into this one
        boxes.append(sc.Mesh(box.vertices, box.faces))
    return sc.Mesh.concatenate(boxes)


def on_ground(name: str, model: sc.Mesh) -> rx.BenchScene:
    """``model`` scaled to MODEL_HEIGHT tall, standing at the centre of a GROUND_SIDE square ground quad,
    under the four lights of :func:`lights`."""
    low, high = model.bounds
    scale = MODEL_HEIGHT / float(high[1] - low[1])
    matrix = np.eye(4)
    matrix[:3, :3] *= scale
    matrix[:3, 3] = -scale * np.array([(low[0] + high[0]) / 2, low[1], (low[2] + high[2]) / 2])
    model = rx.outward(model.transformed(matrix))
    mesh = sc.Mesh.concatenate([model, rx.ground_quad((0.0, 0.0), GROUND_SIDE, 0.0)])
    return rx.BenchScene(name, mesh, lights(), "bench/shadow_map_bias.py", model, 0.0)


def lights() -> list:
    """Low (long shadows), close (severe perspective), high point lights and a directional light."""
    h = MODEL_HEIGHT
    return [sc.PointLight((3.0 * h, 0.6 * h, 1.2 * h)), sc.PointLight((0.9 * h, 1.5 * h, 0.6 * h)),
            sc.PointLight((0.6 * h, 6.0 * h, -0.4 * h)), sc.DirectionalLight((-0.45, -1.0, 0.3))]


LIGHT_NAMES = ("low point", "close point", "high point", "directional")


def new_scenes() -> list[rx.BenchScene]:
    return [on_ground("torus_knot", torus_knot()), on_ground("bracket", bracket()),
            on_ground("icosphere", icosphere()), on_ground("box_stack", box_stack())]


def ground_receivers(scene: rx.BenchScene, count: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Ground points in a square 4 times the model's footprint (long shadows included), normal up."""
    low, high = scene.model.bounds
    side = 4.0 * float(max(high[0] - low[0], high[2] - low[2]))
    xz = (rng.random((count, 2)) - 0.5) * side
    points = np.column_stack([xz[:, 0], np.full(count, scene.ground_y), xz[:, 1]])
    return points, np.broadcast_to([0.0, 1.0, 0.0], points.shape).copy()


def scene_receivers(scene: rx.BenchScene, counts: dict, new: bool, seed: int = 0):
    if not new:
        return rx.receivers(scene, counts["ground"], counts["model"], seed)
    rng = np.random.default_rng(seed)
    ground = ground_receivers(scene, counts["ground"], rng)
    model = rx.sample_triangles(scene.model, counts["model"], rng)
    return np.concatenate([ground[0], model[0]]), np.concatenate([ground[1], model[1]])


# Measurement ------------------------------------------------------------------------------------


def measure(scenes, counts, resolutions, biases, filters, new: bool) -> list[dict]:
    rows = []
    for scene in scenes:
        points, normals = scene_receivers(scene, counts, new)
        bounds = np.stack([points.min(0), points.max(0)])
        for k, light in enumerate(scene.lights):
            truths = {given: sc.shadow_mask(scene.mesh, light, points, normals if given else None, method="exact")
                      for given in (True, False)}
            for resolution in resolutions:
                for bias in biases:
                    for filter in [f for f in filters if f == "nearest" or bias in PCF_BIASES]:
                        shadows = sc.prepare(scene.mesh, light, "shadow_map", bounds=bounds, resolution=resolution,
                                             bias=bias, filter=filter)
                        for given in (True, False):
                            start = time.perf_counter()
                            mask = shadows.mask(points, normals if given else None)
                            seconds = time.perf_counter() - start
                            error = mask_error(mask, truths[given])
                            rows.append(dict(scene=scene.name, light=k, resolution=resolution, bias=bias,
                                             filter=filter, normals=given, receivers=len(points),
                                             false_shadow=error.false_shadow, false_light=error.false_light,
                                             error_pct=100 * error.fraction, query_s=seconds))
                            print(f"{scene.name:12s} {k} {resolution:5d} {bias:8s} {filter:8s} normals={given!s:5s} "
                                  f"{100 * error.fraction:8.4f} % ({error.false_shadow} fs, {error.false_light} fl) "
                                  f"{seconds:.2f} s", flush=True)
    return rows


def speed_ratio(scene: rx.BenchScene, counts: dict, new: bool, repeats: int = 5) -> dict:
    """Query time of "plane", "normal" (2048, nearest) and the exact method, interleaved medians (each prepared once)."""
    points, normals = scene_receivers(scene, counts, new)
    bounds = np.stack([points.min(0), points.max(0)])
    out = {}
    for given in (True, False):
        prepared = {bias: sc.prepare(scene.mesh, scene.lights[0], "shadow_map", bounds=bounds, bias=bias)
                    for bias in ("plane", "normal")}
        prepared["exact"] = sc.prepare(scene.mesh, scene.lights[0], "exact", bounds=bounds)
        timings = interleaved({bias: (lambda s=s: s.mask(points, normals if given else None))
                               for bias, s in prepared.items()}, repeats)
        out["with" if given else "without"] = {bias: t.median for bias, t in timings.items()}
    return out


def table(rows: list[dict]) -> str:
    lines = ["| scene | light | resolution | bias | filter | normals | false shadow | false light | error % | query s |",
             "|---|---|---:|---|---|---|---:|---:|---:|---:|"]
    for r in rows:
        lines.append(f"| {r['scene']} | {r['light']} | {r['resolution']} | {r['bias']} | {r['filter']} | "
                     f"{'yes' if r['normals'] else 'no'} | {r['false_shadow']} | {r['false_light']} | "
                     f"{r['error_pct']:.4f} | {r['query_s']:.2f} |")
    return "\n".join(lines)


def summary(rows: list[dict]) -> str:
    """Worst and mean error per (bias, filter, normals, resolution) over every scene x light."""
    keys = sorted({(r["bias"], r["filter"], r["normals"], r["resolution"]) for r in rows},
                  key=lambda k: (BIASES.index(k[0]) if k[0] in BIASES else 9, k[1], not k[2], k[3]))
    lines = ["| bias | filter | normals | resolution | cases | mean error % | worst error % | worst case |",
             "|---|---|---|---:|---:|---:|---:|---|"]
    for key in keys:
        sel = [r for r in rows if (r["bias"], r["filter"], r["normals"], r["resolution"]) == key]
        worst = max(sel, key=lambda r: r["error_pct"])
        lines.append(f"| {key[0]} | {key[1]} | {'yes' if key[2] else 'no'} | {key[3]} | {len(sel)} | "
                     f"{np.mean([r['error_pct'] for r in sel]):.4f} | {worst['error_pct']:.4f} | "
                     f"{worst['scene']} light {worst['light']} |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--bench-scenes", action="store_true", help="bench/run.py's scenes instead of the new ones")
    parser.add_argument("--resolutions", nargs="+", type=int)
    parser.add_argument("--biases", nargs="+", default=list(BIASES))
    parser.add_argument("--filters", nargs="+", default=list(FILTERS))
    parser.add_argument("--out")
    parser.add_argument("--speed-only", action="store_true",
                        help="measure only the plane / normal speed ratio and update it in the existing results")
    args = parser.parse_args()
    counts = QUICK if args.quick else FULL
    resolutions = args.resolutions or ((512, 2048) if args.quick else RESOLUTIONS)
    new = not args.bench_scenes
    scenes = new_scenes() if new else [rx.load_scene(s) for s in ("bunny", "ogre", str(rx.PROJECT / "scenes/default.toml"),
                                                                   str(rx.PROJECT / "scenes/hard/light_inside.toml"))]
    stem = args.out or ("shadow-map-bias" + ("" if new else "-bench") + ("-quick" if args.quick else ""))
    if args.speed_only:   # the masks do not change when only the kernel's speed does
        doc = json.loads((RESULTS / f"{stem}.json").read_text())
        rows = doc["rows"]
        args.biases, args.filters, resolutions = doc["settings"]["biases"], doc["settings"]["filters"], doc["settings"]["resolutions"]
    else:
        rows = measure(scenes, counts, resolutions, args.biases, args.filters, new)
    ratio = speed_ratio(scenes[0], counts, new)
    doc = dict(settings=dict(counts=counts, resolutions=list(resolutions), biases=args.biases, filters=args.filters,
                             scenes=[s.name for s in scenes], lights={s.name: [str(l) for l in s.lights] for s in scenes}),
               rows=rows, speed_ratio=dict(scene=scenes[0].name, light=0, **ratio))
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{stem}.json").write_text(json.dumps(doc, indent=1))
    text = [f"# Shadow-map biases with and without normals ({'new scenes' if new else 'bench scenes'})", "",
            f"Receivers per scene: {counts['ground']} ground + {counts['model']} model; truth: the exact method "
            "with the same normals (or none). Lights: " + "; ".join(f"{s.name}: " + ", ".join(map(str, s.lights))
                                                                    for s in scenes[:1]) + ".", "",
            f"Query time, {scenes[0].name} light 0 at 2048 nearest, interleaved medians of 5: " +
            ", ".join(f"{k} normals: plane {v['plane']:.3f} s, normal {v['normal']:.3f} s, exact {v['exact']:.3f} s "
                      f"(plane / normal {v['plane'] / v['normal']:.2f}, plane / exact {v['plane'] / v['exact']:.2f})"
                      for k, v in ratio.items()) + ".", "",
            "## Summary over scenes and lights", "", summary(rows), "", "## Every case", "", table(rows), ""]
    (RESULTS / f"{stem}.md").write_text("\n".join(text))
    print(summary(rows))


if __name__ == "__main__":
    main()
