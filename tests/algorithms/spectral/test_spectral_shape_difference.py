"""Modified shape difference operator (App. 7.6.4) and difference-driven sampling (7.4.3)."""

import numpy as np
import pytest
import scipy.sparse as sp

from algorithms.errors import ParameterError
from algorithms.mesh import primitives
from algorithms.mesh.operators import mass_matrix
from algorithms.spectral import (difference_driven_clustering, kmedoids_clustering,
                                 modified_shape_difference, shape_difference_operator)
from algorithms.spectral.operators import cotangent_operator


def _sphere():
    V, F = primitives.icosphere(4)                     # 2562 vertices
    return V / np.linalg.norm(V, axis=1)[:, None], F


def _bulge(V, axis_sign=1.0):
    """Inflate the cap z > 0.5 (or z < -0.5): a smooth, area-expanding local deformation."""
    z = axis_sign * V[:, 2]
    s = np.clip((z - 0.3) / 0.4, 0, 1)
    s = s * s * (3 - 2 * s)
    Vd = V * (1 + 0.4 * s)[:, None]
    Vd[:, :2] *= (1 + 0.5 * s)[:, None]
    return Vd


def _density_ratio(V, F, roots, region):
    """(roots per area inside region) / (roots per area outside)."""
    mass = mass_matrix(V, F).diagonal()
    inside = region[roots].sum() / mass[region].sum()
    outside = (~region[roots]).sum() / mass[~region].sum()
    return inside / outside


def test_modified_shape_difference_of_simple_maps():
    k = 6
    assert np.allclose(modified_shape_difference(np.eye(k)), 0)
    Q, _ = np.linalg.qr(np.random.default_rng(0).normal(size=(k, k)))
    assert np.allclose(modified_shape_difference(Q), 0, atol=1e-12)   # isometry: no difference
    # uniform area scaling by s^2: C^T C = s^2 I -> (1 - s^2)^2 I, expansion and shrinking alike
    for s in (0.5, np.sqrt(1.5)):
        A = modified_shape_difference(s * np.eye(k))
        assert np.allclose(A, (1 - s * s) ** 2 * np.eye(k))
    A = modified_shape_difference(np.random.default_rng(1).normal(size=(9, k)))
    assert np.allclose(A, A.T) and np.linalg.eigvalsh(A).min() > -1e-12


def test_shape_difference_operator_is_a_psd_graph_laplacian():
    V, F = primitives.icosphere(3)
    Vd = _bulge(V / np.linalg.norm(V, axis=1)[:, None])
    sd = shape_difference_operator(V / np.linalg.norm(V, axis=1)[:, None], F, Vd, k=20)
    L = sd.L.toarray()
    assert np.allclose(L, L.T)
    assert np.abs(L.sum(axis=1)).max() < 1e-9 * np.abs(L).max()
    assert np.all(L[~np.eye(len(L), dtype=bool)] <= 0)
    # pattern = mesh edges
    Lc, _ = cotangent_operator(V, F)
    assert (abs(sp.csr_matrix(L)) > 0).nnz == (abs(Lc) > 0).nnz
    assert len(sd.edges) == len(sd.edge_values) and len(sd.A_modified) == 1


def test_identical_shapes_fall_back_to_uniform_weights():
    V, F = primitives.icosphere(2)
    sd = shape_difference_operator(V, F, V.copy(), k=10)
    assert np.abs(sd.edge_values).max() < 1e-8
    off = -sd.L.toarray()[~np.eye(len(V), dtype=bool)]
    assert np.allclose(np.unique(off[off > 0]), 1.0)


def test_roots_concentrate_where_the_shapes_differ():
    """Deform one cap: difference-driven k-medoids puts several times more roots per unit area
    there than elsewhere, while the cotangent operator of the reference samples evenly."""
    V, F = _sphere()
    Vd = _bulge(V)
    region = V[:, 2] > 0.5
    cl = difference_driven_clustering(V, F, Vd, 100, k=30, seed=0)
    ratio = _density_ratio(V, F, cl.roots, region)
    L, M = cotangent_operator(V, F)
    base = _density_ratio(V, F, kmedoids_clustering(L, M, 100, seed=0).roots, region)
    print(f"density ratio deformed/rigid: shape difference {ratio:.2f}, cotangent {base:.2f}")
    assert 0.7 < base < 1.4
    assert ratio > 3.0


def test_several_deformations_combine_by_maximum():
    """Fig. 7.24: one shape bulges at the north pole, another at the south pole; sampling
    follows both, and leaves the rigid equator sparse."""
    V, F = _sphere()
    north, south = V[:, 2] > 0.5, V[:, 2] < -0.5
    cl = difference_driven_clustering(V, F, [_bulge(V, 1.0), _bulge(V, -1.0)], 100, k=30)
    assert _density_ratio(V, F, cl.roots, north) > 1.5
    assert _density_ratio(V, F, cl.roots, south) > 1.5
    assert _density_ratio(V, F, cl.roots, north | south) > 3.0


def test_shape_difference_input_errors():
    V, F = primitives.icosphere(2)
    with pytest.raises(ParameterError):
        shape_difference_operator(V, F, V[:-1], k=5)
    with pytest.raises(ParameterError):
        shape_difference_operator(V, F, [], k=5)
    with pytest.raises(ParameterError):
        shape_difference_operator(V, F, V, k=5, floor=0.0)
