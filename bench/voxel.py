"""Bench of the voxel method (issue 5, Lai & Cheng): error and time against the exact method.

    python bench/voxel.py [--quick] [--out bench/results]

Scenes: scenes/subdivision/{cube,torus,toroidal_tet,suzanne}.toml (a subdivision-surface object on a
subdivision-surface ground, one point light). Ground truth: the exact method on a tessellation finer
than the voxels (segments per control edge with a chord error below 0.5 voxel at 1024^3: 32 for the
objects, 16 for suzanne), receivers area-weighted on that tessellation with face normals, the default
eps; half the receivers on the object, half on the ground.

Errors: ``all`` the whole scene against exact (``object`` and ``ground`` its receivers on each);
``self`` the *self-shadow* error: each surface alone (object alone, ground alone) under the same light
on the same voxel grid (grid_bounds = the whole scene's), against the exact method on that surface
alone, over both receiver halves: the errors a surface makes in shadowing itself, the paper's
topology-versus-offset claim (for the flat ground it is Figure 1's lit plane: any shadow is false).

1. Sweep: resolution 64..1024 x determination (topology, offset) x connectivity (26; 18 up to 512; 6
   up to 256: their leaf counts grow much faster), prepare (voxelize + determine) and classify; the
   exact method is the peer, timed in the same run (time ratio voxel / exact). Voxelization
   throughput: subpatches visited and occupied voxels per second of voxelization; memory: device bytes.
   Through the public calls (sc.prepare, Shadows.mask); median of repeats after a warm-up (timing.py;
   one run after it at 512 and 1024 to keep them bounded).
2. Second view of the same light (section 5.2): the classify time of a second receiver set with the
   frame buffer (a lookup) against without it (section 5.1: voxelize and determine again).
3. Figure 1: the scenes' flat subdivision ground alone under a grazing point or directional light
   (elevation 2..45 degrees): every receiver is lit, so every shadowed one is a false self-shadow.

Writes OUT/voxel.json, voxel.md, voxel.png. Timings share 2 cores with other work: noisy.
"""

from __future__ import annotations

import argparse
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import receivers as rx  # noqa: E402
from report import save  # noqa: E402
from run import public_steps  # noqa: E402
from timing import clock, timed, timed_steps  # noqa: E402

import shadowcl as sc  # noqa: E402
from shadowcl.methods import create_method, default_eps  # noqa: E402
from shadowcl.metrics import mask_error  # noqa: E402

PROJECT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).resolve().parent / "results"
SCENES = ["cube", "torus", "toroidal_tet", "suzanne"]
TRUTH_SEGMENTS = {"suzanne": 16}          # others: 32
FULL = dict(scenes=SCENES, resolutions=[64, 128, 256, 512, 1024], receivers=100_000, repeats=3,
            max_resolution={26: 1024, 18: 512, 6: 256}, figure1_resolutions=[64, 256, 1024])
QUICK = dict(scenes=["torus"], resolutions=[64], receivers=4_000, repeats=1, max_resolution={26: 64, 18: 0, 6: 0},
             figure1_resolutions=[64])


def fine_scene(name: str) -> sc.Scene:
    """The bench scene with every subdivision surface tessellated finer than a 1024^3 voxel."""
    scene = sc.Scene.load(PROJECT / "scenes" / "subdivision" / f"{name}.toml")
    objects = [(n, s, segments(name, n)) for n, s in scene.surfaces]
    return sc.Scene(objects, scene.lights, scene.camera, name=name)


def segments(scene_name: str, object_name: str) -> int:
    return 2 if object_name == "ground" else TRUTH_SEGMENTS.get(scene_name, 32)


def scene_receivers(scene: sc.Scene, count: int, seed: int):
    """(points, normals, on_object): half area-weighted on the object's fine tessellation, half on the
    ground's; on_object marks the first half."""
    rng = np.random.default_rng(seed)
    meshes = dict(scene.objects)
    obj = sc.Mesh.concatenate([m for n, m in scene.objects if n != "ground"])
    p1, n1 = rx.sample_triangles(obj, count // 2, rng)
    p2, n2 = rx.sample_triangles(meshes["ground"], count - count // 2, rng)
    on_object = np.arange(count) < count // 2
    return (np.concatenate([p1, p2]).astype(np.float64), np.concatenate([n1, n2]).astype(np.float64), on_object)


def occupied_voxels(method) -> int:
    """Occupied voxels of a prepared voxel method (its frame buffer: inside the method, untimed)."""
    words = method.vox.frame_words
    if words is None:
        return int(len(np.unique(method.vox.corner_voxels)))
    return int(np.bitwise_count((words | (words >> 1)) & np.uint32(0x55555555)).sum())


def errors(mask, truth, on_object) -> dict:
    return dict(all=mask_error(mask, truth).as_dict(), object=mask_error(mask[on_object], truth[on_object]).as_dict(),
                ground=mask_error(mask[~on_object], truth[~on_object]).as_dict())


def measure_scene(device, name: str, cfg: dict) -> dict:
    scene = fine_scene(name)
    light = scene.light
    points, normals, on_object = scene_receivers(scene, cfg["receivers"], seed=1)
    box = np.stack([points.min(axis=0), points.max(axis=0)])
    eps = default_eps(scene.mesh.bounds)
    exact = timed_steps(public_steps(scene.mesh, light, "exact", box, points, normals, device, eps), cfg["repeats"])
    exact_s, truth = exact["total"].median, exact["total"].result
    # Each surface alone, for the self-shadow error: its receivers and the exact answer without the others
    grid_box = np.stack([np.min([s.patch_table(device).points.min(axis=0) for _, s in scene.surfaces], axis=0),
                         np.max([s.patch_table(device).points.max(axis=0) for _, s in scene.surfaces], axis=0)])
    alone = []
    for object_name, surface in scene.surfaces:
        single = sc.Scene([(object_name, surface, segments(name, object_name))], scene.lights, name=object_name)
        rows = ~on_object if object_name == "ground" else on_object
        alone.append((single, rows, sc.prepare(single.mesh, light, "exact", bounds=box, device=device, eps=eps)
                      .mask(points[rows], normals[rows])))
    out = dict(scene=name, triangles=len(scene.mesh.faces), patches=sum(s.patch_count for _, s in scene.surfaces),
               receivers=len(points), on_object=int(on_object.sum()), exact_s=exact_s,
               truth_shadowed=float(truth.mean()), rows=[])
    for connectivity in (26, 18, 6):
        for resolution in cfg["resolutions"]:
            if resolution > cfg["max_resolution"][connectivity]:
                continue
            for determination in ("topology", "offset"):
                params = dict(resolution=resolution, determination=determination, connectivity=connectivity,
                              frame_buffer=True)
                repeats = cfg["repeats"] if resolution <= 256 else 1      # 512, 1024: one run after the warm-up
                prepared = timed(lambda: sc.prepare(scene, light, "voxel", bounds=box, device=device,
                                                    **params), repeats)
                shadows = prepared.result
                classified = timed(lambda: shadows.mask(points, normals), cfg["repeats"])
                prep_s, classify_s, mask = prepared.median, classified.median, classified.result
                st = shadows.stats
                row = dict(resolution=resolution, determination=determination, connectivity=connectivity,
                           prepare_s=prep_s, classify_s=classify_s, total_s=prep_s + classify_s,
                           ratio_to_exact=(prep_s + classify_s) / exact_s,
                           leaves=st["leaves"], subpatches=st["subpatches"], forced_leaves=st["forced_leaves"],
                           voxels=occupied_voxels(shadows._instance), voxelize_s=st["voxelize_s"],
                           determine_s=st["determine_s"], lists_s=st["lists_s"], sort_s=st["sort_s"],
                           device_bytes=st["device_bytes"], frame_bytes=st["frame_bytes"],
                           list_entries=st.get("list_entries", 0), unplaced=st.get("unplaced", 0),
                           **errors(mask, truth, on_object))
                row["subpatches_per_s"] = row["subpatches"] / max(row["voxelize_s"], 1e-9)
                if connectivity == 26:
                    self_mask, self_truth = np.zeros(len(points), bool), np.zeros(len(points), bool)
                    for single, rows, truth_alone in alone:
                        self_mask[rows] = sc.prepare(single, light, "voxel", bounds=box, device=device,
                                                     resolution=resolution, determination=determination,
                                                     grid_bounds=grid_box).mask(points[rows], normals[rows])
                        self_truth[rows] = truth_alone
                    row["self"] = mask_error(self_mask, self_truth).as_dict()
                    row["self_ground"] = mask_error(self_mask[~on_object], self_truth[~on_object]).as_dict()
                row["voxels_per_s"] = row["voxels"] / max(row["voxelize_s"], 1e-9)
                out["rows"].append(row)
                print(f"{name:13s} R={resolution:5d} N={connectivity:2d} {determination:8s} prepare {prep_s:7.3f} s "
                      f"classify {classify_s:6.3f} s  error {row['all']['percent']:6.2f} % (object "
                      f"{row['object']['percent']:6.2f} %, ground {row['ground']['percent']:6.2f} %, self "
                      f"{row.get('self', {}).get('percent', float('nan')):6.3f} %)  leaves {row['leaves']}",
                      flush=True)
                del shadows, prepared
    # Second view of the same light: frame buffer (lookup) against none (determine again)
    resolution = min(256, max(cfg["resolutions"]))
    view2, normals2, _ = scene_receivers(scene, cfg["receivers"], seed=2)
    second = {}
    for frame_buffer in (True, False):
        first_view, shadows = clock(lambda: sc.prepare(scene, light, "voxel", bounds=box, device=device,
                                                      resolution=resolution, determination="topology",
                                                      frame_buffer=frame_buffer))
        first_view += clock(lambda: shadows.mask(points, normals))[0]
        again = timed(lambda: shadows.mask(view2, normals2), cfg["repeats"])
        second["frame_buffer" if frame_buffer else "no_frame_buffer"] = dict(first_view_s=first_view,
                                                                             second_view_s=again.median)
        second.setdefault("masks", []).append(again.result)
    same = bool(np.array_equal(*second.pop("masks")))
    second.update(resolution=resolution, same_answer=same,
                  speedup=second["no_frame_buffer"]["second_view_s"] / second["frame_buffer"]["second_view_s"])
    out["second_view"] = second
    print(f"{name:13s} second view at {resolution}^3: frame buffer {second['frame_buffer']['second_view_s']:.4f} s, "
          f"without {second['no_frame_buffer']['second_view_s']:.3f} s ({second['speedup']:.0f}x), same={same}", flush=True)
    return out


def figure1(device, cfg: dict) -> list[dict]:
    """False self-shadows on a lit plane (the scenes' ground alone) under grazing light."""
    scene = fine_scene("torus")
    ground = [(n, s) for n, s in scene.surfaces if n == "ground"]
    plane = sc.Scene([(ground[0][0], ground[0][1], 2)], scene.lights, name="ground")
    rng = np.random.default_rng(3)
    points, normals = rx.sample_triangles(plane.mesh, cfg["receivers"] // 4, rng)
    points, normals = points.astype(np.float64), normals.astype(np.float64)
    box = np.stack([points.min(axis=0), points.max(axis=0)])
    eps = default_eps(plane.mesh.bounds)
    rows = []
    for elevation in (2, 5, 10, 20, 45):
        e = np.radians(elevation)
        lights = {"directional": sc.DirectionalLight((np.cos(e), -np.sin(e), 0.3)),
                  "point": sc.PointLight((-4 - 10 * np.cos(e), 10 * np.sin(e), 0.3))}
        for kind, light in lights.items():
            truth = sc.shadow_mask(plane, light, points, normals, method="exact")
            for resolution in cfg["figure1_resolutions"]:
                for determination in ("topology", "offset"):
                    # reached inside on purpose (untimed): the sample states of the frame buffer
                    method = create_method("voxel", device, resolution=resolution, determination=determination)
                    method.prepare(plane, light, box, eps)
                    mask = method.classify(points, normals)
                    rows.append(dict(elevation=elevation, light=kind, resolution=resolution, determination=determination,
                                     error=mask_error(mask, truth).as_dict(),
                                     shadowed_samples=float(np.mean(method.sample_states == 2))))
    for r in rows:
        print(f"figure 1: {r['light']:11s} {r['elevation']:2d} deg R={r['resolution']:4d} {r['determination']:8s} "
              f"false shadow {r['error']['percent']:.3f} % of receivers", flush=True)
    return rows


def self_cell(row: dict) -> str:
    if "self" not in row:
        return "-"
    e = row["self"]
    return f"{e['percent']:.3f} ({e['false_shadow']}/{e['false_light']})"


def claims(doc: dict) -> list[str]:
    """The paper's three claims, checked on this run's rows (N = 26)."""
    def row(s, R, det):
        return next((r for r in s["rows"] if (r["resolution"], r["determination"], r["connectivity"]) == (R, det, 26)), None)
    lines = ["## The paper's claims, checked (N = 26)", ""]
    cells = []
    for s in doc["scenes"]:
        t, o = row(s, 256, "topology"), row(s, 256, "offset")
        if t and o and "self" in t:
            cells.append(f"{s['scene']} {t['self']['percent']:.2f} % vs {o['self']['percent']:.2f} %")
    if cells:
        lines.append("1. Topology-based beats offset-based on self-shadow error at equal resolution (256^3, topology "
                     "vs offset): " + "; ".join(cells) + ". (Convex objects: their only self-shadow is the "
                     "terminator, decided by the N.L rule both share, so they can only tie.)")
    errs = [(s["scene"], row(s, 256, "topology")) for s in doc["scenes"]]
    errs = [(n, r) for n, r in errs if r]
    if errs:
        lines.append("2. 256^3 'acceptable': topology-based error against exact "
                     + "; ".join(f"{n} {r['all']['percent']:.2f} % ({r['all']['false_shadow']} false shadow, "
                                 f"{r['all']['false_light']} false light of {s['receivers']})"
                                 for (n, r), s in zip(errs, doc["scenes"]))
                     + ".")
        fine = [(row(s, 1024, "topology"), r) for (n, r), s in zip(errs, doc["scenes"])]
        ratios = [f["all"]["percent"] / r["all"]["percent"] for f, r in fine if f and r["all"]["percent"] > 0]
        if ratios:
            lines[-1] = lines[-1][:-1] + (f"; at 1024^3 the error is {min(ratios):.2f} to {max(ratios):.2f} "
                                          "of that.")
    sv = [(s["scene"], s["second_view"]) for s in doc["scenes"]]
    lines.append("3. The frame buffer makes a second view of the same light much faster (classify of a second "
                 f"receiver set at {sv[0][1]['resolution']}^3): " + "; ".join(
                     f"{n} {1e3 * v['frame_buffer']['second_view_s']:.0f} ms vs {1e3 * v['no_frame_buffer']['second_view_s']:.0f} ms "
                     f"({v['speedup']:.0f}x)" for n, v in sv) + ".")
    return lines + [""]


def markdown(doc: dict) -> str:
    lines = [f"# Voxel method (Lai & Cheng) against exact — {doc['date']}", "",
             f"Device: {doc['device']}. {doc['note']}", ""] + claims(doc)
    for s in doc["scenes"]:
        lines += [f"## {s['scene']}: {s['patches']} patches, truth on {s['triangles']} triangles, "
                  f"{s['receivers']} receivers ({s['on_object']} on the object); exact {s['exact_s']:.3f} s, "
                  f"{100 * s['truth_shadowed']:.1f} % shadowed", "",
                  "| R | N | determination | prepare s | classify s | x exact | error % | false shadow | false light | "
                  "object % | ground % | self-shadow % (fs/fl) | leaves | subpatches/s | voxels/s | device MiB |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in s["rows"]:
            lines.append(f"| {r['resolution']} | {r['connectivity']} | {r['determination']} | {r['prepare_s']:.3f} | "
                         f"{r['classify_s']:.4f} | {r['ratio_to_exact']:.2f} | {r['all']['percent']:.2f} | "
                         f"{r['all']['false_shadow']} | {r['all']['false_light']} | {r['object']['percent']:.2f} | "
                         f"{r['ground']['percent']:.2f} | {self_cell(r)} | {r['leaves']} | {r['subpatches_per_s']:.3g} | "
                         f"{r['voxels_per_s']:.3g} | {r['device_bytes'] / 2**20:.0f} |")
        sv = s["second_view"]
        lines += ["", f"Second view of the same light at {sv['resolution']}^3 (topology): with the frame buffer "
                  f"{1e3 * sv['frame_buffer']['second_view_s']:.1f} ms, without {1e3 * sv['no_frame_buffer']['second_view_s']:.1f} ms "
                  f"({sv['speedup']:.0f}x); same answer: {sv['same_answer']}.", ""]
    lines += ["## Figure 1: a lit plane under grazing light (false self-shadows, % of receivers)", "",
              "| light | elevation deg | R | topology % | offset % | offset shadowed samples % |", "|---|---|---|---|---|---|"]
    rows = doc["figure1"]
    for r in rows:
        if r["determination"] != "topology":
            continue
        o = next(x for x in rows if x["determination"] == "offset" and
                 (x["light"], x["elevation"], x["resolution"]) == (r["light"], r["elevation"], r["resolution"]))
        lines.append(f"| {r['light']} | {r['elevation']} | {r['resolution']} | {r['error']['percent']:.3f} | "
                     f"{o['error']['percent']:.3f} | {100 * o['shadowed_samples']:.2f} |")
    return "\n".join(lines) + "\n"


def plot(doc: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, len(doc["scenes"]), figsize=(4.2 * len(doc["scenes"]), 7), squeeze=False)
    for k, s in enumerate(doc["scenes"]):
        ax, bx = axes[0, k], axes[1, k]
        for det, style in (("topology", "-"), ("offset", "--")):
            rows = [r for r in s["rows"] if r["determination"] == det and r["connectivity"] == 26]
            R = [r["resolution"] for r in rows]
            ax.plot(R, [r["all"]["percent"] for r in rows], style, marker="o", label=f"{det}: scene")
            ax.plot(R, [r["self"]["percent"] for r in rows], style, marker="s", label=f"{det}: self-shadow")
            bx.plot(R, [r["total_s"] for r in rows], style, marker="o", label=f"{det}")
        bx.axhline(s["exact_s"], color="k", lw=0.8, label="exact (peer)")
        for a in (ax, bx):
            a.set_xscale("log", base=2)
            a.set_xlabel("resolution (voxels per side), N = 26")
        ax.set_yscale("symlog", linthresh=0.01)
        ax.set_ylim(bottom=0)
        ax.set_title(s["scene"])
        ax.set_ylabel("error % (vs exact)")
        bx.set_yscale("log")
        bx.set_ylabel("prepare + classify s")
        ax.legend(fontsize=7)
        bx.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="one small scene at 64^3 (a smoke test)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--scenes", nargs="*", help="subset of " + ", ".join(SCENES))
    args = parser.parse_args(argv)
    cfg = dict(QUICK if args.quick else FULL)
    if args.scenes:
        cfg["scenes"] = args.scenes
    device = sc.get_device()
    doc = dict(date=datetime.now(timezone.utc).isoformat(timespec="seconds"), device=device.name,
               note="2 cores shared with other work: timings are noisy; medians of repeats after a warm-up "
                    "(512 and 1024: one run after the warm-up).", config=cfg,
               figure1=figure1(device, cfg), scenes=[measure_scene(device, name, cfg) for name in cfg["scenes"]])
    stem = "voxel_quick" if args.quick else "voxel"
    save(args.out, stem, doc, markdown(doc), plot)
    return doc


if __name__ == "__main__":
    main()
