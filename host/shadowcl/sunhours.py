"""Direct sun hours on a scene's sensor grids: the study behind ``shadowcl sun-hours``.

Each sun position above the horizon stands for one time step (``step`` hours); a sensor gets the step's
hours when the sun reaches it (not in shadow: the exact method with the sensors' normals, so a face
turned away from the sun gets none). Written as ``.npy`` (hours, one per sensor), ``.csv`` (grid, x, y,
z, hours, the same order) and a heat map seen from above (:func:`heat_map`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .counts import shadow_counts
from .sensors import scene_sensors
from .sun import NORTH, UP, sun_angles, light_directions
from .lights import DirectionalLight

HEAT_MAP_PIXELS = 1600   # the heat map's longer side at most, in pixels


@dataclass(frozen=True)
class SunHours:
    """A study's result: per sensor ``hours`` (N,) float64, its ``points`` (N, 3) and the ``grid``
    name of each (N,); ``steps`` sun-up time steps of ``step_hours`` each; the scene's ``north``
    (for the heat map's orientation)."""

    points: np.ndarray
    grid: np.ndarray
    hours: np.ndarray
    steps: int
    step_hours: float
    north: tuple = NORTH


def sun_hours(scene, latitude, longitude, start, end, step="1h", timezone="UTC", north=NORTH, spacing=None,
              method="exact", client=None, progress=False, **params) -> SunHours:
    """Hours of direct sun on ``scene``'s sensor grids (its ``[[sensors]]``; ``spacing`` overrides
    theirs) from ``start`` to ``end`` every ``step`` at the site (:func:`shadowcl.sun.sun_lights`)."""
    grids = scene_sensors(scene, spacing)
    points = np.concatenate([g.points for g in grids])
    normals = np.concatenate([g.normals for g in grids])
    names = np.concatenate([np.full(len(g.points), g.name) for g in grids])
    if len(points) == 0:
        raise ValueError(f"scene {scene.name!r}: its [[sensors]] grids hold no point (no upward-facing faces "
                         f"under the lattice)")
    elevation, azimuth = sun_angles(latitude, longitude, None, start, end, step, timezone)
    import pandas as pd   # after sun_angles, whose ImportError names the extra

    step_hours = pd.Timedelta(step) / pd.Timedelta("1h")
    if len(elevation) == 0:
        return SunHours(points, names, np.zeros(len(points)), 0, step_hours, tuple(north))
    suns = [DirectionalLight(d) for d in light_directions(elevation, azimuth, UP, north)]
    shadowed = shadow_counts(scene, suns, points, normals, method=method, client=client, progress=progress,
                             weights=np.full(len(suns), step_hours), **params)
    return SunHours(points, names, len(suns) * step_hours - shadowed, len(suns), step_hours, tuple(north))


def write(result: SunHours, png: Path) -> list[Path]:
    """The ``.npy``, ``.csv`` and heat-map ``.png`` of ``result`` beside ``png``; their paths."""
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    npy, csv = png.with_suffix(".npy"), png.with_suffix(".csv")
    np.save(npy, result.hours)
    with csv.open("w") as file:
        file.write("grid,x,y,z,hours\n")
        for name, (x, y, z), hours in zip(result.grid, result.points, result.hours):
            file.write(f"{name},{x:.6g},{y:.6g},{z:.6g},{hours:.17g}\n")
    heat_map(result.points, result.hours, png, f"direct sun hours over {result.steps} sun-up steps", north=result.north)
    return [npy, csv, png]


def heat_map(points: np.ndarray, hours: np.ndarray, path: Path, title: str, up=UP, north=NORTH) -> None:
    """A PNG of ``hours`` seen from above, the scene's ``north`` (made perpendicular to ``up``) up and
    east right: each pixel shows the highest sensor in it, in a colormap with a colour bar in hours;
    pixels without a sensor stay blank."""
    try:
        import matplotlib
    except ImportError:
        raise ImportError("heat map: matplotlib is not installed (pip install 'shadowcl[sun]')") from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    up = np.asarray(up, float) / np.linalg.norm(up)
    north = np.asarray(north, float) - np.dot(north, up) * up
    north /= np.linalg.norm(north)
    east = np.cross(north, up)
    x, y, height = points @ east, points @ north, points @ up
    span = max(np.ptp(x), np.ptp(y), 1e-9)
    spacing = _typical_spacing(x, y)
    pixel = max(spacing, span / HEAT_MAP_PIXELS)
    # lattice points are pixel centres: rounded, not floored (a roof's points, lifted from float32
    # corners, sit a rounding error off the lattice, and flooring put half of them a pixel off)
    width, rows = int(np.rint(np.ptp(x) / pixel)) + 1, int(np.rint(np.ptp(y) / pixel)) + 1
    image = np.full((rows, width), np.nan)
    order = np.argsort(height, kind="stable")               # the highest sensor in a pixel is drawn last
    col = np.rint((x[order] - x.min()) / pixel).astype(int)
    row = np.rint((y[order] - y.min()) / pixel).astype(int)
    image[row, col] = hours[order]
    figure, axes = plt.subplots(figsize=(8, 7), dpi=120)
    half = pixel / 2
    shown = axes.imshow(image, origin="lower", cmap="inferno", interpolation="nearest",
                        extent=(x.min() - half, x.min() - half + width * pixel, y.min() - half, y.min() - half + rows * pixel))
    figure.colorbar(shown, ax=axes, label="hours of direct sun")
    axes.set_xlabel("east")
    axes.set_ylabel("north")
    axes.set_title(title)
    figure.savefig(path, bbox_inches="tight")
    plt.close(figure)


def _typical_spacing(x: np.ndarray, y: np.ndarray) -> float:
    """The grid step: the smallest non-zero gap between sorted coordinates, over a sample."""
    sample = np.unique(np.round(x[:: max(1, len(x) // 20000)], 6))
    gaps = np.diff(sample)
    gaps = gaps[gaps > 1e-6]
    return float(gaps.min()) if len(gaps) else 1.0
