"""Shadow maps (kernels/shadow_map.cl) against the float64 reference (reference/shadow_map.py) and the exact method.

Tolerances:
- Depth maps: the light's views are drawn by the raster kernel; they match reference/raster.py with
  that file's contract: coverage exactly, depth to DEPTH_RTOL relative (float32 interpolation).
- Visibility: the kernel transforms in float32, the reference in float64. A receiver whose answer
  changes when its texel coordinates move by TEXEL_TOL texels or its distance by DISTANCE_RTOL (relative)
  is a tie (float32 rounding may decide it either way); visibility must be equal everywhere else, and
  ties are counted and bounded.
- Against the exact method, a shadow map is wrong near shadow edges by construction: those tests
  report the error (record_property) and bound it loosely; they do not hide leaks.
"""

import numpy as np
import pytest
import trimesh

import shadowcl as sc
from shadowcl import lightspace
from shadowcl.exact import ExactMethod
from shadowcl.geometry import bounds_diagonal
from shadowcl.methods import default_eps
from shadowcl.shadows import shadow_mask
from shadowcl.metrics import mask_error
from shadowcl.reference import raster as raster_ref
from shadowcl.reference import shadow_map as ref
from shadowcl import shadow_map
from shadowcl.shadow_map import ShadowMapMethod

from test_exact import box, grid_plane, soup_mesh

DEPTH_RTOL = 1e-5
TEXEL_TOL = 2e-3        # float32 texel coordinates at RES <= 512: ~1e-4 texel of rounding, 20x margin
DISTANCE_RTOL = 1e-5    # float32 distances and the depth's reciprocal: ~1e-7, 100x margin
MAX_TIES = 0.01

LIGHTS = {
    "perspective": sc.PointLight((0.3, 4.0, 0.2)),
    "cube": sc.PointLight((0.1, 0.2, 0.05)),
    "orthographic": sc.DirectionalLight((0.2, -1.0, 0.3)),
}


def prepared(device, mesh, light, points, **params):
    method = ShadowMapMethod(device, **params)
    method.prepare(mesh, light, np.stack([points.min(0), points.max(0)]), default_eps(mesh.bounds))
    return method


def random_receivers(rng, n=4000):
    points = rng.uniform(-1.2, 1.2, (n, 3))
    normals = rng.normal(size=(n, 3))
    return points, normals / np.linalg.norm(normals, axis=1, keepdims=True)


def host_maps(method) -> np.ndarray:
    """(V, R, R) the method's depth maps read back; zeros (empty) for a cube face not drawn."""
    maps = method.maps
    return np.stack([np.zeros((maps.resolution,) * 2, np.float32) if d is None else d.read() for d in maps.depth])


def host_triangles(method):
    """(ids, vertices, faces, extent) of a "plane" method for the reference: the (V, R, R) triangle-id maps
    read back (-1 for a face not drawn), the mesh's vertices relative to the maps' origin as float32."""
    maps = method.maps
    ids = np.stack([np.full((maps.resolution,) * 2, -1, np.int32) if d is None
                    else method.device.from_device(d.triangle, d.shape, np.int32) for d in maps.depth])
    vertices = (method._mesh.vertices.astype(np.float64) - maps.origin).astype(np.float32)
    return ids, vertices, method._mesh.faces, np.abs(vertices.astype(np.float64)).max()


def reference_visibility(method, points, normals, **perturbation):
    maps = method.maps
    triangles = host_triangles(method) if method.bias == "plane" else None
    return ref.visibility(points - maps.origin, normals, maps.kind, maps.to_light, maps.views, host_maps(method),
                          method.bias_texels().astype(np.float64), method.bias, method.filter, method.pcf_size,
                          method.dither, method.seed, eps=method.eps, triangles=triangles, **perturbation)


def ties(method, points, normals):
    """Receivers whose reference answer changes under rounding-sized perturbations."""
    base = reference_visibility(method, points, normals)
    moved = [reference_visibility(method, points, normals, perturb=p)
             for p in ((TEXEL_TOL, 0, 0), (-TEXEL_TOL, 0, 0), (0, TEXEL_TOL, 0), (0, -TEXEL_TOL, 0),
                       (0, 0, DISTANCE_RTOL), (0, 0, -DISTANCE_RTOL))]
    return np.any([m != base for m in moved], axis=0)


# Depth maps --------------------------------------------------------------------------------------


@pytest.mark.parametrize("light_name", list(LIGHTS))
def test_depth_maps_match_the_reference_rasterizer(device, rng, light_name):
    mesh = soup_mesh(rng, 60)
    points, _ = random_receivers(rng, 500)
    method = prepared(device, mesh, LIGHTS[light_name], points, resolution=64)
    assert method.maps.kind == light_name
    assert len(method.maps.depth) == (6 if light_name == "cube" else 1)
    for k, depth_map in enumerate(method.maps.depth):
        view, depth = depth_map.view, depth_map.read()
        assert view is method.maps.raster_views[k]
        expected = raster_ref.rasterize(mesh, view)
        assert depth.shape == (64, 64) and depth.dtype == np.float32
        covered = expected.triangle >= 0
        assert np.array_equal(depth > 0, covered & (expected.depth > 0)), f"{light_name} view {k}: coverage"
        # at a depth tie (two fragments within rounding) the kernel may keep the runner-up: its depth
        tied = expected.margin <= DEPTH_RTOL * expected.depth
        error = np.abs(depth - expected.depth)[~tied]
        assert np.all(error <= DEPTH_RTOL * expected.depth[~tied]), f"{light_name} view {k}: max {error.max():.3g}"
        assert tied.sum() <= 0.01 * covered.sum(), f"{light_name} view {k}: {int(tied.sum())} tied texels"
    assert host_maps(method).any()


# Cube faces no receiver reaches ------------------------------------------------------------------------


def test_reached_faces_hold_the_face_of_every_point_in_the_box(rng):
    for _ in range(200):
        bounds = np.sort(rng.uniform(-2, 2, (2, 3)), axis=0)
        eye = rng.uniform(-2.5, 2.5, 3)
        reached = shadow_map.reached_faces(bounds, eye)
        # the box's corners, the points nearest the eye's axes and random points, as the kernel picks faces
        points = np.concatenate([lightspace.box_corners(bounds), np.clip(eye, *bounds)[None],
                                 rng.uniform(*bounds, (500, 3))])
        d = np.abs(points - eye)
        axis = np.where((d[:, 0] >= d[:, 1]) & (d[:, 0] >= d[:, 2]), 0, np.where(d[:, 1] >= d[:, 2], 1, 2))
        face = 2 * axis + ((points - eye)[np.arange(len(points)), axis] < 0)
        assert reached[face].all(), (bounds, eye, reached, np.unique(face))
    # a floor below the light (its box 2.4 to 3.2 below, x from -2 to 6 of it, z from -5 to 3):
    # up is never reached, nor -x (2 across at most, 2.4 down at least)
    floor = np.array([[-4.0, -0.2, -4.0], [4.0, 0.6, 4.0]])
    reached = shadow_map.reached_faces(floor, np.array([-2.0, 3.0, 1.0]))
    assert reached.tolist() == [True, False, False, True, True, True]


def floor_under_a_close_light():
    """A floor with a box on it and a plate above the light, the light close above the floor: a cube
    whose upward face no floor point reaches. The plate shadows points above it."""
    plate = grid_plane(2, 0.3, y=1.6)
    plate = sc.Mesh(plate.vertices + [-1.0, 0.0, 0.4], plate.faces)
    mesh = sc.Mesh.concatenate([grid_plane(8, 3.0), box((-0.5, 0.0, -0.5), (0.5, 0.6, 0.5)), plate])
    return mesh, sc.PointLight((-1.0, 1.2, 0.4))


def test_cube_faces_no_receiver_reaches_are_not_drawn(device, rng, monkeypatch):
    mesh, light = floor_under_a_close_light()
    xz = rng.uniform(-3.0, 3.0, (20000, 2))
    points = np.column_stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]])
    normals = np.tile([0.0, 1.0, 0.0], (len(points), 1))
    method = prepared(device, mesh, light, points, resolution=128)
    assert method.maps.kind == "cube" and method.maps.depth[2] is None          # +y
    assert method.stats["drawn"] == sum(d is not None for d in method.maps.depth) < 6
    got = method.visibility(points, normals)
    assert method.maps.depth[2] is None, "points on the floor never use the upward face"
    monkeypatch.setattr(shadow_map, "reached_faces", lambda bounds, eye: np.ones(6, bool))
    every_face = prepared(device, mesh, light, points, resolution=128)
    assert every_face.stats["drawn"] == 6
    np.testing.assert_array_equal(got, every_face.visibility(points, normals))


def test_a_point_whose_face_was_skipped_draws_it_first(device, rng):
    """The rule for points outside the prepared bounds: classify draws the faces they reach, so the
    answer is the one of all six faces. Points above the plate over the light are in its shadow."""
    mesh, light = floor_under_a_close_light()
    floor = np.column_stack([rng.uniform(-3, 3, 1000), np.zeros(1000), rng.uniform(-3, 3, 1000)])
    method = prepared(device, mesh, light, floor, resolution=128)
    assert method.maps.depth[2] is None
    above = np.column_stack([rng.uniform(-1.05, -0.95, 500), np.full(500, 2.0), rng.uniform(0.35, 0.45, 500)])
    mask = method.classify(above, np.tile([0.0, -1.0, 0.0], (500, 1)))
    assert method.maps.depth[2] is not None
    assert mask.all(), f"{int((~mask).sum())} points above the plate lit"
    assert np.array_equal(mask, exact_mask(device, mesh, light, above, np.tile([0.0, -1.0, 0.0], (500, 1))))


# Texel footprint -----------------------------------------------------------------------------------


@pytest.mark.parametrize("light_name", list(LIGHTS))
def test_texel_footprint_is_a_texels_widest_extent_across_the_ray(device, rng, light_name):
    """The bias unit T (reference.texel_footprint, repeated by the kernel) against the projection itself:
    J, the derivative of the texel coordinates (s, t) with respect to the receiver's position, restricted
    to the plane across the light's ray, maps a lateral step to texels; a texel's widest extent there
    is 1 / (J's smallest singular value). Off the axis the old |d|^2 / (d . forward) over-estimated it."""
    mesh = soup_mesh(rng, 20)
    points, _ = random_receivers(rng, 500)
    method = prepared(device, mesh, LIGHTS[light_name], points, resolution=256)
    maps = method.maps
    relative = points - maps.origin
    perspective = maps.kind != "orthographic"
    checked = 0
    covered = np.zeros(len(points), dtype=bool)
    for record in maps.views.astype(np.float64):
        m = record[:16].reshape(4, 4)
        clip = relative @ m[:, :3].T + m[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):   # the points this view's map covers
            seen = (clip[:, 3] > 0) & np.all(np.abs(clip[:, :2] / clip[:, 3:]) <= 1, axis=1)
        p, c = relative[seen], clip[seen]
        covered |= seen
        half = 0.5 * maps.resolution
        # d(x / w) / dp = (row_x w - x row_w) / w^2; s = (x + 1) R / 2, t = (1 - y) R / 2
        ds = half * (m[0, :3] * c[:, 3:] - c[:, :1] * m[3, :3]) / c[:, 3:] ** 2
        dt = -half * (m[1, :3] * c[:, 3:] - c[:, 1:2] * m[3, :3]) / c[:, 3:] ** 2
        ray = p - maps.to_light if perspective else np.broadcast_to(maps.to_light, p.shape)
        ray = ray / np.linalg.norm(ray, axis=1, keepdims=True)
        across = np.cross(ray, rng.normal(size=3))
        across /= np.linalg.norm(across, axis=1, keepdims=True)
        basis = np.stack([across, np.cross(ray, across)], axis=2)          # (N, 3, 2) orthonormal, across the ray
        jacobian = np.einsum("nkj,nja->nka", np.stack([ds, dt], axis=1), basis)
        expected = 1.0 / np.linalg.svd(jacobian, compute_uv=False)[:, -1]
        got = ref.texel_footprint(p, maps.to_light, np.broadcast_to(record, (len(p), len(record))), perspective)
        # the view record is float32: its size and matrix entries are rounded apart (~6e-8 relative each)
        np.testing.assert_allclose(got, expected, rtol=1e-6)
        checked += len(p)
    # A single view's window is cut to the occluders: a point off it is one whose ray misses their box.
    assert checked >= covered.sum() > 0
    assert not np.any(segment_meets_box(points[~covered], LIGHTS[light_name], mesh.bounds))


def segment_meets_box(points, light, box) -> np.ndarray:
    """bool (N,): the segment from each point to the point light (the ray against a directional light's
    travel) meets ``box`` (slab test, float64)."""
    if isinstance(light, sc.PointLight):
        direction, end = light.position - points, 1.0
    else:
        direction, end = np.broadcast_to(-light.direction, points.shape), np.inf
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (box[0] - points) / direction, (box[1] - points) / direction
    enter = np.fmax(np.nanmax(np.fmin(t0, t1), axis=1, initial=-np.inf), 0.0)
    leave = np.fmin(np.nanmin(np.fmax(t0, t1), axis=1, initial=np.inf), end)
    return enter <= leave


# Shadow test against the reference ------------------------------------------------------------------

SETTINGS = [dict(filter=f, bias=b) for f in ("nearest", "bilinear", "pcf")
            for b in ("constant", "slope", "normal", "plane")]
SETTINGS += [dict(filter="nearest", dither=1, seed=7), dict(filter="pcf", pcf_size=5, dither=1)]


@pytest.mark.parametrize("light_name", list(LIGHTS))
@pytest.mark.parametrize("params", SETTINGS, ids=lambda p: "-".join(f"{k}={v}" for k, v in p.items()))
def test_visibility_matches_reference(device, rng, light_name, params):
    mesh = soup_mesh(rng, 80)
    points, normals = random_receivers(rng)
    method = prepared(device, mesh, LIGHTS[light_name], points, resolution=128, **params)
    for n in (normals, None):
        got = method.visibility(points, n)
        assert got.shape == (len(points),) and got.dtype == np.float32
        expected = reference_visibility(method, points, n)
        tied = ties(method, points, n)
        wrong = np.flatnonzero((np.abs(got - expected) > 1e-6) & ~tied)
        assert len(wrong) == 0, (f"{light_name} {params}: {len(wrong)} receivers differ away from ties, first "
                                 f"{points[wrong[0]].tolist()}: kernel {got[wrong[0]]}, reference {expected[wrong[0]]}")
        assert tied.mean() <= MAX_TIES, f"{light_name} {params}: {int(tied.sum())} ties"
        assert np.array_equal(method.classify(points, n), got < 0.5)
        assert 0.02 < (got < 0.5).mean() < 0.98, "the scene should have both lit and shadowed receivers"


# Hard cases -------------------------------------------------------------------------------------


def exact_mask(device, mesh, light, points, normals):
    method = ExactMethod(device)
    method.prepare(mesh, light, np.stack([points.min(0), points.max(0)]), default_eps(mesh.bounds))
    return method.classify(points, normals)


# Lowest light elevation (degrees above the plane) each setting keeps a lit plane clean at, at its
# default bias: the normal offset has no limit; the slope bias is capped at tan = 16 and a nearest
# texel sits up to 0.71 texel away; the constant bias covers tan <= 2 (elevation >= 27 degrees).
GRAZING_LIMITS = {(b, f): 0.0 for b in ("normal", "plane") for f in ("nearest", "bilinear", "pcf")}
GRAZING_LIMITS.update({("slope", "nearest"): 5.0, ("slope", "bilinear"): 1.0, ("slope", "pcf"): 1.0,
                       ("constant", "nearest"): 27.0, ("constant", "bilinear"): 1.0, ("constant", "pcf"): 27.0})


# Only the elevations each setting is documented to handle clean (GRAZING_LIMITS) are cases.
GRAZING_CASES = [(bias, filter, elevation) for (bias, filter), limit in GRAZING_LIMITS.items()
                 for elevation in (0.5, 3.0, 30.0) if elevation >= limit]


@pytest.mark.parametrize("bias, filter, elevation_degrees", GRAZING_CASES, ids=lambda v: str(v))
def test_grazing_light_on_a_lit_plane_casts_no_self_shadow(device, rng, elevation_degrees, bias, filter):
    """Williams' Figure 1: a lit plane under a grazing light must not shadow itself at the default bias
    (the default setting is plane + nearest), down to the limit of each setting; the plane bias also
    without normals (the others fall back to their constant term without them)."""
    plane = grid_plane(20, 1.0)
    points = np.column_stack([rng.uniform(-0.95, 0.95, 5000), np.zeros(5000), rng.uniform(-0.95, 0.95, 5000)])
    normals = np.tile([0.0, 1.0, 0.0], (len(points), 1))
    e = np.radians(elevation_degrees)
    for light in (sc.DirectionalLight((np.cos(e), -np.sin(e), 0.1)), sc.PointLight((-3.0, 3.0 * np.tan(e), 0.2))):
        method = prepared(device, plane, light, points, resolution=512, bias=bias, filter=filter)
        for given in (normals, None) if bias == "plane" else (normals,):
            mask = method.classify(points, given)
            assert not mask.any(), f"{light}, normals {given is not None}: {int(mask.sum())} self-shadowed points"


SCENES = {
    # a box resting on the floor: peter-panning shows as light leaking under the box's edges
    "contact": (lambda: sc.Mesh.concatenate([grid_plane(4, 3.0), box((-0.5, 0.0, -0.5), (0.5, 1.0, 0.5))]),
                sc.PointLight((2.0, 3.0, 1.0))),
    # a two-sided sheet 1e-6 thick, far thinner than a texel, floating above the floor
    "thin": (lambda: sc.Mesh.concatenate([grid_plane(2, 0.3, y=0.5),
                                          sc.Mesh(grid_plane(2, 0.3, y=0.5 - 1e-6).vertices, grid_plane(2, 0.3).faces[:, ::-1]),
                                          grid_plane(4, 1.5, y=0.0)]),
             sc.PointLight((0.1, 2.0, 0.0))),
}


@pytest.mark.parametrize("scene_name", list(SCENES))
@pytest.mark.parametrize("resolution", [256, 1024])
def test_leaks_are_reported_against_exact(device, rng, scene_name, resolution, record_property):
    build, light = SCENES[scene_name]
    mesh = build()
    xz = rng.uniform(-1.2, 1.2, (20000, 2))
    points = np.column_stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]])
    normals = np.tile([0.0, 1.0, 0.0], (len(points), 1))
    truth = exact_mask(device, mesh, light, points, normals)
    method = prepared(device, mesh, light, points, resolution=resolution)
    mask = method.classify(points, normals)
    error = mask_error(mask, truth)
    record_property("error", error.as_dict())
    print(f"{scene_name} at {resolution}: {error}")
    # Errors live along shadow edges: a band of about a texel. Bounded loosely; the figure is recorded.
    assert error.fraction < 0.02, f"{scene_name} at {resolution}: {error}"
    # A leak (light through an occluder, or a shadow lifted off its caster) lies inside the true shadow;
    # an edge error within a texel of its edge (the nearest texel moves an edge by up to half a texel
    # either way, so about half the edge errors are false light: a count bound cannot tell the two
    # apart). Every falsely lit receiver must have a truly lit point (exact method) within 2 texels on the
    # floor (T / cos, the ray's angle to the floor's normal): probes on circles of 1/4, 1/2, 1 that radius.
    maps = method.maps
    assert maps.kind == "perspective"
    leaks = mask < truth
    if not leaks.any():
        return
    leaked = points[leaks]
    views = np.broadcast_to(maps.views[0].astype(np.float64), (len(leaked), shadow_map.VIEW_FLOATS))
    radius = 2 * ref.texel_footprint(leaked - maps.origin, maps.to_light, views, True) / np.einsum(
        "ij,ij->i", normals[leaks], light.direction_to_light(leaked))
    angles = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    ring = np.stack([np.cos(angles), np.zeros(16), np.sin(angles)], axis=1)
    probes = np.concatenate([leaked[:, None] + (f * radius)[:, None, None] * ring for f in (0.25, 0.5, 1.0)], axis=1)
    probe_normals = np.tile([0.0, 1.0, 0.0], (probes.size // 3, 1))
    lit_nearby = ~exact_mask(device, mesh, light, probes.reshape(-1, 3), probe_normals).reshape(len(leaked), -1)
    far = np.flatnonzero(~lit_nearby.any(axis=1))
    assert len(far) == 0, (f"{scene_name} at {resolution}: {len(far)} light leaks more than 2 texels inside the "
                           f"shadow, first at {leaked[far[0]].tolist()}: {error}")


@pytest.mark.parametrize("bias", ["normal", "plane"])
def test_error_falls_as_resolution_rises(device, rng, bias):
    """On the floor around a box and a sphere of triangles smaller than a texel at 128 (the plane bias is
    exact on the box alone: its few large triangles are all in the map), with and without normals. Measured
    wrong of 20,000 at 128 / 512 / 2048: normal 84 / 34 / 7 with normals; plane 100 / 10 / 2, without 101 / 8 / 1."""
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.25)
    build, light = SCENES["contact"]
    mesh = sc.Mesh.concatenate([build(), sc.Mesh(sphere.vertices + [1.0, 0.6, -0.6], sphere.faces)])
    points, normals = random_receivers(rng, 20000)
    points *= [1.0, 0.0, 1.0]
    normals = np.tile([0.0, 1.0, 0.0], (len(points), 1))
    for given in (normals, None):
        truth = exact_mask(device, mesh, light, points, given)
        errors = [mask_error(prepared(device, mesh, light, points, resolution=r, bias=bias).classify(points, given),
                             truth).wrong for r in (128, 512, 2048)]
        assert errors[0] > errors[1] > errors[2], (given is not None, errors)


def test_dither_is_reproducible_with_a_seed(device, rng):
    mesh = soup_mesh(rng, 80)
    points, normals = random_receivers(rng)
    light = LIGHTS["perspective"]

    def run(seed):
        return prepared(device, mesh, light, points, resolution=64, filter="nearest", dither=1, seed=seed).visibility(points, normals)

    assert np.array_equal(run(3), run(3))
    assert not np.array_equal(run(3), run(4))
    plain = prepared(device, mesh, light, points, resolution=64, filter="nearest").visibility(points, normals)
    assert not np.array_equal(run(3), plain)


def test_shadow_mask_api_and_methods_listing(device, rng):
    mesh = soup_mesh(rng, 80)
    points, normals = random_receivers(rng, 2000)
    mask = shadow_mask(mesh, LIGHTS["perspective"], points, normals, method="shadow_map", device=device, resolution=256)
    assert mask.dtype == bool and mask.shape == (2000,)
    facing_away = np.einsum("ij,ij->i", normals, LIGHTS["perspective"].direction_to_light(points)) <= 0
    assert mask[facing_away].all()
    listed = sc.methods()["shadow_map"]
    assert set(listed) == set(ShadowMapMethod.parameters) | {"eps"}
    assert listed["eps"][1].startswith("honoured")
    assert (listed["bias"][0], listed["filter"][0], listed["resolution"][0]) == ("plane", "nearest", None)
    method = ShadowMapMethod(device)
    assert (method.bias, method.filter, method.resolution) == ("plane", "nearest", None)


# Bad input ----------------------------------------------------------------------------------------

BAD_PARAMS = [
    (dict(dither=1.0), ValueError, "dither: expected one of 0, 1"),
    (dict(bias_scale="2"), TypeError, "bias_scale: expected a number"),
    (dict(resolution=0), ValueError, "resolution"),
    (dict(resolution=1.5), TypeError, "resolution"),
    (dict(bias="huge"), ValueError, "bias"),
    (dict(filter="gauss"), ValueError, "filter"),
    (dict(pcf_size=4), ValueError, "pcf_size"),
    (dict(bias_scale=-1), ValueError, "bias_scale"),
    (dict(dither=2), ValueError, "dither"),
    (dict(seed=-1), ValueError, "seed"),
]


@pytest.mark.parametrize("params, error, message", BAD_PARAMS, ids=[str(p) for p, _, _ in BAD_PARAMS])
def test_bad_parameters_are_named(device, params, error, message):
    with pytest.raises(error, match=message):
        ShadowMapMethod(device, **params)


def test_a_resolution_the_device_cannot_hold_is_a_clear_error(device, rng):
    mesh = soup_mesh(rng, 10)
    points, _ = random_receivers(rng, 10)
    side = int(np.sqrt(device.max_alloc_bytes / 4)) + 1
    with pytest.raises(ValueError, match="resolution: a .* depth map needs .* MiB"):
        prepared(device, mesh, LIGHTS["perspective"], points, resolution=side)


def test_classify_before_prepare_is_an_error(device):
    with pytest.raises(RuntimeError, match="prepare"):
        ShadowMapMethod(device).classify(np.zeros((1, 3)), None)


# render: fractional visibility and Williams' post-filter ----------------------------------------------


def test_render_shades_with_fractional_visibility_and_post_filter(device):
    from types import SimpleNamespace

    from conftest import SCENES
    from shadowcl.render import _box_filter, render_report

    scene = sc.Scene.load(SCENES / "default.toml")
    result = render_report(scene, "shadow_map", width=96, height=54, device=device, filter="pcf", resolution=256)
    assert result.image.shape == (54, 96, 3)
    assert np.array_equal(result.shadow, result.visibility < 0.5)
    assert np.any((result.visibility > 0) & (result.visibility < 1)), "pcf should give penumbra-like fractions"
    filtered = render_report(scene, "shadow_map", width=96, height=54, device=device, post_filter=2, resolution=256)
    assert filtered.visibility.dtype == np.float32
    assert np.any((filtered.visibility > 0) & (filtered.visibility < 1)), "the post-filter should blur shadow edges"

    # the filter averages over covered pixels only (brute force on a small image)
    mask = np.zeros((5, 6), bool)
    mask[1:4, 1:5] = True
    seen = SimpleNamespace(mask=mask, pixel_index=np.flatnonzero(mask))
    values = np.arange(mask.sum(), dtype=np.float64)
    image = np.zeros(mask.shape)
    image.ravel()[seen.pixel_index] = values
    windows = [(slice(max(r - 1, 0), r + 2), slice(max(c - 1, 0), c + 2)) for r, c in zip(*np.nonzero(mask))]
    expected = [image[w][mask[w]].mean() for w in windows]
    np.testing.assert_allclose(_box_filter(seen, values, 1), expected, rtol=1e-6)  # float32 result


def test_single_view_refuses_points_outside_its_bounds(device, rng):
    """Beyond the prepared bounds a single view cannot answer (behind the light, off the window)."""
    mesh = grid_plane(4, 1.0)
    points = np.column_stack([rng.uniform(-0.5, 0.5, 100), np.full(100, -0.5), rng.uniform(-0.5, 0.5, 100)])
    method = prepared(device, mesh, sc.PointLight((0.0, 2.0, 0.0)), points)
    assert method.maps.kind != "cube"
    with pytest.raises(ValueError, match="points: outside the receiver_bounds"):
        method.classify(np.array([[0.0, 3.0, 0.0]]), None)
    with pytest.raises(ValueError, match="points: contains NaN or inf"):
        method.classify(np.array([[0.0, np.nan, 0.0]]), None)


@pytest.mark.parametrize("light", [sc.PointLight((0.4, 3.0, 0.3)), sc.DirectionalLight((0.3, -1.0, 0.2))],
                         ids=["point", "directional"])
def test_eps_is_honoured(device, light):
    """DESIGN.md's eps, as the exact method reads it: a plate eps / 2 above a floor does not shadow the
    floor under eps, and does under eps / 8 (normals or not; the margins, >= eps / 4 along the ray, are
    larger than a texel's depth slope here); the kernel agrees with the reference."""
    floor = sc.Mesh([(-2, 0, -2), (2, 0, -2), (2, 0, 2), (-2, 0, 2)], [(0, 2, 1), (0, 3, 2)])
    rng = np.random.default_rng(5)
    points = np.column_stack([rng.uniform(-0.3, 0.3, 2000), np.zeros(2000), rng.uniform(-0.3, 0.3, 2000)])
    normals = np.broadcast_to([0.0, 1.0, 0.0], points.shape).copy()
    eps = 0.02
    plate = sc.Mesh([(-0.5, eps / 2, -0.5), (0.5, eps / 2, -0.5), (0.5, eps / 2, 0.5), (-0.5, eps / 2, 0.5)],
                    [(0, 2, 1), (0, 3, 2)])
    mesh = sc.Mesh.concatenate([floor, plate])
    for given in (normals, None):
        for e, shadowed in ((eps, False), (eps / 8, True)):
            method = ShadowMapMethod(device, resolution=256, bias_scale=1e-3)
            method.prepare(mesh, light, np.stack([points.min(0), points.max(0)]), e)
            mask = method.classify(points, given)
            exact = sc.shadow_mask(mesh, light, points, given, eps=e, device=device)
            assert np.all(mask == shadowed) and np.all(exact == shadowed), (e, given is None, mask.mean(), exact.mean())
            np.testing.assert_allclose(method.visibility(points, given), reference_visibility(method, points, given),
                                       atol=0)


# Without normals: cube maps, far lights ------------------------------------------------------------


def test_cube_map_without_normals_matches_exact_but_for_edges(device, rng):
    """A light inside the scene (six faces), no normals: the plane bias leaves no acne on the floor,
    the box or the plate (receivers on every surface); the errors left are the map's shadow edges."""
    mesh, light = floor_under_a_close_light()
    triangles = mesh.triangles.astype(np.float64)
    area = np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1)
    pick = rng.choice(len(area), 40000, p=area / area.sum())
    u, v = rng.uniform(size=(2, len(pick)))
    u, v = np.where(u + v > 1, 1 - u, u), np.where(u + v > 1, 1 - v, v)
    points = triangles[pick, 0] + u[:, None] * (triangles[pick, 1] - triangles[pick, 0]) + v[:, None] * (
        triangles[pick, 2] - triangles[pick, 0])
    truth = sc.shadow_mask(mesh, light, points, device=device)
    errors = {}
    for bias in ("plane", "normal"):
        method = prepared(device, mesh, light, points, resolution=512, bias=bias)
        assert method.maps.kind == "cube"
        errors[bias] = mask_error(method.classify(points, None), truth)
    # measured 31 of 40,000 wrong (0.08 %), all false shadow along edges, against 5,241 (13 %) for the normal
    # offset without normals (its constant term alone)
    assert errors["plane"].fraction <= 0.002, errors
    assert errors["normal"].fraction > 10 * errors["plane"].fraction, errors


@pytest.mark.parametrize("distance", [1e2, 1e6])
def test_a_point_light_a_million_scene_sizes_away(device, rng, distance):
    """A sun placed as a point light: the plane bias measures plane distances in the scene's frame, and
    the map's depths run from near to a finite far plane, so the answer is the directional light's
    (at 1e6 scene sizes the rays differ by 1e-6 radians) but for the map's edge band."""
    mesh = sc.Mesh.concatenate([grid_plane(8, 3.0), box((-0.5, 0.0, -0.5), (0.5, 1.0, 0.5))])
    xz = rng.uniform(-3.0, 3.0, (20000, 2))
    points = np.column_stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]])
    normals = np.tile([0.0, 1.0, 0.0], (len(points), 1))
    towards = np.array([0.5, 0.8, 0.3]) / np.linalg.norm([0.5, 0.8, 0.3])
    light = sc.PointLight(tuple(towards * distance * bounds_diagonal(mesh.bounds)))
    truth = sc.shadow_mask(mesh, sc.DirectionalLight(tuple(-towards)), points, normals, device=device)
    assert 0.05 < truth.mean() < 0.5
    for given in (normals, None):
        method = prepared(device, mesh, light, points, resolution=1024)
        assert method.maps.kind == "perspective"
        error = mask_error(method.classify(points, given), truth)
        # the edge band: about a texel (6 / 1024 of the floor) along a shadow outline of ~8 units
        assert error.fraction <= 0.001, (distance, given is not None, error)


def test_window_is_not_cut_to_an_occluder_box_reaching_behind_the_light(device):
    """A single perspective view whose occluders' box reaches behind the light (a quad above it, others
    below) must keep its window: the corners behind project mirrored, and a window cut to them lost
    the shadows of the occluders in front (1,201 of 1,246 shadowed receivers came out lit)."""
    def quad_y(y, x0, x1, z0, z1):
        return np.array([(x0, y, z0), (x1, y, z0), (x1, y, z1), (x0, y, z1)], float)
    parts = [quad_y(-2.9, -0.1, 0.1, -0.1, 0.1), quad_y(-0.5, 0.55, 0.65, -0.2, 0.2), quad_y(1.0, -0.1, 0.1, -0.1, 0.1)]
    mesh = sc.Mesh(np.concatenate(parts), np.concatenate([np.array([[0, 1, 2], [0, 2, 3]]) + 4 * i for i in range(3)]))
    light = sc.PointLight((0.0, 0.0, 0.0))
    rng = np.random.default_rng(0)
    points = np.c_[rng.uniform(-4, 4, 20_000), np.full(20_000, -3.0), rng.uniform(-1.5, 1.5, 20_000)]
    truth = sc.shadow_mask(mesh, light, points, method="exact", device=device)
    for resolution in (512, 2048):
        got = sc.shadow_mask(mesh, light, points, method="shadow_map", device=device, resolution=resolution)
        assert truth.sum() > 1000 and np.count_nonzero(truth & ~got) <= 0.01 * truth.sum(), resolution
