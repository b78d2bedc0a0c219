"""Ours vs QSlim vs AMG on shared meshes (acceptance, thesis Figs. 7.17/7.18), plus the operator
zoo (PSD, null space, the point-cloud Laplacian)."""

import numpy as np
import pytest
import scipy.sparse as sp

from algorithms.errors import ParameterError
from algorithms.mesh import primitives
from algorithms.mesh.io import read_mesh
from algorithms.spectral.compare import compare_coarsenings
from algorithms.spectral.operators import OPERATORS, build_operator
from tests.conftest import shared_mesh


def _assert_ours_wins(name, operator, m, k, alpha=10.0):
    md = read_mesh(shared_mesh(name))
    res = compare_coarsenings(md.V, md.F, operator, m, k, alpha=alpha)
    ours, qs, amg = (res.methods[x].metrics for x in ("ours", "qslim", "amg"))
    print(f"\n{name} {operator} n={res.n} m={m} k={k}\n{res.table()}")
    assert ours["c_diag_score"] > qs["c_diag_score"]
    assert ours["c_diag_score"] > amg["c_diag_score"]
    assert ours["eig_rel_error_mean"] < qs["eig_rel_error_mean"]
    assert ours["eig_rel_error_mean"] < amg["eig_rel_error_mean"]
    return res


# Acceptance (thesis Fig. 7.17): n -> m = 500 with k = 100 where the mesh is big enough, small
# meshes at m = max(n/60, 2k+1), k = 20. With the balancing stage (issue 10) ours also wins the
# mean eigenvalue error on these; before it, the thesis energy alone lost it to QSlim on
# fertility, camelhead and wingnut at 500/100 (the lowest eigenvalues came out 15-35% stiff).
# armadillo at 500/100 (cotangent and anisotropic) is left to benchmarks/spectral.py for time.
@pytest.mark.parametrize("name,m,k", [("fandisk.off", 500, 100),
                                      ("spot_lowres.obj", 41, 20), ("bob.obj", 89, 20)])
def test_ours_beats_qslim_and_amg_cotangent(name, m, k):
    _assert_ours_wins(name, "cotangent", m, k)


# Acceptance (thesis Fig. 7.18): the anisotropic Laplacian (Andreux et al. 2014, parameter 70).
@pytest.mark.parametrize("name", ["bob.obj", "fertility.off"])
def test_ours_beats_qslim_and_amg_anisotropic(name):
    _assert_ours_wins(name, "anisotropic", 500, 100, alpha=70.0)


def test_issue10_targets_on_shared_meshes_open_and_closed():
    """Issue 10: on the shared meshes (closed and open: camelhead and hand_lowres have a
    boundary), ours beats QSlim and AMG on the C-diagonal score on every one and on the mean
    eigenvalue error on at least two thirds. The small meshes run at the panel's size-aware
    default (m = n/8, k = m/3) and at the issue's --m 300 --k 60 where that is still a
    coarsening by 3 or more."""
    from algorithms.spectral.coarsen import suggested_coarse_size
    cases = []
    for name in ("spot_lowres.obj", "hand_lowres.obj"):
        md = read_mesh(shared_mesh(name))
        m = suggested_coarse_size(len(md.V))
        cases.append((name, md, m, round(m / 3)))
    for name in ("wingnut.obj", "fertility.off", "camelhead.off"):
        cases.append((name, read_mesh(shared_mesh(name)), 300, 60))
    c_wins, e_wins, lines = 0, 0, []
    for name, md, m, k in cases:
        res = compare_coarsenings(md.V, md.F, "cotangent", m, k)
        o, q, a = (res.methods[x].metrics for x in ("ours", "qslim", "amg"))
        c_wins += o["c_diag_score"] > max(q["c_diag_score"], a["c_diag_score"])
        e_wins += o["eig_rel_error_mean"] < min(q["eig_rel_error_mean"],
                                                a["eig_rel_error_mean"])
        lines.append(f"{name} m={m} k={k}: C {o['c_diag_score']:.3f}/{q['c_diag_score']:.3f}/"
                     f"{a['c_diag_score']:.3f} eig {o['eig_rel_error_mean']:.3f}/"
                     f"{q['eig_rel_error_mean']:.3f}/{a['eig_rel_error_mean']:.3f}")
    print("\n" + "\n".join(lines))
    assert c_wins == len(cases), lines
    assert e_wins >= 2 * len(cases) / 3, lines


@pytest.mark.parametrize("op", [o for o in OPERATORS if o != "point_cloud"])
def test_operators_are_psd_with_constant_null_space(op):
    V, F = primitives.icosphere(2)
    L, M, p, q = build_operator(V, F, op)
    L = L.toarray()
    assert np.allclose(L, L.T, atol=1e-12 * np.abs(L).max())
    assert np.abs(L @ np.ones(len(V))).max() < 1e-9 * np.abs(L).max()
    w = np.linalg.eigvalsh(L)
    assert w.min() > -1e-9 * w.max()
    assert np.all(M.diagonal() > 0)


def test_anisotropic_operator_coarsens():
    V, F = primitives.icosphere(3)
    res = compare_coarsenings(V, F, "anisotropic", 60, 15, methods=("ours",), alpha=5.0)
    assert res.methods["ours"].metrics["c_diag_score"] > 0.8


def test_point_cloud_operator_missing_package_is_a_parameter_error(monkeypatch):
    import sys
    monkeypatch.setitem(sys.modules, "robust_laplacian", None)   # import now fails
    with pytest.raises(ParameterError):
        build_operator(np.random.default_rng(0).normal(size=(20, 3)), None, "point_cloud")


def test_point_cloud_operator_is_robust_laplacian_psd_with_diagonal_mass():
    import robust_laplacian
    V, _ = primitives.icosphere(3)
    V = V * np.array([1.0, 1.3, 0.7])
    L, M, p, q = build_operator(V, None, "point_cloud")
    L0, M0 = robust_laplacian.point_cloud_laplacian(V)
    # same matrix (the package already returns our PSD sign), mass strictly diagonal
    assert abs(L - sp.csr_matrix(L0)).max() < 1e-12 * abs(L).max()
    assert np.allclose(M.diagonal(), M0.diagonal())
    assert (M - sp.diags(M.diagonal())).nnz == 0 or abs(M - sp.diags(M.diagonal())).max() == 0
    Ld = L.toarray()
    assert np.allclose(Ld, Ld.T, atol=1e-12 * np.abs(Ld).max())
    assert Ld.diagonal().min() > 0
    assert np.abs(Ld @ np.ones(len(V))).max() < 1e-9 * np.abs(Ld).max()
    w = np.linalg.eigvalsh(Ld)
    assert w.min() > -1e-9 * w.max()
    assert np.all(M.diagonal() > 0)
    # the total mass approximates the ellipsoid's area (Knud Thomsen's formula, ~1%)
    a, b, c = 1.0, 1.3, 0.7
    pp = 1.6075
    area = 4 * np.pi * (((a * b) ** pp + (a * c) ** pp + (b * c) ** pp) / 3) ** (1 / pp)
    assert abs(M.diagonal().sum() / area - 1) < 0.05
    with pytest.raises(ParameterError):
        build_operator(np.zeros((3, 3)), None, "point_cloud")


def test_point_cloud_coarsening_beats_amg():
    """Spot's vertices as a point cloud (no faces): ours preserves the spectrum, AMG does not."""
    from algorithms.spectral import coarsen
    from algorithms.spectral.baselines import amg_baseline
    from algorithms.spectral.metrics import spectral_metrics
    md = read_mesh(shared_mesh("spot_lowres.obj"))
    L, M, _, _ = build_operator(md.V, None, "point_cloud")
    r = coarsen(L, M, 41, 20)
    ours = spectral_metrics(L, M, r.L, r.M, r.P, 20)
    a = amg_baseline(L, M, 41)
    amg = spectral_metrics(L, M, a.L, a.M, a.P, 20)
    assert ours.c_diag_score > 0.9 and ours.c_diag_score > amg.c_diag_score
    assert ours.eig_rel_error_mean < amg.eig_rel_error_mean


def test_eigenvector_stage_reports_real_progress_and_can_be_cancelled():
    """Issue 11: the fine operator's eigendecomposition (ARPACK) reports its Lanczos steps,
    gives the same eigenpairs as without a callback, and stops when the callback raises."""
    import numpy as np

    from algorithms.mesh.primitives import icosphere
    from algorithms.spectral.coarsen import generalized_eigs
    from algorithms.spectral.compare import compare_coarsenings_iter
    from algorithms.spectral.operators import build_operator
    from algorithms.steps import Cancelled

    V, F = icosphere(3)                       # 642 vertices: the ARPACK path
    L, M, _, _ = build_operator(V, F, "cotangent")
    seen = []
    lam_p, phi_p = generalized_eigs(L, M, 40, progress=lambda f, m: seen.append((f, m)))
    lam, phi = generalized_eigs(L, M, 40)
    assert np.allclose(lam_p, lam, rtol=1e-10, atol=1e-12)
    assert len(seen) >= 10
    fr = [f for f, _ in seen]
    assert fr == sorted(fr) and 0 <= fr[0] < 0.1 and 0.3 < fr[-1] <= 0.9
    assert "Lanczos step" in seen[-1][1] and "of about" in seen[-1][1]

    def stop(f, m):
        if f > 0.2:
            raise Cancelled()
    with pytest.raises(Cancelled):
        generalized_eigs(L, M, 40, progress=stop)

    # the generator streams the stage (NaN energy, per-mille progress) before the optimizer
    gen = compare_coarsenings_iter(V, F, "cotangent", 150, 40, None, methods=("ours",),
                                   eig_progress=True)
    first = []
    for st in gen:
        first.append(st)
        if not np.isnan(st.energy):
            break
    gen.close()
    stage = [s for s in first if np.isnan(s.energy) and s.stage == "eigenvectors"]
    # then the clustering is announced (issue 24: one progress names every stage)
    assert [s.stage for s in first if np.isnan(s.energy)][len(stage):] == ["clustering"]
    assert first[-1].stage == "optimizing"
    # the stage is announced at once; Lanczos steps follow when it lasts longer than a poll
    assert stage and all(s.total == 1000 for s in stage)
    assert all(s.message.startswith("Eigenvectors of the fine operator") for s in stage)
    assert all("Lanczos step" in s.message for s in stage[1:])
