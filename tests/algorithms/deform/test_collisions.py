"""Crossings a deformation made, held back where they are (algorithms.deform.collisions)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from algorithms.deform import collisions
from algorithms.deform.collisions import (ROUNDS, crossings_of, crossings_sentence,
                                          hold_where_crossed)
from algorithms.deform.cubic import mean_l1_of_normals
from algorithms.mesh import read_mesh
from algorithms.mesh.intersections import crossings_away_from, intersecting_pairs_here
from algorithms.steps import Step
from tests.conftest import shared_mesh, unit_square_grid


def _sheets():
    """Two parallel 6 x 6 grids, z = 0 and z = 0.3: (V, F, top vertex ids)."""
    V, F = unit_square_grid(6)
    W = V.copy()
    W[:, 2] = 0.3
    n = len(V)
    return np.vstack([V, W]), np.vstack([F, F + n]), np.arange(n, 2 * n)


def fine_dented_sheets(depth: float = 0.6):
    """Two parallel 20 x 20 grids 0.3 apart, the top one dented ``depth`` down through the
    bottom one: (V0, F, top vertex ids, the dented positions)."""
    V, F = unit_square_grid(20)
    W = V.copy()
    W[:, 2] = 0.3
    V0, F = np.vstack([V, W]), np.vstack([F, F + len(V)])
    top = np.arange(len(V), 2 * len(V))
    return V0, F, top, _dent(V0, top, depth)


def _dent(V0, top, depth):
    """The top sheet with a bump pushed down by ``depth`` around its middle."""
    V = V0.copy()
    r = np.linalg.norm(V0[top, :2] - 0.5, axis=1)
    V[top, 2] -= depth * np.clip(1 - r / 0.35, 0, 1)
    return V


def test_a_dent_pushed_through_the_other_sheet_is_held_where_it_was_before():
    V0, F, top = _sheets()
    depths = np.linspace(0.05, 0.6, 12)  # crosses the bottom sheet (0.3 below) from ~0.3 on
    runs = []

    def steps():
        for i, d in enumerate(depths, 1):
            yield Step(iteration=i, total=None, V=_dent(V0, top, d), metrics={"energy": -d},
                       message=f"it {i}")

    def rerun(ids, targets, V_start):
        runs.append((ids.copy(), targets.copy()))
        V = V_start.copy()
        V[ids] = targets  # a stand-in "deformation" that honours the held vertices
        for k in range(1, 4):
            yield Step(iteration=k, total=None, V=V, metrics={"energy": 0.0}, message=f"r{k}")

    constrained = np.zeros(len(V0), bool)
    constrained[0] = True
    out = list(hold_where_crossed(steps(), V0, F, rerun, constrained=constrained))
    last = out[-1]
    made = crossings_away_from(intersecting_pairs_here(_dent(V0, top, depths[-1]), F), F,
                               intersecting_pairs_here(V0, F))
    assert made > 0
    c = crossings_of(last.metrics)
    assert c == {"checked": True, "made": made, "held_vertices": len(runs[-1][0]), "left": 0}
    assert intersecting_pairs_here(last.V, F).size == 0
    # held vertices come from an earlier iterate that did not cross (the bisection found one)
    ids, targets = runs[0]
    upper = np.isin(ids, top)
    assert not constrained[ids].any() and upper.any() and (~upper).any()
    assert (targets[upper, 2] > 0).all() and (targets[~upper, 2] == 0).all()
    # every Step came through, numbered on from the deformation's last
    assert [s.iteration for s in out[:len(depths)]] == list(range(1, len(depths) + 1))
    assert [s.iteration for s in out[len(depths):]] == [12 + k for k in (1, 2, 3)]
    assert "holding" in out[len(depths) - 1].message
    assert "held where they were before they crossed; none is left" in last.message
    assert last.message == crossings_sentence(last.metrics)


def test_nothing_is_done_or_said_when_nothing_crosses_and_big_meshes_are_not_checked(
        monkeypatch):
    V0, F, top = _sheets()

    def steps():
        yield Step(iteration=1, total=None, V=_dent(V0, top, 0.1), metrics={}, message="done")

    def rerun(ids, targets, V_start):
        raise AssertionError("nothing to hold")

    last = list(hold_where_crossed(steps(), V0, F, rerun))[-1]
    assert last.message == "done" and crossings_of(last.metrics)["made"] == 0
    monkeypatch.setattr(collisions, "CHECK_MAX_FACES", 10)
    last = list(hold_where_crossed(steps(), V0, F, rerun))[-1]
    assert crossings_of(last.metrics) == {"checked": False, "made": None, "held_vertices": 0,
                                          "left": None}
    assert "not checked" in crossings_sentence(last.metrics)


@pytest.mark.parametrize("method", ["Cubic", "Analogies"])
def test_at_its_defaults_camelheads_lips_no_longer_cross_and_the_style_stays(method):
    """camelhead's lips are a few % of an edge apart: the thesis's method (hold off) pushes
    them through each other at λ's default; held, none is left, most of the effect stays."""
    from app.document import MeshState
    from app.recipes import get_recipe

    m = read_mesh(shared_mesh("camelhead.off"))
    recipe = get_recipe(method)
    params = recipe.make_params({})
    state = MeshState.make(m.V, m.F)
    known = intersecting_pairs_here(m.V, m.F)

    def run(p):
        last = None
        for last in recipe.steps(state, p, {}, {}):
            pass
        return last

    plain = run(replace(params, hold_crossings=False))
    made = crossings_away_from(intersecting_pairs_here(plain.V, m.F), m.F, known)
    held = run(params)
    c = crossings_of(held.metrics)
    assert made > 20 and c["made"] == made and c["left"] == 0
    assert crossings_away_from(intersecting_pairs_here(held.V, m.F), m.F, known) == 0
    assert 0 < c["held_vertices"] < 0.05 * len(m.V)
    # the style stays outside the held lips: 90 % of the change of the L1 norm of the normals
    # (measured: 97 % for cubic)
    before = mean_l1_of_normals(m.V, m.F)
    assert before - mean_l1_of_normals(held.V, m.F) > 0.9 * (before - mean_l1_of_normals(plain.V,
                                                                                        m.F))
    if method == "Cubic":  # the pinned vertex stays: the mesh does not shift as a whole
        pin = np.flatnonzero(np.all(plain.V == m.V, axis=1))
        assert pin.size and np.array_equal(held.V[pin], m.V[pin])


def test_rounds_that_do_not_help_go_on_while_the_held_set_grows_and_the_best_is_kept():
    V0, F, top = _sheets()
    deep = _dent(V0, top, 0.6)

    def steps():
        for i, d in enumerate((0.2, 0.6), 1):
            yield Step(iteration=i, total=None, V=_dent(V0, top, d), metrics={}, message="")

    calls = []

    def rerun(ids, targets, V_start):  # a "deformation" that pushes the dent deeper
        calls.append(len(ids))
        yield Step(iteration=1, total=None, V=_dent(V0, top, 0.9), metrics={}, message="")

    out = list(hold_where_crossed(steps(), V0, F, rerun, put_back_rounds=0))
    last = out[-1]
    c = crossings_of(last.metrics)
    assert 1 <= len(calls) <= ROUNDS and calls == sorted(set(calls))  # growing every round
    assert c["held_vertices"] == 0 and c["left"] == c["made"] > 0
    assert np.array_equal(last.V, deep)
    assert last.iteration == 2 + len(calls)  # every iteration counted
    assert "did not reduce them" in last.message
    assert "put_back_vertices" not in last.metrics


def test_where_holding_leaves_crossings_the_surface_is_put_back_towards_the_input_there():
    # issue 38: holding left crossings on the corpus (analogies: pizza 5, ogre 78; cubic: ogre
    # 14); blending the surface around them back towards the input ends them there
    V0, F, top, deep = fine_dented_sheets()

    def steps():
        for i, d in enumerate((0.2, 0.6), 1):
            yield Step(iteration=i, total=None, V=_dent(V0, top, d), metrics={}, message="")

    def rerun(ids, targets, V_start):  # holding does not help
        yield Step(iteration=1, total=None, V=_dent(V0, top, 0.9), metrics={}, message="")

    fixed = np.zeros(len(V0), bool)
    fixed[top[0]] = True                      # held by the caller: never moved
    last = list(hold_where_crossed(steps(), V0, F, rerun, constrained=fixed))[-1]
    c = crossings_of(last.metrics)
    assert c["made"] > 0 and c["left"] == 0 and c["put_back_vertices"] > 0
    known = intersecting_pairs_here(V0, F)
    assert crossings_away_from(intersecting_pairs_here(last.V, F), F, known) == 0
    moved = (last.V != deep).any(axis=1)
    dented = (deep != V0).any(axis=1)
    assert 0 < moved.sum() <= c["put_back_vertices"]
    # around the crossings only: part of the dent keeps the result's positions (measured: 18
    # of its 145 vertices)
    assert not (moved & ~dented).any() and (dented & ~moved).sum() >= 10
    assert not moved[fixed].any()
    # a fixed vertex is never put back: held by the caller in the dent's middle, the crossings
    # there stay (and are said)
    mid = np.zeros(len(V0), bool)
    mid[top[len(top) // 2]] = True
    kept = list(hold_where_crossed(steps(), V0, F, rerun, constrained=mid))[-1]
    assert np.array_equal(kept.V[mid], deep[mid]) and crossings_of(kept.metrics)["left"] > 0
    assert (f"{c['put_back_vertices']} vertices were put back towards the input; none is left"
            in last.message), last.message
    # off, the thesis's result with its crossings (the rounds' best)
    plain = list(hold_where_crossed(steps(), V0, F, rerun, constrained=fixed,
                                    put_back_rounds=0))[-1]
    assert crossings_of(plain.metrics)["left"] > 0


def test_progressive_meshes_finished_on_every_triangle_are_held_too():
    # the finish runs on every triangle, so its crossings are found and held like a direct
    # run's (measured: camelhead through a 5,000-triangle copy, 242 -> 0)
    from app.document import MeshState
    from app.recipes import get_recipe

    m = read_mesh(shared_mesh("camelhead.off"))
    recipe = get_recipe("Cubic")
    last = None
    for last in recipe.steps(MeshState.make(m.V, m.F), recipe.make_params({}),
                             {"progressive": {"target_faces": 5000, "finish": True}}, {}):
        pass
    c = crossings_of(last.metrics)
    assert c["made"] > 20 and c["left"] == 0
    # the panel's closing line still splits the iterations: every held round ran on every
    # triangle
    its = last.metrics["coarse_iterations"] + last.metrics["fine_iterations"]
    assert its == last.iteration
    known = intersecting_pairs_here(m.V, m.F)
    assert crossings_away_from(intersecting_pairs_here(last.V, m.F), m.F, known) == 0


def test_a_put_back_that_would_tear_the_surface_is_not_taken():
    # beast (analogies): the style swung a foot far from where it was; blending it part of the
    # way back stretched edges to 36 times their length and folded triangles. A sheet tilted
    # through the other one as a whole: a blend of part of it back tears, so it is not taken
    from algorithms.deform.collisions import BLEND_STRETCH, _blend_damage, put_back

    V0, F, top, _ = fine_dented_sheets()
    V = V0.copy()
    V[top, 2] = 0.3 - 0.6 * V0[top, 0]          # the top sheet tilted through the bottom one
    from algorithms.mesh.intersections import new_crossings_away_from

    known = intersecting_pairs_here(V0, F)
    bad = new_crossings_away_from(intersecting_pairs_here(V, F), F, known)
    assert len(bad) > 0
    fixed = np.zeros(len(V0), bool)
    # two widenings cover part of the sheet only: every blend tears, none is taken
    X, moved, count = put_back(V, V0, F, known, bad, fixed, rounds=2)
    assert X is V or np.array_equal(X, V)
    assert moved == 0 and count == len(bad)
    # widened further, a blend that ends the crossings without a tear is found: taken
    X, moved, count = put_back(V, V0, F, known, bad, fixed)
    assert count == 0 and moved > 0 and not _blend_damage(V0, V, F)(X)
    # the check itself: the blends tried tear (an edge over BLEND_STRETCH times its lengths)
    damaged = _blend_damage(V0, V, F)
    assert not damaged(V) and not damaged(V0)
    half = V.copy()
    strip = np.isin(np.arange(len(V0)), top) & (np.abs(V0[:, 0] - 0.5) < 0.1)
    half[strip] = V0[strip]                    # a strip of it put back, the rest not
    assert damaged(half) and BLEND_STRETCH == 2.0
