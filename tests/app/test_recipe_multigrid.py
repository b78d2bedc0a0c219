"""The recipes of the Multigrid smoothing panel run headless (app.recipes.run), Qt-free."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from algorithms.errors import ParameterError, Stylize3DError
from algorithms.mesh.operators import cotangent_laplacian, face_areas
from tests.conftest import SAMPLES

MG = {"solver": "multigrid"}


@pytest.fixture(scope="module")
def state():
    from algorithms.mesh import read_mesh
    from app.document import MeshState

    m = read_mesh(str(SAMPLES / "blob.obj"))  # 3,232 vertices: two levels
    return MeshState.make(m.V, m.F)


def roughness(V, F, f):
    return float(f @ (-cotangent_laplacian(V, F) @ f))


def bits(a) -> bytes:
    a = np.asarray(a)
    return a.dtype.str.encode() + str(a.shape).encode() + a.tobytes()


def test_registered_names_commands_and_params():
    from app.recipes import get_recipe, unchanged_result
    from app.recipes import multigrid as mod

    expect = {mod.SMOOTH: ("smooth-data", "DataSmoothingParams"),
              mod.HIERARCHY: ("multigrid-hierarchy", "MultigridParams"),
              mod.COMPARE: ("multigrid-compare", "DataSmoothingParams"),
              mod.FLOW: ("multigrid-flow", "SmoothParams")}
    assert mod.SMOOTH == "Multigrid smoothing"
    for name, (command, params) in expect.items():
        r = get_recipe(command)
        assert r is get_recipe(name) and r.name == name and r.command == command
        assert r.params_cls().__name__ == params
    assert get_recipe(mod.HIERARCHY).result is unchanged_result
    assert get_recipe(mod.COMPARE).result is unchanged_result


def test_noise_is_made_from_the_seed_and_smoothed_into_a_field(state):
    from app.recipes import run
    from app.recipes.multigrid import noisy_field

    opts = {"signal": "noise", "noise": 0.5, "noise_seed": 7}
    res = run("smooth-data", state, MG, opts)
    noisy = res.state.fields["noisy input"]
    np.testing.assert_array_equal(noisy, noisy_field(state.V, state.F, 0.5, 7))
    assert not np.array_equal(noisy, noisy_field(state.V, state.F, 0.5, 8))
    u = res.state.fields["smoothed"]
    assert res.state.V is state.V and u.shape == (len(state.V),)
    assert roughness(state.V, state.F, u) < 0.2 * roughness(state.V, state.F, noisy)
    out = res.outcome
    assert out["solver"] == "multigrid" and out["cycles"] >= 1 and not out["fallback"]
    assert out["relative_residual"] <= 1e-5 and out["warm_start"] is False
    assert not any("second" in k or "time" in k for k in out)
    json.dumps(out)
    # the same input again, with a fresh cache: the same bits
    again = run("Multigrid smoothing", state, MG, dict(opts))
    assert bits(again.state.fields["smoothed"]) == bits(u)
    # the direct solver agrees to the tolerance
    direct = run("smooth-data", state, {"solver": "direct"}, opts)
    assert direct.outcome["solver"] == "direct" and direct.outcome["cycles"] == 0
    np.testing.assert_allclose(direct.state.fields["smoothed"], u, atol=1e-4 * np.abs(u).max())


def test_a_field_of_the_state_is_the_input_and_positions_move_the_shape(state):
    from app.recipes import run

    f = np.linspace(-1.0, 1.0, len(state.V)) ** 3
    st = state.with_field("noisy input", f)
    res = run("smooth-data", st, MG, {"signal": "noise", "noise_seed": 3})
    assert res.state.fields["noisy input"] is st.fields["noisy input"]  # kept, not re-made
    assert "smoothed" in res.state.fields
    pos = run("smooth-data", state, MG, {"signal": "positions"})
    assert pos.state.F is state.F and "smoothed" not in pos.state.fields
    assert np.abs(pos.state.V - state.V).max() > 1e-4
    assert bits(pos.last.V) == bits(pos.state.V)
    assert roughness(pos.state.V, state.F, pos.state.V[:, 0]) < roughness(
        state.V, state.F, state.V[:, 0])


def test_a_field_file_blob_is_the_loaded_signal(state, tmp_path):
    from app.recipes import put_blob_file, run

    path = tmp_path / "values.npy"
    np.save(path, np.sin(7 * state.V[:, 0]))
    ref = put_blob_file(path)
    res = run("smooth-data", state, MG, {"signal": "loaded", "field": ref})
    np.testing.assert_array_equal(res.state.fields["loaded field"], np.sin(7 * state.V[:, 0]))
    assert "smoothed" in res.state.fields
    with pytest.raises(Stylize3DError, match="no input signal"):
        run("smooth-data", state, MG, {"signal": "loaded"})
    with pytest.raises(ParameterError, match="Unknown signal"):
        run("smooth-data", state, MG, {"signal": "colour"})


def test_warm_start_list_gives_the_bits_of_the_slider_sequence(state):
    """A warm-started solve is reproduced from its options alone: ``warm_start`` lists the α's
    it continues from; a fresh cache re-solves them, a warm cache reuses the solution."""
    from app.recipes import run
    from app.recipes.multigrid import warm_start_chain

    f = np.cos(5 * state.V[:, 1]) + 0.3 * np.sin(40 * state.V[:, 0])
    st = state.with_field("noisy input", f)
    cache: dict = {}
    a1, a2, a3 = 1e-3, 2.5e-3, 6e-3
    p1 = {**MG, "alpha": a1}
    first = run("smooth-data", st, p1, {}, cache=cache)
    params2 = first.recipe.make_params({**MG, "alpha": a2})
    assert warm_start_chain(cache, st, params2, {"signal": "noise"}) == [a1]
    live = run("smooth-data", st, params2, {"warm_start": [a1]}, cache=cache)
    assert live.outcome["warm_start"] is True
    fresh = run("smooth-data", st, params2, {"warm_start": [a1]})   # re-solves a1 first
    assert bits(fresh.state.fields["smoothed"]) == bits(live.state.fields["smoothed"])
    cold = run("smooth-data", st, params2, {})
    assert cold.outcome["warm_start"] is False
    # the first guess shows in the bits (within the tolerance): it must be an input
    assert bits(cold.state.fields["smoothed"]) != bits(live.state.fields["smoothed"])
    np.testing.assert_allclose(cold.state.fields["smoothed"], live.state.fields["smoothed"],
                               atol=1e-4)
    # the next α continues the list
    params3 = first.recipe.make_params({**MG, "alpha": a3})
    assert warm_start_chain(cache, st, params3, {"signal": "noise"}) == [a1, a2]
    third = run("smooth-data", st, params3, {"warm_start": [a1, a2]}, cache=cache)
    fresh3 = run("smooth-data", st, params3, {"warm_start": [a1, a2]})
    assert bits(fresh3.state.fields["smoothed"]) == bits(third.state.fields["smoothed"])
    # another input, another energy or the direct solver: no warm start
    other = st.with_field("noisy input", np.array(st.fields["noisy input"]))
    assert warm_start_chain(cache, other, params3, {"signal": "noise"}) == []
    bilap = first.recipe.make_params({**MG, "alpha": a3, "energy": "bilaplacian"})
    assert warm_start_chain(cache, st, bilap, {"signal": "noise"}) == []
    direct = first.recipe.make_params({"solver": "direct", "alpha": a3})
    assert warm_start_chain(cache, st, direct, {"signal": "noise"}) == []
    with pytest.raises(ParameterError, match="warm_start"):
        run("smooth-data", st, params3, {"warm_start": [a1, 2.0]})


def test_warm_start_restarts_cold_past_its_longest_list(state, monkeypatch):
    from app.recipes import multigrid as mod
    from app.recipes import run

    monkeypatch.setattr(mod, "WARM_START_MAX", 1)
    st = state.with_field("noisy input", np.cos(5 * state.V[:, 1]))
    cache: dict = {}
    recipe = run("smooth-data", st, {**MG, "alpha": 1e-3}, {}, cache=cache).recipe
    p = recipe.make_params({**MG, "alpha": 2e-3})
    assert mod.warm_start_chain(cache, st, p, {}) == [1e-3]
    run("smooth-data", st, p, {"warm_start": [1e-3]}, cache=cache)
    assert mod.warm_start_chain(cache, st, p, {}) == []   # two α's: cold again


def test_hierarchy_recipe_outcome_is_deterministic_and_has_no_timings(state):
    from app.recipes import outcome_hash, run

    a = run("multigrid-hierarchy", state, {}, {})
    assert a.state is state and a.last.mg is not None
    out = a.outcome
    assert out["n_levels"] == 2 and out["level_vertices"][0] == len(state.V)
    assert out["level_faces"][0] == len(state.F) and out["prolongation"] == "intrinsic"
    assert not any("second" in k or "time" in k for k in out)
    b = run("multigrid-hierarchy", state, {}, {})
    assert outcome_hash(a.outcome) == outcome_hash(b.outcome)
    c = run("multigrid-hierarchy", state, {"ratio": 0.4}, {})
    assert c.outcome["digest"] != out["digest"]


def test_the_hierarchy_can_come_from_other_positions(state):
    """``hierarchy_positions``: the hierarchy is an input (the panel keeps one per mesh while
    the shape changes); a fresh cache rebuilds that same hierarchy from the blob."""
    from app.recipes import run
    from app.recipes.multigrid import hierarchy_figures, hierarchy_of, hierarchy_option

    cache: dict = {}
    base = run("multigrid-hierarchy", state, {}, {}, cache=cache)
    moved = run("smooth-data", state, MG, {"signal": "positions"}).state
    assert hierarchy_option(cache, state) == {}
    opt = hierarchy_option(cache, moved)
    assert opt["hierarchy_positions"].startswith("blob:")
    assert hierarchy_option(cache, moved) == opt     # one blob per hierarchy
    mg = hierarchy_of(cache, state.F)
    panel_like = run("multigrid-flow", moved, {"step_size": 1e-3, "iterations": 2}, opt,
                     cache=cache)
    assert hierarchy_of(cache, state.F) is mg        # reused, not rebuilt
    fresh_cache: dict = {}
    fresh = run("multigrid-flow", moved, {"step_size": 1e-3, "iterations": 2}, opt,
                cache=fresh_cache)
    assert bits(fresh.state.V) == bits(panel_like.state.V)
    assert hierarchy_figures(hierarchy_of(fresh_cache, moved.F))["digest"] == \
        base.outcome["digest"]
    own = run("multigrid-flow", moved, {"step_size": 1e-3, "iterations": 2}, {})
    assert bits(own.state.V) != bits(fresh.state.V)  # built on the moved shape instead
    np.testing.assert_allclose(own.state.V, fresh.state.V, atol=1e-3)
    from app.recipes import put_blob

    buf = io.BytesIO()
    np.save(buf, np.zeros((5, 3)))
    bad = put_blob(buf.getvalue(), "hierarchy_positions.npy")
    with pytest.raises(ParameterError, match="hierarchy's positions"):
        run("multigrid-flow", moved, {}, {"hierarchy_positions": bad})


def test_flow_shrinks_the_area_deterministically(state):
    from app.recipes import run

    a = run("multigrid-flow", state, {"flow": "cmcf", "step_size": 1e-3, "iterations": 2,
                                      "keep_size": False}, {})
    assert face_areas(a.state.V, state.F).sum() < face_areas(state.V, state.F).sum()
    assert a.outcome["iterations"] == 2 and a.outcome["cycles"] >= 1
    b = run("multigrid-flow", state, {"flow": "cmcf", "step_size": 1e-3, "iterations": 2,
                                      "keep_size": False}, {})
    assert bits(a.state.V) == bits(b.state.V)


def test_compare_outcome_has_both_solutions_and_no_timings(state):
    from app.recipes import outcome_hash, run

    opts = {"signal": "noise", "noise_seed": 11}
    a = run("multigrid-compare", state, {"alpha": 2e-3}, opts)
    assert a.state is state
    out = a.outcome
    assert not any("second" in k or "time" in k for k in out)
    assert out["multigrid_cycles"] >= 1 and not out["multigrid_fallback"]
    assert out["multigrid_solution"].shape == (len(state.V),)
    assert out["max_difference"] == float(np.abs(out["multigrid_solution"]
                                                  - out["direct_solution"]).max())
    assert out["max_difference"] < 1e-3 * np.abs(out["direct_solution"]).max()
    assert set(a.last.info) == {"multigrid", "direct"}
    assert a.last.info["direct"]["seconds"] > 0   # the times are for display only
    b = run("multigrid-compare", state, {"alpha": 2e-3}, opts)
    assert outcome_hash(a.outcome) == outcome_hash(b.outcome)


def test_view_functions(state):
    from app.recipes import run
    from app.recipes.multigrid import coarse_face_colors, coarse_triangle_colors, signal_range

    mg = run("multigrid-hierarchy", state, {}, {}).last.mg
    colors = coarse_face_colors(mg, 1)
    Fc = mg.levels[1][1]
    assert colors.shape == (len(Fc),) and colors.min() >= 0 and colors.max() <= 19
    per_fine = coarse_triangle_colors(mg, 1)
    assert per_fine.shape == (len(state.F),) and per_fine.dtype == np.float64
    assert len(np.unique(per_fine)) > 5
    assert signal_range(None) is None and signal_range(np.array([2.0, -1.0])) == (-1.0, 2.0)
