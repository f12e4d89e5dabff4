"""The working range's measured constants: how far a point light may be, and how close to a surface,
for each method's own arithmetic (``point_light_reach``, ``min_light_clearance`` in
host/shadowcl/methods.py).

    python bench/range.py [--quick] [--out DIR]

Two scenes made here (not in ../shared): an icosphere at y = 1 over a 6 x 6 ground quad lit along
(0.3, 1, 0.2), and a manifold3d box minus a sphere over a 10 x 10 ground quad lit along (-0.5, 0.8, 0.6);
1,500 seeded ground receivers (``--quick``: 500), no normals. Truth is the float64 brute force
(``shadowcl.reference.exact``).

- **distance**: a point light at 10 .. 1e7 scene sizes (box diagonals of occluders and receivers)
  along the scene's direction. Each method is prepared in the working frame with the distant-light
  substitution lifted (``Frame.light(..., limit=DIRECTIONAL_DISTANCE)``: the method's own float32
  arithmetic), and through the public call (``sc.shadow_mask``, which substitutes beyond the method's
  ``point_light_reach``); ``substituted`` counts the receivers where the point light's truth and the
  directional light's truth differ (the substitution's own error).
- **clearance**: angular and shadow_volume with the light 0 .. 1e-2 scene sizes off a face's centre,
  an edge's midpoint and a vertex (along the face normal), 2 random faces each, substitution and
  clearance check lifted (the methods reached inside, through the frame, as the public path would).

Writes OUT/range.{json,md} (``range-quick`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import shadowcl as sc
from report import save
from shadowcl.frame import DIRECTIONAL_DISTANCE, frame_for, union
from shadowcl.methods import create_method
from shadowcl.points import check_points
from shadowcl.reference.exact import shadow_mask as truth

METHODS = ("exact", "shadow_map", "angular", "shadow_volume")
DISTANCES = (1e1, 1e2, 1e3, 1e4, 3e4, 1e5, 3e5, 1e6, 3e6, 1e7)
OFFSETS = (0.0, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2)


def scenes(count: int, rng):
    import manifold3d as m3d
    import trimesh

    ico = trimesh.creation.icosphere(subdivisions=2)
    cut = m3d.Manifold.cube((1.6, 1.0, 1.2), center=True) - m3d.Manifold.sphere(0.7, 48).translate((0.5, 0.4, 0))
    cut = cut.translate((0.3, 1.4, -0.2)).to_mesh()
    for name, (v, f), half, direction in (
            ("icosphere", (ico.vertices + [0, 1, 0], ico.faces), 3.0, (0.3, 1.0, 0.2)),
            ("box_minus_sphere", (cut.vert_properties[:, :3], cut.tri_verts), 5.0, (-0.5, 0.8, 0.6))):
        n = len(v)
        ground = np.array([[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]])
        mesh = sc.Mesh(np.concatenate([v, ground]), np.concatenate([f, [[n, n + 2, n + 1], [n, n + 3, n + 2]]]))
        points = np.c_[rng.uniform(-half, half, count), np.zeros(count), rng.uniform(-half, half, count)]
        direction = np.asarray(direction) / np.linalg.norm(direction)
        yield name, mesh, points, direction


def own_arithmetic(method: str, mesh, light, points) -> np.ndarray:
    """The method's mask in the working frame with no substitution and no clearance check."""
    frame = frame_for(mesh)
    receivers = check_points(points)
    reach = union(mesh.bounds, receivers.bounds)
    instance = create_method(method)
    instance.prepare(frame.mesh(mesh), frame.light(light, reach, DIRECTIONAL_DISTANCE), frame.points(reach),
                     frame.length(1e-4 * np.linalg.norm(mesh.bounds[1] - mesh.bounds[0])))
    return instance.classify(frame.receivers(receivers))


def wrong(mask, reference) -> int:
    return int(np.count_nonzero(mask != reference))


def distance_rows(mesh, points, direction):
    size = float(np.linalg.norm(np.ptp(np.concatenate([mesh.bounds, points]), axis=0)))
    directional = truth(mesh.vertices, mesh.faces, sc.DirectionalLight(-direction), points)
    for sizes in DISTANCES:
        light = sc.PointLight(direction * sizes * size)
        reference = truth(mesh.vertices, mesh.faces, light, points)
        row = {"sizes": sizes, "shadowed": int(reference.sum()), "substituted": wrong(directional, reference)}
        for method in METHODS:
            row[f"{method}_own"] = wrong(own_arithmetic(method, mesh, light, points), reference)
            row[f"{method}_public"] = wrong(sc.shadow_mask(mesh, light, points, method=method), reference)
        yield row


def clearance_rows(mesh, points, rng):
    tri = mesh.triangles
    faces = rng.choice(len(tri) - 2, 2, replace=False)    # occluder faces (the ground quad is last)
    size = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    for offset in OFFSETS:
        for where in ("face", "edge", "vertex"):
            row = {"offset": offset, "where": where}
            for method in ("angular", "shadow_volume"):
                counts = []
                for k in faces:
                    a, b, c = tri[k]
                    normal = np.cross(b - a, c - a)
                    base = {"face": (a + b + c) / 3, "edge": (a + b) / 2, "vertex": a}[where]
                    light = sc.PointLight(base + offset * size * normal / np.linalg.norm(normal))
                    reference = truth(mesh.vertices, mesh.faces, light, points)
                    try:
                        counts.append(wrong(own_arithmetic(method, mesh, light, points), reference))
                    except ValueError as error:       # a refusal of the method itself (light inside a solid)
                        counts.append(str(error).split(";")[0][:60])
                row[method] = counts
            yield row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(14)
    doc = {"distance": {}, "clearance": {}}
    lines = ["# Working range: distant and touching point lights (bench/range.py)", ""]
    for name, mesh, points, direction in scenes(500 if args.quick else 1500, rng):
        rows = list(distance_rows(mesh, points, direction))
        doc["distance"][name] = rows
        lines += [f"## {name}: wrong receivers of {len(points)}, point light at N scene sizes", "",
                  "| sizes | shadowed | substituted | " + " | ".join(f"{m} own / public" for m in METHODS) + " |",
                  "|---" * (3 + len(METHODS)) + "|"]
        lines += [f"| {r['sizes']:.0e} | {r['shadowed']} | {r['substituted']} | "
                  + " | ".join(f"{r[m + '_own']} / {r[m + '_public']}" for m in METHODS) + " |" for r in rows]
        rows = list(clearance_rows(mesh, points, rng))
        doc["clearance"][name] = rows
        lines += ["", f"## {name}: light off the surface (scene sizes), wrong receivers per face, own arithmetic", "",
                  "| offset | at | angular | shadow_volume |", "|---|---|---|---|"]
        lines += [f"| {r['offset']:.0e} | {r['where']} | {r['angular']} | {r['shadow_volume']} |" for r in rows]
        lines.append("")
        print("\n".join(lines), flush=True)
    save(args.out, "range-quick" if args.quick else "range", doc, "\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
