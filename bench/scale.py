"""How the exact method and the peers scale: time against triangles and against receivers, with fitted exponents.

    python bench/scale.py [--quick] [--repeats 3]

Two series, every tool end to end from NumPy arrays (shadowcl: the one-shot ``sc.shadow_mask``; a peer:
its prepare + classify), interleaved per size so that load drift hits all alike (0.2 s apart: run.SETTLE_S),
median of repeats after a warm-up, each mask checked against the exact one (the tool's row says how many
receivers differ):

- triangles: a "city" of n x n icospheres on a ground quad (not a mesh of ../shared/models), 20 k to
  2.5 M triangles, 1.2 M receivers (1 M on the ground, 200 k on the spheres) under a point light;
- receivers: the bunny scene (69 k triangles), 100 k to 10 M receivers.

The exponent is the slope of log(time) against log(size) over the series (least squares): 1 is linear.
Writes bench/results/scale.json, .md and .png.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import trimesh

import receivers as rx
import report
import run
from peers import PEERS
import shadowcl as sc
from shadowcl.methods import default_eps
from timing import interleaved

TOOLS = {"exact": {}, "embreex": {"workers": 2}, "open3d": {}, "mitsuba": {}}
SPHERES = [(2, 4), (4, 4), (8, 4), (8, 5), (11, 5)]   # (n: n x n spheres, icosphere subdivisions): 20 k to 2.5 M triangles
RECEIVERS = [100_000, 300_000, 1_000_000, 3_000_000, 10_000_000]
QUICK_SPHERES, QUICK_RECEIVERS = SPHERES[:3], RECEIVERS[:3]
RESULTS = Path(__file__).resolve().parent / "results"


def city(n: int, subdivisions: int) -> rx.BenchScene:
    """n x n unit icospheres (20 * 4^subdivisions triangles each) resting on a ground quad, light above a corner."""
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.4)
    parts = [sc.Mesh(sphere.vertices + [i - (n - 1) / 2, 0.4, j - (n - 1) / 2], sphere.faces)
             for i in range(n) for j in range(n)]
    model = sc.Mesh.concatenate(parts)
    center, side = rx.footprint(model)
    mesh = sc.Mesh.concatenate([model, rx.ground_quad(center, side, 0.0)])
    light = sc.PointLight((0.6 * n, 0.8 * n + 2, 0.3 * n))
    return rx.BenchScene(f"city {n}x{n} s{subdivisions}", mesh, [light], "bench/scale.py city()", model, 0.0)


def measure(scene: rx.BenchScene, ground: int, model: int, repeats: int, device) -> list[dict]:
    """One size: every tool's median one-shot time and its receivers differing from exact."""
    points, normals = rx.receivers(scene, ground, model)
    case = run.Case(scene, 0, points, normals, default_eps(scene.mesh.bounds))
    peers = {name: PEERS[name](**params) for name, params in TOOLS.items()
             if name in PEERS and run.available(name) is None}
    calls = {"exact": lambda: run.one_shot(case, "exact", {}, device)}
    calls.update({name: (lambda peer=peer: run.peer_run(peer, case, [])) for name, peer in peers.items()})
    try:
        timings = interleaved(calls, repeats, settle=run.SETTLE_S)
    finally:
        for peer in peers.values():
            run.close(peer)
    truth = timings["exact"].result
    return [{"scene": scene.name, "tool": name, "triangles": len(scene.mesh.faces), "receivers": len(points),
             "seconds": t.median, "runs": t.runs, "wrong": int(np.count_nonzero(t.result != truth))}
            for name, t in timings.items()]


def exponents(rows: list[dict], size: str) -> dict:
    """Per tool, the least-squares slope of log(seconds) against log(``size``)."""
    fits = {}
    for tool in dict.fromkeys(r["tool"] for r in rows):
        mine = [r for r in rows if r["tool"] == tool]
        x, y = np.log([r[size] for r in mine]), np.log([r["seconds"] for r in mine])
        fits[tool] = float(np.polyfit(x, y, 1)[0]) if len(mine) > 1 else None
    return fits


def markdown(doc: dict) -> str:
    lines = ["# Scale: time against triangles and receivers (one-shot, median)", "", doc["settings"]["timing"], ""]
    for series, size in (("triangles", "triangles"), ("receivers", "receivers")):
        rows = doc[series]
        tools = list(dict.fromkeys(r["tool"] for r in rows))
        lines += [f"## Against {size}", "", "| scene | triangles | receivers | " + " | ".join(
            f"{t} ms (wrong)" for t in tools) + " |", "|---|---:|---:|" + "---:|" * len(tools)]
        for key in dict.fromkeys((r["scene"], r["triangles"], r["receivers"]) for r in rows):
            cells = {r["tool"]: f"{1e3 * r['seconds']:.1f} ({r['wrong']})" for r in rows
                     if (r["scene"], r["triangles"], r["receivers"]) == key}
            lines.append(f"| {key[0]} | {key[1]:,} | {key[2]:,} | " + " | ".join(cells.get(t, "") for t in tools) + " |")
        lines += ["", "Fitted exponent of time against " + size + ": " + ", ".join(
            f"{tool} {e:.2f}" for tool, e in doc["exponents"][series].items() if e is not None), ""]
    return "\n".join(lines)


def plot(doc: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    for axis, series in zip(axes, ("triangles", "receivers")):
        for tool in dict.fromkeys(r["tool"] for r in doc[series]):
            mine = [r for r in doc[series] if r["tool"] == tool]
            axis.plot([r[series] for r in mine], [1e3 * r["seconds"] for r in mine], "o-",
                      label=f"{tool} (exponent {doc['exponents'][series][tool]:.2f})")
        axis.set(xscale="log", yscale="log", xlabel=series, ylabel="one-shot ms", title=f"time against {series}")
        axis.legend()
        axis.grid(True, which="both", alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description="Time against triangles and receivers, shadowcl and peers.")
    parser.add_argument("--quick", action="store_true", help="the three smallest sizes of each series")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)
    device = sc.get_device()
    spheres, counts = (QUICK_SPHERES, QUICK_RECEIVERS) if args.quick else (SPHERES, RECEIVERS)
    triangles = [row for n, s in spheres for row in measure(city(n, s), 1_000_000, 200_000, args.repeats, device)]
    bunny = rx.load_scene("bunny")
    received = [row for count in counts
                for row in measure(bunny, count * 5 // 6, count // 6, args.repeats, device)]
    doc = {"machine": run.machine(device),
           "settings": {"repeats": args.repeats, "quick": args.quick, "tools": TOOLS,
                        "timing": "one-shot from NumPy arrays (shadowcl: sc.shadow_mask; peers: prepare + classify), "
                                  "tools interleaved per size, median of repeats after a warm-up"},
           "triangles": triangles, "receivers": received,
           "exponents": {"triangles": exponents(triangles, "triangles"), "receivers": exponents(received, "receivers")}}
    text = markdown(doc)
    report.save(RESULTS, "scale-quick" if args.quick else "scale", doc, text, plot)
    print(text)


if __name__ == "__main__":
    main()
