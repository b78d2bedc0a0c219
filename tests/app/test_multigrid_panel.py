"""The Multigrid smoothing panel with real widgets (pytest-qt)."""

from __future__ import annotations

import time

import numpy as np
from PySide6.QtCore import QTimer

from algorithms.mesh.operators import cotangent_laplacian, face_areas
from tests.conftest import SAMPLES


def roughness(V, F, f):
    """Dirichlet energy of a field (how noisy it is)."""
    return float(f @ (-cotangent_laplacian(V, F) @ f))


def open_panel(window, solver="multigrid"):
    assert window.open_path(SAMPLES / "blob.obj")
    panel = window.panels["Multigrid smoothing"]
    panel.raise_()
    # the default "auto" picks the direct solver on this small mesh; these tests are about
    # the multigrid solver
    live = panel.live_box.isChecked()
    panel.live_box.setChecked(False)  # changing the form must not start a live solve here
    panel.form.set_value("solver", solver)
    panel.live_box.setChecked(live)
    return panel


def test_alpha_slider_resolves_live_without_blocking_the_ui(window, dialogs, qtbot):
    panel = open_panel(window)
    doc = window.document
    panel.new_noise()
    noisy = np.array(doc.state.fields["noisy input"])
    assert window.undo_stack.count() == 1
    assert panel.live_box.isChecked()  # live by default: a slider move re-solves

    ticks = []
    timer = QTimer()
    timer.setInterval(5)
    timer.timeout.connect(lambda: ticks.append(time.perf_counter()))
    timer.start()
    started = []
    window.runner.started.connect(lambda _n: started.append(time.perf_counter()))
    slider = panel.form.editors["alpha"].slider
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        slider.setValue(slider.value() + 150)
    finished = time.perf_counter()
    timer.stop()
    # the event loop kept running while the hierarchy was built and the system solved
    assert started and any(started[0] < t < finished for t in ticks)
    smoothed = np.array(doc.state.fields["smoothed"])
    V, F = doc.V, doc.F
    assert roughness(V, F, smoothed) < 0.2 * roughness(V, F, noisy)
    np.testing.assert_allclose(np.array(window.viewport.poly.point_data["signal"]), smoothed)
    assert "multigrid" in panel.times_label.text() and "levels" in panel.hier_label.text()
    assert len(panel.plot.series.get("relative residual", [])) >= 1
    assert panel.plot.series["relative residual"][-1] <= 1e-5
    # a second move re-solves (hierarchy reused) and merges into the same undo step
    first = smoothed
    with qtbot.waitSignal(window.job_committed, timeout=60000):
        slider.setValue(slider.value() + 150)
    second = np.array(doc.state.fields["smoothed"])
    assert roughness(V, F, second) < roughness(V, F, first)  # larger alpha, smoother
    assert "from the last α" in panel.times_label.text()  # warm-started from the first solve
    assert window.undo_stack.count() == 2
    window.undo_stack.undo()
    assert "smoothed" not in doc.state.fields and "noisy input" in doc.state.fields


def test_positions_signal_smooths_the_shape_and_is_undoable(window, dialogs, qtbot):
    panel = open_panel(window)
    panel.live_box.setChecked(False)
    panel.signal_combo.setCurrentIndex(1)  # vertex positions
    V0 = window.document.V.copy()
    F = window.document.F
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    V1 = window.document.V
    assert np.abs(V1 - V0).max() > 1e-4
    np.testing.assert_allclose(window.viewport.points, V1)
    # positions smoothing lowers the bending of the surface: Dirichlet energy of coordinates
    assert roughness(V1, F, V1[:, 0]) <= roughness(V0, F, V0[:, 0])
    window.undo_stack.undo()
    np.testing.assert_array_equal(window.document.V, V0)


def test_hierarchy_views_solver_comparison_and_flow(window, dialogs, qtbot):
    panel = open_panel(window)
    panel.live_box.setChecked(False)
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.build_button.click()
    mg = panel.hierarchy(window.document.F)
    assert mg is not None and mg.n_levels >= 2
    panel.view_combo.setCurrentIndex(2)  # the coarse level's mesh instead of the fine one
    assert "overlay" in window.viewport.plotter.actors
    assert not window.viewport.mesh_actor.GetVisibility()
    window.panels["Cubic"].raise_()  # another panel: the document's mesh comes back
    qtbot.waitUntil(lambda: window.viewport.mesh_actor.GetVisibility(), timeout=5000)
    assert "overlay" not in window.viewport.plotter.actors
    panel.raise_()
    qtbot.waitUntil(lambda: "overlay" in window.viewport.plotter.actors, timeout=5000)
    panel.view_combo.setCurrentIndex(3)  # fine triangles coloured by coarse triangle
    assert "overlay" not in window.viewport.plotter.actors
    assert window.viewport.mesh_actor.GetVisibility()
    labels = np.array(window.viewport.poly.cell_data["coarse_triangle"])
    assert len(labels) == len(window.document.F) and len(np.unique(labels)) > 5
    from algorithms.mesh.topology import edge_flaps

    from app.recipes.multigrid import coarse_face_colors

    colors = coarse_face_colors(mg, 1)  # neighbouring coarse triangles differ
    EF = edge_flaps(mg.levels[1][1])[2]
    EF = EF[(EF >= 0).all(axis=1)]
    assert (colors[EF[:, 0]] != colors[EF[:, 1]]).all()


    panel.new_noise()
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.compare_button.click()
    text = panel.times_label.text()
    assert "multigrid" in text and "direct" in text and " ms" in text
    assert window.undo_stack.count() == 1  # comparing changes nothing

    V0 = window.document.V.copy()
    F = window.document.F
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.mcf_step_button.click()
    assert face_areas(window.document.V, F).sum() < face_areas(V0, F).sum()
    assert panel.hierarchy(F) is mg  # the flow reused the hierarchy
    window.undo_stack.undo()
    np.testing.assert_array_equal(window.document.V, V0)


def test_bad_field_file_is_refused_and_nothing_changes(window, dialogs, qtbot, tmp_path):
    panel = open_panel(window)
    bad = tmp_path / "values.txt"
    bad.write_text("1\n2\n3\n")
    dialogs.open_paths.append(str(bad))
    assert not panel.load_field_dialog()
    assert dialogs.errors and "has 3 values" in dialogs.errors[0][1]
    assert window.undo_stack.count() == 0 and not window.document.state.fields
    good = tmp_path / "good.npy"
    np.save(good, np.linspace(0, 1, len(window.document.V)))
    dialogs.open_paths.append(str(good))
    assert panel.load_field_dialog()
    assert "loaded field" in window.document.state.fields
    panel.live_box.setChecked(False)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    out = tmp_path / "smoothed.csv"
    dialogs.save_paths.append(str(out))
    assert panel.save_field_dialog()
    assert len(np.loadtxt(out)) == len(window.document.V)


def test_unconverged_multigrid_leaves_the_shape_and_says_so(window, dialogs, qtbot, monkeypatch):
    """Issue 10: a solve that stops before its tolerance never replaces the document. Here the
    iterations are capped at 1 and the direct fallback is said not to fit in memory."""
    import app.recipes.multigrid as recipe_module
    from algorithms.multigrid import applications

    monkeypatch.setattr(recipe_module, "MAX_ITERATIONS", 1)
    monkeypatch.setattr(applications, "direct_fits_in_memory", lambda n, e: (False, 1 << 40))
    panel = open_panel(window)
    panel.live_box.setChecked(False)
    panel.signal_combo.setCurrentIndex(1)  # vertex positions
    V0 = window.document.V.copy()
    count = window.undo_stack.count()
    with qtbot.waitSignal(window.runner.failed, timeout=120000):
        panel.run_button.click()
    qtbot.waitUntil(lambda: "Multigrid stopped" in panel.status_label.text(), timeout=10000)
    assert "Nothing was changed" in panel.status_label.text()
    np.testing.assert_array_equal(window.document.V, V0)
    assert window.undo_stack.count() == count


def test_unconverged_multigrid_falls_back_to_direct_saying_so(window, dialogs, qtbot,
                                                              monkeypatch):
    import app.recipes.multigrid as recipe_module

    monkeypatch.setattr(recipe_module, "MAX_ITERATIONS", 1)
    panel = open_panel(window)
    panel.live_box.setChecked(False)
    panel.signal_combo.setCurrentIndex(1)
    V0 = window.document.V.copy()
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    qtbot.waitUntil(lambda: "direct solver instead" in panel.status_label.text(), timeout=10000)
    V1 = window.document.V
    # the committed shape is the direct solve's (converged) result
    from algorithms.multigrid.applications import DataSmoother
    from algorithms.smoothing import unit_area

    F = window.document.F
    ref, _ = DataSmoother(unit_area(V0, F), F, energy=panel.form.params().energy,
                          solver="direct").smooth(V0, panel.form.params().alpha)
    np.testing.assert_allclose(V1, ref, rtol=1e-8, atol=1e-10)


def test_auto_solver_says_which(window, dialogs, qtbot):
    panel = open_panel(window, solver="auto")
    panel.live_box.setChecked(False)
    panel.signal_combo.setCurrentIndex(1)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    qtbot.waitUntil(lambda: "Auto: direct solver" in panel.status_label.text(), timeout=10000)
    # the residual plot has nothing to show after a direct solve: it says why (issue 24 item 10)
    assert not panel.plot.series and "no V-cycles" in panel.plot.placeholder
    # a multigrid solve plots its V-cycles and drops the note
    panel.form.set_value("solver", "multigrid")
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    qtbot.waitUntil(lambda: bool(panel.plot.series), timeout=10000)
    assert panel.plot.placeholder == ""


# -- the panel's jobs are the recipes of app.recipes.multigrid ------------------------------------
def _bits(a) -> bytes:
    a = np.asarray(a)
    return a.dtype.str.encode() + str(a.shape).encode() + a.tobytes()


def _headless(panel):
    """The panel's last request run headless with a fresh cache (as the study replay does)."""
    import json

    from app.recipes import run

    req = panel.last_request
    json.dumps(req["options"])  # JSON-able, as the study log and the project write them
    return run(req["recipe"], req["input"], req["params"], req["options"], cache={})


def test_smoothing_runs_match_the_headless_recipe_bit_for_bit(window, dialogs, qtbot):
    panel = open_panel(window)
    doc = window.document
    panel.live_box.setChecked(False)
    panel.new_noise()
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    req = panel.last_request
    assert req["recipe"] == "Multigrid smoothing" and req["input"] is not doc.state
    assert req["options"]["signal"] == "noise" and "warm_start" not in req["options"]
    first = _headless(panel)
    assert _bits(first.state.fields["smoothed"]) == _bits(doc.state.fields["smoothed"])
    assert first.state.fields.keys() == doc.state.fields.keys()

    # a live slider move warm-starts from the first solve: the options say from which α
    alpha1 = panel.form.params().alpha
    panel.live_box.setChecked(True)
    slider = panel.form.editors["alpha"].slider
    with qtbot.waitSignal(window.job_committed, timeout=60000):
        slider.setValue(slider.value() + 150)
    assert "from the last α" in panel.times_label.text()
    opts = panel.last_request["options"]
    assert opts["warm_start"] == [alpha1]
    second = _headless(panel)  # re-solves alpha1 first, then continues from it
    assert second.outcome["warm_start"] is True
    assert _bits(second.state.fields["smoothed"]) == _bits(doc.state.fields["smoothed"])


def test_positions_flow_compare_and_build_match_the_headless_recipes(window, dialogs, qtbot):
    from app.recipes import get_recipe, outcome_hash

    panel = open_panel(window)
    doc = window.document
    panel.live_box.setChecked(False)
    panel.signal_combo.setCurrentIndex(1)  # vertex positions
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    assert _bits(_headless(panel).state.V) == _bits(doc.V)
    mg = panel.hierarchy(doc.F)
    # Run again on the smoothed shape: the hierarchy of the first shape is kept, so the
    # positions it was built on are an input of the run
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    assert panel.hierarchy(doc.F) is mg
    assert panel.last_request["options"]["hierarchy_positions"].startswith("blob:")
    assert _bits(_headless(panel).state.V) == _bits(doc.V)

    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.mcf_step_button.click()
    req = panel.last_request
    assert req["recipe"] == "Multigrid smoothing: mean curvature flow"
    assert req["params"].iterations == 1 and req["params"].step_size == panel.dt_spin.value()
    assert window.undo_stack.undoText() == "Mean curvature flow"
    assert _bits(_headless(panel).state.V) == _bits(doc.V)

    for button, name in ((panel.compare_button, "Multigrid smoothing: compare solvers"),
                         (panel.build_button, "Multigrid smoothing: hierarchy")):
        count = window.undo_stack.count()
        with qtbot.waitSignal(window.runner.finished, timeout=120000) as blocker:
            button.click()
        assert panel.last_request["recipe"] == name
        recipe = get_recipe(name)
        mine = recipe.outcome(blocker.args[0])
        assert mine and outcome_hash(mine) == outcome_hash(_headless(panel).outcome)
        assert window.undo_stack.count() == count  # analyses change nothing
    assert panel.status_label.text() == "Hierarchy built."


def test_options_are_json_and_restore_the_widgets(window, dialogs, qtbot):
    import json

    panel = open_panel(window)
    panel.live_box.setChecked(False)
    panel.signal_combo.setCurrentIndex(2)
    panel.noise_spin.setValue(1.25)
    panel.dt_spin.setValue(2.5e-4)
    panel.steps_spin.setValue(17)
    panel._noise_seed = 12345
    opts = panel.job_options()
    assert json.loads(json.dumps(opts)) == opts
    assert opts == {"signal": "loaded", "noise": 1.25, "noise_seed": 12345,
                    "flow_step_size": 2.5e-4, "flow_steps": 17}
    panel.signal_combo.setCurrentIndex(0)
    panel.noise_spin.setValue(0.4)
    panel.dt_spin.setValue(1e-3)
    panel.steps_spin.setValue(10)
    panel._noise_seed = 0
    panel.restore_options(json.loads(json.dumps(opts)))
    assert panel.job_options() == opts
    assert panel.signal_combo.currentIndex() == 2 and panel.steps_spin.value() == 17


def test_new_noise_is_seeded_and_logged(window, dialogs, qtbot):
    from app.recipes.multigrid import noisy_field

    panel = open_panel(window)
    panel.live_box.setChecked(False)
    panel.noise_spin.setValue(0.7)
    doc = window.document
    panel.new_noise()
    seed = panel.job_options()["noise_seed"]
    np.testing.assert_array_equal(doc.state.fields["noisy input"],
                                  noisy_field(doc.V, doc.F, 0.7, seed))
    cmd = window.undo_stack.command(window.undo_stack.count() - 1)
    assert cmd.log_details == {"tool": "new_noise", "field": "noisy input", "noise": 0.7,
                               "seed": seed}
    # a run of the recipe on a mesh without the field makes the same one from the options
    from app.document import MeshState
    from app.recipes import run

    bare = MeshState.make(doc.V, doc.F)
    res = run("smooth-data", bare, {"solver": "direct"}, panel.job_options())
    np.testing.assert_array_equal(res.state.fields["noisy input"],
                                  doc.state.fields["noisy input"])


def test_panel_imports_no_numerical_code():
    """app/panels/multigrid.py takes from algorithms only errors, Params classes, UPPER_CASE
    constants and field file reading/writing; the computing is in app/recipes/multigrid.py."""
    import ast
    from pathlib import Path

    import app.panels.multigrid as mod

    allowed = {"field_file_filter", "read_field", "write_field"}
    tree = ast.parse(Path(mod.__file__).read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            assert not any(a.name.startswith("algorithms") for a in node.names)
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("algorithms"):
            for a in node.names:
                ok = (node.module == "algorithms.errors" or a.name.endswith("Params")
                      or a.name.isupper() or a.name in allowed
                      or (node.module == "algorithms.steps" and a.name == "Step"))
                assert ok, f"{node.module}.{a.name}"


def test_the_noisy_input_is_shown_and_compare_plots_its_cycles(window, dialogs, qtbot):
    """Issue 41 item 4: the noisy input was never shown (undo to "New noisy test field" gave
    an uncoloured mesh), and after Compare solvers the residual plot was blank although the
    panel reported the multigrid solve's cycles."""
    from app.recipes.multigrid import NOISY_FIELD

    panel = open_panel(window)
    panel.live_box.setChecked(False)
    panel.new_noise()
    vp = window.viewport
    noisy = window.document.state.fields[NOISY_FIELD]
    assert vp._field_name == "signal"
    np.testing.assert_allclose(np.asarray(vp.poly.point_data["signal"]), noisy)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    assert panel.view_combo.currentIndex() == 0  # the smoothed field
    smoothed = np.asarray(vp.poly.point_data["signal"]).copy()
    assert roughness(window.document.V, window.document.F, smoothed) < \
        0.5 * roughness(window.document.V, window.document.F, noisy)
    window.undo_stack.undo()  # back to the noisy field: shown in colour, not a plain mesh
    assert window.undo_stack.undoText() == "New noisy test field"
    assert vp._field_name == "signal"
    np.testing.assert_allclose(np.asarray(vp.poly.point_data["signal"]), noisy)
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.compare_button.click()
    res = panel.plot.series.get("relative residual", [])
    assert len(res) >= 2 and res[-1] < res[0], res
    import re

    m = re.search(r"(\d+) cycles?", panel.times_label.text())
    assert m and len(res) == int(m.group(1)), (panel.times_label.text(), len(res))


def test_the_flow_says_where_it_held_the_surface_from_crossing_itself(window, dialogs, qtbot):
    """fertility at a strong flow step (issue 38): the arms would pull through each other; the
    panel's line after the flow says what was held, in the flow's words."""
    from tests.conftest import shared_mesh

    assert window.open_path(shared_mesh("fertility.off"))
    panel = window.panels["Multigrid smoothing"]
    panel.raise_()
    panel.live_box.setChecked(False)
    panel.dt_spin.setValue(1e-4)
    panel.steps_spin.setValue(10)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.mcf_run_button.click()
    text = panel.status_label.text()
    assert text.startswith("Flow applied. Its steps would have pushed the surface through "
                           "itself in "), text
    assert "none is left" in text and text.endswith("Undo with Ctrl+Z."), text
