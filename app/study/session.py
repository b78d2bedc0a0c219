"""The Qt side of user-study mode: start dialog, task bar, questionnaire, locking, logging.

:class:`StudySession` attaches to a running :class:`~app.main_window.MainWindow` from outside and
logs through the app's ONE job runner and ONE undo stack, so every panel (including panels added
later) is logged without code of its own:

* ``runner.started`` -> ``run`` (the panel's Params as a dict, its ``job_options()``, the hash of
  the input state, which is saved once per hash under ``<log>_files/states/`` for replay);
  ``finished`` / ``cancelled`` / ``failed`` -> ``result`` (``job_committed`` gives the result's
  hash);
* the undo stack's index -> ``undo`` / ``redo`` / ``edit`` (every other undoable change, e.g. a
  brush stroke: its text and before/after hashes);
* panel switches (a dock brought forward), camera moves (polled twice a second, logged when the
  camera stopped moving), ``open``.

A task locks the app to what the protocol allows in the session's condition: panels not allowed
are hidden (and cannot be re-opened from the Panels menu), locked panels are shown disabled, and
locked parameters keep their protocol values (their editors are disabled; Defaults cannot change
them). Results are saved next to the log: ``<log>_files/<task>.obj`` and
``<log>_files/<task>_answers.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from PySide6.QtCore import QObject, Qt, QTimer, Signal
from PySide6.QtWidgets import (QButtonGroup, QComboBox, QDialog, QDialogButtonBox, QFormLayout,
                               QHBoxLayout, QLabel, QLineEdit, QPlainTextEdit, QPushButton,
                               QRadioButton, QScrollArea, QToolBar, QVBoxLayout, QWidget)

from algorithms.errors import Stylize3DError
from algorithms.params import params_to_dict
from app.widgets import dock_view_action

from .log import LogData, SessionLog, state_hash
from .protocol import Protocol, StudyError, Task, check_against_panels

CAMERA_POLL_MS = 500


def _state_hash(state) -> str:
    return state_hash(state.V, state.F, state.fields, state.handles)


def _edit_details(cmd) -> dict:
    """What an undoable edit changed, from its before/after states: per field the vertices whose
    value changed and their new values, moved vertices, handles; plus ``log_details`` a tool put
    on its command (brush radius, strength, ...)."""
    out = dict(getattr(cmd, "log_details", None) or {})
    before, after = getattr(cmd, "before", None), getattr(cmd, "after", None)
    if before is None or after is None or before.V.shape != after.V.shape:
        return out
    fields = {}
    for name in sorted(set(before.fields) | set(after.fields)):
        a, b = before.fields.get(name), after.fields.get(name)
        if a is None or b is None:
            fields[name] = {"added" if a is None else "removed": True}
            continue
        changed = np.flatnonzero(~((a == b) | (np.isnan(a) & np.isnan(b))))
        if changed.size:
            fields[name] = {"vertices": changed, "values": b[changed]}
    if fields:
        out["fields"] = fields
    moved = np.flatnonzero((before.V != after.V).any(axis=1))
    if moved.size:
        out["moved_vertices"] = moved
    if before.handles != after.handles:
        out["handles"] = [[int(v), list(p)] for v, p in after.handles]
    return out


# ------------------------------------------------------------------------------ dialogs
class StartDialog(QDialog):
    """Participant code and condition; says when a session for that code can be resumed."""

    def __init__(self, protocol: Protocol, log_dir: Path, parent=None):
        super().__init__(parent)
        self.setWindowTitle(f"Start study session — {protocol.study}")
        self.protocol, self.log_dir = protocol, Path(log_dir)
        lay = QFormLayout(self)
        self.code = QLineEdit()
        self.code.setPlaceholderText("e.g. P07")
        self.code.setToolTip("The participant code from your study plan. Nothing else about the "
                             "participant is recorded.")
        self.condition = QComboBox()
        self.condition.addItems(list(protocol.conditions))
        self.condition.setToolTip("The study condition this participant is in.")
        self.note = QLabel("")
        self.note.setWordWrap(True)
        lay.addRow("Participant code", self.code)
        lay.addRow("Condition", self.condition)
        lay.addRow(self.note)
        self.buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok
                                        | QDialogButtonBox.StandardButton.Cancel)
        self.buttons.button(QDialogButtonBox.StandardButton.Ok).setText("Start")
        self.buttons.accepted.connect(self.accept)
        self.buttons.rejected.connect(self.reject)
        lay.addRow(self.buttons)
        self.code.textChanged.connect(self._update)
        self._update()

    def log_path(self) -> Path:
        return log_path_for(self.log_dir, self.protocol.study, self.code.text().strip())

    def _update(self) -> None:
        code = self.code.text().strip()
        ok = bool(code) and code.replace("-", "").replace("_", "").isalnum()
        self.buttons.button(QDialogButtonBox.StandardButton.Ok).setEnabled(ok)
        if ok and self.log_path().exists():
            self.note.setText(f"A session for {code} exists: Start resumes it where it stopped.")
        elif code and not ok:
            self.note.setText("Use letters, digits, '-' or '_' only.")
        else:
            self.note.setText("")


class QuestionnaireDialog(QDialog):
    """Likert items (one row of radio buttons each) and free-text items; OK once every Likert
    item is answered."""

    def __init__(self, task: Task, parent=None):
        super().__init__(parent)
        self.setWindowTitle(f"Questions about '{task.title}'")
        self.task = task
        outer = QVBoxLayout(self)
        intro = QLabel("Please answer these questions about the task you just did.")
        intro.setWordWrap(True)
        outer.addWidget(intro)
        body = QWidget()
        form = QVBoxLayout(body)
        self.groups: dict[str, QButtonGroup] = {}
        self.texts: dict[str, QPlainTextEdit] = {}
        for k, item in enumerate(task.questionnaire, start=1):
            q = QLabel(f"{k}. {item.text}")
            q.setWordWrap(True)
            q.setStyleSheet("font-weight: bold; margin-top: 6px;")
            form.addWidget(q)
            if item.type == "likert":
                row = QHBoxLayout()
                row.addWidget(QLabel(item.labels[0]))
                g = QButtonGroup(self)
                for v in range(1, item.scale + 1):
                    b = QRadioButton(str(v))
                    b.setToolTip(f"{v} of {item.scale}")
                    g.addButton(b, v)
                    row.addWidget(b)
                row.addWidget(QLabel(item.labels[1]))
                row.addStretch(1)
                g.idClicked.connect(lambda _v: self._update())
                self.groups[item.id] = g
                form.addLayout(row)
            else:
                t = QPlainTextEdit()
                t.setPlaceholderText("(optional)")
                t.setMaximumHeight(70)
                self.texts[item.id] = t
                form.addWidget(t)
        form.addStretch(1)  # a short questionnaire stays together at the top (no big gaps)
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setWidget(body)
        outer.addWidget(scroll, 1)
        foot = QHBoxLayout()
        self.progress = QLabel("")
        self.progress.setStyleSheet("color: #555;")
        foot.addWidget(self.progress, 1)
        self.buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok)
        self.buttons.accepted.connect(self.accept)
        foot.addWidget(self.buttons)
        outer.addLayout(foot)
        # as tall as its questions need, up to 520 px (then the questions scroll)
        need = body.sizeHint().height() + intro.sizeHint().height() + 90
        self.resize(640, max(240, min(520, need)))
        self._update()

    def reject(self) -> None:  # noqa: D401 - Qt override
        """Esc or the window's close button: the questions must be answered to go on (a
        questionnaire left open would leave the task neither finished nor running)."""
        self.progress.setText("Please answer the questions to go on (OK when done).")
        self.progress.setStyleSheet("color: #b45309;")

    def set_answer(self, item_id: str, value) -> None:
        """Answer one item as the participant would (tests, scripted sessions)."""
        if item_id in self.groups:
            self.groups[item_id].button(int(value)).click()
        else:
            self.texts[item_id].setPlainText(str(value))
        self._update()

    def answers(self) -> dict:
        out = {k: g.checkedId() for k, g in self.groups.items() if g.checkedId() > 0}
        out.update({k: t.toPlainText() for k, t in self.texts.items()})
        return out

    def _update(self) -> None:
        n = sum(g.checkedId() > 0 for g in self.groups.values())
        done = n == len(self.groups)
        self.progress.setText("" if done else
                              f"{n} of {len(self.groups)} answered: answer each scale to go on.")
        self.buttons.button(QDialogButtonBox.StandardButton.Ok).setEnabled(done)


class TaskBar(QToolBar):
    """Instructions, elapsed time, Done and Skip."""

    def __init__(self, parent=None):
        super().__init__("Study task", parent)
        self.setObjectName("study_task_bar")
        self.setMovable(False)
        w = QWidget()
        lay = QHBoxLayout(w)
        lay.setContentsMargins(6, 2, 6, 2)
        self.title = QLabel("")
        self.title.setStyleSheet("font-weight: bold;")
        self.instructions = QLabel("")
        self.instructions.setWordWrap(True)
        self.instructions.setMinimumWidth(300)
        self.clock = QLabel("0:00")
        self.clock.setToolTip("Time spent on this task")
        self.clock.setStyleSheet("font-family: monospace; font-size: 14px;")
        self.more = QPushButton("Instructions…")
        self.more.setToolTip("Show the whole instructions (and their picture) again.")
        self.done = QPushButton("Done")
        self.done.setToolTip("I have finished this task: save the result and go on.")
        self.done.setStyleSheet("font-weight: bold;")
        self.skip = QPushButton("Skip")
        self.skip.setToolTip("Give up this task and go on to the next one.")
        lay.addWidget(self.title)
        lay.addWidget(self.instructions, 1)
        lay.addWidget(self.clock)
        lay.addWidget(self.more)
        lay.addWidget(self.skip)
        lay.addWidget(self.done)
        self.addWidget(w)


def log_path_for(log_dir: Path, study: str, participant: str) -> Path:
    return Path(log_dir) / f"{study}_{participant}.jsonl"


# ------------------------------------------------------------------------------ the session
class StudySession(QObject):
    """Runs a study protocol in a MainWindow and logs every action (module docstring)."""

    task_started = Signal(str)
    task_ended = Signal(str, str)
    session_ended = Signal()

    def __init__(self, window, protocol: Protocol, log: SessionLog, *,
                 resumed: LogData | None = None):
        super().__init__(window)
        self.window, self.protocol, self.log = window, protocol, log
        self.condition = log.header["condition"]
        self.order: list[str] = list(log.header["task_order"])
        done = set(resumed.finished_tasks) if resumed else set()
        self.remaining = [t for t in self.order if t not in done]
        self.task: Task | None = None
        self.questionnaire_dialog: QuestionnaireDialog | None = None
        self._resumed = resumed
        self._task_t0 = 0.0  # the task_start event's t_mono (the log's clock)
        self._locked: dict[str, dict] = {}
        self._saved_states: set[str] = set()
        self._pending_runs: dict[str, dict] = {}
        self._job_names: set[str] = set()  # names of the jobs run (their commits are runs)
        self._ended = False  # the current task has ended (its questions may still be open)
        self._setting_up = False  # the app itself is showing / hiding panels
        self.finished = False
        check_against_panels(protocol, {t: getattr(p, "params_cls", object)
                                        for t, p in window.panels.items()})
        # the task bar
        self.bar = TaskBar(window)
        window.addToolBar(Qt.ToolBarArea.TopToolBarArea, self.bar)
        window.insertToolBarBreak(self.bar)
        self.bar.show()
        self.bar.done.clicked.connect(lambda: self.end_task("done"))
        self.bar.skip.clicked.connect(lambda: self.end_task("skipped"))
        self.bar.more.clicked.connect(self.show_instructions)
        self._tick = QTimer(self)
        self._tick.setInterval(1000)
        self._tick.timeout.connect(self._on_tick)
        # logging hooks: the one job runner, the one undo stack
        r = window.runner
        r.started.connect(self._on_run_started)
        r.finished.connect(lambda step: self._on_run_ended("done", "", step))
        r.cancelled.connect(lambda msg: self._on_run_ended("cancelled", msg))
        r.failed.connect(lambda msg, _d: self._on_run_ended("failed", msg))
        window.job_committed.connect(self._on_committed)
        self._snapshot_undo()
        window.undo_stack.indexChanged.connect(self._on_undo_index)
        for title, panel in window.panels.items():
            panel.visibilityChanged.connect(
                lambda vis, t=title: self._on_panel_shown(t) if vis else None)
            form = getattr(panel, "form", None)
            if form is not None:
                form.changed.connect(lambda _p, t=title: self._reapply_locks(t))
        self._camera = None
        self._camera_moving = False
        self._cam_timer = QTimer(self)
        self._cam_timer.setInterval(CAMERA_POLL_MS)
        self._cam_timer.timeout.connect(self._poll_camera)
        self._cam_timer.start()

    # -- flow ----------------------------------------------------------------------------------
    def start(self) -> None:
        """Begin (or continue) with the first task not finished yet."""
        if self.log.task and self.log.task in self.remaining:  # resumed mid-task
            self.remaining.remove(self.log.task)
            self._begin(self.log.task, resumed=True)
        else:
            self._next()

    def _next(self) -> None:
        if not self.remaining:
            self._finish_session()
            return
        self._begin(self.remaining.pop(0))

    def _begin(self, task_id: str, resumed: bool = False) -> None:
        task = self.protocol.task(task_id)
        self.task = task
        self._ended = False
        for b in (self.bar.done, self.bar.skip):
            b.setEnabled(True)
        self.log.task = task.id
        if not resumed:
            ev = self._log("task_start", title=task.title)
            self._task_t0 = ev["t_mono"] if ev else self.log.now()
        else:
            # the task's time goes on from where it was when the app stopped (the log's clock
            # leaves out the time the app was not running)
            starts = [e["t_mono"] for e in (self._resumed.events if self._resumed else [])
                      if e.get("action") == "task_start" and e.get("task") == task.id]
            self._task_t0 = starts[-1] if starts else self.log.now()
        mesh = task.mesh
        if mesh.startswith("sample:"):
            from algorithms.mesh.samples import sample_path

            mesh = str(sample_path(mesh.split(":", 1)[1]))
        self.window.undo_stack.setClean()
        self.window.document.modified = False
        # opening clears the undo stack: that is not an undo of the participant's
        self._opening = True
        try:
            opened = self.window.open_path(mesh)
        finally:
            self._opening = False
        if not opened:
            self._log("task_end", status="failed", message=f"could not open {mesh}")
            self.task_ended.emit(task.id, "failed")
            self._next()
            return
        self._snapshot_undo()
        st = self.window.document.state
        self._log("open", mesh=task.mesh, mesh_hash=_state_hash(st),
                  state_file=self._save_state(st)[1])
        self._apply_setup(task)
        # the camera the task opens with is where moves are counted from (the app placed it)
        self._camera, self._camera_moving = self._camera_now(), False
        self.bar.title.setText(f"Task {len(self.order) - len(self.remaining)} of "
                               f"{len(self.order)}: {task.title}")
        self.bar.instructions.setText(task.instructions)
        self._tick.start()
        self._on_tick()
        self.task_started.emit(task.id)
        if not resumed and task.image:
            self.show_instructions()

    def end_task(self, status: str = "done") -> None:
        """Done / Skip / time up: save the result, ask the questions, go on."""
        task = self.task
        if task is None or self._ended:
            return  # a task ends once (a second Done while its questions are open does nothing)
        self._ended = True
        for b in (self.bar.done, self.bar.skip):
            b.setEnabled(False)
        if self.window.runner.busy:
            self.window.runner.cancel()
            self.window.runner.wait(30000)
        self._tick.stop()
        st = self.window.document.state
        h = _state_hash(st) if st is not None else ""
        if st is not None:
            from algorithms.mesh import write_mesh

            try:
                write_mesh(self.log.results_dir / f"{task.id}.obj", st.V, st.F)
            except Stylize3DError as e:
                self._log("note", message=f"result not saved: {e}")
        # one definition of a task's time (the summary's "seconds"): task_start to task_end on
        # the log's clock, the time the app was not running left out
        t = self.log.now()
        self._log("task_end", at=t, status=status, result_hash=h,
                  seconds=round(t - self._task_t0, 3))
        self.task_ended.emit(task.id, status)
        if task.questionnaire:
            self.questionnaire_dialog = QuestionnaireDialog(task, self.window)
            self.questionnaire_dialog.accepted.connect(self._on_answers)
            self.questionnaire_dialog.open()
        else:
            self._after_task()

    def _on_answers(self) -> None:
        dlg, self.questionnaire_dialog = self.questionnaire_dialog, None
        answers = dlg.answers()
        self._log("questionnaire", answers=answers, name=self.task.questionnaire_name)
        path = self.log.results_dir / f"{self.task.id}_answers.json"
        path.write_text(json.dumps(answers, indent=2, ensure_ascii=False))
        dlg.deleteLater()
        self._after_task()

    def _after_task(self) -> None:
        self._unlock()
        self.task = None
        self.log.task = None
        self._next()

    def _finish_session(self) -> None:
        self._log("session_end")
        self.finished = True
        # every task's result is saved next to the log: quitting must not ask the participant
        # to discard changes to the sample mesh (issue 41)
        self.window.undo_stack.setClean()
        self.window.document.modified = False
        self.window._update_title()
        self._cam_timer.stop()
        self._tick.stop()
        self.bar.clock.setText("")
        self._unlock()
        self._setting_up = True  # the app shows the panels again, not the participant
        try:
            for panel in self.window.panels.values():
                panel.setVisible(True)
        finally:
            self._setting_up = False
        self.bar.title.setText("Session complete")
        self.bar.instructions.setText("Thank you! You can close the app now.")
        for b in (self.bar.done, self.bar.skip, self.bar.more):
            b.setEnabled(False)
        self.session_ended.emit()

    def show_instructions(self) -> None:
        if self.task is None:
            return
        from app import dialogs

        text = self.task.instructions
        if self.task.image:
            text += f"\n\n(Picture: {Path(self.task.image).name})"
        dialogs.info(self.window, self.task.title, text)

    def _on_tick(self) -> None:
        if self.task is None:
            return
        s = int(self.log.now() - self._task_t0)
        lim = self.task.time_limit_s
        if lim:
            left = max(0, int(lim) - s)
            self.bar.clock.setText(f"{s // 60}:{s % 60:02d} ({left // 60}:{left % 60:02d} left)")
            if s >= lim:
                self.end_task("timeout")
        else:
            self.bar.clock.setText(f"{s // 60}:{s % 60:02d}")

    # -- locking -------------------------------------------------------------------------------
    def _on_panel_shown(self, title: str) -> None:
        """A panel came forward: logged when the participant did it, not when a task's set-up
        showed or hid panels."""
        if self.log.task and not self._setting_up and not self.finished:
            self._log("panel", title=title)

    def _apply_setup(self, task: Task) -> None:
        self._setting_up = True
        try:
            self._apply_setup_now(task)
        finally:
            self._setting_up = False

    def _apply_setup_now(self, task: Task) -> None:
        setup = task.setup(self.condition)
        self._locked = {name: dict(values) for name, values in setup.params.items()}
        for title, panel in self.window.panels.items():
            allowed = setup.panels is None or title in setup.panels or title in setup.locked_panels
            locked = title in setup.locked_panels
            dock_view_action(panel).setEnabled(allowed)
            panel.setVisible(allowed)
            body = panel.widget()
            if body is not None:
                body.setEnabled(not locked)
                body.setToolTip("Locked in this task." if locked else "")
            form = getattr(panel, "form", None)
            if form is None:
                continue
            for name, w in form.editors.items():
                w.setEnabled(name not in self._locked.get(title, {}))
            self._reapply_locks(title)
        usable = [p for t, p in self.window.panels.items()
                  if (setup.panels is None or t in setup.panels) and t not in setup.locked_panels]
        if usable and setup.panels is not None:
            usable[0].raise_()  # the panel the task is about comes forward

    def _reapply_locks(self, title: str) -> None:
        values = self._locked.get(title)
        panel = self.window.panels.get(title)
        if not values or panel is None:
            return
        form = panel.form
        current = params_to_dict(form.params())
        if any(current.get(k) != v for k, v in values.items()):
            from algorithms.params import params_from_dict

            form.set_params(params_from_dict(form.params_cls, {**current, **values}))

    def _unlock(self) -> None:
        self._locked = {}
        for panel in self.window.panels.values():
            dock_view_action(panel).setEnabled(True)
            if panel.widget() is not None:
                panel.widget().setEnabled(True)
            form = getattr(panel, "form", None)
            if form is not None:
                for w in form.editors.values():
                    w.setEnabled(True)

    # -- logging -------------------------------------------------------------------------------
    def _log(self, action: str, **fields) -> dict | None:
        try:
            return self.log.write(action, **fields)
        except (OSError, StudyError) as e:  # never lose the participant's work over the log
            from app import dialogs

            dialogs.error(self.window, "Study log", f"The session log could not be written: {e}")
            return None

    def _save_state(self, state) -> tuple[str, str]:
        """Save a document state for replay (once per hash); returns (hash, relative file).
        Arrays are stored once per content (a brush stroke adds one field's values, not a
        copy of the mesh), see :func:`app.study.log.save_state`."""
        from .log import save_state

        h = _state_hash(state)
        rel = f"states/{h[:32]}.json"
        if h not in self._saved_states:
            save_state(self.log.results_dir, state, rel)
            self._saved_states.add(h)
        return h, rel

    def _save_blobs(self, options) -> None:
        """Keep the binary inputs a run's options refer to (images, meshes) for replay."""
        from app.recipes import blob_bytes, blob_refs

        for ref in blob_refs(options):
            digest, name = ref[len("blob:"):].split("/", 1)
            d = self.log.results_dir / "blobs" / digest
            if not (d / name).is_file():
                d.mkdir(parents=True, exist_ok=True)
                (d / name).write_bytes(blob_bytes(ref))

    def _on_run_started(self, name: str) -> None:
        if self.log.task is None:
            return
        # the newest request of any panel (a panel may start jobs under other names, such as
        # Multigrid's "Mean curvature flow"); a request is used for one job only
        self._job_names.add(name)
        req, seq = None, getattr(self, "_request_seq", 0)
        for panel in self.window.panels.values():
            s = getattr(panel, "last_request_seq", 0)
            if s > seq and getattr(panel, "last_request", None) is not None:
                req, seq = panel.last_request, s
        self._request_seq = seq
        rec: dict = {"method": name}
        if req is not None:
            rec["recipe"] = req.get("recipe") or name
            rec["params"] = params_to_dict(req["params"])
            rec["options"] = req.get("options", {})
            try:
                self._save_blobs(rec["options"])
            except (OSError, Stylize3DError) as e:
                self._log("note", message=f"an input of this run was not saved: {e}")
            h, rel = self._save_state(req["input"])
            rec["input_hash"], rec["input_file"] = h, rel
        elif self.window.document.state is not None:
            rec["input_hash"] = _state_hash(self.window.document.state)
        self._pending_runs[name] = rec
        self._log("run", **rec)

    def _on_run_ended(self, status: str, message: str, step=None) -> None:
        name = self.window.runner.name or getattr(self.window, "last_job_name", None)
        name = name or "?"
        rec = self._pending_runs.get(name, {"method": name})
        if status == "done" and name in self._pending_runs and step is not None:
            self._log_analysis(name, rec, step)
        if status != "done":
            self._pending_runs.pop(name, None)
            self._log("result", method=name, status=status, message=message,
                      params=rec.get("params", {}),
                      seconds=round(self.window.runner.last_duration, 3))

    def _log_analysis(self, name: str, rec: dict, step) -> None:
        """A finished run that changed nothing in the document (an analysis recipe: spectral
        coarsening, a lighting attack, a training run): logged with the hash of its outcome."""
        from app.recipes import outcome_hash, recipes, unchanged_result

        recipe = recipes().get(rec.get("recipe", name))
        if recipe is None or recipe.result is not unchanged_result:
            return  # a result that was not committed (e.g. the mesh changed meanwhile)
        self._pending_runs.pop(name, None)
        out = recipe.outcome(step) if recipe.outcome is not None else {}
        st = self.window.document.state
        self._log("result", method=name, recipe=recipe.name, status="done",
                  params=rec.get("params", {}), options=rec.get("options", {}),
                  input_hash=rec.get("input_hash", ""),
                  result_hash=_state_hash(st) if st is not None else "",
                  outcome_hash=outcome_hash(out or {}),
                  seconds=round(self.window.runner.last_duration, 3))

    def _on_committed(self, name: str, after) -> None:
        rec = self._pending_runs.pop(name, {"method": name})
        self._snapshot_undo()
        h, rel = self._save_state(after)
        self._log("result", method=name, recipe=rec.get("recipe", name), status="done",
                  params=rec.get("params", {}),
                  options=rec.get("options", {}), input_hash=rec.get("input_hash", ""),
                  result_hash=h, result_file=rel,
                  seconds=round(self.window.runner.last_duration, 3))

    def _snapshot_undo(self) -> None:
        st = self.window.undo_stack
        self._undo_index = st.index()
        self._undo_cmds = [(st.command(i), st.command(i).text()) for i in range(st.count())]

    def _on_undo_index(self, index: int) -> None:
        import shiboken6

        st = self.window.undo_stack
        if not shiboken6.isValid(st) or not shiboken6.isValid(self.window):
            return  # the window is being destroyed (quitting): nothing the participant did
        if getattr(self, "_opening", False):
            self._snapshot_undo()
            return
        old, cmds = self._undo_index, self._undo_cmds
        now = [st.command(i) for i in range(st.count())]
        doc = self.window.document.state
        h = _state_hash(doc) if doc is not None else ""
        rel = self._save_state(doc)[1] if doc is not None and index != old else None
        if index < old:
            for i in range(old - 1, index - 1, -1):
                self._log("undo", text=cmds[i][1] if i < len(cmds) else "", result_hash=h,
                          result_file=rel)
        elif index > old:
            for i in range(old, index):
                redo = (i < len(cmds) and shiboken6.isValid(cmds[i][0])
                        and cmds[i][0] is now[i])
                if redo:
                    self._log("redo", text=cmds[i][1], result_hash=h, result_file=rel)
                elif not (now[i].text().startswith(tuple(self.window.panels))
                          or now[i].text() in self._job_names):
                    # runs are logged as run/result; every other undoable change is an edit,
                    # with what it changed and the tool's inputs (app.edits re-computes it
                    # from the saved input state)
                    extra = {}
                    try:  # files the edit read (a loaded field), kept for replay
                        self._save_blobs(getattr(now[i], "log_details", None) or {})
                    except (OSError, Stylize3DError) as e:
                        self._log("note", message=f"an input of this edit was not saved: {e}")
                    before = getattr(now[i], "before", None)
                    if before is not None and hasattr(before, "V"):
                        extra["before_hash"], extra["before_file"] = self._save_state(before)
                    self._log("edit", text=now[i].text(), after_hash=h, after_file=rel,
                              **extra, **_edit_details(now[i]))
        self._snapshot_undo()

    def _camera_now(self) -> dict | None:
        pose = getattr(self.window.viewport, "camera_pose", None)
        return pose() if callable(pose) else None

    def _poll_camera(self) -> None:
        if self.log.task is None:
            return
        cam = self._camera_now()
        if cam is None:
            return
        if self._camera is None:  # the first pose seen is not a move
            self._camera = cam
            return
        if cam != self._camera:
            self._camera = cam
            self._camera_moving = True
        elif self._camera_moving:  # it stopped moving: one event per camera move
            self._camera_moving = False
            self._log("camera", **cam)


# ------------------------------------------------------------------------------ entry point
def start_study(window, protocol_path, *, log_dir=None, participant: str | None = None,
                condition: str | None = None, ask=None) -> StudySession | None:
    """Open a protocol and start (or resume) a session in ``window``.

    Without ``participant`` / ``condition`` the start dialog asks (``ask(dialog) -> bool`` runs
    it; default: ``dialog.exec()``). Returns None when the experimenter cancels.
    """
    from .protocol import load_protocol

    protocol = load_protocol(protocol_path)
    log_dir = Path(log_dir) if log_dir else Path(protocol_path).resolve().parent / "logs"
    if participant is None or condition is None:
        dlg = StartDialog(protocol, log_dir, window)
        if participant:
            dlg.code.setText(participant)
        if condition:
            dlg.condition.setCurrentText(condition)
        ok = ask(dlg) if ask is not None else dlg.exec() == QDialog.DialogCode.Accepted
        if not ok:
            return None
        participant, condition = dlg.code.text().strip(), dlg.condition.currentText()
    if condition not in protocol.conditions:
        raise StudyError(f"The study has no condition '{condition}' (conditions: "
                         f"{', '.join(protocol.conditions)}).")
    path = log_path_for(log_dir, protocol.study, participant)
    resumed = None
    if path.exists():
        log, resumed = SessionLog.resume(path)
        if resumed.header.get("protocol_sha256") != protocol.sha256:
            log.write("note", message="the protocol file changed since this session started")
    else:
        from app import __version__ as version

        log = SessionLog.create(path, study=protocol.study, protocol_path=protocol.path,
                                protocol_sha256=protocol.sha256, participant=participant,
                                condition=condition, task_order=protocol.task_order(participant),
                                app_version=version)
    session = StudySession(window, protocol, log, resumed=resumed)
    window.study_session = session
    session.start()
    return session
