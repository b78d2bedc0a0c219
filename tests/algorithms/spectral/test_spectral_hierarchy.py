"""Recursive multilevel spectral coarsening (thesis Fig. 7.16)."""

import numpy as np
import pytest

from algorithms.errors import ParameterError
from algorithms.mesh import primitives
from algorithms.mesh.io import read_mesh
from algorithms.spectral import (CoarsenParams, coarsen_hierarchy, generalized_eigs,
                                 spectral_metrics)
from algorithms.spectral.operators import cotangent_operator
from tests.conftest import shared_mesh


def test_hierarchy_levels_are_psd_keep_null_space_and_track_the_spectrum():
    md = read_mesh(shared_mesh("spot_lowres.obj"))
    L, M = cotangent_operator(md.V, md.F)
    n = L.shape[0]
    levels = coarsen_hierarchy(L, M, [250, 80], CoarsenParams(), k=[30, 15])
    assert [lv.m for lv in levels] == [250, 80]
    lam, phi = generalized_eigs(L, M, 11)
    prev = n
    # measured: level 1 C diag 0.997, mean error 0.074; level 2 0.986, 0.213 (errors compound:
    # each level is fitted to the previous level's slightly stiff low spectrum)
    max_err = {250: 0.15, 80: 0.35}
    for lv in levels:
        Lt = lv.L.toarray()
        scale = np.abs(Lt).max()
        assert lv.L.shape == (lv.m, lv.m) and lv.G.shape == (prev, lv.m)
        assert np.abs(Lt - Lt.T).max() <= 1e-12 * scale                  # symmetric
        w = np.linalg.eigvalsh(Lt)
        assert w.min() > -1e-10 * w.max()                                  # PSD
        assert np.abs(Lt @ np.ones(lv.m)).max() < 1e-10 * scale            # constants in kernel
        assert np.sum(w < 1e-10 * w.max()) == 1                            # and nothing else
        assert np.isclose(lv.M.diagonal().sum(), M.diagonal().sum())       # mass is lumped
        # P_total selects lv.m distinct fine nodes
        assert lv.P_total.shape == (lv.m, n) and lv.P_total.nnz == lv.m
        assert len(np.unique(lv.P_total.indices)) == lv.m
        met = spectral_metrics(L, M, lv.L, lv.M, lv.P_total, 10, fine_eigs=(lam, phi))
        assert met.c_diag_score > 0.95, met.c_diag_score
        assert met.eig_rel_error_mean < max_err[lv.m], met.eig_rel_error_mean
        prev = lv.m


def test_hierarchy_callback_and_errors():
    V, F = primitives.icosphere(2)
    L, M = cotangent_operator(V, F)
    seen = []
    levels = coarsen_hierarchy(L, M, [60, 20], CoarsenParams(max_iterations=5), k=5,
                               callback=lambda i, s: seen.append(i))
    assert len(levels) == 2 and set(seen) == {0, 1}
    with pytest.raises(ParameterError):
        coarsen_hierarchy(L, M, [60, 80])
    with pytest.raises(ParameterError):
        coarsen_hierarchy(L, M, [60, 20], k=[5])
    with pytest.raises(ParameterError):
        coarsen_hierarchy(L, M, [])
