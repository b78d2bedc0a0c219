"""The analytic vector-Jacobian product d(image)/d(vertices) against finite differences of
re-rendering (orthographic and perspective), against PyTorch autograd, and the shading's
conventions."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.mesh import icosphere
from algorithms.render import (Camera, LambertianShading, face_unit_normals, image_vjp,
                               light_frame, look_at, normal_vjp, render)
from tests.algorithms.render._helpers import interior_pixels


def _bumpy(seed=0, level=3):
    V, F = icosphere(level)
    rng = np.random.default_rng(seed)
    return V * (1 + 0.08 * rng.random((len(V), 1))), F


CAMERAS = {
    "orthographic": Camera((0.3, 0.2, 3.0), (-0.1, -0.05, -1), (0.1, 1, 0), width=1.2,
                           resolution=96),
    "perspective": Camera((0.4, 0.6, 3.0), (-0.12, -0.2, -1), (0, 1, 0.2),
                          projection="perspective", fov=25, resolution=96),
}


@pytest.mark.parametrize("name", sorted(CAMERAS))
@pytest.mark.parametrize("shading", [LambertianShading(),
                                     LambertianShading([[1, 2, 3], [0, -1, 0.5]],
                                                       [[1.0, 0.3], [0.2, 0.7]],
                                                       frame="world", mapping="linear")],
                         ids=["rgb-camera-axes", "two-lights-world"])
def test_vjp_matches_central_differences_of_a_masked_loss(name, shading):
    V, F = _bumpy()
    cam = CAMERAS[name]
    r0 = render(V, F, cam, shading)
    mask = interior_pixels(r0.raster.face_id)
    assert mask.sum() > 500
    rng = np.random.default_rng(1)
    W = rng.standard_normal(r0.image.shape) * mask[..., None]

    def loss(X):
        r = render(X, F, cam, shading)
        assert (r.raster.face_id[mask] == r0.raster.face_id[mask]).all()  # visibility fixed
        return float((W * r.image).sum())

    g = image_vjp(V, F, r0, W)
    assert g.shape == V.shape
    eps = 1e-6
    for trial in range(3):
        D = rng.standard_normal(V.shape)
        fd = (loss(V + eps * D) - loss(V - eps * D)) / (2 * eps)
        assert fd == pytest.approx(float((g * D).sum()), rel=1e-5, abs=1e-7)
    # single coordinates of vertices that are seen
    seen = np.unique(F[r0.faces[np.unique(r0.slot[mask])]])
    for v in rng.choice(seen, 4, replace=False):
        for d in range(3):
            E = np.zeros_like(V)
            E[v, d] = eps
            fd = (loss(V + E) - loss(V - E)) / (2 * eps)
            assert fd == pytest.approx(g[v, d], rel=1e-5, abs=1e-7)
    # vertices of unseen faces get nothing
    unseen = np.setdiff1d(np.arange(len(V)), np.unique(F[r0.faces]))
    assert np.abs(g[unseen]).max() == 0.0


def test_normal_vjp_matches_finite_differences_of_face_normals():
    V, F = _bumpy(3, level=1)
    rng = np.random.default_rng(0)
    faces = np.arange(len(F))
    G = rng.standard_normal((len(F), 3))
    g = normal_vjp(V, F, faces, G)
    eps = 1e-6
    for _ in range(3):
        D = rng.standard_normal(V.shape)
        fd = ((face_unit_normals(V + eps * D, F) - face_unit_normals(V - eps * D, F)) * G).sum() \
            / (2 * eps)
        assert fd == pytest.approx(float((g * D).sum()), rel=1e-6)


def test_vjp_matches_pytorch_autograd_through_the_same_rasterization():
    torch = pytest.importorskip("torch")
    V, F = _bumpy(4)
    cam = CAMERAS["perspective"]
    sh = LambertianShading()
    r = render(V, F, cam, sh)
    rng = np.random.default_rng(2)
    G = rng.standard_normal(r.image.shape)
    alb = 0.5 + rng.random((len(F), 3))
    r_alb = render(V, F, cam, sh, albedo=alb)
    dV, dA = image_vjp(V, F, r_alb, G, return_albedo=True)

    Vt = torch.tensor(V, requires_grad=True)
    At = torch.tensor(alb, requires_grad=True)
    Ft = torch.tensor(F)
    N = torch.linalg.cross(Vt[Ft[:, 1]] - Vt[Ft[:, 0]], Vt[Ft[:, 2]] - Vt[Ft[:, 0]])
    N = N / N.norm(dim=1, keepdim=True)
    M = torch.tensor(sh.light_matrix(cam))
    col = (0.5 * N @ M + 0.5) * At
    fid = torch.tensor(r.raster.face_id.ravel())
    m = fid >= 0
    img = torch.zeros(fid.shape[0], 3, dtype=torch.float64)
    img[m] = col[fid[m]]
    (img * torch.tensor(G.reshape(-1, 3))).sum().backward()
    np.testing.assert_allclose(dV, Vt.grad.numpy(), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(dA, At.grad.numpy(), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(r_alb.image.reshape(-1, 3)[m.numpy()],
                               img.detach().numpy()[m.numpy()], atol=1e-12)


def test_default_lights_render_the_normals_in_the_camera_frame():
    # a square facing the camera, and one facing the camera's right
    V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    cam = look_at((0, 0, 2), (0, 0, 0), width=1.0, resolution=4)
    r = render(V, F, cam)
    np.testing.assert_allclose(r.image.reshape(-1, 3), [[0.5, 0.5, 1.0]] * 16)
    side = look_at((-2, 0, 0), (0, 0, 0), width=1.0, resolution=4)
    np.testing.assert_allclose(light_frame(side), [[0, 0, 1], [0, 1, 0], [-1, 0, 0]], atol=1e-12)
    V2 = np.array([[0, -1, -1], [0, -1, 1], [0, 1, 1], [0, 1, -1]], float)
    F2 = np.array([[0, 1, 2], [0, 2, 3]])
    np.testing.assert_allclose(face_unit_normals(V2, F2)[0], [-1, 0, 0])  # towards the camera
    np.testing.assert_allclose(render(V2, F2, side).image.reshape(-1, 3), [[0.5, 0.5, 1.0]] * 16)
    back = render(V2, F2[:, ::-1], side).image.reshape(-1, 3)  # seen from behind: blue 0, unclamped
    np.testing.assert_allclose(back, [[0.5, 0.5, 0.0]] * 16)
    c45 = np.cos(np.pi / 4)
    Rz = np.array([[c45, 0, -c45], [0, 1, 0], [c45, 0, c45]])       # V @ Rz turns -x towards (-1, 0, 1)
    tilted = render(V2 @ Rz, F2, side).image.reshape(-1, 3)
    k = (c45 + 1) / 2                                                # half towards camera right (+z)
    np.testing.assert_allclose(tilted, [[k, 0.5, k]] * 16)
    lin = render(V, F, cam, LambertianShading(mapping="linear")).image
    np.testing.assert_allclose(lin.reshape(-1, 3), [[0, 0, 1.0]] * 16)
    grey = render(V, F, cam, LambertianShading([[0, 1, 0]], [[1.0]])).image
    assert grey.shape == (4, 4, 1) and np.allclose(grey, 0.5)


def test_background_pixels_and_bad_gradient_shapes():
    V, F = icosphere(1)
    cam = look_at((0, 0, 3), (0, 0, 0), width=4.0, resolution=16)
    r = render(V, F, cam, background=0.25)
    assert np.all(r.image[~r.mask] == 0.25)
    with pytest.raises(ValueError):
        image_vjp(V, F, r, np.zeros((16, 16, 2)))
