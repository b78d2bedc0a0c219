"""Status texts tell the truth (issue 24 items 7 and 10): stages of a computation are not
"iterations", a direct solve does not report "(0 iterations)", analyses promise no undo."""

from __future__ import annotations

from algorithms.steps import Step
from app.panels.base import step_text
from tests.conftest import SAMPLES


def test_step_text_says_the_stage_and_its_share():
    import numpy as np

    V = np.zeros((1, 3))
    assert step_text(Step(500, 1000, V, {}, "Loop subdivision")) == "Loop subdivision — 50 %"
    assert step_text(Step(3, 10, V)) == "Iteration 3/10"
    assert step_text(Step(3, None, V, {}, "remeshed")) == "Iteration 3: remeshed"


def test_subdivision_and_direct_solves_do_not_count_iterations(window, dialogs, qtbot):
    assert window.open_path(SAMPLES / "blob.obj")
    sub = window.panels["Subdivision"]
    sub.raise_()
    texts = []
    window.runner.preview.connect(lambda _s: texts.append(sub.status_label.text()))
    sub.form.set_params(sub.form.params().__class__(method="loop", levels=1))
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        sub.run_button.click()
    qtbot.waitUntil(lambda: sub.status_label.text().startswith("Done"), timeout=10000)
    assert sub.status_label.text().startswith("Done in ") and "iteration" not in \
        sub.status_label.text()
    assert not any(t.startswith("Iteration") and "/1000" in t for t in texts), texts
    window.undo_stack.undo()
    mg = window.panels["Multigrid smoothing"]
    mg.raise_()
    mg.live_box.setChecked(False)
    mg.form.set_value("solver", "direct")
    mg.signal_combo.setCurrentIndex(1)  # positions
    with qtbot.waitSignal(window.job_committed, timeout=120000):
        mg.run_button.click()
    qtbot.waitUntil(lambda: not window.runner.busy, timeout=10000)
    finished = [t for _s, _l, t in window.message_log.entries if "finished in" in t]
    assert finished and "Multigrid smoothing finished" in finished[-1]
    assert "iteration" not in finished[-1], finished[-1]
