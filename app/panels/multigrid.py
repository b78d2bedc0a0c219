"""Panel "Multigrid smoothing" (thesis ch. 8): smooth a signal on the surface with the surface
multigrid solver, drag the smoothness and see the result at once, compare with a direct solver,
look at the hierarchy, and run mean curvature flow on the same hierarchy.

Signals: a noisy test field made in the app, a per-vertex field loaded from a file, or the vertex
positions themselves. Scalar results go into the document as the field "smoothed" (undoable,
saved with "Save field…"); smoothed positions replace the shape (undoable). Live α changes merge
into one undo step. The hierarchy (geometry only) is built once per mesh connectivity and reused
by every solve, every α, every energy and every flow step.

Every job is a Qt-free recipe of :mod:`app.recipes.multigrid` (smoothing, hierarchy, solver
comparison, mean curvature flow), run on the panel's recipe cache; this panel keeps its form, its
views and its buttons. What a run depends on beyond the document and the form is in its options:
the signal, the noise level and seed, the α's of the earlier solves it warm-starts from (a live
slider drag: the recipe's ``warm_start``, so a replay reproduces the bits) and, when the shape
changed since the hierarchy was built, the positions the hierarchy was built on.
"""

from __future__ import annotations

import time
from pathlib import Path

from PySide6.QtWidgets import (QComboBox, QDoubleSpinBox, QGridLayout, QGroupBox, QHBoxLayout,
                               QLabel, QPushButton, QSpinBox, QVBoxLayout)

from algorithms.errors import Stylize3DError
from algorithms.mesh.fields import FIELD_EXTENSIONS, field_file_filter, read_field, write_field
from algorithms.multigrid.params import DataSmoothingParams, MultigridParams
from algorithms.smoothing import SmoothParams
from app import dialogs
from app.commands import StateCommand
from app.panels.base import MethodPanel
from app.recipes.multigrid import (COMPARE, DEFAULT_NOISE, FLOW, HIERARCHY, LOADED_FIELD,
                                   NOISY_FIELD, RESULT_FIELD, SIGNALS, SMOOTH,
                                   coarse_triangle_colors, hierarchy_of, hierarchy_option,
                                   noisy_field, resolve_solver, signal_range, warm_start_chain)
from app.widgets import plural

SIGNAL_NAMES = ("Noisy test field", "Vertex positions", "Loaded field")  # order of SIGNALS
VIEWS = ("Result", "Input signal", "Coarse level mesh", "Fine triangles by coarse triangle")
SOLVER_NAMES = {"multigrid": "multigrid", "direct": "direct (CHOLMOD)"}
#: the undo text (and job name) of mean curvature flow
FLOW_JOB = "Mean curvature flow"


class MultigridPanel(MethodPanel):
    counts_iterations = False  # its steps are stages and solver cycles
    title = "Multigrid smoothing"
    description = ("Smooths a signal on the surface with surface multigrid: a noisy test field, "
                   "a field from a file, or the shape itself. Drag Smoothness: every change "
                   "re-solves at once on the same hierarchy.")
    params_cls = DataSmoothingParams
    plot_metrics = ("relative residual",)
    plot_title = "Relative residual per V-cycle (last solve)"
    plot_log_y = True
    live_by_default = True
    live_debounce_ms = 120
    live_max_vertices = 200_000  # a solve on the built hierarchy takes well under a second

    def __init__(self, window):
        super().__init__(window)
        # the recipes keep the hierarchy, the Galerkin matrices and recent solutions in
        # self._recipe_cache (one mesh at a time; cleared when the mesh changes)
        self.solve_times: dict[str, str] = {}
        self._noise_seed = 0   # the seed of the last noisy test field ("New noise")
        self._job = ""         # the recipe of the job this panel started last
        self._starting = False  # inside run(): job_options() adds the run's own options
        lay = self.body_layout

        # -- signal ---------------------------------------------------------------------------
        sig = QGroupBox("Signal")
        g = QGridLayout(sig)
        self.signal_combo = QComboBox()
        self.signal_combo.addItems(SIGNAL_NAMES)
        self.signal_combo.setToolTip(
            "What to smooth. Noisy test field: a smooth pattern plus noise, made here. Vertex "
            "positions: smooths the shape itself. Loaded field: one number per vertex from a file.")
        self.noise_spin = QDoubleSpinBox()
        self.noise_spin.setRange(0.0, 3.0)
        self.noise_spin.setSingleStep(0.05)
        self.noise_spin.setValue(DEFAULT_NOISE)
        self.noise_spin.setToolTip("Noise of the test field, relative to the pattern's spread.")
        self.noise_button = QPushButton("New noise")
        self.noise_button.setToolTip("Make a new noisy test field (undoable).")
        self.load_button = QPushButton("Load field…")
        self.load_button.setToolTip("Load one value per vertex from .npy, .txt or .csv (undoable).")
        self.save_button = QPushButton("Save field…")
        self.save_button.setToolTip("Save the smoothed field (one value per vertex).")
        g.addWidget(self.signal_combo, 0, 0, 1, 3)
        g.addWidget(QLabel("Noise"), 1, 0)
        g.addWidget(self.noise_spin, 1, 1)
        g.addWidget(self.noise_button, 1, 2)
        g.addWidget(self.load_button, 2, 1)
        g.addWidget(self.save_button, 2, 2)
        lay.insertWidget(lay.indexOf(self.form), sig)

        # -- solver times ---------------------------------------------------------------------
        row = QHBoxLayout()
        self.times_label = QLabel("Solve times appear here.")
        self.times_label.setWordWrap(True)
        self.times_label.setToolTip("Measured time of the last solve with each solver, on this "
                                    "mesh (the direct solver factors the matrix anew for every "
                                    "α; multigrid reuses its hierarchy).")
        self.compare_button = QPushButton("Compare solvers")
        self.compare_button.setToolTip("Solve once with each solver at this α and show the times "
                                       "(the mesh is not changed).")
        row.addWidget(self.times_label, 1)
        row.addWidget(self.compare_button)
        lay.insertLayout(lay.indexOf(self.live_box) + 1, row)

        # -- hierarchy ------------------------------------------------------------------------
        hier = QGroupBox("Hierarchy")
        hv = QVBoxLayout(hier)
        self.hier_label = QLabel("Built on the first solve (or press Build).")
        self.hier_label.setWordWrap(True)
        hrow = QHBoxLayout()
        self.view_combo = QComboBox()
        self.view_combo.addItems(VIEWS)
        self.view_combo.setToolTip("What to draw on the mesh.")
        self.level_spin = QSpinBox()
        self.level_spin.setRange(1, 1)
        self.level_spin.setToolTip("Which coarse level (1 = the first coarsening).")
        self.build_button = QPushButton("Build")
        self.build_button.setToolTip("Build (or rebuild) the multigrid hierarchy of this mesh.")
        hrow.addWidget(self.view_combo, 1)
        hrow.addWidget(QLabel("level"))
        hrow.addWidget(self.level_spin)
        hrow.addWidget(self.build_button)
        hv.addWidget(self.hier_label)
        hv.addLayout(hrow)
        lay.insertWidget(lay.indexOf(self.plot) + 1, hier)

        # -- mean curvature flow ----------------------------------------------------------------
        mcf = QGroupBox("Mean curvature flow")
        mg_ = QHBoxLayout(mcf)
        self.dt_spin = QDoubleSpinBox()
        self.dt_spin.setDecimals(6)
        self.dt_spin.setRange(1e-6, 1.0)
        self.dt_spin.setSingleStep(1e-4)
        self.dt_spin.setValue(1e-3)
        self.dt_spin.setToolTip("Time step relative to the surface area: 1e-4 gentle, 1e-3 "
                                "clearly visible, 1e-2 rounds the shape off.")
        self.steps_spin = QSpinBox()
        self.steps_spin.setRange(1, 500)
        self.steps_spin.setValue(10)
        self.steps_spin.setToolTip("Number of steps of Run.")
        self.mcf_step_button = QPushButton("Step")
        self.mcf_step_button.setToolTip("One flow step (multigrid on the same hierarchy; undoable).")
        self.mcf_run_button = QPushButton("Run")
        self.mcf_run_button.setToolTip("Run the given number of steps, showing each (undoable).")
        mg_.addWidget(QLabel("dt"))
        mg_.addWidget(self.dt_spin)
        mg_.addWidget(QLabel("steps"))
        mg_.addWidget(self.steps_spin)
        mg_.addWidget(self.mcf_step_button)
        mg_.addWidget(self.mcf_run_button)
        lay.insertWidget(lay.indexOf(hier) + 1, mcf)

        self.signal_combo.currentIndexChanged.connect(self._on_signal_changed)
        self.noise_button.clicked.connect(self.new_noise)
        self.load_button.clicked.connect(self.load_field_dialog)
        self.save_button.clicked.connect(self.save_field_dialog)
        self.compare_button.clicked.connect(self.compare_solvers)
        self.build_button.clicked.connect(lambda: self.build_hierarchy(force=True))
        self.view_combo.currentIndexChanged.connect(lambda _i: self.show_view())
        self.level_spin.valueChanged.connect(lambda _i: self.show_view())
        self.mcf_step_button.clicked.connect(lambda: self.run_flow(1))
        self.mcf_run_button.clicked.connect(lambda: self.run_flow(self.steps_spin.value()))
        window.document.subscribe(self._on_doc)
        self.visibilityChanged.connect(self._on_visibility)

    # -- signals -----------------------------------------------------------------------------------
    @property
    def signal(self) -> str:
        return SIGNALS[self.signal_combo.currentIndex()]

    def _push(self, after, text: str, details: dict | None = None) -> None:
        doc = self.window_.document
        cmd = StateCommand(doc, doc.state, after, text)
        if details:
            cmd.log_details = details  # the study log records the edit's inputs
        self.window_.undo_stack.push(cmd)

    def new_noise(self) -> None:
        doc = self.window_.document
        if doc.is_empty:
            self.status_label.setText("Open a mesh first (File > Open).")
            return
        # a new seed per click, kept (job_options: "noise_seed") and logged with the edit
        self._noise_seed = seed = int(time.time_ns() % (2**31))
        level = float(self.noise_spin.value())
        noisy = noisy_field(doc.V, doc.F, level, seed)
        self._push(doc.state.with_field(NOISY_FIELD, noisy).with_field(RESULT_FIELD, None),
                   "New noisy test field",
                   {"tool": "new_noise", "field": NOISY_FIELD, "noise": level, "seed": seed})
        self.signal_combo.setCurrentIndex(0)
        self.view_combo.setCurrentIndex(1)
        self.show_view()
        self.status_label.setText("A new noisy field; drag Smoothness or press Run.")

    def load_field_dialog(self) -> bool:
        doc = self.window_.document
        if doc.is_empty:
            self.status_label.setText("Open a mesh first (File > Open).")
            return False
        path = dialogs.open_file(self, "Load a per-vertex field", field_file_filter(),
                                 self.window_._last_dir())
        return bool(path) and self.load_field(path)

    def load_field(self, path: str) -> bool:
        doc = self.window_.document
        try:
            values = read_field(path, len(doc.V))
        except Stylize3DError as e:
            dialogs.error(self, "Cannot load the field", str(e))
            return False
        from app.recipes import put_blob_file

        details = {"tool": "load_field", "field": LOADED_FIELD, "file": put_blob_file(path)}
        self._push(doc.state.with_field(LOADED_FIELD, values).with_field(RESULT_FIELD, None),
                   "Load field", details)
        self.signal_combo.setCurrentIndex(2)
        self.view_combo.setCurrentIndex(1)
        self.show_view()
        self.status_label.setText(f"Loaded {len(values):,} values; drag Smoothness or press Run.")
        return True

    def save_field_dialog(self) -> bool:
        doc = self.window_.document
        if doc.is_empty or RESULT_FIELD not in doc.state.fields:
            dialogs.info(self, "Save field", "There is no smoothed field yet: run the smoothing "
                         "on a test field or a loaded field first.")
            return False
        path = dialogs.save_file(self, "Save the smoothed field", field_file_filter(),
                                 self.window_._last_dir())
        if not path:
            return False
        if Path(path).suffix.lower() not in FIELD_EXTENSIONS:
            path += ".txt"
        if not self.window_._may_overwrite(path):
            return False
        try:
            write_field(path, doc.state.fields[RESULT_FIELD])
        except Stylize3DError as e:
            dialogs.error(self, "Cannot save the field", str(e))
            return False
        self.status_label.setText(f"Saved {path}.")
        return True

    def _on_signal_changed(self, _i: int) -> None:
        self.view_combo.setCurrentIndex(0 if self.signal == "positions" else 1)
        self.show_view()

    def _input_values(self, state, signal: str | None = None):
        signal = signal or self.signal
        if signal == "positions":
            return state.V
        name = NOISY_FIELD if signal == "noise" else LOADED_FIELD
        return state.fields.get(name)

    # -- options ---------------------------------------------------------------------------------
    def job_options(self) -> dict:
        """The recipe options of the panel (see :mod:`app.recipes.multigrid`): ``signal``,
        ``noise``, ``noise_seed``, and the flow's ``flow_step_size`` and ``flow_steps`` (kept
        with a project; the smoothing recipe does not use them). While a smoothing run starts
        (:meth:`run`), also that run's ``warm_start`` (the α's of the earlier solves of the
        same input, when the last solve was one) and ``hierarchy_positions`` (when the cached
        hierarchy was built on other positions)."""
        opts = {"signal": self.signal, "noise": float(self.noise_spin.value()),
                "noise_seed": int(self._noise_seed),
                "flow_step_size": float(self.dt_spin.value()),
                "flow_steps": int(self.steps_spin.value())}
        state = self._pending_input if self._starting else None
        if state is not None:
            params = self.form.params()
            if resolve_solver(len(state.V), params)[0] == "multigrid":
                opts.update(hierarchy_option(self._recipe_cache, state))
            chain = warm_start_chain(self._recipe_cache, state, params, opts)
            if chain:
                opts["warm_start"] = chain
        return opts

    def restore_options(self, options: dict) -> None:
        if options.get("signal") in SIGNALS:
            self.signal_combo.setCurrentIndex(SIGNALS.index(options["signal"]))
        if "noise" in options:
            self.noise_spin.setValue(float(options["noise"]))
        if "noise_seed" in options:
            self._noise_seed = int(options["noise_seed"])
        if "flow_step_size" in options:
            self.dt_spin.setValue(float(options["flow_step_size"]))
        if "flow_steps" in options:
            self.steps_spin.setValue(int(options["flow_steps"]))

    def _analysis_options(self, state) -> dict:
        opts = {"signal": self.signal, "noise": float(self.noise_spin.value()),
                "noise_seed": int(self._noise_seed)}
        opts.update(hierarchy_option(self._recipe_cache, state))
        return opts

    def _start_job(self, recipe_name: str, state, params, options: dict,
                   positions_job: str | None = None) -> None:
        """Start one of the panel's other recipes on ``state``: an analysis (the document does
        not change) or, with ``positions_job`` (the job's name, its undo text), a job whose
        result replaces the positions. Sets the run's options, recipe and request (the study
        log reads them) first."""
        recipe = self.recipe(recipe_name)
        self._job = recipe_name
        self._run_options = options
        self._run_recipe = recipe_name
        self.last_request = {"params": params, "options": options, "input": state,
                             "recipe": recipe_name}
        cache = self._recipe_cache

        def factory():
            return recipe.steps(state, params, options, cache)

        if positions_job is None:
            self.window_.start_analysis_job(self.title, factory)
        else:
            self.window_.start_positions_job(
                positions_job, factory,
                commit=lambda before, step: recipe.result(before, step, options))

    # -- caches ------------------------------------------------------------------------------------
    def hierarchy(self, F):
        """The hierarchy this panel holds for the faces ``F`` (the same array), or None."""
        return hierarchy_of(self._recipe_cache, F)

    # -- the smoothing job ----------------------------------------------------------------------------
    def run(self, live: bool = False) -> None:
        doc = self.window_.document
        if doc.is_empty:
            self.status_label.setText("Open a mesh first (File > Open).")
            return
        if self.signal == "noise" and NOISY_FIELD not in doc.state.fields:
            self.new_noise()
        if self.signal == "loaded" and LOADED_FIELD not in doc.state.fields:
            self.status_label.setText("Load a field first (Load field…).")
            return
        self._job = SMOOTH
        self._starting = True
        try:
            super().run(live)
        finally:
            self._starting = False

    def job_factory(self, state, params):
        # the recipe, its options and the cache are taken here, on the GUI thread
        recipe, options, cache = self.recipe(), self._run_options, self._recipe_cache
        return lambda: recipe.steps(state, params, options, cache)

    def _on_finished(self, step) -> None:
        if self.window_.last_job_name == FLOW_JOB:
            # what the flow held where it would cross itself, said when it is applied
            from app.recipes import held_crossings_note

            self._flow_note = held_crossings_note(step.metrics, FLOW)
        if self.window_.last_job_name != self.title:
            return
        info = getattr(step, "info", None)
        if self._job != SMOOTH or not info:  # a hierarchy build or a solver comparison
            self.stop_button.setEnabled(False)
            self.analysis_finished(step)
            return
        name = info.get("requested_solver", info.get("solver"))
        cyc = f", {plural(info['cycles'], 'cycle')}" if info.get("cycles") else ""
        if info.get("warm_start") and cyc:
            cyc += " from the last α"
        self.solve_times[name] = f"{info['seconds'] * 1000:.0f} ms{cyc}"
        self._show_times()
        self._show_hierarchy_info()
        if info.get("fallback"):  # multigrid did not converge: the direct solver's result
            name = "direct"
            cyc = ""
        auto = info.get("auto")
        pre = f"{info['fallback']} " if info.get("fallback") else (
            f"{auto[0].upper()}{auto[1:]}. " if auto else "")
        self.status_label.setText(
            f"{pre}Solved with {SOLVER_NAMES.get(name, name)} in "
            f"{info['seconds'] * 1000:.0f} ms{cyc}. Undo with Ctrl+Z.")
        if name == "direct" and not self.plot.series:
            self.plot.set_placeholder("The direct solver solved it exactly in one step: no "
                                      "V-cycles to plot. Choose Solver = multigrid to watch "
                                      "them converge.")
        self.stop_button.setEnabled(False)

    def _on_committed(self, name: str, after) -> None:
        super()._on_committed(name, after)
        if name == FLOW_JOB:
            self._show_hierarchy_info()
            note = getattr(self, "_flow_note", "")
            self._flow_note = ""
            self.status_label.setText("Flow applied." + (f" {note}" if note else "")
                                      + " Undo with Ctrl+Z.")
        if name == self.title:
            if self.signal != "positions" and self.view_combo.currentIndex() == 1:
                self.view_combo.setCurrentIndex(0)
            self.show_view()

    def _show_times(self) -> None:
        parts = [f"{SOLVER_NAMES[k]}: {v}" for k, v in self.solve_times.items()]
        self.times_label.setText("Last solve — " + " · ".join(parts) if parts else "")

    # -- compare solvers -------------------------------------------------------------------------------
    def compare_solvers(self) -> None:
        doc = self.window_.document
        if doc.is_empty:
            return
        if self.signal == "noise" and NOISY_FIELD not in doc.state.fields:
            self.new_noise()
        state = doc.state
        if self._input_values(state) is None:
            self.status_label.setText("Load a field first (Load field…).")
            return
        self.plot.clear()
        self.status_label.setText("Timing both solvers…")
        self._start_job(COMPARE, state, self.form.params(), self._analysis_options(state))

    # -- hierarchy -------------------------------------------------------------------------------------
    def build_hierarchy(self, force: bool = False) -> None:
        doc = self.window_.document
        if doc.is_empty:
            return
        if force:
            self._recipe_cache.clear()
        self.status_label.setText("Building the hierarchy…")
        self._start_job(HIERARCHY, doc.state, MultigridParams(), {})

    def _show_hierarchy_info(self) -> None:
        doc = self.window_.document
        mg = None if doc.is_empty else self.hierarchy(doc.F)
        if mg is None:
            self.hier_label.setText("Built on the first solve (or press Build).")
            self.level_spin.setRange(1, 1)
            return
        sizes = " → ".join(f"{len(Vh):,}" for Vh, _ in mg.levels)
        self.hier_label.setText(f"{plural(mg.n_levels, 'level')}: {sizes} vertices; built in "
                                f"{mg.build_seconds:.1f} s ({mg.report.get('prolongation')} "
                                "prolongation).")
        self.level_spin.setRange(1, max(1, mg.n_levels - 1))

    # -- mean curvature flow ------------------------------------------------------------------------------
    def run_flow(self, steps_count: int) -> None:
        doc = self.window_.document
        if doc.is_empty:
            self.status_label.setText("Open a mesh first (File > Open).")
            return
        state = doc.state
        # the one implementation of the flows, its linear solves by V-cycles on the hierarchy
        params = SmoothParams(flow="cmcf", step_size=self.dt_spin.value(),
                              iterations=int(steps_count))
        self.plot.clear()
        self.status_label.setText("Mean curvature flow…")
        self._start_job(FLOW, state, params, hierarchy_option(self._recipe_cache, state),
                        positions_job=FLOW_JOB)

    # -- views -----------------------------------------------------------------------------------------------
    def show_view(self) -> None:
        vp = self.window_.viewport
        doc = self.window_.document
        vp.show_overlay(None)
        if doc.is_empty:
            return
        i = self.view_combo.currentIndex()
        fields = doc.state.fields
        if i in (0, 1):
            src = self._input_values(doc.state) if self.signal != "positions" else None
            vals = fields.get(RESULT_FIELD) if i == 0 and self.signal != "positions" else src
            if vals is None:
                # no smoothed field yet (a new noisy field, or undone to it): show the input
                # rather than an uncoloured mesh
                vals = src
            if vals is None:
                vp.show_field(None)
                return
            vp.show_field("signal", vals, "viridis", signal_range(src))
            return
        mg = self.hierarchy(doc.F)
        if mg is None or mg.n_levels < 2:
            vp.show_field(None)
            self.status_label.setText("No coarse levels yet: press Build (meshes under ~2,000 "
                                      "vertices have a single level).")
            return
        level = min(self.level_spin.value(), mg.n_levels - 1)
        if i == 2:
            vp.show_field(None)
            Vc, Fc = mg.levels[level]
            vp.show_overlay(Vc, Fc)
        else:  # the colour of the coarse triangle of each fine centroid
            vp.show_field("coarse_triangle", coarse_triangle_colors(mg, level), "tab20",
                          (0.0, 19.0), categorical=True)

    def _on_visibility(self, visible: bool) -> None:
        if not visible:  # another panel takes over the viewport: the document's mesh comes back
            self.window_.viewport.show_overlay(None)
        elif self.view_combo.currentIndex() >= 2:
            self.show_view()

    def _on_doc(self, what: str) -> None:
        if what in ("mesh", "topology"):
            self._recipe_cache.clear()
            self.solve_times = {}
            self._show_times()
            self._show_hierarchy_info()
        if self.is_shown() and what in ("mesh", "topology", "fields"):
            self.show_view()

    def analysis_finished(self, step=None) -> None:
        """After an analysis job of this panel (hierarchy build, solver comparison); ``step``:
        its last step."""
        self._show_hierarchy_info()
        times = getattr(step, "info", None) if self._job == COMPARE else None
        if times:
            for k, info in times.items():
                cyc = f", {plural(info['cycles'], 'cycle')}" if info.get("cycles") else ""
                self.solve_times[k] = f"{info['seconds'] * 1000:.0f} ms{cyc}"
            self._show_times()
            mgt, dt = times["multigrid"]["seconds"], times["direct"]["seconds"]
            self.status_label.setText(f"Multigrid {mgt * 1000:.0f} ms vs direct "
                                      f"{dt * 1000:.0f} ms at this α ({dt / max(mgt, 1e-9):.1f}× "
                                      "faster)." if mgt < dt else
                                      f"Multigrid {mgt * 1000:.0f} ms vs direct "
                                      f"{dt * 1000:.0f} ms at this α (small meshes favour the "
                                      "direct solver).")
        elif self._job == HIERARCHY and getattr(step, "mg", None) is not None:
            self.status_label.setText("Hierarchy built.")
            self.show_view()
