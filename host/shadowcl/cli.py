"""The ``shadowcl`` command: ``render`` a scene to PNG, ``sun-hours`` on its sensors, list ``devices`` and
``methods``."""

from __future__ import annotations

import argparse
import ast
import contextlib
import os
import re
import sys
import time
from pathlib import Path

from . import scenes as _scene_package

DEFAULT_SCENE = Path(_scene_package.__file__).resolve().parent / "default.toml"
CITY_BLOCK = Path(_scene_package.__file__).resolve().parent / "city_block.toml"


def parse_size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(part) for part in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size: expected WIDTHxHEIGHT such as 960x540, got {text!r}") from None
    if width < 1 or height < 1:
        raise argparse.ArgumentTypeError(f"--size: width and height must be positive, got {text!r}")
    return width, height


def parse_param(text: str) -> tuple[str, object]:
    """``name=value`` with value read as a Python literal when it is one (numbers, None, strings)."""
    name, sep, value = text.partition("=")
    if not sep or not name.isidentifier():
        raise argparse.ArgumentTypeError(f"--param: expected NAME=VALUE, got {text!r}")
    try:
        return name, ast.literal_eval(value)
    except (ValueError, SyntaxError):
        return name, value


class _Parser(argparse.ArgumentParser):
    """argparse with usage errors as one line on stderr (exit code 2), like every other error."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="shadowcl", description="Hard shadows with OpenCL.")
    commands = parser.add_subparsers(dest="command", required=True)

    render = commands.add_parser("render", help="render a scene file to a PNG")
    render.add_argument("scene", nargs="?", type=Path, default=DEFAULT_SCENE, help="scene .toml (default: the built-in demo)")
    render.add_argument("--method", default="exact", help="shadow method (see 'shadowcl methods'; default exact)")
    render.add_argument("--out", type=Path, help="output PNG (default: shadowcl-SCENE-METHOD.png here)")
    render.add_argument("--size", type=parse_size, help="image size WIDTHxHEIGHT (default: the scene's, else 960x540)")
    render.add_argument("--device", help="OpenCL device: 'P:D' indices or part of its name")
    render.add_argument("--param", type=parse_param, action="append", default=[], help="method parameter NAME=VALUE (repeatable)")

    sun = commands.add_parser("sun-hours", help="hours of direct sun on a scene's sensor grids (.npy, .csv, heat map)")
    sun.add_argument("scene", nargs="?", type=Path, default=CITY_BLOCK, help="scene .toml with [[sensors]] (default: the city block)")
    sun.add_argument("--start", help="first time, e.g. 2026-06-21 (default: the scene's [sun])")
    sun.add_argument("--end", help="end time, excluded (default: the scene's [sun])")
    sun.add_argument("--step", help="time step, e.g. 1h or 15min (default: the scene's [sun], else 1h)")
    sun.add_argument("--lat", type=float, help="latitude in degrees (default: the scene's [sun])")
    sun.add_argument("--lon", type=float, help="longitude in degrees (default: the scene's [sun])")
    sun.add_argument("--spacing", type=float, help="sensor grid step, replacing the scene's")
    cluster = sun.add_mutually_exclusive_group()
    cluster.add_argument("--workers", type=int, help="run on a local Dask cluster of N worker processes")
    cluster.add_argument("--scheduler", help="run on the Dask scheduler at this address")
    sun.add_argument("--out", type=Path, default=Path("sun-hours.png"), help="heat map PNG; .npy and .csv beside it")
    sun.add_argument("--device", help="OpenCL device (local runs): 'P:D' indices or part of its name")

    commands.add_parser("devices", help="list OpenCL devices")
    commands.add_parser("methods", help="list shadow methods and their parameters")
    return parser


def run_render(args) -> int:
    from tqdm import tqdm

    from .device import get_device
    from .render import render_report
    from .scene import Scene
    from PIL import Image

    started = time.perf_counter()
    scene = Scene.load(args.scene)
    # the scene's name comes from its file: no separators or '..' into the default output path
    out = args.out or Path(re.sub(r"[^\w.-]|\.\.", "_", f"shadowcl-{scene.name}-{args.method}") + ".png")
    _check_writable(out)
    load_time = time.perf_counter() - started
    width, height = args.size or (None, None)
    stages = ["raster", "receivers"] + ["prepare", "classify"] * len(scene.lights) + ["shading"]
    # disable=None: no bar when stderr is not a terminal, so an error there is the only line
    with tqdm(total=len(stages), desc=f"render {scene.name}", unit="stage", leave=False, disable=None) as bar:
        def progress(stage):
            bar.set_postfix_str(stage)
            bar.update(1)

        result = render_report(scene, args.method, width, height, get_device(args.device), progress=progress, **dict(args.param))
    try:
        Image.fromarray(result.image).save(out)
    except OSError as error:
        raise ValueError(f"--out: cannot write {out}: {error.strerror or error}") from None

    height, width = result.image.shape[:2]
    shadowed = result.shadow.any(axis=0).mean() if result.shadow.size else 0.0
    print(f"scene {scene.name}: {len(scene.mesh.faces)} triangles, {len(scene.lights)} light(s), method {args.method}")
    print(f"image {width}x{height}: {result.covered.sum()} pixels on the scene, {100 * shadowed:.1f} % of them in shadow")
    for index, shadows in enumerate(result.shadows if args.method == "auto" else []):
        print(f"light {index}: {auto_summary(shadows)}")
    print("times: " + ", ".join(f"{name} {seconds * 1e3:.1f} ms" for name, seconds in [("load", load_time), *result.timings.items()]))
    print(f"wrote {out.resolve()}")
    return 0


def auto_summary(shadows) -> str:
    """What method="auto" chose for one light, and on what evidence."""
    chosen = dict(shadows.params["chosen"])
    calibration = shadows.stats["calibration"]
    settings = ", ".join(f"{k}={v!r}" for k, v in chosen.items() if k != "method")
    text = f"auto chose {chosen.pop('method')}" + (f" ({settings})" if settings else "")
    text += f" for budget {calibration['max_error']:g}"
    if calibration["sample"]:
        text += (f": sample {calibration['sample']:,} receivers, error {calibration['error']:.3g}, 99 % bound "
                 f"{calibration['upper_bound']:.3g}")
    tried = [r["method"] + (f"@{r['resolution']}" if "resolution" in r else "") for r in calibration["tried"] if "error" in r]
    return (text + f", calibration {calibration['seconds'] * 1e3:.0f} ms, tried {', '.join(tried) or 'nothing'}; "
            f"sample: {calibration['source']}")


def _check_writable(out: Path) -> None:
    """Make ``out``'s folder and check a PNG can be written there, before any rendering is done."""
    from PIL import Image

    if out.suffix.lower() not in Image.registered_extensions():
        raise ValueError(f"--out: {out.suffix or 'no suffix'!r} is not an image format Pillow writes (use .png)")
    if out.is_dir():
        raise ValueError(f"--out: {out} is a folder")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise ValueError(f"--out: cannot make the folder {out.parent}: a file is in the way") from None
    except OSError as error:
        raise ValueError(f"--out: cannot make the folder {out.parent}: {error.strerror or error}") from None
    if not os.access(out.parent, os.W_OK) or (out.exists() and not os.access(out, os.W_OK)):
        raise ValueError(f"--out: cannot write {out}: permission denied")


def run_sun_hours(args) -> int:
    from .scene import Scene
    from .sunhours import sun_hours, write

    scene = Scene.load(args.scene)
    _check_writable(args.out)
    site = dict(scene.sun or {})
    given = dict(latitude=args.lat, longitude=args.lon, start=args.start, end=args.end, step=args.step)
    site.update({key: value for key, value in given.items() if value is not None})
    missing = [key for key in ("latitude", "longitude", "start", "end") if key not in site]
    if missing:
        raise ValueError(f"{args.scene}: no [sun] table gives {', '.join(missing)}; pass --lat, --lon, --start, --end")
    if args.workers is not None and args.workers < 1:
        raise ValueError(f"--workers: must be at least 1, got {args.workers}")
    started = time.perf_counter()
    with _cluster_client(args) as client:
        result = sun_hours(scene, site["latitude"], site["longitude"], str(site["start"]), str(site["end"]),
                           site.get("step", "1h"), site.get("timezone", "UTC"), site.get("north", (0.0, 0.0, -1.0)),
                           spacing=args.spacing, client=client, progress=True,
                           **({} if client is not None else {"device": args.device}))
    seconds = time.perf_counter() - started
    paths = write(result, args.out)
    print(f"scene {scene.name}: {len(result.hours)} sensors, {result.steps} sun-up steps of {result.step_hours:g} h, "
          f"{seconds:.1f} s ({len(result.hours) * result.steps / max(seconds, 1e-9) / 1e6:.1f} M sensor-suns/s)")
    print(f"hours of direct sun: min {result.hours.min():.1f}, mean {result.hours.mean():.1f}, max {result.hours.max():.1f}")
    print("wrote " + ", ".join(str(path.resolve()) for path in paths))
    return 0


@contextlib.contextmanager
def _cluster_client(args):
    """None for a local run, else a Dask client: a LocalCluster of --workers, or --scheduler's."""
    if args.workers is None and args.scheduler is None:
        yield None
        return
    from .distributed import connect, local_cluster

    if args.scheduler is not None:
        with connect(args.scheduler) as client:
            yield client
        return
    with local_cluster(args.workers) as cluster, connect(cluster.scheduler_address) as client:
        yield client


def run_devices() -> int:
    from .device import list_devices

    for selector, description, _ in list_devices():
        print(f"{selector}  {description}")
    return 0


def run_methods() -> int:
    from .methods import methods

    for name, parameters in methods().items():
        print(name)
        for parameter, (default, description) in parameters.items():
            print(f"  {parameter} = {default!r}: {description}")
    return 0


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        if args.command == "render":
            return run_render(args)
        if args.command == "sun-hours":
            return run_sun_hours(args)
        if args.command == "devices":
            return run_devices()
        return run_methods()
    except (ValueError, TypeError, OSError, RuntimeError, MemoryError, ImportError) as error:   # ImportError: a missing extra, named
        # one line, even for a message that lists things (the devices, say) on lines of its own
        message = "; ".join(line.strip() for line in str(error).splitlines() if line.strip()).replace(":; ", ": ")
        print(f"shadowcl: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
