"""Viewport tools driven by real mouse events on the VTK widget: brush strokes and handles."""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt

from tests.app.conftest import drag, front_vertex
from tests.conftest import SAMPLES


def test_pick_returns_the_face_under_the_cursor(window, dialogs):
    assert window.open_path(SAMPLES / "blob.obj")
    v = front_vertex(window)
    x, y = window.viewport.project(window.document.V[[v]])[0]
    hit = window.viewport.pick(x, y)
    assert hit is not None and v in window.document.F[hit.face]
    assert np.linalg.norm(hit.position - window.document.V[v]) < 0.05
    assert window.viewport.pick(2, 2) is None  # background corner


def test_brush_stroke_changes_field_only_near_stroke_and_is_one_undo_step(window, dialogs, qtbot):
    from app.tools import FieldBrush

    assert window.open_path(SAMPLES / "blob.obj")
    brush = FieldBrush(window, "lambda_scale", low=0.0, high=2.0, default=1.0, label="λ")
    brush.settings.radius, brush.settings.strength = 0.05, 0.8
    window.viewport.set_handler(brush)
    V = window.document.V
    v = front_vertex(window)
    start = window.viewport.project(V[[v]])[0]
    drag(qtbot, window, [start + (dx, 0) for dx in range(0, 30, 5)])
    lam = window.document.state.fields["lambda_scale"]
    changed = np.flatnonzero(lam != 1.0)
    assert changed.size > 0 and (lam[changed] > 1.0).all()
    diag = np.linalg.norm(np.ptp(V, axis=0))
    assert np.linalg.norm(V[changed] - V[v], axis=1).max() < 0.25 * diag  # only near the stroke
    assert changed.size < 0.3 * len(V)
    assert window.undo_stack.count() == 1 and "Paint" in window.undo_stack.undoText()
    window.undo_stack.undo()
    assert "lambda_scale" not in window.document.state.fields
    # the camera did not rotate while painting
    np.testing.assert_allclose(window.viewport.project(V[[v]])[0], start, atol=1e-6)


def test_erase_brings_values_down(window, dialogs, qtbot):
    from app.tools import FieldBrush

    assert window.open_path(SAMPLES / "blob.obj")
    brush = FieldBrush(window, "fixed", low=0.0, high=1.0, default=0.0, label="fixed")
    brush.settings.strength = 1.0
    window.viewport.set_handler(brush)
    v = front_vertex(window)
    p = window.viewport.project(window.document.V[[v]])[0]
    drag(qtbot, window, [p, p + (1, 1)])
    assert window.document.state.fields["fixed"][v] > 0.9
    brush.settings.erase = True
    drag(qtbot, window, [p, p + (1, 1)])
    assert window.document.state.fields["fixed"][v] < 0.1
    assert window.undo_stack.count() == 2


def test_handle_add_drag_and_remove(window, dialogs, qtbot):
    from app.tools import HandleTool

    assert window.open_path(SAMPLES / "blob.obj")
    tool = HandleTool(window)
    window.viewport.set_handler(tool)
    v = front_vertex(window)
    p = window.viewport.project(window.document.V[[v]])[0]
    drag(qtbot, window, [p, p + (20, 0), p + (40, -10)])
    handles = window.document.state.handle_dict
    assert len(handles) == 1
    (hv, target), = handles.items()
    assert hv in window.document.F[window.viewport.pick(*p).face]
    moved = np.array(target) - window.document.V[hv]
    assert np.linalg.norm(moved) > 0.01
    # the target follows the mouse: it projects where the mouse was released
    np.testing.assert_allclose(window.viewport.project(np.array([target]))[0], p + (40, -10), atol=1.5)
    assert window.undo_stack.undoText() == "Add handle"
    drag(qtbot, window, [p, p + (1, 0)], Qt.KeyboardModifier.ControlModifier)
    assert window.document.state.handles == ()
    window.undo_stack.undo()
    assert len(window.document.state.handles) == 1
