"""Issue 25: the multi-colour Gauss-Seidel sweep on Numba's threads (same bits for any thread
count, the NumPy fallback to round-off)."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from algorithms import compiled
from algorithms.mesh import icosphere
from algorithms.mesh.operators import cotangent_laplacian_psd, mass_matrix
from algorithms.multigrid.relaxation import (MultiColorGaussSeidel, compiled_kernels,
                                             set_compiled_kernels)

pytestmark = pytest.mark.skipif(compiled_kernels() is None,
                                reason="compiled kernels unavailable or switched off")


def problem(d):
    V, F = icosphere(5)  # 10242 rows: colours of ~1500 rows, several chunks each
    A = (cotangent_laplacian_psd(V, F) + 1e-2 * mass_matrix(V, F)).tocsr()
    rng = np.random.default_rng(d)
    return A, rng.standard_normal((len(V), d)), rng.standard_normal((len(V), d))


def sweep(mc, x0, b):
    x = x0.copy()
    mc.relax(x, b, 2, backward=False)
    mc.relax(x, b, 2, backward=True)
    return x


@pytest.mark.parametrize("d", [1, 3])
def test_multicolor_threads_same_bits_and_numpy_to_round_off(d):
    import numba

    A, b, x0 = problem(d)
    mc = MultiColorGaussSeidel(A)
    assert mc._kern is not None
    assert np.diff(mc._cptr).max() > 2 * mc._kern.CHUNK  # colours split into several chunks
    previous = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        assert not compiled.use_threads()
        one = sweep(mc, x0, b)
    finally:
        numba.set_num_threads(previous)
    if numba.config.NUMBA_NUM_THREADS >= 2:
        numba.set_num_threads(2)
        try:
            assert compiled.use_threads()
            two = sweep(mc, x0, b)
            two_again = sweep(mc, x0, b)
        finally:
            numba.set_num_threads(previous)
        assert two.tobytes() == one.tobytes()
        assert two_again.tobytes() == two.tobytes()
        out = {}
        t = threading.Thread(target=lambda: out.setdefault("x", sweep(mc, x0, b)))
        t.start()
        t.join(300)
        assert out["x"].tobytes() == one.tobytes()  # from a non-main Python thread
    prev = set_compiled_kernels(False)
    try:
        ref = sweep(MultiColorGaussSeidel(A, mc.coloring), x0, b)
    finally:
        set_compiled_kernels(prev)
    np.testing.assert_allclose(one, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    assert np.abs(one - x0).max() > 1e-3  # the sweeps did something
