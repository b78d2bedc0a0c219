"""A big mesh whose triangles change is checked off the GUI thread (issue 24: showing a subdivided
armadillo froze the window ~1 s in validate_mesh); the stats line says so meanwhile, and only the
report of the mesh on screen lands."""

from __future__ import annotations

from algorithms.mesh import loop_subdivide
from app.commands import StateCommand
from app.document import MeshState
from tests.conftest import SAMPLES


def test_topology_change_of_a_big_mesh_is_checked_in_the_background(window, qtbot):
    assert window.open_path(SAMPLES / "blob.obj")
    doc = window.document
    n0 = len(doc.V)
    window.ASYNC_VALIDATE_FACES = 0  # every mesh counts as big here
    before = doc.state
    V1, F1 = loop_subdivide(doc.V, doc.F, 1)
    after = MeshState.make(V1, F1)
    window.undo_stack.push(StateCommand(doc, before, after, "Subdivide"))
    # at once: the new mesh is drawn, its counts shown, the rest "checking"
    assert window.viewport.n_points == len(V1)
    text = window.stats_label.text()
    assert f"V {len(V1):,}" in text and "checking" in text and "genus" not in text
    assert doc.report is None
    qtbot.waitUntil(lambda: "genus 0" in window.stats_label.text(), timeout=10000)
    assert doc.report is not None and doc.report.stats["vertices"] == len(V1)
    assert "checking" not in window.stats_label.text()
    # undo is a topology change too: checked again, for the restored mesh
    window.undo_stack.undo()
    assert "checking" in window.stats_label.text()
    qtbot.waitUntil(lambda: "genus 0" in window.stats_label.text(), timeout=10000)
    assert doc.report.stats["vertices"] == n0 and f"V {n0:,}" in window.stats_label.text()


def test_a_report_for_triangles_no_longer_shown_is_dropped(window):
    assert window.open_path(SAMPLES / "blob.obj")
    doc = window.document
    report = doc.report
    V1, F1 = loop_subdivide(doc.V, doc.F, 1)
    from algorithms.mesh import validate_mesh

    stale = validate_mesh(V1, F1)
    window._on_report_ready(F1, stale)  # a late report of other triangles
    assert doc.report is report and f"V {len(doc.V):,}" in window.stats_label.text()
    window._on_report_ready(doc.F, RuntimeError("boom"))  # a failed check is said, not raised
    assert window.message_log.entries[-1][1:] == ("error", "Could not check the mesh: boom")
    assert doc.report is report
