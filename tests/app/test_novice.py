"""Issue 11: the app as a first-time user meets it (tabbed docks, shortcuts, responsiveness,
messages, layout, wording, live mode). Real widgets, real viewport, keys and mouse."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPoint, Qt

from tests.conftest import SAMPLES


def _paint_stroke(qtbot, window):
    """A short left-button drag over the vertex nearest the camera."""
    V = window.document.V
    cam = np.array(window.viewport.plotter.camera.position)
    v = int(np.argmin(((V - cam) ** 2).sum(axis=1)))
    x, y = window.viewport.project(V[[v]])[0]
    w = window.viewport.plotter.interactor
    qtbot.mousePress(w, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier,
                     QPoint(int(x), int(y)))
    qtbot.mouseMove(w, QPoint(int(x) + 8, int(y)))
    qtbot.mouseRelease(w, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier,
                       QPoint(int(x) + 8, int(y)))


def _shown_field(window):
    mapper = window.viewport.mesh_actor.mapper
    return window.viewport._field_name if mapper.scalar_visibility else None


# -- defect 1: docks behind another tab do not drive the viewport ---------------------------------
def test_tabbed_away_panels_leave_painted_colours_alone(window, dialogs, qtbot):
    assert window.open_path(SAMPLES / "blob.obj")
    cubic, mg = window.panels["Cubic"], window.panels["Multigrid smoothing"]
    cubic.live_box.setChecked(False)
    # the panels are tabbed together, Cubic in front; the others are behind their tabs
    assert set(window.tabifiedDockWidgets(cubic)) >= {mg, window.panels["Analogies"]}
    cubic.raise_()
    qtbot.waitUntil(lambda: cubic.is_shown() and not mg.is_shown())
    assert mg.isVisible()  # what Qt says of a dock behind a tab (why is_shown exists)
    cubic.tool_buttons["lambda"].click()
    assert cubic.show_combo.currentText() == "λ scale"
    _paint_stroke(qtbot, window)
    assert "lambda_scale" in window.document.state.fields
    # after the release (the stroke became an undoable command) the colours are still there
    assert _shown_field(window) == "lambda_scale"
    window.undo_stack.undo()
    window.undo_stack.redo()
    assert _shown_field(window) == "lambda_scale"
    # the panel brought to the front draws its own view; back on Cubic, λ comes back
    mg.raise_()
    qtbot.waitUntil(lambda: mg.is_shown())
    cubic.raise_()
    qtbot.waitUntil(lambda: _shown_field(window) == "lambda_scale")


# -- defect 2: every key the shortcut sheet lists does what it says -------------------------------
def test_every_listed_shortcut_works_when_pressed(window, dialogs, qtbot, tmp_path):
    import shutil

    from PySide6.QtGui import QKeySequence
    from PySide6.QtTest import QTest

    from app.commands import StateCommand
    from app.main_window import SHORTCUTS

    mesh = tmp_path / "blob.obj"
    shutil.copy(SAMPLES / "blob.obj", mesh)
    assert window.open_path(mesh)
    doc = window.document
    window.undo_stack.push(StateCommand(doc, doc.state, doc.state.with_field(
        "lambda_scale", np.full(len(doc.V), 1.5)), "Paint λ"))
    window.activateWindow()
    qtbot.waitUntil(lambda: window.isActiveWindow())
    target = window.viewport.plotter.interactor
    target.setFocus()

    def press(text: str) -> None:
        combo = QKeySequence(text)[0]
        QTest.keyClick(target, combo.key(), combo.keyboardModifiers())

    listed = {keys for keys, _what, _name in SHORTCUTS}
    for needed in ("Ctrl+Z", "Ctrl+Shift+Z or Ctrl+Y", "Esc", "R", "W", "F", "G", "Ctrl+O"):
        assert needed in listed
    for keys, what, name in SHORTCUTS:
        for key in keys.split(" or "):
            fired = []
            if name is None:  # Esc: the application-wide stop shortcut
                window._esc.activated.connect(lambda: fired.append(1))
            else:
                action = window.actions_by_name[name]
                action.triggered.connect(lambda *_: fired.append(1))
            if name in ("open",):
                dialogs.open_paths.append(None)     # the file dialog is closed
            if name in ("save_as", "screenshot"):
                dialogs.save_paths.append(None)
            if name == "save":
                dialogs.answers.append("Cancel")    # "Replace file?" -> Cancel
            if name == "quit":
                doc.modified = True
                dialogs.answers.append("Cancel")    # "Discard changes?" -> Cancel: stays open
            index = window.undo_stack.index()
            if name == "redo":
                window.undo_stack.undo()
                index = window.undo_stack.index()
            press(key)
            assert fired, f"{key} ({what}) did nothing"
            if name == "undo":
                assert window.undo_stack.index() == index - 1
                window.undo_stack.redo()
            if name == "redo":
                assert window.undo_stack.index() == index + 1, key
    assert window.isVisible()
    assert any("Ctrl+Y" in text for _t, text in dialogs.infos)  # F1 showed the sheet
