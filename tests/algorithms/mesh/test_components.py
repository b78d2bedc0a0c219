"""algorithms.mesh.components against SciPy's csgraph (the same labels, bit for bit)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components as scipy_cc

from algorithms.mesh.components import connected_components


@pytest.mark.parametrize("seed", range(8))
def test_same_labels_as_scipy_on_random_graphs(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 3000))
    m = int(rng.integers(0, 2 * n))
    i, j = rng.integers(0, n, m), rng.integers(0, n, m)
    G = sp.coo_matrix((np.ones(m, np.int8), (i, j)), shape=(n, n))
    want = scipy_cc(G, directed=False)
    for backend in ("numpy", "scipy", "auto"):
        got = connected_components(n, i, j, backend=backend)
        assert got[0] == want[0]
        np.testing.assert_array_equal(got[1], want[1])


def test_long_paths_cycles_and_isolated_nodes():
    n = 20000
    perm = np.random.default_rng(1).permutation(n)  # one long path in a shuffled order
    i, j = perm[:-1], perm[1:]
    assert connected_components(n, i, j, backend="numpy")[0] == 1
    # two cycles and isolated nodes, self loops and repeated edges
    i = np.array([0, 1, 2, 5, 6, 7, 3, 0, 9])
    j = np.array([1, 2, 0, 6, 7, 5, 3, 1, 9])
    count, lab = connected_components(10, i, j, backend="numpy")
    assert count == 6 and list(lab) == [0, 0, 0, 1, 2, 3, 3, 3, 4, 5]
    assert connected_components(0, [], [])[0] == 0
    with pytest.raises(ValueError):
        connected_components(3, [0], [3])


def test_mesh_components_match_on_a_real_mesh():
    from algorithms.mesh import read_mesh
    from tests.conftest import TEST_DATA

    m = read_mesh(TEST_DATA / "wingnut.obj")
    F = m.F
    i = np.concatenate([F[:, 0], F[:, 1], F[:, 2]])
    j = np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
    G = sp.coo_matrix((np.ones(i.size, np.int8), (i, j)), shape=(len(m.V),) * 2)
    want = scipy_cc(G, directed=False)
    got = connected_components(len(m.V), i, j, backend="numpy")
    assert got[0] == want[0]
    np.testing.assert_array_equal(got[1], want[1])


def test_a_bad_backend_is_refused():
    with pytest.raises(ValueError, match="backend"):
        connected_components(3, [0], [1], backend="magic")
