"""Applications: data smoothing with a cheap change of alpha (App. 8.9.5) and mean curvature flow."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.errors import ParameterError
from algorithms.multigrid import galerkin_matrices
from algorithms.multigrid.applications import DataSmoother, smoothness_matrix
from tests.algorithms.multigrid.mg_helpers import KINDS, hierarchy

RNG = np.random.default_rng(11)


def rel(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("energy,accel,precond", [("dirichlet", None, "galerkin"),
                                                  ("dirichlet", "cg", "galerkin"),
                                                  ("bilaplacian", "cg", "galerkin"),
                                                  ("bilaplacian", None, "factored")])
def test_data_smoother_alpha_changes_equal_direct(kind, energy, accel, precond):
    V, F, mg = hierarchy("sphere", kind)
    f = np.column_stack([V[:, 2], V[:, 0]]) + 0.2 * RNG.standard_normal((len(V), 2))
    ds = DataSmoother(V, F, energy=energy, mg=mg)
    dd = DataSmoother(V, F, energy=energy, solver="direct")
    for alpha in (1e-3, 0.05, 0.5):
        u, info = ds.smooth(f, alpha, rtol=1e-10, maxiter=200, accel=accel,
                            preconditioner=precond)
        ud, _ = dd.smooth(f, alpha)
        assert info["converged"] and u.shape == f.shape
        assert rel(u, ud) < 1e-6, (alpha, info["cycles"])
        assert info["seconds"] > 0 and len(info["residuals"]) == info["cycles"] + 1
        # the precomputed split (Eq. 8.17) equals the Galerkin matrices of the assembled system
        s = ds.last_solver
        if precond == "factored" and energy == "bilaplacian":
            a, c = np.sqrt(alpha), np.sqrt(1 - alpha)
            ref = galerkin_matrices(a * ds.L + c * ds.M, mg.prolongations)
        else:
            ref = galerkin_matrices(ds.system(alpha), mg.prolongations)
        for Ah, Rh in zip(s.matrices, ref):
            assert abs(Ah - Rh).max() <= 1e-12 * abs(Rh).max()
    # smoothing reduces the noise: the result is closer to the clean signal than f
    clean = np.column_stack([V[:, 2], V[:, 0]])
    u, _ = ds.smooth(f, 0.05 if energy == "dirichlet" else 1e-3, rtol=1e-8, accel=accel,
                     preconditioner=precond)
    assert rel(u, clean) < 0.5 * rel(f, clean)


def test_factored_bilaplacian_needs_fewer_iterations_than_galerkin():
    V, F, mg = hierarchy("sphere", KINDS[-1])
    ds = DataSmoother(V, F, energy="bilaplacian", mg=mg)
    f = V[:, 1] + 0.1 * RNG.standard_normal(len(V))
    its = {}
    for pc in ("factored", "galerkin"):
        u, info = ds.smooth(f, 0.5, rtol=1e-9, maxiter=300, accel="cg", preconditioner=pc)
        assert info["converged"] and info["method"] == pc
        its[pc] = info["cycles"]
    assert its["factored"] < its["galerkin"], its
    with pytest.raises(ParameterError):
        DataSmoother(V, F, mg=mg).smooth(f, 0.5, preconditioner="ilu")


def test_data_smoother_scalar_and_errors():
    V, F, mg = hierarchy("sphere", "closest_point")
    ds = DataSmoother(V, F, mg=mg, smoother="multicolor")
    f = V[:, 0] + 0.1 * RNG.standard_normal(len(V))
    u, info = ds.smooth(f, 0.1)
    assert u.shape == f.shape and info["cycles"] >= 1
    with pytest.raises(ParameterError):
        ds.smooth(f, 1.5)
    with pytest.raises(ParameterError):
        ds.smooth(f[:-1], 0.1)
    with pytest.raises(ParameterError):
        DataSmoother(V, F, energy="tv")
    with pytest.raises(ParameterError):
        DataSmoother(V, F, solver="jacobi")


def test_hessian_energy_multigrid_matches_direct():
    """The squared Hessian energy (Stein et al. 2020, through gpytoolbox): symmetric, constants
    in its null space, and V-cycle-preconditioned CG reaches the direct solution."""
    V, F, mg = hierarchy("sphere", "intrinsic")
    f = V[:, 0] + 0.05 * RNG.standard_normal(len(V))
    Q = smoothness_matrix(V, F, "hessian")
    assert abs(Q - Q.T).max() < 1e-10 * abs(Q).max()
    assert np.abs(Q @ np.ones(len(V))).max() < 1e-8 * abs(Q).max()
    assert f @ (Q @ f) > 0
    u, info = DataSmoother(V, F, energy="hessian", mg=mg).smooth(f, 0.01, accel="cg",
                                                                   rtol=1e-10, maxiter=300)
    ud, _ = DataSmoother(V, F, energy="hessian", solver="direct").smooth(f, 0.01)
    assert info["converged"]
    assert np.abs(u - ud).max() < 1e-7 * np.abs(ud).max()


def test_params_describe_and_validate():
    from algorithms.multigrid.params import DataSmoothingParams, MultigridParams
    from algorithms.params import describe, validate_params

    names = [s.name for s in describe(MultigridParams)]
    assert names[:4] == ["ratio", "min_vertices", "strategy", "prolongation"]
    p = MultigridParams()
    assert (p.ratio, p.min_vertices, p.presmooth, p.postsmooth) == (0.25, 500, 2, 2)
    validate_params(DataSmoothingParams())
    with pytest.raises(ParameterError):
        validate_params(MultigridParams(smoother="jacobi"))
