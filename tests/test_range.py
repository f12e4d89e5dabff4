"""The working range (shadowcl/frame.py): scale, offset, distant and touching lights, far receivers.

Every check goes through the public call (``sc.shadow_mask``) on scenes made here (an icosphere over a
ground quad; a manifold3d box minus a sphere), against the float64 brute force
(``shadowcl.reference.exact``) on the same float32 vertices. "Right" means: no receiver differs from
the brute force outside the band where the method may legitimately decide either way
(:func:`shadowcl.testing.wrong_receivers`, shared with bench/redteam.py):

- the float32 band of test_exact.py (segment within FLOAT_BAND of a triangle edge, or its nearest
  hit within FLOAT_BAND of the start or the light): rounding decides there, both answers are right;
- the method's own discretisation band (:data:`METHOD_BAND`): a shadow map's texels, the angular
  method's rows (their errors lie along shadow edges, and the band is the segment's distance to one);
- a point light the method is given as the directional light (beyond its ``point_light_reach``):
  the receivers where the point light's and that directional light's brute force differ.

Refusals must be a ValueError naming the argument (``light:``, ``points:``, ``scene_or_mesh:``).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import shadowcl as sc
from conftest import fuzz
from shadowcl.frame import MAX_RECEIVER_DISTANCE
from shadowcl.methods import method_class
from shadowcl.reference import exact as ref
from shadowcl.testing import wrong_receivers

METHODS = ("exact", "shadow_map", "angular", "shadow_volume")
def ground_scene(occluder: str = "sphere", half: float = 3.0):
    """An occluder over a 2 half x 2 half ground quad at y = 0 (the quad is an occluder too)."""
    if occluder == "sphere":
        import trimesh
        shape = trimesh.creation.icosphere(subdivisions=1)
        v, f = shape.vertices + [0.0, 1.0, 0.0], shape.faces
    else:
        import manifold3d as m3d
        solid = m3d.Manifold.cube((1.6, 1.0, 1.2), center=True) - m3d.Manifold.sphere(0.7, 24).translate((0.5, 0.4, 0))
        mesh = solid.translate((0.3, 1.4, -0.2)).to_mesh()
        v, f = mesh.vert_properties[:, :3], mesh.tri_verts
    n = len(v)
    ground = np.array([[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]])
    return np.concatenate([v, ground]), np.concatenate([f, [[n, n + 2, n + 1], [n, n + 3, n + 2]]])


def ground_points(rng, count: int = 400, half: float = 3.0):
    return np.c_[rng.uniform(-half, half, count), np.zeros(count), rng.uniform(-half, half, count)]


def assert_right(method, mesh, light, points, normals=None, eps=None, what=""):
    """``sc.shadow_mask`` by ``method`` agrees with the brute force outside its free band."""
    mask = sc.shadow_mask(mesh, light, points, normals, method=method, eps=eps)
    truth, wrong = wrong_receivers(method, mesh, light, points, mask, normals, eps)
    assert len(wrong) == 0, f"{method} {what}: {len(wrong)} of {len(points)} wrong outside the band, e.g. {wrong[:5]}"
    return truth


@pytest.fixture(scope="module")
def scene():
    rng = np.random.default_rng(140)
    v, f = ground_scene()
    return v, f, ground_points(rng), np.tile([0.0, 1.0, 0.0], (400, 1))


# lights ---------------------------------------------------------------------------------------------------

def test_directions_normalise_without_overflow_or_underflow():
    for big in (1e200, 1e-200, 1e308):
        d = sc.DirectionalLight((big, -big, 0.0)).direction
        assert np.allclose(d, [2 ** -0.5, -(2 ** -0.5), 0.0], rtol=1e-15)
    for bad in ((0, 0, 0), (np.nan, 0, 1), (np.inf, 0, 0), (1e400, 1, 1)):
        with pytest.raises(ValueError, match="direction:"):
            sc.DirectionalLight(bad)


# scale and offset -----------------------------------------------------------------------------------------

@pytest.mark.parametrize("method", METHODS)
def test_power_of_two_scale_and_any_offset_keep_masks(scene, method):
    """The frame scales by a power of two: a scene scaled by 2^k gives bit-identical masks; across
    1e-12 .. 1e20 and offsets of 1e6 sizes every mask is right."""
    v, f, points, normals = scene
    light = np.array([0.7, 4.0, 0.4])
    masks = [sc.shadow_mask(sc.Mesh(v * s, f), sc.PointLight(light * s), points * s, normals, method=method)
             for s in (2.0 ** -40, 1.0, 2.0 ** 50)]
    assert np.array_equal(masks[0], masks[1]) and np.array_equal(masks[1], masks[2])
    for s, offset in ((1e-12, 0.0), (1e12, 0.0), (1e15, 3e15), (1e20, -1e26), (1.0, 1e6)):
        mesh = sc.Mesh(v * s + offset, f)
        assert_right(method, mesh, sc.PointLight(light * s + offset), points * s + offset, normals,
                     what=f"scale {s:g} offset {offset:g}")


def test_scene_below_the_range_is_refused():
    v, f = ground_scene()
    with pytest.raises(ValueError, match="scene_or_mesh:"):
        sc.shadow_mask(sc.Mesh(v * 1e-32, f), sc.PointLight((0, 1, 0)), np.zeros((1, 3)))


# distant point lights ------------------------------------------------------------------------------------

@pytest.mark.parametrize("method", METHODS)
def test_distant_point_lights_from_1_to_1e9_scene_sizes(scene, method):
    """A point light along (0.3, 1, 0.2) at 1 .. 1e9 scene sizes (and at 1e39, beyond float32), with and
    without normals: right to the method's band, or the directional light's answer where it is one."""
    v, f, points, normals = scene
    mesh = sc.Mesh(v, f)
    direction = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    for sizes in (1.0, 1e2, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9):
        light = sc.PointLight(direction * sizes * 8.5)
        assert_right(method, mesh, light, points, what=f"light at {sizes:g} sizes")
        assert_right(method, mesh, light, points, normals, what=f"light at {sizes:g} sizes, normals")
    truth = assert_right(method, mesh, sc.PointLight((1e39, 4.0, 3e38)), points, what="light at 1e39")
    assert not truth.any()   # grazing along the ground: nothing is shadowed, the sphere is above its ray


# far receivers -------------------------------------------------------------------------------------------

@pytest.mark.parametrize("method", METHODS)
def test_far_receivers_cost_nobody_accuracy(scene, method):
    """10 receivers moved 1e6 away (in several directions), the rest where they were: all right."""
    v, f, points, normals = scene
    mesh = sc.Mesh(v, f)
    moved = points.copy()
    moved[:10] = [[1e6, 0, 0], [-1e6, 0, 3], [0, 0, 1e6], [2, 0, -1e6], [5e5, 0, 5e5], [-7e5, 0, 1e5],
                  [1e6, 0, 1e6], [-1e6, 0, -1e6], [3e5, 0, -9e5], [-2e5, 0, 8e5]]
    light = sc.PointLight((0.7, 4.0, 0.4))
    assert_right(method, mesh, light, moved, what="far receivers")
    assert_right(method, mesh, light, moved, normals, what="far receivers, normals")
    assert_right(method, mesh, sc.DirectionalLight((-0.3, -1.0, -0.2)), moved, what="far receivers, directional")


@pytest.mark.parametrize("method", METHODS)
def test_far_receivers_downstream_of_the_occluders(scene, method):
    """Receivers straight downstream of the occluders 3 .. 1e4 sizes away (shadowed at any distance)
    beside the near ones, under a directional and a point light: all right. Before the shadow map cut
    its windows to the occluders, the second map (fitted to these receivers' 1e4-size box) spread its
    texels so wide that the sphere fell between them: every one lost its shadow (bench/redteam.py)."""
    v, f, points, normals = scene
    mesh = sc.Mesh(v, f)
    centre = 0.5 * (mesh.bounds[0] + mesh.bounds[1])
    size = float(np.linalg.norm(np.ptp(mesh.bounds, 0)))
    for light in (sc.DirectionalLight((-0.3, -1.0, -0.2)), sc.PointLight((0.7, 4.0, 0.4))):
        towards = light.direction if isinstance(light, sc.DirectionalLight) else centre - light.position
        towards = towards / np.linalg.norm(towards)
        moved = points.copy()
        moved[:6] = centre + towards * size * np.array([3.0, 10.0, 30.0, 100.0, 1e3, 1e4])[:, None]
        truth = assert_right(method, mesh, light, moved, what=f"downstream receivers, {light}")
        assert truth[:6].all()
        assert_right(method, mesh, light, moved, np.tile([0.0, 1.0, 0.0], (len(moved), 1)),
                     what=f"downstream receivers, {light}, normals")


@pytest.mark.parametrize("method", METHODS)
def test_receivers_far_behind_a_solid_stay_shadowed(method):
    """Receivers 1e3 .. 1e8 units (to 3e7 scene sizes, inside the working range) behind a unit sphere,
    whose segments to the light go through its core: all in shadow, with and without normals, under a
    directional and a point light. Before far segments were clipped to the occluders' box, a float32
    start that far had lost the triangles' size: 299 of 300 came back lit at 1e7 (docs/known-defects.md)."""
    import trimesh
    sphere = trimesh.creation.icosphere(3, radius=1.0)
    mesh = sc.Mesh(sphere.vertices, sphere.faces)
    targets = np.random.default_rng(0).uniform(-0.5, 0.5, (300, 3))
    for light in (sc.DirectionalLight((0.3, 0.2, -1.0)), sc.PointLight((0.3, 0.2, 4.0))):
        away = light.direction if isinstance(light, sc.DirectionalLight) else targets - light.position
        away = away / np.linalg.norm(away, axis=-1, keepdims=True)
        for distance in (1e3, 1e5, 1e7, 1e8):
            points = targets + distance * away
            truth = assert_right(method, mesh, light, points, what=f"{light} at {distance:g}")
            assert truth.all()
            assert_right(method, mesh, light, points, np.broadcast_to(-away, points.shape),
                         what=f"{light} at {distance:g}, normals")


@pytest.mark.parametrize("method", METHODS)
def test_far_point_light_and_a_wide_receiver_grid(method):
    """A point light ~3e4 sizes away (beyond exact's reach: used as directional near the occluders) and
    a 41 x 41 receiver grid over +-100 just under the sphere: answered, right. The fit once cut the box
    to a cube round the occluders' centre, which dropped the grid's plane, and the receiver 1 unit under
    the sphere was refused as 'not parallel' (docs/known-defects.md)."""
    import trimesh
    sphere = trimesh.creation.icosphere(2, radius=1.0)
    mesh = sc.Mesh(sphere.vertices, sphere.faces)
    light = sc.PointLight((1e4, 2e4, 1e5))
    x, y = np.meshgrid(np.linspace(-100, 100, 41), np.linspace(-100, 100, 41))
    points = np.concatenate([[[-0.2, -0.4, -2.0]], np.c_[x.ravel(), y.ravel(), np.full(x.size, -2.0)]])
    truth = assert_right(method, mesh, light, points, what="wide grid")
    assert truth[0] and truth.sum() < 10


def test_point_light_thousands_of_sizes_away_on_fine_grids():
    """A point light 300 .. 1.6e4 scene sizes away (within exact's reach) and receivers 1-5 units behind
    a 5120-triangle sphere, on grids of 256 to 4096 cells a side: right. The views' rows once acted on
    p - light in float32, which rounds by ulp(|light|): at 2.8e3 sizes that moved points by several
    fine cells, and a receiver shadowed 3.7e-4 sizes inside a triangle lost it from its fine cell."""
    import trimesh
    sphere = trimesh.creation.icosphere(4, radius=1.0)
    mesh = sc.Mesh(sphere.vertices + [5.0, -3.0, 2.0], sphere.faces)
    rng = np.random.default_rng(7)
    towards = np.array([0.31, 0.1, 0.95]) / np.linalg.norm([0.31, 0.1, 0.95])
    for sizes in (3e2, 2.8e3, 1.6e4):
        light = sc.PointLight(mesh.bounds.mean(0) + towards * sizes * 3.46)
        points = mesh.bounds.mean(0) - towards * rng.uniform(1.0, 5.0, (400, 1)) + rng.uniform(-1.2, 1.2, (400, 3))
        for resolution in (256, 2048, 4096):
            mask = sc.shadow_mask(mesh, light, points, resolution=resolution)
            truth, wrong = wrong_receivers("exact", mesh, light, points, mask, None, None)
            assert len(wrong) == 0, f"{sizes:g} sizes, {resolution}: {len(wrong)} wrong, e.g. {wrong[:5]}"
            assert 50 < truth.sum() < 390


def test_receivers_beyond_the_range_are_refused_by_index(scene):
    v, f, points, _ = scene
    far = points.copy()
    far[7] = [0.0, 0.0, 1e3 * MAX_RECEIVER_DISTANCE]
    with pytest.raises(ValueError, match=r"points: 1 receiver\(s\).*index 7"):
        sc.shadow_mask(sc.Mesh(v, f), sc.PointLight((0.7, 4.0, 0.4)), far)


def test_distant_light_prepared_for_bounds_and_points_beyond_them(scene):
    """A light taken as directional for the prepared bounds is not parallel for receivers beyond them:
    those more than a scene size away are answered from where their segment enters the occluders' box
    (the light is parallel there); a nearer one, for which it is not, from a second structure fitted
    to it, for which the light is within the method's reach. Every answer right, none refused."""
    v, f, points, _ = scene
    mesh, light = sc.Mesh(v, f), sc.PointLight((0.0, 2e5, 0.0))   # 2.3e4 sizes: beyond exact's reach
    eps = 1e-4 * np.linalg.norm(np.ptp(mesh.bounds, 0))
    far = np.array([[0.0, 0.0, 1e5], [0.0, -1e6, 0.0], [9.0, -2e5, 0.0]])   # beside the ground; below; beside
    near = np.array([[0.0, -1.0, 1.0], [0.0, 0.0, 11.0], [0.0, 3.0, 8.0]])  # under the ground; 8 beside it
    truth = ref.shadow_mask(mesh.vertices, mesh.faces, light, np.concatenate([far, near]), None, eps)
    assert truth.tolist() == [False, True, False, True, False, False]
    for method in ("exact", "shadow_map"):
        shadows = sc.prepare(mesh, light, method)
        assert np.array_equal(shadows.mask(far), truth[:3]), method
        assert np.array_equal(shadows.mask(near), truth[3:]), method
        assert np.array_equal(shadows.mask(np.concatenate([points, far, near]))[-6:], truth), method


# lights on, near and inside geometry ---------------------------------------------------------------------

def touching_lights(v, f):
    """Point lights on a face, an edge, a vertex, 1e-6 off a face, in the ground plane (an occluder)."""
    mesh = sc.Mesh(v, f)
    a, b, c = mesh.triangles[3]
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal)
    return {"on a face": (a + b + c) / 3, "on an edge": (a + b) / 2, "on a vertex": a,
            "1e-6 off a face": (a + b + c) / 3 + 1e-6 * normal, "in the ground plane": np.array([1.2, 0.0, -0.7])}


@pytest.mark.parametrize("method", METHODS)
def test_lights_touching_the_occluders(scene, method):
    """Right (exact) or refused naming the light (angular, shadow volume, shadow map: their clearance)."""
    v, f, points, normals = scene
    mesh = sc.Mesh(v, f)
    clearance = method_class(method).min_light_clearance
    for where, position in touching_lights(v, f).items():
        light = sc.PointLight(position)
        if clearance > 0:
            with pytest.raises(ValueError, match="light: the point light .* lies within"):
                sc.shadow_mask(mesh, light, points, method=method)
        else:
            assert_right(method, mesh, light, points, what=where)
            assert_right(method, mesh, light, points, normals, what=where + ", normals")
    # Just beyond the clearance every method answers, and right.
    a, b, c = mesh.triangles[3]
    normal = np.cross(b - a, c - a)
    off = (a + b + c) / 3 + 2 * max(clearance, 1e-6) * 8.5 * normal / np.linalg.norm(normal)
    assert_right(method, mesh, sc.PointLight(off), points, what="just beyond the clearance")


@pytest.mark.parametrize("method", METHODS)
def test_light_in_a_receiving_plane_that_is_not_an_occluder(method):
    """Receivers on a plane that occludes nothing, the light in that plane: every method right."""
    rng = np.random.default_rng(11)
    v, f = ground_scene()
    mesh = sc.Mesh(v[:-4], f[:-2])        # the sphere alone
    points = ground_points(rng)
    assert_right(method, mesh, sc.PointLight(points[11]), points, what="light in the receivers' plane")


@pytest.mark.parametrize("method", METHODS)
def test_light_inside_a_closed_solid(scene, method):
    """Inside the sphere everything outside is shadowed: right, or refused by the angular method."""
    v, f, points, _ = scene
    light = sc.PointLight((0.1, 1.05, -0.2))
    if method == "angular":
        with pytest.raises(ValueError, match="light: the point light is inside a closed solid"):
            sc.shadow_mask(sc.Mesh(v, f), light, points, method=method)
    else:
        assert assert_right(method, sc.Mesh(v, f), light, points, what="inside the sphere").all()


# eps ---------------------------------------------------------------------------------------------------

def test_huge_eps_is_honoured_by_the_shadow_map_and_refused_by_voxel(scene):
    """eps = 1e6 (far beyond the scene): no hit is beyond eps, so nothing facing the light is shadowed."""
    v, f, points, normals = scene
    mesh, light = sc.Mesh(v, f), sc.PointLight((0.7, 4.0, 0.4))
    assert sc.shadow_mask(mesh, light, points, method="exact").any()       # the scene does cast shadows
    for method in ("exact", "shadow_map"):
        truth = assert_right(method, mesh, light, points, normals, eps=1e6, what="eps=1e6")
        assert not truth.any()
    with pytest.raises(ValueError, match="eps: the voxel method cannot honour eps"):
        sc.prepare(mesh, light, "voxel", eps=1e6)



@pytest.mark.parametrize("method", METHODS)
def test_eps_beyond_the_working_range_is_refused(scene, method):
    """An eps of more than MAX_RECEIVER_DISTANCE scene sizes is refused by name (it had leaked float32
    overflow warnings from the exact method, whose start p + eps n then overflowed)."""
    v, f, points, normals = scene
    mesh = sc.Mesh(v, f)
    limit = MAX_RECEIVER_DISTANCE * np.linalg.norm(np.ptp(mesh.bounds, axis=0))
    for eps in (1e300, 2.0 * limit):
        with pytest.raises(ValueError, match="eps: .* outside the working range"):
            sc.shadow_mask(mesh, sc.PointLight((0.7, 4.0, 0.4)), points, normals, method=method, eps=eps)
    assert_right(method, mesh, sc.PointLight((0.7, 4.0, 0.4)), points, normals, eps=0.5 * limit, what="eps at half the limit")

# the fuzz test -------------------------------------------------------------------------------------------

PLACEMENTS = ("above", "far", "very far", "on a vertex", "near a face", "inside", "directional")


@fuzz(96)
@given(method=st.sampled_from(METHODS), occluder=st.sampled_from(("sphere", "box_minus_sphere")),
       log_scale=st.floats(-12.0, 15.0), offset=st.floats(-1e3, 1e3), placement=st.sampled_from(PLACEMENTS),
       seed=st.integers(0, 2 ** 16), normals=st.booleans(), far_receivers=st.booleans())
def test_fuzz_right_or_a_clear_error(method, occluder, log_scale, offset, placement, seed, normals, far_receivers):
    """Any scale 1e-12 .. 1e15, offset up to 1e3 scene sizes, light placement, method, and 5 receivers
    moved 1e3 .. 1e8 away on the ground's plane or not: the brute force's answer to the method's band,
    or a ValueError naming the argument."""
    rng = np.random.default_rng(seed)
    v, f = ground_scene(occluder)
    points = ground_points(rng, 200)
    if far_receivers:
        angle = rng.uniform(0, 2 * np.pi, 5)
        points[:5] = np.c_[np.cos(angle), np.zeros(5), np.sin(angle)] * 10 ** rng.uniform(3, 8, (5, 1))
    triangle = sc.Mesh(v, f).triangles[rng.integers(len(f) - 2)]
    normal = np.cross(triangle[1] - triangle[0], triangle[2] - triangle[0])
    normal /= np.linalg.norm(normal)
    centre = triangle.mean(0)
    position = {"above": rng.uniform([-2, 2.5, -2], [2, 5, 2]),
                "far": np.array([0.2, 1, 0.3]) * 10 ** rng.uniform(1, 7),
                "very far": np.array([0.2, 1, -0.3]) * 10 ** rng.uniform(7, 30), "on a vertex": triangle[0],
                "near a face": centre + 10 ** rng.uniform(-7, -2) * normal, "inside": np.array([0.4, 1.4, -0.2]),
                "directional": None}[placement]
    scale, shift = 10.0 ** log_scale, offset * 10.0 ** log_scale
    mesh = sc.Mesh(v * scale + shift, f)
    light = (sc.DirectionalLight(rng.normal(size=3) * [1, 0, 1] - [0, 1, 0]) if position is None
             else sc.PointLight(np.asarray(position) * scale + shift))
    pts = points * scale + shift
    # Without normals a shadow map's receivers on an occluder (the ground) are decided by its bias, a
    # matter of the map not of the range: at a 30-degree directional light 16 of 200 self-shadow at any
    # scale (seed 12140), none with normals; the fixed tests above check it without normals.
    nrm = np.tile([0.0, 1.0, 0.0], (len(pts), 1)) if normals or method == "shadow_map" else None
    try:
        assert_right(method, mesh, light, pts, nrm, what=f"{placement} x{scale:.3g} +{shift:.3g}")
    except ValueError as error:
        # A refusal only where a rule of the working range allows one (README "Working range"): a light on,
        # near or inside the occluders for the methods that declare a clearance or refuse a light inside.
        allowed = set()
        if method in ("angular", "shadow_volume", "shadow_map") and placement in ("on a vertex", "near a face", "inside"):
            allowed.add("light")
        assert str(error).split(":")[0] in allowed, error
