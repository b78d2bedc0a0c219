"""The one shape of an iteration's state (DESIGN.md §2: iterative methods are generators).

Every iterative method is ``method_iter(V, F, params) -> Iterator[Step]``. The GUI's job runner
streams ``Step.V`` into the viewport, plots ``Step.metrics`` and cancels by not asking for the next
step; a plain ``method(V, F, params)`` calls :func:`run_to_end`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import threading
from typing import Any, Callable, Iterable, Iterator

import numpy as np

__all__ = ["Step", "run_to_end", "Cancelled", "with_progress"]


@dataclass
class Step:
    """State after one iteration.

    Attributes
    ----------
    iteration : 1-based index of the finished iteration (0 = the initial state, if yielded).
    total : the planned number of iterations, or None when the method stops on a tolerance.
    V : (n, 3) float64 current vertex positions (a fresh array the consumer may keep).
    metrics : figures worth plotting (energy, residual, displacement, ...), all plain floats.
    message : a short status line for the user.
    """

    iteration: int
    total: int | None
    V: np.ndarray
    metrics: dict[str, float] = field(default_factory=dict)
    message: str = ""

    @property
    def fraction(self) -> float | None:
        """Progress in [0, 1] when ``total`` is known."""
        if not self.total:
            return None
        return min(1.0, max(0.0, self.iteration / self.total))


def run_to_end(steps: Iterable[Step], callback: Callable[[Step], None] | None = None) -> Step:
    """Consume a step generator and return its last step (raises if it yielded none)."""
    last = None
    for last in steps:
        if callback is not None:
            callback(last)
    if last is None:
        raise RuntimeError("the method produced no iteration")
    return last




class Cancelled(Exception):
    """Raised inside a blocking computation (from its progress callback) once its consumer has
    stopped listening; :func:`with_progress` swallows it."""


def with_progress(work: Callable[[Callable[[float, str], None]], Any], V: np.ndarray,
                  result: dict, *, poll_seconds: float = 0.05) -> Iterator[Step]:
    """Stream a blocking computation that reports progress as Steps, and let it be cancelled.

    ``work(progress)`` runs on a helper thread and calls ``progress(fraction, message)`` now and
    then. Meanwhile this generator yields a Step (iteration = per-mille done, total 1000, ``V``
    unchanged, message) whenever the progress moved. Its return value is stored in
    ``result["value"]``; an exception it raises is re-raised here. When the consumer stops
    iterating (``close()``: a cancelled job), the next ``progress`` call raises
    :class:`Cancelled`, which ends the computation early.
    """
    state = {"fraction": 0.0, "message": "", "error": None}
    stop = threading.Event()
    lock = threading.Lock()

    def progress(fraction: float, message: str = "") -> None:
        if stop.is_set():
            raise Cancelled()
        with lock:
            state["fraction"] = float(fraction)
            state["message"] = message

    def target() -> None:
        try:
            result["value"] = work(progress)
        except Cancelled:
            pass
        except BaseException as exc:  # noqa: BLE001 - handed over to the consumer
            state["error"] = exc

    t = threading.Thread(target=target, name="stylize3d-work", daemon=True)
    t.start()
    last = -1
    try:
        while t.is_alive():
            t.join(poll_seconds)
            with lock:
                frac, msg = state["fraction"], state["message"]
            it = int(round(1000 * min(1.0, max(0.0, frac))))
            if it != last and t.is_alive():
                last = it
                yield Step(it, 1000, V, {}, msg)
    finally:
        stop.set()
    if state["error"] is not None:
        raise state["error"]
