"""pytest-qt tests driving the real main window and its VTK viewport."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PySide6.QtCore import QMimeData, QPointF, Qt, QUrl
from PySide6.QtGui import QDropEvent, QImage

from algorithms.mesh import read_mesh
from tests.conftest import SAMPLES, shared_mesh

SAMPLE = SAMPLES / "blob.obj"


def open_via_menu(window, dialogs, path) -> None:
    dialogs.open_paths.append(str(path))
    window.actions_by_name["open"].trigger()


def test_open_through_file_menu_shows_mesh(window, dialogs):
    path = shared_mesh("spot_lowres.obj")
    open_via_menu(window, dialogs, path)
    assert not dialogs.errors
    assert window.viewport.n_points == 829
    assert window.viewport.mesh_actor.GetMapper().GetInput().GetNumberOfCells() == 1654
    assert "V 829" in window.stats_label.text() and "genus 0" in window.stats_label.text()
    assert str(Path(path).resolve()) in window.recent_files()
    assert "spot_lowres.obj" in window.windowTitle()


def test_smooth_streams_finishes_and_is_undoable(window, dialogs, qtbot):
    assert window.open_path(SAMPLE)
    V0 = window.document.V.copy()
    panel = window.panels["Smooth"]
    panel.form.editors["iterations"].setValue(25)
    panel.form.editors["step_size"].setValue(0.005)
    previews = []
    window.runner.preview.connect(lambda s: previews.append(s.iteration))
    with qtbot.waitSignal(window.runner.finished, timeout=60000):
        qtbot.mouseClick(panel.run_button, Qt.MouseButton.LeftButton)
    assert previews, "no streamed update reached the GUI"
    V1 = window.document.V.copy()
    assert np.abs(V1 - V0).max() > 1e-4
    np.testing.assert_allclose(window.viewport.points, V1)
    assert window.undo_stack.count() == 1 and window.undo_stack.undoText() == "Smooth"
    assert window.document.modified and window.isWindowModified()
    assert len(panel.plot.series["bending_energy"]) == 25
    window.actions_by_name["undo"].trigger()
    np.testing.assert_array_equal(window.document.V, V0)
    np.testing.assert_array_equal(window.viewport.points, V0)
    assert not window.document.modified
    window.actions_by_name["redo"].trigger()
    np.testing.assert_array_equal(window.document.V, V1)
    np.testing.assert_array_equal(window.viewport.points, V1)


def test_smoothing_that_would_cross_itself_says_what_it_held(window, dialogs, qtbot):
    """fertility at a strong step: its arms would pull through each other; the closing line
    says what was held (issue 38), the setting is a checkbox with its tooltip, one undo step."""
    assert window.open_path(shared_mesh("fertility.off"))
    V0 = window.document.V.copy()
    panel = window.panels["Smooth"]
    box = panel.form.editors["hold_crossings"]
    assert box.isChecked() and "through itself" in box.toolTip()
    panel.form.editors["step_size"].setValue(1e-4)
    with qtbot.waitSignal(window.runner.finished, timeout=60000):
        qtbot.mouseClick(panel.run_button, Qt.MouseButton.LeftButton)
    text = panel.status_label.text()
    assert "Its steps would have pushed the surface through itself in " in text, text
    assert "none is left" in text and "Undo with Ctrl+Z" in text, text
    assert window.undo_stack.count() == 1
    window.undo_stack.undo()
    np.testing.assert_array_equal(window.document.V, V0)


def test_cancel_mid_run_restores_mesh(window, dialogs, qtbot):
    assert window.open_path(SAMPLE)
    V0 = window.document.V.copy()
    panel = window.panels["Smooth"]
    panel.form.editors["flow"].setCurrentText("mcf")  # refactors every step: slow enough to cancel
    panel.form.editors["iterations"].setValue(1000)
    with qtbot.waitSignal(window.runner.preview, timeout=30000):
        panel.run_button.click()
    assert window.cancel_button.isVisible() and window.progress_bar.isVisible()
    assert np.abs(window.viewport.points - V0).max() > 0  # the preview moved the view
    window.activateWindow()
    qtbot.waitUntil(window.isActiveWindow, timeout=5000)
    with qtbot.waitSignal(window.runner.cancelled, timeout=30000):
        qtbot.keyClick(window.viewport, Qt.Key.Key_Escape)
    qtbot.waitUntil(lambda: not window.runner.busy)
    np.testing.assert_array_equal(window.document.V, V0)
    np.testing.assert_array_equal(window.viewport.points, V0)
    assert window.undo_stack.count() == 0
    assert not window.cancel_button.isVisible()
    assert not dialogs.errors


def test_failing_job_shows_message_and_restores(window, dialogs, qtbot):
    assert window.open_path(SAMPLE)
    V0 = window.document.V.copy()
    from algorithms.steps import Step

    def broken():
        yield Step(1, 3, V0 * 2.0)
        raise ZeroDivisionError("boom")

    with qtbot.waitSignal(window.runner.failed, timeout=10000):
        window.start_positions_job("Broken", broken)
    qtbot.waitUntil(lambda: not window.runner.busy)
    assert dialogs.errors and "Broken failed" in dialogs.errors[-1][0]
    assert "ZeroDivisionError" in dialogs.errors[-1][1]
    np.testing.assert_array_equal(window.viewport.points, V0)
    assert window.undo_stack.count() == 0


def test_export_screenshot_is_not_blank(window, dialogs, tmp_path):
    assert window.open_path(SAMPLE)
    out = tmp_path / "shot.png"
    dialogs.save_paths.append(str(out))
    assert window.export_screenshot_dialog()
    img = QImage(str(out))
    assert not img.isNull() and img.width() > 100 and img.height() > 100
    a = np.array([[img.pixelColor(x, y).getRgb()[:3] for x in range(0, img.width(), 8)]
                  for y in range(0, img.height(), 8)], dtype=float)
    bg_corner = a[0, 0]
    differs = np.abs(a - bg_corner).sum(axis=2) > 30
    assert differs.mean() > 0.05, "the screenshot shows only background"
    # the mesh colour (warm beige) is present, not only the blue-grey gradient background
    warm = (a[..., 0] > a[..., 2] + 20)
    assert warm.mean() > 0.02


@pytest.mark.parametrize("kind", ["empty", "garbage", "nan", "out_of_range", "nonmanifold",
                                  "duplicates"])
def test_bad_input_keeps_document(window, dialogs, bad_files, kind):
    assert window.open_path(SAMPLE)
    state = window.document.state
    n = window.viewport.n_points
    # where the problem is fixable, the app offers to clean; this user says Cancel
    dialogs.answers.extend(["Cancel"])
    assert not window.open_path(bad_files[kind])
    shown = dialogs.errors[-1][1] if dialogs.errors else dialogs.questions[-1][1]
    assert len(shown) > 20 and "Traceback" not in shown
    assert window.document.state is state
    assert window.viewport.n_points == n
    assert window.isVisible()


def test_duplicates_can_be_cleaned_on_open(window, dialogs, bad_files):
    dialogs.answers.append("Clean and open")
    assert window.open_path(bad_files["duplicates"])
    assert window.viewport.n_points == 4  # welded tetrahedron
    assert "duplicate" in dialogs.questions[-1][1].lower()


def test_nonmanifold_message_names_the_problem(window, dialogs, bad_files):
    dialogs.answers.append("Cancel")
    window.open_path(bad_files["nonmanifold"])
    text = (dialogs.questions[-1][1] if dialogs.questions else dialogs.errors[-1][1]).lower()
    assert "non-manifold" in text or "more than two" in text


def test_save_over_existing_file_asks_first(window, dialogs, tmp_path, qtbot):
    assert window.open_path(SAMPLE)
    target = tmp_path / "existing.obj"
    target.write_text("precious")
    dialogs.save_paths.append(str(target))
    dialogs.answers.append("Cancel")
    assert not window.save_as()
    assert target.read_text() == "precious"
    assert "Replace" in dialogs.questions[-1][2]
    dialogs.save_paths.append(str(target))
    dialogs.answers.append("Replace")
    assert window.save_as()
    data = read_mesh(target)
    np.testing.assert_allclose(data.V, window.document.V)
    assert window.document.path == target and not window.document.modified
    # saving again to a file this session wrote does not ask again
    assert window.save()


def test_failed_save_keeps_old_file_and_tells(window, dialogs, tmp_path, monkeypatch):
    assert window.open_path(SAMPLE)
    folder = tmp_path / "out"
    folder.mkdir()
    target = folder / "keep.obj"
    target.write_text("old contents")
    import algorithms.mesh.io as io_mod

    def boom(*a, **k):
        raise OSError(28, "No space left on device")

    # fail inside the real writer, after the temporary file was opened
    monkeypatch.setattr(io_mod.os, "fsync", boom)
    dialogs.save_paths.append(str(target))
    dialogs.answers.append("Replace")
    assert not window.save_as()
    assert target.read_text() == "old contents"
    assert dialogs.errors and "save" in dialogs.errors[-1][0].lower()
    assert [p.name for p in folder.iterdir()] == ["keep.obj"], "a temporary file was left behind"


def test_drop_opens_mesh(window, dialogs, qtbot):
    mime = QMimeData()
    mime.setUrls([QUrl.fromLocalFile(str(SAMPLE))])
    ev = QDropEvent(QPointF(50, 50), Qt.DropAction.CopyAction, mime, Qt.MouseButton.LeftButton,
                    Qt.KeyboardModifier.NoModifier)
    with qtbot.waitSignal(window.mesh_shown, timeout=10000):
        window.dropEvent(ev)
    assert window.viewport.n_points == len(read_mesh(SAMPLE).V)


def test_view_toggles_and_ghost(window, dialogs):
    assert window.open_path(SAMPLE)
    window.actions_by_name["wireframe"].setChecked(True)
    assert window.viewport.mesh_actor.prop.show_edges
    window.actions_by_name["flat"].setChecked(True)
    assert window.viewport.mesh_actor.prop.interpolation.name.lower() == "flat"
    window.actions_by_name["ghost"].setChecked(True)
    assert window.viewport.ghost_actor is not None
    window.actions_by_name["ghost"].setChecked(False)
    assert window.viewport.ghost_actor is None


def test_discarding_unsaved_changes_asks(window, dialogs, qtbot):
    assert window.open_path(SAMPLE)
    with qtbot.waitSignal(window.runner.finished, timeout=30000):
        window.panels["Smooth"].run()
    assert window.document.modified
    dialogs.answers.append("Cancel")
    assert not window.open_path(SAMPLE)
    assert window.undo_stack.count() == 1
    dialogs.answers.append("Discard changes")
    assert window.open_path(SAMPLE)
    assert window.undo_stack.count() == 0


def test_settings_persist_recent_files(window, dialogs, tmp_path):
    assert window.open_path(SAMPLE)
    from PySide6.QtCore import QSettings

    s = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    assert str(SAMPLE.resolve()) in [str(p) for p in (s.value("files/recent") or [])]


def test_open_as_is_then_clean_is_undoable(window, dialogs, tmp_path):
    # a mesh with a loose vertex: opens "as it is", smooths (the loose point stays), cleans
    from algorithms.mesh import icosphere, write_mesh

    V, F = icosphere(2)
    path = tmp_path / "loose.obj"
    write_mesh(path, np.vstack([V, [[3.0, 0.0, 0.0]]]), F)
    dialogs.answers.append("Open as it is")
    assert window.open_path(path)
    assert window.viewport.n_points == len(V) + 1
    assert "problem" in window.stats_label.text()
    assert window.clean_mesh()
    assert "unused" in dialogs.infos[-1][1].lower() or "loose" in dialogs.infos[-1][1].lower() \
        or "not used" in dialogs.infos[-1][1].lower()
    assert window.viewport.n_points == len(V) and window.document.V.shape == V.shape
    assert "problem" not in window.stats_label.text()
    window.undo_stack.undo()
    assert window.viewport.n_points == len(V) + 1 and window.document.V.shape[0] == len(V) + 1
    window.undo_stack.redo()
    assert window.viewport.n_points == len(V)
    assert not window.clean_mesh()  # nothing left to fix
    assert "Nothing to fix" in dialogs.infos[-1][1]


def test_a_nan_vertex_is_not_a_dead_end(window, dialogs, tmp_path):
    """Issue 24 item 3: one NaN coordinate in a real mesh: the app offers to remove what cannot
    be repaired (as `stylize3d clean --remove-invalid-faces` does), and says what it removed."""
    from algorithms.mesh.primitives import icosphere

    V, F = icosphere(3)
    V = V.copy()
    V[17, 1] = np.nan
    path = tmp_path / "scan_with_nan.obj"
    with open(path, "w") as f:
        f.writelines(f"v {x} {y} {z}\n" for x, y, z in V)
        f.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F)
    # Cancel: the document stays as it was
    assert window.open_path(SAMPLE)
    state = window.document.state
    dialogs.answers.append("Cancel")
    assert not window.open_path(path)
    assert window.document.state is state
    title, text, choices = dialogs.questions[-1]
    assert choices == ["Remove the broken parts and open", "Cancel"]
    assert "NaN" in text or "not a number" in text.lower()
    assert "repair the file in a mesh editor" not in text
    # the way forward: the vertex and its triangles go, the rest opens
    n_tris = int((F == 17).any(axis=1).sum())
    dialogs.answers.append("Remove the broken parts and open")
    assert window.open_path(path)
    assert len(window.document.F) == len(F) - n_tris
    assert np.isfinite(window.document.V).all() and len(window.document.V) == len(V) - 1
    assert f"{n_tris:,} triangle" in dialogs.questions[-1][1]


def test_ctrl_z_in_a_number_field_undoes_the_document(window, dialogs, qtbot):
    """Issue 24 item 5: after typing λ and Enter, Ctrl+Z sent to the focused number field undoes
    the last change of the document (the field no longer swallows it); while a value is being
    typed, Ctrl+Z still undoes the typing."""
    from PySide6.QtCore import Qt
    from PySide6.QtWidgets import QApplication

    assert window.open_path(SAMPLE)
    panel = window.panels["Cubic"]
    panel.raise_()
    panel.live_box.setChecked(False)
    panel.form.editors["max_iterations"].setValue(5)
    V0 = np.array(window.document.V)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    assert window.undo_stack.count() == 1 and window.undo_stack.index() == 1
    window.activateWindow()
    qtbot.waitUntil(lambda: window.isActiveWindow(), timeout=5000)
    spin = panel.form.editors["lam"].spin
    spin.setFocus()
    qtbot.waitUntil(lambda: QApplication.focusWidget() in (spin, spin.lineEdit()), timeout=5000)
    spin.selectAll()
    focused = QApplication.focusWidget()
    qtbot.keyClicks(focused, "0.5")
    qtbot.keyClick(focused, Qt.Key.Key_Return)
    assert abs(panel.form.params().lam - 0.5) < 1e-9
    qtbot.keyClick(QApplication.focusWidget(), Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier)
    assert window.undo_stack.index() == 0
    np.testing.assert_array_equal(window.document.V, V0)
    qtbot.keyClick(QApplication.focusWidget(), Qt.Key.Key_Z,
                   Qt.KeyboardModifier.ControlModifier | Qt.KeyboardModifier.ShiftModifier)
    assert window.undo_stack.index() == 1
    qtbot.keyClick(QApplication.focusWidget(), Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier)
    qtbot.keyClick(QApplication.focusWidget(), Qt.Key.Key_Y, Qt.KeyboardModifier.ControlModifier)
    assert window.undo_stack.index() == 1
    # typing in progress: the field's own undo, not the document's
    spin.selectAll()
    qtbot.keyClicks(QApplication.focusWidget(), "0.7")
    qtbot.keyClick(QApplication.focusWidget(), Qt.Key.Key_Z, Qt.KeyboardModifier.ControlModifier)
    assert window.undo_stack.index() == 1


def test_colour_bar_text_has_its_greek_letters_and_no_dangling_dots(window, dialogs):
    """Issue 24 item 10: "λ scale" rendered without its λ (VTK's built-in font has no Greek)
    and tick labels ended in a dot ("-346.")."""
    from app.viewport import legend_font_file

    assert window.open_path(SAMPLE)
    panel = window.panels["Cubic"]
    panel.raise_()
    panel.tool_buttons["lambda"].click()
    bar = window.viewport.legend
    assert bar is not None and bar.GetVisibility()
    assert "λ" in bar.GetTitle()
    assert bar.GetLabelFormat() % -346.0 == "-346" and bar.GetLabelFormat() % 0.5 == "0.5"
    font = legend_font_file()
    if font is not None:  # DejaVu Sans comes with the app's system packages
        for prop in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty()):
            assert prop.GetFontFile() == str(font)


def test_toolbar_buttons_stay_put_as_the_undo_label_changes(window, dialogs, qtbot):
    """Issue 41 item 10: the toolbar's buttons jumped as "Undo …" grew."""
    assert window.open_path(SAMPLE)
    window.resize(1024, 700)
    qtbot.wait(50)
    tb = window.toolbar_buttons
    x0 = tb["reset_camera"].geometry().x()
    assert tb["undo"].text() == "Undo"
    panel = window.panels["Multigrid smoothing"]
    panel.raise_()
    panel.live_box.setChecked(False)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    qtbot.wait(50)
    assert tb["undo"].text().startswith("Undo ") and tb["reset_camera"].geometry().x() == x0
    assert window.actions_by_name["undo"].toolTip().startswith(
        "Undo " + window.undo_stack.undoText())
    window.undo_stack.undo()
    qtbot.wait(50)
    assert tb["redo"].text().startswith("Redo") and tb["reset_camera"].geometry().x() == x0


def test_saving_keeps_the_opened_objs_uvs_while_its_triangles_are_kept(window, dialogs, qtbot,
                                                                       tmp_path):
    """Issue 39 item 5 in the app: a textured OBJ smoothed and saved keeps its UVs; after a
    subdivision (new triangles) the save says they were not kept instead of dropping them
    silently."""
    from algorithms.mesh import read_mesh
    from algorithms.mesh.attributes import read_attributes
    from tests.conftest import ROOT

    bob = ROOT / "tests" / "data" / "bob.obj"
    assert window.open_path(bob)
    smooth = window.panels["Smooth"]
    smooth.live_box.setChecked(False)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        smooth.run_button.click()
    out = tmp_path / "bob-smooth.obj"
    dialogs.save_paths.append(str(out))
    assert window.save_as()
    assert "With bob.obj's texture coordinates (UVs)" in window.message_log.entries[-1][2]
    m0, m1 = read_mesh(bob), read_mesh(out)
    a0 = read_attributes(bob, len(m0.V), len(m0.F))
    a1 = read_attributes(out, len(m1.V), len(m1.F))
    np.testing.assert_array_equal(a1.uv, a0.uv)
    assert np.abs(m1.V - m0.V).max() > 0
    sub = window.panels["Subdivision"]
    sub.form.set_value("method", "loop")
    sub.form.set_value("levels", 1)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        sub.run_button.click()
    out2 = tmp_path / "bob-sub.obj"
    dialogs.save_paths.append(str(out2))
    assert window.save_as()  # split with the triangles
    assert "With bob.obj's texture coordinates (UVs)" in window.message_log.entries[-1][2]
    m2 = read_mesh(out2)
    a2 = read_attributes(out2, len(m2.V), len(m2.F))
    assert a2.uv.shape == (4 * len(a0.uv), 3, 2)
    window.undo_stack.undo()
    sub.form.set_value("coarsen_first", 400)  # QSlim remakes the triangles: said, not silent
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        sub.run_button.click()
    out3 = tmp_path / "bob-coarse.obj"
    dialogs.save_paths.append(str(out3))
    assert window.save_as()
    assert "were not saved: the triangles were remade" in window.message_log.entries[-1][2]
