"""Z-buffer correctness: face ids / depth / barycentrics against a brute-force ray cast and
libigl's ray-mesh intersection; compiled and NumPy rasterizers agree."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.mesh import icosphere, torus
from algorithms.render import Camera, compiled_kernels, look_at, rasterize


def _brute_force(V, F, O, D):
    """Nearest hit (face, t) of each ray against every triangle (Moller-Trumbore, both sides)."""
    O, D = O.reshape(-1, 3), D.reshape(-1, 3)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    e1, e2 = b - a, c - a
    p = np.cross(D[:, None], e2[None])
    det = np.einsum("fk,rfk->rf", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = O[:, None] - a[None]
        u = np.einsum("rfk,rfk->rf", s, p) * inv
        q = np.cross(s, e1[None])
        v = np.einsum("rk,rfk->rf", D, q) * inv
        t = np.einsum("fk,rfk->rf", e2, q) * inv
    hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & np.isfinite(t)
    t = np.where(hit, t, np.inf)
    f = np.argmin(t, axis=1)
    tbest = t[np.arange(len(t)), f]
    second = np.partition(t, 1, axis=1)[:, 1]
    f = np.where(np.isfinite(tbest), f, -1)
    return f, tbest, second


def _bumpy(seed=0):
    V, F = icosphere(2)
    rng = np.random.default_rng(seed)
    return V * (1 + 0.1 * rng.random((len(V), 1))), F


@pytest.mark.parametrize("projection", ["orthographic", "perspective"])
def test_face_ids_and_depth_match_a_brute_force_ray_cast(projection):
    V, F = _bumpy()
    # two shapes, one in front of the other, so occlusion matters
    V2, F2 = torus(12, 8)
    V2 = V2 * 0.5 + [0.3, 0.2, 1.4]
    VV = np.vstack([V, V2])
    FF = np.vstack([F, F2 + len(V)])
    cam = Camera((0.2, 0.1, 5), (-0.04, -0.02, -1), (0, 1, 0), projection=projection,
                 width=2.8, fov=34, resolution=40)
    r = rasterize(VV, FF, cam)
    O, D = cam.pixel_rays()
    f, t, t2 = _brute_force(VV, FF, O, D)
    fid = r.face_id.ravel()
    # a pixel may legitimately differ only where two hits are at (almost) the same depth
    # (a shared edge or vertex seen exactly): then both are correct.
    same = fid == f
    with np.errstate(invalid="ignore"):
        tie = np.isfinite(t) & (np.abs(t2 - t) < 1e-9 * (1 + t))
    assert (same | tie).all(), np.flatnonzero(~(same | tie))
    assert same.mean() > 0.97
    hit = fid >= 0
    assert hit.sum() > 300 and (~hit).sum() > 300          # both shapes and background seen
    assert np.isin(np.arange(len(F), len(FF)), fid).any()     # the torus occludes something
    depth_from_t = t[hit] * (D.reshape(-1, 3)[hit] @ cam.direction)
    np.testing.assert_allclose(r.depth.ravel()[hit], depth_from_t, rtol=1e-9, atol=1e-9)
    # barycentrics give the 3D point seen
    B = r.bary.reshape(-1, 3)[hit]
    X = np.einsum("pk,pkd->pd", B, VV[FF[fid[hit]]])
    P = O.reshape(-1, 3)[hit] + t[hit, None] * D.reshape(-1, 3)[hit]
    np.testing.assert_allclose(X, P, atol=1e-9)
    np.testing.assert_allclose(B.sum(1), 1.0, atol=1e-12)


def test_face_ids_match_libigl_ray_mesh_intersect():
    igl = pytest.importorskip("igl")
    V, F = _bumpy(1)
    cam = look_at((0.4, 3.0, 2.0), (0, 0, 0), width=2.6, resolution=16)
    r = rasterize(V, F, cam)
    O, D = cam.pixel_rays()
    agree = 0
    seen = 0
    for o, d, fid in zip(O.reshape(-1, 3), D.reshape(-1, 3), r.face_id.ravel()):
        hits = igl.ray_mesh_intersect(o, d, V, F.astype(np.int32)) or []   # (face, t, u, v)
        if not hits:
            assert fid == -1
            continue
        seen += 1
        tmin = min(h[1] for h in hits)
        nearest = {int(h[0]) for h in hits if h[1] <= tmin + 1e-9}     # ties at shared edges
        agree += int(fid in nearest)
    assert seen > 100
    assert agree == seen


@pytest.mark.skipif(compiled_kernels() is None, reason="Numba not available")
@pytest.mark.parametrize("projection", ["orthographic", "perspective"])
def test_compiled_and_numpy_rasterizers_agree(projection):
    V, F = _bumpy(2)
    cam = look_at((1.5, 0.5, 2.0), (0, 0, 0), projection=projection, width=1.0, fov=40,
                  resolution=48)    # a close camera: part of the shape is outside the image
    a = rasterize(V, F, cam, backend="numpy")
    b = rasterize(V, F, cam, backend="compiled")
    np.testing.assert_array_equal(a.face_id, b.face_id)
    np.testing.assert_allclose(a.depth, b.depth, rtol=1e-12)
    np.testing.assert_allclose(a.bary, b.bary, atol=1e-12)


def test_geometry_behind_an_orthographic_camera_is_not_seen():
    V, F = icosphere(2)
    inside = rasterize(V, F, look_at((0, 0, 0.0), (0, 0, -1), width=0.5, resolution=8))
    # from the centre, looking -z: only the far half of the sphere, at depth 1
    assert inside.mask.all()
    assert inside.depth.min() > 0.9
    behind = rasterize(V, F, look_at((0, 0, -1.5), (0, 0, -3), width=0.5, resolution=8))
    assert not behind.mask.any()


def _agree(V, F, cam):
    """Compiled and NumPy rasterizers give the same face ids and depths (bit for bit)."""
    a = rasterize(V, F, cam, backend="numpy")
    b = rasterize(V, F, cam, backend="compiled")
    np.testing.assert_array_equal(a.face_id, b.face_id)
    np.testing.assert_array_equal(a.depth, b.depth)
    return a


@pytest.mark.skipif(compiled_kernels() is None, reason="Numba not available")
@pytest.mark.parametrize("projection", ["orthographic", "perspective"])
def test_two_pass_occlusion_test_keeps_the_picture(projection):
    """The compiled rasterizer's two passes (one screen orientation, then the other with the
    tile occlusion test) give the NumPy picture on closed, open, self-intersecting and
    near-clipped meshes, small and wide faces, views from outside and inside."""
    rng = np.random.default_rng(11)
    V, F = icosphere(3)
    V = V * (1 + 0.15 * rng.random((len(V), 1)))
    open_F = F[V[F].mean(1)[:, 2] < 0.3]                        # a cap cut off: open
    V2, F2 = torus(16, 10)
    VV = np.vstack([V, V2 * 0.7])                              # the torus crosses the sphere
    FF = np.vstack([F, F2 + len(V)])
    Vc, Fc = icosphere(1)                                      # few, wide faces
    seen = 0
    for k in range(12):
        d = rng.standard_normal(3)
        d /= np.linalg.norm(d)
        dist = [3.0, 1.6, 0.5][k % 3]                          # 0.5: inside the sphere
        res = [48, 7, 64][k % 3]                               # 7: fewer pixels than lanes
        cam = look_at(d * dist, rng.standard_normal(3) * 0.1, projection=projection,
                      width=2.4, fov=50, resolution=res)
        for mesh in ((V, F), (V, open_F), (VV, FF), (Vc * 1.2, Fc)):
            seen += int(_agree(*mesh, cam).mask.sum())
    assert seen > 10000


@pytest.mark.skipif(compiled_kernels() is None, reason="Numba not available")
def test_equal_depths_go_to_the_lower_face_index_across_passes():
    """A grid at depth exactly 0 (near -1) and its reversed copy (the other orientation: the
    other pass): every depth ties, and the lower index wins whichever pass it is in."""
    n = 6
    g = np.linspace(-1, 1, n + 1)
    X, Y = np.meshgrid(g, g)
    V = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)
    q = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None]).ravel()
    F = np.vstack([np.stack([q, q + 1, q + n + 2], 1), np.stack([q, q + n + 2, q + n + 1], 1)])
    cam = Camera((0, 0, 0), (0, 0, -1), (0, 1, 0), width=2.5, resolution=40, near=-1.0)
    for FF, low in ((np.vstack([F, F[:, ::-1]]), "front"), (np.vstack([F[:, ::-1], F]), "back")):
        a = _agree(V, FF, cam)
        assert a.mask.sum() > 1000 and np.all(a.depth[a.mask] == 0)
        assert a.face_id.max() < len(F), low


@pytest.mark.skipif(compiled_kernels() is None, reason="Numba not available")
def test_rasterize_kernel_returns_the_faces_it_rasterized():
    """``kernels.rasterize`` returns the sorted faces it z-tested: every face seen is in it, and
    faces behind the front of a closed mesh are left out by the occlusion test."""
    from algorithms.render import kernels

    V, F = icosphere(4)
    cam = look_at((0.2, 0.3, 3.0), (0, 0, 0), width=2.4, resolution=96)
    P = cam.to_pixels(V)
    fid = np.empty((96, 96), np.int64)
    depth = np.empty((96, 96))
    cand = kernels.rasterize(P, F, 96, False, cam.near, fid, depth, np.empty((0, 0, 3)))
    assert np.all(np.diff(cand) > 0)
    assert np.isin(np.unique(fid[fid >= 0]), cand).all()
    assert len(cand) < 0.8 * len(F)         # half the sphere faces away (most are skipped)
