"""Frames per second in the shape of Fawad, Wang & Wu's Table II, on this machine, on a moving light.

    python bench/table2.py [--quick] [--scenes teapot bunny ogre] [--frames 120] [--repeats 2]
                           [--width 640] [--height 360] [--error-every 10] [--out DIR]

Rows: silhouette detection by brute force, tracking and the randomized method; columns: the original
mesh and the simplified one (Table I's level: teapot 0.5, bunny 0.1; ogre 0.1 like the bunny, it is
not in the paper), i.e. ``shadow_volume`` with ``silhouettes=`` brute / tracking / random and
``lod=None`` / that level. The light: a point light circling the model (bench/lod.py ``light_path``:
the scene light's height and horizontal distance), ``frames`` frames, 360 / frames degrees a frame.
The camera is the scene's, still, its receivers drawn once by the raster kernel (``width`` x ``height``).

A frame is ``prepare(mesh, light_i)`` on ONE method instance kept across frames (so tracking and random
use the last frame's silhouette: temporal coherence), which finds the silhouette, builds the volume
(and resolves the LOD level, cached), then ``classify_view``: the camera-view stencil of the volume
over the camera's Z-buffer, i.e. the classification of the camera's receivers. Stage times come from
the method's ``stats`` (lod, silhouette, volume, stencil).

Correctness first, on a scoring pass (a fresh instance along the whole path): every frame's
silhouette as the tracker found it (``method.tracked_silhouette``, before the method's brute-force
completion) against brute force on the same occluder mesh (recall = edges found / brute-force edges,
with orientation), the frames the method redid by brute force because that silhouette left the volume
open (``stats["silhouettes_missed"] > 0``: "redos"), and every ``error-every``-th frame's mask against
the exact method on the full mesh (false shadow, false light, % of covered pixels).
Timing: ``repeats`` more passes, each on a fresh instance (its first frame has no history); a frame's
time is its fastest pass; the table gives the median frame time over frames after the first, as
frames per second. The machine is shared (2 cores, other jobs): compare the ratios within one run,
not the absolute figures, and never with the paper's 2009 GPU-less figures, which are listed for the
shape only. The stencil dominates a frame and is the
most load-sensitive stage, so the silhouette stage is also given alone (``stats["silhouette_s"]``: the
tracker's update, the completeness check and, on a redo frame, the brute-force redo) as "silhouette
fps", next to its recall.
Writes OUT/table2.{json,md,png}.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

import receivers as rx
from lod import light_path
from report import save
from run import machine
from timing import clock
import shadowcl as sc
from shadowcl import get_device, lod, raster
from shadowcl.methods import create_method, default_eps, method_class
from shadowcl.metrics import mask_error
from shadowcl.render import camera_view

RESULTS = Path(__file__).resolve().parent / "results"
PROJECT = Path(__file__).resolve().parents[1]
SILHOUETTES = ("brute", "tracking", "random")
SIMPLIFIED = {"teapot": 0.5, "bunny": 0.1, "ogre": 0.1}        # Table I's fractions (ogre: as the bunny)
PAPER_FPS = {"teapot": {"brute": (48.00, 85.00), "tracking": (63.30, 90.00), "random": (95.00, 96.10)},
             "bunny": {"brute": (4.35, 34.09), "tracking": (4.90, 54.20), "random": (48.20, 92.00)}}


def require_methods() -> None:
    """Exit with a clear message unless the shadow-volume method and the silhouette trackers import."""
    try:
        method_class("shadow_volume")
        from shadowcl.silhouette import SilhouetteTracker  # noqa: F401
    except (ImportError, AttributeError, ValueError) as error:
        sys.exit(f"bench/table2.py needs shadowcl.shadow_volume (method 'shadow_volume' in METHODS) and "
                 f"shadowcl.silhouette.SilhouetteTracker, which do not import yet: {type(error).__name__}: {error}")


def edge_keys(oriented: np.ndarray, vertices: int) -> np.ndarray:
    """One int64 per oriented edge (tail, head)."""
    oriented = np.asarray(oriented, dtype=np.int64).reshape(-1, 2)
    return oriented[:, 0] * vertices + oriented[:, 1]


def run_path(device, scene, mesh, view, zbuffer, seen, lights, lod_level, silhouettes, eps,
             score: bool = False, truths=None, error_frames=()) -> list[dict]:
    """One pass along ``lights`` on one fresh method instance: per frame its stage times and, when
    ``score``, its silhouette recall against brute force and (on ``error_frames``) its error.

    A timing pass also runs a twin :class:`SilhouetteTracker` (the method's own settings, on the same
    occluder mesh, so the same edges) outside the frame's time, for the tracker's time alone
    (``tracker_s``): the method's silhouette stage adds its completeness check (a facing pass over
    every face when the tracker gives none) and, on a redo frame, the brute force.

    The method is driven directly (``prepare`` + ``classify_view``, render's stencil path) on purpose:
    Table II times the stages of each frame of a light path on one instance (its tracker's history)."""
    from shadowcl.silhouette import SilhouetteTracker, edge_adjacency, silhouette_edges

    method = create_method("shadow_volume", device, lod=lod_level, silhouettes=silhouettes)
    frames, twin = [], None
    for index, light in enumerate(lights):
        prepare_s, _ = clock(lambda: method.prepare(mesh, light, scene.bounds, eps))

        def stencil():
            mask = method.classify_view(view, zbuffer, seen)
            device.queue.finish()
            return mask
        stencil_s, mask = clock(stencil)
        stats = method.stats
        tracker_s = None
        if not score:
            if twin is None or twin.adjacency is not edge_adjacency(method.occluders):
                twin = SilhouetteTracker(device, method.occluders, method=silhouettes)
            tracker_s, _ = clock(lambda: (twin.update(light), device.queue.finish()))
        frame = {"frame": index, "frame_s": prepare_s + stencil_s, "prepare_s": prepare_s, "stencil_s": stencil_s,
                 "lod_s": stats["lod_s"], "silhouette_s": stats["silhouette_s"], "volume_s": stats["volume_s"],
                 "fallback": bool(stats["tracker"].get("fallback", False)),
                 "missed_edges": stats["silhouettes_missed"], "redo": stats["silhouettes_missed"] > 0,
                 "silhouette_edges": stats["silhouette_edges"], "volume_triangles": stats["volume_triangles"],
                 "tracker_s": tracker_s}
        if score:
            occluders = method.occluders
            brute = silhouette_edges(device, edge_adjacency(occluders), light).oriented
            # what the tracker found, not the volume's silhouette (completed by brute force on a redo)
            found = edge_keys(method.tracked_silhouette.oriented, len(occluders.vertices))
            truth_keys = edge_keys(brute, len(occluders.vertices))
            frame["brute_edges"] = len(truth_keys)
            frame["recall"] = float(np.isin(truth_keys, found).mean()) if len(truth_keys) else 1.0
            frame["precision"] = float(np.isin(found, truth_keys).mean()) if len(found) else 1.0
            if index in error_frames:
                frame["error"] = mask_error(mask, truths[index]).as_dict()
                # the same volume through shadow_mask's per-point count (at the point moved eps along its
                # normal), to tell the LOD's own error from the stencil's screen-space one (the stencil
                # moves the depth by eps along the pixel's ray only)
                count = method.classify(seen.points, seen.normals)
                frame["error_count"] = mask_error(count, truths[index]).as_dict()
        frames.append(frame)
    return frames


def exact_truths(device, mesh, seen, lights, eps, frames) -> dict:
    """The exact method's mask of the camera's receivers on the full mesh, for each of ``frames``."""
    return {index: sc.shadow_mask(mesh, lights[index], seen.points, seen.normals, device=device, eps=eps)
            for index in frames}


def summarise(scored: list[dict], timed: list[list[dict]]) -> dict:
    """Frame times (fastest pass per frame, median over frames after the first) and scores."""
    best = [min(run[i]["frame_s"] for run in timed) for i in range(len(scored))]
    frames = range(1, len(scored)) if len(scored) > 1 else range(len(scored))
    stage = {key: statistics.median(min(run[i][key] for run in timed) for i in frames)
             for key in ("prepare_s", "stencil_s", "lod_s", "silhouette_s", "volume_s", "tracker_s")}
    silhouette_mean = statistics.mean(min(run[i]["silhouette_s"] for run in timed) for i in frames)
    later = best[1:] if len(best) > 1 else best
    recalls = [f["recall"] for f in scored]
    errors = [f["error"] for f in scored if "error" in f]
    counts = [f["error_count"]["percent"] for f in scored if "error_count" in f]
    return {
        "frame_ms_median": 1e3 * statistics.median(later), "frame_ms_mean": 1e3 * statistics.mean(later),
        "fps": 1.0 / statistics.median(later), "first_frame_ms": 1e3 * best[0],
        **{f"{key[:-2]}_ms": 1e3 * value for key, value in stage.items()},
        "recall_mean": float(np.mean(recalls)), "recall_min": float(np.min(recalls)),
        "precision_min": float(np.min([f["precision"] for f in scored])),
        "fallbacks": int(sum(f["fallback"] for f in scored)),
        "redos": int(sum(f["redo"] for f in scored)), "missed_edges_max": int(max(f["missed_edges"] for f in scored)),
        "redos_timed": [int(sum(f["redo"] for f in run)) for run in timed],
        "silhouette_fps": 1.0 / stage["silhouette_s"], "silhouette_ms_mean": 1e3 * silhouette_mean,
        "tracker_fps": 1.0 / stage["tracker_s"],
        "silhouette_edges_mean": float(np.mean([f["brute_edges"] for f in scored])),
        "error_percent_mean": float(np.mean([e["percent"] for e in errors])) if errors else None,
        "error_percent_max": float(np.max([e["percent"] for e in errors])) if errors else None,
        "false_shadow_mean": float(np.mean([e["false_shadow"] for e in errors])) if errors else None,
        "false_light_mean": float(np.mean([e["false_light"] for e in errors])) if errors else None,
        "count_error_percent_mean": float(np.mean(counts)) if counts else None,
        "count_error_percent_max": float(np.max(counts)) if counts else None,
    }


def measure_scene(device, name: str, frames: int, repeats: int, size: tuple[int, int], error_every: int,
                  progress) -> dict:
    bench_scene = rx.load_scene(name)
    scene = sc.Scene.load(PROJECT / "scenes" / "models" / f"{name}.toml")
    mesh = scene.mesh
    eps = default_eps(scene.bounds)
    view = camera_view(scene, *size)
    zbuffer = raster.rasterize(device, mesh, view)
    seen = raster.receivers(device, mesh, view, zbuffer)
    lights = light_path(bench_scene, frames)
    error_frames = list(range(0, frames, error_every))
    truths = exact_truths(device, mesh, seen, lights, eps, error_frames)
    level = lod.DEFAULT_FRACTIONS.index(SIMPLIFIED.get(name, 0.1))
    simplified = lod.levels(mesh)[level]
    rows, failed = [], []
    for silhouettes in SILHOUETTES:
        for lod_level in (None, level):
            label = f"{silhouettes} {'original' if lod_level is None else 'simplified'}"
            progress(f"{name} {label}")
            try:
                scored = run_path(device, scene, mesh, view, zbuffer, seen, lights, lod_level, silhouettes, eps,
                                  score=True, truths=truths, error_frames=error_frames)
                timed = [run_path(device, scene, mesh, view, zbuffer, seen, lights, lod_level, silhouettes, eps)
                         for _ in range(repeats)]
            except Exception as error:      # one refused setting (say, a non-manifold occluder) must not end the run
                failed.append({"setting": label, "error": f"{type(error).__name__}: {error}"})
                progress(f"FAILED {name} {label}: {failed[-1]['error']}")
                continue
            rows.append({"scene": name, "silhouettes": silhouettes, "mesh": label.split()[1], "lod": lod_level,
                         "triangles": len((mesh if lod_level is None else simplified).faces), **summarise(scored, timed),
                         "frames_scored": scored})
    brute = next((r for r in rows if r["silhouettes"] == "brute" and r["lod"] is None), None)
    for row in rows:
        row["x_brute_original"] = row["fps"] / brute["fps"] if brute else None
    return {"scene": name, "source": bench_scene.source, "triangles": len(mesh.faces),
            "simplified_triangles": len(simplified.faces), "level": level, "receivers": len(seen.points),
            "rows": rows, "failed": failed}


def markdown(doc: dict, plot_name: str | None) -> str:
    m, s = doc["machine"], doc["settings"]
    lines = [f"# Table II on this machine: shadow-volume frames per second, {doc['date']}", "",
             f"- Machine: {m['cpu']}, {m['cores']} cores, shared with other jobs (timings noisy; compare ratios in "
             f"this run); OpenCL {m['opencl_device']}",
             f"- Path: point light circling the model, {s['frames']} frames ({360 / s['frames']:g} degrees a frame); "
             f"camera {s['width']}x{s['height']}, still; one method instance per path",
             f"- Frame = prepare (silhouette + volume) + classify_view (camera stencil); fps = 1 / median frame "
             f"time over frames 2..N, fastest of {s['repeats']} passes per frame",
             f"- Error vs exact on the full mesh every {s['error_every']} frames (% of covered pixels): 'error' is the "
             "frame's stencil mask, 'count error' the same volume through classify (shadow_mask's per-point count "
             "from the point moved eps along its normal; the stencil moves each pixel's depth by that offset along "
             "the pixel's ray only, so the two differ in screen space, along shadow edges)",
             "- Recall: the silhouette the tracker found (before the method's brute-force completion) vs brute force "
             "on the same occluder, every frame; redos: frames the method redid by brute force because that "
             "silhouette left the volume open (scoring pass)",
             "- Silhouette fps: 1 / median silhouette-stage time (tracker update + completeness check, a facing pass "
             "over every face for tracking and random, + the brute-force redo on a redo frame), fastest of the passes "
             "per frame: the stage the paper's rows differ in, without the load-sensitive stencil; tracker fps: the "
             "same for a twin SilhouetteTracker alone (same settings and edges, timed outside the frame)", ""]
    header = "| model | triangles orig / simpl | " + " | ".join(f"{k} orig | {k} simpl" for k in SILHOUETTES) + " |"
    lines += ["## Frames per second (the paper's Table II shape)", "", header, "|---|---|" + "---:|" * 6]
    for scene in doc["scenes"]:
        by = {(r["silhouettes"], r["mesh"]): r for r in scene["rows"]}
        cells = [f"{by[(k, v)]['fps']:.1f}" if (k, v) in by else "failed" for k in SILHOUETTES
                 for v in ("original", "simplified")]
        lines.append(f"| {scene['scene']} | {scene['triangles']} / {scene['simplified_triangles']} | " + " | ".join(cells) + " |")
    for name, paper in PAPER_FPS.items():
        lines.append(f"| {name} (paper) | | " + " | ".join(f"{v:.2f}" for k in SILHOUETTES for v in paper[k]) + " |")
    lines += ["", "## Silhouette stage only: fps of the method's stage / of the tracker alone (recall mean / min, "
              "redos / frames)", "", header,
              "|---|---|" + "---:|" * 6]
    for scene in doc["scenes"]:
        by = {(r["silhouettes"], r["mesh"]): r for r in scene["rows"]}
        cells = [silhouette_cell(by[(k, v)]) if (k, v) in by else "failed" for k in SILHOUETTES
                 for v in ("original", "simplified")]
        lines.append(f"| {scene['scene']} | {scene['triangles']} / {scene['simplified_triangles']} | " + " | ".join(cells) + " |")
    lines += ["", "## Per setting", "", "| model | setting | tris | ms/frame | fps | x brute orig | lod ms | silhouette ms | "
              "volume ms | stencil ms | first frame ms | silhouette fps | tracker fps | recall mean | recall min | fallbacks | redos | "
              "error % mean | error % max | count error % mean | count error % max |", "|---|---|" + "---:|" * 19]
    for scene in doc["scenes"]:
        for r in scene["rows"]:
            err = " | | | " if r["error_percent_mean"] is None else (
                f"{r['error_percent_mean']:.3f} | {r['error_percent_max']:.3f} | "
                f"{r['count_error_percent_mean']:.3f} | {r['count_error_percent_max']:.3f}")
            lines.append(f"| {r['scene']} | {r['silhouettes']} {r['mesh']} | {r['triangles']} | {r['frame_ms_median']:.1f} | "
                         f"{r['fps']:.1f} | {r['x_brute_original']:.2f} | {r['lod_ms']:.2f} | {r['silhouette_ms']:.1f} | "
                         f"{r['volume_ms']:.1f} | {r['stencil_ms']:.1f} | {r['first_frame_ms']:.0f} | "
                         f"{r['silhouette_fps']:.0f} | {r['tracker_fps']:.0f} | {r['recall_mean']:.4f} | {r['recall_min']:.4f} | {r['fallbacks']} | "
                         f"{r['redos']} | {err} |")
        for f in scene["failed"]:
            lines.append(f"- FAILED {scene['scene']} {f['setting']}: {f['error']}")
    lines += ["", "## Notes (computed from the rows above)", "", *notes(doc)]
    if plot_name:
        lines += ["", f"![frames per second and recall]({plot_name})"]
    return "\n".join(lines) + "\n"


def silhouette_cell(r: dict) -> str:
    """Silhouette-stage fps / tracker-only fps (recall mean / min, redos / frames) of one setting."""
    return (f"{r['silhouette_fps']:.0f} / {r['tracker_fps']:.0f} ({r['recall_mean']:.4f} / {r['recall_min']:.4f}, "
            f"{r['redos']}/{len(r['frames_scored'])})")


def notes(doc: dict) -> list[str]:
    """Where a frame's time goes, which silhouette method is fastest at which recall, and what the
    brute-force redos of incomplete silhouettes cost and leave."""
    lines = []
    for scene in doc["scenes"]:
        rows = scene["rows"]
        if not rows:
            continue
        share = np.mean([r["stencil_ms"] / r["frame_ms_median"] for r in rows])
        lines.append(f"- {scene['scene']}: the camera stencil takes {100 * share:.0f} % of a frame on average.")
        for mesh in ("original", "simplified"):
            ranked = sorted((r for r in rows if r["mesh"] == mesh), key=lambda r: -r["silhouette_fps"])
            if ranked:
                lines.append(f"- {scene['scene']} {mesh}, silhouette stage fastest first: " + "; ".join(
                    f"{r['silhouettes']} {r['silhouette_fps']:.0f} fps ({r['silhouette_ms']:.2f} ms median, "
                    f"{r['silhouette_ms_mean']:.2f} ms mean; tracker alone {r['tracker_fps']:.0f} fps) at recall mean {r['recall_mean']:.4f}, min "
                    f"{r['recall_min']:.4f}" for r in ranked))
        for r in rows:
            if r["redos"] and r["error_percent_max"] is not None:
                lines.append(f"- {scene['scene']} {r['silhouettes']} {r['mesh']}: {r['redos']} of "
                             f"{len(r['frames_scored'])} frames redone by brute force (up to {r['missed_edges_max']} "
                             f"edges missed); with the redo the stencil error stays at {r['error_percent_max']:.3f} % "
                             f"of pixels at most (count {r['count_error_percent_max']:.3f} %)")
    return lines


def plot(doc: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = doc["scenes"]
    figure, axes = plt.subplots(1, 3, figsize=(16, 4.2))
    width = 0.13
    for j, (k, v) in enumerate((k, v) for k in SILHOUETTES for v in ("original", "simplified")):
        fps = [next((r["fps"] for r in s["rows"] if r["silhouettes"] == k and r["mesh"] == v), 0) for s in scenes]
        axes[0].bar(np.arange(len(scenes)) + (j - 2.5) * width, fps, width, label=f"{k} {v}",
                    hatch="//" if v == "simplified" else None)
    axes[0].set(xticks=range(len(scenes)), xticklabels=[s["scene"] for s in scenes], ylabel="frames per second",
                title="shadow-volume frames per second (this machine)")
    axes[0].legend(fontsize=7)
    for s in scenes:
        for r in s["rows"]:
            if r["silhouettes"] != "brute":
                axes[1].plot([f["recall"] for f in r["frames_scored"]], label=f"{s['scene']} {r['silhouettes']} {r['mesh']}")
    axes[1].set(xlabel="frame", ylabel="recall vs brute force", title="silhouette recall along the path")
    axes[1].legend(fontsize=6)
    markers = dict(zip(SILHOUETTES, "os^"))
    for s, colour in zip(scenes, plt.rcParams["axes.prop_cycle"].by_key()["color"]):
        for r in s["rows"]:
            axes[2].plot(r["recall_mean"], r["silhouette_fps"], markers[r["silhouettes"]], color=colour, ms=8,
                         mfc=colour if r["mesh"] == "original" else "none", label=f"{s['scene']} {r['silhouettes']} {r['mesh']}")
    axes[2].set(yscale="log", xlabel="recall mean vs brute force (tracker's own silhouette)",
                ylabel="silhouette-stage fps", title="silhouette stage: speed vs recall\n(filled: original, hollow: simplified)")
    axes[2].legend(fontsize=5, ncol=2)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="teapot only, 8 frames, 1 timed pass, 320x180")
    parser.add_argument("--scenes", nargs="+", default=None)
    parser.add_argument("--frames", type=int, default=None)
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--width", type=int, default=None)
    parser.add_argument("--height", type=int, default=None)
    parser.add_argument("--error-every", type=int, default=None)
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument("--from-json", type=Path, help="rewrite the .md and .png of a saved run, measure nothing")
    args = parser.parse_args(argv)
    if args.from_json:
        doc = json.loads(args.from_json.read_text())
        plot(doc, args.from_json.with_suffix(".png"))
        text = markdown(doc, args.from_json.with_suffix(".png").name)
        args.from_json.with_suffix(".md").write_text(text)
        print(text)
        return doc
    require_methods()
    quick = args.quick
    settings = {"frames": args.frames or (8 if quick else 120), "repeats": args.repeats or (1 if quick else 2),
                "width": args.width or (320 if quick else 640), "height": args.height or (180 if quick else 360),
                "error_every": args.error_every or (4 if quick else 10),
                "simplified": SIMPLIFIED, "timing": "fastest of the timed passes per frame, median over frames 2..N"}
    scenes = args.scenes or (["teapot"] if quick else ["teapot", "bunny", "ogre"])
    device = get_device()
    progress = (lambda text: None) if args.quiet else (lambda text: print(text, file=sys.stderr, flush=True))
    doc = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "machine": machine(device),
           "settings": settings, "scenes": []}
    args.out.mkdir(parents=True, exist_ok=True)
    stem = "table2-quick" if quick else "table2"
    for name in scenes:                     # written after every scene: a long run interrupted keeps its part
        doc["scenes"].append(measure_scene(device, name, settings["frames"], settings["repeats"],
                                           (settings["width"], settings["height"]), settings["error_every"], progress))
        text = markdown(doc, f"{stem}.png")
        save(args.out, stem, doc, text, plot)
    print(text)
    return doc


if __name__ == "__main__":
    main()
