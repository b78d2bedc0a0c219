"""The status bar never sends the user to Clean for a problem Clean cannot fix (issue 10)."""

from __future__ import annotations

import numpy as np

from algorithms.mesh import write_mesh
from tests.conftest import mobius_strip


def test_a_one_sided_mesh_is_sent_to_clean_which_cuts_it_open(window, dialogs, tmp_path):
    V, F = mobius_strip()
    path = tmp_path / "mobius.obj"
    write_mesh(path, V, F)
    dialogs.answers.append("Open as it is")
    assert window.open_path(path)
    text = window.stats_label.text()
    assert "problem" in text and "Edit > Clean Mesh" in text and "cannot fix" not in text
    # Clean cuts it open along its seam and says so; then nothing is left to fix, and Undo
    # brings the one-sided mesh back
    assert window.clean_mesh()
    said = dialogs.infos[-1][1]
    assert "Cut the one-sided surface open along" in said and "Not fixed" not in said
    assert "problem" not in window.stats_label.text()
    assert len(window.document.F) == len(F) and len(window.document.V) > len(V)
    window.undo_stack.undo()
    assert len(window.document.V) == len(V)


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
