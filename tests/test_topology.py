"""shadowcl.topology: components, closedness, concave edges and the point-inside test, each against an
independent answer (a union-find, trimesh, a brute-force dihedral, a solid's own inside test)."""

import manifold3d
import numpy as np
import pytest
import trimesh

import shadowcl as sc
from shadowcl import topology


def _mesh(m) -> sc.Mesh:
    return sc.Mesh(np.asarray(m.vertices), np.asarray(m.faces))


def _solid(manifold) -> sc.Mesh:
    out = manifold.to_mesh()
    return sc.Mesh(out.vert_properties[:, :3], out.tri_verts)


def _union_find(count, pairs):
    parent = list(range(count))

    def root(x):
        while parent[x] != x:
            x = parent[x]
        return x
    for a, b in pairs:
        parent[root(a)] = root(b)
    return np.array([root(x) for x in range(count)])


@pytest.mark.parametrize("count", [0, 1, 2, 63, 64, 65, 500])
def test_components_match_union_find(rng, count):
    pairs = rng.integers(0, max(count, 1), (count // 2, 2)) if count else np.zeros((0, 2), int)
    got, want = topology.components(count, pairs), _union_find(count, pairs)
    assert len(got) == count
    # same partition, labels 0.. in order of each component's least node
    assert np.array_equal(got[:, None] == got[None], want[:, None] == want[None])
    first = [int(np.flatnonzero(got == label)[0]) for label in range(got.max(initial=-1) + 1)]
    assert first == sorted(first)


def test_closed_faces_policy():
    """Closed: every edge two faces wound opposite ways. A hole, a flipped face or a third face on an edge
    opens the whole component; a separate closed part stays closed."""
    box = trimesh.creation.box((1, 1, 1))
    far = trimesh.creation.icosphere(2, 0.5)
    far.vertices += (5, 0, 0)
    cases = {
        "closed": (box.faces, True),
        "hole": (box.faces[1:], False),
        "flipped face": (np.r_[box.faces[:1, ::-1], box.faces[1:]], False),
        "fin": (np.r_[box.faces, [[box.faces[0, 0], box.faces[0, 1], 7]]], False),
    }
    for name, (faces, closed) in cases.items():
        vertices = np.r_[box.vertices, far.vertices]
        faces = np.r_[faces, far.faces + len(box.vertices)]
        adjacency = topology.edge_adjacency(sc.Mesh(vertices, faces))
        nbox = len(faces) - len(far.faces)
        assert adjacency.closed_faces[:nbox].all() == closed and adjacency.closed_faces[:nbox].any() == closed, name
        assert adjacency.closed_faces[nbox:].all(), name          # the sphere beside it stays closed
        assert len(np.unique(adjacency.components)) == 2, name


@pytest.mark.parametrize("flip", [False, True])
def test_enclosing_faces_against_the_solids(rng, flip):
    """Three closed solids far from the origin, both windings: a box with a spherical cavity, a ball, a
    torus (whose hole is inside its bounding box but outside it). A point is enclosed when some closed
    surface surrounds it: in the box (its cavity wall is a closed surface too), the ball or the tube."""
    offset = np.array([1e3, -2e3, 5e2])
    box = manifold3d.Manifold.cube((2, 2, 2), True) - manifold3d.Manifold.sphere(0.8, 48)
    ball = manifold3d.Manifold.sphere(0.5, 32).translate((3, 0, 0))
    torus = manifold3d.Manifold.revolve(manifold3d.CrossSection.circle(0.25, 24).translate((0.8, 0)), 48)
    mesh = _solid((box + ball + torus.translate((0, 3, 0))).translate(tuple(offset)))
    if flip:
        mesh = sc.Mesh(mesh.vertices, mesh.faces[:, ::-1])
    adjacency = topology.edge_adjacency(mesh)
    assert adjacency.closed_faces.all() and len(np.unique(adjacency.components)) == 4
    points = rng.uniform((-1.4, -1.4, -1.4), (4.0, 4.4, 1.4), (3000, 3))
    in_box = np.abs(points).max(axis=1)
    ball_r = np.linalg.norm(points - (3, 0, 0), axis=1)
    tube = np.hypot(np.hypot(points[:, 0], points[:, 1] - 3) - 0.8, points[:, 2])   # revolved about z
    clear = (np.abs(in_box - 1) > 0.02) & (np.abs(ball_r - 0.5) > 0.02) & (np.abs(tube - 0.25) > 0.02)
    want = (in_box < 1) | (ball_r < 0.5) | (tube < 0.25)
    got = np.array([len(adjacency.enclosing_faces(p + offset)) > 0 for p in points[clear]])
    assert clear.sum() > 2500 and 100 < want[clear].sum() < clear.sum() - 100
    assert np.array_equal(got, want[clear])


def test_winding_number_is_integer_off_the_surface():
    sphere = trimesh.creation.icosphere(3, 1.0)
    assert topology.winding_number(sphere.triangles, (0.1, 0.2, -0.3)) == pytest.approx(1, abs=1e-9)
    assert topology.winding_number(sphere.triangles[:, ::-1], (0.1, 0.2, -0.3)) == pytest.approx(-1, abs=1e-9)
    assert topology.winding_number(sphere.triangles, (3.0, 0, 0)) == pytest.approx(0, abs=1e-9)
    # an open hemisphere: a fraction, so enclosing_faces never calls an open component a solid
    half = sphere.triangles[sphere.triangles[:, :, 2].mean(axis=1) > 0]
    assert 0.2 < topology.winding_number(half, (0, 0, 0)) < 0.8


def test_concave_edges_against_dihedral(rng):
    """An L-shaped CSG block (one concave edge line) and a perturbed subdivided sphere (convex): the
    concave edges are those whose dihedral, measured from face centroids, bends inwards by more than the
    tolerance; ``min_degrees`` keeps only sharper folds."""
    block = manifold3d.Manifold.cube((2, 1, 1)) + manifold3d.Manifold.cube((1, 2, 1))
    mesh = _solid(block.rotate((10, 20, 30)))
    adjacency = topology.edge_adjacency(mesh)
    concave = topology.concave_edges(adjacency)
    tri = mesh.vertices.astype(np.float64)[mesh.faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    centroid = tri.mean(axis=1)
    f = adjacency.edge_faces
    rise = np.einsum("ij,ij->i", normal[f[:, 0]], centroid[f[:, 1]] - centroid[f[:, 0]])
    want = np.flatnonzero(rise > 1e-5)
    assert len(want) > 0 and np.array_equal(concave, want)
    assert np.array_equal(topology.concave_edges(adjacency, min_degrees=80), want)    # right-angle folds
    assert len(topology.concave_edges(adjacency, min_degrees=100)) == 0
    sphere = trimesh.creation.icosphere(3, 1.0)
    assert len(topology.concave_edges(topology.edge_adjacency(_mesh(sphere)))) == 0
