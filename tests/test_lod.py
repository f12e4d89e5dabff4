"""Levels of detail (shadowcl.lod): simplification, shadow error per level, and lod="auto".

Errors are checked against the float64 brute force (reference/exact.py) with the exact method's tolerance
(tests/test_exact.py): the kernel and the reference may disagree only on receivers whose segment passes
within BAND (1e-5 of the scene's size) of a triangle edge, where float32 rounding may decide either way.
"""

import gc

import numpy as np
import pytest

import shadowcl as sc
from shadowcl import lod
from shadowcl.testing import icosphere
from shadowcl.metrics import mask_error
from shadowcl.methods import default_eps
from shadowcl.reference import exact as ref

from conftest import require_models
from test_exact import BAND, scene_size, undecided

LIGHT = sc.PointLight((-2.0, 5.0, 1.5))


def ground_quad(half: float = 4.0) -> sc.Mesh:
    return sc.Mesh([[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]], [[0, 2, 1], [0, 3, 2]])


def sphere_scene(subdivisions: int = 3) -> sc.Mesh:
    """A unit icosphere standing 0.3 above a ground quad of 2 triangles: a model on its ground."""
    ball = icosphere(subdivisions)
    return sc.Mesh.concatenate([ground_quad(), sc.Mesh(ball.vertices + np.float32([0, 1.3, 0]), ball.faces)])


def surface_points(mesh, count, rng):
    """Area-weighted points on ``mesh`` with face normals, drawn independently of shadowcl.lod."""
    tri = mesh.triangles
    area = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    face = rng.choice(len(tri), size=count, p=area / area.sum())
    a, b = rng.random((2, count, 1))
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    t = tri[face]
    return t[:, 0] + a * (t[:, 1] - t[:, 0]) + b * (t[:, 2] - t[:, 0]), mesh.face_normals[face]


def triangle_set(mesh) -> set:
    return {tuple(sorted(map(tuple, t.round(6).tolist()))) for t in mesh.triangles}


# levels -------------------------------------------------------------------------------------------
def test_levels_reduce_the_triangles_as_asked():
    ball = icosphere(4)                                    # 5120 triangles, one closed component
    meshes = lod.levels(ball)
    assert meshes[0] is ball
    counts = [len(m.faces) for m in meshes]
    for fraction, count in zip(lod.DEFAULT_FRACTIONS, counts):
        # an edge collapse removes two triangles: the count lands within 2 of the target
        assert abs(count - fraction * 5120) <= 2, (fraction, counts)
    custom = lod.levels(ball, (1, 0.3))
    assert [len(m.faces) for m in custom] == [5120, pytest.approx(1536, abs=2)]
    assert lod.levels(ball)[1] is meshes[1], "levels are cached per mesh and fractions"
    assert len(lod.level_times(ball)) == len(meshes)


def test_level_cache_does_not_keep_the_mesh_alive():
    ball = icosphere(2)
    lod.levels(ball)
    before = len(lod._LEVELS)
    del ball
    gc.collect()
    assert len(lod._LEVELS) == before - 1


def test_the_ground_survives_every_level():
    """A 2-triangle ground quad, a 12-triangle ground box and a subdivided open ground of 512 triangles keep
    their shape and area at every level, and the model beside them never vanishes."""
    box = sc.Mesh(np.array([[x, y, z] for x in (-6, 6) for y in (-0.2, 0) for z in (-6, 6)], float),
                  [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                   [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    x, z = np.meshgrid(np.linspace(-4, 4, 17), np.linspace(-4, 4, 17))
    grid_vertices = np.column_stack([x.ravel(), np.full(x.size, 0.5), z.ravel()])
    a = (np.arange(16)[:, None] * 17 + np.arange(16)[None, :]).ravel()
    grid = sc.Mesh(grid_vertices, np.concatenate([np.stack([a, a + 17, a + 1], 1), np.stack([a + 1, a + 17, a + 18], 1)]))
    model = sphere_scene(3)
    for ground in (box, grid):
        mesh = sc.Mesh.concatenate([ground, model])
        quad, ground_set = triangle_set(ground_quad()), triangle_set(ground)
        for i, level in enumerate(lod.levels(mesh)):
            triangles = triangle_set(level)
            assert quad <= triangles, f"level {i}: the ground quad changed"
            if ground is box:
                assert ground_set <= triangles, f"level {i}: the ground box changed"
            tri = level.triangles
            on_grid = np.all(np.abs(tri[:, :, 1] - 0.5) < 1e-6, axis=1)
            area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
            if ground is grid:
                assert area[on_grid].sum() == pytest.approx(64.0, rel=1e-6), f"level {i}: the open ground eroded"
            assert level.bounds[1][1] > 2.0, f"level {i}: the sphere vanished"


def test_fins_cancel_and_levels_stay_manifold():
    """Edge collapses can leave a fin (two faces on the same corners, wound opposite ways) that makes its
    edges non-manifold; shadow volumes refuse those, so levels of a manifold mesh must stay manifold."""
    tetra = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    fin = np.array([[1, 2, 4], [2, 1, 4]])
    kept = lod._cancel_fins(np.concatenate([tetra, fin, tetra[:1]]))
    assert sorted(map(tuple, kept.tolist())) == sorted(map(tuple, np.concatenate([tetra, tetra[:1]]).tolist())), \
        "the opposite pair goes; a same-way duplicate stays (it is no fin)"
    assert lod._manifold(tetra) and not lod._manifold(np.concatenate([tetra, fin]))
    for level in lod.levels(icosphere(4))[1:]:
        assert lod._manifold(level.faces)


def test_bunny_levels_stay_manifold():
    """The bunny at 10 % (Table I's level) came out of fast-simplification with two fins."""
    models = require_models()
    bunny = sc.Mesh.load(models / "stanford-bunny.obj")
    meshes = lod.levels(bunny)
    assert abs(len(meshes[lod.DEFAULT_FRACTIONS.index(0.1)].faces) - 6945) <= 8     # Table I: 69,451 -> 6,945
    for i, level in enumerate(meshes):
        assert lod._manifold(level.faces), f"level {i}"


@pytest.mark.parametrize("case", ["one triangle", "tetrahedron", "degenerate and duplicated", "open hemisphere"])
def test_meshes_that_cannot_be_reduced_keep_more_triangles(case, rng):
    ball = icosphere(2)
    if case == "one triangle":
        mesh = sc.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    elif case == "tetrahedron":
        mesh = sc.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    elif case == "degenerate and duplicated":
        faces = np.concatenate([ball.faces, ball.faces[:40], [[0, 0, 1], [2, 2, 2]]])
        mesh = sc.Mesh(ball.vertices, faces)
    else:
        keep = ball.triangles[:, :, 1].mean(axis=1) > 0
        mesh = sc.Mesh(ball.vertices, ball.faces[keep])
    meshes = lod.levels(mesh)
    counts = [len(m.faces) for m in meshes]
    assert all(b <= a for a, b in zip(counts, counts[1:])) and min(counts) >= 1, counts
    if case in ("one triangle", "tetrahedron"):
        assert all(m is mesh for m in meshes), "too small to simplify: every level is the mesh itself"
    else:
        assert counts[-1] < counts[0]


# errors -------------------------------------------------------------------------------------------
def test_level_errors_match_the_brute_force(device, rng):
    mesh = sphere_scene(2)                                  # 2 + 320 triangles
    points, normals = surface_points(mesh, 3000, rng)
    eps = default_eps(mesh.bounds)
    meshes = lod.levels(mesh)
    errors = lod.level_errors(device, mesh, LIGHT, points, normals, eps)
    assert len(errors) == len(meshes)
    assert errors[0].wrong == 0, "level 0 is the mesh itself"
    truth = ref.shadow_mask(mesh.vertices, mesh.faces, LIGHT, points, normals, eps)
    band = BAND * scene_size(mesh, points)
    assert errors[-1].wrong > 20, "the coarsest level must cause some error, or this test checks nothing"
    for i, (level, error) in enumerate(zip(meshes, errors)):
        expected = mask_error(ref.shadow_mask(level.vertices, level.faces, LIGHT, points, normals, eps), truth)
        difference = abs(error.false_shadow - expected.false_shadow) + abs(error.false_light - expected.false_light)
        assert error.receivers == len(points)
        if difference:                                  # only then is the (slow) band worth computing
            free = int((undecided(mesh, LIGHT, points, normals, eps, band)
                        | undecided(level, LIGHT, points, normals, eps, band)).sum())
            assert difference <= free <= 0.01 * len(points), \
                f"level {i}: kernel {error}, reference {expected}, {free} receivers in the band"


def test_level_errors_without_normals_and_given_levels(device, rng):
    mesh = sphere_scene(2)
    points = rng.uniform([-3, 0.01, -3], [3, 3, 3], (2000, 3))
    errors = lod.level_errors(device, mesh, LIGHT, points, None, 1e-4, levels=[mesh, mesh])
    assert [e.wrong for e in errors] == [0, 0]


# auto ---------------------------------------------------------------------------------------------
def test_sample_size_rule():
    assert lod.sample_size(0.0) == lod.MAX_SAMPLE and lod.sample_size(0.5) == lod.MIN_SAMPLE
    # the rule's promise: at the sample size, 80 % of the budget passes and the budget itself does not
    for budget in (1e-3, 3e-3, 1e-2):
        n = lod.sample_size(budget)
        assert lod.MIN_SAMPLE <= n < lod.MAX_SAMPLE
        assert lod.upper_bound(int(0.8 * budget * n), n) <= budget < lod.upper_bound(round(budget * n), n)
    n = lod.sample_size(1e-3)
    assert 1e5 < n < 2e5 and lod.upper_bound(int(0.75e-3 * n), n) <= 1e-3


def test_calibration_sample_lies_on_the_surface_inside_the_bounds():
    mesh = sphere_scene(2)
    box = np.array([[-2.0, 0.0, -2.0], [2.0, 1.5, 2.0]])
    points, normals = lod.calibration_sample(mesh, box, 5000)
    assert points.shape == (5000, 3) and normals.shape == (5000, 3)
    assert np.all((points >= box[0]) & (points <= box[1]))
    ground = points[:, 1] == 0
    assert 0.3 < ground.mean() < 0.95 and np.all(normals[ground] == [0, 1, 0])
    on_ball = ~ground
    assert np.allclose(np.linalg.norm(points[on_ball] - [0, 1.3, 0], axis=1), 1.0, atol=0.06)  # flat facets
    again, _ = lod.calibration_sample(mesh, box, 5000)
    assert np.array_equal(points, again), "seeded"
    empty_box = np.array([[10.0, 10, 10], [11, 11, 11]])
    points, normals = lod.calibration_sample(mesh, empty_box, 100)
    assert normals is None and np.all((points >= 10) & (points <= 11))


@pytest.mark.parametrize("max_error", [0.0, 0.004, 0.02, 1.0])
def test_auto_picks_the_coarsest_level_within_budget(device, rng, max_error):
    mesh = sphere_scene(3)                                  # 2 + 1280 triangles
    meshes = lod.levels(mesh)
    box = np.array([[-4.0, 0.0, -4.0], [4.0, 2.3, 4.0]])
    eps = default_eps(mesh.bounds)
    chosen = lod.resolve(device, mesh, LIGHT, box, eps, "auto", max_error)
    calibration = lod.calibrate(device, mesh, LIGHT, box, eps, max_error)
    assert chosen is meshes[calibration.level]
    bounds = calibration.upper_bounds
    assert bounds[calibration.level] <= max_error
    assert all(b > max_error for b in bounds[calibration.level + 1:]), "a coarser level was within budget"
    if max_error == 0.0:
        assert calibration.level == 0
    if max_error == 1.0:
        assert calibration.level == len(meshes) - 1
    if max_error == 0.02:
        assert calibration.level >= 2, f"a 2 % budget should allow a coarse level: {calibration}"
    # never over budget: on independent receivers the chosen level's error is not significantly above it
    points, normals = surface_points(mesh, 100_000, rng)
    inside = np.all((points >= box[0]) & (points <= box[1]), axis=1)
    error = lod.level_errors(device, mesh, LIGHT, points[inside], normals[inside], eps, [mesh, chosen])[1]
    lower = 0.0 if error.wrong == 0 else 1 - lod.upper_bound(error.receivers - error.wrong, error.receivers)
    assert lower <= max_error, f"budget {max_error}: level {calibration.level} measured {error}"


def test_resolve_none_and_index(device):
    mesh = sphere_scene(2)
    box = np.array([[-4.0, 0.0, -4.0], [4.0, 2.3, 4.0]])
    assert lod.resolve(device, mesh, LIGHT, box, 1e-3, None, 1e-3) is mesh
    assert lod.resolve(device, mesh, LIGHT, box, 1e-3, 2, 1e-3) is lod.levels(mesh)[2]
    assert lod.resolve(device, mesh, LIGHT, box, 1e-3, np.int64(1), 1e-3) is lod.levels(mesh)[1]


BAD = [
    (dict(lod=-1), ValueError, "lod: level -1 out of range"),
    (dict(lod=99), ValueError, "lod: level 99 out of range"),
    (dict(lod="fast"), ValueError, "lod: expected None, a level index or 'auto'"),
    (dict(lod=0.5), TypeError, "lod: expected None, a level index"),
    (dict(lod=True), TypeError, "lod: expected None, a level index"),
    (dict(lod="auto", max_error=-0.1), ValueError, "max_error: must be a finite non-negative"),
    (dict(lod="auto", max_error=float("nan")), ValueError, "max_error: must be a finite non-negative"),
    (dict(lod=1, max_error=float("inf")), ValueError, "max_error: must be a finite non-negative"),
    (dict(lod="auto", max_error="0.1"), TypeError, "max_error: expected a number"),
    (dict(mesh="bunny"), TypeError, "mesh: expected a Mesh"),
    (dict(light=(0, 1, 0)), TypeError, "light: expected a PointLight"),
    (dict(lod="auto", receiver_bounds=[[0, 0, 0], [np.nan, 1, 1]]), ValueError, "receiver_bounds: contains NaN"),
    (dict(lod="auto", receiver_bounds=[[1, 1, 1], [0, 0, 0]]), ValueError, "receiver_bounds: low corner"),
    (dict(lod="auto", eps=-1.0), ValueError, "eps: must be a finite non-negative"),
]


@pytest.mark.parametrize("change, error, message", BAD, ids=[str(b[0]) for b in BAD])
def test_bad_input_is_named(device, change, error, message):
    args = dict(mesh=sphere_scene(1), light=LIGHT, receiver_bounds=[[-1, 0, -1], [1, 1, 1]], eps=1e-3, lod=None,
                max_error=1e-3)
    args.update(change)
    with pytest.raises(error, match=message.replace("(", r"\(")):
        lod.resolve(device, **args)


@pytest.mark.parametrize("fractions, error", [((0.5, 0.25), ValueError), ((1, 0.5, 0.5), ValueError),
                                              ((1, 0.0), ValueError), ((1, "half"), TypeError), (None, TypeError)])
def test_bad_fractions_are_named(fractions, error):
    with pytest.raises(error, match="fractions"):
        lod.levels(icosphere(1), fractions)


def test_bad_level_errors_input_is_named(device):
    mesh = sphere_scene(1)
    with pytest.raises(ValueError, match="points: no receivers"):
        lod.level_errors(device, mesh, LIGHT, np.zeros((0, 3)), None, 1e-3)
    with pytest.raises(ValueError, match="normals: expected shape"):
        lod.level_errors(device, mesh, LIGHT, np.zeros((4, 3)), np.ones((3, 3)), 1e-3)
    with pytest.raises(TypeError, match=r"levels\[1\]"):
        lod.level_errors(device, mesh, LIGHT, np.zeros((4, 3)), None, 1e-3, levels=[mesh, "coarse"])
    # regression: calibrate read a bad light's attributes (AttributeError) before checking it
    with pytest.raises(TypeError, match="light: expected a PointLight"):
        lod.calibrate(device, mesh, (0, 1, 0), [[-1, 0, -1], [1, 1, 1]], 1e-3, 1e-3)


# bench/table2.py ----------------------------------------------------------------------------------
def test_table2_says_clearly_when_the_shadow_volume_method_is_missing(monkeypatch):
    import sys
    from pathlib import Path

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "bench"))
    import table2

    methods = sys.modules["shadowcl.methods"]           # shadowcl.methods the module, not the function
    monkeypatch.setattr(methods, "METHODS", {k: v for k, v in methods.METHODS.items() if k != "shadow_volume"})
    with pytest.raises(SystemExit, match="needs shadowcl.shadow_volume"):
        table2.require_methods()
    monkeypatch.setattr(methods, "METHODS", {**methods.METHODS, "shadow_volume": "shadowcl.shadow_volume:ShadowVolumeMethod"})
    table2.require_methods()                            # with the method registered it passes
