"""The Subdivision panel with real widgets (pytest-qt)."""

from __future__ import annotations

import numpy as np

from algorithms.subdivision.model import shipped_weights_path
from tests.conftest import SAMPLES


def open_panel(window):
    assert window.open_path(SAMPLES / "blob.obj")
    panel = window.panels["Subdivision"]
    panel.raise_()
    return panel


def test_subdivide_with_shipped_weights_then_undo_redo(window, dialogs, qtbot):
    assert shipped_weights_path().is_file()
    panel = open_panel(window)
    doc = window.document
    V0, F0 = np.array(doc.V), np.array(doc.F)
    panel.form.set_params(panel.form.params().__class__(method="neural", levels=1,
                                                        coarsen_first=300))
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    m0 = 2 * 300 - 4  # blob is a closed genus-0 mesh: QSlim to ~300 vertices, then 1 level
    assert abs(len(doc.F) - 4 * m0) <= 16 and np.isfinite(doc.V).all()
    assert window.viewport.poly.n_points == len(doc.V)
    window.undo_stack.undo()
    np.testing.assert_array_equal(doc.F, F0)
    np.testing.assert_array_equal(doc.V, V0)
    window.undo_stack.redo()
    assert len(doc.F) > len(F0) or len(doc.F) != len(F0)
    # a baseline too, from the subdivided mesh: each run is one more undo step
    n = window.undo_stack.count()
    panel.form.set_params(panel.form.params().__class__(method="loop", levels=1,
                                                        coarsen_first=0))
    before = len(doc.F)
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        panel.run_button.click()
    assert len(doc.F) == 4 * before and window.undo_stack.count() == n + 1


def test_tiny_training_streams_losses_and_cancel_keeps_best(window, dialogs, qtbot, tmp_path,
                                                           monkeypatch):
    monkeypatch.setenv("STYLIZE3D_CACHE", str(tmp_path / "cache"))
    panel = open_panel(window)
    panel.workers = 1
    panel.coarse_spin.setValue(3)
    panel.epochs_spin.setValue(1000)
    seen = []
    window.runner.metrics.connect(lambda h: seen.extend(m for _i, m in h if "loss" in m))
    panel.train_button.click()
    qtbot.waitUntil(lambda: len(seen) >= 2, timeout=180000)
    with qtbot.waitSignal(window.runner.cancelled, timeout=60000):
        panel.stop_button.click()
    qtbot.waitUntil(lambda: panel.trained_net is not None, timeout=10000)
    assert len(panel.plot.series.get("loss", [])) >= 2
    assert panel.weights_combo.currentText() == "Trained here"
    assert panel.save_button.isEnabled()
    out = tmp_path / "w.pt"
    panel.save_weights(str(out))
    from algorithms.subdivision.model import load_weights

    net, info = load_weights(out)
    assert info["trained_on"] == "the Subdivision panel"
    # the document was not changed by training
    assert window.undo_stack.count() == 0
