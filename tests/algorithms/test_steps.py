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
