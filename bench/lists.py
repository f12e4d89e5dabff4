"""The device prefix sum (``shadowcl.lists.prefix_sum``, serial blocks) against the work-group scan in
local memory tried in its place (and dropped: slower on PoCL), on the default device, in alternating rounds.

    python bench/lists.py [--quick] [--alternative REV] [--repeats 15] [--out bench/results]

The work-group scan's kernels are ``kernels/lists.h`` at git revision ``REV`` (its two kernels built on
their own), launched as that revision's ``prefix_sum`` did (:func:`group_prefix_sum`, copied here).
Three figures, each the two alternated round by round (``timing.interleaved``), medians in ms:

- the scan alone on ``n`` random counts (0-7);
- the exact method's light-space build (``stats["scan_s"]``, the scan of one count per cell; and the
  whole build), bunny and the default scene;
- exact's classify of the scene's receivers, whose receiver binning scans one count per cell too.

Writes ``OUT/lists.json`` and ``OUT/lists.md``. The machine's 2 cores are shared: the load (``uptime``)
is written with the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pyopencl as cl

import receivers as rx
import shadowcl as sc
from shadowcl import lists
from shadowcl.exact import ExactMethod
from shadowcl.methods import default_eps
from timing import interleaved

PROJECT = Path(__file__).resolve().parents[1]
RESULTS = PROJECT / "bench" / "results"
ALTERNATIVE = "d12a58a"         # the commit with the work-group scan


def group_program(device, rev: str) -> cl.Program:
    """The work-group scan's kernels (``scan_group_sums``, ``scan_groups``) of ``lists.h`` at ``rev``, built
    on their own."""
    source = subprocess.run(["git", "-C", str(PROJECT), "show", f"{rev}:kernels/lists.h"], check=True,
                            capture_output=True, text=True).stdout
    folder = Path(tempfile.mkdtemp(prefix="lists-alternative-"))
    (folder / "lists_alternative.h").write_text(source)
    program = cl.Program(device.context, '#include "lists_alternative.h"\n')
    return program.build(options=["-I", str(folder), "-I", str(PROJECT / "kernels")])


def group_prefix_sum(program: cl.Program):
    """That revision's ``prefix_sum``: two launches of work-groups of 128, at most 256 groups, each work-item
    owning at least 8 counts; groups scan their items' sums in local memory."""
    kernels = {name: cl.Kernel(program, name) for name in ("scan_group_sums", "scan_groups")}
    group, most, least = 128, 256, 8

    def prefix_sum(device, kernel, counts, n, offsets, second_row=0):
        if second_row:
            raise ValueError("second_row: that revision scanned one row of counts")
        queue = device.queue
        per_item = max(least, -(-n // (most * group)))
        ngroups = max(1, -(-n // (group * per_item)))
        sums = device.scratch("bench: work-group sums", 8 * (ngroups + 1))
        args = (counts, np.int32(n), np.int32(per_item))
        kernels["scan_group_sums"](queue, (ngroups * group,), (group,), *args, sums)
        kernels["scan_groups"](queue, (ngroups * group,), (group,), *args, sums, offsets, np.int32(ngroups))
        total = np.empty(1, np.int64)
        cl.enqueue_copy(queue, total, sums, src_offset=8 * ngroups)
        return int(total[0])
    return prefix_sum


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one size, the default scene only, 3 repeats")
    parser.add_argument("--alternative", default=ALTERNATIVE)
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    repeats = args.repeats or (3 if args.quick else 15)
    device = sc.get_device()
    versions = {"serial blocks (kept)": lists.prefix_sum,
                f"work-group scan ({args.alternative})": group_prefix_sum(group_program(device, args.alternative))}
    current = lists.prefix_sum

    def using(version, fn):
        def run():
            lists.prefix_sum = versions[version]
            try:
                return fn()
            finally:
                lists.prefix_sum = current
        return run

    rows = []
    lookup = lambda name: device.kernel("lightspace.cl", name, ("-DCORNERS=3", "-DNVIEWS=1", "-DPERSPECTIVE=0"))
    rng = np.random.default_rng(0)
    for n in ([1_200_000] if args.quick else [65_536, 1_200_000, 4_194_307]):
        counts = device.to_device(rng.integers(0, 8, n).astype(np.int32))
        offsets = device.empty(4 * (n + 1))
        want = None
        for version in versions:         # both agree before anything is timed
            total = using(version, lambda: lists.prefix_sum(device, lookup, counts, n, offsets))()
            got = device.from_device(offsets, n + 1, np.int32)
            assert want is None or (np.array_equal(got, want) and total == int(want[-1])), version
            want = got

        def scan():
            lists.prefix_sum(device, lookup, counts, n, offsets)
            device.queue.finish()
        times = interleaved({v: using(v, scan) for v in versions}, repeats)
        rows.append(dict(stage="scan alone", case=f"n = {n:,}", load=load(),
                         **{v: t.median * 1e3 for v, t in times.items()}))
        print(rows[-1], flush=True)

    for name in (["scenes/default.toml"] if args.quick else ["bunny", "scenes/default.toml"]):
        scene = rx.load_scene(name if name in rx.MODEL_FILES else str(PROJECT / name))
        points, normals = rx.receivers(scene, 1_000_000, 200_000)
        light, eps = scene.lights[0], default_eps(scene.mesh.bounds)
        bounds = np.stack([points.min(axis=0), points.max(axis=0)])
        method = ExactMethod(device)
        masks = {}
        for version in versions:
            using(version, lambda: method.prepare(scene.mesh, light, bounds, eps))()
            masks[version] = using(version, lambda: method.classify(points, normals))()
        assert all(np.array_equal(m, masks[next(iter(masks))]) for m in masks.values())
        scan_s, build_s = {v: [] for v in versions}, {v: [] for v in versions}

        def prepare(version):
            def run():
                method.prepare(scene.mesh, light, bounds, eps)
                scan_s[version].append(method.stats["scan_s"])
                build_s[version].append(method.stats["build_s"])
            return using(version, run)
        interleaved({v: prepare(v) for v in versions}, repeats)
        cells = method.stats["cells"]
        rows.append(dict(stage="light-space build: scan", case=f"{scene.name}, {cells:,} cells", load=load(),
                         **{v: float(np.median(scan_s[v])) * 1e3 for v in versions}))
        rows.append(dict(stage="light-space build: whole", case=f"{scene.name}, {cells:,} cells", load=load(),
                         **{v: float(np.median(build_s[v])) * 1e3 for v in versions}))
        times = interleaved({v: using(v, lambda: method.classify(points, normals)) for v in versions}, repeats)
        rows.append(dict(stage="exact classify (receiver binning scan)", case=f"{scene.name}, {len(points):,} receivers",
                         load=load(), **{v: t.median * 1e3 for v, t in times.items()}))
        for row in rows[-3:]:
            print(row, flush=True)

    old, new = versions
    lines = [f"# Prefix sum: serial blocks against a work-group scan ({device.name})", "",
             f"Medians of {repeats} alternating rounds after a warm-up, ms; the work-group scan's kernels from "
             f"{args.alternative}. Load: 1, 5, 15-minute averages when the row was measured (2 shared cores).", "",
             f"| stage | case | {old} | {new} | work-group / serial | load |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['stage']} | {r['case']} | {r[old]:.3f} | {r[new]:.3f} | {r[new] / r[old]:.2f} | {r['load']} |")
    doc = dict(device=device.name, repeats=repeats, alternative=args.alternative, rows=rows)
    if not args.quick:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "lists.json").write_text(json.dumps(doc, indent=1) + "\n")
        (args.out / "lists.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return doc


if __name__ == "__main__":
    main()
