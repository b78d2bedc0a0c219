"""l0's step on auto is smaller at the vertices of thin triangles (``Paparazzi.thin_factors``,
``FilterSpec.step_follows_edge``; issue 38): a triangle's normal turns by about a step over its
altitude, so a sliver's vertices take a step in proportion to the sliver's thinness, and the
other vertices the step they took before."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.mesh import icosphere
from algorithms.paparazzi import Paparazzi, PaparazziParams, register_filter, unregister_filter
from algorithms.paparazzi import optimize

GAP = 1e-3          # the sliver's altitude, in the optimizer's frame (the sphere is already in it)


def sphere_with_a_sliver():
    """``icosphere(2)`` (its own frame: the cube of side 2) with a triangle seen by the front
    camera split 1-to-3 by a point ``GAP`` inside its first edge: the triangle on that edge is a
    sliver. Returns V, F, the sliver's three vertices, and an unused vertex's index."""
    V, F = icosphere(2)
    V, F = np.asarray(V, float), np.asarray(F, np.int64)
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    # seen by the +z camera, tilted (a face turned to the camera has no pull: its colour is
    # at its extreme there)
    k = int(np.argmin(np.abs(N[:, 2] / np.linalg.norm(N, axis=1) - 0.7)))
    a, b, c = F[k]
    mid = 0.5 * (V[a] + V[b])
    inward = V[c] - mid
    p = mid + GAP * inward / np.linalg.norm(inward)                 # in the face's plane
    ip = len(V)
    V = np.vstack([V, p, [0.0, 0.0, 0.0]])                          # and one vertex of no face
    F = np.vstack([np.delete(F, k, axis=0), [[a, b, ip], [b, c, ip], [c, a, ip]]])
    return V, F, (a, b, ip), ip + 1


def altitude(V, tri):
    a, b, c = (V[i] for i in tri)
    longest = max(np.linalg.norm(b - c), np.linalg.norm(c - a), np.linalg.norm(a - b))
    return np.linalg.norm(np.cross(b - a, c - a)) / longest


def test_thin_factors_are_the_smallest_altitude_over_an_equilateral_ones():
    V, F, sliver, unused = sphere_with_a_sliver()
    run = Paparazzi(V, F, "l0")
    assert np.allclose(run.V0, V)                   # already in the optimizer's frame
    assert run.edge_length > optimize.ROUGH_EDGE    # coarse: the scale is ROUGH_EDGE's
    f = run.thin_factors(run.V0, run.F0)
    h = altitude(run.V0, sliver)
    assert h == pytest.approx(GAP, rel=0.05)
    assert f[list(sliver)] == pytest.approx(h / (0.5 * np.sqrt(3) * optimize.ROUGH_EDGE))
    others = np.setdiff1d(np.arange(len(V)), list(sliver))
    assert (f[others] == 1.0).all()                 # every other triangle is thick enough
    assert f[unused] == 1.0
    # on a fine mesh (here: ROUGH_EDGE above its mean edge) the scale is the mean edge's
    # equilateral triangle, whose vertices keep the step edge_factor gave them
    import igl

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(optimize, "ROUGH_EDGE", 10.0)
        f = run.thin_factors(run.V0, run.F0)
    e = run.edge_length
    assert f[list(sliver)] == pytest.approx(h / (0.5 * np.sqrt(3) * e))
    alt = igl.doublearea(run.V0, run.F0) / igl.edge_lengths(run.V0, run.F0).max(1)
    expected = np.ones(len(V))
    for k in range(3):
        np.minimum.at(expected, run.F0[:, k], np.minimum(1.0, alt / (0.5 * np.sqrt(3) * e)))
    assert f == pytest.approx(expected)
    # a triangle without area keeps its vertices where they are
    flat = run.V0.copy()
    flat[sliver[2]] = 0.5 * (flat[sliver[0]] + flat[sliver[1]])
    assert (run.thin_factors(flat, run.F0)[list(sliver)] < 1e-12).all()


@pytest.fixture
def redder():
    """A single-view iterative filter asking for more red (normals turned towards +x): every
    visible face is pulled in the first step; ``step_follows_edge`` as l0."""
    name = "_thin_step_redder"
    register_filter(name, kind="iterative", learning_rate=2e-4, single_view=True,
                    step_follows_edge=True)(lambda image, params, ctx: image + [0.1, 0.0, 0.0])
    yield name
    unregister_filter(name)


def test_a_sliver_moves_in_proportion_to_its_thinness_the_rest_as_before(redder):
    V, F, sliver, _ = sphere_with_a_sliver()
    params = dict(iterations=10, monitor_every=0, remesh_every=0, lowest_fallback=False)

    def first_move(**extra):
        run = Paparazzi(V, F, redder, None, PaparazziParams(**params, **extra))
        step = next(run.steps())
        return run, np.abs((step.V - run.center) / run.scale - run.V0)

    run, moved = first_move()
    lr = run.learning_rate
    assert lr == 2e-4                                   # a coarse mesh: the filter's step
    f = run.thin_factors(run.V0, run.F0)
    assert 0.0 < f[sliver[0]] < 0.1
    # NAdam's first step is 1.9 lr along every coordinate with a pull; here times the factor
    pulled = moved.max(1) > 1e-9 * lr                  # (not the frame's rounding)
    assert pulled[list(sliver)].all() and pulled.sum() > 50
    assert (moved <= 1.9 * lr * f[:, None] * (1 + 1e-9)).all()
    assert moved[list(sliver)].max() > 1.9 * lr * f[sliver[0]] * 0.5
    thick = pulled & (f == 1.0)
    assert np.allclose(moved[thick].max(1), 1.9 * lr, rtol=1e-6)
    # a step the user sets is the step, and so is every step with thin_step off: the sliver
    # takes it too
    _, moved_set = first_move(learning_rate=2e-4)
    assert moved_set[list(sliver)].max() == pytest.approx(1.9 * 2e-4, rel=1e-6)
    _, moved_off = first_move(thin_step=False)
    assert moved_off[list(sliver)].max() == pytest.approx(1.9 * 2e-4, rel=1e-6)
    # and the run says how many vertices took a smaller step
    run = Paparazzi(V, F, redder, None, PaparazziParams(**params))
    last = None
    for last in run.steps():
        pass
    assert last.metrics["thin_step_share"] == pytest.approx(np.mean(f < 1.0))
    assert 0 < last.metrics["thin_step_share"] < 0.05
