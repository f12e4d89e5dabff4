"""The angular method at another git revision against the working tree's, side by side in one process.

    python bench/angular_revisions.py --before REV [--quick] [--out DIR]

REV's package (``host/shadowcl`` with its ``kernels/``) is extracted by ``git archive`` into a temporary
folder and imported under the name ``shadowcl_before``, so both versions run on the same receivers, the
same device and the same load, their calls interleaved (timing.interleaved: a round calls each once).
Scenes: bunny, ogre, teapot (receivers.py: ground + model points with normals, as bench/angular.py), each
table at the default rows (eq. 4, expected_receivers given), through the public calls: ``sc.prepare`` and
``Shadows.mask`` (on a table prepared once), the four calls interleaved. Error against the working tree's
exact method; time as the median over rounds of the round's ratio after / before (with its spread), per
call, and the table's records (the lookups' list length).

Writes OUT/angular_revisions.{json,md} (``-quick`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import receivers as rx  # noqa: E402
from report import save  # noqa: E402
from timing import interleaved  # noqa: E402

import shadowcl as sc  # noqa: E402
from shadowcl.methods import default_eps  # noqa: E402
from shadowcl.metrics import mask_error  # noqa: E402

PROJECT = Path(__file__).resolve().parents[1]
TABLES = ("faces", "loops")


def import_revision(rev: str, folder: Path):
    """The shadowcl package of git revision ``rev``, laid out as installed (kernels inside) under ``folder``
    and imported as ``shadowcl_before`` (its imports are relative, and its method registry is renamed, so
    it never reaches the working tree's)."""
    archive = subprocess.run(["git", "-C", str(PROJECT), "archive", rev, "host/shadowcl", "kernels"],
                             check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    package = folder / "host" / "shadowcl"
    shutil.move(str(folder / "kernels"), str(package / "kernels"))
    spec = importlib.util.spec_from_file_location("shadowcl_before", package / "__init__.py",
                                                  submodule_search_locations=[str(package)])
    module = importlib.util.module_from_spec(spec)
    sys.modules["shadowcl_before"] = module
    spec.loader.exec_module(module)
    methods = importlib.import_module("shadowcl_before.methods")       # its registry names modules absolutely
    methods.METHODS = {name: "shadowcl_before" + path[len("shadowcl"):] for name, path in methods.METHODS.items()}
    return module


def ratios(after, before) -> np.ndarray:
    """Per-round time ratios after / before of two interleaved Timings."""
    return np.array(after.runs) / np.array(before.runs)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", required=True, help="git revision to compare with (e.g. main, HEAD~3)")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results")
    args = parser.parse_args(argv)
    ground, model = (8_000, 2_000) if args.quick else (400_000, 100_000)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        before = import_revision(args.before, Path(tmp))
        for name in rx.MODEL_FILES:
            scene = rx.load_scene(name)
            points, normals = rx.receivers(scene, ground, model)
            box, eps, light = np.stack([points.min(0), points.max(0)]), default_eps(scene.mesh.bounds), scene.lights[0]
            truth = sc.shadow_mask(scene.mesh, light, points, normals, eps=eps)
            old_mesh, old_light = before.Mesh(scene.mesh.vertices, scene.mesh.faces), before.PointLight(light.position)
            for table in TABLES:
                def prepare(pkg, m, lt):
                    return lambda: pkg.prepare(m, lt, "angular", bounds=box, eps=eps, table=table,
                                               expected_receivers=len(points))
                shadows = {"before": prepare(before, old_mesh, old_light)(), "after": prepare(sc, scene.mesh, light)()}
                times = interleaved({"before_prepare": prepare(before, old_mesh, old_light),
                                     "after_prepare": prepare(sc, scene.mesh, light),
                                     "before_mask": lambda: shadows["before"].mask(points, normals),
                                     "after_mask": lambda: shadows["after"].mask(points, normals)}, args.repeats)
                row = dict(scene=name, table=table, receivers=len(points))
                for side in ("before", "after"):
                    err = mask_error(times[f"{side}_mask"].result, truth)
                    stats = shadows[side].stats
                    row.update({f"{side}_prepare_s": times[f"{side}_prepare"].median,
                                f"{side}_mask_s": times[f"{side}_mask"].median, f"{side}_error": err.fraction,
                                f"{side}_false_shadow": err.false_shadow, f"{side}_false_light": err.false_light,
                                f"{side}_records": stats["entries"], f"{side}_rows": stats["rows"]})
                for call in ("prepare", "mask"):
                    r = ratios(times[f"after_{call}"], times[f"before_{call}"])
                    row[f"{call}_ratio"] = float(np.median(r))
                    row[f"{call}_ratio_range"] = [float(r.min()), float(r.max())]
                rows.append(row)
                print(row, flush=True)
    load = os.getloadavg()
    lines = [f"# Angular method: working tree against {args.before} (bench/angular_revisions.py)", "",
             f"{ground + model} receivers per scene (ground + model, normals), default rows; sc.prepare and "
             f"Shadows.mask, {args.repeats} interleaved rounds after a warm-up: medians, and the median (min-max) of "
             f"the rounds' ratios after / before; load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} "
             "(1 / 5 / 15 min) at the end, 2 shared cores.", "",
             "| scene | table | rows | records before / after | error before / after | false shadows / lights after "
             "(receivers) | prepare s before / after | ratio | mask s before / after | ratio |", "|---" * 10 + "|"]
    for r in rows:
        cells = [f"{r['scene']}", r["table"], f"{r['after_rows']}", f"{r['before_records']} / {r['after_records']}",
                 f"{100 * r['before_error']:.3f} / {100 * r['after_error']:.3f} %",
                 f"{r['after_false_shadow']} / {r['after_false_light']}"]
        for call in ("prepare", "mask"):
            low, high = r[f"{call}_ratio_range"]
            cells += [f"{r[f'before_{call}_s']:.3f} / {r[f'after_{call}_s']:.3f}",
                      f"{r[f'{call}_ratio']:.2f} ({low:.2f}-{high:.2f})"]
        lines.append("| " + " | ".join(cells) + " |")
    doc = dict(before=args.before, receivers=ground + model, repeats=args.repeats, load=load, rows=rows)
    save(args.out, "angular_revisions-quick" if args.quick else "angular_revisions", doc, "\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
