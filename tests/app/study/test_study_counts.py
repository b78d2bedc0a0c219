"""Study mode that researchers can trust (issue 24, item 8): a questionnaire cannot be escaped,
each task has exactly one start and one end, only the participant's own undo / redo / panel
switches are counted, the end screen is clean — and a scripted two-task session's summary CSV is
checked column by column against what the script did."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
from PySide6.QtCore import Qt

from app.study.log import read_log
from app.study.summary import BASE_COLUMNS, summary_csv


def _protocol(tmp_path):
    data = {"study": "counts", "conditions": ["A"],
            "tasks": [{"id": "first", "title": "Smooth it", "instructions": "Smooth.",
                       "mesh": "sample:blob",
                       "questionnaire": [{"id": "ease", "type": "likert", "text": "Easy?",
                                          "scale": 7},
                                         {"id": "why", "type": "text", "text": "Why?"}],
                       "conditions": {"A": {"panels": ["Smooth", "Cubic"],
                                            "params": {"Smooth": {"iterations": 2}}}}},
                      {"id": "second", "title": "Cube it", "instructions": "Cube.",
                       "mesh": "sample:bumpy", "questionnaire": "sus",
                       "conditions": {"A": {"panels": ["Cubic"]}}}]}
    p = tmp_path / "study.json"
    p.write_text(json.dumps(data))
    return p


def test_two_task_session_counts_exactly_what_the_participant_did(window, dialogs, qtbot,
                                                                  tmp_path):
    from app.study.session import start_study

    session = start_study(window, _protocol(tmp_path), log_dir=tmp_path / "logs",
                          participant="P11", condition="A")
    log_path = session.log.path
    smooth, cubic = window.panels["Smooth"], window.panels["Cubic"]
    # task 1: the set-up brought Cubic (the first allowed panel) forward — not counted; the
    # participant switches to Smooth, to Cubic and back to Smooth (3 panel switches), runs
    # Smooth twice, undoes once, redoes once, and paints one λ stroke
    assert cubic.is_shown()
    for p in (smooth, cubic, smooth):
        p.raise_()
        qtbot.wait(50)
    for _ in range(2):
        with qtbot.waitSignal(window.job_committed, timeout=120000):
            smooth.run_button.click()
    window.undo_stack.undo()
    window.undo_stack.redo()
    from app.viewport import PickResult

    V = window.document.V
    brush = cubic.lambda_brush
    brush.press(PickResult(np.array(V[0]), 0, (0, 0)))
    brush.release()
    session.bar.done.click()
    dlg = session.questionnaire_dialog
    assert dlg is not None and dlg.isVisible()
    # two questions: a compact dialog, the scale right under its question (issue 41 item 10:
    # large empty gaps between them)
    from PySide6.QtCore import QPoint

    first = dlg.groups["ease"].buttons()[0].mapTo(dlg, QPoint(0, 0)).y()
    text = dlg.texts["why"].mapTo(dlg, QPoint(0, 0)).y()
    assert dlg.height() <= 360 and first < 120 and text - first < 100, (dlg.height(), first,
                                                                         text)
    # Esc does not close it; Done again does not end the task twice
    qtbot.keyClick(dlg, Qt.Key.Key_Escape)
    assert dlg.isVisible() and "answer the questions" in dlg.progress.text()
    assert not session.bar.done.isEnabled()
    session.end_task("done")
    dlg.set_answer("ease", 6)
    dlg.set_answer("why", "fine")
    dlg.accept()
    # task 2: nothing but the SUS questionnaire after Skip
    assert session.task.id == "second"
    assert session.bar.done.isEnabled()
    session.bar.skip.click()
    sus = session.questionnaire_dialog
    for i in range(1, 11):
        sus.set_answer(f"sus{i}", 5 if i % 2 else 1)  # the best answers: SUS 100
    sus.accept()
    assert session.finished
    # a clean end screen: no clock running, every panel back
    assert session.bar.clock.text() == "" and not session._tick.isActive()
    assert all(p.isVisible() and p.toggleViewAction().isEnabled()
               for p in window.panels.values())
    ev = read_log(log_path).events
    assert [e["task"] for e in ev if e["action"] == "task_start"] == ["first", "second"]
    assert [e["task"] for e in ev if e["action"] == "task_end"] == ["first", "second"]
    text, warnings = summary_csv([log_path])
    assert not warnings
    rows = list(csv.DictReader(io.StringIO(text)))
    cols = list(rows[0])
    assert cols == BASE_COLUMNS + ["q_sus1", "q_sus2", "q_sus3", "q_sus4", "q_sus5", "q_sus6",
                                   "q_sus7", "q_sus8", "q_sus9", "q_sus10", "q_ease", "q_why",
                                   "sus_score"]
    a, b = rows
    expect_a = {"study": "counts", "participant": "P11", "condition": "A", "order": "1",
                "task": "first", "status": "done", "runs": "2", "failed_runs": "0",
                "undo": "1", "redo": "1", "camera_moves": "0",
                # 2 runs + 1 undo + 1 redo + 1 stroke + 3 panel switches + 1 questionnaire
                "actions": "9", "q_ease": "6", "q_why": "fine", "sus_score": ""}
    for k, v in expect_a.items():
        assert a[k] == v, (k, a[k], v)
    assert json.loads(a["final_params"])["Smooth"]["iterations"] == 2
    assert float(a["seconds"]) > 0 and len(a["result_hash"]) == 64
    assert all(a[f"q_sus{i}"] == "" for i in range(1, 11))
    expect_b = {"order": "2", "task": "second", "status": "skipped", "runs": "0",
                "failed_runs": "0", "undo": "0", "redo": "0", "camera_moves": "0",
                "actions": "1", "final_params": "{}", "q_ease": "", "q_why": "",
                "sus_score": "100.0"}
    for k, v in expect_b.items():
        assert b[k] == v, (k, b[k], v)
    assert [b[f"q_sus{i}"] for i in range(1, 11)] == ["5", "1"] * 5
    ends = [e for e in ev if e["action"] == "task_end"]
    assert a["result_hash"] == ends[0]["result_hash"] and b["result_hash"] == ends[1]["result_hash"]
    # one definition of a task's time: the CSV's seconds are task_end's seconds, exactly
    assert [a["seconds"], b["seconds"]] == [str(e["seconds"]) for e in ends]
    # final_params: the params of the run the task ended on (the second Smooth, undone and
    # redone, then a stroke on it)
    results = [e for e in ev if e["action"] == "result" and e["task"] == "first"]
    assert len(results) == 2
    assert json.loads(a["final_params"]) == {"Smooth": results[1]["params"]}


def test_camera_moves_count_only_the_participants_moves(window, dialogs, qtbot, tmp_path):
    """The camera the app places when a task opens its mesh is not a move (a task that lasted
    over a second counted one); one real rotation is one move."""
    from app.study.session import CAMERA_POLL_MS, start_study

    session = start_study(window, _protocol(tmp_path), log_dir=tmp_path / "logs",
                          participant="P12", condition="A")
    qtbot.wait(4 * CAMERA_POLL_MS)  # idle: several polls
    assert not [e for e in read_log(session.log.path).events if e["action"] == "camera"]
    cam = window.viewport.plotter.camera
    cam.azimuth = cam.azimuth + 30.0  # the participant turns the model
    window.viewport.render()
    qtbot.wait(4 * CAMERA_POLL_MS)
    cams = [e for e in read_log(session.log.path).events if e["action"] == "camera"]
    assert len(cams) == 1 and cams[0]["task"] == "first"
