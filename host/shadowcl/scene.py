"""Scenes: named objects (triangle meshes), lights and a camera, built in code or read from TOML.

In code: ``Scene([(name, mesh), ...], [light, ...], camera=None, name=..., colors=None, render_size=None)``;
from a file: ``Scene.load("scenes/default.toml")``.

Scene file format (TOML; y is up; lengths in scene units, angles in degrees)::

    name = "demo"                      # optional; default: the file name without .toml
    [render]                           # optional default image size for renderers
    width = 960
    height = 540

    [camera]                           # optional; default: default_camera(), fitted to the scene
    position = [6, 4, 8]
    target = [0, 0.5, 0]
    up = [0, 1, 0]                     # optional, default [0, 1, 0]
    fov = 45                           # optional vertical field of view, default 45

    [[lights]]                         # at least one; lights[0] is scene.light
    type = "point"
    position = [-4, 8, 3]
    [[lights]]
    type = "directional"
    direction = [1, -2, 0]             # the direction the light travels

    [[objects]]                        # at least one: a shape table plus name and color
    name = "ground"                    # optional; default: the mesh file's stem or the shape key
    color = [0.8, 0.8, 0.8]            # optional linear RGB in [0, 1]; default: a palette colour
    box = { size = [20, 0.2, 20], center = true }
    translate = [0, -0.1, 0]

A shape table holds exactly one shape key, and optionally ``scale`` (a number or three),
``rotate`` (degrees about the world x, then y, then z axis) and ``translate``, applied in that order:
scale, rotate, translate. The shape keys (primitive parameters are optional, defaults shown)::

    sphere = { radius = 1, segments = 32 }            # segments round up to a multiple of 4, at most 2048
    box = { size = [1, 1, 1], center = false }        # size may be one number; corner at the origin
    cylinder = { height = 1, radius = 1, radius_top = 1, segments = 32, center = false }   # segments <= 524289
                                                      # along z from z = 0; radius_top defaults to
                                                      # radius, 0 makes a cone; stand it up along y
                                                      # with rotate = [-90, 0, 0]
    union = [shape, ...]                              # CSG: each item is a shape table (primitive
    difference = [shape, minus, ...]                  # or CSG, with its own transforms); TOML's
    intersection = [shape, ...]                       # [[objects.union]] tables work too; nested at
                                                      # most 64 deep
    mesh = "models/bunny.obj"                         # OBJ/PLY/STL/OFF, relative to the scene file
                                                      # (~ and absolute paths allowed)
    triangles = { vertices = [[x, y, z], ...], faces = [[i, j, k], ...] }
    subdivision = "models/cage.obj"                   # a Catmull-Clark control mesh (OBJ, any polygons)
    subdivision = { vertices = [[x, y, z], ...], faces = [[i, j, k, l], ...] }   # inline control mesh
    tessellation = 8                                  # subdivision only: segments per control edge
                                                      # (default: SubdivisionSurface.default_segments;
                                                      # at most MAX_TESSELLATION_CELLS cells)

For sun-hours studies (``shadowcl sun-hours``, :mod:`shadowcl.sun`), optionally::

    [sun]                              # the site and the period: Scene.sun, a dict of these keys
    latitude = 48.85                   # degrees, within ±90 (north positive)
    longitude = 2.35                   # degrees, within ±180 (east positive)
    start = "2026-01-01"               # a TOML date or datetime, or a string pandas reads
    end = "2027-01-01"                 # excluded
    step = "1h"                        # a pandas time step
    timezone = "UTC"                   # of start and end when they carry none (optional, default UTC)
    north = [0, 0, -1]                 # the scene's north (optional, default -z; up is +y)

    [[sensors]]                        # grids of sensor points: Scene.sensors, a list of dicts
    name = "roofs"
    objects = ["tower", "hall"]        # names of objects whose upward-facing triangles carry the grid
    spacing = 1.0                      # grid step in scene units (a square grid seen from above)
    offset = 0.01                      # along the face's normal (optional, default 0.01)

A ``subdivision`` object is a :class:`~shadowcl.subdivision.SubdivisionSurface` (its transform applied
to the control points, which moves the limit surface exactly); it is listed in :attr:`Scene.surfaces`
and its tessellation is its mesh in :attr:`Scene.objects`, so every triangle method works unchanged. In
code, an object may also be ``(name, surface)`` or ``(name, surface, segments)``.

Primitives and CSG go through manifold3d, so they are closed and manifold. ``mesh`` files and inline
``triangles`` are kept as written (degenerate, duplicated, open or non-manifold triangles included)
and cannot be used inside CSG. Mesh files are transformed in float64; every object is stored float32.

Without ``[camera]``, :func:`default_camera` looks at the centre of the scene's bounding box from the
front-right and above, far enough to see the whole box. Every error raises ``ValueError``,
``TypeError`` or ``FileNotFoundError`` naming the scene file and the key path, e.g.
``scenes/x.toml: objects[2].mesh: no such file /data/bunny.obj``; unknown keys are rejected with the
list of allowed keys.
"""

from __future__ import annotations

import datetime
import operator
import tomllib
from contextlib import contextmanager
from functools import cached_property, reduce
from pathlib import Path

import numpy as np
from manifold3d import Manifold

from .checks import positive_int, vector3
from .geometry import Mesh, bounds_diagonal
from .lights import DirectionalLight, PointLight
from .meshio import path_argument
from .subdivision import SubdivisionSurface
from .views import Camera

DEFAULT_SEGMENTS = 32
# Most triangles one sphere or cylinder may have: manifold3d's 2048-segment sphere (2,097,152 triangles)
# took 5 s and 0.8 GB here; 2e9 segments crash it. A sphere of n segments has n^2 / 2 triangles, a
# cylinder 4 n - 4.
MAX_PRIMITIVE_TRIANGLES = 1 << 21
MAX_SPHERE_SEGMENTS = int(np.sqrt(2 * MAX_PRIMITIVE_TRIANGLES))
MAX_CYLINDER_SEGMENTS = (MAX_PRIMITIVE_TRIANGLES + 4) // 4
# ... and all of a scene file's primitives together (CSG keeps its operands until it combines them).
MAX_SCENE_PRIMITIVE_TRIANGLES = 1 << 23
# Largest image side a scene may ask renderers for (render.MAX_SIDE is this).
MAX_RENDER_SIDE = 16384
# Deepest CSG nesting read from a file: far beyond any real scene, well within Python's recursion limit.
MAX_CSG_DEPTH = 64
DEFAULT_FOV = 45.0
# From the scene's centre towards the default camera: to the right (+x), above (+y), in front (+z).
DEFAULT_VIEW_DIRECTION = (1.0, 0.8, 1.4)
# Linear RGB for objects without a colour, by object index.
PALETTE = np.array(
    [
        [0.80, 0.80, 0.78],
        [0.80, 0.30, 0.25],
        [0.25, 0.50, 0.80],
        [0.35, 0.70, 0.35],
        [0.90, 0.70, 0.25],
        [0.60, 0.40, 0.75],
    ]
)

__all__ = ["Scene", "default_camera"]


class Scene:
    """Objects, lights and a camera: what a renderer or a shadow method needs.

    Attributes:
        objects: list of ``(name, Mesh)``, in file order.
        surfaces: list of ``(name, SubdivisionSurface)`` (world coordinates) of the subdivision objects;
            each one's tessellation is its entry in ``objects``.
        colors: (objects, 3) float64 linear RGB of each object.
        mesh: all objects concatenated into one :class:`Mesh` (object order, then face order).
        lights: list of :class:`PointLight` / :class:`DirectionalLight`, at least one.
        light: the first light.
        camera: a :class:`Camera` (:func:`default_camera` when none was given).
        bounds: (2, 3) float64 bounding box of ``mesh`` (lights not included).
        name: a short name (the file name without ``.toml`` for a loaded scene).
        render_size: ``(width, height)`` a renderer should use by default, or None.
        path: the scene file, or None for a scene built in code.
    """

    sun: dict | None = None     # a scene file's [sun] table, checked (module docstring)
    sensors: tuple = ()         # its [[sensors]] tables, checked: dicts of name, objects, spacing, offset

    def __init__(self, objects, lights, camera=None, name="scene", colors=None, render_size=None, path=None):
        """``objects`` is a list of ``(name, Mesh)``, ``(name, SubdivisionSurface)`` or
        ``(name, SubdivisionSurface, segments)``; ``colors`` optionally one RGB (or None) each."""
        objects, self.surfaces = _tessellated(objects)
        self.objects = _checked_objects(objects)
        self.colors = _object_colors(colors, len(self.objects))
        self.lights = _checked_lights(lights)
        self.mesh = Mesh.concatenate([mesh for _, mesh in self.objects])
        self.bounds = self.mesh.bounds
        if camera is not None and not isinstance(camera, Camera):
            raise TypeError(f"camera: expected a Camera or None, got {type(camera).__name__}")
        self.camera = default_camera(self.bounds) if camera is None else camera
        if not isinstance(name, str):
            raise TypeError(f"name: expected a string, got {type(name).__name__}")
        self.name = name
        self.render_size = None if render_size is None else _checked_size(render_size)
        self.path = None if path is None else Path(path)

    @classmethod
    def load(cls, path) -> "Scene":
        """Read a scene file (format in the module docstring); errors name the file and key path."""
        path = path_argument("path", path)
        with _located(str(path)):
            if not path.is_file():
                raise FileNotFoundError("no such scene file")
            try:
                data = path.read_bytes()
            except OSError as error:
                raise ValueError(f"cannot be read ({error.strerror})") from None
            try:
                document = tomllib.loads(data.decode("utf-8"))
            except UnicodeDecodeError as error:
                raise ValueError(f"not UTF-8 text (TOML must be): byte {error.start}") from None
            except RecursionError:
                raise ValueError("arrays or inline tables nested too deep for the TOML parser") from None
            return _read_scene(_Table(document, ""), path)

    @property
    def light(self):
        """The first light."""
        return self.lights[0]

    def object_ids(self) -> np.ndarray:
        """(F,) int32: the index in :attr:`objects` of each triangle of :attr:`mesh`."""
        counts = [len(mesh.faces) for _, mesh in self.objects]
        return np.repeat(np.arange(len(counts), dtype=np.int32), counts)

    @cached_property
    def triangle_colors(self) -> np.ndarray:
        """(F, 3) float64 linear RGB of each triangle of :attr:`mesh` (its object's colour)."""
        return self.colors[self.object_ids()]

    def __repr__(self) -> str:
        names = ", ".join(name for name, _ in self.objects)
        return f"Scene({self.name!r}: {len(self.mesh.faces)} triangles in [{names}], {len(self.lights)} light(s))"


def default_camera(bounds: np.ndarray, fov: float = DEFAULT_FOV) -> Camera:
    """A camera aimed at the centre of ``bounds`` from ``DEFAULT_VIEW_DIRECTION``, seeing all of them.

    Its distance fits the bounding sphere of ``bounds`` in the vertical field of view ``fov``.
    """
    centre = np.mean(bounds, axis=0)
    radius = bounds_diagonal(bounds) / 2 or 1.0  # a scene that is a single point: frame a unit ball
    distance = radius / np.sin(np.radians(fov) / 2)
    direction = np.array(DEFAULT_VIEW_DIRECTION) / np.linalg.norm(DEFAULT_VIEW_DIRECTION)
    return Camera(centre + distance * direction, centre, fov=fov)


# ---- checks of the Scene constructor's arguments ----


def _checked_objects(objects) -> list[tuple[str, Mesh]]:
    if not isinstance(objects, (list, tuple)):
        raise TypeError(f"objects: expected a list of (name, Mesh) pairs, got {type(objects).__name__}")
    if not objects:
        raise ValueError("objects: a scene needs at least one object")
    for index, item in enumerate(objects):
        if not (isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], str) and isinstance(item[1], Mesh)):
            raise TypeError(f"objects[{index}]: expected a (name, Mesh) pair, got {item!r}")
    return list(objects)


def _tessellated(objects) -> tuple:
    """(objects with each subdivision surface replaced by its tessellation, [(name, surface), ...])."""
    if not isinstance(objects, (list, tuple)):
        return objects, []  # _checked_objects names the error
    out, surfaces = [], []
    for index, item in enumerate(objects):
        if isinstance(item, tuple) and len(item) in (2, 3) and isinstance(item[1], SubdivisionSurface):
            with _located(f"objects[{index}]"):   # e.g. too many segments for the control mesh
                if len(item) == 3 and item[2] is not None:
                    mesh = item[1].tessellate(segments=positive_int("segments", item[2]))
                else:
                    mesh = item[1].tessellate()
            surfaces.append((item[0], item[1]))
            item = (item[0], mesh)
        out.append(item)
    return out, surfaces


def _checked_lights(lights) -> list:
    if not isinstance(lights, (list, tuple)):
        raise TypeError(f"lights: expected a list of lights, got {type(lights).__name__}")
    if not lights:
        raise ValueError("lights: a scene needs at least one light ([[lights]] in a scene file)")
    for index, light in enumerate(lights):
        if not isinstance(light, (PointLight, DirectionalLight)):
            raise TypeError(f"lights[{index}]: expected a PointLight or DirectionalLight, got {type(light).__name__}")
    return list(lights)


def _object_colors(colors, count: int) -> np.ndarray:
    """(count, 3) float64: the given colours, palette colours where none (or None) is given."""
    if colors is None:
        colors = [None] * count
    if len(colors) != count:
        raise ValueError(f"colors: expected one colour (or None) per object ({count}), got {len(colors)}")
    rows = []
    for index, color in enumerate(colors):
        rows.append(PALETTE[index % len(PALETTE)] if color is None else _rgb(f"colors[{index}]", color))
    return np.array(rows, dtype=np.float64)


def _rgb(name: str, value) -> np.ndarray:
    rgb = vector3(name, value)
    if not np.all((rgb >= 0) & (rgb <= 1)):
        raise ValueError(f"{name}: expected RGB components in [0, 1], got {rgb.tolist()}")
    return rgb


def _checked_size(size) -> tuple[int, int]:
    if not (isinstance(size, (list, tuple)) and len(size) == 2):
        raise TypeError(f"render_size: expected (width, height), got {size!r}")
    return (positive_int("render_size[0]", size[0], maximum=MAX_RENDER_SIDE),
            positive_int("render_size[1]", size[1], maximum=MAX_RENDER_SIDE))


# ---- reading scene files ----


@contextmanager
def _located(where: str):
    """Re-raise a ValueError, TypeError or FileNotFoundError from the block with ``where: `` in front."""
    try:
        yield
    except (FileNotFoundError, TypeError, ValueError) as error:
        for kind in (FileNotFoundError, TypeError, ValueError):
            if isinstance(error, kind):
                raise kind(f"{where}: {error}") from error


def _toml_type(value) -> str:
    names = {dict: "a table", list: "an array", str: "a string", bool: "a boolean", int: "an integer", float: "a float"}
    return names.get(type(value), type(value).__name__)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


_REQUIRED = object()  # default of a key that must be present


class _Table:
    """A TOML table and its key path; values are read with checks whose errors name the key path."""

    def __init__(self, data, where: str):
        if not isinstance(data, dict):
            raise TypeError(f"{where}: expected a table, got {_toml_type(data)}")
        self.data = data
        self.where = where

    def path(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def invalid(self, key: str, message: str) -> ValueError:
        return ValueError(f"{self.path(key)}: {message}")

    def allow_only(self, allowed) -> None:
        for key in self.data:
            if key not in allowed:
                raise self.invalid(key, f"unknown key; allowed here: {', '.join(allowed)}")

    def _absent(self, key: str, default) -> bool:
        """True when ``key`` is missing and has a default; missing without one is an error."""
        if key in self.data:
            return False
        if default is _REQUIRED:
            raise self.invalid(key, "missing")
        return True

    def raw(self, key: str):
        """The value at ``key``, unchecked; it must be present."""
        self._absent(key, _REQUIRED)
        return self.data[key]

    def number(self, key: str, default=_REQUIRED, positive: bool = False) -> float:
        if self._absent(key, default):
            return default
        value = self.data[key]
        if not _is_number(value):
            raise TypeError(f"{self.path(key)}: expected a number, got {_toml_type(value)}")
        if not np.isfinite(value):
            raise self.invalid(key, f"must be finite, got {value}")
        if positive and not value > 0:
            raise self.invalid(key, f"must be positive, got {value}")
        return float(value)

    def integer(self, key: str, default=_REQUIRED, minimum: int = 1, maximum: int | None = None) -> int:
        if self._absent(key, default):
            return default
        value = self.data[key]
        if not isinstance(value, int) or isinstance(value, bool):
            raise TypeError(f"{self.path(key)}: expected an integer, got {_toml_type(value)}")
        return positive_int(self.path(key), value, minimum=minimum, maximum=maximum)

    def flag(self, key: str, default=_REQUIRED) -> bool:
        return self._typed(key, default, bool, "true or false")

    def text(self, key: str, default=_REQUIRED) -> str:
        return self._typed(key, default, str, "a string")

    def _typed(self, key: str, default, kind: type, expected: str):
        """The value of ``key`` if it is a ``kind`` (``default`` when absent and allowed)."""
        if self._absent(key, default):
            return default
        value = self.data[key]
        if not isinstance(value, kind):
            raise TypeError(f"{self.path(key)}: expected {expected}, got {_toml_type(value)}")
        return value

    def vector(self, key: str, default=_REQUIRED, nonzero: bool = False, scalar_ok: bool = False) -> np.ndarray:
        """Three finite numbers as float64 (one number means three equal ones when ``scalar_ok``)."""
        if self._absent(key, default):
            return np.array(default, dtype=np.float64)
        value = self.data[key]
        if scalar_ok and _is_number(value):
            value = [value] * 3
        if not (isinstance(value, list) and all(_is_number(item) for item in value)):
            expected = "a number or an array of three numbers" if scalar_ok else "an array of three numbers"
            raise TypeError(f"{self.path(key)}: expected {expected}, got {value!r}")
        return vector3(self.path(key), value, nonzero=nonzero)

    def table(self, key: str, default=_REQUIRED) -> "_Table | None":
        return default if self._absent(key, default) else _Table(self.data[key], self.path(key))

    def tables(self, key: str) -> "list[_Table]":
        """The array of tables at ``key`` (empty when absent)."""
        items = self.data.get(key, [])
        if not isinstance(items, list):
            raise TypeError(f"{self.path(key)}: expected an array of tables, got {_toml_type(items)}")
        return [_Table(item, f"{self.path(key)}[{index}]") for index, item in enumerate(items)]


def _sphere(params: _Table):
    params.allow_only(("radius", "segments"))
    radius = params.number("radius", 1.0, positive=True)
    return Manifold.sphere(radius, params.integer("segments", DEFAULT_SEGMENTS, minimum=3, maximum=MAX_SPHERE_SEGMENTS))


def _box(params: _Table):
    params.allow_only(("size", "center"))
    size = params.vector("size", (1.0, 1.0, 1.0), scalar_ok=True)
    if not np.all(size > 0):
        raise params.invalid("size", f"must be positive, got {size.tolist()}")
    return Manifold.cube(tuple(size), params.flag("center", False))


def _cylinder(params: _Table):
    params.allow_only(("height", "radius", "radius_top", "segments", "center"))
    radius = params.number("radius", 1.0, positive=True)
    radius_top = params.number("radius_top", radius)
    if radius_top < 0:
        raise params.invalid("radius_top", f"must not be negative, got {radius_top}")
    return Manifold.cylinder(
        params.number("height", 1.0, positive=True),
        radius,
        radius_top,
        params.integer("segments", DEFAULT_SEGMENTS, minimum=3, maximum=MAX_CYLINDER_SEGMENTS),
        params.flag("center", False),
    )


PRIMITIVES = {"sphere": _sphere, "box": _box, "cylinder": _cylinder}

CSG_OPERATORS = {"union": operator.add, "difference": operator.sub, "intersection": operator.xor}
RAW_KEYS = ("mesh", "triangles")  # shapes kept as written, never through manifold3d
SUBDIVISION_KEY = "subdivision"  # a Catmull-Clark control mesh, kept as a SubdivisionSurface
SHAPE_KEYS = tuple(PRIMITIVES) + tuple(CSG_OPERATORS) + RAW_KEYS + (SUBDIVISION_KEY,)
TRANSFORM_KEYS = ("scale", "rotate", "translate")
OBJECT_KEYS = ("name", "color") + SHAPE_KEYS + TRANSFORM_KEYS + ("tessellation",)
SCENE_KEYS = ("name", "render", "camera", "lights", "objects", "sun", "sensors")
SUN_KEYS = ("latitude", "longitude", "start", "end", "step", "timezone", "north")
SENSOR_KEYS = ("name", "objects", "spacing", "offset")


def _read_scene(root: _Table, path: Path) -> Scene:
    root.allow_only(SCENE_KEYS)
    triangles = _primitive_triangles(root.data.get("objects"))
    if triangles > MAX_SCENE_PRIMITIVE_TRIANGLES:
        raise root.invalid("objects", f"the spheres and cylinders would make about {triangles:,} triangles; "
                                      f"at most {MAX_SCENE_PRIMITIVE_TRIANGLES:,} in one scene")
    objects, colors = [], []
    for table in root.tables("objects"):
        name, shape, color = _read_object(table, path.parent)
        objects.append((name,) + (shape if isinstance(shape, tuple) else (shape,)))
        colors.append(color)
    camera = root.table("camera", None)
    render = root.table("render", None)
    scene = Scene(
        objects,
        [_read_light(table) for table in root.tables("lights")],
        camera=None if camera is None else _read_camera(camera),
        name=root.text("name", path.stem),
        colors=colors,
        render_size=None if render is None else _read_render_size(render),
        path=path,
    )
    sun = root.table("sun", None)
    scene.sun = None if sun is None else _read_sun(sun)
    names = [name for name, _ in scene.objects]
    scene.sensors = tuple(_read_sensors(table, names) for table in root.tables("sensors"))
    return scene


def _read_sun(table: _Table) -> dict:
    table.allow_only(SUN_KEYS)
    sun = {"latitude": table.number("latitude"), "longitude": table.number("longitude")}
    for key, limit in (("latitude", 90), ("longitude", 180)):
        if abs(sun[key]) > limit:
            raise table.invalid(key, f"must be within ±{limit} degrees, got {sun[key]}")
    for key in ("start", "end"):
        value = table.raw(key)
        if not isinstance(value, (str, datetime.date)):
            raise TypeError(f"{table.path(key)}: expected a date, a datetime or a string, got {_toml_type(value)}")
        sun[key] = value
    sun["step"] = table.text("step", "1h")
    sun["timezone"] = table.text("timezone", "UTC")
    sun["north"] = table.vector("north", (0.0, 0.0, -1.0), nonzero=True)
    return sun


def _read_sensors(table: _Table, object_names: list) -> dict:
    table.allow_only(SENSOR_KEYS)
    objects = table.raw("objects")
    if not (isinstance(objects, list) and objects and all(isinstance(name, str) for name in objects)):
        raise TypeError(f"{table.path('objects')}: expected a non-empty array of object names, got {objects!r}")
    unknown = sorted(set(objects) - set(object_names))
    if unknown:
        raise table.invalid("objects", f"no object named {', '.join(unknown)}; objects: {', '.join(object_names)}")
    offset = table.number("offset", 0.01)
    if offset < 0:
        raise table.invalid("offset", f"must not be negative, got {offset}")
    return {"name": table.text("name", "sensors"), "objects": objects,
            "spacing": table.number("spacing", positive=True), "offset": offset}


def _primitive_triangles(value) -> int:
    """Triangles the spheres and cylinders anywhere in a TOML value would make, counted before any is
    built; a bad ``segments`` counts nothing here (reading the shape names it)."""
    total, stack = 0, [value]
    while stack:   # a loop, not recursion: [[objects.union.union...]] tables nest without bound
        item = stack.pop()
        if isinstance(item, list):
            stack.extend(item)
        elif isinstance(item, dict):
            for key, inner in item.items():
                segments = inner.get("segments", DEFAULT_SEGMENTS) if isinstance(inner, dict) else None
                limit = {"sphere": MAX_SPHERE_SEGMENTS, "cylinder": MAX_CYLINDER_SEGMENTS}.get(key, 0)
                if isinstance(segments, int) and 3 <= segments <= limit:
                    rounded = -(-segments // 4) * 4   # manifold3d rounds a sphere's segments up to a multiple of 4
                    total += rounded ** 2 // 2 if key == "sphere" else 4 * segments - 4
                else:
                    stack.append(inner)
    return total


def _read_camera(table: _Table) -> Camera:
    table.allow_only(("position", "target", "up", "fov"))
    position, target = table.vector("position"), table.vector("target")
    up, fov = table.vector("up", (0.0, 1.0, 0.0), nonzero=True), table.number("fov", DEFAULT_FOV, positive=True)
    with _located(table.where):  # a target at the eye, or up along the view
        return Camera(position, target, up, fov)


def _read_light(table: _Table):
    kind = table.text("type")
    if kind == "point":
        table.allow_only(("type", "position"))
        return PointLight(table.vector("position"))
    if kind == "directional":
        table.allow_only(("type", "direction"))
        return DirectionalLight(table.vector("direction", nonzero=True))
    raise table.invalid("type", f'expected "point" or "directional", got {kind!r}')


def _read_render_size(table: _Table) -> tuple[int, int]:
    table.allow_only(("width", "height"))
    return table.integer("width", maximum=MAX_RENDER_SIDE), table.integer("height", maximum=MAX_RENDER_SIDE)


def _read_object(table: _Table, base_dir: Path) -> tuple[str, "Mesh | tuple", np.ndarray | None]:
    """An object table: its name, its mesh (or (surface, segments)) and its colour (None when not given)."""
    table.allow_only(OBJECT_KEYS)
    kind = _shape_key(table)
    if kind == SUBDIVISION_KEY:
        mesh = (_subdivision(table, base_dir), table.integer("tessellation", None))
    elif "tessellation" in table.data:
        raise table.invalid("tessellation", "only allowed with a subdivision shape")
    else:
        mesh = _build_shape(table, kind, base_dir)
    named_by_file = kind == "mesh" or (kind == SUBDIVISION_KEY and isinstance(table.data[kind], str))
    default_name = Path(table.data[kind]).stem if named_by_file else kind
    color = _rgb(table.path("color"), table.vector("color")) if "color" in table.data else None
    return table.text("name", default_name), mesh, color


def _shape_key(table: _Table) -> str:
    """The one shape key of a shape table."""
    present = [key for key in SHAPE_KEYS if key in table.data]
    if len(present) != 1:
        found = f"found {', '.join(present)}" if present else "found none"
        raise ValueError(f"{table.where}: expected exactly one shape key of {', '.join(SHAPE_KEYS)}; {found}")
    return present[0]


def _build_shape(table: _Table, kind: str, base_dir: Path) -> Mesh:
    """The transformed mesh of a shape table whose shape key is ``kind``."""
    if kind == "mesh":
        mesh = _mesh_file(table, base_dir)
    elif kind == "triangles":
        mesh = _inline_triangles(table.table("triangles"))
    else:
        solid = _build_solid(table, kind)
        if solid.is_empty():
            raise ValueError(f"{table.where}: the shape is empty (manifold3d status: {solid.status().name})")
        result = solid.to_mesh64()
        with _located(table.where):   # e.g. a size beyond float32
            return Mesh(np.asarray(result.vert_properties)[:, :3], np.asarray(result.tri_verts))
    matrix = _transform_matrix(table)
    with _located(table.where):       # e.g. a scale that takes the mesh beyond float32
        return mesh.transformed(matrix)


def _mesh_file(table: _Table, base_dir: Path) -> Mesh:
    path = (base_dir / Path(table.text("mesh")).expanduser()).resolve()
    if not path.is_file():
        raise FileNotFoundError(f"{table.path('mesh')}: no such file {path}")
    with _located(table.path("mesh")):  # an unsupported format or an unreadable file
        return Mesh.load(path)


def _subdivision(table: _Table, base_dir: Path) -> SubdivisionSurface:
    """The transformed subdivision surface of an object table (an OBJ file or an inline control mesh)."""
    value = table.raw(SUBDIVISION_KEY)
    if isinstance(value, str):
        path = (base_dir / Path(value).expanduser()).resolve()
        if not path.is_file():
            raise FileNotFoundError(f"{table.path(SUBDIVISION_KEY)}: no such file {path}")
        with _located(table.path(SUBDIVISION_KEY)):
            surface = SubdivisionSurface.load(path)
    else:
        inline = table.table(SUBDIVISION_KEY)
        inline.allow_only(("vertices", "faces"))
        with _located(inline.where):
            surface = SubdivisionSurface(inline.raw("vertices"), inline.raw("faces"))
    return surface.transformed(_transform_matrix(table))


def _inline_triangles(table: _Table) -> Mesh:
    table.allow_only(("vertices", "faces"))
    vertices, faces = table.raw("vertices"), table.raw("faces")
    with _located(table.where):
        return Mesh(vertices, faces)


def _build_solid(table: _Table, kind: str, depth: int = 0):
    """The transformed manifold3d solid of a primitive or CSG shape table ``depth`` CSG levels down."""
    if kind in PRIMITIVES:
        solid = PRIMITIVES[kind](table.table(kind))
    elif kind in CSG_OPERATORS:
        if depth >= MAX_CSG_DEPTH:
            raise table.invalid(kind, f"CSG nested more than {MAX_CSG_DEPTH} deep")
        solid = _combine(table, kind, depth + 1)
    else:
        raise table.invalid(
            kind, "inline triangles, mesh files and subdivision surfaces cannot be used in CSG "
            "(they need not be closed)"
        )
    return solid.transform(_transform_matrix(table)[:3])


def _combine(table: _Table, operation: str, depth: int):
    items = table.tables(operation)
    if not items:
        raise table.invalid(operation, "expected at least one shape table")
    solids = []
    for item in items:
        item.allow_only(SHAPE_KEYS + TRANSFORM_KEYS)
        solids.append(_build_solid(item, _shape_key(item), depth))
    return reduce(CSG_OPERATORS[operation], solids)


def _transform_matrix(table: _Table) -> np.ndarray:
    """4x4 float64 affine map of a shape table's scale, then rotate, then translate."""
    scale = table.vector("scale", (1.0, 1.0, 1.0), scalar_ok=True)
    if not np.all(scale != 0):
        raise table.invalid("scale", f"must not be zero, got {scale.tolist()}")
    x, y, z = table.vector("rotate", (0.0, 0.0, 0.0))
    matrix = np.eye(4)
    matrix[:3, :3] = _axis_rotation(2, z) @ _axis_rotation(1, y) @ _axis_rotation(0, x) @ np.diag(scale)
    matrix[:3, 3] = table.vector("translate", (0.0, 0.0, 0.0))
    return matrix


def _axis_rotation(axis: int, degrees: float) -> np.ndarray:
    """3x3 rotation by ``degrees`` about coordinate axis ``axis`` (right-handed)."""
    cos, sin = _cos_sin(degrees)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]  # the plane it turns, in the positive sense
    rotation = np.eye(3)
    rotation[[i, i, j, j], [i, j, i, j]] = cos, -sin, sin, cos
    return rotation


def _cos_sin(degrees: float) -> tuple[float, float]:
    """Cosine and sine, exact for multiples of 90 degrees so turned boxes stay exactly on the floor."""
    quarter_turns, rest = divmod(degrees, 90.0)
    if rest == 0:
        return [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0)][int(quarter_turns) % 4]
    return float(np.cos(np.radians(degrees))), float(np.sin(np.radians(degrees)))
