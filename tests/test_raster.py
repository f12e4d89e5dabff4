"""Raster kernel against the float64 reference, and the invariants a rasterizer must keep.

The kernel snaps corners in float32 and the reference in float64, so where a snapped corner could
differ the comparison is split in two: the triangle setup (corners within a stated tolerance),
then the rasterization of the kernel's own corners, which must match exactly. Orthographic views
with power-of-two scales and dyadic coordinates make float32 exact, and there the whole pipeline
is compared at once.
"""

import numpy as np
import pytest
import trimesh

import shadowcl as sc
from shadowcl import raster
from shadowcl.reference import raster as reference
from shadowcl.views import View, orthographic_reversed

ONE = 2**raster.SUBPIXEL_BITS  # fixed-point units per pixel

# Depth ties: the kernel interpolates depth in float32 with all weights >= 0, within ~6 ulp
# (4e-7 relative) of the exact value; two fragments closer than twice that may come out in either
# order, so there the kernel may show the reference's runner-up.
TIE_RTOL = 1e-6


# Scenes -----------------------------------------------------------------------------------------


def dyadic_view(width: int, height: int) -> View:
    """Orthographic view in which float32 computes every corner exactly: scales are powers of two,
    the screen spans [-32, 32]^2 world units, depth = z / 16 + 1 for z in [-16, 0]."""
    return View(np.zeros(3), orthographic_reversed(32.0, 32.0, near=0.0, far=16.0), width, height)


def dyadic_soup(rng, count: int) -> tuple[sc.Mesh, np.ndarray]:
    """Triangles with corners on a 1/8 grid (x, y) and 1/64 grid (depth): small and huge ones,
    partly off-screen, both windings, degenerate ones, and duplicates with their corners rotated
    and reversed (exact depth ties). Returns the mesh and the ids of the later copies."""
    centres = rng.integers(-48 * 8, 48 * 8, size=(count, 1, 2))
    spread = np.where(rng.random((count, 1, 1)) < 0.8, 8 * 8, 40 * 8)
    xy = (centres + rng.integers(-spread, spread + 1, size=(count, 3, 2))) / 8
    z = -rng.integers(0, 16 * 64, size=(count, 3, 1)) / 64
    corners = np.concatenate([xy, z], axis=2)
    corners[: count // 20, 2] = corners[: count // 20, 0]  # repeated corner
    collinear = slice(count // 20, count // 10)
    corners[collinear, 2] = 2 * corners[collinear, 1] - corners[collinear, 0]
    originals = rng.choice(count, size=count // 10, replace=False)
    copies = corners[originals][:, [2, 1, 0]]  # the other winding, from another corner
    corners = np.concatenate([corners, copies])
    mesh = sc.Mesh(corners.reshape(-1, 3), np.arange(3 * len(corners)).reshape(-1, 3))
    return mesh, np.arange(count, count + len(originals))


def look_at(eye, target) -> np.ndarray:
    """4x4 rotation from world directions to a view looking from ``eye`` at ``target``, z up."""
    matrix = np.eye(4)
    matrix[:3, :3] = sc.views.look_at_rotation(np.asarray(eye, float), np.asarray(target, float), np.array([0, 0, 1.0]))
    return matrix


def random_soup(rng, kind: str, count: int = 400) -> tuple[sc.Mesh, View]:
    """Random triangles around a view, many cut by its planes: for a perspective camera, crossing
    the near plane, behind the eye, huge; for an orthographic (light's) view, crossing its near and
    far planes."""
    if kind == "perspective":
        eye = np.array([0.5, 1.0, 3.0])
        view = sc.Camera(eye, (0.0, 0.0, 0.0), fov=60).view(97, 64, near=0.25)
    else:
        eye = np.array([1.0, 2.0, 4.0])
        view = View(eye, orthographic_reversed(3.0, 2.0, near=2.0, far=7.0) @ look_at(eye, (0, 0, 0)), 97, 64)
    centres = rng.uniform(-4, 4, size=(count, 1, 3)) + eye * rng.integers(0, 2, size=(count, 1, 1))
    scale = np.where(rng.random((count, 1, 1)) < 0.9, 0.7, 30.0)
    corners = centres + scale * rng.normal(size=(count, 3, 3))
    return sc.Mesh(corners.reshape(-1, 3), np.arange(3 * count).reshape(-1, 3)), view


def grid_mesh(nx: int, ny: int, lo, hi, jitter: float, rng) -> sc.Mesh:
    """A regular grid of (nx x ny) quads in the plane z = 0, split along alternating diagonals,
    inner vertices jittered by up to ``jitter`` cells."""
    x, y = np.meshgrid(np.linspace(lo[0], hi[0], nx + 1), np.linspace(lo[1], hi[1], ny + 1))
    cell = (np.array(hi) - np.array(lo)) / (nx, ny)
    inner = np.zeros_like(x, dtype=bool)
    inner[1:-1, 1:-1] = True
    x = x + inner * rng.uniform(-jitter, jitter, x.shape) * cell[0]
    y = y + inner * rng.uniform(-jitter, jitter, y.shape) * cell[1]
    index = np.arange(x.size).reshape(x.shape)
    faces = []
    for j in range(ny):
        for i in range(nx):
            a, b, c, d = index[j, i], index[j, i + 1], index[j + 1, i + 1], index[j + 1, i]
            faces += [[a, b, c], [a, c, d]] if (i + j) % 2 else [[a, b, d], [b, c, d]]
    return sc.Mesh(np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1), faces)


def icosphere(radius: float, subdivisions: int = 2) -> sc.Mesh:
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return sc.Mesh(sphere.vertices, sphere.faces)


def mixed_windings(mesh: sc.Mesh, rng) -> sc.Mesh:
    """``mesh`` with half its faces reversed: both windings must be drawn alike."""
    faces = mesh.faces.copy()
    flip = rng.random(len(faces)) < 0.5
    faces[flip] = faces[flip][:, ::-1]
    return sc.Mesh(mesh.vertices, faces)


def kernel_polygons(polygons: raster.ScreenPolygons) -> list:
    return [(polygons.xy[i, :count], polygons.depth[i, :count]) for i, count in enumerate(polygons.count)]


# Comparison -------------------------------------------------------------------------------------


def assert_zbuffer_matches(zbuffer: raster.ZBuffer, expected: reference.Raster, what: str) -> None:
    """Coverage exactly; triangle ids exactly except at depth ties; depth to TIE_RTOL."""
    size = f"{zbuffer.view.width}x{zbuffer.view.height}"
    assert zbuffer.depth.shape == zbuffer.triangle.shape == expected.depth.shape, f"{what} {size}: shapes"
    assert zbuffer.depth.dtype == np.float32 and zbuffer.triangle.dtype == np.int32, f"{what} {size}: dtypes"
    covered = expected.triangle >= 0
    wrong = np.argwhere(zbuffer.mask != covered)
    assert len(wrong) == 0, f"{what} {size}: coverage differs at {len(wrong)} pixels (row, col) {wrong[:10].tolist()}"
    mismatch = zbuffer.triangle != expected.triangle
    untied = mismatch & ~(expected.margin <= TIE_RTOL * expected.depth)
    assert not untied.any(), (
        f"{what} {size}: triangle differs away from depth ties at {np.argwhere(untied)[:10].tolist()}; "
        f"kernel {zbuffer.triangle[untied][:10]}, reference {expected.triangle[untied][:10]}"
    )
    # Ties within float32 rounding need two fragments at the same depth away from exact duplicates:
    # along intersection curves only, so few (none in this file's scenes; the bound is generous).
    assert mismatch.sum() <= max(2, 0.01 * covered.sum()), f"{what} {size}: {mismatch.sum()} tied pixels"
    assert np.all((zbuffer.depth >= 0) & (zbuffer.depth <= 1)), f"{what} {size}: depth outside [0, 1]"
    error = np.abs(zbuffer.depth - expected.depth)
    assert np.all(error <= TIE_RTOL * expected.depth), f"{what} {size}: depth max error {error.max():.3g}"


# Kernel against reference -----------------------------------------------------------------------

SIZES = [(1, 1), (2, 3), (7, 5), (64, 48), (63, 65), (129, 31), (256, 256)]


@pytest.mark.parametrize("width, height", SIZES, ids=[f"{w}x{h}" for w, h in SIZES])
def test_dyadic_soup_matches_reference_exactly(device, rng, width, height):
    mesh, copies = dyadic_soup(rng, 300)
    view = dyadic_view(width, height)
    zbuffer = raster.rasterize(device, mesh, view)
    assert_zbuffer_matches(zbuffer, reference.rasterize(mesh, view), "dyadic soup")
    # A duplicate has bit-identical depths whatever its corner order: the first copy always wins.
    assert not np.isin(zbuffer.triangle, copies).any()
    np.testing.assert_array_equal(raster.coverage_count(device, mesh, view), reference.coverage_count(mesh, view))


def test_big_triangles_in_the_shared_launch_match_reference_exactly(device, rng):
    """More big triangles than a work-group holds, their bands numbered band-major after the whole
    triangles in raster_pass's one launch (so a group mixes triangles and bands, and wraps): the
    same pixels, depths, ids and overdraw as the reference."""
    mesh, _ = dyadic_soup(rng, 600)
    view = dyadic_view(256, 256)
    setup = raster._setup(device, mesh, view)
    assert raster._GROUP < setup.big_count < setup.triangles  # the case this test is about
    assert_zbuffer_matches(raster.rasterize(device, mesh, view), reference.rasterize(mesh, view), "big triangles")
    np.testing.assert_array_equal(raster.coverage_count(device, mesh, view), reference.coverage_count(mesh, view))


@pytest.mark.parametrize("kind", ["perspective", "orthographic"])
def test_setup_matches_reference(device, rng, kind):
    mesh, view = random_soup(rng, kind)
    polygons = raster.screen_polygons(device, mesh, view)
    expected = reference.screen_polygons(mesh.vertices, mesh.faces, view.origin, view.matrix, view.width, view.height)
    np.testing.assert_array_equal(polygons.count, [len(xy) for xy, _ in expected])
    assert 0 < np.count_nonzero(polygons.count == 0) and np.count_nonzero(polygons.count > 3) > 10  # clipped cases
    centre = np.array([view.width, view.height]) * ONE // 2
    for i, (xy, depth) in enumerate(expected):
        count = len(xy)
        distance = np.abs(xy - centre).max(axis=1)
        # float32 rounding moves a corner across a rounding boundary by at most one unit; corners cut
        # far out in the guard band carry float32's relative error of the cut, magnified where w is
        # small there (up to ~2e-4 of their distance from the centre, seen), harmless off-screen.
        error = np.abs(polygons.xy[i, :count] - xy).max(axis=1)
        assert np.all(error <= 1 + 1e-3 * distance), f"triangle {i}: corners off by {error.tolist()} units"
        # Depth: a few ulp of the float32 transform's terms: of the depth itself in perspective
        # (z = near, w = distance), of O(1) terms in an orthographic view (depth affine in z). Corners
        # cut by the near plane (depth 1) or far out in the guard band carry the cut's float32 error
        # (relative to the edge's extent in w) divided by a small w: up to 2^-16 seen, so 2^-14.
        cut = (depth == 1.0) | (distance > 2 * centre.max())
        error = np.abs(polygons.depth[i, :count] - depth)
        scale = depth if kind == "perspective" else 1.0
        assert np.all(error <= np.where(cut, 2**-14, 1e-6 * scale)), f"triangle {i}: depth off by {error.tolist()}"
        # The raster passes order depths by their bits: no -0.0 or negative rounding of a cut at z = 0.
        corner_depth = polygons.depth[i, :count]
        assert not np.signbit(corner_depth).any() and np.all(corner_depth <= 1), f"triangle {i}: {corner_depth}"


@pytest.mark.parametrize("kind", ["perspective", "orthographic"])
@pytest.mark.parametrize("width, height", [(1, 1), (97, 64), (200, 151)])
def test_raster_matches_reference_on_kernel_corners(device, rng, kind, width, height):
    mesh, view = random_soup(rng, kind)
    view = View(view.origin, view.matrix, width, height)
    polygons = kernel_polygons(raster.screen_polygons(device, mesh, view))
    zbuffer = raster.rasterize(device, mesh, view)
    assert_zbuffer_matches(zbuffer, reference.rasterize_polygons(polygons, width, height), f"{kind} soup")
    if kind == "perspective":  # depth > 0 for any finite point: covered pixels have depth, empty ones none
        np.testing.assert_array_equal(zbuffer.depth > 0, zbuffer.mask)


# Depth only ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("scene", ["dyadic", "perspective", "orthographic", "inside a sphere"])
def test_depth_map_is_bit_identical_to_rasterize_depth(device, rng, scene):
    if scene == "dyadic":
        mesh, view = dyadic_soup(rng, 300)[0], dyadic_view(129, 31)
    elif scene == "inside a sphere":
        _, mesh, view, _ = closed_mesh_scenes(rng)[1]
    else:
        mesh, view = random_soup(rng, scene)
    depth = raster.depth_map(device, mesh, view)
    assert depth.view is view and depth.shape == (view.height, view.width) and depth.triangle is None
    expected = raster.rasterize(device, mesh, view)
    got = depth.read()
    assert got.dtype == np.float32 and got.any()
    np.testing.assert_array_equal(got.view(np.uint32), expected.depth.view(np.uint32))
    # with triangle ids (the shadow map's plane test): the same depths and rasterize's ids, on the device
    with_ids = raster.depth_map(device, mesh, view, triangles=True)
    np.testing.assert_array_equal(with_ids.read().view(np.uint32), expected.depth.view(np.uint32))
    ids = device.from_device(with_ids.triangle, depth.shape, np.int32)
    np.testing.assert_array_equal(ids, expected.triangle)


# Shared edges: every pixel drawn exactly once -----------------------------------------------------


def assert_drawn_once(count: np.ndarray, name: str) -> None:
    wrong = np.argwhere(count != 1)
    times = np.unique(count).tolist()
    assert len(wrong) == 0, f"{name}: pixels drawn {times} times, e.g. (row, col) {wrong[:5].tolist()}"


def closed_mesh_scenes(rng):
    """(name, mesh, view, expected count) for surfaces every pixel's ray crosses a known number of times."""
    sphere = mixed_windings(icosphere(1.0), rng)
    outside = sc.Camera((0.3, 0.4, 2.2), (0, 0, 0), fov=70).view(61, 47, near=0.1)
    inside = sc.Camera((0.1, -0.2, 0.15), (1, 0.3, 0.2), fov=100).view(61, 47, near=0.01)
    box = trimesh.creation.box(extents=(2, 3, 4))
    cube = mixed_windings(sc.Mesh(box.vertices, box.faces), rng)
    in_cube = sc.Camera((0.9, 1.4, 1.9), (-1, -1, -2), fov=120).view(80, 60, near=0.001)
    return [
        ("icosphere from outside", sphere, outside, None),
        ("icosphere from inside", sphere, inside, 1),
        ("cube from a corner inside", cube, in_cube, 1),
    ]


def test_grid_and_fan_cover_every_pixel_once(device, rng):
    view = dyadic_view(64, 64)  # 1 world unit per pixel, pixel centres at half-integers in [-32, 32]
    grid = mixed_windings(grid_mesh(9, 7, (-40, -37), (41, 35), jitter=0.3, rng=rng), rng)
    # Corners on pixel centres: horizontal, vertical and diagonal edges run through pixel centres.
    centred_grid = mixed_windings(grid_mesh(20, 20, (-40.5, -40.5), (39.5, 39.5), jitter=0.0, rng=rng), rng)
    # A fan around a pixel centre, out past the screen; eight spokes run through pixel centres.
    hub = np.array([0.5, 0.5, 0.0])
    angles = np.concatenate([np.arange(8) * np.pi / 4, rng.uniform(0, 2 * np.pi, 32)])
    directions = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    directions[:8] = np.round(directions[:8] * np.sqrt(2))  # exactly (1, 0), (1, 1), (0, 1), ...
    rim = hub + 80 * directions[np.argsort(angles)]
    fan = sc.Mesh(np.vstack([hub, rim]), [[0, 1 + i, 1 + (i + 1) % len(rim)] for i in range(len(rim))])
    fan = mixed_windings(fan, rng)
    for name, mesh in [("jittered grid", grid), ("grid through pixel centres", centred_grid), ("fan", fan)]:
        assert_drawn_once(raster.coverage_count(device, mesh, view), name)


def test_ground_grid_crossing_the_near_plane_covers_every_pixel_once(device, rng):
    # Looking down at 51 degrees with a 50 degree field of view: the plane z = 0 fills the screen.
    # The grid reaches behind the camera (triangles cut by the near plane); the huge quad's corners
    # lie behind the eye and far outside the guard band, so its shared diagonal is cut by both.
    view = sc.Camera((0.0, 0.0, 1.0), (0.0, 0.8, 0.0), up=(0, 0, 1), fov=50).view(90, 70, near=0.05)
    grid = mixed_windings(grid_mesh(24, 24, (-6, -6), (6, 6), jitter=0.3, rng=rng), rng)
    huge = sc.Mesh([[-1e7, -1e7, 0], [1e7, -1e7, 0], [1e7, 1e7, 0], [-1e7, 1e7, 0]], [[0, 1, 2], [0, 3, 2]])
    for name, mesh in [("grid", grid), ("huge quad", huge)]:
        assert np.any(raster.screen_polygons(device, mesh, view).count > 3), f"{name}: nothing was clipped"
        assert_drawn_once(raster.coverage_count(device, mesh, view), name)


def test_cut_corners_of_a_shared_edge_are_bit_identical(device, rng):
    # Pairs (p, q, r1), (q, p, r2) sharing edge p-q, with q far beyond the guard band (2^21 pixels;
    # 1 world unit per pixel here). Each triangle cuts the edge walking it in its own direction, and
    # both must get the same corner, or the shared edge would crack or overlap. Out there a float32
    # ulp is worth tens of fixed-point units, so any difference in the computation shows.
    view = dyadic_view(64, 64)
    count = 50
    p = np.concatenate([rng.uniform(-30, 30, (count, 2)), rng.uniform(-15, -1, (count, 1))], axis=1)
    away = rng.normal(size=(count, 2))
    away /= np.linalg.norm(away, axis=1, keepdims=True)
    q = np.concatenate([p[:, :2] + 1e7 * away, p[:, 2:]], axis=1)
    side = np.stack([-away[:, 1], away[:, 0], np.zeros(count)], axis=1)
    r1, r2 = p + 5 * side - [0, 0, 0.5], p - 5 * side - [0, 0, 0.5]
    vertices = np.concatenate([p, q, r1, r2])
    index = np.arange(count)
    faces = np.concatenate([np.stack([index, index + count, index + 2 * count], axis=1),
                            np.stack([index + count, index, index + 3 * count], axis=1)])
    polygons = raster.screen_polygons(device, sc.Mesh(vertices, faces), view)
    for i in range(count):
        corners = [{(*polygons.xy[t, k], polygons.depth[t, k]) for k in range(polygons.count[t])}
                   for t in (i, i + count)]
        assert len(corners[0] & corners[1]) == 2, f"pair {i}: the corners on the shared edge differ"  # p, the cut


def test_closed_meshes_are_watertight(device, rng):
    for name, mesh, view, expected in closed_mesh_scenes(rng):
        count = raster.coverage_count(device, mesh, view)
        if expected is None:  # seen from outside: a front and a back face, or nothing
            assert set(np.unique(count)) == {0, 2}, f"{name}: pixels drawn {np.unique(count).tolist()} times"
        else:
            assert np.all(count == expected), f"{name}: pixels drawn {np.unique(count).tolist()} times"
        np.testing.assert_array_equal(count, reference.coverage_count(mesh, view), err_msg=name)


# Hard cases -------------------------------------------------------------------------------------


def test_fill_rule_on_pixel_centres(device):
    # 1 world unit per pixel; x = col + 0.5 - 8 and y = 8 - (row + 0.5) are pixel centres. The square
    # of centres (cols 3..9, rows 2..6) drawn as two triangles: top and left edges are included,
    # bottom and right excluded, the diagonal belongs to exactly one of the two.
    view = View(np.zeros(3), orthographic_reversed(8.0, 8.0, near=0.0, far=4.0), 16, 16)

    def centre(col, row):
        return [col + 0.5 - 8, 8 - (row + 0.5), -1.0]

    corners = [centre(3, 2), centre(9, 2), centre(9, 6), centre(3, 6)]  # top-left, top-right, bottom-right, bottom-left
    expected = np.zeros((16, 16), dtype=int)
    expected[2:6, 3:9] = 1
    for faces in ([[0, 1, 2], [0, 2, 3]], [[0, 1, 3], [1, 2, 3]], [[2, 1, 0], [3, 2, 0]]):
        mesh = sc.Mesh(corners, faces)
        np.testing.assert_array_equal(raster.coverage_count(device, mesh, view), expected, err_msg=str(faces))
        expected_ids = reference.rasterize(mesh, view).triangle
        np.testing.assert_array_equal(raster.rasterize(device, mesh, view).triangle, expected_ids, err_msg=str(faces))
    # Each half alone. The diagonal from centre (3, 2) to (9, 6), 2 (col - 3) = 3 (row - 2), is a left
    # edge of the upper-right half (included: pixels on it are that half's) and a right edge of the
    # lower-left half (excluded), whose top corner therefore is not drawn.
    rows, cols = np.mgrid[0:16, 0:16]
    upper = (expected == 1) & (2 * (cols - 3) >= 3 * (rows - 2))
    np.testing.assert_array_equal(raster.coverage_count(device, sc.Mesh(corners, [[0, 1, 2]]), view), upper)
    np.testing.assert_array_equal(raster.coverage_count(device, sc.Mesh(corners, [[0, 2, 3]]), view), expected - upper)
    assert upper[2, 3] and upper[4, 6] and not upper[5, 3]  # its corner, a pixel on the diagonal; not below


def test_degenerate_triangles_draw_nothing(device):
    view = sc.Camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov=60).view(33, 29, near=0.5)
    vertices = [
        [0, 0, 0], [1, 0.5, 0], [2, 1, 0], [0, 1, 0],
        [-1, 0, 0], [1, 0, -1], [0, 0, -3],  # in the plane y = 0, which holds the eye: seen edge-on
        [0.3, 0.3, 0], [0.3 + 1e-7, 0.3, 0], [0.3, 0.3 + 1e-7, 0],  # zero area after snapping
    ]
    faces = [[0, 1, 2], [2, 0, 1],  # collinear
             [0, 0, 3], [0, 3, 0],  # repeated corner
             [4, 5, 6], [7, 8, 9]]
    mesh = sc.Mesh(vertices, faces)
    assert not raster.coverage_count(device, mesh, view).any()
    zbuffer = raster.rasterize(device, mesh, view)
    assert not zbuffer.depth.any() and np.all(zbuffer.triangle == -1)


def test_off_screen_behind_and_beyond_draw_nothing(device):
    triangle = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0, 0.5, 0]])
    # The camera at z = 5 looks down -z with its near plane at z = 4.5.
    perspective = sc.Camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov=60).view(40, 30, near=0.5)
    beside = [[10, 0, 0], [-10, 0, 0], [0, 10, 0], [0, -10, 0]]
    behind_or_too_near = [[0, 0, 10], [0, 0, 5.2], [0, 0, 4.7]]
    for offset in beside + behind_or_too_near:
        mesh = sc.Mesh(triangle + offset, [[0, 1, 2]])
        assert not raster.coverage_count(device, mesh, perspective).any(), offset
    # Orthographic from z = 5: near plane at z = 4, far plane at z = -1.
    ortho = View(np.array([0.0, 0.0, 5.0]), orthographic_reversed(2.0, 2.0, near=1.0, far=6.0), 40, 30)
    for z in (4.5, -1.5):
        mesh = sc.Mesh(triangle + [0, 0, z], [[0, 1, 2]])
        assert not raster.coverage_count(device, mesh, ortho).any(), z


def test_triangle_behind_the_eye_is_clipped_not_wrapped(device):
    # A floor strip below the camera reaching behind it: projected without clipping, its corner
    # behind the eye would flip to the top of the screen.
    view = sc.Camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), fov=60).view(40, 30, near=0.5)
    mesh = sc.Mesh([[-1, -1, 0], [1, -1, 0], [0.2, -1, 8]], [[0, 1, 2]])
    polygons = raster.screen_polygons(device, mesh, view)
    assert polygons.count[0] == 4  # the near plane cut off the corner
    zbuffer = raster.rasterize(device, mesh, view)
    assert zbuffer.mask[15:].any() and not zbuffer.mask[:15].any()  # below the horizon only
    expected = reference.rasterize_polygons(kernel_polygons(polygons), 40, 30)
    assert_zbuffer_matches(zbuffer, expected, "behind the eye")


# Receivers --------------------------------------------------------------------------------------


def receiver_scene(rng, kind: str) -> tuple[sc.Mesh, View]:
    """A sphere (mixed windings) above a jittered floor, seen by a camera or by a light's orthographic view."""
    floor = grid_mesh(4, 4, (-3, -3), (3, 3), jitter=0.2, rng=rng)
    floor = sc.Mesh(floor.vertices - [0, 0, 1], floor.faces)
    scene = sc.Mesh.concatenate([mixed_windings(icosphere(1.0, subdivisions=3), rng), floor])
    if kind == "perspective":
        return scene, sc.Camera((2.0, -3.0, 1.5), (0.0, 0.0, -0.3), up=(0, 0, 1), fov=55).view(96, 72, near=0.1)
    eye = np.array([1.0, 2.0, 4.0])
    return scene, View(eye, orthographic_reversed(3.0, 3.0, near=0.5, far=9.0) @ look_at(eye, (0, 0, 0)), 64, 64)


@pytest.mark.parametrize("kind", ["perspective", "orthographic"])
def test_receivers_match_reference(device, rng, kind):
    mesh, view = receiver_scene(rng, kind)
    zbuffer = raster.rasterize(device, mesh, view)
    found = raster.receivers(device, mesh, view, zbuffer)
    np.testing.assert_array_equal(found.mask, zbuffer.mask)
    np.testing.assert_array_equal(found.pixel_index, np.flatnonzero(zbuffer.mask))
    np.testing.assert_array_equal(found.triangle, zbuffer.triangle[zbuffer.mask])
    assert found.points.dtype == found.normals.dtype == np.float64 and found.points.shape == (zbuffer.mask.sum(), 3)
    points, normals = reference.receivers(mesh, view, zbuffer.triangle)
    _, direction = view.pixel_rays()
    direction = direction[zbuffer.mask]
    # float32 ray and plane, relative to the origin: the error grows with the distance along the
    # ray and with 1 / |cos| of the incidence (the plane's depth along the ray is that ill-conditioned).
    distance = np.linalg.norm(points - view.origin, axis=1)
    cosine = np.abs(np.einsum("ij,ij->i", normals, direction))
    error = np.linalg.norm(found.points - points, axis=1)
    worst = np.max(error / distance * cosine)
    assert worst <= 1e-6, f"{kind}: worst point error {worst:.3g} x distance / cos"
    np.testing.assert_allclose(np.linalg.norm(found.normals, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(found.normals, normals, atol=1e-5)  # float32 cross product of float32 edges
    assert np.all(np.einsum("ij,ij->i", found.normals, direction) < 0), "normals must face the viewer"


def test_receiver_on_an_edge_on_wall_is_finite(device):
    # Frozen from a search: a vertical wall seen edge-on by an orthographic view looking down -z. Its
    # corners project onto one line, but snapping them moves them off it by up to 1/512 pixel and
    # the sliver covers 5 pixel centres. The rays run exactly parallel to its plane (float32 normal
    # z = 0), so each point comes from the pixel's stored depth instead.
    view = View(np.zeros(3), orthographic_reversed(3.0, 3.0, near=0.0, far=8.0), 256, 256)
    corners = [[0.68359375, -0.65625, -6.0], [0.83984375, -1.359375, -3.125], [0.99609375, -2.0625, -6.25]]
    wall = sc.Mesh(corners, [[0, 1, 2]])
    zbuffer = raster.rasterize(device, wall, view)
    found = raster.receivers(device, wall, view, zbuffer)
    assert len(found.points) == 5 and np.all(np.isfinite(found.points))
    off_plane = np.abs((found.points - wall.vertices[0]) @ wall.face_normals[0])
    assert np.all(off_plane <= 6.0 / 256), "points within a pixel (6/256 units) of the wall's plane"


def test_vertices_are_uploaded_once_per_view_origin(device, rng):
    mesh, view = receiver_scene(rng, "perspective")
    zbuffer = raster.rasterize(device, mesh, view)
    raster.receivers(device, mesh, view, zbuffer)
    raster.coverage_count(device, mesh, view)
    assert len(raster._uploads[mesh].vertices) == 1
    raster.rasterize(device, mesh, View(view.origin + 1.0, view.matrix, 8, 8))
    assert len(raster._uploads[mesh].vertices) == 2


# Bad input --------------------------------------------------------------------------------------

MESH = sc.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
VIEW = sc.Camera((0, 0, 3), (0, 0, 0)).view(8, 6, near=0.1)


def view_with(**changes) -> View:
    fields = dict(origin=VIEW.origin, matrix=VIEW.matrix, width=VIEW.width, height=VIEW.height) | changes
    return View(**fields)


FAR = sc.Mesh([[3e38, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2]])

BAD_INPUTS = [
    (lambda d: raster.rasterize(d, "mesh", VIEW), TypeError, r"mesh: expected a shadowcl.Mesh"),
    (lambda d: raster.rasterize(d, MESH, "view"), TypeError, r"view: expected a shadowcl.View"),
    (lambda d: raster.rasterize(d, MESH, view_with(width=0)), ValueError, r"view.width: must be between 1 and"),
    (lambda d: raster.rasterize(d, MESH, view_with(height=raster.MAX_SIDE + 1)), ValueError, r"view.height: must be"),
    (lambda d: raster.rasterize(d, MESH, view_with(width=8.0)), TypeError, r"view.width: expected an integer"),
    (lambda d: raster.rasterize(d, MESH, view_with(matrix=np.full((4, 4), np.nan))), ValueError, r"view.matrix: expected"),
    (lambda d: raster.rasterize(d, MESH, view_with(matrix=np.zeros((4, 4)))), ValueError, r"view.matrix: is singular"),
    (lambda d: raster.rasterize(d, MESH, view_with(origin=np.array([0, np.inf, 0]))), ValueError, r"view.origin: expected"),
    (lambda d: raster.rasterize(d, MESH, view_with(width=2**20, height=2**11)), ValueError, r"view: 1048576 x 2048 pixels"),
    (lambda d: raster.rasterize(d, MESH, view_with(width=2**15, height=2**14)), ValueError,
     r"depth buffer \(32768 x 16384\): needs 2048 MiB"),
    (lambda d: raster.rasterize(d, FAR, view_with(origin=np.array([-3e38, 0, 0]))), ValueError,
     r"mesh: vertices relative to view.origin overflow float32"),
    (lambda d: raster.depth_map(d, "mesh", VIEW), TypeError, r"mesh: expected a shadowcl.Mesh"),
    (lambda d: raster.depth_map(d, MESH, view_with(height=0)), ValueError, r"view.height: must be between 1 and"),
    (lambda d: raster.depth_map(d, MESH, view_with(width=2**15, height=2**14)), ValueError,
     r"depth buffer \(32768 x 16384\): needs 2048 MiB"),
    (lambda d: raster.receivers(d, MESH, VIEW, "zbuffer"), TypeError, r"zbuffer: expected a ZBuffer"),
    (lambda d: raster.receivers(d, FAR, VIEW, raster.rasterize(d, MESH, VIEW)), ValueError,
     r"zbuffer: was drawn from a different mesh"),
    (lambda d: raster.receivers(d, MESH, view_with(width=9), raster.rasterize(d, MESH, VIEW)), ValueError,
     r"zbuffer: was drawn with a different view"),
]


@pytest.mark.parametrize("call, error, message", BAD_INPUTS, ids=[m for _, _, m in BAD_INPUTS])
def test_bad_input_is_named(small_buffer_device, call, error, message):
    with pytest.raises(error, match=message):
        call(small_buffer_device)

