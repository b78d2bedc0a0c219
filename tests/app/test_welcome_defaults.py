"""Issue 24 items 4 and 6: the welcome window's eight suggestions (one per panel) each open a
sample that shows something with the panel's defaults; the Adversarial one is a coloured object
the classifier recognizes; Smooth's default visibly smooths the bumpy sample and says so when a
shape barely changed."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt

from algorithms.mesh import read_mesh
from tests.conftest import SAMPLES


def test_every_panel_has_one_suggestion_that_opens_its_sample(window, dialogs, qtbot):
    from app.welcome import SAMPLES as SUGGESTIONS

    assert [p for _n, p, _s, _h in SUGGESTIONS] == list(window.panels)  # tab order, all eight
    window.actions_by_name["welcome"].trigger()
    dlg = window.welcome_dialog
    qtbot.waitExposed(dlg)
    for name, panel, short, hint in SUGGESTIONS:
        b = dlg.sample_buttons[panel]
        assert not b.icon().isNull() and short in b.text() and hint in b.text()
        # the whole tile is visible inside the dialog (two rows of four fit)
        top_left = b.mapTo(dlg, b.rect().topLeft())
        assert top_left.x() >= 0 and top_left.x() + b.width() <= dlg.width()
    assert dlg.sizeHint().width() <= 1024 and dlg.sizeHint().height() <= 700
    # equal cards that do not touch (a longer hint made one column wider, issue 41 item 10)
    rects = [b.geometry() for b in dlg.sample_buttons.values()]
    assert len({(r.width(), r.height()) for r in rects}) == 1, [r.size() for r in rects]
    for i, a in enumerate(rects):
        for b in rects[i + 1:]:
            assert not a.intersects(b), (a, b)
    qtbot.mouseClick(dlg.sample_buttons["Smooth"], Qt.MouseButton.LeftButton)
    assert window.document.path.name == "bumpy.obj" and not dlg.isVisible()
    qtbot.waitUntil(window.panels["Smooth"].is_shown)
    assert "bumps" in window.panels["Smooth"].status_label.text()


def test_the_orange_sample_is_coloured_and_recognized_as_an_orange():
    from app.recipes import run
    from app.recipes.adversarial import face_colors_ref, read_face_colors

    path = SAMPLES / "orange.obj"
    mesh = read_mesh(path)
    colors = read_face_colors((path, len(mesh.V), len(mesh.F)), mesh.F)
    assert colors is not None and np.ptp(colors, axis=0).max() > 0.3  # orange and a stem
    res = run("adversary-classify", (mesh.V, mesh.F), {}, {"face_colors": face_colors_ref(colors)})
    from app.recipes.adversarial import class_names_of

    names = class_names_of()
    top = [names[i] for i in res.outcome["top5"]]
    assert top[0] == "orange", top


def _bending_and_move(path):
    from app.recipes import run

    mesh = read_mesh(path)
    steps = []
    res = run("smooth", (mesh.V, mesh.F), {}, {}, callback=steps.append)
    return mesh, res, steps


def test_default_smooth_visibly_removes_the_bumpy_samples_bumps():
    from algorithms.smoothing import SmoothParams, smooth_iter

    mesh, res, steps = _bending_and_move(SAMPLES / "bumpy.obj")
    # the input's own bending energy (one step of size ~0 measures it)
    e0 = next(smooth_iter(mesh.V, mesh.F, SmoothParams(step_size=1e-7, iterations=1)))
    e0 = e0.metrics["bending_energy"]
    assert steps[-1].metrics["bending_energy"] < 0.5 * e0
    assert steps[-1].metrics["moved"] >= 0.005  # half a percent of the size: visible
    diag = np.linalg.norm(np.ptp(mesh.V, axis=0))
    np.testing.assert_allclose(steps[-1].metrics["moved"],
                               np.linalg.norm(res.state.V - mesh.V, axis=1).max() / diag)


def test_smooth_says_when_a_run_barely_changed_the_shape(window, dialogs, qtbot):
    assert window.open_path(SAMPLES / "blob.obj")  # already smooth: the default moves ~0.3 %
    panel = window.panels["Smooth"]
    panel.raise_()
    panel.live_box.setChecked(False)
    qtbot.mouseClick(panel.run_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "Done" in panel.status_label.text(), timeout=60000)
    text = panel.status_label.text()
    assert "changed little" in text and "Step size" in text and "1e-04" in text
    # a visible run does not get the advice
    dialogs.answers.append("Discard changes")
    assert window.open_path(SAMPLES / "bumpy.obj")
    qtbot.mouseClick(panel.run_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: "Done" in panel.status_label.text(), timeout=60000)
    assert "changed little" not in panel.status_label.text()


def test_the_orange_suggestion_shows_its_colours_and_is_classified_an_orange(window, dialogs,
                                                                           qtbot):
    from app.panels.adversarial import FILE_COLORS_FIELD

    window.actions_by_name["welcome"].trigger()
    dlg = window.welcome_dialog
    qtbot.waitExposed(dlg)
    qtbot.mouseClick(dlg.sample_buttons["Adversarial lighting"], Qt.MouseButton.LeftButton)
    panel = window.panels["Adversarial lighting"]
    qtbot.waitUntil(panel.is_shown)
    qtbot.waitUntil(lambda: panel.probs is not None, timeout=180000)
    assert panel.file_colors_box.isChecked()
    vp = window.viewport
    assert vp._field_name == FILE_COLORS_FIELD  # the 3D view shows the file's colours too
    rgb = np.asarray(vp.poly.cell_data[FILE_COLORS_FIELD], dtype=float)
    r, g, b = np.median(rgb, axis=0)
    assert r > 200 and 80 < g < 160 and b < 60  # orange
    assert panel.top5_view.entries[0][0] == "orange"
    window.panels["Cubic"].raise_()
    qtbot.waitUntil(lambda: vp._field_name is None)


def test_the_subdivision_card_shows_the_network_not_loop(window, dialogs, qtbot):
    """Issue 41 item 3: the Subdivision card opened the blob (too dense for the network) at the
    defaults: Loop ran silently and the result looked like the input. The card presets
    'Coarsen first' to the count the method's own advice names, and the network runs."""
    window.actions_by_name["welcome"].trigger()
    dlg = window.welcome_dialog
    qtbot.waitExposed(dlg)
    qtbot.mouseClick(dlg.sample_buttons["Subdivision"], Qt.MouseButton.LeftButton)
    panel = window.panels["Subdivision"]
    qtbot.waitUntil(panel.is_shown)
    assert panel.form.params().coarsen_first == 450
    assert "Coarsen first" in panel.status_label.text() and "450" in panel.status_label.text()
    from app.recipes import run

    # the advice the defaults give on this mesh names the same count
    mesh = read_mesh(SAMPLES / "blob.obj")
    res = run("subdivision", (mesh.V, mesh.F), {}, {})
    # (the network, scaled to its training edge length, makes both levels; the note advises
    # coarsening so that it works as trained)
    assert res.outcome["levels_used"] == ["neural", "neural"]
    assert "about 450 vertices" in res.outcome["note"]
    panel.live_box.setChecked(False)
    steps = []
    window.runner.finished.connect(steps.append)
    with qtbot.waitSignal(window.job_committed, timeout=180000):
        qtbot.mouseClick(panel.run_button, Qt.MouseButton.LeftButton)
    assert "Loop" not in panel.status_label.text(), panel.status_label.text()
    assert panel.recipe().outcome(steps[-1])["method_used"] == "neural"
    assert len(window.document.V) > 4 * 450  # two levels on the coarsened copy
