"""Surface multigrid: hierarchy, Galerkin matrices, V-cycle accuracy, Dirichlet, blocks, PCG."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from algorithms.errors import ParameterError
from algorithms.linalg import SPDSolver
from algorithms.mesh.operators import cotangent_laplacian_psd, mass_matrix, vertex_normals
from algorithms.multigrid import (closest_point_prolongation, galerkin_matrices,
                                  reduce_dirichlet, surface_multigrid)
from algorithms.multigrid.applications import smoothness_matrix
from tests.algorithms.multigrid.mg_helpers import KINDS, boundary_vertices, hierarchy

RNG = np.random.default_rng(7)


def rel(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


# ----------------------------------------------------------------------------- hierarchy
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("name", ["sphere", "cap"])
def test_hierarchy_prolongations(name, kind):
    V, F, mg = hierarchy(name, kind)
    assert mg.n_levels == 3
    assert len(mg.prolongations) == mg.n_levels - 1
    for h, P in enumerate(mg.prolongations):
        nf, nc = len(mg.levels[h][0]), len(mg.levels[h + 1][0])
        assert P.shape == (nf, nc)
        nnz = np.diff(P.indptr)
        assert nnz.max() <= 3 and nnz.min() >= 1
        assert np.all(P.data >= 0)
        np.testing.assert_allclose(np.asarray(P.sum(axis=1)).ravel(), 1.0, atol=1e-12)
        # x0.25 faces per level (the seed vertices may stop it a little above the target)
        mf, mc = len(mg.levels[h][1]), len(mg.levels[h + 1][1])
        if mg.report.get("seeded"):
            assert 0.25 * mf - 2 <= mc <= 0.34 * mf
        else:
            assert abs(mc - 0.25 * mf) <= 2
        # positions are nearly reproduced: the interpolated coarse positions stay within a coarse
        # edge length of the fine ones (the coarse mesh approximates the fine one)
        Vc, Fc = mg.levels[h + 1]
        edge = np.linalg.norm(Vc[Fc[:, 0]] - Vc[Fc[:, 1]], axis=1).mean()
        err = np.linalg.norm(P @ Vc - mg.levels[h][0], axis=1)
        assert err.max() < edge and err.mean() < 0.1 * edge
    assert mg.report["levels"][0]["vertices"] == len(V)
    assert mg.build_seconds > 0


def test_hierarchy_stops_at_min_vertices():
    V, F, _ = hierarchy("sphere", "closest_point")
    mg = surface_multigrid(V, F, min_vertices=500, prolongation="closest_point")
    # 2562 -> 642 (>= 500) -> next would be ~160 < 500: stop
    assert [len(L[0]) for L in mg.levels] == [2562, 642]
    mg1 = surface_multigrid(V, F, min_vertices=5000, prolongation="closest_point")
    assert mg1.n_levels == 1 and mg1.prolongations == []
    # a single level is a direct solve: one cycle is exact
    A = cotangent_laplacian_psd(V, F) + mass_matrix(V, F)
    s = mg1.solver(A)
    b = np.ones(len(V))
    x = s.solve(b, rtol=1e-9)  # exact up to the 1e-12 relative diagonal shift of the coarsest
    assert s.last_info["cycles"] == 1 and rel(x, spla.spsolve(A.tocsc(), b)) < 1e-9


def test_hierarchy_bad_parameters():
    V, F, _ = hierarchy("sphere", "closest_point")
    with pytest.raises(ParameterError):
        surface_multigrid(V, F, prolongation="nearest")
    with pytest.raises(ParameterError):
        surface_multigrid(V, F, ratio=1.5)


def test_closest_point_prolongation_exact_on_the_coarse_mesh():
    V, F, mg = hierarchy("sphere", "closest_point")
    Vc, Fc = mg.levels[1]
    P = closest_point_prolongation(Vc, Vc, Fc)  # coarse vertices lie on the coarse mesh
    np.testing.assert_allclose(P @ Vc, Vc, atol=1e-12)


# ----------------------------------------------------------------------------- Galerkin
@pytest.mark.parametrize("kind", KINDS)
def test_galerkin_matrices_equal_PtAP(kind):
    V, F, mg = hierarchy("sphere", kind)
    A = cotangent_laplacian_psd(V, F) + mass_matrix(V, F)
    s = mg.solver(A)
    Ah = A.toarray()
    for h, P in enumerate(mg.prolongations):
        Ah = P.toarray().T @ Ah @ P.toarray()
        np.testing.assert_allclose(s.matrices[h + 1].toarray(), Ah, atol=1e-12 * np.abs(Ah).max())
    assert galerkin_matrices(A, mg.prolongations)[-1].shape == s.matrices[-1].shape


# ----------------------------------------------------------------------------- accuracy
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("smoother", ["gauss_seidel", "multicolor"])
def test_poisson_dirichlet_matches_direct(kind, smoother):
    V, F, mg = hierarchy("cap", kind)
    L = cotangent_laplacian_psd(V, F)
    M = mass_matrix(V, F)
    fixed = boundary_vertices(F)
    assert fixed.size > 10
    g = np.sin(3 * V[fixed, 0])
    b = M @ np.cos(2 * V[:, 1])
    s = mg.solver(L, fixed=fixed, smoother=smoother)
    res = []
    x = s.solve(b, rtol=1e-10, residuals=res, fixed_values=g, maxiter=60)
    xd = SPDSolver(L, fixed=fixed).solve(b, g)
    assert s.last_info["converged"]
    assert res[-1] <= 1e-10 * np.linalg.norm(b[s.free] - s.A_uk @ g)
    np.testing.assert_allclose(x[fixed], g)
    assert rel(x, xd) < 1e-8
    assert s.last_info["cycles"] < 30


@pytest.mark.parametrize("kind", KINDS)
def test_poisson_neumann_regularized_and_singular(kind):
    V, F, mg = hierarchy("cap", kind)  # boundary: natural (zero Neumann) condition
    L = cotangent_laplacian_psd(V, F)
    M = mass_matrix(V, F)
    f = np.cos(2 * V[:, 1]) + V[:, 0]
    A = (L + 1e-3 * M).tocsr()
    x = mg.solver(A).solve(M @ f, rtol=1e-10, maxiter=60)
    assert rel(x, spla.spsolve(A.tocsc(), M @ f)) < 1e-7
    # singular pure Neumann: compatible right-hand side, solution up to a constant
    m = M.diagonal()
    b = M @ (f - (m @ f) / m.sum())
    s = mg.solver(L)
    x = s.solve(b, rtol=1e-10, maxiter=60)
    assert s.last_info["converged"]
    xd = SPDSolver(L, fixed=[0]).solve(b, np.zeros(1))
    x -= (m @ x) / m.sum()
    xd -= (m @ xd) / m.sum()
    assert rel(x, xd) < 1e-7


@pytest.mark.parametrize("kind", KINDS)
def test_bilaplacian_matches_direct(kind):
    V, F, mg = hierarchy("sphere", kind)
    Q = smoothness_matrix(V, F, "bilaplacian")
    M = mass_matrix(V, F)
    b = M @ (V[:, 2] + 0.1 * RNG.standard_normal(len(V)))
    xd = None
    for alpha, accel in [(1e-4, None), (1e-2, "cg")]:
        A = (alpha * Q + (1 - alpha) * M).tocsr()
        xd = spla.spsolve(A.tocsc(), b)
        s = mg.solver(A)
        x = s.solve(b, rtol=1e-9, maxiter=200, accel=accel)
        assert s.last_info["converged"], (alpha, accel, s.last_info["cycles"])
        assert rel(x, xd) < 1e-6


@pytest.mark.parametrize("kind", KINDS)
def test_block3_vector_system_matches_direct(kind):
    """A shell-like 3|V| x 3|V| system, interleaved (x0 y0 z0 x1 ...), with Dirichlet rows."""
    V, F, mg = hierarchy("cap", kind)
    L = cotangent_laplacian_psd(V, F)
    M = mass_matrix(V, F)
    N = vertex_normals(V, F)
    m = M.diagonal()
    # couple the components: stiffness on the normal direction (block diagonal n n^T)
    blocks = [sp.csr_matrix(10.0 * m[i] * np.outer(N[i], N[i])) for i in range(len(V))]
    A = (sp.kron(L, sp.identity(3)) + sp.kron(M, sp.identity(3)) + sp.block_diag(blocks)).tocsr()
    b = RNG.standard_normal(3 * len(V))
    fixed = (3 * boundary_vertices(F)[:, None] + np.arange(3)).ravel()
    g = RNG.standard_normal(fixed.size)
    s = mg.solver(A, block=3, fixed=fixed)
    assert s.prolongations[0].shape[1] <= 3 * len(mg.levels[1][0])
    np.testing.assert_array_equal(np.diff(mg.block_prolongations(3)[0].indptr).max(), 3)
    x = s.solve(b, rtol=1e-10, maxiter=80, fixed_values=g)
    xd = SPDSolver(A, fixed=fixed).solve(b, g)
    assert s.last_info["converged"]
    assert rel(x, xd) < 1e-7
    with pytest.raises(ParameterError):
        mg.solver(A)  # 3|V| matrix without block=3


def test_dirichlet_reduced_system_removes_empty_columns():
    V, F, mg = hierarchy("sphere", "closest_point")
    L = cotangent_laplacian_psd(V, F)
    M = mass_matrix(V, F)
    fixed = np.flatnonzero(V[:, 2] > -0.2)  # most of the sphere is known
    P0 = mg.prolongations[0]
    # some coarse columns only interpolate fixed vertices
    free = np.setdiff1d(np.arange(len(V)), fixed)
    n_nonempty = np.unique(P0[free].indices).size
    assert n_nonempty < P0.shape[1]
    Ps, kept = reduce_dirichlet(mg.prolongations, free)
    assert Ps[0].shape == (free.size, n_nonempty) and kept[0].size == n_nonempty
    assert Ps[1].shape[0] == n_nonempty  # matching rows of the next prolongation removed
    s = mg.solver(L + 1e-6 * M, fixed=fixed)
    assert s.matrices[1].shape[0] == n_nonempty
    for Ah in s.matrices:
        assert np.all(Ah.diagonal() > 0)  # no empty rows / columns on any level
    g = V[fixed, 0]
    b = M @ V[:, 1]
    x = s.solve(b, rtol=1e-10, fixed_values=g, maxiter=60)
    xd = SPDSolver(L + 1e-6 * M, fixed=fixed).solve(b, g)
    assert rel(x, xd) < 1e-8


# ----------------------------------------------------------------------------- interfaces
@pytest.mark.parametrize("kind", KINDS)
def test_preconditioned_cg(kind):
    V, F, mg = hierarchy("sphere", kind)
    A = (cotangent_laplacian_psd(V, F) + 1e-3 * mass_matrix(V, F)).tocsr()
    b = RNG.standard_normal(len(V))
    s = mg.solver(A)
    Mop = s.aspreconditioner()
    u, v = RNG.standard_normal(len(V)), RNG.standard_normal(len(V))
    assert abs(u @ (Mop @ v) - v @ (Mop @ u)) < 1e-10 * abs(u @ (Mop @ v))  # symmetric
    counts = {}
    for name, prec in [("mg", Mop), ("none", None)]:
        it = [0]
        x, info = spla.cg(A, b, rtol=1e-10, M=prec, maxiter=2000,
                          callback=lambda _: it.__setitem__(0, it[0] + 1))
        assert info == 0
        counts[name] = it[0]
        assert rel(x, spla.spsolve(A.tocsc(), b)) < 1e-7
    assert counts["mg"] < 20 < counts["none"]


def test_cycle_iter_streams_the_same_iterates_as_solve():
    V, F, mg = hierarchy("sphere", "closest_point")
    A = (cotangent_laplacian_psd(V, F) + 1e-2 * mass_matrix(V, F)).tocsr()
    b = RNG.standard_normal((len(V), 2))
    s = mg.solver(A)
    cycles = list(s.cycle_iter(b, maxiter=6))
    r = [c.residual for c in cycles]
    assert len(r) == 6 and all(r[i + 1] < r[i] for i in range(5))
    last = cycles[-1].solution()
    x = s.solve(b, rtol=1e-30, maxiter=6)
    np.testing.assert_allclose(last, x, rtol=0, atol=1e-14 * np.abs(x).max())
    assert x.shape == b.shape
    calls = []
    s.solve(b, rtol=1e-8, callback=calls.append)
    assert len(calls) == s.last_info["cycles"] and calls[-1].shape == b.shape


def test_solver_rejects_bad_input():
    V, F, mg = hierarchy("sphere", "closest_point")
    A = cotangent_laplacian_psd(V, F)
    with pytest.raises(ParameterError):
        mg.solver(A[:-1, :-1])
    with pytest.raises(ParameterError):
        mg.solver(A, smoother="jacobi")
    with pytest.raises(ParameterError):
        mg.solver(A).solve(np.ones(5))


@pytest.mark.parametrize("kind", KINDS)
def test_real_mesh_with_boundary_dirichlet_and_progress(kind):
    """camelhead (a disk, 11k vertices): hierarchy with progress reports, Dirichlet solve."""
    from algorithms.mesh import read_mesh
    from tests.conftest import shared_mesh

    m = read_mesh(shared_mesh("camelhead.off"))
    V, F = m.V, m.F
    calls = []
    mg = surface_multigrid(V, F, prolongation=kind, progress=lambda f, msg: calls.append(f))
    assert mg.n_levels >= 3 and len(mg.levels[-1][0]) >= 500
    assert calls and all(0.0 <= c <= 1.0 for c in calls) and calls[-1] == pytest.approx(1.0)
    assert mg.report["prolongation"] == kind and len(mg.report["levels"]) == mg.n_levels
    L = cotangent_laplacian_psd(V, F)
    fixed = boundary_vertices(F)
    g = V[fixed, 2]
    b = mass_matrix(V, F) @ np.ones(len(V))
    s = mg.solver(L, fixed=fixed)
    xd = SPDSolver(L, fixed=fixed).solve(b, g)
    # 14% of camelhead's cotangent weights are negative (obtuse triangles): plain V-cycles slow
    # down there (thesis §8.8: sensitive to triangle quality; PyAMG SA fails too), the
    # V-cycle-preconditioned CG stays fast
    x = s.solve(b, rtol=1e-9, fixed_values=g, maxiter=40, accel="cg")
    assert s.last_info["converged"], s.last_info["cycles"]
    assert rel(x, xd) < 1e-6
    x = s.solve(b, rtol=1e-5, fixed_values=g, maxiter=60)
    assert s.last_info["converged"] and rel(x, xd) < 1e-3
