"""shadowcl.solids: the certificate that lets the exact method list only the faces a light needs of a
closed solid, against independent answers (a linear program for whether two triangles meet, the
winding number for inside-out regions), and the public exact call with and without the cull."""

import manifold3d
import numpy as np
import pytest
import trimesh
from scipy.optimize import linprog

import shadowcl as sc
from shadowcl import solids, topology


def _solid(manifold) -> sc.Mesh:
    out = manifold.to_mesh()
    return sc.Mesh(out.vert_properties[:, :3], out.tri_verts)


def _joined(*meshes: sc.Mesh) -> sc.Mesh:
    return sc.Mesh.concatenate(list(meshes))


def _finger() -> sc.Mesh:
    """A closed, consistently wound sphere whose north cap is pushed down through the south pole: it
    crosses itself, and inside the finger below the sphere its winding number is -1."""
    sphere = trimesh.creation.icosphere(3)
    v = sphere.vertices.copy()
    cap = v[:, 2] > 0.3
    v[cap, 2] = 0.3 - 3.0 * (v[cap, 2] - 0.3) / 0.7
    v[cap, :2] *= 0.5
    return sc.Mesh(v, sphere.faces)


def _certified_sigma(mesh: sc.Mesh) -> set:
    return set(np.unique(solids.solids(mesh).sigma).tolist())


def test_certifies_embedded_solids_and_their_winding():
    """manifold3d's solids (embedded by construction), CSG with holes and a cavity, disjoint parts that
    overlap one another (each component is judged alone), flat faces made of grids of triangles (whose
    corners' fans have collinear edges: only the sectors' test proves those apart): every face
    certified, +1; reversed, -1."""
    cases = {
        "sphere": _solid(manifold3d.Manifold.sphere(1.0, 48)),
        "box": _solid(manifold3d.Manifold.cube((2, 1, 3), True)),
        "holes": _solid(manifold3d.Manifold.cube((1.4, 1.4, 1.4), True) - manifold3d.Manifold.sphere(0.92, 48)),
        "cavity": _solid(manifold3d.Manifold.cube((2, 2, 2), True) - manifold3d.Manifold.cube((1.5, 1.5, 1.5), True)),
        "overlapping parts": _joined(_solid(manifold3d.Manifold.sphere(1.0, 32)),
                                     _solid(manifold3d.Manifold.sphere(1.0, 32).translate((0.5, 0, 0)))),
        "grid-triangulated box": _solid(manifold3d.Manifold.cube((1, 1, 1), True).refine(4)),
        "stair": _solid(manifold3d.Manifold.cube((3, 1, 1)) + manifold3d.Manifold.cube((2, 1, 1)).translate((0, 0, 1))
                        + manifold3d.Manifold.cube((1, 1, 1)).translate((0, 0, 2))),
    }
    for name, mesh in cases.items():
        sigma = solids.solids(mesh).sigma
        assert np.all(sigma == 1) or (name == "cavity" and set(np.unique(sigma)) == {-1, 1}), name
        flipped = solids.solids(sc.Mesh(mesh.vertices, mesh.faces[:, ::-1])).sigma
        assert np.array_equal(flipped, -sigma), name


def test_refuses_what_is_not_an_embedded_closed_solid():
    """An open box, a self-crossing sphere, a box with a corner pushed through the far side and one
    with a corner pushed onto the far face (touching itself: not provably apart): not certified. A
    separate good part stays certified."""
    box = trimesh.creation.box((1, 1, 1))
    top = np.argmax(box.vertices.sum(axis=1))
    pushed, touching = box.vertices.copy(), box.vertices.copy()
    pushed[top] = (-1.0, -1.0, -1.0)
    touching[top] = (-0.25, -0.25, -0.5)
    good = trimesh.creation.icosphere(2)
    good.vertices += (10, 0, 0)
    cases = {
        "open box": sc.Mesh(box.vertices, box.faces[1:]),
        "finger": _finger(),
        "corner pushed through": sc.Mesh(pushed, box.faces),
        "corner on the far face": sc.Mesh(touching, box.faces),
    }
    for name, mesh in cases.items():
        assert topology.edge_adjacency(mesh).closed_faces.all() or name == "open box", name
        assert _certified_sigma(mesh) == {0}, name
        with_good = _joined(mesh, sc.Mesh(good.vertices, good.faces))
        sigma = solids.solids(with_good).sigma
        assert np.all(sigma[:len(mesh.faces)] == 0) and np.all(sigma[len(mesh.faces):] == 1), name


def test_the_finger_needs_its_certificate():
    """On the finger, listing only the faces turned towards the light (what a certificate would allow)
    changes thousands of answers, so the certificate carries weight. The public call with the cull
    asked for is exact: the finger keeps all its faces."""
    mesh = _finger()
    rng = np.random.default_rng(3)
    points = rng.uniform(-1.5, 1.5, (100_000, 3)) * (1, 1, 2)
    direction = np.array([0.3, -0.2, 1.0])
    light = sc.DirectionalLight(direction)
    normals = np.cross(*(mesh.vertices[mesh.faces[:, k]] - mesh.vertices[mesh.faces[:, 0]] for k in (1, 2)))
    toward = sc.Mesh(mesh.vertices, mesh.faces[normals @ -light.direction > 0])
    truth = sc.shadow_mask(mesh, light, points, eps=1e-4)
    assert np.count_nonzero(sc.shadow_mask(toward, light, points, eps=1e-4) != truth) > 500
    assert np.array_equal(sc.shadow_mask(mesh, light, points, eps=1e-4, cull=True), truth)


def _surface_points(mesh: sc.Mesh, count: int, rng) -> tuple[np.ndarray, np.ndarray]:
    tri = mesh.vertices.astype(np.float64)[mesh.faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(normal, axis=1)
    face = rng.choice(len(tri), count, p=area / area.sum())
    u, v = rng.random((2, count))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[face]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0]), normal[face]


@pytest.mark.parametrize("normals_given", [True, False])
def test_cull_gives_the_same_masks(rng, normals_given):
    """The exact method with the cull against without, on receivers on every surface and in the air:
    a ground slab, a ball, a box with holes, a closed cavity (inwards-wound inner wall) and an open
    roof (not certified: listed for every light); point lights outside everything, inside the cavity
    and inside the ball, and directional lights. The masks are the same bit for bit; every light lists
    fewer faces, and the light outside everything fewer than 60 % of the certified ones."""
    parts = [
        _solid(manifold3d.Manifold.cube((8, 0.2, 8), True).translate((0, -0.1, 0))),
        _solid(manifold3d.Manifold.sphere(0.6, 16).translate((-1.5, 0.6, 0.8))),
        _solid((manifold3d.Manifold.cube((1.4, 1.4, 1.4), True) - manifold3d.Manifold.sphere(0.92, 40))
               .translate((0.5, 0.7, -0.5))),
        _solid((manifold3d.Manifold.cube((1.6, 1.6, 1.6), True) - manifold3d.Manifold.cube((1.2, 1.2, 1.2), True))
               .translate((2.2, 0.8, 1.5))),
        sc.Mesh([(-2.5, 1.8, -2.5), (-0.5, 1.8, -2.5), (-0.5, 1.9, -0.5), (-2.5, 1.9, -0.5)], [(0, 1, 2), (0, 2, 3)]),
    ]
    mesh = _joined(*parts)
    points, normals = _surface_points(mesh, 60_000, rng)
    points = np.r_[points, rng.uniform((-4, -0.5, -4), (4, 3, 4), (20_000, 3))]
    normals = np.r_[normals, rng.normal(size=(20_000, 3))]
    lights = [sc.PointLight((-3.0, 4.0, 2.5)), sc.PointLight((2.2, 0.8, 1.5)), sc.PointLight((-1.5, 0.6, 0.8)),
              sc.PointLight(rng.uniform((-4, 0.5, -4), (4, 3, 4))),
              sc.DirectionalLight((0.4, -1.0, 0.3)), sc.DirectionalLight(rng.normal(size=3))]
    for light in lights:
        shadows = sc.prepare(mesh, light, method="exact", eps=1e-4, cull=True)
        culled = shadows.mask(points, normals if normals_given else None)
        full = sc.shadow_mask(mesh, light, points, normals if normals_given else None, eps=1e-4, cull=False)
        assert np.array_equal(culled, full), light
        listed = shadows._instance.stats["listed_triangles"]
        assert listed < len(mesh.faces), light                        # the cull was made
    certified = solids.solids(mesh).certified_faces
    outside = sc.prepare(mesh, lights[0], method="exact", eps=1e-4, cull=True)._instance.stats
    assert outside["listed_triangles"] < len(mesh.faces) - 0.4 * certified


def _rotated_yard(seed: int):
    """A box and a ball resting on a ground quad, the whole turned at random (no axis-aligned luck), the
    rotation, and 20 k receivers on the ground."""
    from scipy.spatial.transform import Rotation

    base = _joined(_solid(manifold3d.Manifold.cube((1, 1, 1)).translate((0.5, 0, -0.5))),
                   _solid(manifold3d.Manifold.sphere(0.4, 24).translate((-1.5, 0.4, 0))),
                   sc.Mesh([(-4, 0, -4), (4, 0, -4), (4, 0, 4), (-4, 0, 4)], [(0, 2, 1), (0, 3, 2)]))
    rotation = Rotation.random(random_state=seed).as_matrix()
    ground = np.random.default_rng(seed).uniform((-4, 0, -4), (4, 0, 4), (20_000, 3))
    ground[:, 1] = 0
    return sc.Mesh(base.vertices.astype(np.float64) @ rotation.T, base.faces), rotation, ground @ rotation.T


@pytest.mark.parametrize("height", [0.0, 1e-9, 1e-7, 1e-6, 1e-5, -1e-7])
def test_lights_nearly_edge_on_to_a_face_list_its_solid(height):
    """A point light just above (or in, or under) the ground's plane, which is the box's bottom face's,
    and a sun travelling along it: the kernels cannot tell the light's side of those faces, the
    walk may miss a crossing there, so the cull lists such a solid whole. Found by a red team: 57 of
    40 k receivers lit that are in shadow, with the light 1e-7 above the floor, before this rule."""
    mesh, rotation, points = _rotated_yard(2)
    for light in (sc.PointLight(rotation @ np.array([0.1, height, 0.3])),
                  sc.DirectionalLight(rotation @ np.array([-1.0, height, 0.2]))):
        culled = sc.shadow_mask(mesh, light, points, cull=True)
        assert np.array_equal(culled, sc.shadow_mask(mesh, light, points, cull=False)), light


def test_lights_hugging_a_solid_list_it():
    """A point light a few millionths of the scene off a certified solid, farther than its size's
    clearance and edge-on to no face: the walks' float32 segments end within ~6e-8 of their length of
    the light, short of the face it hovers over, or their crossing near an edge falls between the fine
    cells' masks and the watertight test; without the cull the face they entered by catches them.
    Found by a red team (188 of 20 k and 32 of 30 k receivers lit that are in shadow); such a solid is
    listed whole now (solids.NEAR_LIGHT)."""
    rng = np.random.default_rng(0)
    side = 1e-2                                                 # a cube 1/300 of the scene, a ceiling over the light
    cube = _solid(manifold3d.Manifold.cube((side, side, side), True).translate((0, 0, side / 2)))
    ceiling = sc.Mesh([(-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)], [(0, 1, 2), (0, 2, 3)])
    depth = rng.uniform(-3.0, -0.2, 20_000)
    spread = rng.uniform(-0.3, 0.3, (20_000, 2)) * (side - depth)[:, None]
    spread[:10_000, 1] = spread[:10_000, 0]                     # half in the plane of the top face's diagonal
    ball = _solid(manifold3d.Manifold.sphere(0.5, 32))
    corner = ball.vertices.astype(np.float64)[np.argmax(ball.vertices @ np.float32((-0.3, 0.1, 1.0)))]
    near = sc.PointLight(corner * (1 + 1.5e-6 * np.sqrt(3) / 0.5))   # 1.5e-6 of the diagonal off a corner, outwards
    toward = corner + rng.uniform(-0.05, 0.05, (30_000, 3)) * 0.1     # rays from it past the corner's faces
    along = (toward - near.position) / np.linalg.norm(toward - near.position, axis=1)[:, None]
    cases = [(_joined(cube, ceiling), sc.PointLight((0.0, 0.0, side * (1 + 1e-5))), np.c_[spread, depth]),
             (ball, near, near.position + along * rng.uniform(1.0, 2.5, (30_000, 1)))]
    for mesh, light, points in cases:
        assert sc.prepare(mesh, light, eps=1e-7, cull=True)._instance.stats["listed_triangles"] == len(mesh.faces)
        culled = sc.shadow_mask(mesh, light, points, eps=1e-7, cull=True)
        assert np.array_equal(culled, sc.shadow_mask(mesh, light, points, eps=1e-7, cull=False)), light


def test_no_cull_with_the_leaky_test():
    """dot5 leaks through shared edges, and the face it would have stopped the ray at may be one the
    cull leaves out: with test='dot5' every face is listed."""
    mesh, _, points = _rotated_yard(3)
    light = sc.PointLight((0.3, 4.0, 0.2))
    assert sc.prepare(mesh, light, eps=1e-4, cull=True)._instance.stats["listed_triangles"] < len(mesh.faces)
    dot5 = sc.prepare(mesh, light, eps=1e-4, cull=True, test="dot5")
    assert dot5._instance.stats["listed_triangles"] == len(mesh.faces)


def test_cull_on_grid_triangulated_solids(rng):
    """A stair of boxes and a grid-triangulated box (certified through their corners' sectors): the masks
    with and without the cull are the same, and the cull is made."""
    mesh = _joined(_solid(manifold3d.Manifold.cube((3, 1, 1)) + manifold3d.Manifold.cube((2, 1, 1)).translate((0, 0, 1))
                          + manifold3d.Manifold.cube((1, 1, 1)).translate((0, 0, 2))),
                   _solid(manifold3d.Manifold.cube((1, 1, 1), True).refine(4).translate((0.5, 3, 0.5))))
    points, normals = _surface_points(mesh, 30_000, rng)
    points = np.r_[points, rng.uniform((-2, -2, -2), (5, 5, 5), (10_000, 3))]
    normals = np.r_[normals, rng.normal(size=(10_000, 3))]
    for light in (sc.PointLight((4.0, 2.0, 5.0)), sc.PointLight((-1.0, 1.5, 0.5)), sc.DirectionalLight((-0.3, 0.5, -1.0))):
        for given in (normals, None):
            culled = sc.shadow_mask(mesh, light, points, given, eps=1e-4, cull=True)
            assert np.array_equal(culled, sc.shadow_mask(mesh, light, points, given, eps=1e-4, cull=False)), light
        assert sc.prepare(mesh, light, eps=1e-4, cull=True)._instance.stats["listed_triangles"] < len(mesh.faces)


def test_which_faces_a_point_light_needs():
    """Outside a certified solid: the faces turned towards the light; inside it (in the material of a
    box with a ball cut out): those turned away; on its surface (winding number 1/2): every face."""
    mesh = _solid(manifold3d.Manifold.cube((1.4, 1.4, 1.4), True) - manifold3d.Manifold.sphere(0.92, 32))
    certificate = solids.solids(mesh)
    tri = mesh.vertices.astype(np.float64)[mesh.faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    for position, toward in (((0.3, 2.5, 0.1), True), ((0.61, 0.63, 0.66), False)):
        side = np.einsum("ij,ij->i", normal, np.asarray(position) - tri[:, 0])
        listed = certificate.faces_for(sc.PointLight(position), mesh.bounds)
        assert np.array_equal(listed, np.flatnonzero(side > 0 if toward else side < 0)), position
    corner = mesh.vertices[mesh.faces[0, 0]].astype(np.float64)
    assert certificate.faces_for(sc.PointLight(corner), mesh.bounds) is None


def test_no_cull_where_too_few_faces_would_go():
    """A light that would leave out under MIN_CULLED of the faces lists them all (a box among an open
    sheet's faces, like bunny's ground beside its open model); a mesh whose closed parts hold under
    twice that share is not even certified (the proofs would buy nothing)."""
    sheet = trimesh.creation.icosphere(3)
    sheet = sc.Mesh(sheet.vertices, sheet.faces[sheet.vertices[sheet.faces].mean(axis=1)[:, 2] > -0.5])  # open
    box = _solid(manifold3d.Manifold.cube((0.5, 0.5, 0.5), True).translate((3, 0, 0)))
    few = _joined(sheet, box)
    assert solids.solids(few).certified_faces == 0
    ball = _solid(manifold3d.Manifold.sphere(1.0, 24).translate((0, 0, 3)))
    some = _joined(ball, sc.Mesh(sheet.vertices, sheet.faces[: len(ball.faces) // 3]))
    certificate = solids.solids(some)
    assert certificate.certified_faces == len(ball.faces)
    light = sc.DirectionalLight((0.0, 0.0, -1.0))
    assert certificate.faces_for(light, some.bounds) is not None
    half = _joined(ball, sc.Mesh(sheet.vertices, sheet.faces[: len(ball.faces)]))
    assert solids.solids(half).faces_for(light, half.bounds) is None


# The pair tests against a linear program: how far two triangles meet beyond what they share --------------
def _meets_beyond(p: np.ndarray, q: np.ndarray, shared: int) -> float:
    """The largest weight off the shared corners (the first ``shared`` of both) of a point common to
    triangles p and q (3 x 3 each, float64), or -1 when they have no common point."""
    # variables: a0 a1 a2 b0 b1 b2 >= 0; sum a = sum b = 1; a . p = b . q
    eq = np.zeros((5, 6))
    eq[:3, :3], eq[:3, 3:] = p.T, -q.T
    eq[3, :3] = eq[4, 3:] = 1
    objective = np.zeros(6)
    objective[shared:3] = -1                     # maximise p's weight off the shared corners
    result = linprog(objective, A_eq=eq, b_eq=[0, 0, 0, 1, 1], bounds=[(0, None)] * 6, method="highs")
    return -result.fun if result.status == 0 else -1.0


def _pairs(rng, shared: int, count: int, flat: bool):
    for _ in range(count):
        p = rng.normal(size=(3, 3))
        q = rng.normal(size=(3, 3)) * rng.uniform(0.2, 1.5) + rng.normal(size=3) * rng.uniform(0, 2)
        if flat:
            p[:, 2] = q[:, 2] = 0.0
        q[:shared] = p[:shared]
        yield p, q


@pytest.mark.parametrize("shared", [0, 1, 2])
@pytest.mark.parametrize("flat", [False, True])
def test_pair_tests_never_call_meeting_triangles_apart(rng, shared, flat):
    """Random pairs sharing no corner, one or an edge, in space and in one plane: every pair proved
    apart has no common point beyond its shared corners (the linear program); and the proof is found
    for nearly every pair that is apart by a clear margin."""
    pairs = list(_pairs(rng, shared, 300, flat))
    ta, tb = np.array([p for p, _ in pairs]), np.array([q for _, q in pairs])
    ids = np.arange(3)
    fa = np.broadcast_to(ids, (len(ta), 3)).copy()
    fb = np.broadcast_to(ids + 3, (len(ta), 3)).copy()
    fb[:, :shared] = fa[:, :shared]
    meets = np.array([_meets_beyond(p, q, shared) for p, q in pairs])
    apart = solids._apart(ta, tb, fa, fb)
    assert not np.any(apart & (meets > 1e-9)), np.flatnonzero(apart & (meets > 1e-9))
    clear = meets < 0 if shared == 0 else meets < 1e-12
    assert clear.sum() > 30
    assert np.mean(apart[clear]) > 0.97


def test_many_lights_cull_from_their_threshold(monkeypatch, rng):
    """shadow_counts culls from CULL_FROM_LIGHTS lights on (the certificate asked for), not below, and
    unless the caller says; the counts are the same either way."""
    from shadowcl import exact

    mesh = _joined(_solid(manifold3d.Manifold.cube((6, 0.2, 6), True)),
                   _solid(manifold3d.Manifold.sphere(0.5, 24).translate((0, 0.8, 0))))
    points = rng.uniform((-3, 0.1, -3), (3, 1.5, 3), (2000, 3))
    lights = [sc.DirectionalLight((x, -1.0, z)) for x, z in rng.normal(size=(exact.CULL_FROM_LIGHTS, 2)) * 0.5]
    asked = []
    monkeypatch.setattr(exact, "solids", lambda m: asked.append(m) or solids.solids(m))
    many = sc.shadow_counts(mesh, lights, points, eps=1e-4)
    assert asked
    asked.clear()
    few = sc.shadow_counts(mesh, lights[:-1], points, eps=1e-4)
    told = sc.shadow_counts(mesh, lights, points, eps=1e-4, cull=False)
    assert not asked
    assert np.array_equal(many, told) and np.array_equal(few, told - sc.shadow_mask(mesh, lights[-1], points, eps=1e-4))
