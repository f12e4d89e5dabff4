"""Scenes: every shipped scene loads and holds its hard case; the TOML format, shape by shape; bad files."""

import textwrap
from collections import Counter

import numpy as np
import pytest

import shadowcl as sc
from shadowcl import scene as scene_module
from shadowcl.scene import Scene, default_camera

from conftest import SCENES, require_models

# DESIGN.md's hard cases, one scene file each.
HARD_CASES = [
    "grazing_plane", "shared_edges", "sphere_terminator", "contact", "thin_occluder", "light_near_occluder",
    "light_inside", "far_offset", "degenerate", "coplanar", "open_mesh", "non_manifold",
]
PROCEDURAL_SCENES = sorted(SCENES.glob("*.toml")) + sorted((SCENES / "hard").glob("*.toml"))
MODEL_SCENES = sorted((SCENES / "models").glob("*.toml"))

LIGHT = '[[lights]]\ntype = "point"\nposition = [0, 5, 0]\n'
TETRAHEDRON_OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def load_text(tmp_path, text: str, name: str = "scene.toml") -> Scene:
    path = tmp_path / name
    path.write_text(text)
    return Scene.load(path)


def load_object(tmp_path, object_toml: str) -> sc.Mesh:
    """The mesh of a one-object scene whose [[objects]] table is ``object_toml``."""
    return load_text(tmp_path, LIGHT + "[[objects]]\n" + object_toml).mesh


def edge_uses(mesh: sc.Mesh) -> Counter:
    """How many triangles use each undirected edge."""
    edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return Counter(map(tuple, edges.tolist()))


def object_mesh(scene: Scene, name: str) -> sc.Mesh:
    return dict(scene.objects)[name]


# ---- shipped scenes ----


def check_consistent(scene: Scene) -> None:
    assert scene.lights and scene.light is scene.lights[0]
    assert len(scene.mesh.faces) == sum(len(mesh.faces) for _, mesh in scene.objects)
    assert np.array_equal(np.bincount(scene.object_ids()), [len(mesh.faces) for _, mesh in scene.objects])
    assert scene.triangle_colors.shape == (len(scene.mesh.faces), 3)
    assert np.all(np.isfinite(scene.bounds)) and np.all(scene.bounds[1] > scene.bounds[0])
    ground = scene.objects[0][1]  # every shipped scene starts with its ground, top face at y = 0
    assert ground.bounds[1, 1] == 0.0


def test_every_hard_case_has_a_scene_and_nothing_else_is_there():
    assert sorted(path.stem for path in (SCENES / "hard").glob("*.toml")) == sorted(HARD_CASES)


@pytest.mark.parametrize("path", PROCEDURAL_SCENES, ids=lambda path: f"{path.parent.name}/{path.stem}")
def test_procedural_scene_loads(path):
    scene = Scene.load(path)
    check_consistent(scene)
    assert scene.name == path.stem and scene.path == path


@pytest.mark.parametrize("path", MODEL_SCENES, ids=lambda path: path.stem)
def test_model_scene_loads_with_the_model_standing_on_the_ground(path):
    require_models()
    scene = Scene.load(path)
    check_consistent(scene)
    _, model = scene.objects[1]
    assert model.bounds[0, 1] == pytest.approx(0.0, abs=1e-6)  # feet on the ground, not in it
    assert np.allclose((model.bounds[0, [0, 2]] + model.bounds[1, [0, 2]]) / 2, 0, atol=0.1)  # centred


def test_grazing_light_is_2_to_5_degrees_above_the_plane():
    scene = Scene.load(SCENES / "hard" / "grazing_plane.toml")
    elevation = np.degrees(np.arcsin(-scene.light.direction[1]))
    assert 2 <= elevation <= 5


def test_shared_edges_meshes_are_closed_and_consistently_oriented():
    scene = Scene.load(SCENES / "hard" / "shared_edges.toml")
    for name in ("icosahedron", "box"):
        mesh = object_mesh(scene, name)
        assert set(edge_uses(mesh).values()) == {2}, name
        directed = mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        assert len(np.unique(directed, axis=0)) == len(directed), name  # each directed edge once
        centre = mesh.vertices.mean(axis=0)
        outward = np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles.mean(axis=1) - centre)
        assert np.all(outward > 0), name


def test_contact_objects_touch_the_floor_exactly():
    scene = Scene.load(SCENES / "hard" / "contact.toml")
    assert object_mesh(scene, "box").bounds[0, 1] == 0.0
    assert object_mesh(scene, "ball").bounds[0, 1] == 0.0


def test_far_offset_is_the_default_scene_moved_by_1e5():
    near, far = Scene.load(SCENES / "default.toml"), Scene.load(SCENES / "hard" / "far_offset.toml")
    offset = np.array([1e5, 0, 1e5])
    assert [name for name, _ in near.objects] == [name for name, _ in far.objects]
    assert np.array_equal(near.mesh.faces, far.mesh.faces)
    # float32 spacing at 1e5 is 2**-7: each moved vertex is within half of it (plus manifold's rounding).
    assert np.abs(far.mesh.vertices.astype(np.float64) - offset - near.mesh.vertices).max() <= 2**-7
    assert np.allclose(far.light.position - offset, near.light.position)
    assert np.allclose(far.camera.position - offset, near.camera.position)
    assert np.allclose(far.camera.target - offset, near.camera.target)


def test_degenerate_scene_holds_zero_area_and_duplicated_triangles():
    mesh = object_mesh(Scene.load(SCENES / "hard" / "degenerate.toml"), "plate with junk")
    assert mesh.degenerate_count == 3
    assert len(np.unique(np.sort(mesh.faces, axis=1), axis=0)) < len(mesh.faces)


def test_open_and_non_manifold_scenes_have_boundary_and_triple_edges():
    open_scene = Scene.load(SCENES / "hard" / "open_mesh.toml")
    assert Counter(edge_uses(object_mesh(open_scene, "cup")).values())[1] == 4  # the rim
    fins = object_mesh(Scene.load(SCENES / "hard" / "non_manifold.toml"), "fins")
    assert edge_uses(fins)[(0, 1)] == 3


# ---- the format: shapes, CSG, transforms, paths, defaults ----


def test_the_documented_example_scene_loads(tmp_path):
    example = scene_module.__doc__.split("::\n", 1)[1].split("\nA shape table", 1)[0]
    scene = load_text(tmp_path, textwrap.dedent(example))
    assert scene.name == "demo" and len(scene.lights) == 2 and scene.objects[0][0] == "ground"


def test_sphere_box_and_cylinder_parameters(tmp_path):
    sphere = load_object(tmp_path, "sphere = { radius = 2.0, segments = 16 }")
    assert np.allclose(sphere.bounds, [[-2] * 3, [2] * 3])
    box = load_object(tmp_path, "box = { size = [1, 2, 3] }")
    assert np.array_equal(box.bounds, [[0, 0, 0], [1, 2, 3]])
    cube = load_object(tmp_path, "box = { size = 2, center = true }")
    assert np.array_equal(cube.bounds, [[-1] * 3, [1] * 3])
    cylinder = load_object(tmp_path, "cylinder = { height = 3, radius = 0.5, segments = 8 }")
    assert np.allclose(cylinder.bounds, [[-0.5, -0.5, 0], [0.5, 0.5, 3]])  # along z from z = 0
    cone = load_object(tmp_path, "cylinder = { height = 2, radius = 1, radius_top = 0, center = true }")
    assert cone.bounds[0, 2] == -1 and cone.bounds[1, 2] == 1
    assert np.linalg.norm(cone.vertices[cone.vertices[:, 2] > 0.99][:, :2], axis=1).max() < 1e-6  # apex


def test_primitive_defaults(tmp_path):
    assert np.allclose(load_object(tmp_path, "sphere = {}").bounds, [[-1] * 3, [1] * 3])
    assert np.array_equal(load_object(tmp_path, "box = {}").bounds, [[0] * 3, [1] * 3])
    cylinder = load_object(tmp_path, "cylinder = {}")
    assert np.allclose(cylinder.bounds, [[-1, -1, 0], [1, 1, 1]])
    assert len(np.unique(cylinder.vertices[:, :2], axis=0)) == 32  # default segments round the axis


def test_csg_operations(tmp_path):
    two_boxes = '[{ box = { size = 2 } }, { box = { size = 2 }, translate = [1, 1, 1] }]'
    union = load_object(tmp_path, f"union = {two_boxes}")
    assert np.array_equal(union.bounds, [[0] * 3, [3] * 3])
    intersection = load_object(tmp_path, f"intersection = {two_boxes}")
    assert np.array_equal(intersection.bounds, [[1] * 3, [2] * 3])
    difference = load_object(tmp_path, f"difference = {two_boxes}")
    assert np.array_equal(difference.bounds, [[0] * 3, [2] * 3])
    assert not np.any(np.all(difference.vertices == 2, axis=1))  # the corner at (2, 2, 2) is cut away


def test_nested_csg_with_transforms_on_each_level(tmp_path):
    mesh = load_object(
        tmp_path,
        "union = [\n"
        "  { difference = [{ box = { size = 2, center = true } }, { sphere = { radius = 1.2 } }], translate = [5, 0, 0] },\n"
        "  { box = { size = 1 }, scale = 0.5 },\n"
        "]\n"
        "translate = [0, 10, 0]\n",
    )
    assert np.allclose(mesh.bounds, [[0, 9, -1], [6, 11, 1]])


def test_csg_in_array_of_tables_syntax(tmp_path):
    scene = load_text(
        tmp_path,
        LIGHT + "[[objects]]\n[[objects.union]]\nbox = {}\n[[objects.union]]\nbox = {}\ntranslate = [3, 0, 0]\n",
    )
    assert np.array_equal(scene.mesh.bounds, [[0, 0, 0], [4, 1, 1]])


def test_inline_triangles_are_kept_as_written(tmp_path):
    mesh = load_object(
        tmp_path,
        "triangles = { vertices = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [9, 9, 9]], "
        "faces = [[0, 1, 2], [0, 1, 2], [2, 1, 0], [0, 0, 1]] }",
    )
    assert np.array_equal(mesh.vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [9, 9, 9]])
    assert np.array_equal(mesh.faces, [[0, 1, 2], [0, 1, 2], [2, 1, 0], [0, 0, 1]])


def test_transforms_apply_scale_then_rotate_then_translate(tmp_path):
    triangle = "triangles = { vertices = [[1, 0, 0], [0, 1, 0], [0, 0, 1]], faces = [[0, 1, 2]] }\n"
    mesh = load_object(tmp_path, triangle + "scale = [2, 3, 4]\nrotate = [0, 0, 90]\ntranslate = [5, 0, 0]")
    # scale: (2,0,0) (0,3,0) (0,0,4); rotate 90 about z: (x, y) -> (-y, x); translate +5 in x
    assert np.allclose(mesh.vertices, [[5, 2, 0], [2, 0, 0], [5, 0, 4]])


def test_rotations_apply_about_x_then_y_then_z(tmp_path):
    point_up = "triangles = { vertices = [[0, 1, 0], [0, 0, 0], [0, 0, 0]], faces = [[0, 1, 2]] }\n"
    mesh = load_object(tmp_path, point_up + "rotate = [90, 90, 0]")
    assert np.allclose(mesh.vertices[0], [1, 0, 0])  # x: (0,1,0) -> (0,0,1); then y: -> (1,0,0)
    mesh = load_object(tmp_path, point_up + "rotate = [0, 0, 30]")
    assert np.allclose(mesh.vertices[0], [-0.5, np.sqrt(3) / 2, 0])


def test_manifold_and_raw_shapes_transform_alike(tmp_path):
    transform = "scale = [1, 2, 3]\nrotate = [10, 20, 30]\ntranslate = [4, 5, 6]\n"
    solid = load_object(tmp_path, "box = { size = 1 }\n" + transform)
    corners = [[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    faces = [[0, 1, 2], [3, 4, 5], [5, 6, 7]]  # referencing every corner
    raw = load_object(tmp_path, f"triangles = {{ vertices = {corners}, faces = {faces} }}\n" + transform)
    assert np.allclose(np.unique(solid.vertices, axis=0), np.unique(raw.vertices, axis=0), atol=1e-6)


def test_quarter_turns_are_exact(tmp_path):
    box = load_object(tmp_path, "box = { size = [1, 2, 3] }\nrotate = [0, 90, 0]")
    assert box.bounds[0, 1] == 0.0 and np.array_equal(box.bounds, [[0, 0, -1], [3, 2, 0]])
    post = load_object(tmp_path, "cylinder = { height = 2, radius = 0.5 }\nrotate = [-90, 0, 0]")
    assert post.bounds[0, 1] == 0.0 and post.bounds[1, 1] == 2.0  # stands on y = 0 along +y


def test_mesh_paths_relative_absolute_and_home(tmp_path, monkeypatch):
    (tmp_path / "models").mkdir()
    (tmp_path / "scenes").mkdir()
    model = tmp_path / "models" / "tetra.obj"
    model.write_text(TETRAHEDRON_OBJ)
    monkeypatch.setenv("HOME", str(tmp_path))
    for reference in ("../models/tetra.obj", str(model), "~/models/tetra.obj"):
        scene = load_text(tmp_path / "scenes", LIGHT + f'[[objects]]\nmesh = "{reference}"\ntranslate = [0, 1, 0]\n')
        assert scene.objects[0][0] == "tetra"  # named after the file by default
        assert np.array_equal(scene.mesh.bounds, [[0, 1, 0], [1, 2, 1]]), reference


def test_mesh_files_are_transformed_in_float64(tmp_path):
    (tmp_path / "tetra.obj").write_text(TETRAHEDRON_OBJ)
    mesh = load_object(tmp_path, 'mesh = "tetra.obj"\nscale = 0.1\ntranslate = [100000, 0, 0]')
    expected = np.float32(100000 + 0.1)  # one rounding of the float64 result, not two float32 steps
    assert mesh.vertices.dtype == np.float32 and mesh.vertices[1, 0] == expected


def test_scene_level_keys_and_defaults(tmp_path):
    scene = load_text(
        tmp_path,
        'name = "demo"\n[render]\nwidth = 320\nheight = 200\n'
        '[camera]\nposition = [0, 1, 5]\ntarget = [0, 1, 0]\nfov = 30\n'
        + LIGHT + '[[lights]]\ntype = "directional"\ndirection = [0, -2, 0]\n'
        + '[[objects]]\nname = "red"\ncolor = [1, 0, 0]\nbox = {}\n[[objects]]\nsphere = {}\n',
    )
    assert scene.name == "demo" and scene.render_size == (320, 200)
    assert scene.camera.fov == 30 and np.array_equal(scene.camera.up, [0, 1, 0])
    assert isinstance(scene.light, sc.PointLight) and np.array_equal(scene.lights[1].direction, [0, -1, 0])
    assert [name for name, _ in scene.objects] == ["red", "sphere"]
    assert np.array_equal(scene.colors[0], [1, 0, 0]) and np.all((scene.colors[1] >= 0) & (scene.colors[1] <= 1))
    assert np.array_equal(scene.triangle_colors[scene.object_ids() == 0], np.tile([1.0, 0, 0], (12, 1)))


def test_missing_camera_gets_a_default_camera_seeing_the_whole_scene(tmp_path):
    scene = load_text(tmp_path, LIGHT + "[[objects]]\nbox = { size = [4, 1, 2] }\ntranslate = [10, 0, 0]\n")
    assert scene.render_size is None and scene.name == "scene"
    assert np.allclose(scene.camera.target, scene.bounds.mean(axis=0))
    view = scene.camera.view(64, 64, near=0.01)
    corners = np.array([[x, y, z] for x in scene.bounds[:, 0] for y in scene.bounds[:, 1] for z in scene.bounds[:, 2]])
    clip = np.c_[corners - view.origin, np.ones(8)] @ view.matrix.T
    assert np.all(clip[:, 3] > 0) and np.all(np.abs(clip[:, :2] / clip[:, 3:]) <= 1)


def test_default_camera_of_a_single_point_is_still_a_camera():
    camera = default_camera(np.zeros((2, 3)))
    assert np.array_equal(camera.target, [0, 0, 0]) and np.linalg.norm(camera.position) > 0


def test_scene_built_in_code():
    triangle = sc.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    scene = Scene([("a", triangle), ("b", triangle.transformed(np.diag([1, 1, 1, 1.0])))], [sc.PointLight((0, 0, 3))],
                  colors=[(0, 0, 1), None])
    assert scene.path is None and scene.render_size is None and isinstance(scene.camera, sc.Camera)
    assert np.array_equal(scene.object_ids(), [0, 1]) and np.array_equal(scene.colors[0], [0, 0, 1])


TRIANGLE = sc.Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
POINT = sc.PointLight((0, 0, 3))
BAD_CONSTRUCTIONS = [
    (lambda: Scene([], [POINT]), ValueError, r"objects: a scene needs at least one object"),
    (lambda: Scene([TRIANGLE], [POINT]), TypeError, r"objects\[0\]: expected a \(name, Mesh\) pair"),
    (lambda: Scene([("t", TRIANGLE)], []), ValueError, r"lights: a scene needs at least one light"),
    (lambda: Scene([("t", TRIANGLE)], POINT), TypeError, r"lights: expected a list of lights"),
    (lambda: Scene([("t", TRIANGLE)], ["sun"]), TypeError, r"lights\[0\]: expected a PointLight or DirectionalLight"),
    (lambda: Scene([("t", TRIANGLE)], [POINT], camera="top"), TypeError, r"camera: expected a Camera or None"),
    (lambda: Scene([("t", TRIANGLE)], [POINT], colors=[None, None]), ValueError, r"colors: expected one colour"),
    (lambda: Scene([("t", TRIANGLE)], [POINT], colors=[(2, 0, 0)]), ValueError, r"colors\[0\]: expected RGB .* \[0, 1\]"),
    (lambda: Scene([("t", TRIANGLE)], [POINT], render_size=(0, 10)), ValueError, r"render_size\[0\]: must be between 1 and 16384"),
]


@pytest.mark.parametrize("call, error, message", BAD_CONSTRUCTIONS, ids=[m for _, _, m in BAD_CONSTRUCTIONS])
def test_bad_construction_is_named(call, error, message):
    with pytest.raises(error, match=message):
        call()


# ---- bad scene files: each error names the file, the key path and what was wrong ----

BOX = "[[objects]]\nbox = {}\n"
OBJECT = LIGHT + "[[objects]]\n"  # an object table follows
BAD_FILES = [
    (OBJECT + 'mesh = "nothere.obj"\n', FileNotFoundError, r"objects\[0\]\.mesh: no such file .*/nothere\.obj"),
    (OBJECT + 'mesh = "model.xyz"\n', ValueError, r"objects\[0\]\.mesh: path: \S*model.xyz: unsupported mesh format '.xyz'"),
    (LIGHT + BOX + "[lamp]\nposition = [0, 1, 0]\n", ValueError,
     r"lamp: unknown key; allowed here: name, render, camera, lights, objects"),
    (OBJECT + "box = {}\ncolour = [1, 0, 0]\n", ValueError,
     r"objects\[0\]\.colour: unknown key; allowed here: name, color, sphere"),
    (OBJECT + "box = { sise = 1 }\n", ValueError, r"objects\[0\]\.box\.sise: unknown key; allowed here: size, center"),
    (OBJECT + 'sphere = { radius = "big" }\n', TypeError, r"objects\[0\]\.sphere\.radius: expected a number, got a string"),
    (OBJECT + "sphere = { radius = -1 }\n", ValueError, r"objects\[0\]\.sphere\.radius: must be positive, got -1"),
    (OBJECT + "sphere = { segments = 2 }\n", ValueError, r"objects\[0\]\.sphere\.segments: must be between 3 and 2048, got 2"),
    (OBJECT + "sphere = { segments = 8.0 }\n", TypeError,
     r"objects\[0\]\.sphere\.segments: expected an integer, got a float"),
    (OBJECT + 'box = { center = "yes" }\n', TypeError, r"objects\[0\]\.box\.center: expected true or false, got a string"),
    (OBJECT + "box = { size = [1, 0, 1] }\n", ValueError, r"objects\[0\]\.box\.size: must be positive"),
    (OBJECT + "box = 1\n", TypeError, r"objects\[0\]\.box: expected a table, got an integer"),
    (OBJECT + "box = {}\ntranslate = [1, 2]\n", ValueError,
     r"objects\[0\]\.translate: expected three numbers, got shape \(2,\)"),
    (OBJECT + "box = {}\nscale = 0\n", ValueError, r"objects\[0\]\.scale: must not be zero"),
    (OBJECT + "box = {}\ncolor = [1.5, 0, 0]\n", ValueError, r"objects\[0\]\.color: expected RGB components in \[0, 1\]"),
    (OBJECT + "box = {}\nsphere = {}\n", ValueError, r"objects\[0\]: expected exactly one shape key .*; found sphere, box"),
    (OBJECT + 'name = "nothing"\n', ValueError, r"objects\[0\]: expected exactly one shape key .*; found none"),
    (OBJECT + "union = []\n", ValueError, r"objects\[0\]\.union: expected at least one shape table"),
    (OBJECT + 'union = [{ box = {} }, { mesh = "m.obj" }]\n', ValueError,
     r"objects\[0\]\.union\[1\]\.mesh: .*cannot be used in CSG"),
    (OBJECT + "union = [{ box = {}, name = 'x' }]\n", ValueError, r"objects\[0\]\.union\[0\]\.name: unknown key"),
    (OBJECT + "intersection = [{ box = {} }, { box = {}, translate = [5, 0, 0] }]\n", ValueError,
     r"objects\[0\]: the shape is empty"),
    (OBJECT + "triangles = { vertices = [[0, 0, 0]], faces = [[0, 1, 2]] }\n", ValueError,
     r"objects\[0\]\.triangles: faces: face 0 has vertex index 1 out of range for 1 vertices"),
    (OBJECT + "triangles = { faces = [[0, 1, 2]] }\n", ValueError, r"objects\[0\]\.triangles\.vertices: missing"),
    ("objects = 3\n" + LIGHT, TypeError, r"objects: expected an array of tables, got an integer"),
    (LIGHT, ValueError, r"objects: a scene needs at least one object"),
    (BOX, ValueError, r"lights: a scene needs at least one light"),
    (BOX + '[[lights]]\ntype = "directional"\ndirection = [0, 0, 0]\n', ValueError,
     r"lights\[0\]\.direction: must have non-zero length"),
    (BOX + '[[lights]]\ntype = "point"\nposition = [0, nan, 0]\n', ValueError, r"lights\[0\]\.position: must be finite"),
    (BOX + '[[lights]]\ntype = "point"\nposition = [inf, 1, 0]\n', ValueError, r"lights\[0\]\.position: must be finite"),
    (BOX + '[[lights]]\ntype = "point"\nposition = ["0", 1, 0]\n', TypeError,
     r"lights\[0\]\.position: expected an array of three numbers"),
    (BOX + '[[lights]]\ntype = "spot"\nposition = [0, 1, 0]\n', ValueError,
     r'lights\[0\]\.type: expected "point" or "directional", got \'spot\''),
    (BOX + '[[lights]]\ntype = "point"\ndirection = [0, 1, 0]\n', ValueError,
     r"lights\[0\]\.direction: unknown key; allowed here: type, position"),
    (BOX + "[[lights]]\nposition = [0, 1, 0]\n", ValueError, r"lights\[0\]\.type: missing"),
    (BOX + LIGHT + "[camera]\nposition = [0, 1, 0]\ntarget = [0, 1, 0]\n", ValueError,
     r"camera: target: must differ from the eye position"),
    (BOX + LIGHT + "[camera]\nposition = [0, 1, 0]\n", ValueError, r"camera\.target: missing"),
    (BOX + LIGHT + "[camera]\nposition = [0, 1, 5]\ntarget = [0, 1, 0]\nfov = 0\n", ValueError,
     r"camera\.fov: must be positive"),
    (BOX + LIGHT + "[render]\nwidth = 0\nheight = 10\n", ValueError, r"render\.width: must be between 1 and 16384, got 0"),
    ("name = 3\n" + BOX + LIGHT, TypeError, r"name: expected a string, got an integer"),
    (BOX + "[[lights]\n", ValueError, r"Expected ']]' .*\(at line 3"),  # TOML syntax error, with its position
    # sizes: bounded before manifold3d or the tessellation allocates anything
    (OBJECT + "sphere = { segments = 2000000000 }\n", ValueError,
     r"objects\[0\]\.sphere\.segments: must be between 3 and 2048, got 2000000000"),
    (OBJECT + "union = [{ cylinder = { segments = 1000000 } }]\n", ValueError,
     r"objects\[0\]\.union\[0\]\.cylinder\.segments: must be between 3 and 524289, got 1000000"),
    (OBJECT + "subdivision = { vertices = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0]], "
              "faces = [[0, 1, 2, 3], [1, 4, 5, 2]] }\ntessellation = 1025\n", ValueError,
     r"objects\[0\]: segments: must be between 1 and 1024, got 1025"),
    (OBJECT + "subdivision = { vertices = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0], [3, 0, 0], "
              "[3, 1, 0]], faces = [[0, 1, 2, 3], [1, 4, 5, 2], [4, 6, 7, 5]] }\ntessellation = 1024\n", ValueError,
     r"objects\[0\]: segments: 1024 per control edge make 3,145,728 cells"),
    (OBJECT + "union = [" + ", ".join(["{ sphere = { segments = 2048 } }"] * 5) + "]\n", ValueError,
     r"objects: the spheres and cylinders would make about 10,485,760 triangles; at most 8,388,608 in one scene"),
    (OBJECT + "box = { size = 1e300 }\n", ValueError, r"objects\[0\]: vertices: coordinates overflow float32"),
    (OBJECT + 'mesh = "good.obj"\nscale = 1e300\n', ValueError, r"objects\[0\]: vertices: coordinates overflow float32"),
    (OBJECT + 'mesh = "bad.obj"\n', ValueError, r"objects\[0\]\.mesh: path: .*bad\.obj: line 2: expected three numbers"),
    (BOX + LIGHT + "[render]\nwidth = 100000000000000000000\nheight = 10\n", ValueError,
     r"render\.width: must be between 1 and 16384, got 100000000000000000000"),
]


@pytest.mark.parametrize("text, error, message", BAD_FILES, ids=[m for _, _, m in BAD_FILES])
def test_bad_scene_file_is_named(tmp_path, text, error, message):
    (tmp_path / "model.xyz").write_text("not a mesh")
    (tmp_path / "bad.obj").write_text("v 0 0 0\nv 1 0 x\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "good.obj").write_text(TETRAHEDRON_OBJ)
    with pytest.raises(error, match=r"scene\.toml: " + message):
        load_text(tmp_path, text)


def test_scene_path_that_is_not_a_path_or_not_utf8_is_named(tmp_path):
    with pytest.raises(TypeError, match=r"^path: expected a file path, got NoneType$"):
        Scene.load(None)
    path = tmp_path / "latin.toml"
    path.write_bytes("# caf\xe9\n".encode("latin-1") + (LIGHT + BOX).encode())
    with pytest.raises(ValueError, match=r"latin\.toml: not UTF-8 text \(TOML must be\): byte 5"):
        Scene.load(path)


def test_missing_scene_file_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match=r"nothere\.toml: no such scene file"):
        Scene.load(tmp_path / "nothere.toml")
