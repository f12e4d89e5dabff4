"""Silhouette edges along moving lights: brute force, tracking and the randomized method, time and recall.

    python bench/silhouettes.py [--models stanford-bunny teapot ogre] [--repeats 3] [--quick]

Paths (a point light 1.5 bounding-box diagonals from each model's centre, a quarter diagonal above
it): ``circle`` 120 frames, 3 degrees a frame; ``fast`` 24 frames, 15 degrees a frame.
Settings: ``SilhouetteTracker`` methods brute (the peer: every edge on the device), tracking (walks
on the device, concave seeds from 180 degrees; concave seeds from 185 degrees, cheaper), random with
fractions 0.02, 0.1 and 0.5 (grown on the host; big face batches on the device, or not): where the
device pays.

Correctness first: the first frame's brute force is checked against the float64 reference (away from
ties), then every frame of every setting is scored against brute force (recall, precision; an edge
counts with its orientation). Timing: each path is run ``repeats`` times with a reset tracker after a
warm-up run; a frame's time is its fastest run, and the row gives the median over frames after the
first (the first frame has no history). The machine is shared (2 cores, other jobs running): timings
are noisy, ratios to brute force in the same run are the figures to quote. Also per model: the
adjacency build, ``silhouette_loops``, the NumPy host classification of every edge, and the cost of
testing faces on the host (``host_facing``) against one device pass over every face.
Writes results/silhouettes.{json,md,png}.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import shadowcl as sc
from shadowcl.reference import silhouette as ref
from shadowcl.silhouette import (SilhouetteTracker, _facing_on_device, edge_adjacency, host_facing, silhouette_edges,
                                 silhouette_loops)
from timing import clock, timed

MODELS = Path(__file__).resolve().parents[2] / "shared" / "models"
RESULTS = Path(__file__).resolve().parent / "results"
PATHS = {"circle": (120, 3.0), "fast": (24, 15.0)}
QUICK_PATHS = {"circle": (12, 3.0), "fast": (4, 15.0)}
SETTINGS = [
    ("brute", {"method": "brute"}),
    ("tracking", {"method": "tracking"}),
    ("tracking concave>=185", {"method": "tracking", "concave_angle": 5.0}),
    ("random 0.02", {"method": "random", "fraction": 0.02}),
    ("random 0.1", {"method": "random", "fraction": 0.1}),
    ("random 0.5", {"method": "random", "fraction": 0.5}),
    ("random 0.02 host faces", {"method": "random", "fraction": 0.02, "device_batch": 10**12}),
]
RECALL_BAR = 0.99      # issue 6: tracking finds >= 99 % of the brute-force silhouette edges


def light_path(mesh, frames: int, degrees: float) -> list:
    centre = mesh.bounds.mean(axis=0)
    diagonal = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    angles = np.radians(degrees * np.arange(frames))
    offsets = np.stack([1.5 * np.cos(angles), np.full(frames, 0.25), 1.5 * np.sin(angles)], axis=1)
    return [sc.PointLight(centre + diagonal * o) for o in offsets]


def host_codes(adjacency, light) -> np.ndarray:
    """A host peer of the brute force: codes in NumPy (float64 facing, the same rules)."""
    facing = ref.facing_values(adjacency.vertices, adjacency.faces, light)[0] > 0
    f0, f1 = adjacency.edge_faces.T
    lit0, lit1 = facing[f0], (f1 >= 0) & facing[np.maximum(f1, 0)]
    return np.where(lit0 == lit1, 0, np.where(lit0, adjacency.edge_senses[:, 0], adjacency.edge_senses[:, 1]))


def check_first_frame(device, mesh, light) -> None:
    sil = silhouette_edges(device, mesh, light)
    truth = ref.classify(mesh.vertices, mesh.faces, light)["oriented"]
    adjacency = sil.adjacency
    owner_edge = np.repeat(np.arange(len(adjacency.edges)), adjacency.face_count)
    tie_items = np.isin(adjacency.face_items, ref.tie_faces(mesh.vertices, mesh.faces, light))
    near_tie = set(map(tuple, adjacency.edges[np.unique(owner_edge[tie_items])].tolist()))
    got = {e for e in map(tuple, sil.oriented.tolist()) if (min(e), max(e)) not in near_tie}
    expected = {e for e in truth if (min(e), max(e)) not in near_tie}
    if got != expected:
        raise SystemExit(f"silhouettes differ from the reference on {len(got ^ expected)} edges; not timing")


def median_ms(function, repeats: int) -> float:
    return timed(function, repeats).median_ms


def follow(device, adjacency, lights, truths, params: dict, repeats: int) -> dict:
    """One setting along one path: scored on the first run, timed on ``repeats`` more after it. The
    tracker is timed directly (it is inside ``shadow_volume``; no public call times it alone), frame by
    frame with ``clock``: its state makes frames differ, so a frame keeps its fastest pass."""
    tracker = SilhouetteTracker(device, adjacency, **params)
    recalls, precisions, fallbacks, tested = [], [], 0, []
    for light, truth in zip(lights, truths):                      # scoring run (also the warm-up)
        sil = tracker.update(light)
        recall, precision = ref.recall_precision(sil.codes, truth.codes)
        recalls.append(recall)
        precisions.append(precision)
        fallbacks += bool(tracker.stats.get("fallback"))
        tested.append(tracker.stats["faces_tested"] if tracker.stats["faces_tested"] is not None else np.nan)
    best = np.full(len(lights), np.inf)
    for _ in range(repeats):
        tracker.reset()
        for i, light in enumerate(lights):
            best[i] = min(best[i], clock(lambda: tracker.update(light))[0])
    return {"frame_ms": 1e3 * float(np.median(best[1:])), "first_frame_ms": 1e3 * float(best[0]),
            "recall_mean": float(np.mean(recalls[1:])), "recall_min": float(np.min(recalls[1:])),
            "recall_first": float(recalls[0]), "precision_min": float(np.min(precisions)),
            "fallback_frames": fallbacks, "faces_tested_median": _int_or_none(np.median(tested[1:]))}


def _int_or_none(value: float):
    return None if np.isnan(value) else int(value)


def _count(value, missing: str) -> str:
    return missing if value is None else f"{value:,}"


def measure(device, name: str, paths: dict, repeats: int) -> tuple[dict, list]:
    mesh = sc.Mesh.load(MODELS / f"{name}.obj")
    adjacency_s, adjacency = clock(lambda: edge_adjacency(mesh))
    adjacency_ms = 1e3 * adjacency_s
    lights = light_path(mesh, *paths["circle"])
    check_first_frame(device, mesh, lights[0])
    light = lights[0]
    sil = silhouette_edges(device, adjacency, light)
    some = np.random.default_rng(0).choice(len(mesh.faces), min(4000, len(mesh.faces)), replace=False)

    def device_pass():
        facing_g, _ = _facing_on_device(device, adjacency, light)
        device.from_device(facing_g, len(mesh.faces), np.uint8)

    model = {"model": name, "triangles": len(mesh.faces), "edges": len(adjacency.edges),
             "border_edges": len(adjacency.border_edges), "adjacency_ms": adjacency_ms,
             "brute_ms": median_ms(lambda: silhouette_edges(device, adjacency, light), repeats),
             "loops_ms": median_ms(lambda: silhouette_loops(sil), repeats),
             "host_numpy_classify_ms": median_ms(lambda: host_codes(adjacency, light), repeats),
             "host_facing_4000_faces_ms": median_ms(lambda: host_facing(mesh.vertices, mesh.faces, light, some),
                                                    repeats),
             "device_facing_pass_ms": median_ms(device_pass, repeats),
             "silhouette_edges": int(sil.mask.sum()), "loops": len(silhouette_loops(sil)),
             "concave_edges": len(SilhouetteTracker(device, adjacency, method="tracking").concave_edges)}
    rows = []
    for path, (frames, degrees) in paths.items():
        lights = light_path(mesh, frames, degrees)
        truths = [silhouette_edges(device, adjacency, light) for light in lights]
        for label, params in SETTINGS:
            row = {"model": name, "path": path, "frames": frames, "degrees_per_frame": degrees, "setting": label,
                   **params, **follow(device, adjacency, lights, truths, params, repeats)}
            rows.append(row)
        on_path = [r for r in rows if r["path"] == path]
        brute = next(r["frame_ms"] for r in on_path if r["setting"] == "brute")
        for row in on_path:
            row["time_vs_brute"] = row["frame_ms"] / brute
    return model, rows


def markdown(doc: dict, plot_name: str | None) -> str:
    lines = [f"# Silhouettes along moving lights ({doc['device']})", "",
             "Per frame: median over the frames after the first of each frame's fastest of "
             f"{doc['repeats']} runs (a warm-up run first); recall and precision against brute force per frame "
             "(mean and min over the frames after the first; the first frame separately). Shared 2-core "
             "machine: timings are noisy, compare ratios within a run.", "",
             "| model | tris | edges | sil. edges | loops | concave edges | brute ms | loops ms | "
             "NumPy host classify ms | host_facing 4000 faces ms | device facing pass ms |", "|---" * 11 + "|"]
    for m in doc["models"]:
        lines.append(f"| {m['model']} | {m['triangles']:,} | {m['edges']:,} | {m['silhouette_edges']:,} | "
                     f"{m['loops']} | {m['concave_edges']:,} | "
                     f"{m['brute_ms']:.2f} | {m['loops_ms']:.2f} | {m['host_numpy_classify_ms']:.2f} | "
                     f"{m['host_facing_4000_faces_ms']:.2f} | {m['device_facing_pass_ms']:.2f} |")
    lines += ["", "| model | path | setting | ms/frame | x brute | fps | recall mean | recall min | "
              "first-frame recall | precision min | fallbacks | faces tested (median) |", "|---" * 12 + "|"]
    for r in doc["rows"]:
        lines.append(f"| {r['model']} | {r['path']} ({r['frames']}x{r['degrees_per_frame']:g} deg) | {r['setting']} | "
                     f"{r['frame_ms']:.2f} | {r['time_vs_brute']:.2f} | {1e3 / r['frame_ms']:.0f} | "
                     f"{r['recall_mean']:.4f} | {r['recall_min']:.4f} | {r['recall_first']:.4f} | "
                     f"{r['precision_min']:.4f} | {r['fallback_frames']} | "
                     f"{_count(r['faces_tested_median'], 'n/a (device walks)')} |")
    lines += ["", "## Bar and fastest method", ""] + summary(doc) + [
        "", "Where the device pays: one device pass over every face costs about as much as `host_facing` on "
        "~1000 + F/20 faces (launch and read-back dominate; the first table), so the tracker tests big batches of "
        "faces on the device and small ones on the host, and runs tracking's walks as kernels (one work-item "
        "per candidate; the same walks in NumPy, now the reference of the kernels, were 1.05-9.9x slower). Brute "
        "force stays fastest here: "
        "its two kernels are branch-free and vectorised by PoCL, while tracking needs three launches and two "
        "read-backs a frame and tests every concave edge (the concave-edges column) to catch loops born between "
        "frames; the randomized method grows its chains in NumPy rounds on the host. After a jump (the fast path) "
        "tracking detects stale edges and redoes the frame by brute force (the fallbacks column)."]
    if plot_name:
        lines += ["", f"![time against recall]({plot_name})"]
    return "\n".join(lines) + "\n"


def summary(doc: dict) -> list[str]:
    """The issue's bar per model and path, and the fastest setting at recall >= 0.99 and overall."""
    lines = []
    for m in doc["models"]:
        for path in doc["paths"]:
            rows = [r for r in doc["rows"] if r["model"] == m["model"] and r["path"] == path]
            if not rows:
                continue
            tracking = next(r for r in rows if r["setting"] == "tracking")
            verdict = "met" if tracking["recall_min"] >= RECALL_BAR else "MISSED"
            fastest = min(rows, key=lambda r: r["frame_ms"])
            good = min((r for r in rows if r["recall_min"] >= RECALL_BAR), key=lambda r: r["frame_ms"])
            lines.append(f"- {m['model']}, {path}: tracking recall min {tracking['recall_min']:.4f} "
                         f"(bar >= {RECALL_BAR}: {verdict}), {tracking['frame_ms']:.2f} ms/frame = "
                         f"{tracking['time_vs_brute']:.2f}x brute, {tracking['fallback_frames']} fallback frames. "
                         f"Fastest at recall >= {RECALL_BAR}: {good['setting']} {good['frame_ms']:.2f} ms/frame; "
                         f"fastest overall: {fastest['setting']} {fastest['frame_ms']:.2f} ms/frame at recall "
                         f"mean {fastest['recall_mean']:.4f} (min {fastest['recall_min']:.4f}).")
    return lines


def plot(doc: dict, path: Path) -> bool:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    models = [m["model"] for m in doc["models"]]
    figure, axes = plt.subplots(1, len(models), figsize=(5 * len(models), 4.2), squeeze=False)
    settings = [label for label, _ in SETTINGS]
    colours = plt.cm.tab10(np.arange(len(settings)) % 10)
    for ax, name in zip(axes[0], models):
        for row in (r for r in doc["rows"] if r["model"] == name):
            ax.scatter(row["recall_mean"], row["frame_ms"], color=colours[settings.index(row["setting"])],
                       marker="o" if row["path"] == "circle" else "^", s=40,
                       label=row["setting"] if row["path"] == "circle" else None)
        ax.set(title=name, xlabel="recall (mean over frames)", ylabel="ms per frame", yscale="log")
        ax.axvline(RECALL_BAR, color="grey", lw=0.8, ls="--")
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7, title="o circle 3 deg, ^ fast 15 deg", title_fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    return True


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=["stanford-bunny", "teapot", "ogre"])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="teapot only, 12- and 4-frame paths, one repeat")
    parser.add_argument("--out", type=Path, help="JSON path (default results/silhouettes.json, "
                                                  "results/quick-silhouettes.json with --quick)")
    args = parser.parse_args(argv)
    if args.quick:
        args.models, args.repeats = ["teapot"], 1
    args.out = args.out or RESULTS / ("quick-silhouettes.json" if args.quick else "silhouettes.json")
    paths = QUICK_PATHS if args.quick else PATHS
    device = sc.get_device()
    models, rows = [], []
    for name in args.models:
        model, model_rows = measure(device, name, paths, args.repeats)
        models.append(model)
        rows += model_rows
    doc = {"device": device.name, "repeats": args.repeats, "paths": {k: list(v) for k, v in paths.items()},
           "models": models, "rows": rows}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1))
    png = args.out.with_suffix(".png")
    text = markdown(doc, png.name if plot(doc, png) else None)
    args.out.with_suffix(".md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
