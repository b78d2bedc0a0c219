"""File > Batch…: apply the current panel's settings to a whole folder of meshes.

The dialog builds the batch's job from the chosen panel's Params and ``job_options()``
(:func:`app.batch.job_from_settings`, exactly what ``stylize3d batch SETTINGS.json`` runs) and
runs :func:`app.batch.run_batch` on a QThread: the meshes are computed by worker processes, the
thread only waits for them, so the window stays responsive. Progress (done / failed / skipped /
remaining, rate, time left) and every mesh's record are shown as they come; Cancel stops the
batch (meshes in flight are abandoned and run again next time: the batch is resumable, and
starting it again on the same folder skips what is done). Results never replace files without
asking.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

from PySide6.QtCore import QThread, Signal
from PySide6.QtWidgets import (QComboBox, QDialog, QFormLayout, QHBoxLayout, QHeaderView, QLabel,
                               QLineEdit, QListWidget, QProgressBar, QPushButton, QSpinBox,
                               QTableWidget, QTableWidgetItem, QVBoxLayout)

from algorithms.errors import Stylize3DError
from app import dialogs


class BatchThread(QThread):
    """Runs one batch; ``record`` after every mesh, ``done`` with the summary or ``error``."""

    record = Signal(object, object)  # (record dict or None, counts dict)
    done = Signal(object)  # BatchSummary
    error = Signal(str)

    def __init__(self, job, inputs, out_dir, workers: int, parent=None):
        super().__init__(parent)
        self.job, self.inputs, self.out_dir, self.workers = job, inputs, out_dir, workers
        self.stop_requested = False

    def run(self) -> None:  # noqa: D401 - QThread
        from app.batch import run_batch

        try:
            summary = run_batch(self.job, self.inputs, self.out_dir, workers=self.workers,
                                on_record=lambda rec, counts: self.record.emit(rec, counts),
                                should_stop=lambda: self.stop_requested)
        except Stylize3DError as e:
            self.error.emit(str(e))
            return
        except Exception as e:  # noqa: BLE001 - shown to the user, never a traceback
            self.error.emit(f"The batch stopped unexpectedly: {type(e).__name__}: {e}")
            return
        self.done.emit(summary)


class BatchDialog(QDialog):
    """Apply a panel's current settings to many meshes (module docstring)."""

    def __init__(self, window):
        super().__init__(window)
        from app.batch import PANEL_METHODS

        self.window_ = window
        self.setWindowTitle("Batch: apply a panel's settings to many meshes")
        self.thread_: BatchThread | None = None
        self._running = False
        self.summary = None
        self._t0 = 0.0
        lay = QVBoxLayout(self)
        intro = QLabel("Runs the chosen panel with its current settings on every mesh you add "
                       "and writes each result under the output folder with the mesh's own "
                       "file name. You can keep working meanwhile; a batch that was stopped "
                       "continues where it left off when you start it again.")
        intro.setWordWrap(True)
        lay.addWidget(intro)
        form = QFormLayout()
        self.panel_combo = QComboBox()
        self.panel_combo.setToolTip("Whose settings to apply: the panel's form and its other "
                                    "choices (style, filter, weights, ...) as they are now.")
        titles = [t for t in window.panels if t in PANEL_METHODS]
        self.panel_combo.addItems(titles)
        front = next((t for t, p in window.panels.items() if t in titles and p.is_shown()), None)
        if front:
            self.panel_combo.setCurrentText(front)
        form.addRow("Method", self.panel_combo)
        # what the batch does differently from the panel (said before Start, never silently)
        self.note_label = QLabel()
        self.note_label.setWordWrap(True)
        self.note_label.setStyleSheet("color: #b45309;")
        self.note_label.setVisible(False)
        form.addRow("", self.note_label)
        self.inputs = QListWidget()
        self.inputs.setToolTip("Mesh files and folders (folders are searched with their "
                               "sub-folders for OBJ, PLY, STL, OFF, glb and .s3d files).")
        self.inputs.setMinimumHeight(70)
        self.inputs.setMaximumHeight(120)
        row = QHBoxLayout()
        self.add_files_button = QPushButton("Add files…")
        self.add_folder_button = QPushButton("Add folder…")
        self.remove_button = QPushButton("Remove")
        for b in (self.add_files_button, self.add_folder_button, self.remove_button):
            row.addWidget(b)
        row.addStretch(1)
        box = QVBoxLayout()
        box.addWidget(self.inputs)
        box.addLayout(row)
        form.addRow("Meshes", box)
        out_row = QHBoxLayout()
        self.out_edit = QLineEdit()
        self.out_edit.setPlaceholderText("a folder for the results")
        self.out_edit.setToolTip("Results go here under each mesh's own file name, with "
                                 "batch-report.jsonl (one line per mesh: status, message, "
                                 "seconds, the method's figures).")
        self.out_button = QPushButton("Choose…")
        out_row.addWidget(self.out_edit, 1)
        out_row.addWidget(self.out_button)
        form.addRow("Output folder", out_row)
        self.workers_spin = QSpinBox()
        self.workers_spin.setRange(1, max(1, os.cpu_count() or 1) * 4)
        self.workers_spin.setValue(max(1, os.cpu_count() or 1))
        self.workers_spin.setMaximumWidth(90)
        self.workers_spin.setToolTip("How many meshes are computed at once (one process each). "
                                     "The default is the number of processor cores.")
        form.addRow("Meshes at once", self.workers_spin)
        lay.addLayout(form)
        self.progress = QProgressBar()
        self.progress.setRange(0, 1)
        self.progress.setValue(0)
        lay.addWidget(self.progress)
        self.status = QLabel("Add meshes and an output folder, then Start.")
        self.status.setWordWrap(True)
        lay.addWidget(self.status)
        self.table = QTableWidget(0, 3)
        self.table.setHorizontalHeaderLabels(["Mesh", "Status", "Message"])
        self.table.horizontalHeader().setSectionResizeMode(2, QHeaderView.ResizeMode.Stretch)
        self.table.verticalHeader().setVisible(False)
        self.table.setEditTriggers(QTableWidget.EditTrigger.NoEditTriggers)
        self.table.setMinimumHeight(180)
        self.table.verticalHeader().setDefaultSectionSize(22)
        lay.addWidget(self.table, 1)
        buttons = QHBoxLayout()
        self.start_button = QPushButton("Start")
        self.start_button.setToolTip("Run the batch (already finished meshes are skipped).")
        self.cancel_button = QPushButton("Stop")
        self.cancel_button.setToolTip("Stop the batch; start it again later to continue.")
        self.cancel_button.setEnabled(False)
        self.close_button = QPushButton("Close")
        self.save_steps_button = QPushButton("Save as step file…")
        self.save_steps_button.setToolTip(
            "Save the chosen panel's settings as a step file (.toml) for the command line: "
            "stylize3d batch FILE.toml INPUT... -o OUT_DIR (more steps can be added to it).")
        self.save_steps_button.clicked.connect(self.save_step_file_dialog)
        buttons.addWidget(self.save_steps_button)
        buttons.addStretch(1)
        for b in (self.start_button, self.cancel_button, self.close_button):
            buttons.addWidget(b)
        lay.addLayout(buttons)
        self.add_files_button.clicked.connect(self.add_files_dialog)
        self.add_folder_button.clicked.connect(self.add_folder_dialog)
        self.remove_button.clicked.connect(self._remove_selected)
        self.out_button.clicked.connect(self.choose_output_dialog)
        self.out_edit.textChanged.connect(lambda _t: self._update_hint())
        self.start_button.clicked.connect(self.start)
        self.cancel_button.clicked.connect(self.stop)
        self.close_button.clicked.connect(self.close)
        self.panel_combo.currentTextChanged.connect(lambda _t: self.update_note())
        self.update_note()
        self.resize(720, 560)

    def save_step_file_dialog(self) -> bool:
        path = dialogs.save_file(self, "Save as step file", "Stylize3D step file (*.toml)", "")
        if not path:
            return False
        if not path.lower().endswith(".toml"):
            path += ".toml"
        return self.save_step_file(path)

    def save_step_file(self, path: str) -> bool:
        """Write the chosen panel's settings as a one-step step file (True when written)."""
        from algorithms.mesh.io import atomic_write
        from algorithms.params import params_to_dict
        from app.batch import PANEL_METHODS
        from app.batch.pipeline import step_file_text

        title = self.panel_combo.currentText()
        panel = self.window_.panels[title]
        try:
            text = step_file_text(PANEL_METHODS[title], params_to_dict(panel.form.params()),
                                  panel.job_options())
            atomic_write(path, lambda fh: fh.write(text.encode("utf-8")))
        except Stylize3DError as e:
            dialogs.error(self, "Cannot save the step file", str(e))
            return False
        self.status.setText(f"Saved {path}: stylize3d batch {Path(path).name} INPUT... -o "
                            "OUT_DIR runs it.")
        return True

    def update_note(self) -> None:
        """Say what the batch will do differently from the chosen panel (or hide the note)."""
        from app.batch import settings_note

        title = self.panel_combo.currentText()
        panel = self.window_.panels.get(title)
        note = settings_note(title, panel.job_options()) if panel is not None else ""
        self.note_label.setText(note)
        self.note_label.setVisible(bool(note))

    def showEvent(self, event) -> None:  # noqa: N802 - Qt override
        self.update_note()  # the panel's settings may have changed since the dialog was made
        super().showEvent(event)

    # -- inputs -----------------------------------------------------------------------------
    def add_inputs(self, paths) -> None:
        have = {self.inputs.item(i).text() for i in range(self.inputs.count())}
        for p in paths:
            if p and str(p) not in have:
                self.inputs.addItem(str(p))
                have.add(str(p))
        self._update_hint()

    def _update_hint(self) -> None:
        """The line under the progress bar says what is still missing, or that Start is ready
        (it kept saying "Add meshes and an output folder" after both were set)."""
        if self.running:
            return
        n = self.inputs.count()
        out = self.out_edit.text().strip()
        if not n and not out:
            text = "Add meshes and an output folder, then Start."
        elif not n:
            text = "Add meshes (files or folders), then Start."
        elif not out:
            text = "Choose an output folder, then Start."
        else:
            text = (f"Ready: {n} item(s) added; results go to {out}. Press Start.")
        self.status.setText(text)

    def add_files_dialog(self) -> None:
        from algorithms.mesh import file_filter

        path = dialogs.open_file(self, "Add meshes", file_filter(), self.window_._last_dir())
        if path:
            self.add_inputs([path])

    def add_folder_dialog(self) -> None:
        path = dialogs.open_folder(self, "Add a folder of meshes", self.window_._last_dir())
        if path:
            self.add_inputs([path])

    def choose_output_dialog(self) -> None:
        path = dialogs.open_folder(self, "Output folder", self.window_._last_dir())
        if path:
            self.out_edit.setText(path)

    def _remove_selected(self) -> None:
        for item in self.inputs.selectedItems():
            self.inputs.takeItem(self.inputs.row(item))
        self._update_hint()

    # -- running ----------------------------------------------------------------------------
    @property
    def running(self) -> bool:
        # True from Start until the thread's queued ``finished`` reaches this (GUI) thread, which
        # is after its ``done``/``error``: whoever sees ``running`` False also sees the summary.
        # (``QThread.isRunning()`` turns False before the queued ``done`` is delivered.)
        return self._running

    def _job(self):
        from app.batch import job_from_settings

        title = self.panel_combo.currentText()
        panel = self.window_.panels[title]
        return job_from_settings(title, panel.form.params(), panel.job_options())

    def start(self) -> bool:
        """Start the batch with the chosen panel's settings now (True when it started)."""
        from app.batch import collect_inputs_with_roots, output_names, plan

        if self.running:
            return False
        roots = [self.inputs.item(i).text() for i in range(self.inputs.count())]
        out_dir = self.out_edit.text().strip()
        if not roots or not out_dir:
            self.status.setText("Add at least one mesh or folder, and choose an output folder.")
            return False
        try:
            job = self._job()
            found = collect_inputs_with_roots(roots, out_dir=out_dir)
            if not found:
                raise Stylize3DError("No mesh files were found in what you added.")
            inputs = [p for p, _ in found]
            outputs = output_names(inputs, out_dir, roots=[r for _, r in found])
            items = plan(job, inputs, outputs, Path(out_dir) / "batch-report.jsonl")
        except Stylize3DError as e:
            dialogs.error(self, "Cannot start the batch", str(e))
            return False
        replaced = [it.output for it in items if it.action != "skip" and Path(it.output).exists()]
        if replaced and not dialogs.confirm(
                self, "Replace files?", f"{len(replaced)} file(s) in {out_dir} would be "
                f"replaced by new results (e.g. {Path(replaced[0]).name}). Replace them?",
                yes="Replace", no="Cancel"):
            return False
        self.table.setRowCount(0)
        for it in items:  # listed too: the meshes a finished earlier run already did
            if it.action == "skip":
                self._add_row(it.input, "skipped", it.reason)
        self.progress.setRange(0, len(inputs))
        self.progress.setValue(0)
        self.summary = None
        self._t0 = time.monotonic()
        self.thread_ = BatchThread(job, inputs, out_dir, self.workers_spin.value(), self)
        self.thread_.record.connect(self._on_record)
        self.thread_.done.connect(self._on_done)
        self.thread_.error.connect(self._on_error)
        self.thread_.finished.connect(self._on_thread_finished)
        self._set_running(True)
        self.status.setText(f"Starting {len(inputs)} mesh(es) with the "
                            f"{self.panel_combo.currentText()} panel's settings…")
        self.window_.report(f"Batch started: {len(inputs)} mesh(es) into {out_dir}.")
        self.thread_.start()
        return True

    def stop(self) -> None:
        if self.running:
            self.thread_.stop_requested = True
            self.status.setText("Stopping… (meshes being computed now will run again next "
                                "time)")
            self.cancel_button.setEnabled(False)

    def _set_running(self, on: bool) -> None:
        self._running = on
        for w in (self.start_button, self.panel_combo, self.add_files_button,
                  self.add_folder_button, self.remove_button, self.out_button, self.out_edit,
                  self.workers_spin):
            w.setEnabled(not on)
        self.cancel_button.setEnabled(on)

    def _on_record(self, rec, counts) -> None:
        finished = counts.get("done", 0) + counts.get("failed", 0) + counts.get("skipped", 0)
        self.progress.setValue(finished)
        total = self.progress.maximum()
        left = max(0, total - finished)
        rate = ""
        ran = counts.get("done", 0) + counts.get("failed", 0)
        dt = time.monotonic() - self._t0
        if ran and dt > 0:
            per_s = ran / dt
            rate = f" — {per_s:.2f} meshes/s, about {left / per_s:.0f} s left"
        self.status.setText(f"done {counts.get('done', 0)} · failed {counts.get('failed', 0)} · "
                            f"skipped {counts.get('skipped', 0)} · remaining {left}{rate}")
        if rec is None:
            return
        self._add_row(rec.get("input", ""), rec.get("status", ""), rec.get("message", ""))

    def _add_row(self, path, status: str, message: str) -> None:
        r = self.table.rowCount()
        self.table.insertRow(r)
        for c, text in enumerate((Path(path).name, status, message)):
            item = QTableWidgetItem(str(text))
            item.setToolTip(str(path) if c == 0 else str(text))
            self.table.setItem(r, c, item)
        self.table.scrollToBottom()

    def _on_done(self, summary) -> None:
        self.summary = summary
        c = summary.counts()
        what = "stopped" if summary.stopped else "finished"
        text = (f"Batch {what}: {c.get('done', 0)} done, {c.get('failed', 0)} failed, "
                f"{c.get('skipped', 0)} skipped in {summary.seconds:.1f} s. "
                f"Report: {summary.report}")
        self.status.setText(text)
        self.window_.report(text)

    def _on_error(self, message: str) -> None:
        self.status.setText(message)
        dialogs.error(self, "The batch stopped", message)

    def _on_thread_finished(self) -> None:
        self._set_running(False)

    def closeEvent(self, event) -> None:  # noqa: N802 - Qt override
        if self.running:
            if not dialogs.confirm(self, "Stop the batch?", "The batch is still running. "
                                   "Stop it? (Starting it again later continues it.)",
                                   yes="Stop", no="Keep running"):
                event.ignore()
                return
            self.stop()
            self.thread_.wait(60000)
        event.accept()
