"""JobRunner without a viewport: streaming, throttling, cancel, failure, restart."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from algorithms.errors import InvalidMeshError
from algorithms.steps import Step


@pytest.fixture
def runner(qtbot):
    from app.jobs import JobRunner

    r = JobRunner()
    yield r
    r.cancel()
    r.wait(5000)


def slow_steps(n, delay, thread_ids=None):
    def gen():
        if thread_ids is not None:
            thread_ids.append(threading.get_ident())
        for i in range(1, n + 1):
            time.sleep(delay)
            yield Step(i, n, np.full((4, 3), float(i)), {"e": 1.0 / i})
    return gen


def test_runs_off_the_gui_thread_and_finishes(runner, qtbot):
    ids = []
    previews = []
    runner.preview.connect(lambda s: previews.append(s.iteration))
    with qtbot.waitSignal(runner.finished, timeout=10000) as blocker:
        runner.start("demo", slow_steps(10, 0.02, ids))
    assert blocker.args[0].iteration == 10
    assert ids and ids[0] != threading.get_ident()
    assert previews and previews == sorted(previews)
    assert not runner.busy


def test_previews_are_throttled(runner, qtbot):
    previews, history = [], []
    runner.preview.connect(lambda s: previews.append(s.iteration))
    runner.metrics.connect(lambda h: history.extend(it for it, _m in h))
    with qtbot.waitSignal(runner.finished, timeout=20000):
        runner.start("fast", slow_steps(3000, 0.0002))
    # ~0.6 s or more of work at <= ~30 Hz: far fewer previews than steps...
    assert 0 < len(previews) < 200
    # ...but the metrics of every step reach the plots, in order
    assert history == list(range(1, 3001))
    assert previews[-1] == 3000


def test_cancel_stops_early(runner, qtbot):
    with qtbot.waitSignal(runner.preview, timeout=5000):
        runner.start("long", slow_steps(10000, 0.005))
    with qtbot.waitSignal(runner.cancelled, timeout=5000):
        runner.cancel()
    assert not runner.busy


def test_errors_become_plain_messages(runner, qtbot):
    def bad():
        yield Step(1, 2, np.zeros((1, 3)))
        raise InvalidMeshError("The mesh has a hole where it should not.")

    with qtbot.waitSignal(runner.failed, timeout=5000) as blocker:
        runner.start("bad", bad)
    assert blocker.args[0] == "The mesh has a hole where it should not."

    def bug():
        raise KeyError("x")
        yield  # pragma: no cover

    with qtbot.waitSignal(runner.failed, timeout=5000) as blocker:
        runner.start("buggy", bug)
    assert "unexpected error" in blocker.args[0] and "KeyError" in blocker.args[1]


def test_start_while_busy_restarts(runner, qtbot):
    done = []
    runner.finished.connect(lambda s: done.append(s.V[0, 0]))
    with qtbot.waitSignal(runner.preview, timeout=5000):
        runner.start("first", slow_steps(10000, 0.005))
    with qtbot.waitSignal(runner.finished, timeout=10000):
        runner.start("second", slow_steps(3, 0.01))
    assert done == [3.0] and runner.name is None
