"""The Analogies panel with real widgets and the real viewport."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPoint, Qt

from algorithms.mesh.operators import vertex_normals
from tests.conftest import SAMPLES


def open_panel(window):
    assert window.open_path(SAMPLES / "blob.obj")
    panel = window.panels["Analogies"]
    panel.live_box.setChecked(False)
    panel.form.editors["max_iterations"].setValue(20)
    return panel


def test_gallery_run_is_one_undoable_command_and_reduces_angles(window, dialogs, qtbot):
    panel = open_panel(window)
    V0 = window.document.V.copy()
    items = {panel.gallery.item(i).data(256): i for i in range(panel.gallery.count())}
    assert {"cube", "tetrahedron", "hexagonal_prism", "capture sphere"} <= set(items)
    assert not panel.gallery.item(items["cube"]).icon().isNull()  # thumbnails ship
    panel.gallery.setCurrentRow(items["octahedron"])
    assert "octahedron" in panel.style_label.text()
    with qtbot.waitSignal(window.runner.finished, timeout=120000) as blocker:
        panel.run_button.click()
    m = blocker.args[0].metrics
    hist = panel.plot.series["mean_angle_to_targets"]
    assert hist[-1] < hist[0] and m["mean_angle_to_targets"] == hist[-1]
    assert window.undo_stack.undoText() == "Analogies"
    text = panel.status_label.text()   # a shape that changed says nothing of the kind
    assert "Done" in text and "did not change" not in text and "changed little" not in text
    window.undo_stack.undo()
    np.testing.assert_array_equal(window.document.V, V0)


def test_views_colour_by_angle_and_curvature(window, dialogs):
    panel = open_panel(window)
    panel.view_combo.setCurrentIndex(1)
    ang = window.viewport.poly.point_data["angle_to_targets"]
    assert ang.min() >= 0 and ang.max() > 5
    panel.view_combo.setCurrentIndex(2)
    K = window.viewport.poly.point_data["gaussian_curvature"]
    assert np.isfinite(K).all() and K.mean() > 0  # a closed genus-0 blob: ∫K = 4π > 0


def test_capture_sphere_painting_changes_exactly_the_matching_targets(window, dialogs, qtbot):
    panel = open_panel(window)
    panel.gallery.setCurrentRow(panel.gallery.count() - 1)  # capture sphere
    panel.target_combo.setCurrentText("+Z")
    view = panel.capture_view
    cam = np.array(view.plotter.camera.position)
    d = cam / np.linalg.norm(cam)
    x, y = view.project(d[None, :])[0]
    w = view.plotter.interactor
    qtbot.mousePress(w, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier,
                     QPoint(int(x), int(y)))
    qtbot.mouseRelease(w, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier,
                       QPoint(int(x), int(y)))
    cap = panel.capture
    painted = cap.labels >= 0
    assert painted.any() and window.undo_stack.undoText() == "Paint capture sphere"
    np.testing.assert_allclose(cap.targets[cap.labels[painted]], [[0, 0, 1]] * painted.sum())
    N = vertex_normals(window.document.V, window.document.F)
    T = panel.target_map()(N)
    in_region = painted[cap.nearest_vertex(N)]
    assert in_region.any() and (~in_region).any()
    np.testing.assert_allclose(T[in_region], [[0, 0, 1]] * in_region.sum(), atol=1e-12)
    Nu = N[~in_region] / np.linalg.norm(N[~in_region], axis=1, keepdims=True)
    np.testing.assert_allclose(T[~in_region], Nu, atol=1e-9)  # unpainted: unchanged
    window.undo_stack.undo()
    assert (panel.capture.labels < 0).all()


def test_load_style_refuses_genus_one_plainly(window, dialogs, tmp_path):
    from algorithms.mesh import torus, write_mesh

    panel = open_panel(window)
    V, F = torus()
    write_mesh(tmp_path / "torus.obj", V, F)
    dialogs.open_paths.append(str(tmp_path / "torus.obj"))
    assert not panel.load_style_dialog()
    assert dialogs.errors and "genus" in dialogs.errors[-1][1]
    assert panel.style_name == "cube"


def test_shift_click_picks_a_custom_target(window, dialogs, qtbot):
    panel = open_panel(window)
    view = panel.capture_view
    cam = np.array(view.plotter.camera.position)
    d = cam / np.linalg.norm(cam)
    x, y = view.project(d[None, :])[0]
    w = view.plotter.interactor
    qtbot.mousePress(w, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.ShiftModifier,
                     QPoint(int(x), int(y)))
    qtbot.mouseRelease(w, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.ShiftModifier,
                       QPoint(int(x), int(y)))
    assert panel.target_combo.currentText() == "custom"
    assert np.degrees(np.arccos(np.clip(panel.capture_target() @ d, -1, 1))) < 3.0
    assert (panel.capture.labels < 0).all()  # picking does not paint
    assert window.undo_stack.count() == 0


def test_target_direction_view_matches_capture_colours(window, dialogs):
    from app.panels.analogies import direction_hue

    panel = open_panel(window)
    panel.gallery.setCurrentRow(panel.gallery.count() - 1)
    panel.capture.paint_cap([0, 1, 0], 50.0, [1, 0, 0])
    panel.refresh_capture_view()
    panel.view_combo.setCurrentIndex(3)
    hue = window.viewport.poly.point_data["target_direction"]
    N = vertex_normals(window.document.V, window.document.F)
    up = N[:, 1] / np.linalg.norm(N, axis=1) > np.cos(np.radians(45))
    np.testing.assert_allclose(hue[up], direction_hue(np.array([[1.0, 0, 0]]))[0])


# -- the recipe "Analogies" (app/recipes/analogies.py) through the panel ----------------------
def drag_on_capture(qtbot, panel, points, modifier=None):
    """A left-button drag on the capture sphere's view through the pixel ``points``."""
    modifier = Qt.KeyboardModifier.NoModifier if modifier is None else modifier
    w = panel.capture_view.plotter.interactor
    pts = [QPoint(int(round(x)), int(round(y))) for x, y in points]
    qtbot.mousePress(w, Qt.MouseButton.LeftButton, modifier, pts[0])
    for p in pts[1:]:
        qtbot.mouseMove(w, p)
    qtbot.mouseRelease(w, Qt.MouseButton.LeftButton, modifier, pts[-1])


def front_of_capture(panel):
    cam = np.array(panel.capture_view.plotter.camera.position)
    d = cam / np.linalg.norm(cam)
    return panel.capture_view.project(d[None, :])[0]


def run_panel(window, panel, qtbot):
    state = window.document.state
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.run_button.click()
    assert window.document.state is not state
    return state


def test_panel_run_equals_the_headless_recipe_bit_for_bit(window, dialogs, qtbot):
    from app.recipes import run

    panel = open_panel(window)
    items = {panel.gallery.item(i).data(256): i for i in range(panel.gallery.count())}
    panel.gallery.setCurrentRow(items["octahedron"])
    before = run_panel(window, panel, qtbot)
    req = panel.last_request
    assert req["recipe"] == "Analogies" and req["input"] is before
    assert req["options"]["style"] == "octahedron"
    head = run("analogy", before, panel.form.params(), panel.job_options())
    assert head.state.V.tobytes() == window.document.V.tobytes()
    np.testing.assert_array_equal(head.state.F, window.document.F)
    assert head.outcome["iterations"] == 20
    # a second Run starts from the same base shape as the first (issue 41 item 9): the same
    # precomputation, the same result
    sa = panel._recipe_cache["analogy"][2]
    first = window.document.V.copy()
    run_panel(window, panel, qtbot)
    assert panel.last_request["input"].V is before.V and panel._recipe_cache["analogy"][2] is sa
    assert window.document.V.tobytes() == first.tobytes()
    # "Stylize the result instead": a Run from the result reuses nothing stale: it equals a
    # headless run too
    panel.continue_button.click()
    before2 = run_panel(window, panel, qtbot)
    assert panel.last_request["input"] is before2 and before2.V.tobytes() == first.tobytes()
    assert panel._recipe_cache["analogy"][2] is not sa  # new input positions, new precompute
    head2 = run("Analogies", before2, panel.form.params(), panel.job_options())
    assert head2.state.V.tobytes() == window.document.V.tobytes()


def test_painted_capture_stroke_replays_and_its_run_equals_the_recipe(window, dialogs, qtbot):
    import copy
    import json

    from app.recipes import run
    from app.recipes.analogies import apply_capture_stroke, capture_hash, replay_capture_edit
    from app.study.session import _edit_details

    panel = open_panel(window)
    panel.gallery.setCurrentRow(panel.gallery.count() - 1)  # capture sphere
    panel.target_combo.setCurrentText("−X")
    x, y = front_of_capture(panel)
    before = panel.capture.to_dict()
    drag_on_capture(qtbot, panel, [(x, y), (x + 6, y), (x + 12, y + 4)])
    cmd = window.undo_stack.command(window.undo_stack.index() - 1)
    assert cmd.text() == "Paint capture sphere"
    d = cmd.log_details
    assert d["tool"] == "capture" and d["capture_before"] == before
    stroke = d["stroke"]
    assert len(stroke["dabs"]) >= 2 and stroke["target"] == [-1.0, 0.0, 0.0]
    assert stroke["radius"] == panel.brush_settings.radius and stroke["erase"] is False
    assert d["capture_after_hash"] == capture_hash(panel.capture.to_dict())
    assert panel.capture.to_dict() == apply_capture_stroke(before, stroke)
    # the study log writes it as JSON and reads it back: it still replays
    logged = json.loads(json.dumps(d))
    assert replay_capture_edit(d) and replay_capture_edit(logged)
    for change in ({"radius": stroke["radius"] * 1.5}, {"target": [0.0, 1.0, 0.0]},
                   {"erase": True}, {"dabs": stroke["dabs"][:1]},
                   {"dabs": [[p[0], p[1] + 0.2, p[2]] for p in stroke["dabs"]]}):
        altered = copy.deepcopy(logged)
        altered["stroke"].update(change)
        assert not replay_capture_edit(altered), change
    assert not replay_capture_edit({**logged, "capture_before": apply_capture_stroke(
        before, stroke)})
    # the study log's edit record of the stroke (it reads before/after of document commands)
    assert _edit_details(cmd)["tool"] == "capture"
    # an erase stroke replays too
    panel.erase_button.setChecked(True)
    drag_on_capture(qtbot, panel, [(x, y)])
    cmd2 = window.undo_stack.command(window.undo_stack.index() - 1)
    assert cmd2.log_details["stroke"]["erase"] is True and replay_capture_edit(cmd2.log_details)
    window.undo_stack.undo()
    assert panel.capture.to_dict() == apply_capture_stroke(before, stroke)
    # a Run with the painted sphere equals the headless recipe with the panel's options
    assert panel.job_options()["capture"] == panel.capture.to_dict()
    start = run_panel(window, panel, qtbot)
    head = run("analogy", start, panel.form.params(), panel.job_options())
    assert head.state.V.tobytes() == window.document.V.tobytes()


def test_job_options_are_json_and_restore_round_trips(window, dialogs, tmp_path):
    import json

    from algorithms.mesh import octahedron, write_mesh

    panel = open_panel(window)
    items = {panel.gallery.item(i).data(256): i for i in range(panel.gallery.count())}
    # a primitive and a painted sphere
    panel.gallery.setCurrentRow(items["pyramid"])
    panel.capture.paint_cap([0, 0, 1], 30.0, [1, 0, 0])
    opts = panel.job_options()
    saved = json.loads(json.dumps(opts))
    assert saved == opts and opts["style"] == "pyramid"
    label = panel.style_label.text()
    panel.gallery.setCurrentRow(items["cube"])
    panel.capture.erase(np.arange(len(panel.capture.vertices)))
    undo_count = window.undo_stack.count()
    panel.restore_options(saved)
    assert panel.job_options() == opts
    assert panel.gallery.currentItem().data(256) == "pyramid"
    assert panel.style_label.text() == label
    assert (panel.capture.labels >= 0).any() and window.undo_stack.count() == undo_count
    np.testing.assert_array_equal(
        panel.capture_view.poly.point_data["capture"][panel.capture.labels < 0], np.nan)
    # the capture sphere style
    panel.gallery.setCurrentRow(panel.gallery.count() - 1)
    opts = json.loads(json.dumps(panel.job_options()))
    panel.gallery.setCurrentRow(items["cube"])
    panel.restore_options(opts)
    assert panel.style_name == "capture sphere" and panel.job_options() == opts
    assert panel.style_label.text() == "your painted capture sphere"
    # a loaded style file goes into the options as a blob reference
    V, F = octahedron()
    path = tmp_path / "my_style.obj"
    write_mesh(path, 2.0 * V, F)
    dialogs.open_paths.append(str(path))
    assert panel.load_style_dialog()
    opts = json.loads(json.dumps(panel.job_options()))
    assert opts["style"].startswith("blob:") and opts["style"].endswith("/my_style.obj")
    label = panel.style_label.text()
    assert "my_style.obj" in label
    path.unlink()  # the run depends on the stored bytes, not on the file
    panel.gallery.setCurrentRow(items["cube"])
    panel.restore_options(opts)
    assert panel.job_options() == opts and panel.style_label.text() == label
    assert panel.gallery.currentItem() is None or not panel.gallery.currentItem().isSelected()
    N = np.array([[0.9, 0.2, 0.3]])
    np.testing.assert_allclose(panel.target_map()(N), [[1, 1, 1]] / np.sqrt(3), atol=1e-12)


def test_a_flat_drawing_says_its_normals_already_match_the_cube_style(window, dialogs, qtbot,
                                                                      tmp_path):
    """Analogies (cube style) on a flat drawing: the closing line says why nothing changed."""
    from tests.app.conftest import open_and_run
    from tests.conftest import unit_square_grid

    def cube_style(panel):
        items = {panel.gallery.item(i).data(256): i for i in range(panel.gallery.count())}
        panel.gallery.setCurrentRow(items["cube"])

    panel = open_and_run(window, qtbot, tmp_path, *unit_square_grid(8), "Analogies",
                         cube_style)
    qtbot.waitUntil(lambda: "already within" in panel.status_label.text(), timeout=10000)
