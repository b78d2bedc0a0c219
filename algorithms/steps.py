"""The one shape of an iteration's state (DESIGN.md §2: iterative methods are generators).

Every iterative method is ``method_iter(V, F, params) -> Iterator[Step]``. The GUI's job runner
streams ``Step.V`` into the viewport, plots ``Step.metrics`` and cancels by not asking for the next
step; a plain ``method(V, F, params)`` calls :func:`run_to_end`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterable, Iterator

import numpy as np

__all__ = ["Step", "run_to_end"]


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


