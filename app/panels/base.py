"""The pattern every method panel copies: Params form, Run/Stop, live re-run, streamed preview,
a metrics plot, and the finished result as one undoable command.

A subclass sets ``title``, ``params_cls``, ``description``, ``plot_metrics`` and implements
:meth:`build_steps`, which receives an immutable snapshot of the document and returns the method's
Step generator. It runs on the worker thread, so it must not touch widgets.

Methods that change the connectivity (remeshing, subdivision) set ``changes_faces = True`` and
yield steps that carry their faces (``step.F``, see :func:`app.jobs.step_faces`): the 3D view
then shows each streamed step's V and F, Stop / a failure put the document's mesh back on the
view, and the finished result becomes ONE undoable command whose state has the new V and F
(per-vertex fields and handles are kept only when the faces did not change). This is the one
place that commits such results (the window's positions jobs commit vertex arrays of the
input's size).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Iterator

import numpy as np
from PySide6.QtCore import Qt, QTimer
from PySide6.QtWidgets import (QCheckBox, QComboBox, QDockWidget, QFrame, QHBoxLayout, QLabel,
                               QPushButton, QScrollArea, QVBoxLayout, QWidget)

from algorithms.steps import Step
from app.commands import StateCommand
from app.document import MeshState
from app.forms import ParamsForm
from app.widgets import LinePlot, plural

if TYPE_CHECKING:  # pragma: no cover
    from app.main_window import MainWindow


def step_text(step: Step) -> str:
    """A streamed step in words: a stage's own message with its share done (per-mille progress
    of a blocking computation, see algorithms.steps.with_progress), else "Iteration i/total"."""
    if step.message and step.total == 1000:
        return f"{step.message} — {step.iteration / 10:.0f} %"
    total = f"/{step.total}" if step.total else ""
    text = f"Iteration {step.iteration}{total}"
    return f"{text}: {step.message}" if step.message else text


class MethodPanel(QDockWidget):
    title = "Method"
    description = ""
    params_cls: type = object
    plot_metrics: tuple[str, ...] = ()
    #: Run (not only a live re-run) on top of this panel's last result starts again from the
    #: shape that result came from (see :meth:`start_state`); the footer says which shape
    run_from_base = False
    #: the plot shows a Run's curve (cleared when that run is cancelled: the mesh goes back),
    #: not a job whose Stop keeps a result (Subdivision's training keeps its best weights)
    plot_shows_run = True
    plot_title = ""
    plot_log_y = False
    #: what the plot says while it is empty (e.g. which button fills it)
    plot_empty_text = ""
    live_debounce_ms = 300
    live_by_default = False
    #: live re-runs start switched on only for meshes up to this many vertices (where a run
    #: takes a second or two); on bigger meshes the user presses Run or ticks Live
    live_max_vertices = 10_000
    #: folded sections of rarely used fields (title -> field names), see ParamsForm
    param_groups: dict[str, tuple[str, ...]] = {}
    #: field -> the bool field that must be on for it to be editable, see ParamsForm
    param_enable_when: dict[str, str] = {}
    #: field -> f(params) -> text shown at the field's minimum ("auto (167)"), see ParamsForm
    param_auto_text: dict = {}
    #: docs/<help_page>.md is the panel's page for users (default: the title, lower case, "_")
    help_page = ""
    #: built-in presets: name -> the fields that differ from the defaults
    builtin_presets: dict[str, dict] = {}
    #: the steps may carry new faces (``step.F``): streamed and committed as whole meshes
    #: (see the module docstring)
    changes_faces = False
    #: a run's steps are iterations of the method (False: stages of a computation, such as
    #: "QSlim", "subdivision", whose count would mean nothing to the user)
    counts_iterations = True
    #: undo-merge id of live re-runs (one per panel class)
    _merge_ids: dict = {}

    def __init__(self, window: "MainWindow"):
        super().__init__(self.title, window)
        self.setObjectName(f"panel_{self.title.lower().replace(' ', '_')}")
        self.window_ = window
        body = QWidget()
        lay = QVBoxLayout(body)
        self.body_layout = lay
        if self.description:
            desc = QLabel(self.description)
            desc.setWordWrap(True)
            desc.setStyleSheet("color: #444;")
            lay.addWidget(desc)
        self.help_button = QPushButton("What does this do?")
        self.help_button.setFlat(True)
        self.help_button.setStyleSheet("QPushButton { color: #1d4ed8; text-decoration: underline;"
                                       " text-align: left; border: none; padding: 0; }")
        self.help_button.setToolTip("What this panel does, when to use it, every setting, its "
                                    "limits, in plain words.")
        self.help_button.setCursor(Qt.CursorShape.PointingHandCursor)
        self.help_button.clicked.connect(self.show_help)
        self.help_button.setVisible(self.help_path().exists())
        lay.addWidget(self.help_button, 0, Qt.AlignmentFlag.AlignLeft)
        self._build_presets_row(lay)
        self.form = ParamsForm(self.params_cls, groups=self.param_groups,
                               enable_when=self.param_enable_when,
                               auto_text=self.param_auto_text)
        lay.addWidget(self.form)
        # the footer: Run / Stop / Defaults and the panel's status, always visible below the
        # scrolling body (a tall panel never hides its Run button)
        footer = QFrame()
        footer.setObjectName("panel_footer")
        footer.setFrameShape(QFrame.Shape.StyledPanel)
        fl = QVBoxLayout(footer)
        fl.setContentsMargins(6, 4, 6, 4)
        row = QHBoxLayout()
        self.run_button = QPushButton(f"Run {self.title.lower()}")
        self.run_button.setToolTip("Run with these settings. The result can be undone (Ctrl+Z).")
        self.stop_button = QPushButton("Stop")
        self.stop_button.setToolTip("Stop the running job; the mesh goes back to how it was (Esc).")
        self.stop_button.setEnabled(False)
        self.defaults_button = QPushButton("Defaults")
        self.defaults_button.setToolTip("Reset every parameter to its default value.")
        row.addWidget(self.run_button, 2)
        row.addWidget(self.stop_button, 1)
        row.addWidget(self.defaults_button, 1)
        fl.addLayout(row)
        self.status_label = QLabel("Ready.")
        self.status_label.setWordWrap(True)
        # room for two lines: the dock's layout does not grow a wrapped label by itself
        self.status_label.setMinimumHeight(2 * self.status_label.fontMetrics().lineSpacing() + 2)
        self.status_label.setAlignment(Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignTop)
        self.footer = footer
        # the Live switch lives in the footer, next to Run: always in sight, however long the
        # panel's settings are (Cubic's was at the bottom of a long scroll)
        self.live_box = QCheckBox("Live: re-run when a parameter changes")
        self.live_box.setToolTip("Each parameter change restarts the method from the current mesh, "
                                 "so you see its effect at once. The result is applied only when "
                                 "the run finishes.")
        fl.addWidget(self.live_box)
        # where Run and the slider start from (panels with run_from_base): one base shape
        self.base_label = QLabel()
        self.base_label.setWordWrap(True)
        self.base_label.setStyleSheet("color: #444;")
        self.base_label.setToolTip("Run and every live re-run start from this shape, so moving a "
                                   "slider or pressing Run again never piles one result on "
                                   "another.")
        self.continue_button = QPushButton("Stylize the result instead")
        self.continue_button.setFlat(True)
        self.continue_button.setStyleSheet(
            "QPushButton { color: #1d4ed8; text-decoration: underline; text-align: left; "
            "border: none; padding: 0; }")
        self.continue_button.setCursor(Qt.CursorShape.PointingHandCursor)
        self.continue_button.setToolTip("Make the mesh as it is now the start of the next run "
                                        "(to apply the method to its own result).")
        self.continue_button.clicked.connect(self.continue_from_result)
        base_row = QHBoxLayout()
        base_row.addWidget(self.base_label, 1)
        base_row.addWidget(self.continue_button, 0)
        fl.addLayout(base_row)
        for w in (self.base_label, self.continue_button):
            w.setVisible(self.run_from_base)
        fl.addWidget(self.status_label)
        self.plot = LinePlot(self.plot_title or ", ".join(self.plot_metrics), log_y=self.plot_log_y,
                             empty_text=self.plot_empty_text)
        lay.addWidget(self.plot)
        lay.addStretch(1)
        scroll = QScrollArea()
        scroll.setWidgetResizable(True)
        scroll.setFrameShape(QScrollArea.Shape.NoFrame)
        scroll.setWidget(body)
        scroll.setMinimumWidth(body.sizeHint().width() + 24)
        self.scroll_area = scroll
        outer = QWidget()
        ol = QVBoxLayout(outer)
        ol.setContentsMargins(0, 0, 0, 0)
        ol.setSpacing(0)
        ol.addWidget(scroll, 1)
        ol.addWidget(footer)
        self.setWidget(outer)

        self._last: tuple[MeshState, MeshState] | None = None  # (input, result) of last run
        self._recipe_cache: dict = {}  # the recipe's precomputation, kept between runs
        self._run_options: dict | None = None
        self._pending_input: MeshState | None = None
        self._mesh_job: dict | None = None  # the running changes_faces job (see run)
        self._shown_F: np.ndarray | None = None  # faces a mesh job put on the 3D view
        window.job_committed.connect(self._on_committed)
        self._debounce = QTimer(self)
        self._debounce.setSingleShot(True)
        self._debounce.setInterval(self.live_debounce_ms)
        self._debounce.timeout.connect(lambda: self.run(live=True))
        self.live_box.setChecked(self.live_by_default)
        self._live_text = self.live_box.text()
        window.document.subscribe(self._on_document_for_panel)
        self.run_button.clicked.connect(lambda: self.run())
        self.stop_button.clicked.connect(window.cancel_job)
        self.defaults_button.clicked.connect(self.form.reset_defaults)
        self.form.changed.connect(self._on_params_changed)
        runner = window.runner
        # mesh jobs first: the view must show the document's faces again before the window's
        # own handlers (connected after the panels) move its points back
        runner.started.connect(self._on_mesh_job_started)
        runner.finished.connect(self._on_mesh_job_finished)
        runner.cancelled.connect(lambda _m: self._on_mesh_job_stopped())
        runner.failed.connect(lambda _m, _d: self._on_mesh_job_stopped())
        runner.preview.connect(self._on_preview)
        runner.metrics.connect(self._on_metrics)
        runner.started.connect(self._on_busy)
        runner.busy_changed.connect(self._on_busy)
        runner.finished.connect(self._on_finished)
        runner.cancelled.connect(self._on_stopped)
        runner.cancelled.connect(self._on_cancelled)
        runner.failed.connect(lambda msg, _d: self._on_stopped(msg))
        self.visibilityChanged.connect(self._on_visibility_changed)

    # -- to implement -------------------------------------------------------------------------
    def job_options(self) -> dict:
        """Settings of the next run that are not in the Params form (e.g. a switch of the
        panel's own, the chosen style, a seed, blob references of loaded images), as a
        JSON-able dict: with the state and the Params they are the recipe's whole input; the
        study log and the project file record them."""
        return {}

    def restore_options(self, options: dict) -> None:
        """Set the panel's own widgets from ``options`` saved by :meth:`job_options` (a project
        file being opened). The default has nothing to restore."""

    #: the recipe a plain Run computes (default: the one registered under the panel's title)
    recipe_name: str = ""
    #: counts requests over all panels: the study log takes the newest one as the request of
    #: the job that starts next, whatever the job's name
    _request_counter = 0

    @property
    def last_request(self) -> dict | None:
        """What the job being started asks for: ``params``, ``options``, ``input`` (the state)
        and ``recipe`` (its name); set by every panel just before it starts a job."""
        return getattr(self, "_last_request", None)

    @last_request.setter
    def last_request(self, request: dict | None) -> None:
        MethodPanel._request_counter += 1
        self._last_request = request
        self.last_request_seq = MethodPanel._request_counter

    def recipe(self, name: str | None = None):
        """A Qt-free recipe of this panel (:mod:`app.recipes`): ``name``, else the one of the
        run being started (``self._run_recipe``), else ``recipe_name`` or the panel's title;
        None when none is registered."""
        from app.recipes import recipes

        name = name or getattr(self, "_run_recipe", None) or self.recipe_name or self.title
        return recipes().get(name)

    def build_steps(self, state: MeshState, params: Any) -> Iterator[Step]:
        """The run's Step generator (worker thread): the panel's recipe with the options read
        on the GUI thread when the run started."""
        recipe = self.recipe()
        if recipe is None:
            raise NotImplementedError(f"{self.title} has no recipe")
        options = getattr(self, "_run_options", None)
        if options is None:
            options = self.job_options()
        return recipe.steps(state, params, options, self._recipe_cache)

    def job_factory(self, state: MeshState, params: Any):
        """The job's factory (called on the worker thread) for one run. The default calls
        :meth:`build_steps`; override it to snapshot, here on the GUI thread, other widgets'
        settings the run needs, so a later click cannot change a queued run."""
        return lambda: self.build_steps(state, params)

    def commit_function(self):
        """``commit(before, last_step) -> MeshState`` for the job being started (by default the
        recipe's ``result`` with this run's options), or None to take the last step's
        positions (see MainWindow.start_positions_job)."""
        recipe = self.recipe()
        if recipe is None:
            return None
        options = getattr(self, "_run_options", None) or {}
        return lambda before, step: recipe.result(before, step, options)

    @property
    def merge_id(self) -> int:
        return MethodPanel._merge_ids.setdefault(type(self).__name__,
                                                 1000 + len(MethodPanel._merge_ids))

    # -- help ----------------------------------------------------------------------------------
    def help_path(self):
        """docs/<panel>.md: the page for users ("What does this do?")."""
        from pathlib import Path

        slug = self.help_page or self.title.lower().replace(" ", "_")
        return Path(__file__).resolve().parents[2] / "docs" / f"{slug}.md"

    def show_help(self):
        from app.dialogs import help_window

        page = getattr(self, "help_dialog", None)
        if page is None:
            page = self.help_dialog = help_window(self, f"{self.title}: what does this do?",
                                                  self.help_path())
        page.show()
        page.raise_()
        return page

    # -- presets -------------------------------------------------------------------------------
    def _build_presets_row(self, lay) -> None:
        row = QHBoxLayout()
        self.preset_combo = QComboBox()
        self.preset_combo.setToolTip("Named settings of this panel: built-in ones, and yours "
                                     "(Save…). Choosing one sets the form (Live re-runs).")
        self.preset_save = QPushButton("Save…")
        self.preset_save.setToolTip("Keep the current settings under a name (for this panel).")
        self.preset_delete = QPushButton("Delete")
        self.preset_delete.setToolTip("Forget the chosen preset of yours.")
        row.addWidget(QLabel("Preset"))
        row.addWidget(self.preset_combo, 1)
        row.addWidget(self.preset_save)
        row.addWidget(self.preset_delete)
        lay.addLayout(row)
        self.preset_combo.activated.connect(lambda i: self.apply_preset(
            self.preset_combo.itemText(i)))
        self.preset_save.clicked.connect(self.save_preset_dialog)
        self.preset_delete.clicked.connect(
            lambda: self.delete_preset(self.preset_combo.currentText()))
        self._fill_presets()

    def _preset_key(self) -> str:
        return f"presets/{self.objectName()}"

    def user_presets(self) -> dict[str, dict]:
        import json

        raw = self.window_.settings.value(self._preset_key(), "")
        try:
            data = json.loads(raw) if raw else {}
        except (TypeError, ValueError):
            data = {}
        return data if isinstance(data, dict) else {}

    def presets(self) -> dict[str, dict]:
        """Every preset by name: "Defaults", the built-in ones, then the user's."""
        return {"Defaults": {}, **self.builtin_presets, **self.user_presets()}

    def _fill_presets(self, current: str = "") -> None:
        self.preset_combo.blockSignals(True)
        self.preset_combo.clear()
        self.preset_combo.addItem("")  # the form as it is
        for name in self.presets():
            self.preset_combo.addItem(name)
        self.preset_combo.setCurrentText(current)
        self.preset_combo.blockSignals(False)
        self.preset_delete.setEnabled(current in self.user_presets())

    def apply_preset(self, name: str) -> bool:
        from algorithms.errors import Stylize3DError
        from algorithms.params import params_from_dict, params_to_dict

        values = self.presets().get(name)
        if values is None:
            return False
        try:
            params = params_from_dict(self.params_cls,
                                      {**params_to_dict(self.params_cls()), **values})
        except Stylize3DError as e:  # a preset saved by another version of the app
            self.status_label.setText(f"The preset {name!r} does not fit this version: {e}")
            return False
        self.form.set_params(params)
        self.form.changed.emit(self.form.params())
        self._fill_presets(name)
        self.status_label.setText(f"Preset {name!r} applied.")
        return True

    def save_preset_dialog(self) -> bool:
        from app import dialogs

        name = dialogs.ask_text(self, "Save preset", "Name of these settings:")
        return bool(name) and self.save_preset(name)

    def save_preset(self, name: str) -> bool:
        import json

        from algorithms.params import params_to_dict

        if name == "Defaults" or name in self.builtin_presets:
            self.status_label.setText(f"{name!r} is a built-in preset: choose another name.")
            return False
        defaults = params_to_dict(self.params_cls())
        values = {k: v for k, v in params_to_dict(self.form.params()).items() if defaults[k] != v}
        user = self.user_presets()
        user[name] = values
        self.window_.settings.setValue(self._preset_key(), json.dumps(user))
        self._fill_presets(name)
        self.status_label.setText(f"Saved the preset {name!r}.")
        return True

    def delete_preset(self, name: str) -> bool:
        import json

        user = self.user_presets()
        if name not in user:
            return False
        del user[name]
        self.window_.settings.setValue(self._preset_key(), json.dumps(user))
        self._fill_presets()
        return True

    # -- on screen or not ----------------------------------------------------------------------
    def is_shown(self) -> bool:
        """Whether the user can see this panel now: open and not behind another panel's tab.

        A dock behind another tab still answers ``isVisible() == True``; only the panel in
        front (or one docked on its own, or floating) may drive the shared viewport. Panels
        draw their colour views only when this is True, and redraw them in
        :meth:`refresh_view` when they come to the front (the one mechanism; see
        ``_on_visibility_changed``)."""
        return self.isVisible() and not self.visibleRegion().isEmpty()

    def refresh_view(self) -> None:
        """Draw this panel's colour view / overlays on the viewport (subclasses). Called when
        the panel comes to the front; not called while it is behind another tab."""

    def hide_view(self) -> None:
        """Take this panel's own drawings (marker dots, its colour view) off the 3D view: it
        went behind another tab or was closed (subclasses that draw overlays)."""

    def _on_visibility_changed(self, visible: bool) -> None:
        if visible:  # the tab bar switches after this signal: look once the layout settled
            QTimer.singleShot(0, self._refresh_if_shown)
        else:
            self.hide_view()

    def _refresh_if_shown(self) -> None:
        doc = self.window_.document
        if not self.is_shown() or doc.is_empty:
            return
        poly = getattr(self.window_.viewport, "poly", None)
        if poly is None or poly.n_points != len(doc.V):
            # the 3D view does not show the document's mesh yet (a mesh being opened, a job's
            # remeshed preview): the window redraws it, and the panel's view follows then
            return
        self.refresh_view()

    # -- behaviour ----------------------------------------------------------------------------
    def _mine(self) -> bool:
        return self.window_.runner.name == self.title

    def run(self, live: bool = False) -> None:
        """Start the method; ``live`` runs (from parameter changes) merge into one undo step."""
        state = self.window_.document.state
        if state is None:
            self.status_label.setText("Open a mesh first (File > Open).")
            return
        params = self.form.params()
        start = self.start_state(state, live)
        self._pending_input = start
        # read once, here on the GUI thread: the worker, the commit and the study log use it
        self._run_options = self.job_options()
        self._run_recipe = self.recipe_name or self.title
        # what this run asks for, read by the study log (app/study/session.py) when it starts:
        # a panel that starts other jobs (recipes of other names) sets the same four keys
        self.last_request = {"params": params, "options": self._run_options, "input": start,
                             "recipe": self._run_recipe}
        self._debounce.stop()
        self.show_live_state("running" if live else None)
        self.plot.clear()
        self.plot_shows_run = True  # the curve of a run whose result Stop throws away
        self.status_label.setText("Starting…")
        merge_id = self.merge_id if live else -1
        if self.changes_faces:
            # the window only runs it; this panel shows its meshes and commits the result
            self._mesh_job = {"before": state, "merge_id": merge_id, "active": False}
            self.window_.start_analysis_job(self.title, self.job_factory(start, params))
            return
        self.window_.start_positions_job(self.title, self.job_factory(start, params),
                                         merge_id=merge_id, commit=self.commit_function())

    # -- jobs whose steps carry new faces (changes_faces) ---------------------------------------
    def show_step_mesh(self, step: Step) -> None:
        """Put a streamed step of a mesh job on the 3D view: its V and F (just its points when
        the faces are those already shown)."""
        vp = self.window_.viewport
        if vp.poly is None:
            return
        from app.jobs import step_faces

        V = np.asarray(step.V, dtype=np.float64)
        F = step_faces(step)
        shown = self._shown_F if self._shown_F is not None else self.window_.document.F
        if F is None or (F is shown or (F.shape == shown.shape and len(V) == vp.poly.n_points
                                        and np.array_equal(F, shown))):
            if len(V) == vp.poly.n_points:
                vp.update_points(V)
            return
        if not (V.ndim == 2 and V.shape[1] == 3 and F.size and F.min() >= 0
                and F.max() < len(V) and np.isfinite(V).all()):
            return  # a broken step is not drawn; the commit refuses it
        vp.set_mesh(V, F, reset_camera=False)
        self._shown_F = F

    def restore_mesh_view(self) -> None:
        """Show the document's own mesh again after a mesh job put other faces on the view."""
        doc = self.window_.document
        if self._shown_F is not None and doc.state is not None:
            self.window_.viewport.set_mesh(doc.V, doc.F, reset_camera=False)
        self._shown_F = None

    def _on_mesh_job_started(self, name: str) -> None:
        if self._mesh_job is not None and name == self.title:
            self._mesh_job["active"] = True
            self._shown_F = None

    def _on_mesh_job_stopped(self) -> None:
        # any job that ends without a result (ours, or one a newer run replaced) leaves the
        # document as it was: show its faces again
        self.restore_mesh_view()
        if self._mesh_job is not None and self._mesh_job["active"]:
            self._mesh_job = None

    def _on_mesh_job_finished(self, step: Step) -> None:
        job = self._mesh_job
        if job is None or not job["active"] or self.window_.last_job_name != self.title:
            return
        self._mesh_job = None
        from app import dialogs
        from app.jobs import step_faces

        win = self.window_
        doc = win.document
        before = job["before"]
        if doc.state is not before:  # the document changed meanwhile: the result is stale
            self.restore_mesh_view()
            return
        V = np.asarray(step.V, dtype=np.float64)
        F = step_faces(step)
        F = before.F if F is None else np.asarray(F, dtype=np.int64)
        ok = (V.ndim == 2 and V.shape[1] == 3 and len(V) > 0 and np.isfinite(V).all()
              and F.ndim == 2 and F.shape[1] == 3 and len(F) > 0 and F.min() >= 0
              and F.max() < len(V))
        if not ok:
            self.restore_mesh_view()
            text = "The method returned an invalid result; your mesh was not changed."
            win.report(f"{self.title} failed: {text}", "error")
            dialogs.error(win, f"{self.title} failed", text)
            return
        recipe = self.recipe()
        if recipe is not None:
            after = recipe.result(before, step, self._run_options or {})
        else:
            same_faces = F is before.F or (F.shape == before.F.shape
                                           and V.shape == before.V.shape
                                           and np.array_equal(F, before.F))
            after = before.with_positions(V) if same_faces else MeshState.make(V, F)
        self._shown_F = None  # the document's change redraws the view with the new faces
        win.undo_stack.push(StateCommand(doc, before, after, self.title,
                                         merge_id=job["merge_id"]))
        win.job_committed.emit(self.title, after)

    def shutdown(self) -> None:
        """Stop pending live re-runs (window closing)."""
        self._debounce.stop()
        self.live_box.setChecked(False)

    def _on_committed(self, name: str, after: MeshState) -> None:
        if name == self.title and self._pending_input is not None:
            self._last = (self._pending_input, after)
        self._update_base_label()

    def _on_document_for_panel(self, what: str) -> None:
        if what == "mesh":
            self.on_new_mesh()
            self._live_default_for_mesh(what)
        self._update_base_label()

    def on_new_mesh(self) -> None:
        """Another mesh was opened: nothing of the previous mesh's runs stays in the panel (its
        status, its plot, the shape a live re-run would start from)."""
        self._debounce.stop()
        self._last = None
        self._pending_input = None
        self.plot.clear()
        self.status_label.setText("Ready.")
        self.show_live_state(None)

    def start_state(self, state: MeshState, live: bool) -> MeshState:
        """The shape a run starts from. A live re-run (and, in a panel with ``run_from_base``,
        a click on Run) on top of this panel's last result starts again from the positions that
        result was computed from, with the current painted fields and handles: moving a slider
        back and forth, or pressing Run again, never compounds the effect. Otherwise the run
        starts from the mesh as it is (Smooth: Run again smooths more)."""
        last = self._last
        if ((live or self.run_from_base) and last is not None and state.V is last[1].V
                and last[0].V is not last[1].V):  # (a field result keeps V)
            prev = last[0]
            # (a result with new faces starts again from the whole previous input)
            return state.with_positions(prev.V) if prev.F is state.F else prev
        return state

    def continue_from_result(self) -> None:
        """The next run starts from the mesh as it is now (the last result), not from the
        shape that result was computed from."""
        self._last = None
        self._update_base_label()
        self.status_label.setText("The next run starts from the mesh as it is now.")

    def _update_base_label(self) -> None:
        if not self.run_from_base:
            return
        st = self.window_.document.state
        on_result = (st is not None and self.start_state(st, live=True) is not st)
        if st is None:
            text = ""
        elif on_result:
            text = (f"Starts from: the mesh before your last {self.title} run (Run and the "
                    "slider re-do it from there).")
        else:
            text = "Starts from: the mesh as it is now."
        self.base_label.setText(text)
        self.continue_button.setVisible(on_result)

    def _on_params_changed(self, _params) -> None:
        if self.live_box.isChecked() and not self.window_.document.is_empty:
            self._debounce.start()
            self.show_live_state("pending")

    def show_live_state(self, state: str | None) -> None:
        """Say on the Live switch whether a live re-run is "pending" (waiting for the slider to
        rest), "running", or nothing (None)."""
        suffix = {"pending": "  — re-run pending…", "running": "  — re-running…"}.get(state, "")
        self.live_box.setText(self._live_text + suffix)
        self.live_box.setStyleSheet("color: #b45309;" if suffix else "")

    def _live_default_for_mesh(self, what: str) -> None:
        if what != "mesh" or not self.live_by_default:
            return
        n = len(self.window_.document.V)
        small = n <= self.live_max_vertices
        self.live_box.setChecked(small)
        if not small:
            self.status_label.setText(
                f"Live is off for this {n:,}-vertex mesh (a run takes a while): press Run, "
                "or tick Live.")

    def _on_busy(self, *_):
        busy = self.window_.runner.busy
        self.stop_button.setEnabled(busy and self._mine())
        if not (busy and self._mine()):
            self.show_live_state("pending" if self._debounce.isActive() else None)

    def _on_metrics(self, history) -> None:
        if not self._mine():
            return
        for _it, metrics in history:
            for name in self.plot_metrics:
                if name in metrics:
                    self.plot.append(name, metrics[name])

    def _on_preview(self, step: Step) -> None:
        if not self._mine():
            return
        if self._mesh_job is not None and self._mesh_job["active"]:
            self.show_step_mesh(step)
        self.status_label.setText(step_text(step))

    def _on_finished(self, step: Step) -> None:
        if self.window_.last_job_name != self.title:
            return
        seconds = f"{self.window_.runner.last_duration:.2f} s"
        if self.counts_iterations and "fine_iterations" in step.metrics:
            # progressive meshes finished on every triangle: say how the iterations split
            coarse = int(step.metrics.get("coarse_iterations", 0))
            fine = int(step.metrics["fine_iterations"])
            text = (f"Done: {plural(coarse, 'iteration')} on the coarse copy, then "
                    f"{plural(fine, 'iteration')} on every triangle, in {seconds}.")
        elif self.counts_iterations and step.iteration > 0:
            text = f"Done: {plural(step.iteration, 'iteration')} in {seconds}."
            if step.metrics.get("finish_skipped") and step.message:
                # progressive meshes not finished (too big): the recipe's note says why
                text += f" {step.message[0].upper()}{step.message[1:]}."
        else:
            text = f"Done in {seconds}."
        from app.recipes import held_crossings_note, unchanged_result

        said = held_crossings_note(step.metrics, self.title)  # held where it crossed itself
        if said:
            text += f" {said}"
        recipe = self.recipe()

        if recipe is None or recipe.result is not unchanged_result:
            text += " Undo with Ctrl+Z."
        self.status_label.setText(text)
        self.stop_button.setEnabled(False)

    def _on_stopped(self, message: str) -> None:
        if self.window_.last_job_name != self.title:
            return
        self.status_label.setText(message)
        self.stop_button.setEnabled(False)

    def _on_cancelled(self, _message: str) -> None:
        # the mesh went back to how it was: the plot no longer shows the cancelled run's curve
        # (a live re-run that replaced the cancelled one fills it again)
        if (self.window_.last_job_name == self.title and not self.window_.runner.busy
                and self.plot_shows_run):
            self.plot.clear()
