"""Views: projection conventions the raster kernel and the receivers rely on."""

import numpy as np
import pytest

import shadowcl as sc
from shadowcl.views import View, orthographic_reversed, window_orthographic, window_perspective


def project(view: View, world: np.ndarray) -> np.ndarray:
    clip = np.append(world - view.origin, 1.0) @ view.matrix.T
    return clip[:3] / clip[3]


def test_camera_depth_is_reversed_and_centre_ray_looks_at_target():
    camera = sc.Camera((0, 0, 10), (0, 0, 0), fov=60)
    view = camera.view(65, 33, near=0.5)
    near_point, far_point = project(view, np.array([0, 0, 9.5])), project(view, np.array([0, 0, -1e6]))
    assert near_point[2] == pytest.approx(1.0) and 0 <= far_point[2] < 1e-6
    start, direction = view.pixel_rays()
    np.testing.assert_allclose(direction[16, 32], [0, 0, -1], atol=1e-12)  # odd sizes: a pixel on the axis
    np.testing.assert_allclose(start[16, 32], [0, 0, -0.5], atol=1e-12)


def test_pixel_rays_pass_through_projected_points(rng):
    camera = sc.Camera((3, 2, 5), (0, 0.5, 0), fov=50)
    view = camera.view(80, 60, near=0.1)
    start, direction = view.pixel_rays()
    x, y = view.pixel_ndc()
    for row, col in rng.integers(0, [60, 80], size=(10, 2)):
        point = view.origin + start[row, col] + 7.0 * direction[row, col]
        np.testing.assert_allclose(project(view, point)[:2], [x[row, col], y[row, col]], atol=1e-9)


def test_orthographic_depth_range():
    view = View(np.zeros(3), orthographic_reversed(2.0, 1.0, near=1.0, far=5.0), 4, 2)
    assert project(view, np.array([0, 0, -1.0]))[2] == pytest.approx(1.0)
    assert project(view, np.array([0, 0, -5.0]))[2] == pytest.approx(0.0)
    np.testing.assert_allclose(project(view, np.array([2.0, 1.0, -3.0]))[:2], [1.0, 1.0])
    start, direction = view.pixel_rays()
    np.testing.assert_allclose(direction, np.broadcast_to([0, 0, -1.0], direction.shape), atol=1e-12)


def _ndc(matrix: np.ndarray, relative: np.ndarray) -> np.ndarray:
    clip = np.append(relative, 1.0) @ matrix.T
    return clip[:3] / clip[3]


def test_window_projections_map_the_window_to_the_screen_and_depth_as_documented(rng):
    """The light's projections (shadow_map): window corners at screen corners, depth 1 at near, 0 at far."""
    for _ in range(20):
        axes = np.linalg.qr(rng.normal(size=(3, 3)))[0].T   # rows right, up, forward
        right, up, forward = axes
        u0, u1 = np.sort(rng.normal(size=2))
        v0, v1 = np.sort(rng.normal(size=2))
        near, far = rng.uniform(0.5, 2.0), rng.uniform(3.0, 9.0)
        ortho = window_orthographic(axes, (u0, u1, v0, v1), near, far)
        for u, v, t, expected in [(u0, v0, near, (-1, -1, 1)), (u1, v1, far, (1, 1, 0)),
                                  (u0, v1, 0.5 * (near + far), (-1, 1, 0.5))]:
            np.testing.assert_allclose(_ndc(ortho, u * right + v * up + t * forward), expected, atol=1e-9)
        eye = rng.normal(size=3) * 10
        far_ahead = far + forward @ eye
        for finite in (False, True):
            persp = window_perspective(axes, (u0, u1, v0, v1), eye, near, far_ahead if finite else None)
            for u, v, w in [(u0, v0, near), (u1, v1, far), (u1, v0, 0.5 * (near + far))]:
                ndc = _ndc(persp, eye + w * (u * right + v * up + forward))
                depth = near * (far - w) / (w * (far - near)) if finite else near / w
                np.testing.assert_allclose(ndc, [2 * (u - u0) / (u1 - u0) - 1, 2 * (v - v0) / (v1 - v0) - 1, depth],
                                           atol=1e-9)
