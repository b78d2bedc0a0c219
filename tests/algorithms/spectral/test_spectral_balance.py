"""The balancing stage after the thesis's NADAM (issue 10): its L-BFGS, its constraint, and what it
is for (the lowest eigenvalues, which the thesis energy leaves too stiff)."""

import numpy as np
import pytest
from scipy.optimize import minimize, rosen, rosen_der

from algorithms.mesh import primitives
from algorithms.spectral import CoarsenParams, coarsen, generalized_eigs
from algorithms.spectral.coarsen import lbfgs_iter
from algorithms.spectral.metrics import spectral_metrics
from algorithms.spectral.operators import build_operator


def test_lbfgs_iter_minimizes_rosenbrock_like_scipy():
    x0 = np.array([-1.2, 1.0, -0.5, 0.8, 1.5])
    steps = list(lbfgs_iter(lambda x: (rosen(x), rosen_der(x)), x0, 500, ftol=1e-15,
                            patience=5))
    ref = minimize(rosen, x0, jac=rosen_der, method="L-BFGS-B", options={"gtol": 1e-10})
    it, f, x = steps[-1]
    assert f < 1e-10 and np.allclose(x, ref.x, atol=1e-4) and np.allclose(x, 1.0, atol=1e-4)
    fs = [s[1] for s in steps]
    assert all(b <= a for a, b in zip(fs, fs[1:]))      # Armijo: f never increases


def test_lbfgs_iter_stays_on_an_affine_constraint():
    """min |x - c|^2 subject to sum(x) = 1, with the gradient projected on the tangent space:
    the iterates stay feasible and reach the orthogonal projection of c."""
    rng = np.random.default_rng(0)
    c = rng.normal(size=20)

    def fun(x):
        g = 2 * (x - c)
        return float(np.sum((x - c) ** 2)), g - g.mean()

    def project(x):
        return x - (x.sum() - 1.0) / len(x)

    x0 = np.full(20, 1 / 20)
    steps = list(lbfgs_iter(fun, x0, 100, project=project))
    assert all(abs(x.sum() - 1) < 1e-12 for _, _, x in steps)
    assert np.allclose(steps[-1][2], project(c), atol=1e-8)


@pytest.fixture(scope="module")
def blob_case():
    V, F = primitives.organic_sample("blob")           # 3,232 vertices
    L, M, _, _ = build_operator(V, F)
    k = 30
    lam, phi = generalized_eigs(L, M, k + 1)
    return L, M, (lam, phi), k


def test_balancing_corrects_the_lowest_eigenvalues(blob_case):
    L, M, eigs, k = blob_case
    lam, phi = eigs
    res = {}
    for name, its in (("thesis", 0), ("balanced", 200)):
        r = coarsen(L, M, 150, k, CoarsenParams(balance_iterations=its),
                    eigs=(lam[:k], phi[:, :k]))
        res[name] = (r, spectral_metrics(L, M, r.L, r.M, r.P, k, fine_eigs=eigs))
    (rt, st), (rb, sb) = res["thesis"], res["balanced"]
    low_t = np.mean(np.abs(st.lam_coarse[1:6] / lam[1:6] - 1))
    low_b = np.mean(np.abs(sb.lam_coarse[1:6] / lam[1:6] - 1))
    assert low_b < 0.6 * low_t
    assert sb.eig_rel_error_mean < 0.7 * st.eig_rel_error_mean
    assert sb.c_diag_score > 0.95 * st.c_diag_score
    # the result keeps the null space (G P 1 = 1) and is PSD
    ones = np.ones(L.shape[0])
    assert np.abs(rb.G @ (rb.P @ ones) - ones).max() < 1e-9
    w = np.linalg.eigvalsh(rb.L.toarray())
    assert w.min() > -1e-9 * w.max()
    assert rb.timings["balancing_iterations"] > 0 and rt.timings.get("balancing") is None


def test_balancing_steps_are_streamed(blob_case):
    """The GUI sees every balancing iteration (so it can plot and cancel)."""
    from algorithms.spectral import coarsen_iter
    L, M, (lam, phi), k = blob_case
    steps = list(coarsen_iter(L, M, 150, k, CoarsenParams(balance_iterations=15),
                              eigs=(lam[:k], phi[:, :k])))
    bal = [s for s in steps if "balanced_energy" in s.metrics]
    assert 1 <= len(bal) <= 15 and steps[-1].done
    assert all(np.isfinite(s.energy) for s in steps)
