"""The compiled (Numba) paths of the renderer give the NumPy paths' numbers: projection
(bit-identical), seen faces, normals, image, per-face pixel sums, the normal VJP, and the SH
shading (colours, irradiance, lighting / albedo / vertex derivatives, with and without the basis
kept in the rendering). Switched with algorithms.render.set_compiled_kernels."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.mesh import icosphere
from algorithms.render import (Camera, LambertianShading, compiled_kernels, face_unit_normals,
                               image_vjp, look_at, normal_vjp, render, set_compiled_kernels)
from algorithms.render.render import face_color_gradients
from algorithms.render.sh import SHShading, SHState, environment, sh_image_vjp, sh_render

pytestmark = pytest.mark.skipif(compiled_kernels() is None, reason="Numba not available")

CAMERAS = {
    "orthographic": look_at((1.5, 0.5, 2.0), (0, 0, 0), width=1.6, resolution=40),
    "perspective": Camera((0.4, 0.6, 3.0), (-0.12, -0.2, -1), (0, 1, 0.2),
                          projection="perspective", fov=30, resolution=40),
}


def _bumpy(seed=0, level=3):
    V, F = icosphere(level)
    rng = np.random.default_rng(seed)
    return V * (1 + 0.08 * rng.random((len(V), 1))), F


def _both(fn):
    """``fn()`` with the compiled kernels on, then off (the setting is restored)."""
    prev = set_compiled_kernels(True)
    try:
        a = fn()
        set_compiled_kernels(False)
        b = fn()
    finally:
        set_compiled_kernels(prev)
    return a, b


@pytest.mark.parametrize("name", sorted(CAMERAS))
def test_compiled_projection_is_bit_identical_to_to_pixels(name):
    from algorithms.render import kernels

    cam = CAMERAS[name]
    V, _ = _bumpy(1)
    V = np.vstack([V, [[0.4, 0.6, 3.0]]])          # a point at the eye: depth 0 (inf / nan)
    P = np.empty_like(V)
    kernels.project(V, cam.position, cam._basis, cam.perspective, cam.projection_scale,
                    cam.resolution, P)
    with np.errstate(divide="ignore", invalid="ignore"):
        Q = cam.to_pixels(V)
    np.testing.assert_array_equal(P, Q)


@pytest.mark.parametrize("name", sorted(CAMERAS))
def test_lazy_and_eager_barycentrics_are_identical(name):
    from algorithms.render import kernels, rasterize

    cam = CAMERAS[name]
    V, F = _bumpy(8)
    r = rasterize(V, F, cam, backend="compiled")
    res = cam.resolution
    P = cam.to_pixels(V)
    fid, depth, bary = np.empty((res, res), np.int64), np.empty((res, res)), np.empty((res, res, 3))
    kernels.rasterize(P, F, res, cam.perspective, cam.near, fid, depth, bary)
    np.testing.assert_array_equal(fid, r.face_id)
    np.testing.assert_array_equal(depth, r.depth)
    np.testing.assert_array_equal(bary, r.bary)
    r2 = rasterize(V, F, cam, backend="compiled")
    prev = set_compiled_kernels(False)           # read after switching off: the NumPy formulas
    try:
        np.testing.assert_allclose(r2.bary, bary, rtol=0, atol=1e-12)
    finally:
        set_compiled_kernels(prev)
    assert (fid >= 0).sum() > 300 and np.all(bary[fid < 0] == 0)
    np.testing.assert_allclose(bary[fid >= 0].sum(1), 1.0, atol=1e-12)


@pytest.mark.parametrize("name", sorted(CAMERAS))
def test_render_and_image_vjp_agree_with_numpy(name):
    cam = CAMERAS[name]
    V, F = _bumpy(2)
    rng = np.random.default_rng(3)
    alb = 0.5 + rng.random((len(F), 3))
    G = rng.standard_normal((40, 40, 3))
    sh = LambertianShading()

    def run():
        r = render(V, F, cam, sh, albedo=alb, background=0.3)
        return r, face_color_gradients(r, G), image_vjp(V, F, r, G, return_albedo=True)

    (a, ga, (dva, daa)), (b, gb, (dvb, dab)) = _both(run)
    assert 200 < len(a.faces) < len(F) and (~a.mask).any()
    np.testing.assert_array_equal(a.raster.face_id, b.raster.face_id)
    np.testing.assert_array_equal(a.raster.depth, b.raster.depth)
    np.testing.assert_array_equal(a.raster.bary, b.raster.bary)
    np.testing.assert_array_equal(a.faces, b.faces)
    np.testing.assert_array_equal(a.slot, b.slot)
    np.testing.assert_allclose(a.normals, b.normals, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.image, b.image, rtol=0, atol=1e-12)
    assert np.all(a.image[~a.mask] == 0.3)
    np.testing.assert_allclose(ga, gb, rtol=0, atol=1e-12)
    scale = np.abs(dvb).max()
    assert scale > 1
    np.testing.assert_allclose(dva, dvb, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(daa, dab, rtol=0, atol=1e-12)


def test_normal_vjp_agrees_with_numpy_including_degenerate_faces():
    V, F = _bumpy(4, level=2)
    F = np.vstack([F, [[0, 0, 1], [2, 3, 2]]])                # zero-area faces get nothing
    faces = np.arange(len(F))
    G = np.random.default_rng(5).standard_normal((len(F), 3))
    a, b = _both(lambda: normal_vjp(V, F, faces, G))
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * np.abs(b).max())
    n = face_unit_normals(V, F)
    assert (n[-2:] == 0).all()


@pytest.mark.parametrize("degree", [0, 1, 2, 6])
def test_sh_shading_agrees_with_numpy(degree):
    rng = np.random.default_rng(degree)
    N = rng.standard_normal((300, 3)) * 2.0                   # not unit: normalized inside
    N[:2] = [[0, 0, 1.0], [0, 0, -3.0]]                       # the poles
    U = rng.standard_normal(((degree + 1) ** 2, 3))
    sh = SHShading(U)
    G = rng.standard_normal((300, 3))
    alb = rng.random((300, 3))

    def run():
        col, st = sh.face_colors_with_state(N, None, alb)
        return (sh.face_colors(N, None, alb), sh.irradiance(N), col, st.basis,
                *sh.face_colors_vjp(N, None, G, alb), sh.lighting_vjp(N, G, alb),
                sh.lighting_vjp(N, G, alb, basis=st.basis))

    for x, y in zip(*_both(run)):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-12 * max(1.0, np.abs(y).max()))


def test_sh_render_and_vjps_agree_with_numpy_with_and_without_the_kept_basis():
    V, F = _bumpy(6)
    cam = look_at((0.5, 1.0, 2.5), (0, 0, 0), width=2.4, resolution=40)
    rng = np.random.default_rng(7)
    U = environment("Grace Cathedral") + 0.05 * rng.standard_normal((49, 3))
    alb = 0.3 + 0.6 * rng.random((len(F), 3))
    G = rng.standard_normal((40, 40, 3))

    def run():
        r = sh_render(V, F, cam, U, albedo=alb)
        assert isinstance(r.state, SHState) and r.state.basis.shape == (len(r.faces), 49)
        g = sh_image_vjp(V, F, r, G, albedo=True)
        r.state = None                                        # recomputed from the normals
        h = sh_image_vjp(V, F, r, G, albedo=True)
        return r.image, g.vertices, g.lighting, g.albedo, h.vertices, h.lighting, h.albedo

    a, b = _both(run)
    for x, y in zip(a, b):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-12 * max(1.0, np.abs(y).max()))
    for x, y in zip(a[1:4], a[4:]):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-12 * max(1.0, np.abs(y).max()))
    assert np.abs(a[1]).max() > 0.1 and np.abs(a[2]).max() > 1


@pytest.mark.parametrize("name", sorted(CAMERAS))
@pytest.mark.parametrize("mapping", ["authors", "linear"])
def test_lambertian_fast_path_agrees_with_numpy(name, mapping):
    """Without albedo the compiled path shades Lambertian faces in the normals' loop and applies
    dE/dn = scale M gc in the normal derivative's loop: same numbers as the NumPy path."""
    cam = CAMERAS[name]
    V, F = _bumpy(9)
    G = np.random.default_rng(4).standard_normal((40, 40, 3))
    sh = LambertianShading([[1, 0.2, 0], [0, 1, 0.5]], [[1, 0.5, 0], [0, 0.3, 1]],
                           mapping=mapping)

    def run():
        r = render(V, F, cam, sh, background=0.2)
        return r, image_vjp(V, F, r, G)

    (a, dva), (b, dvb) = _both(run)
    np.testing.assert_array_equal(a.faces, b.faces)
    np.testing.assert_array_equal(a.slot, b.slot)
    np.testing.assert_allclose(a.normals, b.normals, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.colors, b.colors, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.image, b.image, rtol=0, atol=1e-12)
    assert a.state is None and np.all(a.image[~a.mask] == 0.2)
    scale = np.abs(dvb).max()
    assert scale > 1
    np.testing.assert_allclose(dva, dvb, rtol=0, atol=1e-12 * scale)
