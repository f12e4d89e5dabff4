"""README's figures, generated from the committed bench results, never typed.

    python bench/figures.py           # rewrite README.md's generated blocks from bench/results/*.json
    python bench/figures.py --check   # exit 1 (and say which block) when README.md is out of date

A generated block is the text between ``<!-- figures: NAME -->`` and ``<!-- /figures -->`` in
README.md; :data:`BLOCKS` maps NAME to the function that writes it. Every number in a block comes from
a JSON file in bench/results, named beside it; prose is static text here. The exact/Embree figures
come from the newest full ``run-*.json``.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

import numpy as np

import report
from peers import PEERS
from report import time_of

BENCH = Path(__file__).resolve().parent
RESULTS = BENCH / "results"
README = BENCH.parent / "README.md"
MODELS = ("bunny", "ogre", "teapot")


def load(name: str) -> dict:
    return json.loads((RESULTS / name).read_text())


def newest_run(predicate=lambda doc: True) -> tuple[str, dict]:
    """The newest full ``run-*.json`` (names sort by date) for which ``predicate(doc)`` holds."""
    for path in sorted(RESULTS.glob("run-*.json"), reverse=True):
        doc = json.loads(path.read_text())
        if not doc["settings"].get("quick") and predicate(doc):
            return path.name, doc
    raise FileNotFoundError(f"no full run-*.json in {RESULTS} fits")


def span(values, digits: int = 2, unit: str = "") -> str:
    """``low–high`` (or one value) with ``digits`` significant digits."""
    low, high = (f"{v:.{digits}g}" for v in (min(values), max(values)))
    return f"{low}{unit}" if low == high else f"{low}–{high}{unit}"


def count(n: int) -> str:
    return f"{n / 1e6:.1f} M" if n >= 1e6 else f"{n / 1e3:.0f} k" if n >= 1e3 else str(n)


def src(*names: str) -> str:
    return " (" + ", ".join(f"`{n}`" for n in names) + ")"


def judged(peers: list[dict]) -> str:
    """The float64 reference's verdict on the peers' disagreements with exact (run.judge_disputes), or ''."""
    disputes = [r["disputes"] for r in peers if r.get("disputes")]
    if not disputes:
        return ""
    total = {key: sum(d[key] for d in disputes) for key in ("judged", "truth_right", "row_right", "within_rounding")}
    return (f"; of {total['judged']} such receivers judged by the float64 reference, exact is right on "
            f"{total['truth_right']}, wrong on {total['row_right']}, and {total['within_rounding']} lie within "
            f"float32 rounding (a segment within 1e-6 scene sizes of an edge or of its ends)")


def exact_cells() -> tuple[str, str]:
    name, run = newest_run(lambda d: "oneshot_s" in d["rows"][0])
    rows = {(*report.case_key(r)[::2], r["label"]): r for r in run["rows"]}       # (scene, normals, label)
    scenes = sorted({r["scene"] for r in run["rows"]}, key=lambda s: (s not in MODELS, s))
    modes = sorted({r.get("normals", True) for r in run["rows"]}, reverse=True)   # with normals first
    peers = [r for r in run["rows"] if r["method"] in PEERS]
    leaks = load("leaks.json")["rows"]
    with_without = " / ".join("with" if mode else "without" for mode in modes)
    error = (f"the reference: at most {max(r['wrong'] for r in peers)} of {count(peers[0]['receivers'])} receivers "
             f"differ from {', '.join(sorted({r['method'] for r in peers}))} on {', '.join(scenes)} ({with_without} normals)"
             f"{judged(peers)}{src(name)}; "
             f"{sum(r['watertight_leaks'] for r in leaks)} leaks over {count(sum(r['rays'] for r in leaks))} rays "
             f"aimed at shared edges and vertices (dot5: {span([r['dot5_leak_percent'] for r in leaks])} %)"
             f"{src('leaks.json')}")
    exact = [rows[(s, mode, "exact")] for s in scenes for mode in modes]
    split = [r for r in exact if r["method_stats"].get("split_triangles")]
    whole = [r for r in exact if not r["method_stats"].get("split_triangles")]
    host = f"{span([100 * r['host_share'] for r in whole])} % of the call's time on the host (outside OpenCL calls)"
    if split:
        host += (f", {span([100 * r['host_share'] for r in split])} % where large occluders are split on the host "
                 f"({', '.join(sorted({r['scene'] for r in split}))})")
    per_scene = ", ".join(f"{s} " + " / ".join(f"{rows[(s, mode, 'exact')]['receivers_per_s'] / 1e6:.1f}"
                                               for mode in modes) for s in scenes)
    speed = (f"one-shot `shadow_mask`, M receivers/s ({with_without} normals): {per_scene}; "
             f"{span([r['vs_peer'] for r in exact])}× the fastest peer's throughput (of "
             f"{', '.join(sorted({r['method'] for r in peers}))}; prepare + classify) in the same run; `prepare` {span([1e3 * r['prepare_s'] for r in exact], 3)} ms, `mask` "
             f"{span([r['receivers_per_s_query'] / 1e6 for r in exact])} M receivers/s; {host}{src(name)}")
    return error, speed


def shadow_map_cells() -> tuple[str, str]:
    def worst(doc: dict, resolution: int, bias: str, normals: bool) -> float:
        return max(r["error_pct"] for r in doc["rows"] if (r["resolution"], r["bias"], r["filter"], r["normals"])
                   == (resolution, bias, "nearest", normals))

    def errors(doc: dict, bias: str) -> str:
        return "; ".join(f"{res}: {worst(doc, res, bias, False):.2f} / {worst(doc, res, bias, True):.3f} %"
                         for res in (512, 2048, 4096))

    new, bench = load("shadow-map-bias.json"), load("shadow-map-bias-bench.json")
    count = len({(r["scene"], r["light"]) for r in new["rows"]})
    error = (f"default (bias \"plane\", nearest), worst of {count} new scenes x lights without / with normals: "
             f"{errors(new, 'plane')} (normal offset: {errors(new, 'normal')}){src('shadow-map-bias.json')}; "
             f"worst of bunny / ogre / default / light_inside: {errors(bench, 'plane')}{src('shadow-map-bias-bench.json')}")
    name, run = newest_run(lambda d: len(d["settings"]["sweep"].get("shadow_map", {}).get("resolution", [])) > 2)
    by_case = {}
    for r in run["rows"]:
        by_case.setdefault(report.case_key(r), []).append(r)
    parts = []
    for resolution in run["settings"]["sweep"]["shadow_map"]["resolution"]:
        ratios, errs = [], []
        for (scene, *_), group in by_case.items():
            exact = next((r for r in group if r["method"] == "exact"), None)
            mine = [r for r in group if r["method"] == "shadow_map" and r["params"].get("resolution") == resolution
                    and r["params"].get("bias", "normal") == "normal" and r["params"].get("filter", "nearest") == "nearest"]
            if scene in MODELS and exact and mine:
                ratios.append(time_of(mine[0], "oneshot_s") / time_of(exact, "oneshot_s"))
                errs.append(mine[0]["error_percent"])
        if ratios:
            parts.append(f"{resolution}: {span(ratios)}× ({span(errs)} %)")
    def ratios(doc: dict) -> str:
        r = doc["speed_ratio"]
        return (f"{r['scene']}: plane / normal offset {r['with']['plane'] / r['with']['normal']:.1f}x with normals, "
                f"{r['without']['plane'] / r['without']['normal']:.1f}x without; plane / exact "
                f"{r['with']['plane'] / r['with']['exact']:.1f}x, {r['without']['plane'] / r['without']['exact']:.1f}x")

    speed = (f"query time at 2048, {ratios(new)}{src('shadow-map-bias.json')}; {ratios(bench)}"
             f"{src('shadow-map-bias-bench.json')}; run.py's default of its day, time / exact's on the models "
             "(error): " + ", ".join(parts) + src(name))
    return error, speed


def voxel_cells() -> tuple[str, str]:
    doc = load("voxel.json")
    scenes = [s["scene"] for s in doc["scenes"]]

    def rows(resolution, determination):
        return [r for s in doc["scenes"] for r in s["rows"] if r["resolution"] == resolution
                and r["determination"] == determination and r["connectivity"] == 26]

    error = (f"256³, topology: {span([r['all']['percent'] for r in rows(256, 'topology')])} % on {', '.join(scenes)} "
             f"(offset {span([r['all']['percent'] for r in rows(256, 'offset')])} %); 1024³: "
             f"{span([r['all']['percent'] for r in rows(1024, 'topology')])} %{src('voxel.json')}")
    speed = (f"{span([r['ratio_to_exact'] for r in rows(256, 'topology')])}× the exact method's time at 256³ (exact "
             f"is fast on the tessellations); a second view of the same light from the frame buffer "
             f"{span([s['second_view']['speedup'] for s in doc['scenes']])}× faster than recomputing{src('voxel.json')}")
    return error, speed


def shadow_volume_cells() -> tuple[str, str]:
    rows = load("shadow_volume.json")["rows"]
    masks = [r for r in rows if r["path"] == "shadow_mask"]
    renders = [r for r in rows if r["path"].startswith("render") and "failed" not in r]
    lod = load("lod.json")
    bunny = next(s for s in lod["scenes"] if s["scene"] == "bunny")
    auto = bunny["lights"][0]["auto"]
    error = (f"`shadow_mask`: {max(r['differ'] for r in masks)} of {count(masks[0]['receivers'])} receivers differ "
             f"from exact on {', '.join(r['scene'] for r in masks)}; `render` stencil: "
             f"{span([r['fraction'] for r in renders])} of pixels, all within "
             f"{max(r['max_silhouette_distance_px'] for r in renders):.1g} px of a silhouette (pixel ray vs "
             f"eps-offset point){src('shadow_volume.json')}; `lod=\"auto\"` at {100 * lod['settings']['max_error']:g} %: "
             f"bunny {count(auto['triangles'])} of {count(bunny['triangles'])} triangles, ≤ "
             f"{max(light['auto']['bench_error']['percent'] for light in bunny['lights']):.2g} % over "
             f"{len(bunny['lights'])} lights{src('lod.json')}")
    fragments = load("stencil_profile.json")
    speed = (f"`shadow_mask` {span([r['ratio'] for r in masks])}× exact's time; the stencil (z-fail, z-pass) "
             f"{span([r['ratio'] for r in renders])}× exact's on the same pixels{src('shadow_volume.json')}; "
             f"{fragments['fragments'] / 1e6:.1f} M fragments on the bunny (filling the long side quads)"
             f"{src('stencil_profile.json')}")
    return error, speed


def angular_cells() -> tuple[str, str]:
    doc = load("angular.json")
    rows = [r for r in doc["speed_error"] if r["method"] == "angular"]
    default = {r["scene"]: r for r in rows if r["params"] == "theta_resolution=None, table=faces"}
    bunny = {r["params"]: r["error"] for r in rows if r["scene"] == "bunny"}
    limits = (100, 300, 600)
    error = (f"default rows (eq. 4): " + ", ".join(f"{s} {100 * default[s]['error']:.3f} %" for s in MODELS)
             + f"; {' / '.join(map(str, limits))} rows on the bunny: "
             + " / ".join(f"{100 * bunny[f'theta_resolution={n}, table=faces']:.2g}" for n in limits) + " %"
             + src("angular.json") + "; receivers lying on a closed occluder (normals), falsely shadowed: "
             + caps_error() + src("angular_caps.json"))
    hard = [r for s, r in default.items() if s not in MODELS and r.get("vs_shadow_map") is not None]
    lookup = doc["lookup_rate"]
    speed = (f"{span([default[s]['vs_exact'] for s in MODELS])}× exact's time on the models; faster than the "
             f"cheapest shadow map at least as accurate on {sum(r['vs_shadow_map'] < 1 for r in hard)} of {len(hard)} "
             f"hard scenes; {lookup['us_per_lookup']:.2g} µs per lookup on {count(lookup['cubes'])} cubes (paper: "
             f"~{lookup['paper_us_per_lookup']:g} µs){src('angular.json')}")
    return error, speed


def caps_error() -> str:
    """The two tables' false shadows on receivers lying on closed occluders, per kind of occluder, and their
    false lights on the ground under them (every scene and light)."""
    rows = load("angular_caps.json")["rows"]
    convex = [r for r in rows if r["scene"] in ("sphere", "cylinder", "torus") and r["light"].startswith("directional")]
    concave = [r for r in rows if r["scene"] == "box_minus_sphere"]
    return "; ".join(
        [f"{what}: faces {span([100 * r['faces_occluder_false_shadow'] for r in part])} %, loops "
         f"{span([100 * r['loops_occluder_false_shadow'] for r in part])} %"
         for what, part in (("curved caps (sphere, torus, cylinder), directional light", convex),
                            ("box minus sphere", concave))]
        + [f"the ground under them, falsely lit: faces {span([100 * r['faces_ground_false_light'] for r in rows])} %, "
           f"loops {span([100 * r['loops_ground_false_light'] for r in rows])} %"])


METHOD_ROWS = [  # method, paper, status (static prose), and the function giving its two figure cells
    ("`exact`", "Lai & Cheng 2007 §4.2 on the original triangles: light-space lists built on the device with atomics "
     "(an irregular Z-buffer), receivers binned by cell and tested 8 at a time; per triangle a plane test, then the "
     "edge planes through the light with rounding bounds, and the watertight test of Woop et al. 2013 for the lanes "
     "those cannot settle (`test=\"dot5\"`: the paper's 5-dot-product test)", "done", exact_cells),
    ("`shadow_map`", "Williams 1978: light-view depth and triangle ids from the raster kernel; bias \"plane\" "
     "(default, no normals needed: the texel's triangle plane at the receiver's ray and exact tests of the 3 x 3 "
     "texels' triangles, after Dou et al. 2014's adaptive depth bias), constant / slope / normal-offset bias, "
     "nearest / bilinear / PCF, dither, post-filter", "done", shadow_map_cells),
    ("`voxel`", "Lai & Cheng 2007: Catmull-Clark limit surfaces voxelized by breadth-first parameter-space subdivision "
     "on the device into a 2-bit cubic frame buffer; topology-based (sorted subpatch lists on the light-space lists + "
     "5-dot-product test) or offset-based determination; `render` draws the leaves tessellated crack-free (§5.3), "
     "ambient + 1/2^n of the reflection for n shadowed corners", "done (subdivision-surface scenes only; triangle "
     "objects are refused)", voxel_cells),
    ("`shadow_volume`", "Fawad, Wang & Wu: silhouettes by brute force, tracking or the randomized method, LOD occluders "
     "(`lod=None\\|level\\|\"auto\"`), volumes closed with caps; camera stencil (z-fail / z-pass) drawn by the raster "
     "kernel in `render`, per-point cap count in `shadow_mask`", "done", shadow_volume_cells),
    ("`angular`", "Thakur, Cheng & Miura: ridge-edge loops, span table per θ row built on the device: `table=\"loops\"` "
     "the paper's (ridge-edge crossings paired by §4's rule, chord depth, creases in duplicate), `table=\"faces\"` "
     "(default: one record per light-facing face and row band it meets, its span over the whole band, and the hit "
     "tested on the triangle itself, watertight edge functions after the plane: no discretization error), "
     "binary-search lookups, scan-line runs in `render`, several lights (`shadow_counts`), light inside", "done",
     angular_cells),
]


def methods_table() -> str:
    lines = ["| method | paper | status | error vs exact | speed |", "|---|---|---|---|---|"]
    for method, paper, status, cells in METHOD_ROWS:
        lines.append(f"| {method} | {paper} | {status} | {' | '.join(cells())} |")
    return "\n".join(lines)


def auto_table() -> str:
    """method="auto" and lod="auto" per budget, from ``auto.json`` (bench/auto.py)."""
    doc = load("auto.json")
    rows = doc["rows"]
    lines = ["| budget | cases | budget broken: auto / lod=\"auto\" | auto / exact: median, worst | "
             "auto / sweep's oracle: median, worst | chosen (most frequent per case) |", "|---|---|---|---|---|---|"]
    for budget in sorted({r["budget"] for r in rows}, reverse=True):
        cases = [r for r in rows if r["budget"] == budget]
        ratios = [r["auto_vs_exact"] for r in cases]
        oracle = [r["auto_vs_oracle"] for r in cases]
        chosen = {c: sum(r["chosen"] == c for r in cases) for c in sorted({r["chosen"] for r in cases})}
        lines.append(f"| {budget:g} | {len(cases)} | {sum(r['broken'] for r in cases)} / "
                     f"{sum(r['lod_auto']['broken'] for r in cases)} | {np.median(ratios):.2f}, {max(ratios):.2f} | "
                     f"{np.median(oracle):.2f}, {max(oracle):.2f} | "
                     f"{', '.join(f'{c} {n}' for c, n in chosen.items())} |")
    scenes = sorted({r["scene"] for r in rows}, key=[r["scene"] for r in rows].index)
    loads = doc["settings"].get("load")
    load_note = f"; load average {loads[0][0]:.1f} at the start, {loads[1][0]:.1f} at the end on 2 cores" if loads else ""
    lines.append(f"\nScenes: {', '.join(scenes)}, {count(rows[0]['receivers'])} receivers, with and without normals "
                 f"(`auto.json`, {doc['settings']['repeats']} interleaved rounds{load_note}; per case: "
                 f"`bench/results/auto.md`).")
    return "\n".join(lines)


BLOCKS = {"methods-table": methods_table, "auto-table": auto_table}
BLOCK = re.compile(r"(<!-- figures: ([\w-]+) -->\n)(.*?)(<!-- /figures -->)", re.DOTALL)


def regenerate(text: str) -> str:
    """``text`` with every generated block rewritten; an unknown block name raises ``KeyError``."""
    return BLOCK.sub(lambda m: m.group(1) + BLOCKS[m.group(2)]() + "\n" + m.group(4), text)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Regenerate README.md's figures from bench/results/*.json.")
    parser.add_argument("--check", action="store_true", help="do not write; exit 1 if README.md is out of date")
    args = parser.parse_args(argv)
    text = README.read_text()
    new = regenerate(text)
    if args.check:
        stale = [m.group(2) for m, n in zip(BLOCK.finditer(text), BLOCK.finditer(new)) if m.group(0) != n.group(0)]
        if stale or not BLOCK.search(text):
            print(f"README.md is out of date (blocks: {', '.join(stale) or 'none found'}); run python bench/figures.py",
                  file=sys.stderr)
            return 1
        return 0
    README.write_text(new)
    return 0


if __name__ == "__main__":
    sys.exit(main())
