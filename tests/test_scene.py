"""Scene files: shapes, CSG, transforms, paths, and a table of bad files."""

import textwrap

import numpy as np
import pytest

import shadowcl as sc

from conftest import MODELS, SCENES, require_models

LIGHT = '[[lights]]\ntype = "point"\nposition = [0, 5, 0]\n'


def load(tmp_path, body: str, name="scene.toml") -> sc.Scene:
    path = tmp_path / name
    path.write_text(textwrap.dedent(body))
    return sc.Scene.load(path)


@pytest.mark.parametrize("path", sorted(SCENES.rglob("*.toml")), ids=lambda p: p.relative_to(SCENES).as_posix())
def test_every_shipped_scene_loads(path):
    if "models" in path.parts:
        require_models()
    scene = sc.Scene.load(path)
    assert len(scene.mesh.faces) > 0 and scene.lights and scene.camera is not None
    assert scene.name == path.stem


def test_primitives_csg_and_defaults(tmp_path):
    scene = load(tmp_path, LIGHT + """
        [[objects]]
        sphere = { radius = 2, segments = 48 }
        [[objects]]
        difference = [ { box = { size = 2, center = true } }, { sphere = { radius = 1.2 } } ]
        [[objects]]
        cylinder = { height = 3, radius = 0.5 }
    """)
    sphere, hollow, cylinder = (mesh for _, mesh in scene.objects)
    np.testing.assert_allclose(np.linalg.norm(sphere.vertices, axis=1), 2, rtol=1e-6)
    np.testing.assert_allclose(hollow.bounds, [[-1] * 3, [1] * 3], atol=1e-6)
    assert len(hollow.faces) > 12  # the sphere cut the box
    np.testing.assert_allclose(cylinder.bounds[:, 2], [0, 3], atol=1e-6)  # stands on z = 0 along z
    assert scene.name == "scene" and scene.camera is not None  # default camera from the bounds
    assert scene.triangle_colors.shape == (len(scene.mesh.faces), 3)


def test_transform_order_is_scale_rotate_translate(tmp_path):
    scene = load(tmp_path, LIGHT + """
        [[objects]]
        triangles = { vertices = [[1, 0, 0], [0, 1, 0], [0, 0, 1]], faces = [[0, 1, 2]] }
        scale = [2, 1, 1]
        rotate = [0, 0, 90]
        translate = [10, 0, 0]
    """)
    # (1,0,0) -> scale (2,0,0) -> 90 deg about z (0,2,0) -> translate (10,2,0)
    np.testing.assert_allclose(scene.mesh.vertices[0], [10, 2, 0], atol=1e-6)


def test_mesh_paths_are_relative_to_the_scene_file(tmp_path):
    require_models()
    sub = tmp_path / "scenes"
    sub.mkdir()
    relative = "../" * (len(sub.parts) - 1) + str(MODELS / "teapot.obj").lstrip("/")
    scene = load(sub, LIGHT + f'[[objects]]\nmesh = "{relative}"\n')
    assert len(scene.mesh.faces) == 6320 and scene.objects[0][0] == "teapot"


def test_raw_triangles_are_kept_as_written(tmp_path):
    scene = load(tmp_path, LIGHT + """
        [[objects]]
        triangles = { vertices = [[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces = [[0, 1, 2], [0, 1, 2], [0, 0, 1]] }
    """)
    assert len(scene.mesh.faces) == 3 and scene.mesh.degenerate_count == 1


BAD_SCENES = [
    ('[[objects]]\nmesh = "absent.obj"\n' + LIGHT, FileNotFoundError, r"objects\[0\]\.mesh: .*absent\.obj"),
    ("[[objects]]\nsphere = { radius = 1 }\nwobble = 3\n" + LIGHT, ValueError, r"objects\[0\].*wobble"),
    ('[[objects]]\nsphere = { radius = "big" }\n' + LIGHT, TypeError, r"objects\[0\]\.sphere\.radius"),
    ('[[objects]]\nsphere = { radius = 1 }\n[[lights]]\ntype = "directional"\ndirection = [0, 0, 0]\n',
     ValueError, r"lights\[0\]\.direction: must have non-zero length"),
    ('[[objects]]\nsphere = { radius = 1 }\n[[lights]]\ntype = "point"\nposition = [0, nan, 0]\n',
     ValueError, r"lights\[0\]\.position: must be finite"),
    ("[[objects]]\nsphere = { radius = 1 }\n", ValueError, r"lights"),
    ("[[objects]]\nsphere = { radius = 1 }\n[[lights]]\ntype = \"spot\"\n", ValueError, r"lights\[0\]\.type"),
    ("this is not toml", ValueError, r"scene\.toml"),
]


@pytest.mark.parametrize("body, error, message", BAD_SCENES, ids=[m for _, _, m in BAD_SCENES])
def test_bad_scene_files_name_file_and_key(tmp_path, body, error, message):
    with pytest.raises(error, match=message) as info:
        load(tmp_path, body)
    assert "scene.toml" in str(info.value)


def test_missing_scene_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing.toml: no such scene file"):
        sc.Scene.load(tmp_path / "nothing.toml")
