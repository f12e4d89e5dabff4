"""Mesh-file reading: ``sc.Mesh.load`` against ``trimesh.load(..., process=False)``, and the line parser.

    python bench/mesh_files.py [--repeats 7] [--quick]

Files: every OBJ in ``../shared/models``; a 1.1 M-triangle OBJ (the bunny, subdivided twice: a scan's
size); the bunny written by trimesh as binary and ASCII PLY, binary and ASCII STL, and OFF. Per file,
interleaved rounds (after a warm-up) call, in turn:

- ``shadowcl``: ``sc.Mesh.load(path)``, as a user calls it (parse, checks, fan triangulation, Mesh);
- ``trimesh``: ``trimesh.load(path, process=False)`` (parse only: no merging, no checks);
- ``line parser`` (OBJ only): the same file through ``meshio._read_obj_by_line`` (reached inside on
  purpose: it is the reader before the bulk path, and still what reads a file the bulk path declines),
  then the same Mesh.

A figure is the median of ``--repeats`` rounds; ``spread`` is the lowest and highest of the per-round
ratios shadowcl / trimesh (the machine is shared: this is the noise). Writes
bench/results/mesh-files.json and .md.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from pathlib import Path

import numpy as np
import trimesh

import report
import shadowcl as sc
from shadowcl import meshio
from timing import interleaved

MODELS = Path(__file__).resolve().parents[1] / ".." / "shared" / "models"
RESULTS = Path(__file__).resolve().parent / "results"
WRITTEN = {"bunny.ply (binary)": ("ply", {"encoding": "binary"}), "bunny.ply (ascii)": ("ply", {"encoding": "ascii"}),
           "bunny.stl (binary)": ("stl", {}), "bunny.stl (ascii)": ("stl_ascii", {}), "bunny.off": ("off", {})}


def files(folder: Path, quick: bool) -> dict:
    """{label: path}: the shared OBJ models, then the files written here into ``folder``."""
    found = {path.name: path for path in sorted(MODELS.resolve().glob("*.obj"))}
    bunny = trimesh.load(found["stanford-bunny.obj"], process=False)
    if not quick:
        v, f = trimesh.remesh.subdivide(bunny.vertices, bunny.faces)
        v, f = trimesh.remesh.subdivide(v, f)
        found["bunny subdivided twice.obj"] = folder / "scan.obj"
        trimesh.Trimesh(v, f, process=False).export(found["bunny subdivided twice.obj"])
    for label, (file_type, options) in WRITTEN.items():
        found[label] = folder / f"bunny-{len(found)}.{file_type.split('_')[0]}"
        bunny.export(found[label], file_type=file_type, **options)
    return found


def line_parser_load(path: Path) -> sc.Mesh:
    polygons = meshio._read_obj_by_line(path.read_bytes())
    return sc.Mesh(polygons.vertices, polygons.triangles())


def measure(label: str, path: Path, repeats: int) -> dict:
    calls = {"shadowcl": lambda: sc.Mesh.load(path), "trimesh": lambda: trimesh.load(path, process=False)}
    if path.suffix == ".obj":
        calls["line parser"] = lambda: line_parser_load(path)
    timings = interleaved(calls, repeats)
    mine, theirs = timings["shadowcl"].result, timings["trimesh"].result
    # both read the same mesh: trimesh keeps the triangles but may renumber vertices (it splits them by UV)
    same = len(mine.faces) == len(theirs.faces) and np.allclose(np.sort(mine.triangles.reshape(-1, 3), axis=0),
                                                                np.sort(theirs.triangles.reshape(-1, 3), axis=0))
    ratios = [a / b for a, b in zip(timings["shadowcl"].runs, timings["trimesh"].runs)]
    row = {"file": label, "bytes": path.stat().st_size, "triangles": len(mine.faces), "same_triangles": bool(same),
           **{f"{name}_s": t.median for name, t in timings.items()},
           "ratio": timings["shadowcl"].median / timings["trimesh"].median,
           "spread": [min(ratios), max(ratios)], "runs": {name: t.runs for name, t in timings.items()}}
    print(f"{label}: shadowcl {row['shadowcl_s']:.4f} s, trimesh {row['trimesh_s']:.4f} s, ratio "
          f"{row['ratio']:.2f} ({min(ratios):.2f}-{max(ratios):.2f})", flush=True)
    return row


def markdown(doc: dict) -> str:
    lines = [f"# Mesh files: sc.Mesh.load against trimesh.load(process=False)\n",
             f"Medians of {doc['repeats']} interleaved rounds after a warm-up; ratio = shadowcl / trimesh "
             f"(below 1: shadowcl faster), spread = lowest and highest per-round ratio (the shared machine's "
             f"noise). 'line parser' is the OBJ reader before the bulk path.\n",
             "| file | MB | triangles | shadowcl s | trimesh s | ratio | spread | line parser s | same triangles |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row in doc["rows"]:
        before = f"{row['line parser_s']:.4f}" if "line parser_s" in row else "-"
        lines.append(f"| {row['file']} | {row['bytes'] / 1e6:.2f} | {row['triangles']} | {row['shadowcl_s']:.4f} | "
                     f"{row['trimesh_s']:.4f} | {row['ratio']:.2f} | {row['spread'][0]:.2f}-{row['spread'][1]:.2f} "
                     f"| {before} | {row['same_triangles']} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--quick", action="store_true", help="3 repeats, no 1.1 M-triangle file")
    args = parser.parse_args()
    repeats = 3 if args.quick else args.repeats
    with tempfile.TemporaryDirectory() as folder:
        rows = [measure(label, path, repeats) for label, path in files(Path(folder), args.quick).items()]
    doc = {"repeats": repeats, "quick": args.quick, "trimesh": trimesh.__version__, "numpy": np.__version__,
           "rows": rows, "median_ratio": statistics.median(row["ratio"] for row in rows)}
    report.save(RESULTS, "mesh-files-quick" if args.quick else "mesh-files", doc, markdown(doc))
    print(markdown(doc))


if __name__ == "__main__":
    main()
