"""Meshes, lights and cameras: validation (a table of bad inputs) and derived quantities."""

import re

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
    (lambda: sc.Mesh(TRIANGLE, [[0, 1, 3]]), ValueError, r"faces: face 0 has vertex index 3 out of range for 3 vertices"),
    (lambda: sc.Mesh(TRIANGLE, [[0, -1, 2]]), ValueError, r"faces: face 0 has vertex index -1 out of range for 3 vertices"),
    (lambda: sc.Mesh(TRIANGLE, [[0, 1, 2], [2, 7, -4]]), ValueError,      # the first bad index, not the extreme
     r"faces: face 1 has vertex index 7 out of range for 3 vertices"),
    (lambda: sc.Mesh(TRIANGLE[:, :2], FACE), ValueError, r"vertices: expected shape \(N, 3\), got \(3, 2\)"),
    (lambda: sc.Mesh(TRIANGLE, [0, 1, 2]), ValueError, r"faces: expected shape \(F, 3\), got \(3,\)"),
    (lambda: sc.Mesh(TRIANGLE, FACE.astype(float)), TypeError, r"faces: expected integer indices, got dtype float64"),
    (lambda: sc.Mesh(TRIANGLE.astype(str), FACE), TypeError, r"vertices: expected a numeric array"),
    (lambda: sc.Mesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=int)), ValueError, r"faces: the mesh is empty"),
    (lambda: sc.Mesh([[1e39, 0, 0], [1, 0, 0], [0, 1, 0]], FACE), ValueError, r"vertices: coordinates overflow float32"),
    (lambda: sc.DirectionalLight((0, 0, 0)), ValueError, r"direction: must have non-zero length"),
    (lambda: sc.PointLight((0, np.nan, 0)), ValueError, r"position: must be finite"),
    (lambda: sc.PointLight((0, 1)), ValueError, r"position: expected three numbers"),
    # booleans and strings are not coordinates (the red team's PointLight((True, 0, -1)) was (1, 0, -1))
    (lambda: sc.PointLight((True, 0, -1)), TypeError, r"position: expected three numbers"),
    (lambda: sc.DirectionalLight(("1", 0, 0)), TypeError, r"direction: expected three numbers"),
    (lambda: sc.DirectionalLight(np.ones(3, dtype=bool)), TypeError, r"direction: expected three numbers"),
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
    (lambda: sc.Mesh.load("model.xyz"), ValueError, r"path: model.xyz: unsupported mesh format '.xyz'"),
    (lambda: sc.Mesh.load("/no/such/model.obj"), FileNotFoundError, r"path: no mesh file at /no/such/model.obj"),
    (lambda: sc.Mesh.load(None), TypeError, r"path: expected a file path, got NoneType"),
    (lambda: sc.PointLight((10**400, 0, 0)), ValueError, r"position: .* is beyond the floating-point range"),
    (lambda: shadow_mask(MESH, LIGHT, np.zeros((2, 3)), method="shadow_volume", max_error=10**400), ValueError,
     r"max_error: 1000.* is beyond the floating-point range"),
    (lambda: shadow_mask(MESH, LIGHT, np.zeros((2, 3)), method="voxel", frame_buffer=1.0), TypeError,
     r"frame_buffer: expected a bool, got float"),
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


# ---- mesh files: read by shadowcl.meshio, every malformed file named with its line ----

BAD_FILES = [
    ("bad.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", r"line 4: faces: face 0 has vertex index 7 out of range for 3 vertices \(numbered from 1\)"),
    ("bad.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", r"line 4: vertex index 0 is not valid here"),
    ("bad.obj", b"v 0 0 0\nv a b c\nv 0 1 0\nf 1 2 3\n", r"line 2: expected three numbers after 'v', got 'a b c'"),
    ("bad.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 -4 2\n", r"line 4: vertex index -4 is not valid here"),
    ("bad.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", r"line 4: face 0 has 2 corners; a face needs at least 3"),
    ("bad.obj", b"v 0 0 inf\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", r"line 1: vertex 0 is NaN, infinite or beyond float32"),
    ("bad.obj", b"v 0 0 1e39\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", r"line 1: vertex 0 is NaN, infinite or beyond float32"),
    ("bad.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n", r"line 4: an integer does not fit in 64 bits"),
    ("bad.obj", b"# only a comment\n", r"no faces"),
    ("bad.ply", bytes(range(256)) * 4, r"not a PLY file"),
    ("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                b"element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n",
     r"line 13: faces: face 0 has vertex index 5 out of range for 3 vertices"),
    ("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                b"element face 0\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n", r"no faces"),
    ("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                b"element face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n0\n0\n",
     r"line 13: face 0 has 0 corners"),
    ("bad.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\n"
                b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n" + bytes(64),
     r"line 3: element 'vertex': the header announces 4000000000 rows, at least 48000000000 bytes, but 64 remain"),
    ("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nelement face 0\n"
                b"property list uchar int vertex_indices\nend_header\n",
     r"line 3: the vertex element needs number properties x, y and z"),
    ("bad.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                b"property float z\nelement face 1\nproperty list uint int vertex_indices\nend_header\n" + bytes(36)
                + (4000000000).to_bytes(4, "little") + bytes(12), r"element 'face' row 0: the file ends inside it"),
    ("bad.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                b"property float z\nelement face 1\nproperty list char int vertex_indices\nend_header\n" + bytes(36)
                + b"\xff" + bytes(12), r"element 'face' row 0: list 'vertex_indices' has negative length -1"),
    ("bad.off", b"OFF\n1000000000 1 0\n0 0 0\n", r"line 1: the header announces 1000000000 vertices and 1 faces"),
    ("bad.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n", r"line 6: expected a face 'n i1 .. in', got '4 0 1 2'"),
    ("bad.off", b"COFF? 3 1\n", r"line 1: expected the header 'OFF'"),
    ("bad.stl", b"solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\nendsolid\n",
     r"line 7: a facet needs exactly 3 vertices, this one has 2"),
    ("bad.stl", bytes(80) + (7).to_bytes(4, "little") + bytes(50), r"neither a binary STL"),
]


@pytest.mark.parametrize("name, data, message", BAD_FILES, ids=[m[:40] for _, _, m in BAD_FILES])
def test_malformed_mesh_files_are_named_with_the_line(tmp_path, name, data, message):
    path = tmp_path / name
    path.write_bytes(data)
    with pytest.raises(ValueError, match=r"^path: " + re.escape(str(path)) + ": " + message):
        sc.Mesh.load(path)


def test_latin1_comments_and_negative_obj_indices_load(tmp_path):
    path = tmp_path / "latin.obj"
    path.write_bytes("# caf\xe9 \xa9 mod\xe8le\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf -4 -2 -1\n".encode("latin-1"))
    mesh = sc.Mesh.load(path)
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3]])


def test_every_format_and_layout_reads_the_same_mesh(tmp_path):
    """A box with quads, written by trimesh (binary PLY, binary STL, OFF) and by hand (ASCII STL and PLY
    with extra properties and elements, big-endian PLY with mixed polygons), reads back as written."""
    import struct

    import trimesh

    box = trimesh.creation.box(extents=(1, 2, 3))
    expected = np.sort(box.triangles.reshape(-1, 9), axis=0)
    for name, options in [("b.ply", {}), ("a.ply", {"encoding": "ascii"}), ("b.stl", {}),
                          ("a.stl", {"file_type": "stl_ascii"}), ("a.off", {}), ("a.obj", {})]:
        box.export(tmp_path / name, **options)
        triangles = sc.Mesh.load(tmp_path / name).triangles.reshape(-1, 9)
        np.testing.assert_allclose(np.sort(triangles, axis=0), expected, rtol=1e-6, err_msg=name)
    # big-endian, a quad and a triangle, a double coordinate, an extra element after the faces
    header = (b"ply\nformat binary_big_endian 1.0\nelement vertex 5\nproperty double x\nproperty float y\n"
              b"property float z\nproperty uchar alpha\nelement face 2\nproperty list uchar uint vertex_indices\n"
              b"property float quality\nelement edge 1\nproperty int a\nproperty int b\nend_header\n")
    vertices = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0.5, 0.5, 1)]
    body = b"".join(struct.pack(">dffB", *v, 9) for v in vertices)
    body += struct.pack(">B4If", 4, 0, 1, 2, 3, 0.5) + struct.pack(">B3If", 3, 0, 1, 4, 0.5) + struct.pack(">ii", 0, 1)
    (tmp_path / "mixed.ply").write_bytes(header + body)
    mesh = sc.Mesh.load(tmp_path / "mixed.ply")
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4]])
    np.testing.assert_array_equal(mesh.vertices, np.array(vertices, dtype=np.float32))


# ---- inputs are owned: copies, never the caller's buffers ----


def test_mesh_owns_its_arrays():
    vertices = np.vstack([TRIANGLE, [[0, 0, 1]]])
    faces = np.array([[0, 1, 2], [0, 1, 3]], dtype=np.int32)
    buffer = vertices.astype(np.float32)
    mesh = sc.Mesh(buffer[:], faces)
    faces[0, 0] = 1                  # the caller's arrays stay writeable, and editing them changes nothing
    buffer[0, 0] = 7
    np.testing.assert_array_equal(mesh.faces[0], [0, 1, 2])
    assert mesh.vertices[0, 0] == 0 and faces.flags.writeable and buffer.flags.writeable
    assert not np.shares_memory(mesh.vertices, buffer) and not np.shares_memory(mesh.faces, faces)


def test_lights_cameras_and_prepared_bounds_own_their_vectors():
    position, target, box = np.array([0.0, 0, 5]), np.array([0.0, 0, 0]), np.array([[-1.0, -1, -1], [1, 1, 1]])
    light, camera = sc.PointLight(position), sc.Camera(position, target)
    shadows = sc.prepare(MESH, light, bounds=box)
    position[:] = 9
    target[:] = 9
    box[:] = 0
    np.testing.assert_array_equal(light.position, [0, 0, 5])
    np.testing.assert_array_equal(camera.position, [0, 0, 5])
    np.testing.assert_array_equal(camera.target, [0, 0, 0])
    np.testing.assert_array_equal(shadows.bounds, [[-1, -1, -1], [1, 1, 1]])


def test_prepared_method_parameters_are_copies():
    from shadowcl.subdivision import SubdivisionSurface

    cube = np.array([[x, y, z] for x in (0, 1) for y in (1, 2) for z in (0, 1)], dtype=float)
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    grid_bounds = np.array([[-1.0, 0, -1], [2, 3, 2]])
    shadows = sc.prepare(SubdivisionSurface(cube, faces), LIGHT, method="voxel", grid_bounds=grid_bounds, resolution=16)
    grid_bounds[:] = 0
    np.testing.assert_array_equal(shadows.params["grid_bounds"], [[-1, 0, -1], [2, 3, 2]])


def test_moved_mesh_is_kept_and_its_bounds_equal_recomputed_ones():
    """Mesh.moved: the same (centre, scale) gives the same object; its seeded bounds equal the bounds
    computed from its vertices (only referenced vertices count), for awkward centres and scales."""
    rng = np.random.default_rng(5)
    vertices = rng.normal(size=(50, 3)) * 1e3 + 7e5
    vertices[0] = 1e9                                  # unreferenced: outside every face
    mesh = sc.Mesh(vertices, rng.integers(1, 50, (40, 3)))
    for centre, scale in ((np.array([7e5, 7e5, 7e5]), 2.0 ** 11), (np.array([0.1, -3.3, 1e-7]), 2.0 ** -20)):
        moved = mesh.moved(centre, scale)
        assert mesh.moved(centre.copy(), scale) is moved
        used = moved.vertices[np.unique(moved.faces)].astype(np.float64)
        assert np.array_equal(moved.bounds, np.stack([used.min(0), used.max(0)]))
        assert np.array_equal(moved.vertices, ((mesh.vertices.astype(np.float64) - centre) / scale).astype(np.float32))
