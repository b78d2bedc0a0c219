"""The Cubic panel with real widgets and the real viewport."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPoint, Qt

from algorithms.deform.cubic import mean_l1_of_normals as l1_of_normals
from algorithms.mesh.operators import vertex_normals
from tests.app.conftest import drag, front_vertex
from tests.conftest import SAMPLES


def open_cubic(window):
    assert window.open_path(SAMPLES / "blob.obj")
    panel = window.panels["Cubic"]
    panel.live_box.setChecked(False)
    panel.form.editors["max_iterations"].setValue(30)
    return panel


def test_run_streams_and_is_one_undoable_command(window, dialogs, qtbot):
    panel = open_cubic(window)
    V0 = window.document.V.copy()
    F = window.document.F
    panel.form.editors["lam"].setValue(0.4)
    previews = []
    window.runner.preview.connect(lambda s: previews.append(s.iteration))
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        qtbot.mouseClick(panel.run_button, Qt.MouseButton.LeftButton)
    assert previews
    V1 = window.document.V
    assert l1_of_normals(V1, F) < l1_of_normals(V0, F) - 0.01  # cubier
    assert window.undo_stack.count() == 1 and window.undo_stack.undoText() == "Cubic"
    assert len(panel.plot.series["energy"]) >= 2
    # a shape that changed says nothing about an unchanged one
    text = panel.status_label.text()
    assert "Done" in text and "did not change" not in text and "changed little" not in text
    window.undo_stack.undo()
    np.testing.assert_array_equal(window.document.V, V0)
    np.testing.assert_array_equal(window.viewport.points, V0)


def test_cancel_restores(window, dialogs, qtbot):
    panel = open_cubic(window)
    V0 = window.document.V.copy()
    panel.form.editors["max_iterations"].setValue(100000)
    panel.form.editors["rel_displacement_tol"].setValue(0.0)
    with qtbot.waitSignal(window.runner.preview, timeout=60000):
        panel.run_button.click()
    with qtbot.waitSignal(window.runner.cancelled, timeout=60000):
        window.cancel_button.click()
    qtbot.waitUntil(lambda: not window.runner.busy)
    np.testing.assert_array_equal(window.viewport.points, V0)
    assert window.undo_stack.count() == 0


def test_live_slider_restarts_from_the_input_and_merges_undo(window, dialogs, qtbot):
    panel = open_cubic(window)
    V0 = window.document.V.copy()
    panel.live_box.setChecked(True)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.form.set_value("lam", 0.3)
    V_a = window.document.V.copy()
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.form.set_value("lam", 0.0)
    # λ = 0 from the *input* gives the input back (no compounding of the previous result)
    np.testing.assert_allclose(window.document.V, V0, atol=1e-8)
    assert np.abs(V_a - V0).max() > 1e-3
    assert window.undo_stack.count() == 1  # both live runs are one undo step
    window.undo_stack.undo()
    np.testing.assert_array_equal(window.document.V, V0)


def test_gauss_map_painting_changes_lambda_of_matching_normals(window, dialogs, qtbot):
    panel = open_cubic(window)
    gm = panel.gauss.view
    # paint the direction that faces the sphere view's camera
    cam = np.array(gm.plotter.camera.position)
    d = cam / np.linalg.norm(cam)
    x, y = gm.project(d[None, :] * 1.0)[0]
    w = gm.plotter.interactor
    qtbot.mousePress(w, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier,
                     QPoint(int(x), int(y)))
    qtbot.mouseRelease(w, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier,
                       QPoint(int(x), int(y)))
    lam = window.document.state.fields["lambda_scale"]
    N = vertex_normals(window.document.V, window.document.F)
    angle = np.degrees(np.arccos(np.clip(N @ d, -1, 1)))
    changed = lam != 1.0
    assert changed.any()
    theta_r = panel.brush_settings.radius * 180.0
    assert angle[changed].max() <= theta_r + 1.0  # only vertices whose normals match
    assert (changed[angle < 0.5 * theta_r]).all()
    assert window.undo_stack.undoText() == "Paint λ"
    # the sphere shows the painted field
    sv = panel.gauss.sphere_values()
    assert np.nanmax(sv) > 1.0


def test_lambda_brush_from_the_panel_paints_near_the_stroke_only(window, dialogs, qtbot):
    panel = open_cubic(window)
    panel.tool_buttons["lambda"].click()
    assert window.viewport.handler is panel.lambda_brush
    assert panel.show_combo.currentText() == "λ scale"
    V = window.document.V
    v = front_vertex(window)
    x, y = window.viewport.project(V[[v]])[0]
    drag(qtbot, window, [(x, y), (x + 10, y)])
    lam = window.document.state.fields["lambda_scale"]
    changed = np.flatnonzero(lam != 1.0)
    diag = np.linalg.norm(np.ptp(V, axis=0))
    assert changed.size and np.linalg.norm(V[changed] - V[v], axis=1).max() < 0.2 * diag
    panel.tool_buttons["camera"].click()
    assert window.viewport.handler is None
    # Clear painting is one undoable step
    panel.clear_button.click()
    assert "lambda_scale" not in window.document.state.fields
    window.undo_stack.undo()
    assert "lambda_scale" in window.document.state.fields


def test_progressive_mode_runs_and_reuses_its_preprocessing(window, dialogs, qtbot):
    panel = open_cubic(window)
    assert not panel.progressive_box.isChecked()  # small mesh: off by default
    V0 = window.document.V.copy()
    F = window.document.F
    panel.progressive_box.setChecked(True)
    panel.progressive_form.editors["target_faces"].setValue(1500)
    panel.form.editors["lam"].setValue(0.5)
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.run_button.click()
    from algorithms.deform.progressive import ProgressiveCubic

    solver = panel._recipe_cache["solver"]
    assert isinstance(solver, ProgressiveCubic)
    assert l1_of_normals(window.document.V, F) < l1_of_normals(V0, F) - 0.01
    np.testing.assert_array_equal(window.document.F, F)  # faces never change
    window.undo_stack.undo()
    panel.form.editors["lam"].setValue(0.3)
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.run_button.click()
    assert panel._recipe_cache["solver"] is solver  # λ changed: decimation reused
    # finished on every triangle by default (issue 37); unticked: the copy alone, less cubic,
    # and the decimation is still reused
    finish = panel.progressive_form.editors["finish"]
    assert finish.isChecked() and "λ values quickly" in panel.progressive_box.toolTip()
    finished = window.document.V.copy()
    assert solver._fine is not None
    assert "on the coarse copy, then" in panel.status_label.text()
    assert "on every triangle" in panel.status_label.text()
    window.undo_stack.undo()
    qtbot.mouseClick(finish, Qt.LeftButton, pos=QPoint(6, finish.height() // 2))
    assert not finish.isChecked()
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.run_button.click()
    assert panel._recipe_cache["solver"] is solver
    alone = window.document.V
    assert "coarse copy" not in panel.status_label.text()
    np.testing.assert_allclose(alone, solver.stylize(panel.form.params()), atol=1e-9)
    assert l1_of_normals(alone, F) > l1_of_normals(finished, F)


def test_frame_brush_paints_a_local_cube_frame(window, dialogs, qtbot):
    panel = open_cubic(window)
    panel.form.set_value("rot_y", 45.0)
    panel.tool_buttons["frame"].click()
    V = window.document.V
    v = front_vertex(window)
    x, y = window.viewport.project(V[[v]])[0]
    drag(qtbot, window, [(x, y)])  # a click: press and release in place
    st = window.document.state
    ry = st.fields["frame_ry"]
    assert ry[v] == 45.0 and np.isnan(ry).sum() > 0.5 * len(V)
    assert window.undo_stack.undoText() == "Paint cube frame"
    from app.recipes.cubic import frames_of

    frames = frames_of(st, np.eye(3))
    np.testing.assert_allclose(frames[v] @ np.array([1.0, 0, 0]),
                               [np.cos(np.radians(45)), 0, -np.sin(np.radians(45))], atol=1e-12)
    far = int(np.flatnonzero(np.isnan(ry))[0])
    np.testing.assert_array_equal(frames[far], np.eye(3))
    panel.form.set_value("rot_y", 0.0)
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.run_button.click()
    assert window.undo_stack.undoText() == "Cubic"


def test_multigrid_global_step_option(window, dialogs, qtbot):
    panel = open_cubic(window)
    V0 = window.document.V.copy()
    F = window.document.F
    panel.form.editors["lam"].setValue(0.4)
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.run_button.click()
    direct = window.document.V.copy()
    window.undo_stack.undo()
    panel.progressive_box.setChecked(True)
    panel.multigrid_box.setChecked(True)  # the two big-mesh modes exclude each other
    assert not panel.progressive_box.isChecked()
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.run_button.click()
    solver = panel._recipe_cache["solver"]
    assert solver.system.backend == "multigrid" and solver.system.multigrid.n_levels >= 2
    V1 = window.document.V
    assert l1_of_normals(V1, F) < l1_of_normals(V0, F) - 0.01
    diag = np.linalg.norm(np.ptp(V0, axis=0))
    assert np.abs(V1 - direct).max() < 1e-3 * diag  # same result as the direct global step
    panel.progressive_box.setChecked(True)
    assert not panel.multigrid_box.isChecked()


def test_a_stroke_starting_off_the_model_paints_and_leaves_the_camera(window, dialogs, qtbot):
    """Issue 24 item 10: starting a brush stroke just off the model rotated the camera."""
    panel = open_cubic(window)
    panel.tool_buttons["lambda"].click()
    cam = window.viewport.plotter.camera
    pose = (tuple(cam.position), tuple(cam.focal_point), tuple(cam.up))
    V = window.document.V
    v = front_vertex(window)
    x, y = window.viewport.project(V[[v]])[0]
    # from the view's corner (background) onto the model
    drag(qtbot, window, [(4, 4), ((4 + x) / 2, (4 + y) / 2), (x, y), (x + 6, y)])
    assert (tuple(cam.position), tuple(cam.focal_point), tuple(cam.up)) == pose
    lam = window.document.state.fields["lambda_scale"]
    assert (lam != 1.0).any() and window.undo_stack.undoText() == "Paint λ"
    # a drag entirely off the model does nothing at all
    n = window.undo_stack.count()
    drag(qtbot, window, [(4, 4), (30, 6), (60, 8)])
    assert window.undo_stack.count() == n
    assert (tuple(cam.position), tuple(cam.focal_point), tuple(cam.up)) == pose


def test_painting_tools_are_in_sight_at_1024x700(window, qtbot):
    """Issue 24 item 10: at 1024×700 Cubic's tools were below the fold (under the big-mesh
    options). They come right after the parameters; the big-mesh options fold away and open
    themselves when one is turned on."""
    assert window.open_path(SAMPLES / "blob.obj")
    window.resize(1024, 700)
    panel = window.panels["Cubic"]
    panel.raise_()
    qtbot.waitUntil(panel.is_shown)
    qtbot.wait(50)
    for key in ("lambda", "fix", "handle"):
        b = panel.tool_buttons[key]
        assert not b.visibleRegion().isEmpty(), f"{key} is off-screen"
    assert not panel.big_section.isChecked() and not panel.progressive_box.isVisible()
    panel.multigrid_box.setChecked(True)
    assert panel.big_section.isChecked() and panel.multigrid_box.isVisible()
    panel.multigrid_box.setChecked(False)


def test_run_and_the_slider_start_from_one_base_shape(window, dialogs, qtbot):
    """Issue 41 item 9: a second Run stylized the stylized shape while the λ slider re-ran from
    the last Run's input. Both start from one base shape, which the footer names; "Stylize the
    result instead" makes the result the next start."""
    panel = open_cubic(window)
    panel.form.editors["max_iterations"].setValue(5)
    V0 = window.document.V.copy()
    assert panel.base_label.isVisible() and "as it is now" in panel.base_label.text()
    assert not panel.continue_button.isVisible()
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        qtbot.mouseClick(panel.run_button, Qt.MouseButton.LeftButton)
    V1 = window.document.V.copy()
    assert "before your last Cubic run" in panel.base_label.text()
    assert panel.continue_button.isVisible()
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        qtbot.mouseClick(panel.run_button, Qt.MouseButton.LeftButton)
    np.testing.assert_array_equal(window.document.V, V1)  # the same start, the same result
    qtbot.mouseClick(panel.continue_button, Qt.MouseButton.LeftButton)
    assert "as it is now" in panel.base_label.text() and not panel.continue_button.isVisible()
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        qtbot.mouseClick(panel.run_button, Qt.MouseButton.LeftButton)
    F = window.document.F
    assert l1_of_normals(window.document.V, F) < l1_of_normals(V1, F) - 1e-4  # on the result
    # undo back to the input: the next start is the mesh as it is (the input)
    while window.undo_stack.canUndo():
        window.undo_stack.undo()
    np.testing.assert_array_equal(window.document.V, V0)
    assert "as it is now" in panel.base_label.text()


def test_opening_another_mesh_leaves_nothing_of_the_previous_one(window, dialogs, qtbot):
    """Issue 41 item 8: after opening another mesh, Cubic still said "Done: … Undo with Ctrl+Z"
    (Undo greyed), and its energy plot kept the previous mesh's curve; after Esc the plot kept
    the cancelled run's curve while the mesh was back."""
    panel = open_cubic(window)
    window.resize(1024, 700)  # and the status bar's messages are whole at this size
    panel.form.editors["max_iterations"].setValue(5)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    assert panel.status_label.text().startswith("Done") and panel.plot.series
    assert window.statusBar().currentMessage().endswith("Undo with Ctrl+Z.")
    dialogs.answers.append("Discard changes")
    assert window.open_path(SAMPLES / "bumpy.obj")
    assert panel.status_label.text() == "Ready." and not panel.plot.series
    assert "as it is now" in panel.base_label.text()
    # Esc: the plot does not keep the cancelled run's curve
    panel.form.editors["max_iterations"].setValue(100000)
    panel.form.editors["rel_displacement_tol"].setValue(0.0)
    with qtbot.waitSignal(window.runner.metrics, timeout=60000):
        panel.run_button.click()
    qtbot.waitUntil(lambda: any(len(v) for v in panel.plot.series.values()), timeout=30000)
    window.activateWindow()
    qtbot.waitUntil(window.isActiveWindow, timeout=5000)
    with qtbot.waitSignal(window.runner.cancelled, timeout=60000):
        qtbot.keyClick(window.viewport, Qt.Key.Key_Escape)
    qtbot.waitUntil(lambda: not window.runner.busy)
    assert not any(len(v) for v in panel.plot.series.values())
    assert window.statusBar().currentMessage().endswith("The mesh is as it was.")


def test_the_live_switch_is_in_the_footer_next_to_run(window, qtbot):
    """Issue 41 item 10: Cubic's Live switch was at the bottom of a long scroll."""
    assert window.open_path(SAMPLES / "blob.obj")
    window.resize(1024, 700)
    for panel in window.panels.values():
        assert panel.footer.isAncestorOf(panel.live_box), panel.title
    panel = window.panels["Cubic"]
    panel.raise_()
    qtbot.waitUntil(panel.is_shown)
    qtbot.wait(50)
    assert not panel.live_box.visibleRegion().isEmpty()


def test_touching_separate_parts_are_announced_before_and_after_a_run(window, dialogs, qtbot,
                                                                      tmp_path):
    """Issue 41 item 2: Cubic on a 62-part CAD model pulled touching parts apart and said only
    "Done". Separate parts that touch are named when the mesh opens and after a run."""
    from algorithms.mesh import write_mesh
    from algorithms.mesh.primitives import icosphere
    from algorithms.mesh.topology import touching_parts

    V, F = icosphere(2)
    V2 = np.concatenate([V, V + [2.0, 0, 0], V + [6.0, 0, 0]])  # two touch, one apart
    F2 = np.concatenate([F, F + len(V), F + 2 * len(V)])
    assert touching_parts(V2, F2) == (3, 2)
    path = tmp_path / "parts.obj"
    write_mesh(path, V2, F2)
    assert window.open_path(path)
    panel = window.panels["Cubic"]
    panel.live_box.setChecked(False)
    assert "3 separate parts, 2 of them touching" in panel.status_label.text()
    panel.form.editors["max_iterations"].setValue(5)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    assert "stylized each on its own" in panel.status_label.text()
    # one part: nothing to say
    dialogs.answers.append("Discard changes")
    assert window.open_path(SAMPLES / "blob.obj")
    assert panel.status_label.text() == "Ready."


def test_a_mesh_above_the_finish_limit_says_it_gets_the_copy_alone(window, dialogs, qtbot,
                                                                   monkeypatch):
    """Opening a mesh above FINISH_MAX_FACES: progressive meshes turn on, the panel says the
    copy alone will be stylized and why, and the finished run's message says it again."""
    import app.panels.cubic as cubic_panel
    from algorithms.deform import progressive

    monkeypatch.setattr(cubic_panel, "AUTO_PROGRESSIVE_FACES", 1000)
    monkeypatch.setattr(progressive, "FINISH_MAX_FACES", 2000)
    panel = open_cubic(window)
    n = len(window.document.F)
    assert n > 2000 and panel.progressive_box.isChecked()
    text = panel.status_label.text()
    assert f"{n:,} triangles" in text and "only the coarse copy will be stylized" in text
    assert "GB of" in text and "2,000 triangles" in text
    panel.progressive_form.editors["target_faces"].setValue(1000)
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.run_button.click()
    done = panel.status_label.text()
    assert done.startswith("Done:") and "Not finished on every triangle" in done
    assert "coarse copy, then" not in done


def test_a_run_that_would_cross_itself_says_what_it_held(window, dialogs, qtbot, tmp_path):
    """camelhead's lips: the closing line says where the surface would have passed through
    itself and that the held points leave no crossing (algorithms.deform.collisions); the
    setting is a plain checkbox with its tooltip."""
    from tests.conftest import shared_mesh

    assert window.open_path(shared_mesh("camelhead.off"))
    V0 = window.document.V.copy()
    panel = window.panels["Cubic"]
    panel.live_box.setChecked(False)
    box = panel.form.editors["hold_crossings"]
    assert box.isChecked() and "through itself" in box.toolTip()
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        qtbot.mouseClick(panel.run_button, Qt.MouseButton.LeftButton)
    text = panel.status_label.text()
    assert "through itself" in text and "none is left" in text, text
    assert not np.array_equal(window.document.V, V0)
    window.undo_stack.undo()  # the held run is one undo step, like any run
    assert np.array_equal(window.document.V, V0)


def test_a_box_says_its_faces_already_face_the_axes(window, dialogs, qtbot, tmp_path):
    """Cubic on a shape that is a box already: the closing line says why nothing changed."""
    from algorithms.mesh.primitives import cube
    from tests.app.conftest import open_and_run

    panel = open_and_run(window, qtbot, tmp_path, *cube(3), "Cubic")
    qtbot.waitUntil(lambda: "already face the axes" in panel.status_label.text(),
                    timeout=10000)
