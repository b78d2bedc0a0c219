"""Edits as recipes (app/edits.py) and project files in the real window: every painting tool's
stroke is re-computed bit for bit from its logged inputs; a project saved after painting,
fixing and dragging a handle re-makes the app's Cubic result headless, bit for bit."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPoint, Qt

from app.edits import replay_edit
from app.study.log import state_hash
from tests.app.conftest import drag, front_vertex
from tests.conftest import SAMPLES


def _h(st):
    return state_hash(st.V, st.F, st.fields, st.handles)


def _open(window):
    assert window.open_path(SAMPLES / "blob.obj")
    panel = window.panels["Cubic"]
    panel.live_box.setChecked(False)
    panel.form.editors["max_iterations"].setValue(20)
    return panel


def _stroke(qtbot, window, dx=12):
    V = window.document.V
    v = front_vertex(window)
    x, y = window.viewport.project(V[[v]])[0]
    drag(qtbot, window, [(x, y), (x + dx / 2, y + 2), (x + dx, y)])
    return v


def _check_last_command(window, tool):
    st = window.undo_stack
    cmd = st.command(st.index() - 1)
    details = cmd.log_details
    assert details["tool"] == tool
    again = replay_edit(cmd.before, details)
    assert again is not None and _h(again) == _h(cmd.after), tool
    return cmd


def test_every_painting_tool_is_recomputed_from_its_logged_inputs(window, dialogs, qtbot):
    panel = _open(window)
    for key, tool in (("lambda", "brush"), ("fix", "brush"), ("plane", "brush"),
                      ("frame", "stamp")):
        panel.tool_buttons[key].click()
        n = window.undo_stack.count()
        _stroke(qtbot, window)
        assert window.undo_stack.count() == n + 1, key
        cmd = _check_last_command(window, tool)
        assert len(cmd.log_details.get("dabs", [])) >= 2
    # a changed stroke gives another state: the check can fail
    cmd = window.undo_stack.command(0)
    d = dict(cmd.log_details, strength=cmd.log_details["strength"] / 2)
    assert _h(replay_edit(cmd.before, d)) != _h(cmd.after)
    # erase mode
    panel.brush_settings.erase = True
    panel.tool_buttons["lambda"].click()
    _stroke(qtbot, window)
    assert _check_last_command(window, "brush").log_details["erase"] is True
    panel.brush_settings.erase = False
    # Gauss map: a click on the sphere view
    gm = panel.gauss.view
    cam = np.array(gm.plotter.camera.position)
    x, y = gm.project((cam / np.linalg.norm(cam))[None, :])[0]
    w = gm.plotter.interactor
    for ev in (qtbot.mousePress, qtbot.mouseRelease):
        ev(w, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier, QPoint(int(x), int(y)))
    cmd = _check_last_command(window, "brush")
    assert cmd.log_details["space"] == "gauss"
    # handles: add one by dragging, then remove it with Ctrl+click
    panel.tool_buttons["handle"].click()
    _stroke(qtbot, window, dx=25)
    cmd = _check_last_command(window, "handles")
    assert len(cmd.after.handles) == 1
    # Clear painting
    panel.clear_button.click()
    _check_last_command(window, "clear")
    assert not window.document.state.fields and not window.document.state.handles


def test_clean_mesh_is_recomputed(window, dialogs, qtbot):
    from algorithms.mesh import write_mesh
    from tests.conftest import ROOT  # noqa: F401  (the repository root exists)

    from algorithms.mesh.primitives import icosphere

    V, F = icosphere(2)
    V = np.vstack([V, [[5.0, 5.0, 5.0]]])  # an unreferenced vertex: Clean removes it
    p = window.settings.fileName().rsplit("/", 1)[0] + "/loose.obj"
    write_mesh(p, V, F)
    dialogs.answers.append("Open as it is")
    assert window.open_path(p)
    dialogs.answers.clear()
    assert window.clean_mesh()
    _check_last_command(window, "clean")


def test_project_saved_in_the_app_remakes_the_run_headless(window, dialogs, qtbot, tmp_path):
    from app.project import read_project
    from app.recipes import run

    panel = _open(window)
    panel.tool_buttons["lambda"].click()
    _stroke(qtbot, window)
    panel.tool_buttons["fix"].click()
    _stroke(qtbot, window, dx=-14)
    panel.tool_buttons["handle"].click()
    _stroke(qtbot, window, dx=30)
    panel.tool_buttons["camera"].click()
    st = window.document.state
    assert {"lambda_scale", "fixed"} <= set(st.fields) and len(st.handles) == 1
    panel.form.editors["lam"].setValue(0.35)
    panel.plane_axis.setCurrentIndex(2)
    path = tmp_path / "scene.s3d"
    dialogs.save_paths.append(str(path))
    assert window.save_project_dialog() and path.is_file()
    assert window.windowTitle().startswith("scene.s3d")
    # the app's Run ...
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.run_button.click()
    V_app = np.array(window.document.V)
    # ... and the same run from the project, headless, give the same bits
    project = read_project(path)
    res = run("cubic", project)
    assert res.params.lam == 0.35 and res.options["plane_axis"] == 2
    np.testing.assert_array_equal(res.state.V, V_app)
    assert np.abs(V_app - st.V).max() > 1e-3
    # opening the project restores the painting, the handles and the panel's settings
    window.undo_stack.setClean()
    window.document.modified = False
    panel.form.editors["lam"].setValue(0.2)
    panel.plane_axis.setCurrentIndex(0)
    panel.live_box.setChecked(True)  # restoring settings must not start a live re-run
    assert window.open_path(path)
    qtbot.wait(panel.live_debounce_ms + 200)
    assert not window.runner.busy and window.undo_stack.count() == 0
    back = window.document.state
    assert _h(back) == _h(st)
    assert panel.form.params().lam == 0.35 and panel.plane_axis.currentIndex() == 2
    assert window.undo_stack.count() == 0 and not window.document.modified
    # a damaged project: a plain message, the document unchanged
    bad = tmp_path / "bad.s3d"
    bad.write_bytes(path.read_bytes()[:100])
    assert not window.open_path(bad)
    assert dialogs.errors and "project" in dialogs.errors[-1][0].lower()
    assert _h(window.document.state) == _h(st)


def test_the_discard_prompt_names_the_project_the_window_is_about(window, dialogs, qtbot,
                                                                  tmp_path):
    """Issue 41 item 11: the prompt named another file than the project in the title bar."""
    import shutil

    from tests.conftest import SAMPLES

    proj = tmp_path / "mine.s3d"
    shutil.copy(SAMPLES / "blob-painted.s3d", proj)
    assert window.open_project(proj)
    assert window.windowTitle().startswith("mine.s3d")
    smooth = window.panels["Smooth"]
    smooth.live_box.setChecked(False)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        smooth.run_button.click()
    dialogs.answers.append("Cancel")
    window.close()
    title, text, _ = dialogs.questions[-1]
    assert title == "Unsaved changes" and text.startswith("mine.s3d has changes"), text
    assert window.isVisible()  # Cancel keeps the window
