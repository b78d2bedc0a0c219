"""Recipe "Smooth": implicit Laplacian / mean-curvature flow of the vertex positions."""

from __future__ import annotations

from typing import Iterator

from algorithms.steps import Step
from app.recipes import VISIBLE_MOVE, Recipe, register


def smooth_steps(state, params, options=None, cache=None) -> Iterator[Step]:
    from algorithms.smoothing import smooth_iter

    return smooth_iter(state.V, state.F, params)


def change_advice(last: Step, params, flags: bool = False) -> str:
    """What to tell a user whose run barely changed the shape (empty when it visibly did):
    the input was already smooth at this step size, and how to smooth more -- the panel's
    setting names, or with ``flags`` the command line's (``--step-size 1e-04``)."""
    moved = float(last.metrics.get("moved", 1.0))
    if moved >= VISIBLE_MOVE:
        return ""
    if moved < 1e-9:
        # a flat surface with its border fixed (a 2-D drawing): the cotangent Laplacian of
        # positions in a plane is zero inside it, so no step size moves anything
        return ("Nothing moved: the surface is flat with a fixed border (or every point is "
                "fixed), which these flows leave as it is.")
    stronger = min(1.0, float(params.step_size) * 10.0)
    raise_it = (f"Raise --step-size (e.g. --step-size {stronger:.0e}) or --iterations" if flags
                else f"Raise Step size (e.g. to {stronger:.0e}) or Iterations")
    return (f"The shape changed little (at most {100 * moved:.2g} % of its size): it is already "
            f"smooth at this step size. {raise_it} to smooth more.")


def _smooth_params():
    from algorithms.smoothing import SmoothParams

    return SmoothParams


def _smooth_outcome(last: Step) -> dict:
    return {"iterations": int(last.iteration), **{k: float(v) for k, v in last.metrics.items()}}


register(Recipe("Smooth", "smooth", _smooth_params, smooth_steps, outcome=_smooth_outcome))
