"""Monitor views filtered side by side (``FilterSpec.parallel_views``): the same numbers as one
view after the other, in this process and across fresh processes with one or two threads; only
the filters that allow it; a failing filter still stops the run with its message."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

from algorithms.errors import Stylize3DError
from algorithms.mesh import icosphere, read_mesh
from algorithms.paparazzi import FilterFailed, Paparazzi, PaparazziParams, get_filter
from algorithms.paparazzi.filters import _quiet_empty_cluster_warning
from tests.conftest import ROOT

numba = pytest.importorskip("numba")


class _threads:
    """Numba's thread count for this Python thread within the block (restored after)."""

    def __init__(self, n):
        self.n = n

    def __enter__(self):
        self.before = numba.get_num_threads()
        numba.set_num_threads(min(self.n, numba.config.NUMBA_NUM_THREADS))

    def __exit__(self, *exc):
        numba.set_num_threads(self.before)


def _bumpy():
    V, F = icosphere(3)
    rng = np.random.default_rng(3)
    return V * (1.0 + 0.03 * rng.standard_normal((len(V), 1))), F


needs_two = pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2,
                               reason="Numba has one thread on this machine")


@needs_two
@pytest.mark.parametrize("name", ["l0", "slic", "guided", "quantize"])
def test_the_views_side_by_side_give_the_same_bits(name):
    V, F = _bumpy()
    spec = get_filter(name)
    run = Paparazzi(V, F, spec, spec.params(), PaparazziParams(resolution=64))
    with _threads(1):
        assert run.view_threads(16) == 1
        e1, g1 = run.monitor_pull(run.V0, run.F0, renders=(r1 := []))
    with _threads(2):
        assert run.view_threads(16) == 2
        e2, g2 = run.monitor_pull(run.V0, run.F0, renders=(r2 := []))
        assert run.monitor_energy(run.V0, run.F0) == e2
    assert e1 == e2 and e1 > 0
    assert np.array_equal(g1, g2) and np.abs(g1).max() > 0
    # the renderings come back in the views' order
    assert all(np.array_equal(a.image, b.image) for a, b in zip(r1, r2, strict=True))


def test_only_filters_that_allow_it_run_side_by_side():
    V, F = _bumpy()
    with _threads(2):
        ns = get_filter("neural-style")
        assert not ns.parallel_views
        plain = dataclasses.replace(get_filter("l0"), name="l0-serial", parallel_views=False)
        assert Paparazzi(V, F, plain, plain.params(), PaparazziParams()).view_threads(16) == 1
        assert Paparazzi(V, F, ns, ns.params(), PaparazziParams()).view_threads(16) == 1
        l0 = get_filter("l0")
        run = Paparazzi(V, F, l0, l0.params(), PaparazziParams())
        assert run.view_threads(1) == 1               # one view: nothing to share
        assert run.view_threads(16) == min(2, numba.config.NUMBA_NUM_THREADS)
    # every built-in image filter allows it (they keep no state between pictures)
    for name in ("guided", "quantize", "slic", "l0", "target-image", "target-mesh"):
        assert get_filter(name).parallel_views, name


@needs_two
def test_a_filter_that_fails_in_a_helper_thread_still_says_why():
    calls = []

    def broken(image, params, ctx):
        calls.append(1)
        if len(calls) > 3:
            raise ValueError("no good at this view")
        return image * 0.5

    spec = dataclasses.replace(get_filter("l0"), name="broken", function=broken,
                               parallel_views=True, min_change=0.0)
    V, F = _bumpy()
    run = Paparazzi(V, F, spec, spec.params(), PaparazziParams(resolution=32))
    with _threads(2), pytest.raises(FilterFailed, match="no good at this view") as err:
        run.monitor_energy(run.V0, run.F0)
    assert isinstance(err.value, Stylize3DError)


def test_slics_warning_filter_is_installed_once_and_narrowly():
    with warnings.catch_warnings():
        warnings.resetwarnings()
        _quiet_empty_cluster_warning()
        _quiet_empty_cluster_warning()
        mine = [f for f in warnings.filters if f[1] is not None
                and f[1].pattern == "One of the clusters is empty"]
        assert len(mine) == 1 and mine[0][0] == "ignore" and mine[0][2] is UserWarning
        assert len(warnings.filters) == 1                     # nothing else was touched
        with pytest.warns(UserWarning, match="something else"):
            warnings.warn("something else", UserWarning)


_RUN = """
import sys, numpy as np
from algorithms.mesh import icosphere, write_mesh
from algorithms.paparazzi import Paparazzi, PaparazziParams, paparazzi
V, F = icosphere(3)
V = V * (1.0 + 0.03 * np.random.default_rng(3).standard_normal((len(V), 1)))
params = PaparazziParams(iterations=40, remesh_every=20, monitor_every=10, resolution=64)
print(Paparazzi(V, F, sys.argv[1], params=params).view_threads(16))
out = paparazzi(V, F, sys.argv[1], params=params)
write_mesh(sys.argv[2], *out)
"""


@needs_two
def test_fresh_processes_with_one_or_two_threads_write_the_same_mesh(tmp_path):
    outs = []
    for n in ("1", "2"):
        env = {k: v for k, v in os.environ.items()
               if k not in ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS")}
        env["OMP_NUM_THREADS"] = n
        path = tmp_path / f"out{n}.obj"
        res = subprocess.run([sys.executable, "-c", _RUN, "l0", str(path)], cwd=ROOT, env=env,
                             capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, res.stderr[-2000:]
        assert res.stdout.split()[-1] == n           # views side by side with two threads
        outs.append(read_mesh(str(path)))
    assert np.array_equal(outs[0].F, outs[1].F)
    assert np.array_equal(outs[0].V, outs[1].V)
    assert path.read_bytes() == (tmp_path / "out1.obj").read_bytes()
