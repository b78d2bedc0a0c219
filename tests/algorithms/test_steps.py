"""algorithms.steps.with_progress: streams a blocking computation, passes errors, cancels it."""

import threading
import time

import numpy as np
import pytest

from algorithms.steps import Cancelled, Step, run_to_end, with_progress

V = np.zeros((3, 3))


def test_streams_progress_and_returns_value():
    def work(progress):
        for i in range(5):
            progress(i / 5, f"part {i}")
            time.sleep(0.03)
        return 42

    out = {}
    steps = list(with_progress(work, V, out, poll_seconds=0.01))
    assert out["value"] == 42
    assert steps, "no progress was streamed"
    assert all(isinstance(s, Step) and s.total == 1000 and s.V is V for s in steps)
    its = [s.iteration for s in steps]
    assert its == sorted(its) and len(set(its)) == len(its)
    assert any(s.message.startswith("part") for s in steps)


def test_errors_are_raised_in_the_consumer():
    def work(progress):
        progress(0.5, "half")
        raise ValueError("broken input")

    with pytest.raises(ValueError, match="broken input"):
        run_to_end(with_progress(work, V, {}, poll_seconds=0.01))


def test_closing_the_generator_cancels_the_work():
    calls = []
    ended = threading.Event()

    def work(progress):
        try:
            for i in range(1000):
                progress(i / 1000, "")
                calls.append(i)
                time.sleep(0.005)
        except Cancelled:
            ended.set()
            raise
        return "finished"

    out = {}
    gen = with_progress(work, V, out, poll_seconds=0.01)
    next(gen)
    gen.close()
    assert ended.wait(2.0), "the work did not stop after the consumer went away"
    assert len(calls) < 1000 and "value" not in out


# -- isolated_iter: a generator in a child process ------------------------------------------------
def test_isolated_iter_streams_items_and_returns_the_value():
    from algorithms.spectral.compare import compare_coarsenings_iter
    from algorithms.steps import isolated_iter
    from algorithms.mesh.primitives import icosphere

    V, F = icosphere(2)
    gen = isolated_iter(compare_coarsenings_iter, V, F, "cotangent", 40, 10, None,
                        methods=("ours",))
    items = []
    while True:
        try:
            items.append(next(gen))
        except StopIteration as stop:
            result = stop.value
            break
    assert len(items) >= 2 and items[-1].done
    assert result.n == len(V) and result.m == 40 and "ours" in result.methods
    # the same computation in this process gives the same numbers
    from algorithms.spectral.compare import compare_coarsenings

    here = compare_coarsenings(V, F, "cotangent", 40, 10, None, methods=("ours",))
    assert np.allclose(here.methods["ours"].metrics["c_diag_score"],
                       result.methods["ours"].metrics["c_diag_score"], rtol=0, atol=1e-12)


def test_isolated_iter_reraises_the_childs_error_and_reports_a_dead_child():
    import itertools
    import multiprocessing as mp
    import os

    from algorithms.errors import ParameterError
    from algorithms.mesh.primitives import icosphere
    from algorithms.spectral.compare import compare_coarsenings_iter
    from algorithms.steps import IsolatedProcessError, isolated_iter

    V, F = icosphere(1)
    with pytest.raises(ParameterError, match="need 1 <= k < m < n"):
        list(isolated_iter(compare_coarsenings_iter, V, F, "cotangent", 20, 30))
    with pytest.raises(IsolatedProcessError, match="exit code 3"):
        list(isolated_iter(os._exit, 3))
    # closing the generator (a cancelled job) ends the child
    gen = isolated_iter(itertools.count, 5)
    assert [next(gen) for _ in range(3)] == [5, 6, 7]
    gen.close()
    assert not [p for p in mp.active_children() if p.name == "stylize3d-isolated"]
