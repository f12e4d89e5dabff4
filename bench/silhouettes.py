"""Brute-force silhouette edges per frame along a moving light: device classification and loops.

    python bench/silhouettes.py [--models stanford-bunny ogre teapot] [--frames 60] [--repeats 5]

The light circles each model (radius 1.5 bounding-box diagonals, a quarter diagonal above its
centre). Per frame: ``silhouette_edges`` (two kernels and the read-back of codes and facing) and
``silhouette_loops``; the peer is the same classification on the host in NumPy (facing in float64,
codes from the adjacency table). The first frame is checked against the float64 reference (away from
ties) before anything is timed; times are medians over frames of the fastest of ``repeats`` runs.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import shadowcl as sc
from shadowcl.reference import silhouette as ref
from shadowcl.silhouette import edge_adjacency, silhouette_edges, silhouette_loops

MODELS = Path(__file__).resolve().parents[2] / "shared" / "models"


def light_path(mesh, frames: int) -> list:
    centre = mesh.bounds.mean(axis=0)
    diagonal = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    angles = np.linspace(0.0, 2.0 * np.pi, frames, endpoint=False)
    offsets = np.stack([1.5 * np.cos(angles), np.full(frames, 0.25), 1.5 * np.sin(angles)], axis=1)
    return [sc.PointLight(centre + diagonal * o) for o in offsets]


def host_codes(adjacency, light) -> np.ndarray:
    """The peer: silhouette codes in NumPy on the host (float64 facing, the same rules)."""
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


def fastest(function, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best


def measure(device, name: str, frames: int, repeats: int) -> dict:
    mesh = sc.Mesh.load(MODELS / f"{name}.obj")
    start = time.perf_counter()
    adjacency = edge_adjacency(mesh)
    adjacency_s = time.perf_counter() - start
    lights = light_path(mesh, frames)
    check_first_frame(device, mesh, lights[0])
    silhouette_edges(device, adjacency, lights[0])                       # warm-up: build, upload
    classify, loops, host, edges, loop_counts = [], [], [], [], []
    for light in lights:
        sil = silhouette_edges(device, adjacency, light)
        classify.append(fastest(lambda: silhouette_edges(device, adjacency, light), repeats))
        loops.append(fastest(lambda: silhouette_loops(sil), repeats))
        host.append(fastest(lambda: host_codes(adjacency, light), repeats))
        edges.append(int(sil.mask.sum()))
        loop_counts.append(len(silhouette_loops(sil)))
    return {"model": name, "triangles": len(mesh.faces), "edges": len(adjacency.edges), "frames": frames,
            "adjacency_ms": 1e3 * adjacency_s, "classify_ms": 1e3 * float(np.median(classify)),
            "loops_ms": 1e3 * float(np.median(loops)), "host_numpy_classify_ms": 1e3 * float(np.median(host)),
            "silhouette_edges": int(np.median(edges)), "loops": int(np.median(loop_counts))}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=["stanford-bunny", "ogre", "teapot"])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results" / "silhouettes.json")
    args = parser.parse_args(argv)
    device = sc.get_device()
    rows = [measure(device, name, args.frames, args.repeats) for name in args.models]
    for r in rows:
        frame = r["classify_ms"] + r["loops_ms"]
        print(f"{r['model']:15s} {r['triangles']:>7,d} tris {r['edges']:>7,d} edges: adjacency {r['adjacency_ms']:.1f} ms once; "
              f"per frame classify {r['classify_ms']:.2f} ms + loops {r['loops_ms']:.2f} ms = {frame:.2f} ms "
              f"({1e3 / frame:.0f} fps); NumPy host classify {r['host_numpy_classify_ms']:.2f} ms; "
              f"~{r['silhouette_edges']} silhouette edges in ~{r['loops']} loops")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"device": device.name, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
