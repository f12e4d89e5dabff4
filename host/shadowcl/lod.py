"""Levels of detail for occluders, and their shadow error measured against the exact method.

Fawad, Wang & Wu (Table I) cast shadow volumes from simplified meshes chosen by human observers;
shadowcl chooses by measured error instead. A *level* is the occluder mesh simplified by
fast-simplification (quadric edge collapse) to a fraction of its triangles; its *error* is how many
receivers of the full-resolution surface change state when the simplified mesh occludes instead of the
full one, both classified by the exact method (:mod:`shadowcl.exact`).

>>> meshes = levels(mesh)                                   # [mesh, 50 %, 25 %, 10 %, ...], cached
>>> errors = level_errors(device, mesh, light, points, normals, eps)   # one MaskError per level
>>> occluder = resolve(device, mesh, light, receiver_bounds, eps, lod="auto", max_error=1e-3)

What simplification does to a scene mesh:

- Vertices at equal positions are welded first (texture seams would otherwise be borders that tear
  open as they collapse), and triangles that become degenerate by the weld are dropped.
- Connected components of at most :data:`KEEP_COMPONENT` triangles (a ground quad of 2 triangles, a
  ground box of 12, a thin card) are kept verbatim: collapsing them gains almost nothing and destroys
  their shape. Every other component is simplified on its own to its share (one call on the whole
  mesh let a small sphere beside a large open ground vanish at 2.5 %), so a bunny on a ground box at
  level 0.1 keeps 10 % of the bunny's triangles plus the box's 12 (Table I: teapot 6,320 -> 3,160
  exactly; bunny 69,451 -> 6,941, the 6,945 asked less two cancelled fins).
- Border vertices (of open meshes) are never collapsed (fast-simplification's ``preserve_border``):
  without it a subdivided flat ground of 512 triangles lost 80 % of its area at level 0.05. Open
  models keep their holes' outlines, and so their shadows (the teapot stops at 186 triangles at 0.01).
- A component that was manifold and consistently wound stays so, as shadow volumes require: the
  zero-volume fins edge collapses leave (two faces on the same corners, wound opposite ways) are
  cancelled, and when a target still breaks the component, nearby then larger targets are tried.
- A mesh fast-simplification cannot reduce as asked (tiny, open, degenerate: it stops early, or
  returns nothing) simply keeps more triangles at that level: a level is never empty and never has more
  triangles than the level before it.
"""

from __future__ import annotations

import math
import time
import weakref
from dataclasses import dataclass

import numpy as np

from .checks import check_bounds, non_negative_float
from .geometry import Mesh
from .lights import PointLight, check_light
from .metrics import MaskError, mask_error
from .points import check_points
from .topology import components

# 1 is the mesh itself. 0.5 and 0.1 are Table I's reductions (teapot 6,320 -> 3,160; bunny 69,451 ->
# 6,945); the steps between at most halve the triangles, so "auto" is never forced more than ~2x finer
# than its budget allows; 0.01 reaches ~1 k triangles on the largest model (ogre, 124 k).
DEFAULT_FRACTIONS = (1.0, 0.5, 0.25, 0.1, 0.05, 0.025, 0.01)
KEEP_COMPONENT = 12        # components this small (a quad, a box) are never simplified
MIN_TRIANGLES = 4          # a simplified component keeps at least a tetrahedron's worth
DEFAULT_MAX_ERROR = 1e-3   # issue 6: lod="auto" stays within 0.1 % of receivers
CONFIDENCE_Z = 2.326       # one-sided 99 % normal quantile (sample size rule)
PASS_SHARE = 0.8           # a level measured at 80 % of the budget must still pass (sample size rule)
MIN_SAMPLE, MAX_SAMPLE = 20_000, 400_000
SAMPLE_SEED = 20261122
MAX_CALIBRATIONS = 256     # per mesh
LIGHT_BIN_DEGREES = 5.0    # lod="auto" calibrates once per bin of light direction this wide

_LEVELS: "weakref.WeakKeyDictionary[Mesh, dict]" = weakref.WeakKeyDictionary()
_CALIBRATIONS: "weakref.WeakKeyDictionary[Mesh, dict]" = weakref.WeakKeyDictionary()


# levels ----------------------------------------------------------------------------------------------
def _check_fractions(fractions) -> tuple[float, ...]:
    try:
        values = tuple(float(f) for f in fractions)
    except (TypeError, ValueError):
        raise TypeError(f"fractions: expected a sequence of numbers, got {fractions!r}") from None
    if not values or values[0] != 1.0:
        raise ValueError(f"fractions: must start with 1 (level 0 is the mesh itself), got {values}")
    if any(not (0 < b < a) for a, b in zip(values, values[1:])):
        raise ValueError(f"fractions: must decrease strictly and stay above 0, got {values}")
    return values


def _weld(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Float64 vertices with equal positions merged, and the faces that still have three corners."""
    vertices, inverse = np.unique(mesh.vertices, axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[mesh.faces].astype(np.int32)
    distinct = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return vertices.astype(np.float64), faces[distinct]


def _components(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(F,) label of each face's connected component (faces joined through shared vertices): the graph
    of vertices and faces (nodes V + f), so labels follow each component's least vertex."""
    rows = n_vertices + np.repeat(np.arange(len(faces)), 3)
    return components(n_vertices + len(faces), np.stack([faces.reshape(-1), rows], axis=1))[faces[:, 0]]


def _compact(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertices ``faces`` use, and the faces renumbered to them."""
    used, inverse = np.unique(faces, return_inverse=True)
    return vertices[used], inverse.reshape(-1, 3).astype(np.int32)


def _manifold(faces: np.ndarray) -> bool:
    """No directed edge twice: at most two faces per edge, consistently wound (what silhouettes need)."""
    directed = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).astype(np.int64)
    keys = directed[:, 0] * (int(faces.max()) + 1) + directed[:, 1]
    return len(np.unique(keys)) == len(keys)


def _cancel_fins(faces: np.ndarray) -> np.ndarray:
    """``faces`` without pairs of faces on the same three vertices wound opposite ways (the zero-volume
    fins edge collapses leave): as a surface such a pair cancels, so a closed mesh stays closed, and its
    edges lose the two extra faces that made them non-manifold."""
    if len(faces) == 0:
        return faces
    _, group = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True)
    group = group.reshape(-1)
    first = np.argmin(faces, axis=1)[:, None]
    rotated = np.take_along_axis(faces, (first + np.arange(3)) % 3, axis=1)
    sense = (rotated[:, 1] < rotated[:, 2]).astype(np.int64)          # 1: a rotation of the sorted order
    counts = np.zeros((group.max() + 1, 2), dtype=np.int64)
    np.add.at(counts, (group, sense), 1)
    # rank of each face among the faces of its group and sense; the first min(count) of each sense go
    key = 2 * group + sense
    order = np.argsort(key, kind="stable")
    starts = np.searchsorted(key[order], key[order])
    rank = np.empty(len(faces), dtype=np.int64)
    rank[order] = np.arange(len(faces)) - starts
    return faces[rank >= counts.min(axis=1)[group]]


def _simplify(vertices: np.ndarray, faces: np.ndarray, target: int, manifold: bool):
    """fast-simplification of one component to about ``target`` triangles, fins cancelled; None when
    nothing is left, or when a ``manifold`` component would not stay so at any of a few targets."""
    import fast_simplification

    # nearby targets first (the breakage is local), then coarser steps up: a level keeps more triangles
    # rather than break; the ogre's body at 1 % needed ~1.5x its target
    for attempt in (target, target - 2, target + 2, *(round(target * 1.25 ** k) for k in range(1, 6))):
        if not 0 < attempt < len(faces):
            continue
        try:
            # preserve_border: an open flat ground (a subdivided plane) would otherwise erode from its border
            points, triangles = fast_simplification.simplify(np.array(vertices), np.array(faces), target_count=attempt,
                                                             preserve_border=True)
        except (ValueError, RuntimeError):
            return None
        triangles = _cancel_fins(triangles)
        if not len(triangles):
            return None
        if not manifold or _manifold(triangles):
            return points, triangles
    return None


def levels(mesh: Mesh, fractions=DEFAULT_FRACTIONS) -> list[Mesh]:
    """The levels of detail of ``mesh``: level 0 is ``mesh`` itself, level i keeps about ``fractions[i]``
    of the triangles of its simplifiable part (see the module docstring for what is kept verbatim).

    Cached per mesh (weakly, like :func:`shadowcl.silhouette.edge_adjacency`) and per ``fractions``;
    the wall time of each level's simplification is in :func:`level_times`. A mesh that cannot be
    reduced as far as asked keeps more triangles at that level (possibly all of them).
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected a Mesh, got {type(mesh).__name__}")
    fractions = _check_fractions(fractions)
    per_mesh = _LEVELS.setdefault(mesh, {})
    if fractions not in per_mesh:
        per_mesh[fractions] = _build_levels(mesh, fractions)
    simplified, _ = per_mesh[fractions]
    # the cache holds None for "the mesh itself": a reference to the mesh would keep its weak key alive
    return [mesh] + [mesh if level is None else level for level in simplified]


def _build_levels(mesh: Mesh, fractions: tuple[float, ...]) -> tuple[tuple, tuple]:
    """Levels 1.. (None where a level is the mesh itself) and their simplification seconds.

    Each component is simplified on its own, to its share of the fraction (at least MIN_TRIANGLES), and
    stays manifold if it was (see the module docstring; the bunny at 10 % had two fins).
    """
    vertices, faces = _weld(mesh)
    labels = _components(faces, len(vertices))
    sizes = np.bincount(labels)
    kept = _compact(vertices, faces[sizes[labels] <= KEEP_COMPONENT])
    parts = [_compact(vertices, faces[labels == c]) for c in np.flatnonzero(sizes > KEEP_COMPONENT)]
    current = list(parts)                                   # each component at the previous level
    manifold = [_manifold(part) for _, part in parts]       # simplification must not break what was whole
    result, seconds = [], [0.0]
    for fraction in fractions[1:]:
        start = time.perf_counter()
        changed = False
        for i, (part_vertices, part) in enumerate(parts):
            target = max(MIN_TRIANGLES, round(fraction * len(part)))
            if target >= len(current[i][1]):
                continue
            simplified = _simplify(part_vertices, part, target, manifold[i])
            if simplified is not None and len(simplified[1]) < len(current[i][1]):
                current[i], changed = simplified, True
        if changed:
            pieces = [kept] + current
            offsets = np.cumsum([0] + [len(v) for v, _ in pieces[:-1]])
            level = Mesh(np.concatenate([v for v, _ in pieces]),
                         np.concatenate([f.astype(np.int64) + o for (_, f), o in zip(pieces, offsets)]))
        else:
            level = result[-1] if result else None
        seconds.append(time.perf_counter() - start)
        result.append(level)
    return tuple(result), tuple(seconds)


def level_times(mesh: Mesh, fractions=DEFAULT_FRACTIONS) -> list[float]:
    """Seconds each level of :func:`levels` took to simplify (0 for level 0), computing them if needed."""
    levels(mesh, fractions)
    return list(_LEVELS[mesh][_check_fractions(fractions)][1])


_all_levels = levels  # level_errors' parameter ``levels`` hides the function


# errors ----------------------------------------------------------------------------------------------
def _classify(device, occluder: Mesh, light, receivers, eps: float) -> np.ndarray:
    from .shadows import shadow_mask

    return shadow_mask(occluder, light, receivers, method="exact", device=device, eps=eps)


def level_errors(device, mesh: Mesh, light, points, normals, eps: float, levels=None) -> list[MaskError]:
    """The shadow error of each level: the exact method's mask with the level occluding, against its mask
    with ``mesh`` occluding, on the same receivers ``points`` ((N, 3), on the full-resolution surface,
    with ``normals`` or None) and ``eps``. ``levels`` defaults to :func:`levels` of ``mesh``; a level
    that is ``mesh`` itself has error 0 by construction.
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected a Mesh, got {type(mesh).__name__}")
    light = check_light(light)
    receivers = check_points(points, normals)
    if len(receivers) == 0:
        raise ValueError("points: no receivers")
    eps = non_negative_float("eps", eps)
    chosen = _all_levels(mesh) if levels is None else list(levels)
    for i, level in enumerate(chosen):
        if not isinstance(level, Mesh):
            raise TypeError(f"levels[{i}]: expected a Mesh, got {type(level).__name__}")
    truth = _classify(device, mesh, light, receivers, eps)
    masks: dict[int, np.ndarray] = {id(mesh): truth}
    errors = []
    for level in chosen:
        if id(level) not in masks:
            masks[id(level)] = _classify(device, level, light, receivers, eps)
        errors.append(mask_error(masks[id(level)], truth))
    return errors


# auto ------------------------------------------------------------------------------------------------
def sample_size(max_error: float, pass_share: float = PASS_SHARE, minimum: int = MIN_SAMPLE) -> int:
    """Calibration receivers for an error budget ``max_error`` (a fraction of receivers).

    A level passes when the one-sided 99 % Clopper-Pearson upper bound of its error is within the budget
    (so "auto" picks a level over budget with probability <= 1 %). The sample is large enough that a
    level measured at ``pass_share`` (default :data:`PASS_SHARE`) of the budget still passes: the normal approximation
    ``n = z^2 r / ((1 - r)^2 b)`` (108,206 for ``b = 0.001``, ``r = 0.8``, ``z = 2.326``) grown in 1 %
    steps until the exact bound agrees: 128,158 receivers for ``b = 0.001``, an expected 128 wrong at the
    budget. Clamped to [minimum (default MIN_SAMPLE), MAX_SAMPLE] (MAX_SAMPLE for b = 0, or any b below ~3e-4).
    """
    if max_error <= 0:
        return MAX_SAMPLE
    n = math.ceil(CONFIDENCE_Z ** 2 * pass_share / ((1 - pass_share) ** 2 * max_error))
    while n < MAX_SAMPLE and upper_bound(math.floor(pass_share * max_error * n), n) > max_error:
        n = math.ceil(1.01 * n)
    return int(min(MAX_SAMPLE, max(minimum, n)))


def upper_bound(wrong: int, receivers: int) -> float:
    """One-sided 99 % Clopper-Pearson upper bound of an error rate measured as ``wrong`` of ``receivers``."""
    from scipy.stats import beta

    return 1.0 if wrong >= receivers else float(beta.ppf(0.99, wrong + 1, receivers - wrong))


def calibration_sample(mesh: Mesh, receiver_bounds, count: int, eps: float = 0.0, seed: int = SAMPLE_SEED):
    """``count`` area-weighted random points on ``mesh``'s surface inside ``receiver_bounds`` (grown by
    ``eps``), with their face normals; seeded. Only faces whose box meets the bounds are drawn from, and
    points outside are redrawn, in at most 64 rounds (fewer points come back when the surface inside
    the bounds is a tiny share of those faces' area). When the bounds hold no surface: ``count`` uniform
    points in the box, normals None.
    """
    box = check_bounds("receiver_bounds", receiver_bounds)
    low, high = box[0] - eps, box[1] + eps
    rng = np.random.default_rng(seed)
    tri = mesh.triangles
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    meets = np.all(tri.min(axis=1) <= high, axis=1) & np.all(tri.max(axis=1) >= low, axis=1) & (area > 0)
    candidates = np.flatnonzero(meets)
    points, normals, drawn = [], [], 0
    while candidates.size and drawn < count and len(points) < 64:
        face = candidates[rng.choice(len(candidates), size=count, p=area[candidates] / area[candidates].sum())]
        r1, r2 = np.sqrt(rng.random(count))[:, None], rng.random(count)[:, None]
        t = tri[face]
        p = (1 - r1) * t[:, 0] + r1 * (1 - r2) * t[:, 1] + r1 * r2 * t[:, 2]
        inside = np.all((p >= low) & (p <= high), axis=1)
        points.append(p[inside])
        normals.append(mesh.face_normals[face[inside]])
        drawn += int(inside.sum())
    if drawn == 0:
        return low + rng.random((count, 3)) * (high - low), None
    return np.concatenate(points)[:count], np.concatenate(normals)[:count]


@dataclass(frozen=True)
class Calibration:
    """What ``lod="auto"`` measured: per level its triangles, error on the sample and 99 % upper bound,
    and the level chosen (the coarsest whose upper bound is within ``max_error``; level 0 always qualifies)."""

    max_error: float
    receivers: int
    triangles: tuple[int, ...]
    errors: tuple[MaskError, ...]
    upper_bounds: tuple[float, ...]
    level: int
    seconds: float


def _light_bin(light, box: np.ndarray) -> tuple:
    """The bin of ``light`` as seen from the receivers' box: its direction from the box's centre in
    :data:`LIGHT_BIN_DEGREES` steps of polar and azimuth angle, and for a point light its distance in
    quarter octaves. A calibration is reused across the lights of a bin (frames of a moving light)."""
    if isinstance(light, PointLight):
        offset = light.position - box.mean(axis=0)
        distance = float(np.linalg.norm(offset))
        kind = ("point", round(4 * math.log2(distance)) if distance > 0 else None)
        direction = offset / distance if distance > 0 else np.array([0.0, 1.0, 0.0])
    else:
        kind, direction = ("dir",), -light.direction / np.linalg.norm(light.direction)
    polar = math.degrees(math.acos(float(np.clip(direction[1], -1, 1))))
    azimuth = math.degrees(math.atan2(float(direction[2]), float(direction[0])))
    return (*kind, round(polar / LIGHT_BIN_DEGREES), round(azimuth / LIGHT_BIN_DEGREES) if polar > 1e-9 else 0)


def calibrate(device, mesh: Mesh, light, receiver_bounds, eps: float, max_error: float,
              receivers=None) -> Calibration:
    """Measure every level of ``mesh`` on a calibration sample and choose one for ``max_error``.

    The sample is drawn from the caller's ``receivers`` (points (N, 3), ``(points, normals)`` or a
    ``Points``: with their normals or their absence; all of them when fewer than the budget needs) by
    :func:`shadowcl.auto.calibration_sample`, sized by :func:`sample_size` with method="auto"'s pass share
    and floor; without ``receivers``, :func:`calibration_sample` on ``mesh``'s surface in the bounds.
    Cached per (mesh, light bin (:func:`_light_bin`), bounds, eps, max_error, receivers' count and box):
    the frames of a moving light reuse the calibration of their bin.
    """
    from . import auto

    light = check_light(light)
    box = check_bounds("receiver_bounds", receiver_bounds)
    eps = non_negative_float("eps", eps)
    max_error = non_negative_float("max_error", max_error)
    receivers = auto.calibration_receivers(receivers)
    described = None if receivers is None else (len(receivers), receivers.bounds.tobytes(), receivers.normals is None)
    key = (_light_bin(light, box), box.tobytes(), eps, max_error, described)
    per_mesh = _CALIBRATIONS.setdefault(mesh, {})
    if key not in per_mesh:
        start = time.perf_counter()
        meshes = levels(mesh)
        if receivers is None:
            points, normals = calibration_sample(mesh, box, sample_size(max_error), eps)
        else:
            count = sample_size(max_error, auto.PASS_SHARE, auto.MIN_SAMPLE)
            sample = receivers if len(receivers) <= count else auto.calibration_sample(receivers, count)
            points, normals = sample.positions, sample.normals
        errors = level_errors(device, mesh, light, points, normals, eps, meshes)
        bounds = [0.0 if level is mesh else upper_bound(e.wrong, e.receivers) for level, e in zip(meshes, errors)]
        chosen = max(i for i, b in enumerate(bounds) if b <= max_error)
        if len(per_mesh) >= MAX_CALIBRATIONS:          # a moving light adds one per frame: drop the oldest
            del per_mesh[next(iter(per_mesh))]
        per_mesh[key] = Calibration(max_error, len(points), tuple(len(m.faces) for m in meshes), tuple(errors),
                                    tuple(bounds), chosen, time.perf_counter() - start)
    return per_mesh[key]


def resolve(device, mesh: Mesh, light, receiver_bounds, eps: float, lod, max_error=DEFAULT_MAX_ERROR,
            receivers=None) -> Mesh:
    """The occluder mesh a method should use for ``lod``: None gives ``mesh``; an int gives
    ``levels(mesh)[lod]``; ``"auto"`` gives the coarsest level whose measured error on a calibration
    sample (:func:`calibrate`, on ``receivers`` when given) is within ``max_error`` (a fraction of receivers,
    >= 0) with 99 % confidence.

    "auto" measures every level (0.2-1 s on the bench's models, plus building the levels), then reuses
    the calibration for every light of the same direction bin (:func:`_light_bin`).
    """
    if not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected a Mesh, got {type(mesh).__name__}")
    light = check_light(light)
    max_error = non_negative_float("max_error", max_error)
    if lod is None:
        return mesh
    if isinstance(lod, str):
        if lod != "auto":
            raise ValueError(f"lod: expected None, a level index or 'auto', got {lod!r}")
        return levels(mesh)[calibrate(device, mesh, light, receiver_bounds, eps, max_error, receivers).level]
    if isinstance(lod, bool) or not isinstance(lod, (int, np.integer)):
        raise TypeError(f"lod: expected None, a level index (int) or 'auto', got {type(lod).__name__} {lod!r}")
    meshes = levels(mesh)
    if not 0 <= lod < len(meshes):
        raise ValueError(f"lod: level {lod} out of range; {mesh!r} has levels 0 to {len(meshes) - 1}")
    return meshes[int(lod)]
