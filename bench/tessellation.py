"""Subdivision tessellation grid: the vectorised grid against the per-sample loop it replaced.

    python bench/tessellation.py [--quick] [--repeats 3] [--out DIR]

For each control mesh (suzanne and the ccss models in ../shared/models) and segments per control edge,
the grid (which (face, u, v) points a tessellation evaluates, and its triangles) is built by
``shadowcl.subdivision.tessellation.tessellation`` and by the reference loop
(``shadowcl.reference.subdivision.tessellation_grid``, the library's former code): both are checked
equal, then timed interleaved (timing.interleaved: a warm-up, then the median of ``repeats``; the ratio
in one run is the figure to quote, the machine is shared), and so is ``SubdivisionSurface.tessellate``
with each grid (grid + device evaluation). ``--quick``: segments 8 only, one repeat.
Writes OUT/tessellation.json and tessellation.md.
"""

from __future__ import annotations

import argparse
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from report import save
from run import machine
from timing import interleaved
from shadowcl import get_device
from shadowcl.reference.subdivision import tessellation_grid
from shadowcl.subdivision import SubdivisionSurface
from shadowcl.subdivision import surface as surface_module
from shadowcl.subdivision.tessellation import tessellation

RESULTS = Path(__file__).resolve().parent / "results"
MODELS = Path(__file__).resolve().parents[2] / "shared" / "models"
CASES = [("suzanne.obj", (8, 32, 64)), ("ccss/catmark_torus.obj", (8, 32, 64)), ("ccss/catmark_pole64.obj", (8, 32))]
GRIDS = {"loop": tessellation_grid, "vectorised": tessellation}


def with_grid(grid, surface, segments):
    """``surface.tessellate(segments=...)`` built on ``grid``."""
    surface_module.tessellation = grid
    try:
        return surface.tessellate(segments=segments)
    finally:
        surface_module.tessellation = tessellation


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    device = get_device()
    rows = []
    repeats = 1 if args.quick else args.repeats
    for name, segment_list in CASES:
        segment_list = segment_list[:1] if args.quick else segment_list
        surface = SubdivisionSurface.load(MODELS / name)
        surface.tessellate(segments=2)                       # kernel build out of the timings
        for segments in segment_list:
            got, want = tessellation(surface.faces, segments), tessellation_grid(surface.faces, segments)
            if not all(np.array_equal(g, w) for g, w in zip(got[:4] + got[4], want[:4] + want[4])):
                raise SystemExit(f"{name} at {segments}: the grids differ")
            grid = interleaved({k: (lambda g=g: g(surface.faces, segments)) for k, g in GRIDS.items()}, repeats)
            full = interleaved({k: (lambda g=g: with_grid(g, surface, segments)) for k, g in GRIDS.items()}, repeats)
            rows.append(dict(mesh=name, faces=len(surface.faces), segments=segments, triangles=len(got[3]),
                             grid_loop_s=grid["loop"].median, grid_vectorised_s=grid["vectorised"].median,
                             tessellate_loop_s=full["loop"].median, tessellate_vectorised_s=full["vectorised"].median))
            print(rows[-1], flush=True)
    doc = dict(created=datetime.now(timezone.utc).isoformat(timespec="seconds"), machine=machine(device),
               repeats=repeats, rows=rows)
    lines = ["| mesh | faces | segments | triangles | grid: loop / vectorised s | tessellate: loop / vectorised s |",
             "|---|---|---|---|---|---|"]
    lines += [f"| {r['mesh']} | {r['faces']} | {r['segments']} | {r['triangles']} | {r['grid_loop_s']:.3f} / "
              f"{r['grid_vectorised_s']:.3f} ({r['grid_loop_s'] / r['grid_vectorised_s']:.1f}x) | "
              f"{r['tessellate_loop_s']:.3f} / {r['tessellate_vectorised_s']:.3f} "
              f"({r['tessellate_loop_s'] / r['tessellate_vectorised_s']:.1f}x) |" for r in rows]
    save(args.out, "tessellation", doc, "# Tessellation grid: vectorised vs the per-sample loop\n\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
