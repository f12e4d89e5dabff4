"""Silhouette edges (kernels/silhouette.cl via shadowcl.silhouette) against the float64 reference
(reference/silhouette.py), and the invariants of their loops.

Tolerance: edge sets are compared exactly, except the edges of faces whose facing is a tie (the
face's plane passes within the reference's rounding band of the light: ``ref.tie_faces``, TIE = 1e-5
relative); those are counted and bounded, and left out of both sets.
"""

import functools
import json
import sys

import numpy as np
import pytest

import shadowcl as sc
from shadowcl.testing import icosphere
from shadowcl.reference import silhouette as ref
from shadowcl.silhouette import (NONMANIFOLD, Silhouette, SilhouetteTracker, edge_adjacency, host_facing,
                                 silhouette_edges, silhouette_loops, vertex_balance)

from conftest import PROJECT, require_models

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


# Tracking and the randomized method (SilhouetteTracker) ------------------------------------------------
def circling_lights(mesh, frames, degrees, radius=1.5, height=0.25, start=0.0):
    """Point lights circling ``mesh`` by ``degrees`` per frame, ``radius`` diagonals from its centre."""
    centre = mesh.bounds.mean(0)
    diagonal = float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))
    angles = np.radians(start + degrees * np.arange(frames))
    return [sc.PointLight(centre + diagonal * np.array([radius * np.cos(a), height, radius * np.sin(a)]))
            for a in angles]


def follow(device, mesh, lights, **params):
    """Run a tracker along ``lights``: (recalls, precisions, stats) per frame against brute force. Every
    frame also checks that the tracker's ``facing`` (computed on use) is the kernel's."""
    tracker = SilhouetteTracker(device, mesh, **params)
    recalls, precisions, stats = [], [], []
    for light in lights:
        sil = tracker.update(light)
        truth = silhouette_edges(device, mesh, light)
        recall, precision = ref.recall_precision(sil.codes, truth.codes)
        recalls.append(recall)
        precisions.append(precision)
        stats.append(dict(tracker.stats))
    assert np.array_equal(sil.facing, truth.facing)
    return np.array(recalls), np.array(precisions), stats


def test_host_facing_is_the_kernels_bit_for_bit(device, rng):
    # The tracker tests faces on the host; its answers must be the brute force's, ties included.
    for mesh in (model("stanford-bunny"), sc.Mesh(icosphere(3).vertices.astype(np.float64) + 1e4, icosphere(3).faces)):
        for light in random_lights(mesh, rng):
            sil = silhouette_edges(device, mesh, light)
            assert np.array_equal(host_facing(mesh.vertices, mesh.faces, light), sil.facing)
            which = rng.choice(len(mesh.faces), 50)
            assert np.array_equal(host_facing(mesh.vertices, mesh.faces, light, which), sil.facing[which])


def test_brute_tracker_is_silhouette_edges(device, rng):
    mesh = model("teapot")
    tracker = SilhouetteTracker(device, mesh)
    for light in random_lights(mesh, rng, 2, 1):
        assert np.array_equal(tracker.update(light).codes, silhouette_edges(device, mesh, light).codes)


@pytest.mark.parametrize("method, params", [("tracking", {}), ("random", {"fraction": 0.1})],
                         ids=["tracking", "random"])
def test_icosphere_small_moves_find_every_edge(device, method, params):
    # Convex: one loop; 2 degrees a frame. The random method's first frame needs one sampled edge on the
    # loop (~70 of 1920 edges; 192 samples miss it with probability ~1e-3; seed 0 does not).
    mesh = icosphere(3)
    directional = [sc.DirectionalLight((np.cos(a), -0.3, np.sin(a))) for a in np.radians(np.arange(0, 20, 2.0))]
    for lights in (circling_lights(mesh, 30, 2.0), directional):
        recalls, precisions, stats = follow(device, mesh, lights, method=method, **params)
        assert np.all(recalls == 1.0) and np.all(precisions == 1.0)
        assert not any(s["fallback"] for s in stats)
        if method == "random":                                    # the device's walks do not count faces
            assert all(s["faces_tested"] < len(mesh.faces) for s in stats[1:]), "a coherent frame tests few faces"


def test_tracking_along_a_bunny_path(device, record_property):
    # The bar: >= 99 % of the brute-force silhouette edges, every frame, found edges all real.
    # 3 degrees a frame; the bunny's scanned surface has ~150 loops, half of them 3-edge islands.
    mesh = model("stanford-bunny")
    recalls, precisions, stats = follow(device, mesh, circling_lights(mesh, 16, 3.0, start=40.0), method="tracking")
    assert recalls.min() >= 0.99 and np.all(precisions == 1.0)
    assert not any(s["fallback"] for s in stats[1:])               # small moves: tracked, not redone
    record_property("recall_min", float(recalls.min()))


def test_random_along_a_real_mesh_path(device, record_property):
    # The teapot's smooth patches: few, long loops, which a 5 % sample plus last frame's edges keeps.
    mesh = model("teapot")
    recalls, precisions, _ = follow(device, mesh, circling_lights(mesh, 30, 3.0), method="random", fraction=0.05)
    assert recalls[1:].min() >= 0.99 and np.all(precisions == 1.0)
    record_property("recall_mean", float(recalls.mean()))


def test_random_recall_on_the_bunny_grows_with_the_fraction(device):
    # Markosian's trade: the bunny's single-face islands are found only when sampled, so recall < 1
    # with a small fraction and rises with it; precision stays 1.
    mesh = model("stanford-bunny")
    lights = circling_lights(mesh, 8, 3.0)
    low, precision_low, _ = follow(device, mesh, lights, method="random", fraction=0.02)
    high, precision_high, _ = follow(device, mesh, lights, method="random", fraction=0.5)
    assert np.all(precision_low == 1.0) and np.all(precision_high == 1.0)
    assert 0.7 < low.mean() < high.mean() and high[1:].min() >= 0.98


def test_large_jump_falls_back_to_brute_force(device):
    # 90 degrees in one frame: most of last frame's edges are stale; the tracker says so and redoes the
    # frame by brute force rather than returning a partial silhouette.
    mesh = model("stanford-bunny")
    lights = circling_lights(mesh, 2, 3.0) + circling_lights(mesh, 1, 0.0, start=93.0)
    recalls, precisions, stats = follow(device, mesh, lights, method="tracking")
    assert np.all(recalls == 1.0) and np.all(precisions == 1.0)
    assert [s["fallback"] for s in stats] == [False, False, True] and stats[2]["stale"] > 0.5
    assert stats[0]["faces_tested"] == len(mesh.faces)             # the first frame is brute force


def test_tracking_from_an_empty_silhouette_falls_back(device):
    # A light inside a closed sphere lights no face: no silhouette to track from. Moved outside, the
    # silhouette must still be found (it was silently empty, recall 0, before the fallback).
    mesh = icosphere(3)
    lights = [sc.PointLight((0.0, 0.0, 0.0)), sc.PointLight((0.1, 0.0, 0.0)), sc.PointLight((3.0, 0.2, 0.0)),
              sc.PointLight((3.0, 0.3, 0.0))]
    recalls, precisions, stats = follow(device, mesh, lights, method="tracking")
    assert np.all(recalls == 1.0) and np.all(precisions == 1.0)
    assert [s["fallback"] for s in stats] == [False, True, True, False]     # tracked again once it has edges


def test_walks_find_a_silhouette_that_moved_away(device):
    # A light 1.5 radii from a sphere lights a cap of 48 degrees; moved by 120 degrees, the new cap and
    # the old one do not meet, so every seed must come from a III.B walk (stale share 1).
    mesh = icosphere(3)
    angle = np.radians(120.0)
    lights = [sc.PointLight((1.5, 0.0, 0.0)), sc.PointLight((1.5 * np.cos(angle), 0.2, 1.5 * np.sin(angle)))]
    recalls, precisions, stats = follow(device, mesh, lights, method="tracking", max_stale=1.0, max_walk=64)
    assert np.all(recalls == 1.0) and np.all(precisions == 1.0)
    assert stats[1]["stale"] == 1.0 and not stats[1]["fallback"]
    # Walks of one step cannot get there: lost, and the tracker falls back instead of losing the loop.
    recalls, _, stats = follow(device, mesh, lights, method="tracking", max_stale=1.0, max_walk=1, max_lost=0.5)
    assert stats[1]["fallback"] and stats[1]["lost_walks"] > 0.5 * stats[0]["edges_found"]   # a walk per old edge
    assert np.all(recalls == 1.0)


@pytest.mark.parametrize("method", ["tracking", "random"])
def test_open_mesh_border_edges_are_tested(device, method):
    # An icosphere without its top cap: border edges are silhouettes when their face faces the light
    # (the module's border rule), tested every frame as the paper says.
    sphere = icosphere(3)
    centres = sphere.vertices[sphere.faces].mean(1)
    mesh = sc.Mesh(sphere.vertices, sphere.faces[centres[:, 1] < 0.7])
    assert len(edge_adjacency(mesh).border_edges) > 0
    lights = circling_lights(mesh, 20, 4.0, height=0.6)
    recalls, precisions, _ = follow(device, mesh, lights, method=method, fraction=0.1)
    assert np.all(recalls == 1.0) and np.all(precisions == 1.0)


@pytest.mark.parametrize("method", ["tracking", "random"])
def test_tracking_degenerate_and_empty_tables(device, method):
    # The cube with a zero-area sliver (faces no light) and a collapsed face (no edges): still every
    # edge, frame by frame; a table with no edges at all gives empty silhouettes.
    lights = [sc.PointLight((0.5 + 0.2 * i, -3.0, 0.6)) for i in range(4)]
    recalls, precisions, _ = follow(device, degenerate_cube(), lights, method=method, fraction=0.5)
    assert np.all(recalls == 1.0) and np.all(precisions == 1.0)
    tracker = SilhouetteTracker(device, sc.Mesh(CUBE_VERTICES, [[0, 0, 1], [2, 3, 3]]), method=method)
    assert all(tracker.update(light).codes.shape == (0,) for light in lights)


def test_nonmanifold_and_misoriented_meshes(device):
    fin = fin_mesh()
    for method in ("tracking", "random"):
        with pytest.raises(ValueError, match=rf"method='{method}'\): mesh: 1 non-manifold edges"):
            SilhouetteTracker(device, fin, method=method)
    sil = SilhouetteTracker(device, fin).update(sc.PointLight((0.3, 0.2, 2.0)))     # brute force reports it
    assert sil.codes[edge_adjacency(fin).nonmanifold_edges].tolist() == [NONMANIFOLD]
    faces = CUBE_FACES.copy()
    faces[0] = faces[0][::-1]
    cube = sc.Mesh(CUBE_VERTICES, faces)
    with pytest.raises(ValueError, match="wound the same way"):           # the III.C walk needs the winding
        SilhouetteTracker(device, cube, method="tracking")
    lights = [sc.PointLight((3.0, 2.0 + 0.1 * i, 1.5)) for i in range(5)]
    recalls, precisions, _ = follow(device, cube, lights, method="random", fraction=1.0)   # growth is unoriented
    assert np.all(recalls == 1.0) and np.all(precisions == 1.0)


def test_reset_forgets_the_history(device):
    mesh = icosphere(3)
    lights = circling_lights(mesh, 3, 2.0)
    for method in ("tracking", "random"):
        tracker = SilhouetteTracker(device, mesh, method=method, fraction=0.1, seed=3)
        first = [tracker.update(light).codes for light in lights]
        tracker.reset()
        assert np.array_equal(tracker.update(lights[0]).codes, first[0])
        if method == "tracking":
            assert tracker.stats["faces_tested"] == len(mesh.faces)     # a first frame again: brute force


@pytest.mark.parametrize("name, degrees, max_walk", [("stanford-bunny", 3.0, 16), ("teapot", 15.0, 16),
                                                     ("stanford-bunny", 15.0, 1)])
def test_device_walks_are_the_reference_walks(device, name, degrees, max_walk):
    # kernels track_previous, seed_edges and complete_loops against the NumPy walks from the same last
    # frame and the kernel's facing: the same edges, stale share, lost walks and fallbacks, frame by frame
    # (the teapot is open; one-step walks on a fast path get lost).
    mesh = model(name)
    tracker = SilhouetteTracker(device, mesh, method="tracking", max_walk=max_walk)
    h = tracker.halves
    extra = np.r_[tracker.adjacency.border_edges, tracker.concave_edges]
    fallbacks = stale = 0
    for light in circling_lights(mesh, 6, degrees):
        previous = tracker._previous
        codes = tracker.update(light).codes
        if previous is None:                                        # the first frame: brute force
            continue
        lit_faces = np.r_[silhouette_edges(device, mesh, light).facing, False]      # face -1: missing
        found, stats = ref.tracking_frame(h.twin, h.edge, h.tails, h.heads, h.edge_halves, previous, extra,
                                          lambda faces: lit_faces[faces], max_walk, tracker.max_stale,
                                          tracker.max_lost)
        assert (found is None) == tracker.stats["fallback"]
        for key in stats:
            assert stats[key] == pytest.approx(tracker.stats[key]), key
        if found is not None:
            want = np.zeros_like(codes)
            want[h.edge[found]] = np.where(h.tails[found] < h.heads[found], 1, -1)
            assert np.array_equal(codes, want)
        fallbacks += tracker.stats["fallback"]
        stale += stats["stale"] > 0
    assert stale > 0 and (fallbacks > 0) == (max_walk == 1)


def test_device_batches_and_host_tests_agree(device):
    # The same frames with every face test on the host and with large batches on the device.
    mesh = model("stanford-bunny")
    lights = circling_lights(mesh, 4, 3.0)
    host = SilhouetteTracker(device, mesh, method="random", device_batch=10**9)
    batched = SilhouetteTracker(device, mesh, method="random", device_batch=1)
    for light in lights:
        assert np.array_equal(host.update(light).codes, batched.update(light).codes)
    assert host.stats["faces_tested"] < len(mesh.faces) == batched.stats["faces_tested"]


@pytest.mark.parametrize("kwargs, error, match", [
    ({"method": "fast"}, ValueError, "method: expected one of"),
    ({"fraction": 0.0}, ValueError, "fraction: must be a finite positive"),
    ({"fraction": 1.5}, ValueError, "fraction: must be at most 1"),
    ({"seed": -1}, ValueError, "seed: must be at least 0"),
    ({"seed": 1.5}, TypeError, "seed: expected an integer"),
    ({"max_walk": 0}, ValueError, "max_walk: must be at least 1"),
    ({"max_stale": 2.0}, ValueError, "max_stale: must be at most 1"),
    ({"max_lost": 0.0}, ValueError, "max_lost: must be a finite positive"),
    ({"concave_angle": -1.0}, ValueError, "concave_angle: must be a finite non-negative"),
])
def test_tracker_bad_input(device, kwargs, error, match):
    with pytest.raises(error, match=match):
        SilhouetteTracker(device, icosphere(1), **kwargs)


def test_tracker_bad_mesh_and_light(device):
    with pytest.raises(TypeError, match="mesh_or_adjacency: expected a Mesh or an EdgeAdjacency"):
        SilhouetteTracker(device, CUBE_FACES)
    with pytest.raises(TypeError, match="light: expected a PointLight or DirectionalLight"):
        SilhouetteTracker(device, icosphere(1), method="tracking").update((0.0, 0.0, 5.0))


def test_lazy_facing_on_host_and_device(device):
    mesh = model("teapot")
    light = sc.PointLight((3.0, 2.0, 1.0))
    truth = silhouette_edges(device, mesh, light)
    for on in (None, device):
        assert np.array_equal(Silhouette(truth.adjacency, light, truth.codes, device=on).facing, truth.facing)


def test_bench_quick_mode(tmp_path):
    # bench/silhouettes.py --quick (teapot, short paths, one repeat): rows for every setting, all scored.
    require_models()
    sys.path.insert(0, str(PROJECT / "bench"))
    try:
        import silhouettes as bench
    finally:
        sys.path.remove(str(PROJECT / "bench"))
    out = tmp_path / "s.json"
    assert bench.main(["--quick", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert len(doc["rows"]) == len(bench.SETTINGS) * len(bench.QUICK_PATHS)
    assert all(row["precision_min"] == 1.0 for row in doc["rows"])
    assert all(row["recall_min"] >= 0.99 for row in doc["rows"] if row["method"] == "tracking")
    assert "Bar and fastest method" in out.with_suffix(".md").read_text()
