"""Relaxation: Alg. 10 colouring, multi-colour Gauss-Seidel, compiled vs fallback sweeps, and the
convergence factor against PyAMG (thesis Fig. 8.3)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from algorithms.mesh.operators import cotangent_laplacian_psd, mass_matrix
from algorithms.multigrid import greedy_coloring, is_valid_coloring
from algorithms.multigrid.applications import smoothness_matrix
from algorithms.multigrid.relaxation import (GaussSeidel, MultiColorGaussSeidel,
                                             compiled_kernels, set_compiled_kernels)
from tests.algorithms.multigrid.mg_helpers import KINDS, hierarchy

RNG = np.random.default_rng(3)


@pytest.mark.parametrize("energy", ["dirichlet", "bilaplacian"])
def test_greedy_coloring_is_valid(energy):
    V, F, _ = hierarchy("cap", "closest_point")
    Q = smoothness_matrix(V, F, energy)
    col = greedy_coloring(Q)
    assert is_valid_coloring(Q, col)
    k = col.max() + 1
    assert np.array_equal(np.unique(col), np.arange(k))
    # far fewer colours than rows; the 1-ring graph of a triangle mesh needs only a handful
    assert k <= (12 if energy == "dirichlet" else 40)
    # move-to-back palette balances the colours (no colour holds most rows)
    assert np.bincount(col).max() < 0.5 * len(V)
    # the validity check can fail: merge two colours that touch
    bad = col.copy()
    C = sp.coo_matrix(Q)
    i, j = next((r, c) for r, c in zip(C.row, C.col) if r != c)
    bad[bad == bad[j]] = bad[i]
    assert not is_valid_coloring(Q, bad)


def test_coloring_compiled_equals_python_fallback():
    V, F, _ = hierarchy("cap", "closest_point")
    L = cotangent_laplacian_psd(V, F)
    if compiled_kernels() is None:
        pytest.skip("Numba kernels are switched off")
    col = greedy_coloring(L)
    prev = set_compiled_kernels(False)
    try:
        col_py = greedy_coloring(L)
    finally:
        set_compiled_kernels(prev)
    np.testing.assert_array_equal(col, col_py)


def test_gauss_seidel_compiled_equals_pyamg_fallback():
    V, F, _ = hierarchy("cap", "closest_point")
    A = (cotangent_laplacian_psd(V, F) + mass_matrix(V, F)).tocsr()
    if compiled_kernels() is None:
        pytest.skip("Numba kernels are switched off")
    b = RNG.standard_normal((len(V), 2))
    x0 = RNG.standard_normal((len(V), 2))
    out = []
    for enabled in (True, False):
        prev = set_compiled_kernels(enabled)
        try:
            gs = GaussSeidel(A)
            assert (gs._kern is not None) == enabled
            x = x0.copy()
            gs.relax(x, b, 2, backward=False)
            gs.relax(x, b, 1, backward=True)
            out.append(x)
        finally:
            set_compiled_kernels(prev)
    np.testing.assert_allclose(out[0], out[1], rtol=1e-12, atol=1e-12)
    # and it is Gauss-Seidel: one forward sweep solves (D + L_strict) x' = b - U x
    x = x0[:, :1].copy()
    GaussSeidel(A).relax(x, np.ascontiguousarray(b[:, :1]), 1)
    lower = sp.tril(A, format="csr")
    upper = sp.triu(A, k=1, format="csr")
    ref = sp.linalg.spsolve_triangular(lower, b[:, :1] - upper @ x0[:, :1], lower=True)
    np.testing.assert_allclose(x, ref, rtol=1e-10, atol=1e-12)


def test_multicolor_sweep_is_gauss_seidel_in_colour_order():
    V, F, _ = hierarchy("cap", "closest_point")
    A = (cotangent_laplacian_psd(V, F) + mass_matrix(V, F)).tocsr()
    mc = MultiColorGaussSeidel(A)
    perm = np.argsort(mc.coloring, kind="stable")
    b = RNG.standard_normal((len(V), 1))
    x0 = RNG.standard_normal((len(V), 1))
    x = x0.copy()
    mc.relax(x, b, 2)
    Ap = A[perm][:, perm]
    xp = np.ascontiguousarray(x0[perm])
    GaussSeidel(Ap).relax(xp, np.ascontiguousarray(b[perm]), 2)
    np.testing.assert_allclose(x[perm], xp, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("kind", KINDS)
def test_multicolor_and_serial_reach_the_same_fixed_point(kind):
    V, F, mg = hierarchy("sphere", kind)
    A = (cotangent_laplacian_psd(V, F) + 1e-2 * mass_matrix(V, F)).tocsr()
    b = RNG.standard_normal(len(V))
    xs = [mg.solver(A, smoother=k).solve(b, rtol=1e-11, maxiter=60)
          for k in ("gauss_seidel", "multicolor")]
    np.testing.assert_allclose(xs[0], xs[1], rtol=0, atol=1e-8 * np.abs(xs[0]).max())


@pytest.mark.parametrize("kind", KINDS)
def test_convergence_factor_beats_pyamg(kind):
    """Thesis Fig. 8.3: Poisson problem, residual reduction per V-cycle, PyAMG with defaults."""
    import pyamg

    V, F, mg = hierarchy("sphere5", kind)
    A = (cotangent_laplacian_psd(V, F) + 1e-3 * mass_matrix(V, F)).tocsr()
    b = mass_matrix(V, F) @ RNG.standard_normal(len(V))
    cycles = 10

    def factor(res):
        return (res[-1] / res[0]) ** (1.0 / (len(res) - 1))

    s = mg.solver(A)
    res = []
    s.solve(b, rtol=1e-30, maxiter=cycles, residuals=res)
    ours = factor(res)
    peers = {}
    for name, fn in [("rs", pyamg.ruge_stuben_solver), ("sa", pyamg.smoothed_aggregation_solver)]:
        ml = fn(A)
        r = []
        ml.solve(b, tol=1e-30, maxiter=cycles, residuals=r)
        peers[name] = factor(r)
    assert ours < 0.2
    assert ours < peers["rs"] and ours < peers["sa"], (ours, peers)
