"""The angular method's two tables on receivers lying on closed occluders (with normals).

    python bench/angular_caps.py [--quick] [--out DIR]

Scenes made here (not in ../shared): a sphere (icosphere, 4 subdivisions), a manifold3d torus, a box
minus a sphere and a cylinder, each over a 10 x 10 ground quad; lights: two directional ((0.3, -1, 0.2),
(-0.7, -0.5, 0.4)) and a point light at (0.7, 4, 0.4). Receivers: 2,000 seeded points on the occluder's
surface with its face normals and 1,000 on the ground with normals up (``--quick``: 500 + 250). Each
table (``table="faces"``, ``"loops"``) at the default rows through ``sc.shadow_mask``, against the
float64 brute force (``shadowcl.reference.exact``): false shadows and false lights on the occluder and
on the ground, as fractions of those receivers.

Writes OUT/angular_caps.{json,md} (``angular_caps-quick`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import shadowcl as sc
from report import save
from shadowcl.reference.exact import shadow_mask as truth

LIGHTS = {"directional (0.3, -1, 0.2)": sc.DirectionalLight((0.3, -1.0, 0.2)),
          "directional (-0.7, -0.5, 0.4)": sc.DirectionalLight((-0.7, -0.5, 0.4)),
          "point (0.7, 4, 0.4)": sc.PointLight((0.7, 4.0, 0.4))}


def occluders():
    import manifold3d as m3d
    import trimesh

    def solid(manifold):
        mesh = manifold.to_mesh()
        return trimesh.Trimesh(mesh.vert_properties[:, :3], mesh.tri_verts)

    yield "sphere", trimesh.creation.icosphere(subdivisions=4)
    yield "torus", solid(m3d.Manifold.revolve(m3d.CrossSection.circle(0.35, 32).translate((0.8, 0)), 64)
                         .rotate((90, 0, 0)))
    yield "box_minus_sphere", solid(m3d.Manifold.cube((1.6, 1.0, 1.2), center=True)
                                    - m3d.Manifold.sphere(0.7, 48).translate((0.5, 0.4, 0)))
    yield "cylinder", solid(m3d.Manifold.cylinder(1.2, 0.6, 0.6, 48, center=True).rotate((90, 30, 0)))


def main(argv=None) -> int:
    import trimesh

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args(argv)
    on_count, ground_count = (500, 250) if args.quick else (2000, 1000)
    rng = np.random.default_rng(14)
    rows = []
    for name, shape in occluders():
        shape = shape.copy()
        shape.apply_translation([0.0, 1.2 - shape.bounds[0, 1], 0.0])     # resting 0.2 above the ground
        v, f = shape.vertices, shape.faces
        n = len(v)
        ground = np.array([[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]], dtype=float)
        mesh = sc.Mesh(np.concatenate([v, ground]), np.concatenate([f, [[n, n + 2, n + 1], [n, n + 3, n + 2]]]))
        on, face = trimesh.sample.sample_surface(shape, on_count, seed=14)
        points = np.concatenate([on, np.c_[rng.uniform(-5, 5, ground_count), np.zeros(ground_count),
                                           rng.uniform(-5, 5, ground_count)]])
        normals = np.concatenate([shape.face_normals[face], np.tile([0.0, 1.0, 0.0], (ground_count, 1))])
        part = {"occluder": slice(0, on_count), "ground": slice(on_count, None)}
        for light_name, light in LIGHTS.items():
            reference = truth(mesh.vertices, mesh.faces, light, points, normals)
            row = {"scene": name, "light": light_name}
            for table in ("faces", "loops"):
                mask = sc.shadow_mask(mesh, light, points, normals, method="angular", table=table)
                for where, index in part.items():
                    m, t = mask[index], reference[index]
                    row[f"{table}_{where}_false_shadow"] = float(np.mean(m & ~t))
                    row[f"{table}_{where}_false_light"] = float(np.mean(~m & t))
            rows.append(row)
            print(row, flush=True)
    lines = ["# Angular tables on receivers lying on closed occluders (bench/angular_caps.py)", "",
             f"{on_count} receivers on the occluder (face normals), {ground_count} on the ground (normals up); "
             "fractions of each set, default rows, against the float64 brute force.", "",
             "| scene | light | faces: occluder false shadow / light | loops: occluder false shadow / light "
             "| faces: ground false shadow / light | loops: ground false shadow / light |", "|---" * 6 + "|"]
    for r in rows:
        cells = [f"{100 * r[f'{t}_{w}_false_shadow']:.2f} / {100 * r[f'{t}_{w}_false_light']:.2f} %"
                 for w in ("occluder", "ground") for t in ("faces", "loops")]
        lines.append(f"| {r['scene']} | {r['light']} | " + " | ".join(cells) + " |")
    save(args.out, "angular_caps-quick" if args.quick else "angular_caps", {"rows": rows}, "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
