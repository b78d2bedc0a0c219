"""Panel "Multigrid smoothing" (thesis ch. 8): smooth a signal on the surface with the surface
multigrid solver, drag the smoothness and see the result at once, compare with a direct solver,
look at the hierarchy, and run mean curvature flow on the same hierarchy.

Signals: a noisy test field made in the app, a per-vertex field loaded from a file, or the vertex
positions themselves. Scalar results go into the document as the field "smoothed" (undoable,
saved with "Save field…"); smoothed positions replace the shape (undoable). Live α changes merge
into one undo step. The hierarchy (geometry only) is built once per mesh connectivity and reused
by every solve, every α, every energy and every flow step.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from PySide6.QtWidgets import (QComboBox, QDoubleSpinBox, QGridLayout, QGroupBox, QHBoxLayout,
                               QLabel, QPushButton, QSpinBox, QVBoxLayout)

from algorithms.errors import Stylize3DError
from algorithms.mesh.fields import FIELD_EXTENSIONS, field_file_filter, read_field, write_field
from algorithms.multigrid import greedy_coloring, surface_multigrid
from algorithms.multigrid.applications import DataSmoother, choose_solver
from algorithms.multigrid.params import DataSmoothingParams
from algorithms.smoothing import SmoothParams, noisy_test_field, smooth_iter, unit_area
from algorithms.steps import Step, with_progress
from app import dialogs
from app.commands import StateCommand
from app.panels.base import MethodPanel
from app.widgets import plural

NOISY_FIELD = "noisy input"
LOADED_FIELD = "loaded field"
RESULT_FIELD = "smoothed"
SIGNALS = ("Noisy test field", "Vertex positions", "Loaded field")
VIEWS = ("Result", "Input signal", "Coarse level mesh", "Fine triangles by coarse triangle")
SOLVER_NAMES = {"multigrid": "multigrid", "direct": "direct (CHOLMOD)"}
#: at most this many CG steps per multigrid solve (they also stop early on growth or a stall)
MAX_ITERATIONS = 100


class MultigridPanel(MethodPanel):
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
        self._hierarchies: dict = {}    # id(F) -> (F, SurfaceMultigrid)
        self._smoothers: dict = {}      # (id(V), id(F), energy, solver) -> (V, F, DataSmoother)
        self._last_solution = None      # (key, u) of the last solve, the next α's first guess
        self.solve_times: dict[str, str] = {}
        self._holder: dict = {}
        lay = self.body_layout

        # -- signal ---------------------------------------------------------------------------
        sig = QGroupBox("Signal")
        g = QGridLayout(sig)
        self.signal_combo = QComboBox()
        self.signal_combo.addItems(SIGNALS)
        self.signal_combo.setToolTip(
            "What to smooth. Noisy test field: a smooth pattern plus noise, made here. Vertex "
            "positions: smooths the shape itself. Loaded field: one number per vertex from a file.")
        self.noise_spin = QDoubleSpinBox()
        self.noise_spin.setRange(0.0, 3.0)
        self.noise_spin.setSingleStep(0.05)
        self.noise_spin.setValue(0.4)
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
        return ("noise", "positions", "loaded")[self.signal_combo.currentIndex()]

    def _push(self, after, text: str) -> None:
        doc = self.window_.document
        self.window_.undo_stack.push(StateCommand(doc, doc.state, after, text))

    def new_noise(self) -> None:
        doc = self.window_.document
        if doc.is_empty:
            self.status_label.setText("Open a mesh first (File > Open).")
            return
        seed = int(time.time_ns() % (2**31))
        _clean, noisy = noisy_test_field(doc.V, doc.F, self.noise_spin.value(), seed)
        self._push(doc.state.with_field(NOISY_FIELD, noisy).with_field(RESULT_FIELD, None),
                   "New noisy test field")
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
        self._push(doc.state.with_field(LOADED_FIELD, values).with_field(RESULT_FIELD, None),
                   "Load field")
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

    # -- caches (filled on the worker thread, read on the GUI thread) -------------------------------
    def hierarchy(self, F):
        hit = self._hierarchies.get(id(F))
        return hit[1] if hit is not None and hit[0] is F else None

    def _hierarchy_steps(self, V, F, holder):
        """Steps while the hierarchy of (V, F) is built (nothing when it exists)."""
        mg = self.hierarchy(F)
        if mg is None:
            out: dict = {}
            yield from with_progress(lambda progress: surface_multigrid(V, F, progress=progress),
                                     V, out)
            mg = out["value"]
            self._hierarchies = {id(F): (F, mg)}  # one mesh at a time
            self._smoothers = {}
        holder["mg"] = mg
        return mg

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
        super().run(live)

    def commit_function(self):
        # Called on the GUI thread just before the job starts; build_steps (worker thread) fills
        # this same holder. Only the newest job runs (the runner drops superseded ones), and it
        # is the one whose commit function the window keeps.
        holder = self._holder = {"signal": self.signal}  # widgets are read here, not later
        if self.signal == "positions":
            return None

        def commit(before, _step):
            return before.with_field(RESULT_FIELD, holder["u"])

        return commit

    def build_steps(self, state, params):
        holder = self._holder
        solver, why = params.solver, None
        if solver == "auto":
            solver, why = choose_solver(len(state.V), params.energy)
        holder["solver"], holder["auto"] = solver, why
        signal = holder["signal"]
        f_src = self._input_values(state, signal)
        if f_src is None:
            raise Stylize3DError("There is no input signal: make a noisy field or load one.")
        f = np.array(f_src, dtype=np.float64)
        V, F = state.V, state.F
        rtol = 1e-5

        def steps():
            mg = None
            if solver == "multigrid":
                mg = yield from self._hierarchy_steps(V, F, holder)
            key = (id(V), id(F), params.energy, solver)
            hit = self._smoothers.get(key)
            if hit is not None and hit[0] is V and hit[1] is F:
                sm = hit[2]
            else:
                yield Step(0, None, V, {}, "preparing the Galerkin matrices")
                sm = DataSmoother(unit_area(V, F), F, energy=params.energy,
                                  solver=solver, mg=mg)
                self._smoothers[key] = (V, F, sm)
            # a new α starts from the previous α's solution (same input, same operator): about
            # half the V-cycles while the slider moves
            warm_key = key + (id(f_src),)
            last = self._last_solution
            x0 = (last[1] if last is not None and last[0] == warm_key
                  and last[1].shape == f.shape else None)
            # an unconverged solve falls back to the direct solver when it fits in memory
            # (info["fallback"] says so) or raises NotConvergedError: the job fails, the
            # document stays as it was and the message is shown
            u, info = sm.smooth_checked(f, params.alpha, rtol=rtol, maxiter=MAX_ITERATIONS,
                                        x0=x0)
            self._last_solution = (warm_key, u)
            info["warm_start"] = x0 is not None
            res = np.asarray(info.get("residuals") or [], dtype=np.float64)
            if res.size:
                res = res / (res[0] if res[0] > 0 else 1.0)
                for k, r in enumerate(res[1:], 1):
                    yield Step(k, None, V, {"relative residual": float(r)}, "")
            holder.update(u=u, info=info)
            Vout = u if signal == "positions" else V
            yield Step(int(info.get("cycles", 0)), None, Vout, {},
                       f"{info['seconds']:.3f} s")

        return steps()

    def _on_finished(self, step) -> None:
        if self.window_.last_job_name != self.title:
            return
        holder = self._holder
        info = holder.get("info")
        if info is None:  # a hierarchy build or a solver comparison
            self.stop_button.setEnabled(False)
            self.analysis_finished()
            return
        name = holder["solver"]
        cyc = f", {plural(info['cycles'], 'cycle')}" if info.get("cycles") else ""
        if info.get("warm_start") and cyc:
            cyc += " from the last α"
        self.solve_times[name] = f"{info['seconds'] * 1000:.0f} ms{cyc}"
        self._show_times()
        self._show_hierarchy_info()
        if info.get("fallback"):  # multigrid did not converge: the direct solver's result
            name = "direct"
            cyc = ""
        pre = f"{info['fallback']} " if info.get("fallback") else (
            f"{holder['auto'][0].upper()}{holder['auto'][1:]}. " if holder.get("auto") else "")
        self.status_label.setText(
            f"{pre}Solved with {SOLVER_NAMES.get(name, name)} in "
            f"{info['seconds'] * 1000:.0f} ms{cyc}. Undo with Ctrl+Z.")
        self.stop_button.setEnabled(False)

    def _on_committed(self, name: str, after) -> None:
        super()._on_committed(name, after)
        if name == "Mean curvature flow":
            self._show_hierarchy_info()
            self.status_label.setText("Flow applied. Undo with Ctrl+Z.")
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
        f = self._input_values(state)
        if f is None:
            self.status_label.setText("Load a field first (Load field…).")
            return
        params = self.form.params()
        V, F = state.V, state.F
        holder = self._holder = {}
        f = np.array(f, dtype=np.float64)

        def steps():
            mg = yield from self._hierarchy_steps(V, F, holder)
            times = {}
            for k, solver in enumerate(("multigrid", "direct")):
                sm = DataSmoother(unit_area(V, F), F, energy=params.energy, solver=solver,
                                  mg=mg if solver == "multigrid" else None)
                _u, info = sm.smooth_checked(f, params.alpha, rtol=1e-5,
                                             maxiter=MAX_ITERATIONS)
                times[solver] = info
                yield Step(k + 1, 2, V, {}, f"{solver}: {info['seconds']:.3f} s")
            holder["times"] = times

        self.plot.clear()
        self.status_label.setText("Timing both solvers…")
        self.window_.start_analysis_job(self.title, steps)
        self._compare_holder = holder

    # -- hierarchy -------------------------------------------------------------------------------------
    def build_hierarchy(self, force: bool = False) -> None:
        doc = self.window_.document
        if doc.is_empty:
            return
        if force:
            self._hierarchies = {}
            self._smoothers = {}
        V, F = doc.V, doc.F
        holder = self._holder = {}

        def steps():
            yield from self._hierarchy_steps(V, F, holder)
            yield Step(1, 1, V, {}, "hierarchy built")

        self.status_label.setText("Building the hierarchy…")
        self.window_.start_analysis_job(self.title, steps)

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
        V, F = state.V, state.F
        # the one implementation of the flows, its linear solves by V-cycles on the hierarchy
        params = SmoothParams(flow="cmcf", step_size=self.dt_spin.value(),
                              iterations=int(steps_count))
        holder = self._holder = {}

        def steps():
            mg = yield from self._hierarchy_steps(V, F, holder)
            yield from smooth_iter(V, F, params, multigrid=mg)

        self.plot.clear()
        self.status_label.setText("Mean curvature flow…")
        self.window_.start_positions_job("Mean curvature flow", steps)

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
                vp.show_field(None)
                return
            lim = (float(np.min(src)), float(np.max(src))) if src is not None else None
            vp.show_field("signal", vals, "viridis", lim)
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
        else:
            labels, _bary = mg.locate(level)  # the coarse triangle of each fine centroid
            colors = self._coarse_face_colors(mg, level)
            vp.show_field("coarse_triangle", colors[labels].astype(float), "tab20",
                          (0.0, 19.0), categorical=True)

    @staticmethod
    def _coarse_face_colors(mg, level: int) -> np.ndarray:
        """Colours 0..19 of the coarse triangles, different for triangles sharing a vertex
        (greedy colouring of the face graph, Alg. 10; wraps around only past 20 colours)."""
        Fc = mg.levels[level][1]
        nv = int(Fc.max()) + 1
        inc = sp.csr_matrix((np.ones(Fc.size), (np.repeat(np.arange(len(Fc)), 3), Fc.ravel())),
                            shape=(len(Fc), nv))
        return greedy_coloring(inc @ inc.T) % 20

    def _on_visibility(self, visible: bool) -> None:
        if not visible:  # another panel takes over the viewport: the document's mesh comes back
            self.window_.viewport.show_overlay(None)
        elif self.view_combo.currentIndex() >= 2:
            self.show_view()

    def _on_doc(self, what: str) -> None:
        if what in ("mesh", "topology"):
            self._hierarchies, self._smoothers = {}, {}
            self._last_solution = None
            self.solve_times = {}
            self._show_times()
            self._show_hierarchy_info()
        if self.is_shown() and what in ("mesh", "topology", "fields"):
            self.show_view()

    def analysis_finished(self) -> None:
        """After an analysis job of this panel (hierarchy build, solver comparison)."""
        self._show_hierarchy_info()
        times = self._holder.get("times")
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
        elif self._holder.get("mg") is not None:
            self.status_label.setText("Hierarchy built.")
            self.show_view()
