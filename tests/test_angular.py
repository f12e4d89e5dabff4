"""The angular method (kernels/angular.cl, shadowcl.angular) against its float64 reference
(shadowcl.reference.angular) and the exact method."""


import numpy as np
import pytest
import trimesh

import shadowcl as sc
from shadowcl import angular
from shadowcl.reference import angular as ref
from shadowcl.render import camera_view, render_report

from conftest import SCENES

EPS = 1e-4


# Meshes --------------------------------------------------------------------------------------------------

def _mesh(*parts) -> sc.Mesh:
    vertices, faces, base = [], [], 0
    for part in parts:
        vertices.append(np.asarray(part.vertices))
        faces.append(np.asarray(part.faces) + base)
        base += len(part.vertices)
    return sc.Mesh(np.vstack(vertices), np.vstack(faces))


def _box(extents, centre):
    box = trimesh.creation.box(extents=extents)
    box.apply_translation(centre)
    return box


def cube_over_plane() -> sc.Mesh:
    return _mesh(_box((1, 1, 1), (0, 1.5, 0)), _box((8, 0.2, 8), (0, -0.1, 0)))


def coil(turns=1.6, per_turn=40, r_in=1.0, r_out=1.6, rise=0.6, thickness=0.2) -> sc.Mesh:
    """A helical ribbon of ``turns`` turns with vertical walls (figure 2(b)): lit from straight above, its
    one ridge-edge loop (the rim of its top strip) winds twice round the sector where the turns overlap."""
    n = int(round(turns * per_turn))
    a = np.linspace(0.0, 2 * np.pi * turns, n + 1)
    y = rise * a / (2 * np.pi)
    ring = []
    for r, dy in ((r_in, 0.0), (r_out, 0.0), (r_out, thickness), (r_in, thickness)):
        ring.append(np.c_[r * np.cos(a), y + dy, r * np.sin(a)])
    vertices = np.stack(ring, axis=1).reshape(-1, 3)
    faces = []
    for i in range(n):
        for c in range(4):
            p, q = 4 * i + c, 4 * i + (c + 1) % 4
            faces += [[p, q, q + 4], [p, q + 4, p + 4]]
    faces += [[0, 2, 1], [0, 3, 2], [4 * n, 4 * n + 1, 4 * n + 2], [4 * n, 4 * n + 2, 4 * n + 3]]
    mesh = trimesh.Trimesh(vertices, np.array(faces), process=False)
    trimesh.repair.fix_winding(mesh)
    if mesh.volume < 0:
        mesh.invert()
    return sc.Mesh(mesh.vertices, mesh.faces)


def ground_points(rng, n, half=4.0, y=0.0):
    return np.c_[rng.uniform(-half, half, n), np.full(n, y), rng.uniform(-half, half, n)]


def prepared(device, mesh, light, points, **params):
    method = angular.AngularMethod(device, **params)
    method.prepare(mesh, light, np.stack([points.min(0), points.max(0)]), EPS)
    return method


def local_vertices(method):
    return method.frame.to_local(method.mesh.vertices.astype(np.float64).astype(np.float32))


# 1. Ridge-edge loops ---------------------------------------------------------------------------------------

def _check_loops(device, mesh, light, point):
    loops = angular.ridge_loops(device, mesh, light)
    origin = light.position if point else np.zeros(3)
    local = mesh.vertices.astype(np.float64) - origin
    if not point:                      # the reference's directional light comes from +Z
        _, rotation = angular.angular_frame(light, mesh.vertices)
        local = local @ rotation.T
    expected = ref.ridge_edges(local, mesh.faces, point)
    got = set()
    for loop in loops:
        chain = loop.vertices.tolist()
        for tail, head in zip(chain, chain[1:] + chain[:1]):
            assert (tail, head) not in got, "an edge appears twice in the loops"
            got.add((tail, head))
    assert got == expected
    degree = np.zeros(len(mesh.vertices), dtype=int)
    for tail, head in expected:
        degree[tail] += 1
        degree[head] += 1
    assert np.all(degree % 2 == 0), "section 2: an even number of ridge edges at every vertex"
    return loops


def test_loops_convex_and_multi(device):
    cube = _box((1, 1, 1), (0, 1.5, 0))
    assert len(_check_loops(device, _mesh(cube), sc.PointLight((0.3, 5, 0.2)), True)) == 1
    two = _mesh(cube, _box((1, 1, 1), (3, 1.5, 0)))
    assert len(_check_loops(device, two, sc.PointLight((1.3, 5, 0.2)), True)) == 2
    # a torus lit from above its axis: outer rim and inner rim, one inside the other
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=24, minor_sections=12)
    loops = _check_loops(device, _mesh(torus), sc.DirectionalLight((0, 0, -1)), False)
    assert len(loops) == 2


def test_loops_coiled(device):
    mesh = coil()
    loops = _check_loops(device, mesh, sc.DirectionalLight((0, -1, 0)), False)
    assert len(loops) == 1
    xz = mesh.vertices[loops[0].vertices][:, [0, 2]].astype(np.float64)
    # winding number round a point of the overlapped sector (angle 0.3 turn, radius 1.3): two turns
    centre = np.array([1.3 * np.cos(0.6 * np.pi), 1.3 * np.sin(0.6 * np.pi)])
    angles = np.unwrap(np.arctan2(*(xz - centre).T[::-1]))
    turns = (angles[-1] - angles[0] + np.angle(np.exp(1j * (angles[0] - angles[-1])))) / (2 * np.pi)
    assert abs(abs(turns) - 2) < 1e-6, turns


def test_loops_open_mesh_through_border(device):
    # a cup without a top: the lit inside's loop closes along the rim (border edges)
    scene = sc.Scene.load(SCENES / "hard" / "open_mesh.toml")
    _check_loops(device, scene.mesh, scene.lights[0], True)


def test_loops_non_manifold_refused(device):
    scene = sc.Scene.load(SCENES / "hard" / "non_manifold.toml")
    with pytest.raises(ValueError, match="mesh: "):
        angular.ridge_loops(device, scene.mesh, scene.lights[0])


# 2. The table ----------------------------------------------------------------------------------------------

def _ref_table(method):
    f = method.frame
    return ref.table(local_vertices(method), method.mesh.faces, method.table.table_faces, f.t0, f.dt, f.rows,
                     f.full_circle, f.point, f.pad_t, f.pad_s)


def _compare_table(method):
    f = method.frame
    got = method.entries()
    want = _ref_table(method)
    # discrete part: the (face, row) pairs, identified by the plane; ties at the ends of a face's padded
    # range (a row boundary within ROW_TIE of it) aside
    corners = local_vertices(method)[method.mesh.faces[method.table.table_faces]]
    t = ref.row_coordinate(corners, f.point)
    if f.point:
        t = t[:, :1] + (t - t[:, :1] + np.pi) % (2 * np.pi) - np.pi
    _, pads = ref.face_rows(corners, f.t0, f.dt, f.rows, f.full_circle, f.point, f.pad_t)
    ends = np.stack([t.min(1) - pads, t.max(1) + pads], axis=1)
    tie_faces = set()
    for face, (lo, hi) in zip(method.table.table_faces, ends):
        for e in (lo, hi):
            g = (e - f.t0) / f.dt
            if abs(g - np.round(g)) < ref.ROW_TIE:
                tie_faces.add(int(face))
    got_face = got["face"]
    assert set(got_face.tolist()) <= set(method.table.table_faces.tolist())
    planes = want["plane"][got_face]
    scale = np.linalg.norm(planes[:, :3], axis=1, keepdims=True)
    assert np.allclose(got["plane"] / scale, planes / scale, atol=1e-5)   # float32 cross products of O(1) corners
    got_set = {(int(r), int(fc)) for r, fc in zip(got["row"], got_face) if fc not in tie_faces}
    want_set = {(int(r), int(fc)) for r, fc in zip(want["row"], want["face"]) if fc not in tie_faces}
    assert got_set == want_set, f"(row, face) pairs differ: {len(got_set ^ want_set)} of {len(want_set)}"
    # rows sorted by s_lo (section 7.1, step 1.7)
    for k in range(f.rows):
        lo = got["s_lo"][got["offsets"][k]:got["offsets"][k + 1]]
        assert np.all(np.diff(lo) >= 0)
    # a face's pieces in a row (kernels/angular.cl face_rows) tile its span: joined, the span; spans within
    # S_TOL (reference docstring) where both cut the face
    pieces = {}
    for lo, hi, r, fc in zip(got["s_lo"], got["s_hi"], got["row"], got_face):
        pieces.setdefault((int(r), int(fc)), []).append((float(lo), float(hi)))
    index = {(int(r), int(fc)): i for i, (r, fc) in enumerate(zip(want["row"], want["face"]))}
    errors = []
    for key, parts in pieces.items():
        parts.sort()
        assert all(a[1] == b[0] for a, b in zip(parts, parts[1:])) or parts[0][0] > parts[0][1], (key, parts)
        lo, hi = parts[0][0], parts[-1][1]
        j = index.get(key)
        if j is not None and want["s_lo"][j] <= want["s_hi"][j] and lo <= hi:
            errors.append(max(abs(lo - want["s_lo"][j]), abs(hi - want["s_hi"][j])))
    assert len(errors) > 0.9 * len(got_set)
    assert max(errors) < ref.S_TOL, max(errors)
    return got, want


@pytest.mark.parametrize("rows", [1, 7, 64, 255])
def test_table_point_light_closed(device, rows):
    mesh = cube_over_plane()
    pts = ground_points(np.random.default_rng(rows), 100)
    method = prepared(device, mesh, sc.PointLight((0.3, 5, 0.2)), pts, theta_resolution=rows)
    assert method.stats["closed"] and method.stats["table_faces"] == 4   # the lit tops of the cube and the plane
    _compare_table(method)


def test_table_random_soup(device, rng):
    # an open triangle soup: every face enters the table, hidden ones too
    centres = rng.uniform(-1, 1, (60, 3))
    tris = centres[:, None] + rng.normal(scale=0.3, size=(60, 3, 3))
    mesh = sc.Mesh(tris.reshape(-1, 3), np.arange(180).reshape(60, 3))
    pts = rng.uniform(-2, 2, (500, 3))
    for light in (sc.PointLight((0.2, 4.0, 0.5)), sc.DirectionalLight((0.3, -1, 0.2))):
        method = prepared(device, mesh, light, pts, theta_resolution=97)
        assert not method.stats["closed"] and method.stats["table_faces"] == 60
        _compare_table(method)
        _compare_lookups(method, pts, None)


@pytest.mark.parametrize("rows", [16, 90])
def test_table_light_inside_full_circle(device, rng, rows):
    """A light inside the scene: rows wrap round at +-pi (faces across the cut), pillars round the pole axis
    (faces in every row, spans reaching s = +-1); table and lookups against the reference."""
    scene = sc.Scene.load(SCENES / "hard" / "light_inside.toml")
    method = angular.AngularMethod(device, theta_resolution=rows)
    method.prepare(scene.mesh, scene.lights[0], scene.bounds, EPS)
    assert method.frame.full_circle
    got, _ = _compare_table(method)
    rows_of_face = np.bincount(np.unique(np.c_[got["face"], got["row"]], axis=0)[:, 0])
    assert rows_of_face.max() == rows                              # some face is in every row (round the pole)
    assert np.any(np.maximum(got["s_hi"], -got["s_lo"]) > 1 - 1e-3)  # a span reaching the pole (s = +-1)
    lo, hi = scene.bounds
    _compare_lookups(method, rng.uniform(lo, hi, (1500, 3)), None)


# 3. Lookups ------------------------------------------------------------------------------------------------

def _compare_lookups(method, points, normals):
    """Kernel lookups against the reference lookups on the same frame; receivers whose decision is a
    float32 tie are left out: the answer changes when the faces' edges move by 1e-5 of their size (the
    device's float32 edge functions; reference docstring) or the hit's distance from the receiver moves
    by 1e-4 of eps. A receiver's row and s are no ties: spans and rows are padded past float32's error
    (a receiver on a row boundary meets the same faces in both rows)."""
    f = method.frame
    got = method.classify(points, normals)
    lp = f.to_local(points)
    ln = None if normals is None else normals @ f.rotation.T
    tab = _ref_table(method)

    def run(grow=0.0, eps=method.eps):
        return ref.classify(lp, ln, tab, f.t0, f.dt, f.rows, f.full_circle, f.point, eps, grow)

    want = run()
    tie = (run(grow=1e-5) != run(grow=-1e-5)) | (run(eps=method.eps * (1 + 1e-4)) != run(eps=method.eps * (1 - 1e-4)))
    differ = np.flatnonzero((got != want) & ~tie)
    assert len(differ) == 0, f"angular_classify: {len(differ)} of {len(lp)} differ, first {differ[:5]}"
    assert (~tie).sum() > 0.8 * len(lp)
    return got


def test_lookups_cube_over_plane(device, rng):
    mesh = cube_over_plane()
    pts = np.r_[ground_points(rng, 2000), rng.uniform(-0.6, 0.6, (300, 3)) + (0, 1.5, 0)]
    normals = np.tile([0.0, 1.0, 0.0], (len(pts), 1))
    for light in (sc.PointLight((0.3, 5, 0.2)), sc.DirectionalLight((0.3, -1, 0.2))):
        method = prepared(device, mesh, light, pts, theta_resolution=50)
        _compare_lookups(method, pts, None)
        _compare_lookups(method, pts, normals)


def test_render_runs_equal_per_pixel(device):
    """render: scan-line runs give the per-pixel masks bit for bit, and with the pole on the camera's right
    axis (rows along the scan lines) one lookup serves several pixels."""
    scene = sc.Scene.load(SCENES / "default.toml")
    runs = render_report(scene, "angular", width=160, height=90)
    single = render_report(scene, "angular", width=160, height=90, runs=False)
    assert np.array_equal(runs.shadow, single.shadow)
    seen = runs.receivers
    method = angular.AngularMethod(device, expected_receivers=len(seen.points))
    method.prepare(scene.mesh, scene.lights[0], scene.bounds, EPS)
    view = camera_view(scene, 160, 90)
    mask = method.classify_view(view, None, seen)
    right = view.matrix[0, :3] / np.linalg.norm(view.matrix[0, :3])
    assert abs(method.frame.rotation[0] @ right) > 0.999
    assert np.array_equal(mask, method.classify(seen.points, seen.normals))
    assert method.stats["lookups"] < 0.5 * len(seen.points), method.stats["lookups"]


def test_runs_count_lookups(device, rng):
    mesh = cube_over_plane()
    # scan lines across the plane: receivers in left-to-right order along world x, rows along world z
    xs, zs = np.meshgrid(np.linspace(-4, 4, 200), np.linspace(-4, 4, 50))
    pts = np.c_[xs.ravel(), np.zeros(xs.size), zs.ravel()]
    method = prepared(device, mesh, sc.PointLight((0.3, 5, 0.2)), pts, theta_resolution=100, prefer_x=(1, 0, 0))
    line = np.repeat(np.arange(50), 200)
    by_runs = method.classify_lines(pts, None, line, 50)
    lookups = method.stats["lookups"]
    assert np.array_equal(by_runs, method.classify(pts))
    assert by_runs.any() and lookups < len(pts) / 4, lookups


# Masks against the exact method ------------------------------------------------------------------------------

@pytest.mark.parametrize("table", angular.TABLES)
def test_cube_over_plane_error_bound(device, rng, table):
    """Ground receivers against exact. faces: a face's span covers the whole row band and the hit must lie
    in the triangle, so only float32 ties may differ (measured: 0 of 20 000 at 60 and 240 rows). loops: a
    receiver may differ only if the exact answer changes within half a row (in theta) of its direction,
    as the pairs are cut at the row's centre."""
    mesh, cube = cube_over_plane(), _mesh(_box((1, 1, 1), (0, 1.5, 0)))
    light = sc.PointLight((0.3, 5, 0.2))
    pts = ground_points(rng, 20000)
    exact = sc.shadow_mask(mesh, light, pts, method="exact", eps=EPS)
    errors = []
    for rows in (60, 240):
        method = prepared(device, mesh, light, pts, theta_resolution=rows, table=table)
        got = method.classify(pts)
        differ = np.flatnonzero(got != exact)
        errors.append(len(differ))
        if table == "faces":
            assert len(differ) <= 2, (rows, len(differ))
            continue
        # rotate each differing receiver about the frame's X axis (through the light) by up to half a row
        local = method.frame.to_local(pts[differ])
        changes = np.zeros(len(differ), dtype=bool)
        for frac in np.linspace(-0.5, 0.5, 11) * 1.01:
            a = frac * method.frame.dt
            c, s = np.cos(a), np.sin(a)
            rot = local.copy()
            rot[:, 1], rot[:, 2] = c * local[:, 1] - s * local[:, 2], s * local[:, 1] + c * local[:, 2]
            world = rot @ method.frame.rotation + method.frame.origin
            # the cube alone: a rotated receiver can dip under the plane, which must not count as shadow
            changes |= sc.shadow_mask(cube, light, world, method="exact", eps=EPS) != exact[differ]
        assert changes.all(), f"{(~changes).sum()} receivers differ with no shadow edge within half a row"
    if table == "loops":
        assert errors[1] < errors[0]
        assert errors[1] < 0.005 * len(pts)


HARD = sorted((SCENES / "hard").glob("*.toml"))


@pytest.mark.parametrize("path", HARD, ids=[p.stem for p in HARD])
def test_hard_cases(device, path):
    """Every hard scene, both tables. faces: at most 2 pixels differ from exact at any rows (float32 ties;
    bench/results/angular.md measured 0 on every hard scene at 960 x 540). loops: the error at the default
    resolution (the image's own limit) stays under 3 % of the covered pixels (the discretization band), and
    360 rows are no worse than 90."""
    scene = sc.Scene.load(path)
    exact = render_report(scene, "exact", width=160, height=90).shadow
    for table in angular.TABLES:
        wrong = {}
        for rows in (None, 90, 360):
            result = render_report(scene, "angular", width=160, height=90, theta_resolution=rows, table=table)
            wrong[rows] = np.count_nonzero(result.shadow != exact)
        if table == "faces":
            assert max(wrong.values()) <= 2, wrong
            continue
        # 3 %: the 256-segment sphere's terminator (a grazing self-shadow band half a row wide)
        assert wrong[None] <= 0.03 * exact.size, (table, wrong)
        assert wrong[360] <= wrong[90] + 0.002 * exact.size, (table, wrong)


@pytest.mark.parametrize("table", angular.TABLES)
def test_coiled_pairing(device, table):
    """Figure 4: a coiled loop. The paper's pairing of the loop's crossings (reference) covers the doubly
    wound sector that even-odd pairing would leave as a hole, and the device table's spans cover it: loops,
    the device's own section-4 pairs, the same; faces, the lit faces' spans over the whole row band, at
    least that (they also hold the directions off the row's centre)."""
    mesh = coil()
    light = sc.DirectionalLight((0, -1, 0))
    pts = ground_points(np.random.default_rng(4), 4000, half=2.0, y=-0.5)
    method = prepared(device, mesh, light, pts, theta_resolution=40, table=table)
    loops = angular.ridge_loops(device, mesh, light)
    loop_local = method.frame.to_local(mesh.vertices[loops[0].vertices].astype(np.float64))
    got = method.entries()
    holes = 0
    for k, tk in enumerate(method.frame.row_centres):
        paper = ref.paper_pairs(loop_local, tk, False)
        naive = ref.even_odd_pairs(loop_local, tk, False)
        s = np.linspace(-2, 2, 801)
        ends = np.array([e for p in paper for e in p] + [e for p in naive for e in p])
        far = np.min(np.abs(s[:, None] - ends[None, :]), axis=1) > 1e-3 if len(ends) else np.ones(len(s), bool)
        sel = slice(got["offsets"][k], got["offsets"][k + 1])
        spans = list(zip(got["s_lo"][sel], got["s_hi"][sel]))
        if table == "loops":
            assert np.array_equal(ref.covered(spans, s)[far], ref.covered(paper, s)[far]), f"row {k}"
        else:
            assert np.all(ref.covered(spans, s)[far] >= ref.covered(paper, s)[far]), f"row {k}"
        holes += np.count_nonzero(ref.covered(paper, s)[far] & ~ref.covered(naive, s)[far])
    assert holes > 0, "the coil is there: even-odd pairing would open holes"
    exact = sc.shadow_mask(mesh, light, pts, method="exact", eps=EPS)
    assert np.mean(method.classify(pts) != exact) < 0.03


def _over_ground(shape):
    """(shape resting 0.2 above a 10 x 10 ground quad, the two as one mesh)."""
    shape = shape.copy()
    shape.apply_translation([0.0, 1.2 - shape.bounds[0, 1], 0.0])
    n = len(shape.vertices)
    ground = np.array([[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]], dtype=float)
    return shape, sc.Mesh(np.r_[shape.vertices, ground], np.r_[shape.faces, [[n, n + 2, n + 1], [n, n + 3, n + 2]]])


@pytest.mark.parametrize("shape", ["sphere", "torus"])
def test_lit_caps_and_ground(device, shape):
    """Receivers ON a closed occluder's lit side (face normals, directional light) are not shadowed by a
    neighbouring face's plane (the faces table used to cut faces at the row's centre and extend their
    planes past their edges: 15-22 % false shadows on such caps, bench/results/angular_caps.md), and the
    ground under it loses no shadow (spans cover the whole row band: no face is missed). Measured on 3000
    + 3000 receivers per shape and light (three lights, these two shapes): 0 false shadows and 0 false
    lights on both sets; the bound of 2 per 1500 leaves room for float32 ties (a receiver within ~1e-6 of
    a face's edge or of the eps offset), far below the old 12 %."""
    from shadowcl.reference.exact import shadow_mask as truth

    made = {"sphere": lambda: trimesh.creation.icosphere(subdivisions=3),
            "torus": lambda: trimesh.creation.torus(major_radius=0.8, minor_radius=0.35, major_sections=48,
                                                    minor_sections=24)}
    solid, mesh = _over_ground(made[shape]())
    on, face = trimesh.sample.sample_surface(solid, 1500, seed=7)
    rng = np.random.default_rng(7)
    ground = np.c_[rng.uniform(-2.5, 2.5, 1500), np.zeros(1500), rng.uniform(-2.5, 2.5, 1500)]
    for light in (sc.DirectionalLight((0.3, -1, 0.2)), sc.DirectionalLight((-0.7, -0.5, 0.4))):
        for points, normals in ((on, solid.face_normals[face]), (ground, np.tile([0.0, 1.0, 0.0], (1500, 1)))):
            got = sc.shadow_mask(mesh, light, points, normals, method="angular", device=device)
            want = truth(mesh.vertices, mesh.faces, light, points, normals)
            assert 0.03 * len(points) < want.sum() < 0.97 * len(points)     # both answers are exercised
            assert np.count_nonzero(got & ~want) <= 2, (shape, light.direction, "false shadows")
            assert np.count_nonzero(~got & want) <= 2, (shape, light.direction, "false lights")


def test_shadow_counts_two_lights(device, rng):
    mesh = cube_over_plane()
    lights = [sc.PointLight((0.3, 5, 0.2)), sc.PointLight((-2.0, 4, 1.0))]
    pts = ground_points(rng, 5000)
    counts = sc.shadow_counts(mesh, lights, pts, method="angular", theta_resolution=400, device=device, eps=EPS)
    exact = sum(sc.shadow_mask(mesh, l, pts, method="exact", eps=EPS).astype(int) for l in lights)
    assert counts.dtype == np.float64 and counts.max() == 2
    assert np.mean(counts != exact) < 0.01


def test_api(device):
    assert "theta_resolution" in sc.methods()["angular"]
    mesh = cube_over_plane()
    mask = sc.shadow_mask(mesh, sc.PointLight((0.3, 5, 0.2)), [[0.0, 0.0, 0.0], [3.5, 0.0, 3.5]], method="angular")
    assert mask.tolist() == [True, False]
    image = sc.render(sc.Scene.load(SCENES / "default.toml"), method="angular", width=64, height=36)
    assert image.shape == (36, 64, 3)


# Bad input -----------------------------------------------------------------------------------------------

# The paper's table (table="loops") -------------------------------------------------------------------------

def torus_over_plane(axis_up=True) -> sc.Mesh:
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=24, minor_sections=12)
    if axis_up:
        torus.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    torus.apply_translation((0, 1.5, 0))
    return _mesh(torus, _box((8, 0.2, 8), (0, -0.1, 0)))


def _tie_rows(method, local):
    """Rows whose centre lies within ROW_TIE (row units) of a vertex's row coordinate: an edge ending there
    may cross the row in float32 and not in float64 (or the other way)."""
    f = method.frame
    g = (ref.row_coordinate(local, f.point) - f.t0) / f.dt - 0.5
    near = np.abs(g - np.round(g)) < ref.ROW_TIE
    rows = np.round(g[near]).astype(np.int64)
    return set((rows % f.rows if f.full_circle else rows).tolist())


def _compare_loop_table(method):
    """Device loop table against ref.loop_table on the same frame and loops: per row (ties aside) the same
    number of pairs, in s_lo order, the same spans within S_TOL, the same grouping into regions (a
    one-to-one map of the labels), and both reference ends on the device pair's depth plane."""
    f = method.frame
    local = local_vertices(method)
    chains = [loop.vertices.tolist() for loop in method.loops.loops]
    want = ref.loop_table(local, method.mesh.faces, chains, f.t0, f.dt, f.rows, f.full_circle, f.point)
    got = method.entries()
    ties = _tie_rows(method, local)
    mapping, checked = {}, 0
    for k in range(f.rows):
        g = np.arange(got["offsets"][k], got["offsets"][k + 1])
        assert np.all(np.diff(got["s_lo"][g]) >= 0), f"row {k} not sorted by s_lo"
        if k in ties:
            continue
        w = np.flatnonzero(want["row"] == k)
        assert len(g) == len(w), f"row {k}: {len(g)} pairs, reference {len(w)}"
        assert np.all(got["region"][g] >= 0)
        # match each device pair to an unused reference pair of the row with the same ends (s within S_TOL:
        # float32 cuts of float32 corners, reference docstring) whose ends both lie on the device pair's depth
        # plane (float32 plane from float32 points: ~1e-6 relative; 1e-4 leaves room for grazing cuts). A
        # zero plane (chord along the light's rays) matches a zero-width reference pair. Degenerate rows (a
        # coil's end wall edge-on to the light) hold equal spans with different planes: hence the matching.
        free = set(w.tolist())
        for i in g:
            plane = got["plane"][i].astype(np.float64)
            found = None
            for j in sorted(free):
                if abs(got["s_lo"][i] - want["s_lo"][j]) > ref.S_TOL or abs(got["s_hi"][i] - want["s_hi"][j]) > ref.S_TOL:
                    continue
                scale = np.linalg.norm(plane[:3]) * max(np.linalg.norm(want["a"][j]), 1.0)
                if scale == 0:
                    ok = want["s_hi"][j] - want["s_lo"][j] < ref.S_TOL
                else:
                    ok = all(abs(plane[:3] @ end - plane[3]) <= 1e-4 * scale for end in (want["a"][j], want["b"][j]))
                if ok:
                    found = j
                    break
            assert found is not None, f"row {k}: no reference pair for device pair {i}"
            free.discard(found)
            assert mapping.setdefault(int(got["region"][i]), int(want["region"][found])) == want["region"][found], \
                f"row {k}: regions differ"
        checked += len(w)
    assert len(set(mapping.values())) == len(mapping)
    assert checked > 0
    return got, want


@pytest.mark.parametrize("case", ["cube_point_7", "cube_point_64", "cube_directional", "torus_point", "torus_directional",
                                  "coil", "light_inside"])
def test_loop_table(device, case):
    rng = np.random.default_rng(5)
    if case.startswith("cube"):
        mesh, rows = cube_over_plane(), int(case.split("_")[-1]) if case[-1].isdigit() else 50
        light = sc.DirectionalLight((0.3, -1, 0.2)) if "directional" in case else sc.PointLight((0.3, 5, 0.2))
        method = prepared(device, mesh, light, ground_points(rng, 100), theta_resolution=rows, table="loops")
    elif case.startswith("torus"):
        light = sc.DirectionalLight((0.2, -1, 0.1)) if "directional" in case else sc.PointLight((0.3, 5, 0.2))
        method = prepared(device, torus_over_plane(), light, ground_points(rng, 100), theta_resolution=83,
                          table="loops")
    elif case == "coil":
        # tilted: from straight above the two turns project onto each other and crossings tie in s (the
        # pairing of equal keys is then a matter of sort order)
        method = prepared(device, coil(), sc.DirectionalLight((0.07, -1, 0.04)),
                          ground_points(rng, 100, half=2.0, y=-0.5), theta_resolution=40, table="loops")
    else:
        scene = sc.Scene.load(SCENES / "hard" / "light_inside.toml")
        method = angular.AngularMethod(device, theta_resolution=90, table="loops")
        method.prepare(scene.mesh, scene.lights[0], scene.bounds, EPS)
        assert method.frame.full_circle and method.stats["poles"] > 0     # pillars round the pole axis
    assert method.stats["table_faces"] == 0 and method.stats["pairs"] == method.table.entries
    _compare_loop_table(method)
    if case.startswith("torus") or case == "light_inside":
        assert method.stats["creases"] > 0                 # section 5's duplicates are exercised
    _compare_lookups_loops(method, rng)


def _compare_lookups_loops(method, rng):
    """Kernel lookups on the loop table against a float64 lookup of the device's own records: s in a
    span (ties within S_TOL aside) whose plane the segment to the light meets further than eps."""
    lo, hi = method.mesh.bounds
    pts = rng.uniform(lo - 0.5, hi + 0.5, (3000, 3))
    got = method.classify(pts)
    e = method.entries()
    f = method.frame
    lp = f.to_local(pts)
    tab = dict(row=e["row"], face=np.arange(len(e["row"])), s_lo=e["s_lo"].astype(np.float64),
               s_hi=e["s_hi"].astype(np.float64), plane=e["plane"].astype(np.float64))
    want = ref.classify(lp, None, tab, f.t0, f.dt, f.rows, f.full_circle, f.point, method.eps)
    k, s, _ = ref.receiver_keys(lp, f.t0, f.dt, f.rows, f.full_circle, f.point)
    g = (ref.row_coordinate(lp, f.point) - f.t0) / f.dt
    tie = np.abs(g - np.round(g)) < ref.ROW_TIE
    for i in range(len(lp)):
        sel = e["row"] == k[i]
        ends = np.r_[e["s_lo"][sel], e["s_hi"][sel]]
        if len(ends) and np.min(np.abs(ends - s[i])) < 10 * ref.S_TOL:
            tie[i] = True
    assert not np.any((got != want) & ~tie)
    assert (~tie).sum() > 0.8 * len(lp)


def test_loops_masks(device, rng):
    """The loop table against exact: the torus's hole stays lit (its outer and inner loops bound one lit
    region and pair together), and the ground under both the cube and the torus errs only in the
    discretization band."""
    light = sc.PointLight((0.3, 5, 0.2))
    pts = ground_points(rng, 20000)
    for mesh in (cube_over_plane(), torus_over_plane()):
        exact = sc.shadow_mask(mesh, light, pts, method="exact", eps=EPS)
        wrong = {}
        for table in angular.TABLES:
            for rows in (100, 400):
                got = prepared(device, mesh, light, pts, theta_resolution=rows, table=table).classify(pts)
                wrong[table, rows] = np.count_nonzero(got != exact)
        # the faces table is exact but for float32 ties (test_cube_over_plane_error_bound); the loop table's
        # pairs are cut at the rows' centres: its error is the half-row band
        for rows in (100, 400):
            assert wrong["faces", rows] <= min(wrong["loops", rows], 2), wrong
        assert wrong["loops", 400] < wrong["loops", 100] < 0.01 * len(pts), wrong
    # the hole: ground points seen through it from the light are lit
    hole = pts[np.hypot(pts[:, 0] - 0.1, pts[:, 2] - 0.07) < 0.6]
    mesh = torus_over_plane()
    got = prepared(device, mesh, light, pts, theta_resolution=400, table="loops").classify(hole)
    assert len(hole) > 50 and not got.any()


def test_light_inside_closed_solid(device):
    """A point light inside a closed solid: refused with a ValueError naming the light (every receiver
    outside would be in shadow; no face turns to the light, so the table would say lit)."""
    box = _box((1, 1, 1), (0, 1.5, 0))
    inverted = trimesh.Trimesh(box.vertices, box.faces[:, ::-1], process=False)    # wound inwards: all faces lit
    for mesh in (_mesh(box, _box((8, 0.2, 8), (0, -0.1, 0))), _mesh(inverted), cube_over_plane()):
        for table in angular.TABLES:
            with pytest.raises(ValueError, match="light.*inside a closed solid"):
                prepared(device, mesh, sc.PointLight((0.1, 1.6, -0.2)), ground_points(np.random.default_rng(1), 10),
                         table=table)
    with pytest.raises(ValueError, match="light"):
        sc.shadow_mask(cube_over_plane(), sc.PointLight((0.0, 1.5, 0.0)), [[3.0, 0.0, 3.0]], method="angular")
    # outside it (just above the top), and a light in a room (inside the walls' ring, not their material): fine
    prepared(device, cube_over_plane(), sc.PointLight((0.1, 2.01, -0.2)), ground_points(np.random.default_rng(1), 10))
    scene = sc.Scene.load(SCENES / "hard" / "light_inside.toml")
    angular.AngularMethod(device, theta_resolution=30).prepare(scene.mesh, scene.lights[0], scene.bounds, EPS)


BAD = [
    (lambda d: angular.AngularMethod(d, table="paper"), ValueError, "table"),
    (lambda d: angular.AngularMethod(d, table=1), TypeError, "table"),
    (lambda d: angular.AngularMethod(d, theta_resolution=0), ValueError, "theta_resolution"),
    (lambda d: angular.AngularMethod(d, theta_resolution=1.5), TypeError, "theta_resolution"),
    (lambda d: angular.AngularMethod(d, theta_resolution=10**7), ValueError, "theta_resolution"),
    (lambda d: angular.AngularMethod(d, runs="yes"), TypeError, "runs"),
    (lambda d: angular.AngularMethod(d, prefer_x=(np.nan, 0, 0)), ValueError, "prefer_x"),
    (lambda d: angular.AngularMethod(d, prefer_x=(1, 0)), ValueError, "prefer_x"),
    (lambda d: angular.AngularMethod(d, prefer_x=(0, 0, 0)), ValueError, "prefer_x"),
    (lambda d: angular.AngularMethod(d).classify(np.zeros((1, 3))), RuntimeError, "prepare"),
    (lambda d: angular.AngularMethod(d).prepare("mesh", sc.PointLight((0, 1, 0)), np.zeros((2, 3)), 0.0),
     TypeError, "mesh"),
    (lambda d: angular.AngularMethod(d).prepare(cube_over_plane(), "light", np.zeros((2, 3)), 0.0), TypeError, "light"),
    (lambda d: angular.AngularMethod(d).prepare(cube_over_plane(), sc.PointLight((0, 5, 0)), np.zeros((2, 3)),
                                                -1.0), ValueError, "eps"),
    (lambda d: prepared(d, cube_over_plane(), sc.PointLight((0, 5, 0)), np.zeros((2, 3))).classify([[np.nan, 0, 0]]),
     ValueError, "points"),
    (lambda d: prepared(d, cube_over_plane(), sc.PointLight((0, 5, 0)), np.zeros((2, 3))).classify(
        np.zeros((2, 3)), np.zeros((2, 3))), ValueError, "normals"),
    (lambda d: prepared(d, cube_over_plane(), sc.PointLight((0, 5, 0)), np.zeros((2, 3))).classify_lines(
        np.zeros((2, 3)), None, [1, 0], 2), ValueError, "line"),
    (lambda d: sc.shadow_counts(cube_over_plane(), [], np.zeros((1, 3)), method="angular", device=d), ValueError,
     "lights"),
    (lambda d: sc.shadow_mask(cube_over_plane(), sc.PointLight((0, 5, 0)), np.zeros((1, 3)), method="angular",
                              theta_bins=3), TypeError, "theta_bins"),
]


@pytest.mark.parametrize("call, error, match", BAD, ids=[f"bad{i}" for i in range(len(BAD))])
def test_bad_input(device, call, error, match):
    with pytest.raises(error, match=match):
        call(device)


def test_table_too_big(small_buffer_device):
    # 65536 rows of a plane spanning them all: ~65536 records of 32 bytes fit; a mesh of many such faces not
    big = _mesh(*[_box((8, 0.2, 8), (0, -0.1 - 1e-3 * i, 0)) for i in range(100)])
    method = angular.AngularMethod(small_buffer_device, theta_resolution=angular.MAX_ROWS)
    with pytest.raises(ValueError, match="theta_resolution"):
        method.prepare(big, sc.PointLight((0.1, 5, 0.1)), big.bounds, EPS)


def test_bench_quick(tmp_path):
    """bench/angular.py --quick (about 7 s): runs, and its results hold both tables."""
    import json
    import sys
    from conftest import PROJECT

    sys.path.insert(0, str(PROJECT / "bench"))
    import angular as bench  # noqa: E402  (bench/angular.py, not shadowcl.angular)

    bench.main(["--quick", "--out", str(tmp_path)])
    doc = json.loads((tmp_path / "angular-quick.json").read_text())
    tables = {r.get("table") for r in doc["speed_error"] if r["method"] == "angular"}
    assert tables == set(angular.TABLES)
    assert {p["table"] for p in doc["scalability"]["points"]} == set(angular.TABLES)
    assert "Tables at theta_resolution=None" in (tmp_path / "angular-quick.md").read_text()


@pytest.mark.parametrize("table, kernel", [("faces", "fill_rows"), ("loops", "fill_edges")])
def test_fills_never_write_past_their_rows(device, monkeypatch, table, kernel):
    """The fills write behind the rows' counts: given too few slots (a quarter of the counted records),
    a fill drops the writes past each row's end and the host raises, naming the kernel, instead of
    writing out of bounds or returning a short table."""
    counts = angular.row_counts
    monkeypatch.setattr(angular.table, "row_counts", lambda *args: counts(*args) // 4)   # where build_table looks it up
    with pytest.raises(RuntimeError, match=f"angular {kernel} met .* entries more than its count made room for"):
        prepared(device, torus_over_plane(), sc.PointLight((0.3, 3.0, 0.2)), ground_points(np.random.default_rng(2), 10),
                 theta_resolution=64, table=table)


def test_distant_point_light_keeps_the_table_small_and_right(device):
    """The float32 pads scale with the occluders' angular size: a point light 1e4 sizes away lists about
    as many entries as one 10 sizes away (absolute pads put every face in most rows: 14x at 1e4 on
    this sphere), and the faces table still answers as exact does."""
    from shadowcl.testing import icosphere
    mesh = icosphere(4)
    rng = np.random.default_rng(5)
    points = np.c_[rng.uniform(-3, 3, 20_000), np.full(20_000, -2.0), rng.uniform(-3, 3, 20_000)]
    entries = {}
    for distance in (10.0, 1e3, 1e4):
        light = sc.PointLight((0.01 * distance, distance, 0.007 * distance))
        shadows = sc.prepare(mesh, light, "angular", bounds=[points.min(0), points.max(0)], device=device)
        got = shadows.mask(points)
        truth = sc.shadow_mask(mesh, light, points, method="exact", device=device)
        assert truth.sum() > 1000 and np.count_nonzero(got != truth) <= 2, distance
        entries[distance] = shadows.stats["entries"]
    assert entries[1e4] <= 1.5 * entries[10.0] and entries[1e3] <= 1.5 * entries[10.0], entries
