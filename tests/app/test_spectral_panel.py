"""The Spectral coarsening panel with real widgets (pytest-qt)."""

from __future__ import annotations

import numpy as np

from tests.conftest import SAMPLES


def test_panel_produces_heatmaps_eigenvalue_plot_and_browser(window, dialogs, qtbot):
    assert window.open_path(SAMPLES / "blob.obj")
    V0 = window.document.V.copy()
    panel = window.panels["Spectral coarsening"]
    panel.form.editors["m"].setValue(60)
    panel.form.editors["k"].setValue(15)
    panel.form.editors["max_iterations"].setValue(60)
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.run_button.click()
    qtbot.waitUntil(lambda: panel.result is not None, timeout=5000)
    for name in ("ours", "qslim", "amg"):
        pm = panel.heatmaps[name].pixmap()
        assert pm is not None and not pm.isNull() and "C diag" in panel.scores[name].text()
    assert len(panel.plot.series["energy"]) >= 2
    assert set(panel.eig_plot.series) == {"fine", "ours", "qslim", "amg"}
    assert len(panel.eig_plot.series["fine"]) == 15
    # clusters and roots drawn on the mesh; the mesh itself is unchanged and nothing to undo
    assert "clusters" in window.viewport.poly.point_data
    np.testing.assert_array_equal(window.document.V, V0)
    assert window.undo_stack.count() == 0
    panel.show_combo.setCurrentIndex(2)
    fine = np.array(window.viewport.poly.point_data["eigenfunction"])
    panel.show_combo.setCurrentIndex(3)
    coarse = np.array(window.viewport.poly.point_data["eigenfunction"])
    corr = fine @ coarse / np.linalg.norm(fine) / np.linalg.norm(coarse)
    assert corr > 0.5  # the prolonged coarse eigenvector resembles the fine one


def test_point_cloud_operator_from_the_panel(window, dialogs, qtbot):
    assert window.open_path(SAMPLES / "blob.obj")
    panel = window.panels["Spectral coarsening"]
    panel.operator_combo.setCurrentText("point cloud (vertices only)")
    panel.form.editors["m"].setValue(60)
    panel.form.editors["k"].setValue(15)
    panel.form.editors["max_iterations"].setValue(40)
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        panel.run_button.click()
    qtbot.waitUntil(lambda: panel.result is not None, timeout=5000)
    ours = panel.result.methods["ours"].metrics
    assert 0.0 < ours["c_diag_score"] <= 1.0 and np.isfinite(ours["eig_rel_error_mean"])
