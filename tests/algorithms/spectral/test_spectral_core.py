"""Core of spectral coarsening: gradient, projection, operator properties, anisotropy."""

import numpy as np
import pytest
import scipy.sparse as sp

from algorithms.errors import ParameterError
from algorithms.mesh import primitives
from algorithms.mesh.operators import cotangent_laplacian, mass_matrix
from algorithms.spectral import (CoarsenParams, cluster_sparsity, coarsen, energy_and_gradient,
                                 generalized_eigs, kmedoids_clustering, null_space,
                                 project_constraint)


def _sphere():
    V, F = primitives.icosphere(2)
    L = -cotangent_laplacian(V, F)
    M = mass_matrix(V, F)
    return V, F, sp.csr_matrix(L), M


def _setup(m=40, k=10, seed=0):
    V, F, L, M = _sphere()
    mass = M.diagonal()
    lam, phi = generalized_eigs(L, M, k)
    cl = kmedoids_clustering(L, M, m, seed=seed)
    SG = cluster_sparsity(L, cl.K)
    mt = np.asarray(cl.K @ mass).ravel()
    A = cl.P @ ((L @ phi) / mass[:, None])
    B = cl.P @ phi
    return L, M, mass, lam, phi, cl, SG, mt, A, B


def test_sparse_gradient_matches_finite_differences():
    L, M, mass, lam, phi, cl, SG, mt, A, B = _setup()
    rng = np.random.default_rng(1)
    G = SG.copy().astype(float)
    G.data = rng.uniform(0, 1, G.nnz)
    E, g, _ = energy_and_gradient(G, L, A, B, mt)
    idx = rng.choice(G.nnz, 30, replace=False)
    h = 1e-6
    for z in idx:
        Gp, Gm = G.copy(), G.copy()
        Gp.data[z] += h
        Gm.data[z] -= h
        fd = (energy_and_gradient(Gp, L, A, B, mt, gradient=False)[0]
              - energy_and_gradient(Gm, L, A, B, mt, gradient=False)[0]) / (2 * h)
        assert abs(fd - g[z]) <= 1e-5 * max(1.0, np.abs(g).max())


def test_projection_enforces_null_space_constraint():
    L, M, mass, lam, phi, cl, SG, mt, A, B = _setup()
    rng = np.random.default_rng(2)
    G = SG.copy().astype(float)
    G.data = rng.normal(size=G.nnz)
    Phi0 = null_space(L)
    assert Phi0.shape[1] == 1
    Gp = project_constraint(G, cl.P @ Phi0, Phi0)
    assert np.abs(Gp @ (cl.P @ Phi0) - Phi0).max() < 1e-10
    assert Gp.nnz == G.nnz and np.array_equal(Gp.indices, G.indices)
    # general (several null vectors) branch: a second, unrelated constraint vector
    Phi2 = np.c_[Phi0, rng.normal(size=(L.shape[0], 1))]
    G2 = project_constraint(G, cl.P @ Phi2, Phi2)
    assert np.abs(G2 @ (cl.P @ Phi2) - Phi2).max() < 1e-10
    # orthogonality: projecting a feasible G changes nothing
    assert abs(project_constraint(Gp, cl.P @ Phi0, Phi0) - Gp).max() < 1e-12


def test_coarse_operator_symmetric_psd_with_null_space():
    V, F, L, M = _sphere()
    res = coarsen(L, M, 40, 10, CoarsenParams(max_iterations=200))
    Lt = res.L.toarray()
    assert res.L.shape == (40, 40) and res.G.shape == (L.shape[0], 40)
    assert np.abs(Lt - Lt.T).max() < 1e-12 * np.abs(Lt).max()
    w = np.linalg.eigvalsh(Lt)
    assert w.min() > -1e-10 * w.max()
    assert np.abs(Lt @ np.ones(40)).max() < 1e-10 * np.abs(Lt).max()
    assert np.abs(res.G @ (res.P @ np.ones(L.shape[0])) - 1).max() < 1e-10
    # M~ = K M K^T lumps all the mass
    assert np.isclose(res.M.diagonal().sum(), M.diagonal().sum())
    assert res.energy < 0.5 * res.metrics["energy"] / res.metrics["relative_energy"]


def test_iterates_and_energy_decreases():
    from algorithms.spectral import coarsen_iter
    V, F, L, M = _sphere()
    steps = list(coarsen_iter(L, M, 40, 10, CoarsenParams(max_iterations=30)))
    assert steps[-1].done and steps[-1].L is not None
    assert all(not s.done for s in steps[:-1])
    assert steps[-1].energy < steps[0].energy


def test_kmedoids_respects_anisotropy():
    """Strong anisotropy on a flat grid: clusters elongate along the low-resistance direction."""
    from algorithms.spectral.operators import tensor_laplacian
    V, F = primitives.grid(60, 60)
    V = np.c_[V[:, :2], np.zeros(len(V))] if V.shape[1] >= 2 else V
    n = len(V)
    slow = np.tile([1.0, 0.0, 0.0], (len(F), 1))     # diffusion along x is slow
    ratios = {}
    for alpha in (0.0, 30.0):
        L, M = tensor_laplacian(V, F, slow, alpha)
        cl = kmedoids_clustering(L, M, 60, seed=3)
        ex, ey = [], []
        for c in range(60):
            P = V[cl.labels == c]
            ex.append(np.ptp(P[:, 0]))
            ey.append(np.ptp(P[:, 1]))
        ratios[alpha] = np.mean(ey) / np.mean(ex)
    assert 0.7 < ratios[0.0] < 1.4
    assert ratios[30.0] > 2.0, ratios


def test_blockwise_gradient_equals_gathered_gradient():
    from algorithms.spectral.coarsen import _cluster_blocks
    L, M, mass, lam, phi, cl, SG, mt, A, B = _setup()
    G = SG.copy().astype(float)
    G.data = np.random.default_rng(4).uniform(0, 1, G.nnz)
    blocks = _cluster_blocks(G, cl.labels)
    assert blocks is not None
    _, g1, _ = energy_and_gradient(G, L, A, B, mt)
    _, g2, _ = energy_and_gradient(G, L, A, B, mt, blocks=blocks)
    assert np.allclose(g1, g2, rtol=1e-12, atol=1e-12 * np.abs(g1).max())


def test_thesis_step_is_fixed_and_stops_at_first_stall():
    """Thesis 7.3.2: fixed step 0.02, stop after 10 non-improving iterations (lr_decays = 0)."""
    from algorithms.spectral import coarsen_iter
    V, F, L, M = _sphere()
    steps = list(coarsen_iter(L, M, 40, 10, CoarsenParams(max_iterations=400,
                                                          balance_iterations=0)))
    lrs = {s.metrics["learning_rate"] for s in steps[1:-1]}
    assert lrs == {0.02}
    assert steps[-1].timings["iterations"] < 400          # stopped by the stall rule
    E = [s.energy for s in steps[:-1]]
    # the last `patience` iterations did not improve on the best before them
    assert min(E[-10:]) >= min(E[:-10])


def test_authors_schedule_halves_only_after_a_stall():
    from algorithms.spectral import coarsen_iter
    V, F, L, M = _sphere()
    p = CoarsenParams(max_iterations=600, lr_decays=2, balance_iterations=0)
    steps = list(coarsen_iter(L, M, 40, 10, p))[1:-1]
    lrs = [s.metrics["learning_rate"] for s in steps]
    assert set(lrs) <= {0.02, 0.01, 0.005}
    assert lrs == sorted(lrs, reverse=True)
    first_drop = next((i for i, v in enumerate(lrs) if v < 0.02), None)
    if first_drop is not None:   # at least `patience` non-improving steps precede every halving
        E = [s.energy for s in steps]
        assert first_drop >= 10
        assert min(E[first_drop - 10:first_drop]) >= min(E[:first_drop - 10] or [np.inf]) or \
            first_drop == 10


def test_optimizer_is_independent_of_units():
    """Scaling the mesh by 10 scales E by 10^-4 (lam ~ s^-2, Phi ~ s^-1, M~ ~ s^2); the
    normalized NADAM takes the same steps, so G is the same."""
    V, F = primitives.icosphere(2)
    V = V * np.array([1.0, 1.2, 0.8])
    # the thesis's NADAM alone, then with balancing. Every step of both stages is invariant to
    # units, but L-BFGS on this non-convex energy amplifies round-off over its iterations
    # (measured: G differs by 2e-9 after 20, 4e-7 after 50, 8e-4 after 100, 4e-3 after 200), so
    # the balanced run is compared after 50 iterations, tightly
    for balance_iterations in (0, 50):
        out = []
        for s in (1.0, 10.0):
            L = sp.csr_matrix(-cotangent_laplacian(V * s, F))
            M = mass_matrix(V * s, F)
            r = coarsen(L, M, 40, 10, CoarsenParams(max_iterations=60,
                                                    balance_iterations=balance_iterations))
            out.append(r)
        a, b = out
        assert np.array_equal(a.P.indices, b.P.indices)
        tol = 1e-6 if balance_iterations == 0 else 1e-5
        assert np.allclose(a.G.toarray(), b.G.toarray(), atol=tol)
        assert np.isclose(a.energy, b.energy * 1e4, rtol=tol)


def test_initial_interpolations():
    """Both initial G satisfy G P 1 = 1; the smoothed one lies in the pattern S_G (nothing of
    the Jacobi-smoothed K^T is cut off) and starts at a lower energy; K^T is the default."""
    assert CoarsenParams().initial_G == "constant"
    from algorithms.spectral import coarsen_iter
    V, F, L, M = _sphere()
    cl = kmedoids_clustering(L, M, 40, seed=0)
    SG = cluster_sparsity(L, cl.K)
    S = (sp.diags(1.0 / L.diagonal()) @ L).tocsr()
    Ksm = (cl.K.T - 0.5 * (S @ cl.K.T)).tocsr()
    outside = Ksm - Ksm.multiply(SG)
    assert abs(outside).max() == 0 if outside.nnz else True
    E0 = {}
    for init in ("constant", "smoothed"):
        p = CoarsenParams(max_iterations=0, initial_G=init)
        steps = list(coarsen_iter(L, M, 40, 10, p, clustering=cl))
        E0[init] = steps[0].energy
        G = steps[-1].G
        assert np.abs(G @ (steps[-1].P @ np.ones(L.shape[0])) - 1).max() < 1e-10
    assert E0["smoothed"] < E0["constant"]
    with pytest.raises(ParameterError):
        list(coarsen_iter(L, M, 40, 10, CoarsenParams(initial_G="cubic")))
