"""The status bar never sends the user to Clean for a problem Clean cannot fix (issue 10)."""

from __future__ import annotations

import numpy as np

from algorithms.mesh import write_mesh
from tests.conftest import mobius_strip


def test_status_bar_advice_for_non_orientable_mesh(window, dialogs, tmp_path):
    V, F = mobius_strip()
    path = tmp_path / "mobius.obj"
    write_mesh(path, V, F)
    assert window.open_path(path)  # only a warning Clean cannot fix: opens without a question
    assert not dialogs.questions
    text = window.stats_label.text()
    assert "problem" in text and "Clean Mesh" not in text and "Clean cannot fix" in text
    assert "cannot fix" in window.stats_label.toolTip()
    # Clean itself agrees: nothing it can do, and it says so
    assert not window.clean_mesh()
    assert "Not fixed" in dialogs.infos[-1][1] and "not orientable" in dialogs.infos[-1][1]
    assert "Clean Mesh" not in window.stats_label.text()


def test_status_bar_sends_to_clean_when_clean_can_fix(window, dialogs, tmp_path):
    V, F = mobius_strip()
    path = tmp_path / "loose.obj"
    write_mesh(path, np.vstack([V, [[5.0, 5.0, 5.0]]]), F)
    dialogs.answers.append("Open as it is")
    assert window.open_path(path)
    assert "Edit > Clean Mesh" in window.stats_label.text()


def test_unexpected_error_in_a_slot_is_a_plain_dialog(window, dialogs):
    from app.gui import make_excepthook

    hook = make_excepthook(window)
    try:
        raise RuntimeError("Factor is exactly singular")
    except RuntimeError as e:
        hook(type(e), e, e.__traceback__)
    title, text = dialogs.errors[-1]
    assert title == "Something went wrong" and "Factor is exactly singular" in text
    assert "Traceback" not in text and "Undo" in text
    try:
        raise MemoryError()
    except MemoryError as e:
        hook(type(e), e, e.__traceback__)
    assert "ran out of memory" in dialogs.errors[-1][1]
