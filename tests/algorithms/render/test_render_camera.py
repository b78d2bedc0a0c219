"""Camera conventions of the one renderer (see algorithms/render/camera.py)."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.errors import ParameterError
from algorithms.render import Camera, look_at


def test_basis_is_orthonormal_with_right_up_back_right_handed_and_up_is_reorthogonalized():
    cam = Camera((1, 2, 3), (0, 0, -2), (0, 1, 0.5))
    B = cam.basis
    np.testing.assert_allclose(B @ B.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(np.stack([B[0], B[1], -B[2]])) == pytest.approx(1.0)  # x, y, -view: right-handed
    np.testing.assert_allclose(B[2], [0, 0, -1])
    np.testing.assert_allclose(B[1], [0, 1, 0], atol=1e-12)   # the 0.5 along the view is dropped
    np.testing.assert_allclose(B[0], [1, 0, 0], atol=1e-12)   # right = direction x up


@pytest.mark.parametrize("projection", ["orthographic", "perspective"])
def test_image_orientation_right_is_right_and_up_is_row_zero(projection):
    cam = look_at((0, 0, 5), (0, 0, 0), projection=projection, width=2.0, fov=40, resolution=10)
    P = cam.to_pixels(np.array([[0, 0, 0], [0.5, 0, 0], [0, 0.5, 0]]))
    np.testing.assert_allclose(P[0, :2], [4.5, 4.5])           # centre of a 10-pixel image
    assert P[1, 0] > 4.5 and P[1, 1] == pytest.approx(4.5)      # +x -> right
    assert P[2, 1] < 4.5 and P[2, 0] == pytest.approx(4.5)      # +y -> up = smaller row
    assert P[0, 2] == pytest.approx(5.0)                        # depth along the view direction


def test_orthographic_width_and_perspective_fov_map_to_the_image_border():
    cam = look_at((0, 0, 5), (0, 0, 0), width=0.5, resolution=8)
    # x = width/2 is the right border of the last pixel: column 7 + 0.5
    assert cam.to_pixels([[0.25, 0, 0]])[0, 0] == pytest.approx(7.5)
    camp = look_at((0, 0, 5), (0, 0, 0), projection="perspective", fov=90, resolution=8)
    # at depth 5 and fov 90, x = 5 is on the border
    assert camp.to_pixels([[5.0, 0, 0]])[0, 0] == pytest.approx(7.5)


@pytest.mark.parametrize("projection", ["orthographic", "perspective"])
def test_pixel_rays_pass_through_pixel_centres(projection):
    cam = Camera((0.3, -0.2, 4), (0.1, 0.05, -1), (0.2, 1, 0), projection=projection,
                 width=1.3, fov=35, resolution=7)
    O, D = cam.pixel_rays()
    P = cam.to_pixels((O + 2.5 * D).reshape(-1, 3))
    jj, ii = np.meshgrid(np.arange(7), np.arange(7))
    np.testing.assert_allclose(P[:, 0], jj.ravel(), atol=1e-9)
    np.testing.assert_allclose(P[:, 1], ii.ravel(), atol=1e-9)


def test_default_near_planes_and_bad_cameras_are_refused_plainly():
    assert look_at((0, 0, 1), (0, 0, 0)).near == 0.0
    assert look_at((0, 0, 1), (0, 0, 0), projection="perspective").near == pytest.approx(1e-3)
    with pytest.raises(ParameterError, match="parallel"):
        Camera((0, 0, 0), (0, 1, 0), (0, 2, 0))
    with pytest.raises(ParameterError, match="projection"):
        Camera((0, 0, 0), (0, 0, 1), (0, 1, 0), projection="fisheye")
    with pytest.raises(ParameterError, match="resolution"):
        Camera((0, 0, 0), (0, 0, 1), (0, 1, 0), resolution=0)
    with pytest.raises(ParameterError, match="zero"):
        Camera((0, 0, 0), (0, 0, 0), (0, 1, 0))
