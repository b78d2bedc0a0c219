"""Tests for algorithms.mesh.operators."""

from __future__ import annotations

import igl
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from algorithms.errors import InvalidMeshError, ParameterError
from algorithms.mesh import operators as O
from algorithms.mesh.primitives import cube, grid, icosphere, organic_sample, torus


def independent_cotangent_laplacian(V, F):
    """Plain NumPy cotangent Laplacian (negative semi-definite), written from the formula."""
    n = V.shape[0]
    rows, cols, vals = [], [], []
    for c in range(3):
        i, j, k = F[:, c], F[:, (c + 1) % 3], F[:, (c + 2) % 3]
        u, v = V[j] - V[i], V[k] - V[i]  # angle at corner i is opposite edge (j, k)
        cot = np.einsum("ij,ij->i", u, v) / np.linalg.norm(np.cross(u, v), axis=1)
        rows += [j, k]
        cols += [k, j]
        vals += [cot / 2, cot / 2]
    W = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    return W - sp.diags(np.asarray(W.sum(axis=1)).ravel())


def test_face_areas_and_normals():
    V = np.array([[0, 0, 0], [2, 0, 0], [0, 3, 0], [1, 0, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 1], [0, 1, 3]])
    np.testing.assert_allclose(O.face_areas(V, F), [3, 3, 0])
    np.testing.assert_allclose(O.face_normals(V, F), [[0, 0, 1], [0, 0, -1], [0, 0, 0]])
    V, F = organic_sample("blob")
    np.testing.assert_allclose(O.face_areas(V, F), igl.doublearea(V, F) / 2, rtol=1e-12)
    np.testing.assert_allclose(O.face_normals(V, F), igl.per_face_normals(V, F, np.array([0.0, 0, 0])), atol=1e-12)


def test_vertex_normals_icosphere_radial_and_libigl():
    V, F = icosphere(3)
    N = O.vertex_normals(V, F)
    np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0)
    assert np.min(np.einsum("ij,ij->i", N, V)) > 0.999
    Ni = igl.per_vertex_normals(V, F, igl.PER_VERTEX_NORMALS_WEIGHTING_TYPE_AREA)
    np.testing.assert_allclose(N, Ni, atol=1e-12)
    # unreferenced vertex -> zero
    N2 = O.vertex_normals(np.vstack([V, [[5, 5, 5]]]), F)
    np.testing.assert_array_equal(N2[-1], 0.0)


def test_barycentric_areas_and_mass():
    V, F = torus()
    a = O.barycentric_vertex_areas(V, F)
    total = O.face_areas(V, F).sum()
    assert a.shape == (V.shape[0],)
    assert a.sum() == pytest.approx(total, rel=1e-12)
    for kind in ("barycentric", "voronoi"):
        M = O.mass_matrix(V, F, kind)
        assert sp.isspmatrix_csr(M) and M.shape == (V.shape[0],) * 2
        assert (M - sp.diags(M.diagonal())).count_nonzero() == 0
        np.testing.assert_allclose(np.asarray(M.sum(axis=1)).ravel().sum(), total, rtol=1e-10)
    np.testing.assert_allclose(O.mass_matrix(V, F).diagonal(), a, rtol=1e-12)
    # analytic area of the torus 4 pi^2 R r (discretization error is small)
    assert total == pytest.approx(4 * np.pi**2 * 0.35, rel=0.01)
    with pytest.raises(ParameterError, match="barycentric"):
        O.mass_matrix(V, F, "full-ish")


@pytest.mark.parametrize("maker", [lambda: icosphere(2), lambda: grid(5, 4), lambda: organic_sample("pretzel")])
def test_cotangent_laplacian_matches_independent_formula(maker):
    V, F = maker()
    L = O.cotangent_laplacian(V, F)
    assert sp.isspmatrix_csr(L)
    ref = independent_cotangent_laplacian(V, F)
    assert abs(L - ref).max() < 1e-10
    assert abs(L - L.T).max() < 1e-12
    np.testing.assert_allclose(np.asarray(L.sum(axis=1)).ravel(), 0, atol=1e-10)
    assert np.all(L.diagonal() <= 0)  # negative semi-definite convention (libigl)
    x = np.random.default_rng(0).normal(size=V.shape[0])
    assert x @ (L @ x) <= 1e-12
    P = O.cotangent_laplacian_psd(V, F)
    assert abs(P + L).max() == 0
    assert x @ (P @ x) >= -1e-12


def test_laplacian_of_linear_function_vanishes_inside_flat_grid():
    V, F = grid(6, 6)
    L = O.cotangent_laplacian(V, F)
    f = 2 * V[:, 0] - 3 * V[:, 1]
    interior = (V[:, 0] > 0) & (V[:, 0] < 1) & (V[:, 1] > 0) & (V[:, 1] < 1)
    np.testing.assert_allclose((L @ f)[interior], 0, atol=1e-12)


def test_signed_volume_and_diagonal():
    V, F = cube()
    assert O.signed_volume(V, F) == pytest.approx(8.0)
    assert O.signed_volume(V, F[:, [0, 2, 1]]) == pytest.approx(-8.0)
    assert O.bounding_box_diagonal(V) == pytest.approx(2 * np.sqrt(3))
    assert O.bounding_box_diagonal(np.array([[np.nan, 0, 0], [1, 1, 1], [0, 0, 0]])) == pytest.approx(np.sqrt(3))
    assert O.bounding_box_diagonal(np.zeros((0, 3))) == 0.0


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.tuples(*[st.floats(-1e6, 1e6, allow_nan=False)] * 3), min_size=1, max_size=30),
)
def test_normalize_unit_box_property(points):
    V = np.array(points)
    U, center, scale = O.normalize_unit_box(V)
    assert U.shape == V.shape
    side = U.max(axis=0) - U.min(axis=0)
    if (V.max(axis=0) - V.min(axis=0)).max() > 0:
        assert side.max() == pytest.approx(1.0, rel=1e-9)
    np.testing.assert_allclose((U.max(axis=0) + U.min(axis=0)) / 2, 0, atol=1e-9)
    np.testing.assert_allclose(O.denormalize(U, center, scale), V, rtol=1e-9, atol=1e-9 * max(1.0, scale))


def test_normalize_unit_box_errors():
    with pytest.raises(InvalidMeshError, match="NaN"):
        O.normalize_unit_box(np.array([[0, 0, np.nan]]))
    with pytest.raises(InvalidMeshError, match=r"\(n, 3\)"):
        O.normalize_unit_box(np.zeros((0, 3)))
    U, c, s = O.normalize_unit_box(np.array([[1.0, 2.0, 3.0]]))
    assert s == 1.0 and np.all(U == 0)


def test_operators_reject_bad_input():
    V, F = cube()
    with pytest.raises(InvalidMeshError, match="do not exist"):
        O.face_areas(V, F + 10)
    with pytest.raises(InvalidMeshError, match=r"\(n, 3\)"):
        O.face_normals(V[:, :2], F)
    with pytest.raises(InvalidMeshError, match=r"\(m, 3\)"):
        O.vertex_normals(V, F[:, :2])


def test_operators_keep_trailing_loose_vertices():
    from algorithms.mesh import icosphere
    from algorithms.mesh.operators import cotangent_laplacian, mass_matrix

    V, F = icosphere(1)
    V2 = np.vstack([V, [[3.0, 0.0, 0.0], [4.0, 0.0, 0.0]]])
    for kind in ("barycentric", "voronoi"):
        M = mass_matrix(V2, F, kind)
        assert M.shape == (len(V2), len(V2)) and M[len(V), len(V)] == 0
        np.testing.assert_allclose(M[: len(V), : len(V)].toarray(), mass_matrix(V, F, kind).toarray())
    L = cotangent_laplacian(V2, F)
    assert L.shape == (len(V2), len(V2)) and abs(L[len(V):]).sum() == 0


def test_gaussian_curvature_gauss_bonnet_and_sphere():
    from algorithms.mesh import icosphere, torus
    from algorithms.mesh.operators import gaussian_curvature, mass_matrix

    V, F = icosphere(4)
    K = gaussian_curvature(V, F)
    A = mass_matrix(V, F, "voronoi").diagonal()
    assert (K * A).sum() == pytest.approx(4 * np.pi, rel=1e-9)  # χ = 2
    assert np.median(K) == pytest.approx(1.0, rel=0.02)  # unit sphere: K = 1
    V, F = torus()
    assert (gaussian_curvature(V, F) * mass_matrix(V, F, "voronoi").diagonal()).sum() \
        == pytest.approx(0.0, abs=1e-8)  # χ = 0
