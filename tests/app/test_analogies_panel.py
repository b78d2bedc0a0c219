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
