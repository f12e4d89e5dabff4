"""render: every shipped scene renders, and the default scene's shadows are the exact answer."""

import importlib

import numpy as np
import pytest

import shadowcl as sc
from shadowcl.geometry import bounds_diagonal
from shadowcl.reference import exact as exact_ref
from shadowcl.methods import default_eps
from shadowcl.render import render_report

from conftest import SCENES, require_models

SHIPPED = sorted(SCENES.glob("*.toml")) + sorted((SCENES / "hard").glob("*.toml"))


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.relative_to(SCENES).as_posix())
def test_every_shipped_scene_renders(path, device):
    scene = sc.Scene.load(path)
    result = render_report(scene, width=64, height=36, device=device)
    assert result.image.shape == (36, 64, 3) and result.image.dtype == np.uint8
    assert result.covered.any(), "the camera sees nothing of the scene"
    assert result.shadow.shape == (len(scene.lights), result.covered.sum())


@pytest.mark.parametrize("name", ["bunny", "teapot", "ogre"])
def test_model_scenes_render(name, device):
    require_models()
    scene = sc.Scene.load(SCENES / "models" / f"{name}.toml")
    result = render_report(scene, width=80, height=45, device=device)
    assert result.covered.any() and result.shadow.any()


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.relative_to(SCENES).as_posix())
def test_rendered_shadows_are_exact(path, device):
    """Every shipped scene (every hard case): render's mask equals the float64 brute force."""
    scene = sc.Scene.load(path)
    result = render_report(scene, width=64, height=36, device=device)
    seen = result.receivers
    v, f = scene.mesh.vertices, scene.mesh.faces
    eps = default_eps(scene.bounds)
    for light, shadow in zip(scene.lights, result.shadow):
        truth = exact_ref.shadow_mask(v, f, light, seen.points, seen.normals, eps=eps)
        differ = shadow != truth
        if not differ.any():
            continue
        # Receivers whose segment passes within 2e-6 of the scene size (~10 float32 ulps of its
        # coordinates) of a triangle edge may go either way on the device; no other may differ. A wider
        # band would also catch ground points near the ground's own edges under grazing light, whose
        # segment starts only eps * sin(elevation) above the edge: those are decided, not ambiguous.
        band = 2e-6 * bounds_diagonal(scene.bounds)
        near_edge = exact_ref.segment_edge_distance(v, f, light, seen.points, seen.normals, eps) < band
        assert not np.any(differ & ~near_edge), f"{np.count_nonzero(differ & ~near_edge)} receivers differ away from edges"


def test_default_scene_shows_light_and_shadow(device):
    result = render_report(sc.Scene.load(SCENES / "default.toml"), width=96, height=54, device=device)
    assert 0.05 < result.shadow[0].mean() < 0.6, "the demo should show lit and shadowed surfaces"


def test_shadowed_pixels_are_darker(device):
    scene = sc.Scene.load(SCENES / "default.toml")
    result = render_report(scene, width=96, height=54, device=device)
    pixels = result.image.reshape(-1, 3)[result.covered.ravel()].astype(float).sum(axis=1)
    ground = scene.object_ids()[result.receivers.triangle] == 0
    shadow = result.shadow[0]
    assert pixels[ground & shadow].mean() < 0.7 * pixels[ground & ~shadow].mean()


def test_render_rejects_bad_sizes(device):
    scene = sc.Scene.load(SCENES / "default.toml")
    with pytest.raises(ValueError, match="width: must be between 1 and"):
        sc.render(scene, width=0, height=10, device=device)
    with pytest.raises(TypeError, match="height: expected an integer"):
        sc.render(scene, width=10, height=2.5, device=device)


def test_render_sizes_are_checked_against_memory_before_allocating(device, monkeypatch):
    """A frame that does not fit the host's (or the device's) free memory is refused with the amount
    needed; the memory figures are set here so the test does not depend on the machine."""
    render_module = importlib.import_module("shadowcl.render")   # sc.render is the function
    scene = sc.Scene.load(SCENES / "default.toml")
    monkeypatch.setattr(render_module, "available_host_bytes", lambda: 1 << 30)
    with pytest.raises(ValueError, match=r"width, height: a 4096 x 4096 frame with 1 light\(s\) needs about 4\.81 GiB "
                                         r"but the host has 1\.00 GiB available"):
        sc.render(scene, width=4096, height=4096, device=device)
    assert sc.render(scene, width=64, height=32, device=device).shape == (32, 64, 3)   # a size that fits works
    monkeypatch.setattr(render_module, "DEVICE_BYTES_PER_PIXEL", 1 << 40)
    with pytest.raises(ValueError, match=r"width, height: .* but device .* has"):
        sc.render(scene, width=64, height=32, device=device)


def test_method_resolutions_are_checked_against_host_memory(device, monkeypatch):
    """On a CPU device, a buffer the host cannot give is refused with what it was for (PoCL would crash)."""
    device_module = importlib.import_module("shadowcl.device")
    monkeypatch.setattr(device_module, "available_host_bytes", lambda: 100 << 20)
    scene = sc.Scene.load(SCENES / "default.toml")
    points = np.array([[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match=r"depth buffer \(8192 x 8192\): a 256 MiB buffer needs about 0\.25 GiB but the host has 0\.10 GiB"):
        sc.shadow_mask(scene, scene.light, points, method="shadow_map", resolution=8192, device=device)
    assert sc.shadow_mask(scene, scene.light, points, method="shadow_map", resolution=1024, device=device).shape == (1,)


def test_far_offset_scene_renders_like_the_default(device):
    # The same scene 1e5 away from the origin: float32 world coordinates there are 0.008 apart, so
    # vertices move by up to 0.004 (1e-4 of the scene) and only pixels along shadow edges may change.
    near = render_report(sc.Scene.load(SCENES / "default.toml"), width=160, height=90, device=device)
    far = render_report(sc.Scene.load(SCENES / "hard" / "far_offset.toml"), width=160, height=90, device=device)
    assert np.array_equal(near.covered, far.covered) or (near.covered != far.covered).mean() < 0.002
    both = near.covered & far.covered
    near_shadow = np.zeros(both.shape, bool)
    far_shadow = np.zeros(both.shape, bool)
    near_shadow[near.covered] = near.shadow[0]
    far_shadow[far.covered] = far.shadow[0]
    assert (near_shadow != far_shadow)[both].mean() < 0.005


def test_slivers_get_finite_normals_and_render(device, rng):
    """Collinear triangles (0, b, b / 2 on a dyadic grid, the camera too, so the corners relative to it
    are exact and their float32 cross product is exactly zero) can still cover pixels once their
    projected corners are snapped to the sub-pixel grid; their receivers must get a finite unit normal,
    not NaN (which broke render)."""
    n = 20000
    b = rng.integers(-1024, 1024, (n, 3)) / 1024.0
    corners = np.stack([np.zeros_like(b), b, b * np.float32(0.5)], axis=1)
    slivers = sc.Mesh(corners.reshape(-1, 3), np.arange(3 * n).reshape(-1, 3))
    scene = sc.Scene([("slivers", slivers)], [sc.PointLight((0, 3, 0))], sc.Camera((0.25, 0.125, 1.5), (0, 0, 0)))
    result = render_report(scene, width=256, height=256, device=device)
    normals = result.receivers.normals
    assert result.covered.any()
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-5)
