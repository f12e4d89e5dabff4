"""Silhouette edges (kernels/silhouette.cl via shadowcl.silhouette) against the float64 reference
(reference/silhouette.py), and the invariants of their loops.

Tolerance: edge sets are compared exactly, except the edges of faces whose facing is a tie (the
face's plane passes within the reference's rounding band of the light: ``ref.tie_faces``, TIE = 1e-5
relative); those are counted and bounded, and left out of both sets.
"""

import functools

import numpy as np
import pytest

import shadowcl as sc
from shadowcl.hard_cases import icosphere
from shadowcl.reference import silhouette as ref
from shadowcl.silhouette import (NONMANIFOLD, edge_adjacency, silhouette_edges, silhouette_loops,
                                 vertex_balance)

from conftest import require_models

MAX_TIE_SHARE = 1e-3    # of the faces: random lights rarely pass near a face's plane


@functools.lru_cache(maxsize=None)
def model(name):
    return sc.Mesh.load(require_models() / f"{name}.obj")


@functools.lru_cache(maxsize=None)
def reference_table(mesh):
    return ref.undirected_edges(mesh.faces)


def random_lights(mesh, rng, npoint=4, ndirectional=2):
    """Point lights from just outside to far from the mesh (0.3 to 3 diagonals from its centre, the close
    ones inside its bounding box), and directional lights; directions uniform on the sphere."""
    centre = mesh.bounds.mean(0)
    diagonal = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    directions = rng.normal(size=(npoint + ndirectional, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    distances = np.geomspace(0.3, 3.0, npoint) * diagonal
    points = [sc.PointLight(centre + r * u) for r, u in zip(distances, directions)]
    return points + [sc.DirectionalLight(u) for u in directions[npoint:]]


def oriented_set(silhouette):
    return set(map(tuple, silhouette.oriented.tolist()))


def check_against_reference(device, mesh, light, what, exact=False, max_tie_share=MAX_TIE_SHARE):
    """Kernel and reference agree on every silhouette edge and its orientation, and on the non-manifold
    edges, except the edges of tie faces; returns the silhouette and the number of tie faces.
    ``exact``: compare tie faces too, for meshes and lights where float32 arithmetic is exact (small
    integers and halves: zero-area faces and lights in a face's plane give s = 0 on both sides)."""
    table = reference_table(mesh)
    sil = silhouette_edges(device, edge_adjacency(mesh), light)
    truth = ref.classify(mesh.vertices, mesh.faces, light, table)
    found = ref.tie_faces(mesh.vertices, mesh.faces, light)
    ties = set() if exact else set(found.tolist())
    assert len(ties) <= max_tie_share * len(mesh.faces) + 1, f"{what}: {len(ties)} tie faces"
    near_tie = {key for key, around in table.items() if any(f in ties for f, _, _ in around)}

    def away_from_ties(edges):
        return {e for e in edges if (min(e), max(e)) not in near_tie}

    got, expected = away_from_ties(oriented_set(sil)), away_from_ties(truth["oriented"])
    assert got == expected, (f"{what}: {len(got - expected)} edges only from the kernel (first "
                             f"{sorted(got - expected)[:3]}), {len(expected - got)} only from the reference "
                             f"(first {sorted(expected - got)[:3]}), of {len(mesh.faces)} faces")
    free = np.ones(len(mesh.faces), dtype=bool)
    free[list(ties)] = False
    assert np.array_equal(sil.facing[free], truth["facing"][free]), f"{what}: facing differs"
    nonmanifold = set(map(tuple, sil.adjacency.edges[sil.nonmanifold].tolist()))
    assert nonmanifold == truth["nonmanifold"], what
    return sil, len(found)


def check_loops(silhouette, what):
    """Even silhouette count at every vertex (as many arriving as leaving) and closed, chained loops
    covering every silhouette edge once."""
    assert not np.any(vertex_balance(silhouette)), what
    degree = np.bincount(silhouette.oriented.reshape(-1), minlength=len(silhouette.adjacency.vertices))
    assert np.all(degree % 2 == 0), what
    loops = silhouette_loops(silhouette)
    assert sorted(np.concatenate([loop.edges for loop in loops] + [[]]).tolist()) == silhouette.indices.tolist(), what
    edges = silhouette.adjacency.edges
    for loop in loops:
        heads = np.roll(loop.vertices, -1)
        assert np.array_equal(np.sort(np.stack([loop.vertices, heads], axis=1), axis=1), edges[loop.edges]), what
    return loops


# Adjacency --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["stanford-bunny", "teapot", "suzanne"])
def test_adjacency_matches_reference_table(name):
    mesh = model(name)
    adjacency = edge_adjacency(mesh)
    assert edge_adjacency(mesh) is adjacency                      # cached per mesh
    table = reference_table(mesh)
    assert len(adjacency.edges) == len(table)
    for e in np.random.default_rng(1).choice(len(adjacency.edges), 500):
        around = table[tuple(adjacency.edges[e].tolist())]
        assert adjacency.faces_of(e).tolist() == sorted(f for f, _, _ in around)
        senses = adjacency.face_senses[adjacency.face_offsets[e]:adjacency.face_offsets[e + 1]]
        assert senses.tolist() == [1 if tail < head else -1 for _, tail, head in sorted(around)]
    counts = np.array([len(around) for around in table.values()])
    assert len(adjacency.border_edges) == np.count_nonzero(counts == 1)
    assert len(adjacency.nonmanifold_edges) == np.count_nonzero(counts > 2)


# Kernel against reference -----------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["stanford-bunny", "teapot", "suzanne"])
def test_real_meshes_match_reference(device, rng, name, record_property):
    mesh = model(name)
    ties = 0
    for i, light in enumerate(random_lights(mesh, rng)):
        sil, count = check_against_reference(device, mesh, light, f"{name} light {i}")
        assert sil.mask.sum() > 0
        ties += count
        if not len(sil.adjacency.nonmanifold_edges):
            check_loops(sil, f"{name} light {i}")        # open meshes too: the border rule keeps them balanced
    record_property("tie_faces", ties)


def test_suzanne_reports_its_nonmanifold_edge(device):
    mesh = model("suzanne")
    sil = silhouette_edges(device, edge_adjacency(mesh), sc.DirectionalLight((0, 0, -1)))
    assert len(sil.nonmanifold) == 1 and np.all(sil.codes[sil.nonmanifold] == NONMANIFOLD)
    with pytest.raises(ValueError, match="1 non-manifold edges"):
        silhouette_loops(sil)


@pytest.mark.parametrize("subdivisions", [0, 1, 3])
def test_icosphere_has_one_loop_from_outside(device, rng, subdivisions):
    mesh = icosphere(subdivisions)
    for i, light in enumerate(random_lights(mesh, rng)):
        sil, _ = check_against_reference(device, mesh, light, f"icosphere({subdivisions}) light {i}")
        loops = check_loops(sil, f"icosphere({subdivisions}) light {i}")
        assert sil.facing.any() and len(loops) == 1               # convex, light outside: one terminator


def test_closed_mesh_loops_close(device, rng):
    mesh = model("fandisk")
    assert edge_adjacency(mesh).is_closed_manifold
    for i, light in enumerate(random_lights(mesh, rng)):
        check_loops(check_against_reference(device, mesh, light, f"fandisk light {i}")[0], f"fandisk light {i}")


@pytest.mark.parametrize("offset, max_tie_share", [(1e2, 0.01), (1e4, 0.3)])
def test_far_from_the_origin(device, rng, offset, max_tie_share, record_property):
    # The light rounded to float32 moves by ~1e-3 at 1e4, so the tie band widens with |L| (up to a quarter
    # of this unit sphere's faces at 1e4 in our runs); away from it the sets still agree exactly.
    mesh = sc.Mesh(icosphere(3).vertices.astype(np.float64) + offset, icosphere(3).faces)
    ties = 0
    for i, light in enumerate(random_lights(mesh, rng)):
        sil, count = check_against_reference(device, mesh, light, f"offset {offset} light {i}",
                                             max_tie_share=max_tie_share)
        assert len(check_loops(sil, f"offset {offset} light {i}")) == 1
        ties += count
    record_property("tie_faces", ties)


def test_light_in_a_face_plane_is_a_counted_tie(device):
    mesh = icosphere(2)
    v = mesh.vertices.astype(np.float64)[mesh.faces[0]]
    in_plane = v[0] + 2.0 * (v[1] - v[0]) + 1.5 * (v[2] - v[0])      # outside the sphere, on face 0's plane
    light = sc.PointLight(in_plane)
    assert 0 in ref.tie_faces(mesh.vertices, mesh.faces, light)
    check_loops(check_against_reference(device, mesh, light, "in-plane light")[0], "in-plane light")


# Open, non-manifold and degenerate meshes -------------------------------------------------------------
CUBE_VERTICES = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
CUBE_FACES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                       [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])   # outward; +z last
CUBE_RIM = {(1, 3), (3, 7), (5, 7), (1, 5)}


def open_box():
    """The unit cube without its lid (z = 1): four border edges around the rim."""
    return sc.Mesh(CUBE_VERTICES, CUBE_FACES[:-2])


def test_cube_is_closed_and_consistently_wound():
    adjacency = edge_adjacency(sc.Mesh(CUBE_VERTICES, CUBE_FACES))
    assert adjacency.is_closed_manifold and len(adjacency.misoriented_edges) == 0


@pytest.mark.parametrize("light, ties", [(sc.PointLight((3.0, 0.4, 0.7)), 0),
                                         (sc.PointLight((0.5, 0.5, 3.0)), 0),
                                         (sc.PointLight((1.0, 0.5, 3.0)), 2),
                                         (sc.DirectionalLight((-1.0, 0.2, -0.5)), 0)],
                         ids=["side", "above", "in-the-plane-of-a-wall", "directional"])
def test_open_box_border_edges_follow_their_face(device, light, ties):
    mesh = open_box()
    adjacency = edge_adjacency(mesh)
    assert set(map(tuple, adjacency.edges[adjacency.border_edges].tolist())) == CUBE_RIM
    assert not adjacency.is_closed_manifold
    sil, found = check_against_reference(device, mesh, light, "open box", exact=True)
    assert found == ties                               # the wall x = 1 (two faces) contains the light
    for e in adjacency.border_edges:
        face = adjacency.faces_of(e)[0]
        assert sil.mask[e] == sil.facing[face]        # the border rule
    check_loops(sil, "open box")


def test_open_box_from_above_has_no_silhouette(device):
    # The light looks into the box: it sees only back faces (their inner sides).
    sil = silhouette_edges(device, edge_adjacency(open_box()), sc.PointLight((0.5, 0.5, 3.0)))
    assert not sil.facing.any() and not sil.mask.any() and silhouette_loops(sil) == []


def fin_mesh():
    """Three triangles on the edge (0, 1): a non-manifold fin."""
    vertices = [[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, -1, 0], [0.5, 0, 1]]
    return sc.Mesh(vertices, [[0, 1, 2], [1, 0, 3], [0, 1, 4]])


def test_nonmanifold_edge_is_reported_not_dropped(device):
    mesh = fin_mesh()
    adjacency = edge_adjacency(mesh)
    assert adjacency.edges[adjacency.nonmanifold_edges].tolist() == [[0, 1]]
    assert adjacency.faces_of(adjacency.nonmanifold_edges[0]).tolist() == [0, 1, 2]
    with pytest.raises(ValueError, match=r"1 non-manifold edges .*\[0, 1\] with faces \[0, 1, 2\]"):
        adjacency.require_manifold()
    sil, _ = check_against_reference(device, mesh, sc.PointLight((0.3, 0.2, 2.0)), "fin")
    assert sil.nonmanifold.tolist() == adjacency.nonmanifold_edges.tolist()
    assert not sil.mask[adjacency.nonmanifold_edges].any()
    with pytest.raises(ValueError, match="non-manifold"):
        silhouette_loops(sil)


def test_misoriented_faces_are_refused_by_loops(device):
    faces = CUBE_FACES.copy()
    faces[0] = faces[0][::-1]
    adjacency = edge_adjacency(sc.Mesh(CUBE_VERTICES, faces))
    assert len(adjacency.misoriented_edges) == 3
    with pytest.raises(ValueError, match="wound the same way"):
        silhouette_loops(silhouette_edges(device, adjacency, sc.PointLight((3.0, 2.0, 1.5))))


def degenerate_cube():
    """The closed cube with the edge (0, 4) split at its midpoint 8: faces on one side use 8, and a
    zero-area sliver (0, 4, 8) closes the T-junction; plus a collapsed face (2, 2, 6)."""
    vertices = np.vstack([CUBE_VERTICES, [0.5, 0.0, 0.0]])
    faces = CUBE_FACES.tolist()
    faces[4:6] = [[0, 8, 5], [8, 4, 5], [0, 5, 1]]          # the y = 0 side goes through 8; z = 0 keeps (0, 4)
    return sc.Mesh(vertices, faces + [[0, 4, 8], [2, 2, 6]])


@pytest.mark.parametrize("light", [sc.PointLight((0.5, -3.0, 0.5)), sc.PointLight((-3.0, 0.4, 0.6)),
                                   sc.DirectionalLight((0.3, 1.0, 0.2))], ids=["front", "side", "directional"])
def test_degenerate_triangles(device, light):
    mesh = degenerate_cube()
    adjacency = edge_adjacency(mesh)
    sliver, collapsed = len(mesh.faces) - 2, len(mesh.faces) - 1
    assert adjacency.collapsed_faces.tolist() == [collapsed]
    assert adjacency.is_closed_manifold and len(adjacency.misoriented_edges) == 0
    assert mesh.degenerate_count == 2
    sil, ties = check_against_reference(device, mesh, light, "degenerate cube", exact=True)
    assert ties == 2                                                 # s = 0 exactly: a tie, decided alike
    assert not sil.facing[sliver] and not sil.facing[collapsed]      # zero area: faces no light
    check_loops(sil, "degenerate cube")


def test_only_collapsed_faces_give_an_empty_table(device):
    adjacency = edge_adjacency(sc.Mesh(CUBE_VERTICES, [[0, 0, 1], [2, 3, 3]]))
    assert adjacency.edges.shape == (0, 2) and adjacency.collapsed_faces.tolist() == [0, 1]
    sil = silhouette_edges(device, adjacency, sc.DirectionalLight((0, 0, 1)))
    assert sil.codes.shape == (0,) and silhouette_loops(sil) == []


def test_a_mesh_stands_for_its_table(device):
    mesh = open_box()
    light = sc.PointLight((3.0, 0.4, 0.7))
    by_mesh = silhouette_edges(device, mesh, light)
    assert by_mesh.adjacency is edge_adjacency(mesh)
    assert np.array_equal(by_mesh.codes, silhouette_edges(device, edge_adjacency(mesh), light).codes)


@pytest.mark.parametrize("adjacency, light, error, match", [
    (open_box(), (0.0, 0.0, 1.0), TypeError, "light: expected a PointLight or DirectionalLight"),
    (CUBE_FACES, sc.PointLight((3.0, 0.0, 0.0)), TypeError, "adjacency: expected an EdgeAdjacency or a Mesh"),
])
def test_bad_input(device, adjacency, light, error, match):
    with pytest.raises(error, match=match):
        silhouette_edges(device, adjacency, light)
