"""The public path: sc.prepare / sc.Shadows, sc.shadow_mask over it, sc.Renderer, one receiver check.

Every method is called the way a user calls it, on the shipped scenes, and compared with itself called
another way (prepare vs one-shot, split vs union queries, a kept Renderer vs fresh renders) or with the
exact method where the answer must be exact (points outside the prepared bounds).
"""

import numpy as np
import pytest

import shadowcl as sc
from shadowcl import points as points_module
from shadowcl.points import check_points
from conftest import SCENES, require_models

TRIANGLE_METHODS = ("exact", "shadow_map", "angular", "shadow_volume")
SCENE_FILES = ["default.toml", "hard/contact.toml", "hard/light_inside.toml", "hard/grazing_plane.toml",
               "hard/open_mesh.toml"]


def scene_receivers(scene, count, rng):
    """``count`` area-weighted points on ``scene``'s triangles, with their face normals."""
    tri = scene.mesh.triangles.astype(np.float64)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(normal, axis=1)
    face = rng.choice(len(tri), count, p=area / area.sum())
    u, v = rng.random((2, count))
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    points = tri[face, 0] + u[:, None] * (tri[face, 1] - tri[face, 0]) + v[:, None] * (tri[face, 2] - tri[face, 0])
    return points, normal[face] / area[face, None]


def box_of(points):
    return np.stack([points.min(axis=0), points.max(axis=0)])


# The angular method refuses a point light inside a closed solid (a named error, tested in test_angular).
CASES = [(name, method) for name in SCENE_FILES for method in TRIANGLE_METHODS
         if (name, method) != ("hard/light_inside.toml", "angular")]


@pytest.mark.parametrize("name, method", CASES)
def test_prepare_mask_is_shadow_mask(device, rng, name, method):
    scene = sc.Scene.load(SCENES / name)
    points, normals = scene_receivers(scene, 4000, rng)
    one_shot = sc.shadow_mask(scene, scene.light, points, normals, method=method, device=device)
    params = {"expected_receivers": len(points)} if "expected_receivers" in sc.methods()[method] else {}
    shadows = sc.prepare(scene, scene.light, method, bounds=box_of(points), device=device, **params)
    assert np.array_equal(shadows.mask(points, normals), one_shot)
    assert shadows.method == method and shadows.stats["method"] == method
    assert shadows.stats["receivers"] == len(points) and shadows.stats["outside_bounds"] == 0
    assert shadows.stats["prepare_s"] > 0 and shadows.stats["classify_s"] > 0
    assert None not in (shadows.params.get("resolution", 0), shadows.params.get("theta_resolution", 0))


@pytest.mark.parametrize("method", TRIANGLE_METHODS)
def test_split_queries_equal_one_query(device, rng, method):
    scene = sc.Scene.load(SCENES / "default.toml")
    points, normals = scene_receivers(scene, 6001, rng)
    shadows = sc.prepare(scene, scene.light, method, device=device)
    whole = shadows.mask(points, normals)
    first, second = shadows.mask(points[:2500], normals[:2500]), shadows.mask(points[2500:], normals[2500:])
    assert np.array_equal(np.concatenate([first, second]), whole)
    assert shadows.stats["receivers"] == len(points) - 2500
    visibility = shadows.visibility(points, normals)
    assert visibility.dtype == np.float32 and visibility.shape == whole.shape
    assert np.all((visibility >= 0) & (visibility <= 1))


@pytest.mark.parametrize("method", TRIANGLE_METHODS)
def test_points_outside_bounds_are_answered(device, rng, method):
    """Prepared for one corner of the scene, queried everywhere: the points outside are counted and
    answered as a call fitted to them answers them (exact-valued methods: the exact answer)."""
    scene = sc.Scene.load(SCENES / "default.toml")
    points, normals = scene_receivers(scene, 5000, rng)
    low, high = scene.bounds
    corner = np.stack([low, low + 0.4 * (high - low)])
    shadows = sc.prepare(scene, scene.light, method, bounds=corner, device=device)
    mask = shadows.mask(points, normals)
    outside = np.any((points < corner[0]) | (points > corner[1]), axis=1)
    assert shadows.stats["outside_bounds"] == outside.sum() > 1000
    truth = sc.shadow_mask(scene, scene.light, points, normals, device=device)
    if method in ("exact", "shadow_volume"):
        assert np.array_equal(mask, truth)
    elif method == "shadow_map":   # the outside points get maps fitted to them: as a one-shot call on them
        alone = sc.shadow_mask(scene, scene.light, points[outside], normals[outside], method=method, device=device)
        assert np.array_equal(mask[outside], alone)
    else:                          # angular's table covers every direction from the light; rows set its error
        assert np.mean(mask != truth) < 0.01


@pytest.mark.parametrize("method", TRIANGLE_METHODS)
def test_normals_any_length_and_zero_refused(device, rng, method):
    scene = sc.Scene.load(SCENES / "default.toml")
    points, normals = scene_receivers(scene, 3000, rng)
    shadows = sc.prepare(scene, scene.light, method, device=device)
    unit = shadows.mask(points, normals)
    lengths = rng.uniform(1e-3, 1e3, (len(points), 1))
    assert np.array_equal(shadows.mask(points, normals * lengths), unit)
    assert np.array_equal(sc.shadow_mask(scene, scene.light, points, normals * 7.5, method=method, device=device),
                          sc.shadow_mask(scene, scene.light, points, normals, method=method, device=device))
    normals[17] = 0
    with pytest.raises(ValueError, match=r"normals: zero-length normal at index 17"):
        shadows.mask(points, normals)
    with pytest.raises(ValueError, match=r"normals: zero-length normal at index 17"):
        sc.shadow_mask(scene, scene.light, points, normals, method=method, device=device)


def test_voxel_method_through_prepare(device, rng):
    require_models()
    scene = sc.Scene.load(SCENES / "subdivision" / "torus.toml")
    points, normals = scene_receivers(scene, 3000, rng)
    shadows = sc.prepare(scene, scene.light, "voxel", bounds=box_of(points), device=device, resolution=32)
    mask = shadows.mask(points, normals)
    assert np.array_equal(mask, sc.shadow_mask(scene, scene.light, points, normals, method="voxel", device=device,
                                               resolution=32))
    assert np.array_equal(shadows.mask(points, normals * 4.0), mask)
    assert shadows.params["resolution"] == 32 and shadows.params["frame_buffer"] is True
    assert shadows.stats["device_bytes"] > 0


def test_eps_is_honoured_or_refused_and_listed():
    """Every method either honours eps or refuses one given (the voxel method: its voxel size sets the
    offset), at every public entry point, and sc.methods() says which; the check comes before any work."""
    listing = sc.methods()
    assert all(entry["eps"][1].startswith(("honoured", "not honoured")) for entry in listing.values())
    refusing = [name for name, entry in listing.items() if entry["eps"][1].startswith("not honoured")]
    assert refusing == ["voxel"]
    scene = sc.Scene.load(SCENES / "subdivision" / "torus.toml")
    message = r"eps: the voxel method cannot honour eps"
    with pytest.raises(ValueError, match=message):
        sc.prepare(scene, scene.light, "voxel", eps=1e-3)
    with pytest.raises(ValueError, match=message):
        sc.shadow_mask(scene, scene.light, np.zeros((4, 3)), method="voxel", eps=1e-3)
    with pytest.raises(ValueError, match=message):
        sc.Renderer(scene, "voxel", eps=1e-3)
    with pytest.raises(TypeError, match=r"eps: expected a number"):
        sc.prepare(scene, scene.light, "exact", eps="1e-3")


def test_shadow_volume_points_build_no_volume(device, rng):
    """The point query is the exact method on the light-facing faces: no silhouette, no volume."""
    scene = sc.Scene.load(SCENES / "default.toml")
    points, normals = scene_receivers(scene, 3000, rng)
    shadows = sc.prepare(scene, scene.light, "shadow_volume", device=device)
    shadows.mask(points, normals)
    assert shadows._instance._volume is None
    assert "silhouette_edges" not in shadows.stats and shadows.stats["cap_triangles"] > 0


def with_light(scene, light):
    return sc.Scene(scene.objects, [light], camera=scene.camera, name=scene.name, colors=scene.colors)


LIGHT_PATH = [(-6.0, 3.8, 1.2), (-5.8, 3.9, 1.5), (-5.5, 4.0, 1.9)]


@pytest.mark.parametrize("method, params", [("exact", {}), ("shadow_map", {"resolution": 512}), ("angular", {}),
                                            ("shadow_volume", {"silhouettes": "tracking"})])
def test_renderer_moving_light_matches_render(device, method, params):
    scene = sc.Scene.load(SCENES / "default.toml")
    renderer = sc.Renderer(scene, method, width=96, height=54, device=device, **params)
    for frame, position in enumerate(LIGHT_PATH):
        light = sc.PointLight(position)
        image = renderer.render(light=light)
        fresh = sc.render(with_light(scene, light), method, width=96, height=54, device=device, **params)
        assert np.array_equal(image, fresh), f"{method} frame {frame}"
        assert renderer.report.reused == {"camera": frame > 0, "prepared": [False]}
    again = renderer.render(light=sc.PointLight(LIGHT_PATH[-1]))
    assert np.array_equal(again, image) and renderer.report.reused == {"camera": True, "prepared": [True]}
    if method == "shadow_volume":   # the tracker walked from the last frame instead of testing every face
        assert renderer._slots[0].stats["tracker"]["faces_tested"] != len(scene.mesh.faces)


def test_renderer_moving_camera_keeps_prepared(device):
    scene = sc.Scene.load(SCENES / "default.toml")
    renderer = sc.Renderer(scene, "exact", width=80, height=45, device=device)
    first = renderer.render()
    camera = sc.Camera(scene.camera.position + [0.3, 0.2, 0.0], scene.camera.target, fov=scene.camera.fov)
    moved = renderer.render(camera=camera)
    assert renderer.report.reused == {"camera": False, "prepared": [True] * len(scene.lights)}
    assert "prepare" not in renderer.report.timings and not np.array_equal(first, moved)
    moved_scene = sc.Scene(scene.objects, scene.lights, camera=camera, colors=scene.colors)
    assert np.array_equal(moved, sc.render(moved_scene, "exact", width=80, height=45, device=device))


def test_renderer_voxel_second_view_reuses_frame_buffer(device):
    require_models()
    scene = sc.Scene.load(SCENES / "subdivision" / "torus.toml")
    renderer = sc.Renderer(scene, "voxel", width=64, height=36, device=device, resolution=32)
    renderer.render()
    camera = sc.Camera(scene.camera.position * 1.1, scene.camera.target, fov=scene.camera.fov)
    moved = renderer.render(camera=camera)
    assert renderer.report.reused["prepared"] == [True] * len(scene.lights)
    moved_scene = sc.Scene([(n, s) for n, s in scene.surfaces], scene.lights, camera=camera, colors=scene.colors)
    assert np.array_equal(moved, sc.render(moved_scene, "voxel", width=64, height=36, device=device, resolution=32))


def test_angular_render_builds_one_table_per_view(device):
    """classify_view rebuilds the table for the camera once; the next frame of the same view reuses it."""
    scene = sc.Scene.load(SCENES / "default.toml")
    renderer = sc.Renderer(scene, "angular", width=96, height=54, device=device)
    renderer.render()
    table = renderer._slots[0]._instance.table
    renderer.render()
    assert renderer._slots[0]._instance.table is table


MESH = sc.Mesh([[0, 1, 0], [1, 1, 0], [0, 1, 1]], [[0, 1, 2]])
LIGHT = sc.PointLight((0.2, 3.0, 0.2))
POINTS = np.array([[0.1, 0.0, 0.1], [2.0, 0.0, 2.0]])
BAD_INPUT = [
    (lambda d: sc.prepare("mesh", LIGHT, device=d), TypeError, r"scene_or_mesh"),
    (lambda d: sc.prepare(MESH, (0, 3, 0), device=d), TypeError, r"light"),
    (lambda d: sc.prepare(MESH, LIGHT, "raytrace", device=d), ValueError, r"method: unknown method"),
    (lambda d: sc.prepare(MESH, LIGHT, 3, device=d), TypeError, r"method"),
    (lambda d: sc.prepare(MESH, LIGHT, bounds=[[0, 0, 0]], device=d), ValueError, r"bounds: expected shape \(2, 3\)"),
    (lambda d: sc.prepare(MESH, LIGHT, bounds=[[1, 1, 1], [0, 0, 0]], device=d), ValueError, r"bounds: low corner"),
    (lambda d: sc.prepare(MESH, LIGHT, bounds=[[0, 0, 0], [np.nan, 1, 1]], device=d), ValueError, r"bounds:.*NaN"),
    (lambda d: sc.prepare(MESH, LIGHT, eps=-1, device=d), ValueError, r"eps"),
    (lambda d: sc.prepare(MESH, LIGHT, eps="small", device=d), TypeError, r"eps"),
    (lambda d: sc.prepare(MESH, LIGHT, device=d, colour=1), TypeError, r"colour: not a parameter"),
    (lambda d: sc.prepare(MESH, LIGHT, "shadow_map", device=d, resolution=0), ValueError, r"resolution"),
    (lambda d: sc.prepare(MESH, LIGHT, device=d).mask(np.zeros((2, 2))), ValueError, r"points: expected shape"),
    (lambda d: sc.prepare(MESH, LIGHT, device=d).mask([[0, 0, "x"]]), TypeError, r"points"),
    (lambda d: sc.prepare(MESH, LIGHT, device=d).mask([[0, np.inf, 0]]), ValueError, r"points: contains NaN or inf"),
    (lambda d: sc.prepare(MESH, LIGHT, device=d).mask([[0, 1e39, 0]]), ValueError, r"points: coordinates overflow"),
    (lambda d: sc.prepare(MESH, LIGHT, device=d).mask(POINTS, np.zeros((3, 3))), ValueError, r"normals: expected shape"),
    (lambda d: sc.prepare(MESH, LIGHT, device=d).mask(POINTS, [[0, 1, 0], [0, np.nan, 0]]), ValueError,
     r"normals: contains NaN or inf \(first at index 1\)"),
    (lambda d: sc.prepare(MESH, LIGHT, device=d).visibility(POINTS, [[0, 1, 0], [0, 0, 0]]), ValueError,
     r"normals: zero-length normal at index 1"),
    (lambda d: sc.Renderer(MESH, device=d), TypeError, r"scene"),
    (lambda d: sc.Renderer(sc.Scene.load(SCENES / "default.toml"), "fast", device=d), ValueError, r"method"),
    (lambda d: sc.Renderer(sc.Scene.load(SCENES / "default.toml"), width=0, device=d), ValueError, r"width"),
    (lambda d: sc.Renderer(sc.Scene.load(SCENES / "default.toml"), height=20000, device=d), ValueError, r"height"),
    (lambda d: sc.Renderer(sc.Scene.load(SCENES / "default.toml"), device=d, bias="x"), TypeError, r"bias: not a"),
    (lambda d: sc.Renderer(sc.Scene.load(SCENES / "default.toml"), device=d).render(light="sun"), TypeError, r"light"),
    (lambda d: sc.Renderer(sc.Scene.load(SCENES / "default.toml"), device=d).render(light=[]), ValueError, r"light"),
    (lambda d: sc.Renderer(sc.Scene.load(SCENES / "default.toml"), device=d).render(camera="top"), TypeError,
     r"camera"),
]


@pytest.mark.parametrize("call, error, match", BAD_INPUT)
def test_bad_input(device, call, error, match):
    with pytest.raises(error, match=match):
        call(device)


def test_checked_points_pass_through():

    points = check_points(np.zeros((4, 3), np.float32), np.ones((4, 3)))
    assert check_points(points) is points
    assert points.positions.dtype == np.float64 and points.positions.flags.c_contiguous
    assert np.allclose(np.linalg.norm(points.unit_normals(), axis=1), 1)
    huge = check_points(np.zeros((1, 3)), [[1e300, 1e300, 0]])     # squared length overflows: rescaled
    assert np.allclose(huge.unit_normals(), [[2**-0.5, 2**-0.5, 0]])
    with pytest.raises(TypeError, match="normals"):
        check_points(points, np.ones((4, 3)))


@pytest.mark.parametrize("count", [1, 2, 63, 64, 65, 127, 128, 129, 100_003])
def test_receiver_bounds_at_every_size(rng, count):
    """The wide reduction of shadowcl.points gives the row-wise box at sizes straddling its row width."""

    points = rng.normal(size=(count, 3)) * [1, 1e3, 1e-3]
    box = check_points(points).bounds
    assert np.array_equal(box, np.stack([points.min(axis=0), points.max(axis=0)]))
    points[count // 2, 1] = np.nan
    with pytest.raises(ValueError, match=rf"points: contains NaN or inf \(first at index {count // 2}\)"):
        check_points(points)


def test_an_empty_subset_with_normals_has_empty_unit_normals():
    """Points.unit_normals on an empty subset that has normals: (0, 3), not a TypeError (sqrt of None)."""
    receivers = check_points(np.zeros((3, 3)), np.tile([0.0, 2.0, 0.0], (3, 1)))
    empty = receivers.subset(np.zeros(3, dtype=bool))
    assert empty.unit_normals().shape == (0, 3)
    assert empty.facing_away(sc.PointLight((0, 1, 0))).shape == (0,)


def test_moved_points_are_the_host_move_bit_for_bit_and_read_lazily(rng):
    """The working frame moves receivers lazily (MovedPoints): the same bits as (x - c) * (1 / 2^k) in
    float64, a subset and Points.near the same as on eagerly moved points, and len() reads nothing."""
    from shadowcl.points import MovedPoints, Points, check_points
    world = check_points(rng.uniform(-1e3, 1e3, (5_000, 3)) + 1e6 * rng.normal(size=3), rng.normal(size=(5_000, 3)))
    centre, scale = world.positions[17] + 0.123, 2.0 ** 11
    moved = MovedPoints(world, centre, scale, (world.bounds - centre) / scale)
    assert len(moved) == 5_000 and "positions" not in vars(moved)
    eager = Points((world.positions - centre) / scale, world.normals, moved.bounds)   # as Frame.points
    assert np.array_equal(moved.positions, eager.positions)
    index = rng.choice(5_000, 300, replace=False)
    assert np.array_equal(moved.subset(index).positions, eager.subset(index).positions)
    assert np.array_equal(moved.subset(index).bounds, eager.subset(index).bounds)
    for k in rng.choice(5_000, 20, replace=False):      # boxes round real receivers, of several sizes
        point, reach = eager.positions[k], float(rng.choice([1e-9, 1e-3, 0.1, 0.3]))
        fresh = MovedPoints(world, centre, scale, moved.bounds)
        assert np.array_equal(fresh.near(point, reach), eager.near(point, reach))
        assert "positions" not in vars(fresh)


@pytest.mark.parametrize("with_normals", [True, False], ids=["normals", "no-normals"])
def test_exact_moves_receivers_on_the_device_as_the_host_does(device, rng, with_normals):
    """The exact method fuses the frame's move into its first pass: its masks on MovedPoints equal its
    masks on the same receivers moved on the host first, on a scene far from the origin."""
    from shadowcl.exact import ExactMethod
    from shadowcl.points import MovedPoints, Points, check_points
    from shadowcl.testing import icosphere
    mesh = icosphere(3).moved(-np.array([3e5, -2e5, 1e5]), 1.0)
    points = rng.uniform(-3, 3, (20_000, 3)) * [1, 0, 1] + [3e5, -2e5 - 1.2, 1e5]
    normals = np.tile([0.0, 1.0, 0.0], (len(points), 1)) if with_normals else None
    world = check_points(points, normals)
    centre, scale = 0.5 * (mesh.bounds[0] + mesh.bounds[1]), 4.0
    framed_mesh = mesh.moved(centre, scale)
    moved = MovedPoints(world, centre, scale, (world.bounds - centre) / scale)
    eager = Points(moved.positions.copy(), world.normals, moved.bounds)
    method = ExactMethod(device)
    method.prepare(framed_mesh, sc.PointLight((np.array([3e5, -2e5 + 4, 1e5 + 0.5]) - centre) / scale),
                   moved.bounds, 1e-4)
    lazy = MovedPoints(world, centre, scale, moved.bounds)
    fused = method.classify(lazy)
    assert "positions" not in vars(lazy)          # the device moved them: the host never did
    host = method.classify(eager)
    assert 0.05 < fused.mean() < 0.95 and np.array_equal(fused, host)


def test_bounds_of_many_points_are_reduced_in_parts_alike():
    """From PARALLEL_BOUNDS points the box is reduced in parts on threads: the same box as NumPy's
    axis-0 min and max, and a NaN or inf in the last part is still found, at its index."""
    rng = np.random.default_rng(7)
    points = rng.normal(size=(3 * points_module.PARALLEL_BOUNDS + 17, 3)) * [1.0, 1e3, 1e-3]
    assert np.array_equal(check_points(points).bounds, np.array([points.min(axis=0), points.max(axis=0)]))
    points[len(points) - 5, 2] = np.inf
    with pytest.raises(ValueError, match=rf"points: contains NaN or inf \(first at index {len(points) - 5}\)"):
        check_points(points)


def test_one_shot_exact_reads_the_points_on_the_device_only(device, rng, monkeypatch):
    """shadow_mask's exact call on a device with doubles makes no host pass over the points (no box, no
    finiteness check: the device reads them first), and answers as the structure prepared for their box,
    with receivers beyond the occluders' near box (answered on the host by clipping) among them."""
    from shadowcl.exact import ExactMethod
    assert ExactMethod.checks_receivers_on(device), "PoCL's CPU device has doubles: this path is the one tested"
    scene = sc.Scene.load(SCENES / "default.toml")
    points, normals = scene_receivers(scene, 6000, rng)
    diagonal = float(np.linalg.norm(scene.bounds[1] - scene.bounds[0]))
    points[::50] += rng.normal(size=(120, 3)) * 3 * diagonal          # beyond NEAR: far receivers
    reductions = []
    real = points_module._bounds
    monkeypatch.setattr(points_module, "_bounds", lambda p: reductions.append(len(p)) or real(p))
    for with_normals in (normals, None):
        reductions.clear()
        one_shot = sc.shadow_mask(scene, scene.light, points[1::50], with_normals[1::50] if with_normals is not None
                                  else None, device=device)
        assert len(points[1::50]) not in reductions       # near receivers only: their box never computed
        mixed = sc.shadow_mask(scene, scene.light, points, with_normals, device=device)
        assert len(points) in reductions                  # the far ones sent the host check over them all
        prepared = sc.prepare(scene, scene.light, bounds=box_of(points), device=device).mask(points, with_normals)
        assert np.array_equal(mixed, prepared) and 0.1 < mixed.mean() < 0.9
        assert np.array_equal(one_shot, prepared[1::50])


@pytest.mark.parametrize("value, column, match", [
    (np.nan, 0, r"points: contains NaN or inf \(first at index 17\)"),
    (-np.inf, 2, r"points: contains NaN or inf \(first at index 17\)"),
    (1e39, 1, r"points: coordinates overflow float32"),
    (1e30, 1, r"points: 1 receiver\(s\) lie more than .* \(first at index 17"),
])
def test_one_shot_exact_names_a_bad_point_as_the_host_check(device, rng, value, column, match):
    """The device codes a point it cannot walk (not finite, beyond the near box); the host's own check
    then names it, with the caller's index, as a prepared structure's query does."""
    scene = sc.Scene.load(SCENES / "default.toml")
    points, normals = scene_receivers(scene, 300, rng)
    points[17, column] = value
    prepared = sc.prepare(scene, scene.light, device=device)
    for call in (lambda: sc.shadow_mask(scene, scene.light, points, normals, device=device),
                 lambda: prepared.mask(points, normals)):
        with pytest.raises(ValueError, match=match):
            call()
    normals[40] = 0.0
    points[17, column] = 0.0
    with pytest.raises(ValueError, match=r"normals: zero-length normal at index 40"):
        sc.shadow_mask(scene, scene.light, points, normals, device=device)


@pytest.mark.parametrize("method", TRIANGLE_METHODS)
def test_a_bad_normal_in_a_part_is_named_by_its_index(device, rng, method):
    """Far receivers, and for a bounded method those outside its bounds, are answered apart from the
    others: a bad normal in any part is still named by its index in the caller's array (it was its index
    in the part)."""
    scene = sc.Scene.load(SCENES / "default.toml")
    points, normals = scene_receivers(scene, 300, rng)
    low, high = scene.bounds
    corner = np.stack([low, low + 0.4 * (high - low)])
    outside = np.flatnonzero(np.any((points < corner[0]) | (points > corner[1]), axis=1))
    inside = np.setdiff1d(np.arange(len(points)), outside)
    far = points.copy()
    far[::3] *= 50.0                                          # far: beyond NEAR occluder diagonals
    calls = [lambda p, n: sc.shadow_mask(scene, scene.light, p, n, method=method, device=device),
             lambda p, n: sc.prepare(scene, scene.light, method, device=device).mask(p, n),
             lambda p, n: sc.prepare(scene, scene.light, method, bounds=corner, device=device).mask(p, n)]
    for where, bad in ((far, 40), (far, 41), (points, outside[5]), (points, inside[5])):
        zeroed = normals.copy()
        zeroed[bad] = 0.0
        for call in calls:
            with pytest.raises(ValueError, match=rf"normals: zero-length normal at index {bad}\b"):
                call(where, zeroed)


def test_one_shot_exact_fits_the_points_where_a_single_view_would_miss_them(device, rng, monkeypatch):
    """A point light outside the occluders' box sees them in one perspective view, behind which a point
    would be tested against every triangle: shadow_mask then fits the structure to the points' box (a
    cube of views round the light), as before, and reads their box on the host."""
    from shadowcl.testing import icosphere
    mesh, light = icosphere(3), sc.PointLight((0.1, 3.0, 0.2))
    points = np.concatenate([rng.uniform(-3, 3, (2000, 3)) * [1, 0, 1] + [0, 3.8, 0],      # behind the light
                             rng.uniform(-3, 3, (2000, 3)) * [1, 0, 1] + [0, -1.5, 0]])    # under the sphere
    reductions = []
    real = points_module._bounds
    monkeypatch.setattr(points_module, "_bounds", lambda p: reductions.append(len(p)) or real(p))
    mask = sc.shadow_mask(mesh, light, points, device=device)
    assert len(points) in reductions
    prepared = sc.prepare(mesh, light, bounds=box_of(points), device=device)
    assert np.array_equal(mask, prepared.mask(points)) and prepared.stats["brute_fallback"] == 0
    assert not mask[:2000].any() and 0.05 < mask[2000:].mean() < 0.95
