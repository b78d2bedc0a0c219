from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from algorithms.linalg import SPDSolver, cholmod_available
from algorithms.mesh import icosphere
from algorithms.mesh.operators import cotangent_laplacian

BACKENDS = ["superlu"] + (["cholmod"] if cholmod_available() else [])


def laplacian_system():
    V, F = icosphere(2)
    L = cotangent_laplacian(V, F)
    return sp.csc_matrix(-L), len(V)  # PSD, definite once a vertex is fixed


def dense_solution(A, b, fixed, x_fixed):
    A = A.toarray()
    n = len(A)
    free = np.setdiff1d(np.arange(n), fixed)
    x = np.zeros(b.shape)
    x[fixed] = x_fixed
    x[free] = np.linalg.solve(A[np.ix_(free, free)], b[free] - A[np.ix_(free, fixed)] @ x_fixed)
    return x


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("ncols", [None, 1, 3])
def test_solve_with_fixed_unknowns_matches_a_dense_solve(backend, ncols):
    A, n = laplacian_system()
    rng = np.random.default_rng(0)
    fixed = np.array([0, 5, 17])
    shape = (n,) if ncols is None else (n, ncols)
    b = rng.standard_normal(shape)
    x_fixed = rng.standard_normal((3,) + shape[1:])
    solver = SPDSolver(A, fixed, backend=backend)
    b0 = b.copy()
    x = solver.solve(b, x_fixed)
    np.testing.assert_array_equal(b, b0)  # the right-hand side is not modified
    assert x.shape == b.shape and x.dtype == np.float64
    np.testing.assert_array_equal(x[fixed], x_fixed)
    np.testing.assert_allclose(x, dense_solution(A, b, fixed, x_fixed), atol=1e-10)
    # the free rows of A x equal b
    r = (A @ x - b)[solver.free]
    assert np.abs(r).max() < 1e-10


def test_solve_without_fixed_unknowns_and_errors():
    A, n = laplacian_system()
    A = (A + sp.identity(n)).tocsc()
    b = np.random.default_rng(1).standard_normal((n, 2))
    x = SPDSolver(A).solve(b)
    np.testing.assert_allclose(A @ x, b, atol=1e-10)
    solver = SPDSolver(A, [3])
    with pytest.raises(ValueError, match="x_fixed"):
        solver.solve(b)
    with pytest.raises(ValueError, match="rows"):
        solver.solve(b[:-1], np.zeros((1, 2)))
    with pytest.raises(ValueError, match="out of range"):
        SPDSolver(A, [n])
    with pytest.raises(ValueError, match="backend"):
        SPDSolver(A, backend="nope")


@pytest.mark.parametrize("backend", BACKENDS)
def test_fixed_unknowns_as_identity_rows_keep_the_callers_matrix_and_many_fixed(backend):
    # the factored matrix keeps the fixed unknowns in place as identity rows: the caller's
    # matrix is not touched, and a large fixed set (half the unknowns, scattered) still solves
    # the reduced system
    A, n = laplacian_system()
    A = A.tocsc()
    snapshot = (A.indptr.copy(), A.indices.copy(), A.data.copy())
    rng = np.random.default_rng(2)
    fixed = np.sort(rng.choice(n, n // 2, replace=False))
    b = rng.standard_normal((n, 3))
    x_fixed = rng.standard_normal((len(fixed), 3))
    solver = SPDSolver(A, fixed, backend=backend)
    for before, after in zip(snapshot, (A.indptr, A.indices, A.data)):
        np.testing.assert_array_equal(before, after)
    x = solver.solve(b, x_fixed)
    np.testing.assert_array_equal(x[fixed], x_fixed)
    np.testing.assert_allclose(x, dense_solution(A, b, fixed, x_fixed), atol=1e-9)
    # the factored matrix: A_ff in place, identity on the fixed rows and columns
    Ae = solver.A_e.toarray()
    free = solver.free
    np.testing.assert_array_equal(Ae[np.ix_(free, free)], A.toarray()[np.ix_(free, free)])
    np.testing.assert_array_equal(Ae[np.ix_(fixed, fixed)], np.eye(len(fixed)))
    assert not Ae[np.ix_(free, fixed)].any() and not Ae[np.ix_(fixed, free)].any()
