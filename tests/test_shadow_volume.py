"""Shadow volumes: the volume against its float64 reference, the stencil kernel against reference
fragments, render and shadow_mask against the exact answer (z-fail and z-pass, camera outside and
inside a volume), the hard cases, open and non-manifold meshes, bad input."""

import tempfile
from pathlib import Path

import numpy as np
import pytest

import shadowcl as sc
from shadowcl import raster
from shadowcl.geometry import bounds_diagonal
from shadowcl.testing import icosphere
from shadowcl.methods import create_method, default_eps
from shadowcl.reference import exact as exact_ref
from shadowcl.reference import raster as raster_ref
from shadowcl.reference import shadow_volume as reference
from shadowcl.reference.silhouette import tie_faces
from shadowcl.render import camera_view, render_report
from shadowcl.shadow_volume import ShadowVolumeMethod, two_sided
from shadowcl.silhouette import silhouette_edges

from conftest import SCENES, require_models

SHIPPED = sorted(SCENES.glob("*.toml")) + sorted((SCENES / "hard").glob("*.toml"))
BROKEN = {"coplanar", "degenerate", "non_manifold"}    # scenes with non-manifold edges: faces detached
LIGHTS = {"point": sc.PointLight((1.5, 4.0, 2.0)), "directional": sc.DirectionalLight((-0.3, -1.0, -0.4))}


def blobs(rng, open_cap: bool) -> sc.Mesh:
    """Two perturbed icospheres (closed) above a ground quad (open); with ``open_cap`` the second
    sphere loses its top faces, an open bowl that shadows through its inside."""
    parts = [sc.Mesh([[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], [[0, 2, 1], [0, 3, 2]])]
    for centre in ((-0.8, 1.2, 0.3), (0.9, 1.6, -0.4)):
        ball = icosphere(2)
        vertices = ball.vertices * (0.6 + 0.05 * rng.standard_normal((len(ball.vertices), 1))) + centre
        faces = ball.faces
        if open_cap and centre[0] > 0:
            faces = faces[ball.vertices[faces].mean(axis=1)[:, 1] < 0.6]
        parts.append(sc.Mesh(vertices, faces))
    return sc.Mesh.concatenate(parts)


def canonical(faces) -> np.ndarray:
    """Triangles as index triples rotated to start at their least index, rows sorted: a set to compare."""
    faces = np.asarray(faces, dtype=np.int64)
    turn = np.argmin(faces, axis=1)
    rows = np.arange(len(faces))[:, None]
    rotated = faces[rows, (turn[:, None] + np.arange(3)) % 3]
    return rotated[np.lexsort(rotated.T[::-1])]


def prepared(device, mesh, light, box, **params) -> ShadowVolumeMethod:
    method = ShadowVolumeMethod(device, **params)
    method.prepare(mesh, light, box, default_eps(mesh.bounds))
    return method


def silhouette_distance(method, light, points, normals, eps) -> np.ndarray:
    """Distance from each receiver's tested segment to the nearest silhouette edge (float64), through
    the reference's segment/edge distance with each edge as the degenerate triangle (a, b, b)."""
    edges = method.volume.silhouette
    faces = np.stack([edges[:, 0], edges[:, 1], edges[:, 1]], axis=1)
    return exact_ref.segment_edge_distance(method.occluders.vertices, faces, light, points, normals, eps)


# The volume against the reference ---------------------------------------------------------------

@pytest.mark.parametrize("open_cap", [False, True], ids=["closed", "open"])
@pytest.mark.parametrize("kind", sorted(LIGHTS))
def test_volume_matches_reference(device, rng, kind, open_cap):
    mesh, light = blobs(rng, open_cap), LIGHTS[kind]
    box = np.array([[-4.0, 0.0, -4.0], [4.0, 2.5, 4.0]])
    method = prepared(device, mesh, light, box)
    vertices_ref, faces_ref = reference.two_sided(mesh.vertices, mesh.faces)
    doubled = method.occluders
    assert np.array_equal(doubled.vertices, vertices_ref.astype(np.float32)), "two-sided vertices"
    assert np.array_equal(canonical(doubled.faces), canonical(faces_ref)), "two-sided faces"
    # open: the ground and the bowl; the whole sphere (320 faces) stays one-sided
    assert len(two_sided(mesh).open_faces) == (len(mesh.faces) - 320 if open_cap else 2)
    # Facing decided in float32 on the device, float64 here: random shapes have no face in the tie band.
    assert len(tie_faces(doubled.vertices, doubled.faces, light)) == 0
    facing = np.zeros(len(doubled.faces), dtype=bool)
    facing[method.volume.cap] = True
    assert np.array_equal(facing, reference.facing(doubled.vertices, doubled.faces, light))
    volume_vertices, volume_faces = reference.volume(doubled.vertices, doubled.faces, light, method.volume.extrusion)
    assert np.array_equal(canonical(method.volume.mesh.faces), canonical(volume_faces)), "volume faces"
    # Far corners are float32 roundings of the float64 ones: relative 2^-24 of their distance from the origin.
    scale = np.abs(volume_vertices).max(axis=1, keepdims=True)
    assert np.all(np.abs(method.volume.mesh.vertices - volume_vertices) <= 2.0**-23 * scale)


@pytest.mark.parametrize("open_cap", [False, True], ids=["closed", "open"])
@pytest.mark.parametrize("kind", sorted(LIGHTS))
def test_volume_is_closed_and_its_count_is_the_exact_shadow(device, rng, kind, open_cap):
    """The reference winding number of the method's own volume: the same along two random directions
    (the volume is closed and consistently wound), never negative, nonzero exactly where the exact
    reference says shadow; the method's per-point count (classify) says the same."""
    mesh, light = blobs(rng, open_cap), LIGHTS[kind]
    box = np.array([[-4.0, 0.0, -4.0], [4.0, 2.5, 4.0]])
    method = prepared(device, mesh, light, box)
    points = np.concatenate([rng.uniform(box[0], box[1], (600, 3)),
                             np.c_[rng.uniform(-4, 4, 600), np.full(600, 0.01), rng.uniform(-4, 4, 600)]])
    triangles = method.volume.mesh.triangles.astype(np.float64)
    first, second = (reference.winding_numbers(triangles, points, d) for d in rng.standard_normal((2, 3)))
    assert np.array_equal(first, second), "winding depends on the direction: the volume is not closed"
    assert first.min() >= 0 and first.max() >= 1
    # The winding number is the pure geometric answer (eps = 0: no hit ignored near the point); the two
    # may differ only where a segment grazes a silhouette (float32 far corners, float64 ties).
    geometric = exact_ref.shadow_mask(mesh.vertices, mesh.faces, light, points, eps=0.0)
    differ = np.flatnonzero((first != 0) != geometric)
    assert np.all(silhouette_distance(method, light, points[differ], None, 0.0) < 1e-9)
    eps = default_eps(mesh.bounds)
    truth = exact_ref.shadow_mask(mesh.vertices, mesh.faces, light, points, eps=eps)
    mask = method.classify(points)
    band = 2e-6 * bounds_diagonal(box)                     # the exact method's float32 band (test_render.py)
    differ = np.flatnonzero(mask != truth)
    assert np.all(exact_ref.segment_edge_distance(mesh.vertices, mesh.faces, light, points[differ], eps=eps) < band)
    assert truth.any() and not truth.all()


# The stencil kernel against reference fragments ---------------------------------------------------

def reference_stencil(device, volumes, view, zbuffer, cap_faces, zfail) -> tuple[np.ndarray, np.ndarray]:
    """Stencil from the reference rasterizer's fragments of the kernel's own clipped corners, and the
    pixels where a fragment's depth is within float32 rounding of the surface (either way is right).
    A cap triangle over the pixel where its own face is visible is exactly at the surface: behind."""
    polygons = raster.screen_polygons(device, volumes, view)
    depth = zbuffer.depth.ravel().astype(np.float64)
    visible = zbuffer.triangle.ravel()
    count = np.zeros(view.width * view.height, dtype=np.int64)
    unsure = np.zeros(view.width * view.height, dtype=bool)
    for i in range(len(polygons.count)):
        n = polygons.count[i]
        xy, z = polygons.xy[i, :n].astype(np.int64), polygons.depth[i, :n].astype(np.float64)
        for k in range(1, n - 1):
            fan = [0, k, k + 1]
            a, b, c = xy[fan]
            area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
            pixels, fragment = raster_ref.triangle_fragments(xy[fan], z[fan], view.width, view.height)
            winding = 1 if area > 0 else -1
            own = (i < len(cap_faces)) & (visible[pixels] == cap_faces[i % len(cap_faces)])
            behind = own | (fragment < depth[pixels])
            unsure[pixels[~own & (np.abs(fragment - depth[pixels]) <= 1e-5 * depth[pixels])]] = True
            if zfail:
                np.add.at(count, pixels[behind], winding)
            else:
                np.add.at(count, pixels[~behind], -winding)
    return count.reshape(view.height, view.width), unsure.reshape(view.height, view.width)


@pytest.mark.parametrize("stencil", ["zfail", "zpass"])
def test_stencil_matches_reference_fragments(device, rng, stencil):
    mesh, light = blobs(rng, False), LIGHTS["point"]
    view = sc.Camera((3.0, 3.5, 5.0), (0.0, 0.8, 0.0)).view(64, 48, near=0.05)
    method = prepared(device, mesh, light, mesh.bounds)
    zbuffer = raster.rasterize(device, mesh, view)
    kernel = raster.stencil(device, method.volume.mesh, view, zbuffer, zfail=stencil == "zfail")
    expected, unsure = reference_stencil(device, method.volume.mesh, view, zbuffer, method.volume.cap,
                                         stencil == "zfail")
    covered = zbuffer.mask & ~unsure
    assert covered.sum() > 0.9 * zbuffer.mask.sum()
    assert np.array_equal(kernel[covered], expected[covered])
    assert np.any(kernel[covered] != 0)


def test_stencil_keeps_the_raster_passes_unchanged(device, rng):
    """The stencil is an extra pass: the Z-buffer of the same mesh is bit-identical before and after."""
    mesh = blobs(rng, False)
    view = sc.Camera((3.0, 3.5, 5.0), (0.0, 0.8, 0.0)).view(48, 32, near=0.05)
    before = raster.rasterize(device, mesh, view)
    volume = prepared(device, mesh, LIGHTS["point"], mesh.bounds).volume.mesh
    raster.stencil(device, volume, view, before)
    after = raster.rasterize(device, mesh, view)
    assert np.array_equal(before.depth, after.depth) and np.array_equal(before.triangle, after.triangle)


# render and shadow_mask against the exact answer --------------------------------------------------

def footprint(scene, view, points) -> np.ndarray:
    """World size of one pixel at each point (perspective camera)."""
    distance = np.linalg.norm(points - scene.camera.position, axis=1)
    return distance * 2 * np.tan(np.radians(scene.camera.fov) / 2) / view.height


def assert_render_matches_exact(scene, device, stencils=("zfail", "zpass"), width=64, height=36):
    """Render's stencil mask equals the exact method's (tested against the float64 brute force in
    test_render.py) except where the receiver's segment passes within a quarter of a pixel's
    footprint plus 2 eps of a silhouette edge: the stencil decides with volume faces snapped to 1/256
    pixel and depths interpolated over snapped triangles, and at the point of the pixel's ray nearest
    to the receiver moved eps along its normal (up to eps from where the exact answer starts its
    segment). Measured: at most 0.3 footprint at 960 x 540 on the model scenes, where eps is half a
    pixel's footprint."""
    exact = render_report(scene, method="exact", width=width, height=height, device=device)
    for stencil in stencils:
        result = render_report(scene, method="shadow_volume", width=width, height=height, device=device,
                               stencil=stencil)
        assert np.array_equal(result.receivers.pixel_index, exact.receivers.pixel_index)
        assert_near_silhouettes(scene, device, result, exact.shadow, width, height)
    return result


def assert_near_silhouettes(scene, device, result, exact_shadow, width, height):
    seen = result.receivers
    eps = default_eps(scene.bounds)
    view = camera_view(scene, width, height)
    for light, shadow, truth in zip(scene.lights, result.shadow, exact_shadow):
        differ = np.flatnonzero(shadow != truth)
        if len(differ):
            method = prepared(device, scene.mesh, light, scene.bounds)
            distance = silhouette_distance(method, light, seen.points[differ], seen.normals[differ], eps)
            band = 0.25 * footprint(scene, view, seen.points[differ]) + 2 * eps
            away = np.count_nonzero(distance >= band)
            assert away == 0, f"{away} receivers differ away from silhouettes"
        assert len(differ) <= 1e-3 * len(truth) + 10


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.relative_to(SCENES).as_posix())
def test_render_matches_exact_on_hard_cases(path, device):
    scene = sc.Scene.load(path)
    assert (len(two_sided(scene.mesh).detached_faces) > 0) == (path.stem in BROKEN)
    assert_render_matches_exact(scene, device)


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.relative_to(SCENES).as_posix())
def test_shadow_mask_matches_exact_on_hard_cases(path, device, rng):
    scene = sc.Scene.load(path)
    tri = scene.mesh.triangles.astype(np.float64)
    pick = rng.integers(0, len(tri), 400)
    w = rng.dirichlet(np.ones(3), 400)
    points = np.einsum("nk,nkj->nj", w, tri[pick])
    normals = np.cross(tri[pick, 1] - tri[pick, 0], tri[pick, 2] - tri[pick, 0])
    keep = np.linalg.norm(normals, axis=1) > 0
    points, normals = points[keep], normals[keep]
    light = scene.lights[0]
    mask = sc.shadow_mask(scene, light, points, normals, method="shadow_volume", device=device)
    eps = default_eps(scene.mesh.bounds)
    truth = exact_ref.shadow_mask(scene.mesh.vertices, scene.mesh.faces, light, points, normals, eps=eps)
    band = 2e-6 * bounds_diagonal(scene.bounds)            # the exact method's float32 band (test_render.py)
    differ = np.flatnonzero(mask != truth)
    near = exact_ref.segment_edge_distance(scene.mesh.vertices, scene.mesh.faces, light, points[differ],
                                           normals[differ], eps) < band
    assert np.all(near), f"{np.count_nonzero(~near)} points differ away from edges"


def plate_scene(camera_position) -> sc.Scene:
    """A thick plate high above the ground under a light straight above it: the camera goes under it."""
    text = f"""
name = "plate"
[camera]
position = {list(camera_position)}
target = [2.0, 0.0, 0.5]
fov = 60
[[lights]]
type = "point"
position = [0.0, 8.0, 0.0]
[[objects]]
name = "ground"
box = {{ size = [14, 0.2, 14], center = true }}
translate = [0, -0.1, 0]
[[objects]]
name = "plate"
box = {{ size = [3, 0.3, 3], center = true }}
translate = [0, 3.0, 0]
"""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "plate.toml"
        path.write_text(text)
        return sc.Scene.load(path)


def test_camera_inside_a_volume(device):
    """The eye in the plate's shadow, under it: z-fail needs nothing; z-pass starts from the eye's
    winding number (1 here) and still matches the exact answer."""
    scene = plate_scene((0.3, 1.0, 0.2))
    method = prepared(device, scene.mesh, scene.lights[0], scene.bounds)
    view = camera_view(scene, 64, 36)
    assert method.volume.mesh is not None and method._eye_winding(view) == 1
    result = assert_render_matches_exact(scene, device)
    assert result.shadow.any() and not result.shadow.all()


def test_eye_winding_through_an_edge_two_cap_faces_share(device):
    """Regression: the eye straight under the light, so its segment to the light passes through the
    diagonal the plate's top (and bottom) square is split along; counted along that segment through the
    caps the eye's winding number came out 2, and z-pass drew false shadow wherever the count is 1 short
    of it. Along a ray that grazes no edge it is 1."""
    scene = plate_scene((0.0, 1.0, 0.0))
    method = prepared(device, scene.mesh, scene.lights[0], scene.bounds)
    assert method._eye_winding(camera_view(scene, 64, 36)) == 1
    assert_render_matches_exact(scene, device, ("zpass",))


def test_zpass_refuses_a_near_plane_cutting_a_volume(device):
    """The eye within the near plane's reach of the plate's side volume face: z-pass would lose the
    cut-off part, so it is refused by name; z-fail renders it right."""
    # On the plane of the side quad over the plate's top edge x = 1.5, y = 3.15, seen from the light at
    # (0, 8, 0): at y = 1 it passes x = 1.5 * 7 / 4.85.
    scene = plate_scene((1.5 * 7 / 4.85, 1.0, 0.0))
    with pytest.raises(ValueError, match=r"stencil='zpass': the camera's near plane may cut \d+ shadow-volume"):
        render_report(scene, method="shadow_volume", width=32, height=18, device=device, stencil="zpass")
    assert_render_matches_exact(scene, device, ("zfail",))


def test_stencil_refuses_receivers_beyond_the_far_cap(device):
    """Regression: prepared with receiver_bounds around the plate only, the volume is truncated short of
    the far ground the camera sees, which the stencil silently left lit; now refused by name, while
    classify (the per-point count, independent of the extrusion) still gives the exact answer there."""
    scene = plate_scene((0.3, 1.0, 0.2))
    light = scene.lights[0]
    box = np.array([[-1.5, 2.85, -1.5], [1.5, 3.15, 1.5]])
    method = prepared(device, scene.mesh, light, box)
    view = camera_view(scene, 64, 36)
    zbuffer = raster.rasterize(device, scene.mesh, view)
    seen = raster.receivers(device, scene.mesh, view, zbuffer)
    assert not method.volume.reaches(light, seen.points)
    with pytest.raises(ValueError, match="seen: pixels lie beyond the shadow volume's far cap"):
        method.classify_view(view, zbuffer, seen)
    eps = default_eps(scene.mesh.bounds)
    truth = exact_ref.shadow_mask(scene.mesh.vertices, scene.mesh.faces, light, seen.points, seen.normals, eps=eps)
    differ = np.flatnonzero(method.classify(seen.points, seen.normals) != truth)
    band = 2e-6 * bounds_diagonal(scene.bounds)            # the exact method's float32 band (test_render.py)
    assert np.all(exact_ref.segment_edge_distance(scene.mesh.vertices, scene.mesh.faces, light, seen.points[differ],
                                                  seen.normals[differ], eps) < band)


def test_model_scene_renders_like_exact(device):
    require_models()
    scene = sc.Scene.load(SCENES / "models" / "teapot.toml")   # open parts: 1,036 border edges
    assert_render_matches_exact(scene, device, ("zfail",), width=96, height=54)


# Open and non-manifold meshes ---------------------------------------------------------------------

def test_open_bowl_shadows_through_its_inside(device, rng):
    """An open bowl with the light inside it: every bowl face turns away from the light, so a one-sided
    volume would cast no shadow at all; the ground below is shadowed through those faces, which the
    two-sided copy (faces flipped towards the light) catches."""
    bowl = icosphere(2)
    faces = bowl.faces[bowl.vertices[bowl.faces].mean(axis=1)[:, 1] < 0.5]      # open at the top
    mesh = sc.Mesh.concatenate([sc.Mesh(bowl.vertices + (0, 1.5, 0), faces),
                                sc.Mesh([[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], [[0, 2, 1], [0, 3, 2]])])
    light = sc.PointLight((0.0, 1.5, 0.0))                 # inside the bowl: sees only inner (back) faces
    assert two_sided(mesh).open_faces.size == len(mesh.faces)
    points = np.c_[rng.uniform(-3, 3, 2000), np.zeros(2000), rng.uniform(-3, 3, 2000)]
    normals = np.tile([0.0, 1.0, 0.0], (2000, 1))
    mask = sc.shadow_mask(mesh, light, points, normals, method="shadow_volume", device=device)
    truth = exact_ref.shadow_mask(mesh.vertices, mesh.faces, light, points, normals, eps=default_eps(mesh.bounds))
    assert truth.mean() > 0.3
    band = 2e-6 * bounds_diagonal(mesh.bounds)            # the exact method's float32 band (test_render.py)
    near = exact_ref.segment_edge_distance(mesh.vertices, mesh.faces, light, points, normals) < band
    assert not np.any((mask != truth) & ~near)


@pytest.mark.parametrize("inverted", [False, True], ids=["outward", "inward"])
def test_point_light_inside_a_closed_ball(device, rng, inverted):
    """Regression: a point light inside a closed ball (wound outward) faces none of its faces, and the
    one-sided volume cast no shadow at all where the exact answer shadows everything outside. The
    light's winding number is nonzero (-1 wound inward, where every face faces the light and one side
    would do; two-sided is right for both), so the frame goes two-sided."""
    ball = icosphere(2)
    faces = ball.faces[:, ::-1] if inverted else ball.faces
    ground = sc.Mesh([[-4, -1.2, -4], [4, -1.2, -4], [4, -1.2, 4], [-4, -1.2, 4]], [[0, 2, 1], [0, 3, 2]])
    mesh = sc.Mesh.concatenate([sc.Mesh(ball.vertices, faces), ground])
    light = sc.PointLight((0.1, 0.2, -0.05))
    method = prepared(device, mesh, light, mesh.bounds)
    assert method.stats["light_inside_closed"]
    points = np.c_[rng.uniform(-4, 4, 1000), np.full(1000, -1.2), rng.uniform(-4, 4, 1000)]
    points = np.concatenate([points, rng.uniform(-0.4, 0.4, (200, 3))])       # and inside the ball
    eps = default_eps(mesh.bounds)
    truth = exact_ref.shadow_mask(mesh.vertices, mesh.faces, light, points, eps=eps)
    assert truth[:1000].all() and not truth[1000:].any()
    assert np.array_equal(method.classify(points), truth)


def test_two_sided_cache_keeps_no_mesh_alive(rng):
    import gc
    import weakref
    for closed in (True, False):                                  # returned as it is, or doubled
        mesh = icosphere(1) if closed else blobs(rng, True)
        assert (two_sided(mesh).mesh is mesh) == closed
        alive = weakref.ref(mesh)
        del mesh
        gc.collect()
        assert alive() is None


@pytest.mark.parametrize("kind", ["fin", "duplicate", "misoriented"])
def test_broken_meshes_are_detached_and_exact(device, rng, kind):
    """Three faces on an edge (a fin on a closed box), a duplicated face, a face wound the wrong way:
    the faces on those edges are detached and two-sided, and the shadow is the exact one."""
    ball = icosphere(2)
    faces = ball.faces.copy()
    if kind == "fin":
        a, b = faces[0, :2]
        faces = np.r_[faces, [[a, b, len(ball.vertices)]]]
        vertices = np.r_[ball.vertices, [ball.vertices[a] * 2.0]]
    elif kind == "duplicate":
        faces, vertices = np.r_[faces, faces[:1]], ball.vertices
    else:
        faces[0] = faces[0, ::-1]
        vertices = ball.vertices
    ground = sc.Mesh([[-4, -1.2, -4], [4, -1.2, -4], [4, -1.2, 4], [-4, -1.2, 4]], [[0, 2, 1], [0, 3, 2]])
    mesh = sc.Mesh.concatenate([sc.Mesh(vertices, faces), ground])
    detached = two_sided(mesh).detached_faces
    assert 0 < len(detached) <= 6
    light = sc.PointLight(ball.vertices[faces[0]].mean(axis=0) * 3.0)     # right over the broken spot
    points = np.c_[rng.uniform(-4, 4, 2000), np.full(2000, -1.2), rng.uniform(-4, 4, 2000)]
    normals = np.tile([0.0, 1.0, 0.0], (2000, 1))
    method = prepared(device, mesh, light, mesh.bounds)
    assert method.stats["detached_faces"] == len(detached)
    triangles = method.volume.mesh.triangles.astype(np.float64)
    above = points + 0.01 * normals
    first, second = (reference.winding_numbers(triangles, above, d) for d in rng.standard_normal((2, 3)))
    assert np.array_equal(first, second), "the volume is not closed"
    eps = default_eps(mesh.bounds)
    truth = exact_ref.shadow_mask(mesh.vertices, mesh.faces, light, points, normals, eps=eps)
    mask = method.classify(points, normals)
    differ = np.flatnonzero(mask != truth)
    band = 2e-6 * bounds_diagonal(mesh.bounds)            # the exact method's float32 band (test_render.py)
    assert np.all(exact_ref.segment_edge_distance(mesh.vertices, mesh.faces, light, points[differ],
                                                  normals[differ], eps) < band)
    assert truth.any() and not truth.all()


# Silhouette methods and LOD -----------------------------------------------------------------------

@pytest.mark.parametrize("silhouettes", ["tracking", "random"])
def test_tracked_silhouettes_keep_one_tracker_and_give_the_brute_force_volume(device, rng, silhouettes):
    mesh = blobs(rng, False)
    box = mesh.bounds
    tracked = ShadowVolumeMethod(device, silhouettes=silhouettes)
    brute = ShadowVolumeMethod(device)
    points = np.c_[rng.uniform(-4, 4, 1000), np.zeros(1000), rng.uniform(-4, 4, 1000)]
    trackers = set()
    for angle in np.linspace(0.0, 0.2, 3):
        light = sc.PointLight((4 * np.cos(angle), 5.0, 4 * np.sin(angle)))
        tracked.prepare(mesh, light, box, 1e-4)
        brute.prepare(mesh, light, box, 1e-4)
        # Edges the tracker missed (the randomized search may miss whole loops) are counted and the frame
        # redone by brute force: the volume is always the closed one. The tracker reports no wrong edge.
        found = tracked.tracked_silhouette                  # the volume and its tracker are built on use
        trackers.add(id(tracked._tracker))
        full = silhouette_edges(device, found.adjacency, light)
        assert np.isin(found.indices, full.indices).all()
        assert tracked.stats["silhouettes_missed"] == len(full.indices) - len(found.indices)
        assert np.array_equal(canonical(tracked.volume.mesh.faces), canonical(brute.volume.mesh.faces))
        assert np.array_equal(tracked.classify(points), brute.classify(points))
    assert len(trackers) == 1


def test_missed_silhouettes_are_counted(device, rng):
    """A silhouette with one edge dropped is short by exactly that edge (the volume would be open)."""
    from shadowcl.shadow_volume import _missing_silhouettes
    from shadowcl.silhouette import Silhouette
    full = silhouette_edges(device, blobs(rng, True), LIGHTS["point"])
    assert _missing_silhouettes(full) == 0
    codes = full.codes.copy()
    codes[full.indices[:3]] = 0
    assert _missing_silhouettes(Silhouette(full.adjacency, full.light, codes, full.facing)) == 3


def test_lod_level_zero_is_the_full_mesh(device, rng):
    mesh, light = blobs(rng, False), LIGHTS["point"]
    full = prepared(device, mesh, light, mesh.bounds)
    level0 = prepared(device, mesh, light, mesh.bounds, lod=0)
    assert np.array_equal(full.volume.mesh.faces, level0.volume.mesh.faces)


# Bad input ----------------------------------------------------------------------------------------

MESH = sc.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
BOX = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
BAD_INPUTS = [
    (lambda d: create_method("shadow_volume", d, stencil="zmiddle"), ValueError, r"stencil: expected one of"),
    (lambda d: create_method("shadow_volume", d, silhouettes="psychic"), ValueError, r"silhouettes: expected one of"),
    (lambda d: create_method("shadow_volume", d, lod="coarse"), TypeError, r"lod: expected None, a level index"),
    (lambda d: create_method("shadow_volume", d, lod=1.5), TypeError, r"lod: expected None, a level index"),
    (lambda d: create_method("shadow_volume", d, max_error=-1), ValueError, r"max_error"),
    (lambda d: create_method("shadow_volume", d, expected_receivers=0), ValueError, r"expected_receivers"),
    (lambda d: create_method("shadow_volume", d, colour=1), TypeError, r"colour: not a parameter"),
    (lambda d: create_method("shadow_volume", d).prepare("mesh", LIGHTS["point"], BOX, 0.0), TypeError, r"mesh:"),
    (lambda d: create_method("shadow_volume", d).prepare(MESH, "light", BOX, 0.0), TypeError, r"light"),
    (lambda d: create_method("shadow_volume", d).prepare(MESH, LIGHTS["point"], BOX[0], 0.0), ValueError,
     r"receiver_bounds"),
    (lambda d: create_method("shadow_volume", d).prepare(MESH, LIGHTS["point"], BOX, np.nan), ValueError, r"eps:"),
    (lambda d: create_method("shadow_volume", d).classify(np.zeros((1, 3))), RuntimeError, r"classify: call prepare"),
    (lambda d: prepared(d, MESH, LIGHTS["point"], BOX).classify(np.zeros((2, 2))), ValueError,
     r"points: expected shape"),
    (lambda d: prepared(d, MESH, LIGHTS["point"], BOX).classify([[0, 0, np.nan]]), ValueError, r"points: contains NaN"),
    (lambda d: prepared(d, MESH, sc.PointLight((0.2, 0.2, 1e-30)), BOX).volume, ValueError,   # built on use
     r"light: lies \(almost\) in the plane of a light-facing face"),
    (lambda d: raster.stencil(d, MESH, VIEW, "zbuffer"), TypeError, r"zbuffer: expected a ZBuffer"),
    (lambda d: raster.stencil(d, "mesh", VIEW, None), TypeError, r"mesh: expected a shadowcl.Mesh"),
    (lambda d: raster.stencil(d, MESH, VIEW, raster.rasterize(d, MESH, VIEW), surface=np.zeros((6, 8))), ValueError,
     r"surface: expected a \(6, 8\) float32 depth image"),
    (lambda d: raster.stencil(d, MESH, VIEW, raster.rasterize(d, MESH, VIEW), surface=np.full((6, 8), 2, np.float32)),
     ValueError, r"surface: depths must lie in \[0, 1\]"),
]
VIEW = sc.Camera((0, 0, 3), (0, 0, 0)).view(8, 6, near=0.1)


@pytest.mark.parametrize("call, error, message", BAD_INPUTS, ids=[m for _, _, m in BAD_INPUTS])
def test_bad_input_is_named(device, call, error, message):
    with pytest.raises(error, match=message):
        call(device)


def test_listed_in_methods():
    assert set(sc.methods()["shadow_volume"]) == {"lod", "silhouettes", "max_error", "receivers", "stencil",
                                                  "expected_receivers", "eps"}


def test_cap_lists_are_sized_by_expected_receivers(device, rng):
    """method="auto" queries a small sample first: the cap lists' grid follows expected_receivers, not the
    first query's count, and the answers are exact's either way."""
    mesh = icosphere(3)
    light, box = LIGHTS["point"], np.array([[-2.0, -2.0, -2.0], [2.0, 2.0, 2.0]])
    points = np.c_[rng.uniform(-2, 2, 10), np.full(10, -1.5), rng.uniform(-2, 2, 10)]     # below the ball
    exact = create_method("exact", device)
    exact.prepare(mesh, light, box, 1e-4)
    grids = {}
    for expected in (None, 2_000_000):
        method = create_method("shadow_volume", device, expected_receivers=expected)
        method.prepare(mesh, light, box, 1e-4)
        np.testing.assert_array_equal(method.classify(points), exact.classify(points))
        grids[expected] = method._exact.resolved_params()["resolution"]
    assert grids[2_000_000] > grids[None]
