"""Views: projection conventions the raster kernel and the receivers rely on."""

import numpy as np
import pytest

import shadowcl as sc
from shadowcl.views import View, orthographic_reversed


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
