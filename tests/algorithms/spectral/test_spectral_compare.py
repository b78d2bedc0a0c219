"""Ours vs QSlim vs AMG on shared meshes (m = max(n/60, 2k+1)), plus the operator zoo."""

import numpy as np
import pytest
import scipy.sparse as sp

from algorithms.errors import ParameterError
from algorithms.mesh import primitives
from algorithms.mesh.io import read_mesh
from algorithms.spectral.compare import compare_coarsenings
from algorithms.spectral.operators import OPERATORS, build_operator
from tests.conftest import shared_mesh

K = 20


@pytest.mark.parametrize("name", ["spot_lowres.obj", "bob.obj"])
def test_ours_beats_qslim_and_amg(name):
    md = read_mesh(shared_mesh(name))
    n = len(md.V)
    m = max(n // 60, 2 * K + 1)
    res = compare_coarsenings(md.V, md.F, "cotangent", m, K)
    ours, qs, amg = (res.methods[x].metrics for x in ("ours", "qslim", "amg"))
    print(f"\n{name} n={n} m={m} k={K}\n{res.table()}")
    assert ours["c_diag_score"] > qs["c_diag_score"]
    assert ours["c_diag_score"] > amg["c_diag_score"]
    assert ours["eig_rel_error_mean"] < qs["eig_rel_error_mean"]
    assert ours["eig_rel_error_mean"] < amg["eig_rel_error_mean"]


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


def test_point_cloud_operator_missing_package_is_a_parameter_error():
    try:
        import robust_laplacian  # noqa: F401
    except ImportError:
        with pytest.raises(ParameterError):
            build_operator(np.zeros((4, 3)), None, "point_cloud")
    else:
        pytest.skip("robust_laplacian is installed")
