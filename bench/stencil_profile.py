"""Where render's shadow-volume stencil (``ShadowVolumeMethod.classify_view``) spends its time.

    python bench/stencil_profile.py [--quick] [--scene bunny] [--width 960] [--height 540] [--repeats 7]
                                    [--bands 64 8] [--out DIR]

On scenes/models/SCENE.toml (its point light, brute-force silhouettes, full mesh, z-fail), after one
warm-up, ``repeats`` interleaved rounds time, each after ``queue.finish()``:

- ``exact_classify``: the exact method's classify on the same covered pixels (the peer: the ratio
  classify_view / exact_classify is the figure to quote, the machine is shared and noisy);
- ``classify_view``: the whole stencil classification as render calls it, and
  ``classify_view_bands64``: the same with every big triangle split into BANDS (64) bands, as before
  raster.STENCIL_MIN_GROUPS (one work-group per big triangle);
- its stages: ``facing_away`` (the normal rule), ``moved_depths`` (the Z-buffer moved by eps),
  ``geometry_upload`` (the volume's vertices and faces: a new volume every frame), ``setup``
  (raster_setup: transform, clip, snap), ``fill_small`` / ``fill_big`` (raster_stencil over the
  triangles drawn by one work-item / the big ones shared by ``bands`` work-items each; one column per
  ``--bands`` value), ``readback``;
- the stencil images of every ``--bands`` value compared bit for bit.

Also counted: volume triangles, big triangles, rows of big triangles' boxes, stencil fragments.
Writes OUT/stencil_profile.{json,md} (``stencil_profile-quick`` with ``--quick``).
"""

from __future__ import annotations

import argparse
import json
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from report import to_json
from run import machine
from timing import Timing, clock
import shadowcl as sc
from shadowcl import get_device, raster
from shadowcl.methods import create_method, default_eps
from shadowcl.points import check_points
from shadowcl.render import camera_view

RESULTS = Path(__file__).resolve().parent / "results"
PROJECT = Path(__file__).resolve().parents[1]
FULL = {"width": 960, "height": 540, "repeats": 7}
QUICK = {"width": 160, "height": 90, "repeats": 1}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--scene", default="bunny")
    parser.add_argument("--width", type=int)
    parser.add_argument("--height", type=int)
    parser.add_argument("--repeats", type=int)
    parser.add_argument("--bands", type=int, nargs="+", default=[raster.BANDS, raster._BAND_GROUP],
                        help="bands per big triangle to time the fill with (multiples of 8)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    size = dict(QUICK if args.quick else FULL)
    size.update({k: getattr(args, k) for k in size if getattr(args, k) is not None})
    width, height = size["width"], size["height"]

    device = get_device()
    queue = device.queue
    scene = sc.Scene.load(PROJECT / "scenes" / "models" / f"{args.scene}.toml")
    view = camera_view(scene, width, height)
    zbuffer = raster.rasterize(device, scene.mesh, view)
    seen = raster.receivers(device, scene.mesh, view, zbuffer)
    eps, light = default_eps(scene.bounds), scene.lights[0]
    # Inside on purpose: the stencil's stages, and exact's classify on the same pixels as its yardstick
    # (both without the public calls' receiver check), are what this profile splits apart.
    volume_method = create_method("shadow_volume", device)
    volume_method.prepare(scene.mesh, light, scene.bounds, eps)
    exact = create_method("exact", device, expected_receivers=len(seen.points))
    exact.prepare(scene.mesh, light, scene.bounds, eps)
    volume = volume_method.volume.mesh
    surface = volume_method._moved_depths(view, seen, zbuffer)
    kernel = device.kernel(raster._FILE, "raster_pass", raster._OPTIONS)

    times: dict[str, Timing] = {}
    images: dict[str, np.ndarray] = {}

    def timed(name, call, keep):
        """One stage between drained queues (stages depend on each other: timing.clock, not timing.timed)."""
        queue.finish()
        seconds, result = clock(lambda: (call(), queue.finish())[0])
        if keep:
            times.setdefault(name, Timing()).runs.append(seconds)
        return result

    for round_ in range(size["repeats"] + 1):          # round 0: warm-up
        keep = round_ > 0
        timed("exact_classify", lambda: exact.classify(seen.points, seen.normals), keep)
        timed("classify_view", lambda: volume_method.classify_view(view, zbuffer, seen), keep)
        chosen = raster.STENCIL_MIN_GROUPS
        raster.STENCIL_MIN_GROUPS = 1 << 30                # every big triangle gets BANDS bands
        try:
            timed("classify_view_bands64", lambda: volume_method.classify_view(view, zbuffer, seen), keep)
        finally:
            raster.STENCIL_MIN_GROUPS = chosen
        timed("facing_away", lambda: check_points(seen.points, seen.normals).facing_away(volume_method.light), keep)
        timed("moved_depths", lambda: volume_method._moved_depths(view, seen, zbuffer), keep)
        fresh = sc.Mesh(volume.vertices, volume.faces)   # a new volume, as after every prepare
        timed("geometry_upload", lambda: raster._geometry(device, fresh, view.origin), keep)
        setup = timed("setup", lambda: raster._setup(device, fresh, view), keep)
        depth = device.to_device(surface)
        for bands in args.bands:
            image = raster._image(device, view, 0, "stencil")
            # raster._draw's one launch split in two: the whole triangles (no big ones), the big ones alone
            for part, n, big_count in (("small", setup.triangles, 0), ("big", 0, setup.big_count)):
                def launch():
                    if n + big_count:
                        kernel(queue, (raster._rounded(n + big_count * bands),), (raster._GROUP,), setup.big,
                               np.int32(n), np.int32(big_count), np.int32(bands), setup.count, setup.xy, setup.depth,
                               np.int32(width), np.int32(height), np.int32(raster._ZFAIL_STENCIL_PASS), image, depth)
                timed("fill_small" if part == "small" else f"fill_big_bands{bands}", launch, keep)
            images[bands] = timed("readback", lambda: device.from_device(image, (height, width), np.int32), keep)
    reference = next(iter(images.values()))
    identical = all(np.array_equal(image, reference) for image in images.values())

    boxes = raster.screen_polygons(device, volume, view)
    rows = []
    for i in np.flatnonzero(boxes.count >= 3):
        xy = boxes.xy[i, :boxes.count[i]].astype(np.int64)
        low = np.clip(xy.min(axis=0), 0, [width << raster.SUBPIXEL_BITS, height << raster.SUBPIXEL_BITS])
        high = np.clip(xy.max(axis=0), 0, [width << raster.SUBPIXEL_BITS, height << raster.SUBPIXEL_BITS])
        extent = (high - low) >> raster.SUBPIXEL_BITS
        rows.append((extent[0], extent[1]))
    extent = np.array(rows).reshape(-1, 2)
    big = extent[:, 0] * extent[:, 1] > raster.BIG_BOX
    fragments = raster.coverage_count(device, volume, view)
    medians = {name: timing.median_ms for name, timing in times.items()}
    result = {
        "when": datetime.now(timezone.utc).isoformat(timespec="seconds"), "machine": machine(device),
        "scene": args.scene, "width": width, "height": height, "repeats": size["repeats"], "bands": args.bands,
        "stencils_identical": identical,
        "covered_pixels": int(len(seen.points)), "volume_triangles": int(len(volume.faces)),
        "big_triangles": int(big.sum()), "big_box_rows": int(extent[big, 1].sum()),
        "fragments": int(fragments.sum()), "max_overdraw": int(fragments.max()),
        "median_ms": medians, "all_ms": {k: [1e3 * t for t in v.runs] for k, v in times.items()},
        "classify_view_over_exact": medians["classify_view"] / medians["exact_classify"],
        "classify_view_bands64_over_exact": medians["classify_view_bands64"] / medians["exact_classify"],
        "classify_view_over_bands64": medians["classify_view"] / medians["classify_view_bands64"],
    }
    write(args.out, "stencil_profile" + ("-quick" if args.quick else ""), result)
    return result


def write(folder: Path, stem: str, result: dict) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{stem}.json").write_text(json.dumps(result, indent=1, default=to_json))
    lines = [f"# Shadow-volume stencil profile: {result['scene']} at {result['width']} x {result['height']}", "",
             f"{result['when']}; median of {result['repeats']} rounds after a warm-up, interleaved; shared "
             "2-core machine (other jobs running): compare ratios within this run, not absolute times.", "",
             f"volume triangles {result['volume_triangles']:,}, big {result['big_triangles']:,} "
             f"(box rows {result['big_box_rows']:,}), stencil fragments {result['fragments']:,}, "
             f"max overdraw {result['max_overdraw']}, covered pixels {result['covered_pixels']:,}; "
             f"stencil images identical across kernels and bands: {result['stencils_identical']}", "",
             "| stage | median ms |", "| --- | ---: |"]
    lines += [f"| {name} | {ms:.1f} |" for name, ms in result["median_ms"].items()]
    lines += ["", f"classify_view / exact classify: **{result['classify_view_over_exact']:.2f}** "
              f"(with 64 bands per big triangle, as before: {result['classify_view_bands64_over_exact']:.2f}); "
              f"classify_view / classify_view_bands64: **{result['classify_view_over_bands64']:.2f}**"]
    (folder / f"{stem}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    figures = main()
    print(json.dumps({k: figures[k] for k in ("median_ms", "classify_view_over_exact", "classify_view_over_bands64",
                                              "stencils_identical")},
                     indent=1, default=float))
