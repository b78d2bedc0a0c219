"""Spherical-harmonics lighting (thesis ch. 3, App. 3.7.3): the basis against the literal
spherical-coordinate formulas, orthonormality, the clamped-cosine coefficients against quadrature,
the three vector-Jacobian products against finite differences, the sphere against a brute-force
irradiance integral, and PyTorch autograd through the same image formation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from algorithms.errors import ParameterError
from algorithms.mesh import icosphere
from algorithms.render import Camera, look_at
from algorithms.render.sh import (ENVIRONMENTS, SHShading, clamped_cosine_coefficients,
                                  convolution_weights, environment, face_albedo,
                                  n_coefficients, read_mesh_colors, sh_basis, sh_basis_gradient,
                                  sh_basis_gradient_polar, sh_basis_polar, sh_image_vjp,
                                  sh_face_colors_torch, sh_index, sh_render)
from tests.algorithms.render._helpers import interior_pixels


def _directions(k, seed=0):
    rng = np.random.default_rng(seed)
    N = rng.standard_normal((k, 3))
    return N / np.linalg.norm(N, axis=1, keepdims=True)


def _sphere_quadrature(n_theta=96, n_phi=192):
    """Gauss-Legendre in cos(theta) x uniform phi: exact for polynomials of degree < 2 n_theta."""
    x, w = np.polynomial.legendre.leggauss(n_theta)
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    ct = np.repeat(x, n_phi)
    st = np.sqrt(1 - ct ** 2)
    ph = np.tile(phi, n_theta)
    D = np.stack([st * np.cos(ph), st * np.sin(ph), ct], axis=1)
    W = np.repeat(w, n_phi) * (2 * np.pi / n_phi)
    return D, W


def test_cartesian_basis_equals_eq_3_16_in_polar_angles():
    N = _directions(200)
    theta = np.arccos(N[:, 2])
    phi = np.arctan2(N[:, 1], N[:, 0])
    Y = sh_basis(N)
    assert Y.shape == (200, 49)
    np.testing.assert_allclose(Y, sh_basis_polar(theta, phi), atol=1e-12)
    # the familiar degree-2 constants of Ramamoorthi and Hanrahan
    x, y, z = N.T
    np.testing.assert_allclose(Y[:, sh_index(0, 0)], 0.282095, atol=1e-6)
    np.testing.assert_allclose(Y[:, sh_index(1, -1)], 0.488603 * y, atol=1e-6)
    np.testing.assert_allclose(Y[:, sh_index(1, 1)], 0.488603 * x, atol=1e-6)
    np.testing.assert_allclose(Y[:, sh_index(2, -2)], 1.092548 * x * y, atol=1e-6)
    np.testing.assert_allclose(Y[:, sh_index(2, 0)], 0.315392 * (3 * z * z - 1), atol=1e-6)
    np.testing.assert_allclose(Y[:, sh_index(2, 2)], 0.546274 * (x * x - y * y), atol=1e-6)


def test_basis_is_orthonormal_on_the_sphere():
    D, W = _sphere_quadrature(20, 40)
    Y = sh_basis(D)
    np.testing.assert_allclose((Y * W[:, None]).T @ Y, np.eye(49), atol=1e-10)


def test_clamped_cosine_coefficients_match_quadrature_of_eq_3_20():
    # Eq. 3.20 over the upper hemisphere only (the integrand is smooth there): Gauss-Legendre
    # in cos(theta) on [0, 1] x uniform phi
    x, w = np.polynomial.legendre.leggauss(20)
    ct, wt = (x + 1) / 2, w / 2
    phi = (np.arange(32) + 0.5) * 2 * np.pi / 32
    st = np.sqrt(1 - ct ** 2)
    D = np.stack([np.outer(st, np.cos(phi)).ravel(), np.outer(st, np.sin(phi)).ravel(),
                  np.repeat(ct, 32)], axis=1)
    W = np.repeat(wt, 32) * (2 * np.pi / 32)
    Y = sh_basis(D)
    G = (Y * (W * D[:, 2])[:, None]).sum(0)
    Gt = clamped_cosine_coefficients(6)
    for l in range(7):
        assert G[sh_index(l, 0)] == pytest.approx(Gt[l], abs=1e-12)
    A = convolution_weights(6)
    assert [A[sh_index(l, 0)] for l in (0, 1, 2, 4, 6)] == pytest.approx(
        [np.pi, 2 * np.pi / 3, np.pi / 4, -np.pi / 24, np.pi / 64])
    assert A[sh_index(3, 0)] == 0 and A[sh_index(5, 2)] == 0


def test_gradient_equals_eq_3_37_to_3_40_and_finite_differences():
    N = _directions(100, seed=3)
    N = N[np.hypot(N[:, 0], N[:, 1]) > 0.1]          # the polar formulas are singular at the poles
    g = sh_basis_gradient(N)
    np.testing.assert_allclose(g, sh_basis_gradient_polar(N), atol=1e-9)
    eps = 1e-6
    for d in range(3):
        E = np.zeros(3)
        E[d] = eps
        fd = (sh_basis(N + E) - sh_basis(N - E)) / (2 * eps)   # sh_basis normalizes: Y(n/|n|)
        np.testing.assert_allclose(g[..., d], fd, atol=1e-6)
    # no singularity at the poles
    P = np.array([[0, 0, 1.0], [0, 0, -1.0]])
    gp = sh_basis_gradient(P)
    assert np.isfinite(gp).all()
    fd = (sh_basis(P + [eps, 0, 0]) - sh_basis(P - [eps, 0, 0])) / (2 * eps)
    np.testing.assert_allclose(gp[..., 0], fd, atol=1e-6)


def test_published_environments_round_to_the_paper_table():
    # two-decimal values of Ramamoorthi & Hanrahan 2001 (their table), first and last rows
    assert np.round(ENVIRONMENTS["Grace Cathedral"][0], 2) == pytest.approx([0.79, 0.44, 0.54])
    assert np.round(ENVIRONMENTS["Grace Cathedral"][8], 2) == pytest.approx([0.21, -0.05, -0.30])
    assert np.round(ENVIRONMENTS["Eucalyptus Grove"][0], 2) == pytest.approx([0.38, 0.43, 0.45])
    assert np.round(ENVIRONMENTS["St. Peter's Basilica"][0], 2) == pytest.approx([0.36, 0.26, 0.23])
    U = environment("grace cathedral")
    assert U.shape == (49, 3) and (U[9:] == 0).all()
    with pytest.raises(ParameterError, match="Choose one of"):
        environment("Moon")


def _bumpy(seed=0, level=3):
    V, F = icosphere(level)
    rng = np.random.default_rng(seed)
    return V * (1 + 0.08 * rng.random((len(V), 1))), F


CAM = Camera((0.3, 0.5, 3.0), (-0.1, -0.15, -1), (0.1, 1, 0), width=1.2, resolution=96)


def _random_lighting(seed=0):
    rng = np.random.default_rng(seed)
    U = environment("Grace Cathedral") + 0.1 * rng.standard_normal((49, 3))
    return U


def test_all_three_vjps_match_central_differences_away_from_silhouettes():
    V, F = _bumpy()
    rng = np.random.default_rng(2)
    U = _random_lighting()
    rho = 0.3 + 0.7 * rng.random((len(F), 3))
    r0 = sh_render(V, F, CAM, U, albedo=rho)
    mask = interior_pixels(r0.raster.face_id)
    assert mask.sum() > 500
    W = rng.standard_normal(r0.image.shape) * mask[..., None]

    def loss(X=V, U_=U, rho_=rho):
        r = sh_render(X, F, CAM, U_, albedo=rho_)
        assert (r.raster.face_id[mask] == r0.raster.face_id[mask]).all()
        return float((W * r.image).sum())

    g = sh_image_vjp(V, F, r0, W, albedo=True)
    assert g.vertices.shape == V.shape and g.lighting.shape == U.shape
    assert g.albedo.shape == rho.shape
    # lighting and albedo: the image is linear in them, so differences are exact
    for trial in range(3):
        D = rng.standard_normal(U.shape)
        fd = (loss(U_=U + D) - loss(U_=U - D)) / 2
        assert fd == pytest.approx(float((g.lighting * D).sum()), rel=1e-9, abs=1e-9)
        D = rng.standard_normal(rho.shape)
        fd = (loss(rho_=rho + D) - loss(rho_=rho - D)) / 2
        assert fd == pytest.approx(float((g.albedo * D).sum()), rel=1e-9, abs=1e-9)
    eps = 1e-6
    for trial in range(3):
        D = rng.standard_normal(V.shape)
        fd = (loss(X=V + eps * D) - loss(X=V - eps * D)) / (2 * eps)
        assert fd == pytest.approx(float((g.vertices * D).sum()), rel=1e-5, abs=1e-7)
    seen = np.unique(F[r0.faces[np.unique(r0.slot[mask])]])
    for v in rng.choice(seen, 3, replace=False):
        for d in range(3):
            E = np.zeros_like(V)
            E[v, d] = eps
            fd = (loss(X=V + E) - loss(X=V - E)) / (2 * eps)
            assert fd == pytest.approx(g.vertices[v, d], rel=1e-5, abs=1e-7)
    # single lighting coefficients of a high degree are not dead
    j = sh_index(6, -3)
    E = np.zeros_like(U)
    E[j, 1] = 1.0
    assert (loss(U_=U + E) - loss(U_=U - E)) / 2 == pytest.approx(g.lighting[j, 1], rel=1e-9)


def _hemisphere_around(n, n_theta=24, n_phi=48):
    """Directions and weights of a quadrature of the hemisphere around unit ``n`` (Gauss-Legendre
    in cos(theta) on [0, 1] x uniform phi, rotated to ``n``)."""
    x, w = np.polynomial.legendre.leggauss(n_theta)
    ct, wt = (x + 1) / 2, w / 2
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    st = np.sqrt(1 - ct ** 2)
    local = np.stack([np.outer(st, np.cos(phi)).ravel(), np.outer(st, np.sin(phi)).ravel(),
                      np.repeat(ct, n_phi)], axis=1)
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    return local @ np.stack([t1, t2, n]), np.repeat(wt, n_phi) * (2 * np.pi / n_phi)


def test_degree_2_sphere_matches_brute_force_irradiance_integral():
    """Eq. 3.8 (the hemisphere integral of radiance times cosine) integrated numerically for the
    normal each pixel sees, against the SH rendering of a sphere (degree-2 lighting: Grace
    Cathedral): within 1 % of the image's range, per pixel and channel."""
    V, F = icosphere(4)
    U = environment("Grace Cathedral", degree=2)
    cam = look_at((0.4, 0.8, 3.0), (0, 0, 0), width=2.2, resolution=48)
    r = sh_render(V, F, cam, U)
    seen = r.slot >= 0
    assert seen.sum() > 1000
    faces = np.unique(r.slot[seen])
    brute = np.empty((len(faces), 3))
    for i, f in enumerate(faces):
        n = r.normals[f]
        D, W = _hemisphere_around(n)
        brute[i] = (W * (D @ n)) @ (sh_basis(D, 2) @ U)        # sum of u(w) (w.n) dw
    ours = r.colors[faces]
    rel = np.abs(ours - brute) / np.abs(brute).max(axis=0)
    assert rel.max() < 0.01, rel.max()
    assert rel.max() < 1e-9          # with a polynomial integrand the quadrature is exact
    # the image carries those face colours
    np.testing.assert_array_equal(r.image[seen], r.colors[r.slot[seen]])


def test_matches_pytorch_autograd_through_the_same_image_formation():
    torch = pytest.importorskip("torch")
    torch.set_num_threads(1)
    V, F = _bumpy(level=2)
    U = _random_lighting(1)
    rho = np.full((len(F), 3), 0.8)
    r = sh_render(V, F, CAM, U, albedo=rho)
    rng = np.random.default_rng(0)
    W = rng.standard_normal(r.image.shape)
    g = sh_image_vjp(V, F, r, W)
    Vt = torch.tensor(V, requires_grad=True)
    Ut = torch.tensor(U, requires_grad=True)
    col = sh_face_colors_torch(Vt, Ut, F[r.faces], rho[r.faces])
    img = col[torch.tensor(r.slot[r.slot >= 0])]
    loss = (img * torch.tensor(W[r.slot >= 0])).sum()
    loss.backward()
    assert float(loss.detach()) == pytest.approx(float((W * r.image).sum()), rel=1e-10)
    np.testing.assert_allclose(g.lighting, Ut.grad.numpy(), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(g.vertices, Vt.grad.numpy(), rtol=1e-7, atol=1e-8)


def test_albedo_forms_and_plain_errors(tmp_path):
    F = np.array([[0, 1, 2], [0, 2, 3]])
    assert face_albedo(F, 0.5).shape == (2, 3)
    np.testing.assert_allclose(face_albedo(F, [1, 0, 0])[1], [1, 0, 0])
    vc = np.array([[1, 0, 0], [1, 0, 0], [0, 0, 1], [0, 0, 1.0]])
    np.testing.assert_allclose(face_albedo(F, vc)[0], [2 / 3, 0, 1 / 3])
    with pytest.raises(ParameterError, match="one colour per face"):
        face_albedo(F, np.ones((2, 2)))
    with pytest.raises(ParameterError, match="49"):
        SHShading(np.ones((10, 3)))
    assert SHShading(np.ones(4)).channels == 1 and n_coefficients(2) == 9
    obj = tmp_path / "c.obj"
    obj.write_text("v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 1 2 3\n")
    kind, C = read_mesh_colors(obj, 3, 1)
    assert kind == "vertex" and C[1] == pytest.approx([0, 1, 0])
    ply = tmp_path / "c.ply"
    ply.write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                   "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                   "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
                   "0 0 0\n1 0 0\n0 1 0\n3 0 1 2 255 0 51\n")
    kind, C = read_mesh_colors(ply, 3, 1)
    assert kind == "face" and C[0] == pytest.approx([1, 0, 0.2])
    plain = tmp_path / "p.obj"
    plain.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert read_mesh_colors(plain, 3, 1) is None
