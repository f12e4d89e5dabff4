"""Meshes, lights and cameras: validation (a table of bad inputs) and derived quantities."""

import numpy as np
import pytest

import shadowcl as sc
from shadowcl.shadows import shadow_mask

from conftest import require_models

TRIANGLE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=np.float64)
FACE = np.array([[0, 1, 2]])
MESH = sc.Mesh(TRIANGLE, FACE)
LIGHT = sc.PointLight((0, 0, 5))

BAD_INPUTS = [
    (lambda: sc.Mesh([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]], FACE), ValueError, r"vertices: contains NaN or inf"),
    (lambda: sc.Mesh([[0, 0, np.inf], [1, 0, 0], [0, 1, 0]], FACE), ValueError, r"vertices: contains NaN or inf"),
    (lambda: sc.Mesh(TRIANGLE, [[0, 1, 3]]), ValueError, r"faces: vertex index 3 out of range for 3 vertices"),
    (lambda: sc.Mesh(TRIANGLE, [[0, -1, 2]]), ValueError, r"faces: negative vertex index -1"),
    (lambda: sc.Mesh(TRIANGLE[:, :2], FACE), ValueError, r"vertices: expected shape \(N, 3\), got \(3, 2\)"),
    (lambda: sc.Mesh(TRIANGLE, [0, 1, 2]), ValueError, r"faces: expected shape \(F, 3\), got \(3,\)"),
    (lambda: sc.Mesh(TRIANGLE, FACE.astype(float)), TypeError, r"faces: expected integer vertex indices"),
    (lambda: sc.Mesh(TRIANGLE.astype(str), FACE), TypeError, r"vertices: expected a numeric array"),
    (lambda: sc.Mesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=int)), ValueError, r"faces: the mesh is empty"),
    (lambda: sc.Mesh([[1e39, 0, 0], [1, 0, 0], [0, 1, 0]], FACE), ValueError, r"vertices: coordinates overflow float32"),
    (lambda: sc.DirectionalLight((0, 0, 0)), ValueError, r"direction: must have non-zero length"),
    (lambda: sc.PointLight((0, np.nan, 0)), ValueError, r"position: must be finite"),
    (lambda: sc.PointLight((0, 1)), ValueError, r"position: expected three numbers"),
    (lambda: sc.Camera((0, 0, 0), (0, 0, 0)), ValueError, r"target: must differ from the eye position"),
    (lambda: sc.Camera((0, 0, 0), (0, 1, 0)), ValueError, r"up: must not be parallel"),
    (lambda: sc.Camera((0, 0, 0), (0, 0, 1), fov=190), ValueError, r"fov: must be below 180"),
    (lambda: shadow_mask(MESH, LIGHT, np.zeros((4, 2))), ValueError, r"points: expected shape \(N, 3\), got \(4, 2\)"),
    (lambda: shadow_mask(MESH, LIGHT, [[0, 0, np.nan]]), ValueError, r"points: contains NaN or inf"),
    (lambda: shadow_mask(MESH, LIGHT, np.zeros((2, 3)), normals=np.zeros((2, 3))), ValueError, r"normals: zero-length normal"),
    (lambda: shadow_mask(MESH, LIGHT, np.zeros((2, 3)), normals=np.ones((3, 3))), ValueError, r"normals: expected shape \(2, 3\)"),
    (lambda: shadow_mask(MESH, "light", np.zeros((2, 3))), TypeError, r"light: expected a PointLight or DirectionalLight"),
    (lambda: shadow_mask("mesh", LIGHT, np.zeros((2, 3))), TypeError, r"scene_or_mesh: expected a Mesh or a Scene"),
    (lambda: shadow_mask(MESH, LIGHT, np.zeros((2, 3)), method="nope"), ValueError, r"method: unknown method 'nope'"),
    (lambda: shadow_mask(MESH, LIGHT, np.zeros((2, 3)), eps=-1.0), ValueError, r"eps: must be a finite non-negative"),
    (lambda: shadow_mask(MESH, LIGHT, np.zeros((2, 3)), eps="a"), TypeError, r"eps: expected a number"),
    (lambda: shadow_mask(MESH, LIGHT, np.zeros((2, 3)), eps=[1e-3]), TypeError, r"eps: expected a number"),
    (lambda: shadow_mask(MESH, LIGHT, [[1e39, 0, 0]]), ValueError, r"points: coordinates overflow float32"),
    (lambda: sc.render(MESH), TypeError, r"scene: expected a shadowcl.Scene"),
    (lambda: sc.Mesh.load("model.xyz"), ValueError, r"path: unsupported mesh format '.xyz'"),
    (lambda: sc.Mesh.load("/no/such/model.obj"), FileNotFoundError, r"path: no mesh file at /no/such/model.obj"),
]


@pytest.mark.parametrize("call, error, message", BAD_INPUTS, ids=[m for _, _, m in BAD_INPUTS])
def test_bad_input_is_named(call, error, message):
    with pytest.raises(error, match=message):
        call()


def test_mesh_is_stored_float32_int32_and_read_only():
    mesh = sc.Mesh(TRIANGLE, FACE.astype(np.int64))
    assert mesh.vertices.dtype == np.float32 and mesh.faces.dtype == np.int32
    with pytest.raises(ValueError):
        mesh.vertices[0, 0] = 1


def test_degenerate_triangles_are_allowed_and_counted():
    vertices = np.vstack([TRIANGLE, [[2, 0, 0]]])
    faces = [[0, 1, 2], [0, 0, 1], [0, 1, 3], [2, 1, 0]]  # repeated index, collinear, duplicate (reversed)
    mesh = sc.Mesh(vertices, faces)
    assert mesh.degenerate_count == 2
    np.testing.assert_array_equal(mesh.face_normals[1], 0)


def test_bounds_ignore_unreferenced_vertices():
    mesh = sc.Mesh(np.vstack([TRIANGLE, [[100, 100, 100]]]), FACE)
    np.testing.assert_array_equal(mesh.bounds, [[0, 0, 0], [1, 1, 0]])


def test_transform_and_concatenate():
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    flipped = MESH.transformed(mirror)
    np.testing.assert_allclose(flipped.face_normals, MESH.face_normals)  # winding follows the mirror
    both = sc.Mesh.concatenate([MESH, flipped])
    assert len(both.faces) == 2 and both.faces.max() == 5


def test_directional_light_is_normalised():
    light = sc.DirectionalLight((0, -2, 0))
    np.testing.assert_allclose(light.direction, [0, -1, 0])
    np.testing.assert_allclose(light.direction_to_light(np.zeros((2, 3))), [[0, 1, 0]] * 2)


@pytest.mark.parametrize("name", ["teapot.obj", "suzanne.obj"])
def test_load_real_meshes(name):
    mesh = sc.Mesh.load(require_models() / name)
    assert len(mesh.faces) > 100 and np.all(np.isfinite(mesh.vertices))


def test_load_other_formats(tmp_path):
    import trimesh

    box = trimesh.creation.box()
    for suffix in (".ply", ".stl", ".off"):
        path = tmp_path / f"box{suffix}"
        box.export(path)
        assert len(sc.Mesh.load(path).faces) == 12
