"""Bench scenes and their receivers: deterministic (seeded) points with normals.

A model scene is a real mesh from ``../shared/models`` standing on a ground quad under a point light.
Its receivers are points on the ground around the model (uniform in a square three times the model's
footprint, normal up) and points on the model's surface (area-weighted, face normals). Any other scene
gets area-weighted points on all of its triangles.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shadowcl import Mesh, PointLight

PROJECT = Path(__file__).resolve().parents[1]
MODELS = PROJECT.parent / "shared" / "models"
MODEL_FILES = {"bunny": "stanford-bunny.obj", "ogre": "ogre.obj", "teapot": "teapot.obj"}
GROUND_MARGIN = 3.0  # the ground square's side as a multiple of the model's footprint
LIGHT_OFFSET = (1.5, 2.0, 1.0)  # built-in point light, in model sizes from the model's base centre


@dataclass
class BenchScene:
    """Occluders (``mesh``, ground included), lights, and for model scenes the model and ground parts."""

    name: str
    mesh: Mesh
    lights: list
    source: str  # where the scene came from, for the report
    model: Mesh | None = None  # the model's triangles (model scenes only)
    ground_y: float | None = None  # height of the ground's top (model scenes only)


def ground_quad(center_xz, side: float, y: float) -> Mesh:
    """A two-triangle square of ``side`` centred on ``center_xz`` at height ``y``, facing up (+y)."""
    cx, cz = center_xz
    h = side / 2
    vertices = [(cx - h, y, cz - h), (cx + h, y, cz - h), (cx + h, y, cz + h), (cx - h, y, cz + h)]
    return Mesh(vertices, [(0, 2, 1), (0, 3, 2)])


def footprint(model: Mesh) -> tuple[np.ndarray, float]:
    """Centre (x, z) and side of the square around the model's footprint, scaled by ``GROUND_MARGIN``."""
    low, high = model.bounds
    return (low[[0, 2]] + high[[0, 2]]) / 2, GROUND_MARGIN * float(max(high[0] - low[0], high[2] - low[2]))


def outward(model: Mesh) -> Mesh:
    """``model`` with its winding flipped if its signed volume is negative (so face normals point out)."""
    tri = model.triangles
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()
    return model if volume >= 0 else Mesh(model.vertices, model.faces[:, ::-1])


def model_scene(name: str, model: Mesh, source: str = "built in code") -> BenchScene:
    """``model`` scaled to unit size, centred on x = z = 0 and standing on a ground quad at y = 0,
    under a point light above and to the side."""
    low, high = model.bounds
    scale = 1.0 / float(np.max(high - low))
    matrix = np.eye(4)
    matrix[:3, :3] *= scale
    matrix[:3, 3] = -scale * np.array([(low[0] + high[0]) / 2, low[1], (low[2] + high[2]) / 2])
    model = outward(model.transformed(matrix))
    center, side = footprint(model)
    mesh = Mesh.concatenate([model, ground_quad(center, side, 0.0)])
    return BenchScene(name, mesh, [PointLight(LIGHT_OFFSET)], source, model, 0.0)


def split_ground(mesh: Mesh) -> tuple[Mesh, float]:
    """The model part of a model-on-ground ``mesh`` and the ground's top height.

    Ground triangles are the ones spanning at least half of the scene's horizontal size: a quad or a
    thin box under the model is made of such triangles, and the model, standing on a ground larger
    than itself, has none.
    """
    tri = mesh.triangles
    span = np.ptp(tri[:, :, [0, 2]], axis=1).max(axis=1)
    scene_span = float(np.ptp(mesh.vertices[:, [0, 2]], axis=0).max())
    is_ground = span >= 0.5 * scene_span
    if not is_ground.any() or is_ground.all():
        raise ValueError(f"scene: cannot tell the ground from the model ({int(is_ground.sum())} ground triangles)")
    return Mesh(mesh.vertices, mesh.faces[~is_ground]), float(tri[is_ground][:, :, 1].max())


def load_scene(name_or_path: str) -> BenchScene:
    """A bench scene: a model name (``bunny``, ``ogre``, ``teapot``) or a scene file path (``.toml``).

    A model name uses ``scenes/models/NAME.toml`` when that file and ``shadowcl.scene`` exist, else
    builds the scene in code from ``../shared/models``.
    """
    if name_or_path in MODEL_FILES:
        toml = PROJECT / "scenes" / "models" / f"{name_or_path}.toml"
        try:
            from shadowcl.scene import Scene
        except ImportError:
            Scene = None
        if Scene is None or not toml.is_file():
            return model_scene(name_or_path, Mesh.load(MODELS / MODEL_FILES[name_or_path]))
        scene = Scene.load(toml)
        model, ground_y = split_ground(scene.mesh)
        source = str(toml.relative_to(PROJECT))
        return BenchScene(name_or_path, scene.mesh, list(scene.lights), source, outward(model), ground_y)
    path = Path(name_or_path)
    if path.suffix != ".toml":
        raise ValueError(f"scene: expected one of {sorted(MODEL_FILES)} or a .toml path, got {name_or_path!r}")
    from shadowcl.scene import Scene

    scene = Scene.load(path)
    return BenchScene(path.stem, scene.mesh, list(scene.lights), str(path))


def sample_triangles(mesh: Mesh, count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points uniform on the surface of ``mesh`` (area-weighted) and their face normals."""
    tri = mesh.triangles
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    face = rng.choice(len(tri), size=count, p=area / area.sum())
    r1, r2 = np.sqrt(rng.random(count))[:, None], rng.random(count)[:, None]
    t = tri[face]
    points = (1 - r1) * t[:, 0] + r1 * (1 - r2) * t[:, 1] + r1 * r2 * t[:, 2]
    return points, mesh.face_normals[face]


def sample_ground(scene: BenchScene, count: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points uniform in the square around the model's footprint on the ground, normal up."""
    center, side = footprint(scene.model)
    xz = center + (rng.random((count, 2)) - 0.5) * side
    points = np.column_stack([xz[:, 0], np.full(count, scene.ground_y), xz[:, 1]])
    return points, np.broadcast_to([0.0, 1.0, 0.0], points.shape).copy()


def receivers(scene: BenchScene, ground: int, model: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) float64 points and unit normals: ``ground`` on the ground and ``model`` on the model for a
    model scene; ``ground + model`` on all triangles otherwise. The same seed gives the same points."""
    rng = np.random.default_rng(seed)
    if scene.model is None:
        return sample_triangles(scene.mesh, ground + model, rng)
    on_ground, on_model = sample_ground(scene, ground, rng), sample_triangles(scene.model, model, rng)
    return np.concatenate([on_ground[0], on_model[0]]), np.concatenate([on_ground[1], on_model[1]])
