"""The ``shadowcl`` command: ``render`` a scene to PNG, list ``devices`` and ``methods``."""

from __future__ import annotations

import argparse
import ast
import os
import re
import sys
import time
from pathlib import Path

from . import scenes as _scene_package

DEFAULT_SCENE = Path(_scene_package.__file__).resolve().parent / "default.toml"


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
    print("times: " + ", ".join(f"{name} {seconds * 1e3:.1f} ms" for name, seconds in [("load", load_time), *result.timings.items()]))
    print(f"wrote {out.resolve()}")
    return 0


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
        if args.command == "devices":
            return run_devices()
        return run_methods()
    except (ValueError, TypeError, OSError, RuntimeError, MemoryError) as error:
        # one line, even for a message that lists things (the devices, say) on lines of its own
        message = "; ".join(line.strip() for line in str(error).splitlines() if line.strip()).replace(":; ", ": ")
        print(f"shadowcl: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
