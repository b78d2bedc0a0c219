"""Recipe "Smooth": implicit Laplacian / mean-curvature flow of the vertex positions."""

from __future__ import annotations

from typing import Iterator

from algorithms.steps import Step
from app.recipes import Recipe, register


def smooth_steps(state, params, options=None, cache=None) -> Iterator[Step]:
    from algorithms.smoothing import smooth_iter

    return smooth_iter(state.V, state.F, params)


def _smooth_params():
    from algorithms.smoothing import SmoothParams

    return SmoothParams


def _smooth_outcome(last: Step) -> dict:
    return {"iterations": int(last.iteration), **{k: float(v) for k, v in last.metrics.items()}}


register(Recipe("Smooth", "smooth", _smooth_params, smooth_steps, outcome=_smooth_outcome))
