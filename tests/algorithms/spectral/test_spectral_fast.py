"""Issue 25 / 24 item 1: the fast energy (fixed-pattern sparse products, compiled kernels) is
the thesis's energy and gradient, on every path (Numba parallel / serial, SciPy), and the
eigenpairs are scipy's."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
import scipy.sparse as sp

from algorithms.mesh.primitives import icosphere
from algorithms.spectral.coarsen import (CoarsenParams, cluster_sparsity, coarsen,
                                         energy_and_gradient, generalized_eigs,
                                         kmedoids_clustering, project_constraint)
from algorithms.spectral.operators import build_operator

C = importlib.import_module("algorithms.spectral.coarsen")


@pytest.fixture(scope="module")
def problem():
    V, F = icosphere(3)
    V = V * np.array([1.3, 1.0, 0.8]) * (1 + 0.2 * V[:, :1])
    L, M, _, _ = build_operator(V, F, "cotangent")
    mass = M.diagonal()
    k, m = 20, 80
    lam, phi = generalized_eigs(L, M, k)
    cl = kmedoids_clustering(L, mass, m)
    SG = cluster_sparsity(L, cl.K)
    A = cl.P @ ((L @ phi) / mass[:, None])
    B = cl.P @ phi
    mt = np.asarray(cl.K @ mass).ravel()
    Phi0 = np.ones((L.shape[0], 1))
    B0 = cl.P @ Phi0
    G = SG.copy()
    G.data = np.random.default_rng(3).standard_normal(G.nnz)
    return dict(L=L, M=M, mass=mass, lam=lam, phi=phi, A=A, B=B, mt=mt, B0=B0, Phi0=Phi0, G=G,
                m=m, k=k)


def _ref(p, weights=None):
    A, B = p["A"], p["B"]
    if weights is not None:
        A, B = A * np.sqrt(weights), B * np.sqrt(weights)
    return energy_and_gradient(p["G"], p["L"], A, B, p["mt"])


@pytest.mark.parametrize("path", ["numba", "numba-serial", "numba-no-Z", "scipy"])
def test_fast_energy_and_gradient_are_the_reference(problem, path, monkeypatch):
    p = problem
    if path == "scipy":
        previous = C._KERNELS.set(False)
    else:
        previous = C._KERNELS.set(True)
        if C._KERNELS.get() is None:
            pytest.skip("Numba is not installed")
    try:
        if path == "numba-serial":
            kn = C._KERNELS.get()
            monkeypatch.setattr(kn, "use_threads", lambda: False)
        if path == "numba-no-Z":
            monkeypatch.setattr(C._Energy, "Z_LIMIT", 10)
        ev = C._Energy(p["G"], p["L"], p["A"], p["B"], p["mt"], p["B0"], p["Phi0"])
        E, Ew, g = ev(p["G"].data)
        E1, g1, Lt1 = _ref(p)
        assert E == pytest.approx(E1, rel=1e-12) and Ew == E
        np.testing.assert_allclose(g, g1, rtol=0, atol=1e-11 * np.abs(g1).max())
        w = np.linspace(1.0, 4.0, p["k"])
        E2, Ew2, g2 = ev(p["G"].data, w)
        Ew_ref, gw_ref, _ = _ref(p, w)
        assert E2 == pytest.approx(E1, rel=1e-12)
        assert Ew2 == pytest.approx(Ew_ref, rel=1e-12)
        np.testing.assert_allclose(g2, gw_ref, rtol=0, atol=1e-11 * np.abs(gw_ref).max())
        assert abs(ev.coarse_operator(p["G"].data) - Lt1).max() <= 1e-12 * abs(Lt1).max()
        # the constraint, on the stored values, is project_constraint's
        ref = project_constraint(p["G"], p["B0"], p["Phi0"]).data
        np.testing.assert_allclose(ev.project(p["G"].data), ref, rtol=0, atol=1e-13)
        t = ev.project(p["G"].data, tangent=True)
        Gt = p["G"].copy()
        Gt.data = t
        assert np.abs(Gt @ p["B0"]).max() < 1e-12
    finally:
        C._KERNELS.set(previous)


def test_kernels_give_the_same_bits_serial_and_parallel(problem, monkeypatch):
    kn = pytest.importorskip("algorithms.spectral.kernels")
    p = problem
    G = p["G"]
    ip, ix = G.indptr.astype(np.int64), G.indices.astype(np.int64)
    X = np.random.default_rng(0).standard_normal((G.shape[1], 7))
    Z = np.random.default_rng(1).standard_normal((G.shape[1], G.shape[1]))
    Ys = (p["L"] @ G).tocsr()
    Ys.sort_indices()
    yp, yi = Ys.indptr.astype(np.int64), Ys.indices.astype(np.int64)
    L = p["L"].tocsr()
    out = {}
    for par in (True, False):
        monkeypatch.setattr(kn, "use_threads", lambda par=par: par)
        out[par] = (kn.csr_dense(ip, ix, G.data, X),
                    kn.pattern_dots(ip, ix, Ys @ X, X, Ys @ X, X),
                    kn.spgemm_fixed(L.indptr.astype(np.int64), L.indices.astype(np.int64),
                                    L.data, ip, ix, G.data, yp, yi, G.shape[1]),
                    kn.pattern_rowdot(ip, ix, yp, yi, Ys.data, Z),
                    kn.sym_outer(Z[:, :7], X))
    for a, b in zip(out[True], out[False]):
        assert a.tobytes() == b.tobytes()
    np.testing.assert_allclose(out[True][0], G @ X, atol=1e-12)
    np.testing.assert_allclose(out[True][2], Ys.data, atol=1e-12 * abs(Ys.data).max())
    np.testing.assert_allclose(out[True][4], Z[:, :7] @ X.T + X @ Z[:, :7].T, atol=1e-12)
    YZ = np.asarray(Ys @ Z.T)
    np.testing.assert_allclose(out[True][3], YZ[np.repeat(np.arange(G.shape[0]), np.diff(ip)),
                                               ix], atol=1e-10)


def test_coarsening_is_the_same_with_and_without_compiled_kernels(problem):
    """Same optimizer path (thesis stage and balancing) up to round-off on both code paths."""
    p = problem
    params = CoarsenParams(m=p["m"], k=p["k"], max_iterations=40, balance_iterations=15)
    previous = C._KERNELS.set(False)
    try:
        a = coarsen(p["L"], p["M"], params=params)
    finally:
        C._KERNELS.set(previous)
    b = coarsen(p["L"], p["M"], params=params)
    assert a.iteration == b.iteration
    assert b.energy == pytest.approx(a.energy, rel=1e-6)
    assert abs(a.L - b.L).max() <= 1e-6 * abs(a.L).max()
    assert a.timings["balancing_iterations"] == b.timings["balancing_iterations"] > 0


def test_eigenpairs_agree_with_scipy_eigsh():
    """generalized_eigs (shift-invert ARPACK from a fixed start, M-orthonormalized) against
    scipy.sparse.linalg.eigsh called directly with another start vector, and against the
    dense solver, on a mesh with distinct eigenvalues."""
    import scipy.linalg as sla
    from scipy.sparse.linalg import eigsh

    V, F = icosphere(3)
    V = V * np.array([1.3, 1.0, 0.8]) * (1 + 0.2 * V[:, :1])
    L, M, _, _ = build_operator(V, F, "cotangent")
    k = 30
    lam, phi = generalized_eigs(L, M, k)
    lam_s, phi_s = eigsh(sp.csc_matrix(L), k=k, M=sp.csc_matrix(M), sigma=-1e-6, which="LM",
                         v0=np.random.default_rng(7).standard_normal(L.shape[0]))
    order = np.argsort(lam_s)
    lam_s, phi_s = lam_s[order], phi_s[:, order]
    lam_d = sla.eigh(L.toarray(), M.toarray(), eigvals_only=True)[:k]
    np.testing.assert_allclose(lam, lam_s, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(lam, lam_d, rtol=1e-9, atol=1e-9)
    Mv = M.diagonal()
    np.testing.assert_allclose(phi.T @ (Mv[:, None] * phi), np.eye(k), atol=1e-10)
    overlap = np.abs(np.sum(phi * Mv[:, None] * phi_s, axis=0))
    assert overlap.min() > 1 - 1e-6        # the same eigenvectors up to sign


def test_eigenpairs_of_a_mesh_of_many_parts_are_found_part_by_part():
    """A mesh of 60 loose spheres asking for more pairs than its null space holds (the corpus's
    abominevole: 1,740 parts, 1,750 pairs, 96 s in one ARPACK run, 2.6 s part by part): the
    same eigenvalues as a dense solve of the whole, M-orthonormal eigenvectors, and each
    supported on one part."""
    import scipy.linalg as sla

    rng = np.random.default_rng(0)
    Vs, Fs, off = [], [], 0
    for i in range(60):
        V, F = icosphere(1 if i % 3 else 2)
        Vs.append(V * (0.5 + rng.random()) + [3.0 * i, 0.0, 0.0])
        Fs.append(F + off)
        off += len(V)
    V, F = np.vstack(Vs), np.vstack(Fs)
    L, M, _, _ = build_operator(V, F, "cotangent")
    assert C.EIGS_BY_PART <= 60
    k = 80   # past the null space (60)
    lam, phi = generalized_eigs(L, M, k)
    ref = sla.eigh(L.toarray(), M.toarray(), subset_by_index=[0, k - 1])[0]
    np.testing.assert_allclose(lam, ref, atol=1e-8)
    assert np.abs(phi.T @ (M @ phi) - np.eye(k)).max() < 1e-10
    assert np.abs(L @ phi - (M @ phi) * lam).max() < 1e-8
    part = np.repeat(np.arange(60), [len(v) for v in Vs])
    for j in range(k):
        assert len(np.unique(part[np.abs(phi[:, j]) > 1e-12])) == 1
    # a vertex with no area in one part: the same plain refusal as for a whole operator
    from algorithms.errors import ParameterError

    mass = np.asarray(M.diagonal()).copy()
    mass[5] = 0.0
    with pytest.raises(ParameterError, match="mass matrix"):
        generalized_eigs(L, sp.diags(mass), k)
