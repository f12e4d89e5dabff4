"""Tracking along bench/silhouettes.py's light paths, this checkout against an older revision, in
alternating processes (old, new, old, new, ...), so a shared machine's load hits both alike.

    python bench/silhouettes_compare.py [--rev 77f36cc] [--rounds 5] [--cases bunny:fast ogre:fast bunny:circle]

Each process times one path as bench/silhouettes.py does (a warm-up run, then 3 runs with a reset
tracker; a frame's time is its fastest run; the median over the frames after the first), importing
``shadowcl`` and ``kernels`` from this checkout or from ``git archive REV``. Writes
``results/silhouettes_compare.md`` with every round, the medians and the load.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

PROJECT = Path(__file__).resolve().parents[1]
MODELS = PROJECT.parent / "shared" / "models"
RESULTS = Path(__file__).resolve().parent / "results"
PATHS = {"circle": (120, 3.0), "fast": (24, 15.0)}       # bench/silhouettes.py's
FILES = {"bunny": "stanford-bunny.obj", "ogre": "ogre.obj", "teapot": "teapot.obj"}

# One path, timed in a fresh process (argv: model file, frames, degrees); prints the median ms.
TIMER = """
import sys, time, numpy as np
import shadowcl as sc
from shadowcl.silhouette import SilhouetteTracker
mesh = sc.Mesh.load(sys.argv[1])
frames, degrees = int(sys.argv[2]), float(sys.argv[3])
centre = mesh.bounds.mean(axis=0)
diagonal = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
angles = np.radians(degrees * np.arange(frames))
offsets = np.stack([1.5 * np.cos(angles), np.full(frames, 0.25), 1.5 * np.sin(angles)], axis=1)
lights = [sc.PointLight(centre + diagonal * o) for o in offsets]
device = sc.get_device()
tracker = SilhouetteTracker(device, mesh, method="tracking")
best = np.full(frames, np.inf)
for run in range(4):
    tracker.reset()
    for k, light in enumerate(lights):
        start = time.perf_counter()
        tracker.update(light)
        device.queue.finish()
        if run:
            best[k] = min(best[k], time.perf_counter() - start)
print(1e3 * np.median(best[1:]))
"""


def run(source: "Path | None", model: str, path: str) -> float:
    env = dict(os.environ)
    if source is not None:                         # the old revision's package and kernels first
        env["PYTHONPATH"] = os.pathsep.join([str(source / "host"), str(source)])
    frames, degrees = PATHS[path]
    out = subprocess.run([sys.executable, "-c", TIMER, str(MODELS / FILES[model]), str(frames), str(degrees)],
                         env=env, check=True, capture_output=True, text=True).stdout
    return float(out.split()[-1])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rev", default="77f36cc", help="the older revision (default: bench/silhouettes.py's last run)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--cases", nargs="+", default=["bunny:fast", "ogre:fast", "bunny:circle"])
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    old = Path(tempfile.mkdtemp(prefix="silhouettes-old-"))
    archive = subprocess.run(["git", "-C", str(PROJECT), "archive", args.rev], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(old)], input=archive, check=True)
    lines = [f"# Tracking, this checkout against {args.rev}, alternating processes", "",
             "ms per frame (median over the frames after the first of each frame's fastest of 3 runs), one process "
             "per entry, old and new alternated round by round; load: 1, 5, 15-minute averages after the case.", "",
             "| model | path | old rounds | new rounds | old median | new median | new / old | load |",
             "|---|---|---|---|---|---|---|---|"]
    for case in args.cases:
        model, path = case.split(":")
        times = {"old": [], "new": []}
        for _ in range(args.rounds):
            times["old"].append(run(old, model, path))
            times["new"].append(run(None, model, path))
        o, n = statistics.median(times["old"]), statistics.median(times["new"])
        load = " ".join(f"{x:.1f}" for x in os.getloadavg())
        lines.append(f"| {model} | {path} | {', '.join(f'{t:.2f}' for t in times['old'])} | "
                     f"{', '.join(f'{t:.2f}' for t in times['new'])} | {o:.2f} | {n:.2f} | {n / o:.2f} | {load} |")
        print(lines[-1], flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "silhouettes_compare.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
