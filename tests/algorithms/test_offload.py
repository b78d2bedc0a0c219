"""The helper process for compiled calls that keep Python's lock (algorithms.offload).

The desktop app turns it on so that a job's remeshing or exact intersection test does not freeze
the window; these tests check that the calls really run elsewhere, give the same bits, and that
errors and crashes come back as exceptions, not as a hung or dead app. The helper runs
module-level functions by name, so the probes here are standard-library functions.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from algorithms import offload
from algorithms.errors import Stylize3DError
from tests.conftest import TEST_DATA


@pytest.fixture
def helper():
    offload.keep_lock_free(True)
    yield offload
    offload.keep_lock_free(False)


def test_off_by_default_runs_here():
    assert not offload.lock_free()
    assert offload.call(os.getpid) == os.getpid()


def test_on_runs_in_another_process_and_keeps_it(helper):
    pid = helper.call(os.getpid)
    assert pid != os.getpid()
    assert helper.helper_pid() == pid
    assert helper.call(os.getpid) == pid          # one persistent helper, not one per call


def test_exceptions_come_back_with_their_type_and_message(helper):
    with pytest.raises(ValueError, match="math domain error"):
        helper.call(math.sqrt, -1.0)
    assert helper.call(math.sqrt, 4.0) == 2.0      # still serving


def test_a_helper_that_dies_mid_call_is_an_error_and_the_next_call_starts_a_new_one(helper):
    first = helper.call(os.getpid)
    with pytest.raises(Stylize3DError, match="helper process stopped"):
        helper.call(os._exit, 3)
    assert helper.helper_pid() is None
    second = helper.call(os.getpid)
    assert second not in (first, os.getpid())


def test_paparazzi_cores_give_the_same_bits_in_the_helper(helper):
    from algorithms.mesh.io import read_mesh
    from algorithms.paparazzi.optimize import Paparazzi, _intersecting_pairs

    mesh = read_mesh(TEST_DATA / "spot_lowres.obj")
    pz = Paparazzi(mesh.V, mesh.F)
    V, F = pz.V0, pz.F0
    free = pz._free_mask(F, len(V))
    free[:5] = False                                # a few fixed vertices: the reordering path
    rng = np.random.default_rng(0)
    V = V + 0.3 * pz.edge_length * rng.standard_normal(V.shape)
    from algorithms.paparazzi.optimize import _intersecting_pairs_touching

    some = np.arange(0, len(F), 3)
    there = (pz._remesh(V, F, free), _intersecting_pairs(V, F),
             _intersecting_pairs_touching(V, F, some))
    assert helper.helper_pid() is not None
    helper.keep_lock_free(False)
    here = (pz._remesh(V, F, free), _intersecting_pairs(V, F),
            _intersecting_pairs_touching(V, F, some))
    assert len(there[2]) > 0
    np.testing.assert_array_equal(np.unique(np.sort(there[2], axis=1), axis=0),
                                  np.unique(np.sort(here[2], axis=1), axis=0))
    assert len(there[1]) > 0                       # the noise made it cross itself somewhere
    np.testing.assert_array_equal(there[0][0], here[0][0])
    np.testing.assert_array_equal(there[0][1], here[0][1])
    # libigl reports the pairs in a thread-dependent order (in one process too): same set
    np.testing.assert_array_equal(np.unique(np.sort(there[1], axis=1), axis=0),
                                  np.unique(np.sort(here[1], axis=1), axis=0))


def test_smoothing_refactorizations_release_the_lock_in_the_app_same_result(helper):
    from algorithms.linalg import SPDSolver
    from algorithms.mesh.io import read_mesh
    from algorithms.smoothing import SmoothParams, smooth

    import scipy.sparse as sp

    A = sp.diags([2.0, 3.0, 4.0]).tocsc()
    assert SPDSolver(A, backend="auto-once").backend == "superlu"
    assert SPDSolver(A, backend="auto").backend != "superlu" or not _has_cholmod()
    mesh = read_mesh(TEST_DATA / "spot_lowres.obj")
    in_app = smooth(mesh.V, mesh.F, SmoothParams(iterations=3))
    helper.keep_lock_free(False)
    # the command line, batch and a study replay use the same solver as the app: the same
    # bits (issue 41: the replay of an app's Smooth run differed by 1.5e-15 of the diagonal
    # when it factored with CHOLMOD and reported a mismatch)
    assert SPDSolver(A, backend="auto-once").backend == "superlu"
    elsewhere = smooth(mesh.V, mesh.F, SmoothParams(iterations=3))
    np.testing.assert_array_equal(in_app, elsewhere)


def _has_cholmod() -> bool:
    from algorithms.linalg import cholmod_available

    return cholmod_available()
