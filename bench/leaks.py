"""Light leaks through shared edges and vertices: watertight against Badouel's dot5 test, ≥ 1 M rays.

    python bench/leaks.py [--subdivisions 6] [--per-edge 16] [--out bench/results/leaks.json]

Receivers sit inside a closed icosphere, each aimed so that its segment to the light crosses the
surface exactly once, through a float32 edge point or vertex (shadowcl.testing.aimed_receivers):
every one is in shadow, and each lit receiver is a leak.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

import shadowcl as sc
from shadowcl.testing import aimed_receivers, icosphere
from shadowcl.methods import create_method

LIGHTS = {
    "point": sc.PointLight((0.3, 3.0, 0.2)),
    "point, close": sc.PointLight((0.02, 1.3, 0.01)),
    "directional": sc.DirectionalLight((0.2, -1.0, 0.1)),
}


def count_leaks(mesh, light, points, test: str) -> int:
    method = create_method("exact", test=test)
    bounds = np.stack([points.min(axis=0), points.max(axis=0)])
    method.prepare(mesh, light, bounds, eps=1e-6)
    return int(np.count_nonzero(~method.classify(points, None)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subdivisions", type=int, default=6)
    parser.add_argument("--per-edge", type=int, default=16)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "results" / "leaks.json")
    args = parser.parse_args(argv)

    mesh = icosphere(args.subdivisions)
    rows = []
    for name, light in LIGHTS.items():
        rng = np.random.default_rng(args.seed)
        position = light.position if isinstance(light, sc.PointLight) else None
        towards = None if position is not None else -light.direction
        points = aimed_receivers(mesh, towards, args.per_edge, rng, position)
        row = {"light": name, "triangles": len(mesh.faces), "rays": len(points)}
        for test in ("watertight", "dot5"):
            leaks = count_leaks(mesh, light, points, test)
            row[f"{test}_leaks"] = leaks
            row[f"{test}_leak_percent"] = 100.0 * leaks / len(points)
        rows.append(row)
        print(f"{name:13s} {row['rays']:>9,d} rays: watertight {row['watertight_leaks']} leaks, "
              f"dot5 {row['dot5_leaks']} ({row['dot5_leak_percent']:.2f} %)")
    total = sum(row["rays"] for row in rows)
    print(f"{total:,d} rays in all; watertight leaks {sum(r['watertight_leaks'] for r in rows)}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"mesh": f"icosphere({args.subdivisions})", "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
