"""Panel "Spectral coarsening" (thesis ch. 7): coarsen the mesh's operator with ours, QSlim and
AMG; see the energy per iteration, the clusters and root nodes on the mesh, the |C| heat maps of
the three methods side by side (Fig. 7.1), the eigenvalues (Fig. 7.2), and browse eigenfunctions:
Φ_i on the fine mesh next to the prolonged coarse eigenvector. The mesh itself never changes.

The run is the recipe "Spectral coarsening" (:mod:`app.recipes.spectral`) in a child process
(option ``isolated``); the views read its outcome (``self.outcome``) through that module's
plain functions.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtGui import QImage, QPixmap
from PySide6.QtWidgets import (QComboBox, QGridLayout, QGroupBox, QHBoxLayout, QLabel,
                               QSpinBox, QVBoxLayout)

from algorithms.errors import Stylize3DError
from algorithms.spectral.coarsen import CoarsenParams
from app.panels.base import MethodPanel
from app.recipes import spectral as recipe_mod
from app.widgets import LinePlot

OPERATORS = {"cotangent": "cotangent", "intrinsic Delaunay": "intrinsic_delaunay",
             "anisotropic (α 70)": "anisotropic", "graph": "graph",
             "point cloud (vertices only)": "point_cloud"}
#: the anisotropy the panel uses for "anisotropic (α 70)" (the others ignore it)
ANISOTROPIC_ALPHA = 70.0
METHODS = recipe_mod.METHODS


def heatmap_image(C: np.ndarray, size: int = 140) -> QImage:
    """|C| as a white-to-dark-blue image (size × size), see recipes.spectral.heatmap_rgb."""
    buf = recipe_mod.heatmap_rgb(C, size)
    return QImage(buf.data, size, size, 3 * size, QImage.Format.Format_RGB888).copy()


class SpectralPanel(MethodPanel):
    counts_iterations = False  # its steps are stages and solver cycles
    title = "Spectral coarsening"
    description = ("Builds a small operator (m rows) whose low eigenvectors and eigenvalues match "
                   "the mesh's, and compares it with simplification (QSlim) and algebraic "
                   "multigrid. The mesh is not changed.")
    params_cls = CoarsenParams
    plot_metrics = ("energy",)
    plot_title = "Energy per optimizer iteration"
    plot_log_y = True
    param_auto_text = {"k": lambda p: f"auto ({max(1, round(p.m / 3))})"}  # 0 = round(m/3)

    def __init__(self, window):
        super().__init__(window)
        self.outcome: dict | None = None   # the last finished run's recipe outcome
        self._outcome_shape: tuple | None = None   # the shape of V it was computed on
        self._coarse_eigs = None
        self.live_box.setChecked(False)
        self.live_box.setVisible(False)
        lay = self.body_layout
        row = QHBoxLayout()
        self.operator_combo = QComboBox()
        self.operator_combo.addItems(list(OPERATORS))
        self.operator_combo.setToolTip("The operator to coarsen (its mass matrix comes along).")
        row.addWidget(QLabel("Operator"))
        row.addWidget(self.operator_combo, 1)
        lay.insertLayout(lay.indexOf(self.form), row)

        res = QGroupBox("Results")
        g = QVBoxLayout(res)
        grid = QGridLayout()
        self.heatmaps: dict[str, QLabel] = {}
        self.scores: dict[str, QLabel] = {}
        method_tips = {
            "ours": "Ours: spectral coarsening (this panel's method), which optimizes the coarse "
                    "operator so its low eigenvectors match the fine mesh's.",
            "qslim": "QSlim: the usual way to make a coarse mesh (simplify the shape by "
                     "collapsing edges), then build its operator; shown for comparison.",
            "amg": "AMG: algebraic multigrid's coarsening of the matrix, which ignores the "
                   "shape; shown for comparison.",
        }
        score_tip = ("C diag: how well the coarse eigenvectors match the fine ones (1 = "
                     "perfectly, 0 = not at all). Eig err: mean relative error of the first k "
                     "eigenvalues (0 = exact). Higher C diag and lower eig err are better.")
        for j, name in enumerate(METHODS):
            t = QLabel(name)
            t.setAlignment(Qt.AlignmentFlag.AlignCenter)
            t.setToolTip(method_tips[name])
            img = QLabel()
            img.setFixedSize(110, 110)
            img.setToolTip(f"|C| of {name}: a clean diagonal means the coarse eigenvectors match "
                           "the fine ones (thesis Fig. 7.1).")
            sc = QLabel("")
            sc.setAlignment(Qt.AlignmentFlag.AlignCenter)
            sc.setToolTip(score_tip)
            grid.addWidget(t, 0, j)
            grid.addWidget(img, 1, j)
            grid.addWidget(sc, 2, j)
            self.heatmaps[name], self.scores[name] = img, sc
        g.addLayout(grid)
        self.eig_plot = LinePlot("Eigenvalues: fine and coarse (first k)")
        g.addWidget(self.eig_plot)
        row = QHBoxLayout()
        self.show_combo = QComboBox()
        self.show_combo.addItems(["Shape only", "Clusters and roots", "Fine eigenfunction Φ_i",
                                  "Prolonged coarse eigenvector"])
        self.show_combo.setToolTip("What to draw on the mesh.")
        self.eig_index = QSpinBox()
        self.eig_index.setRange(1, 1)
        self.eig_index.setToolTip("Which eigenfunction (1 = the first non-constant one).")
        row.addWidget(self.show_combo, 1)
        row.addWidget(QLabel("i"))
        row.addWidget(self.eig_index)
        g.addLayout(row)
        lay.insertWidget(lay.indexOf(self.plot) + 1, res)
        self.show_combo.currentIndexChanged.connect(lambda _i: self.show_result())
        self.eig_index.valueChanged.connect(lambda _i: self.show_result())
        window.mesh_shown.connect(self._fit_size_to_mesh)
        window.document.subscribe(self._on_doc)
        # what a run with these settings will take, said before it starts (issue 24 item 1)
        self.estimate_label = QLabel("")
        self.estimate_label.setWordWrap(True)
        self.estimate_label.setToolTip(
            "An estimate from a simple cost model of the stages (eigenvectors of the mesh's "
            "operator, clustering, optimizing, balancing, comparing with QSlim and AMG): "
            "larger m, k or iteration counts take longer.")
        fl = self.footer.layout()
        fl.insertWidget(1, self.estimate_label)
        self.form.changed.connect(lambda _p: self.update_estimate())
        self.operator_combo.currentIndexChanged.connect(lambda _i: self.update_estimate())
        window.mesh_shown.connect(self.update_estimate)
        # the base's tooltip promises an undo: an analysis changes nothing to undo
        self.run_button.setToolTip("Coarsen the operator and compare with the baselines. The "
                                   "mesh is not changed; the results appear below.")

    def _fit_size_to_mesh(self) -> None:
        """A newly opened mesh gets a coarse size that suits it: the thesis's 500, but at most
        n / 8 (see suggested_coarse_size); the panel says so."""
        doc = self.window_.document
        if doc.is_empty:
            return
        n = len(doc.V)
        m = recipe_mod.suggested_coarse_size(n, CoarsenParams().m)
        current = self.form.editors["m"].value()
        # never override a size the user chose: only the default or our last suggestion
        untouched = current in (CoarsenParams().m, getattr(self, "_suggested_m", None))
        self._suggested_m = m
        if untouched and current != m:
            self.form.set_value("m", m)
            self.form.set_value("k", 0)
            self.status_label.setText(
                f"Coarse size set to m = {m} for this {n:,}-vertex mesh (spectral coarsening "
                f"is made for strong reductions: at most n/8), k = {round(m / 3)} eigenvectors.")
        elif untouched:  # a word about this mesh, never the last mesh's
            self.status_label.setText(f"Coarse size m = {m} suits this {n:,}-vertex mesh.")
        else:
            self.status_label.setText(f"Coarse size m = {current} (your choice) for this "
                                      f"{n:,}-vertex mesh; Defaults suggests {m}.")

    def update_estimate(self) -> None:
        """Say next to Run about how long a run with the form's settings will take on the
        open mesh (app.recipes.spectral.estimate_text)."""
        doc = self.window_.document
        if doc.is_empty:
            self.estimate_label.setText("")
            return
        try:
            text = recipe_mod.estimate_text(len(doc.V), self.form.params(), self.job_options())
        except Stylize3DError:
            text = ""
        self.estimate_label.setText(text)

    def _on_preview(self, step) -> None:
        """The run's one progress: the stage with its step of total, the time so far and
        what is left (the same words as the status bar's)."""
        if not self._mine():
            return
        import time

        elapsed = time.perf_counter() - self.window_.runner.started_at
        self.status_label.setText(f"{step.message} ({elapsed:.0f} s so far, "
                                  f"{step.iteration} % done)")

    # -- the job ---------------------------------------------------------------------------------
    def job_options(self) -> dict:
        """The operator (and its anisotropy), both baselines, and the child process the
        computation runs in (see app.recipes.spectral)."""
        op = OPERATORS[self.operator_combo.currentText()]
        return {"operator": op, "alpha": ANISOTROPIC_ALPHA if op == "anisotropic" else 10.0,
                "compare": list(recipe_mod.BASELINES), "isolated": True}

    def restore_options(self, options: dict) -> None:
        op = options.get("operator", "cotangent")
        for label, name in OPERATORS.items():
            if name == op:
                self.operator_combo.setCurrentText(label)
                break

    def job_factory(self, state, params):
        """The recipe's steps with this run's options (read on the GUI thread at Run)."""
        recipe, options, cache = self.recipe(), dict(self._run_options or {}), self._recipe_cache
        return lambda: recipe.steps(state, params, options, cache)

    def run(self, live: bool = False) -> None:
        state = self.window_.document.state
        if state is None:
            self.status_label.setText("Open a mesh first (File > Open).")
            return
        params = self.form.params()
        self._pending_input = state
        # read once, here on the GUI thread: the worker and the study log use it
        self._run_options = self.job_options()
        self._run_recipe = self.recipe_name or self.title
        self.last_request = {"params": params, "options": self._run_options, "input": state,
                             "recipe": self._run_recipe}
        self.plot.clear()
        self.status_label.setText("Starting: " + (self.estimate_label.text() or "…"))
        self.window_.start_analysis_job(self.title, self.job_factory(state, params))

    def _on_finished(self, step) -> None:
        super()._on_finished(step)
        if self.window_.last_job_name != self.title:
            return
        recipe = self.recipe()
        outcome = recipe.outcome(step) if recipe is not None else {}
        if outcome:
            self.outcome = outcome
            self._outcome_shape = np.shape(step.V)
            self._coarse_eigs = None
            self.show_comparison()

    # -- display -----------------------------------------------------------------------------------
    def show_comparison(self) -> None:
        r = self.outcome
        for name in METHODS:
            if name not in r["methods"]:
                self.heatmaps[name].clear()
                self.scores[name].setText("left out" if name != "ours" else "")
                continue
            self.heatmaps[name].setPixmap(QPixmap.fromImage(heatmap_image(r[f"{name}.C"], 110)))
            self.scores[name].setText(f"C diag {r[f'{name}.c_diag_score']:.3f}\n"
                                      f"eig err {r[f'{name}.eig_rel_error_mean']:.3f}")
        self.eig_plot.clear()
        k = r["k"]
        for v in r["fine.eigenvalues"][:k]:
            self.eig_plot.append("fine", float(v))
        for name in METHODS:
            if name in r["methods"]:
                for v in r[f"{name}.eigenvalues"][:k]:
                    self.eig_plot.append(name, float(v))
        self.eig_index.setRange(1, max(1, k - 1))
        self.status_label.setText(
            f"n = {r['n']} → m = {r['m']}, k = {r['k']}. Ours: C diag "
            f"{r['ours.c_diag_score']:.3f}, mean eigenvalue error "
            f"{r['ours.eig_rel_error_mean']:.3f}."
            + "".join(f"\n{note}" for note in r["notes"]))
        if self.show_combo.currentIndex() == 0:
            self.show_combo.setCurrentIndex(1)
        else:
            self.show_result()

    #: colour views this panel draws (taken off the 3D view with its root dots when hidden)
    _own_fields = ("clusters", "eigenfunction")

    def hide_view(self) -> None:
        vp = self.window_.viewport
        vp.show_points(None)
        if getattr(vp, "_field_name", None) in self._own_fields:
            vp.show_field(None)

    def refresh_view(self) -> None:
        self.show_result()

    def _on_doc(self, what: str) -> None:
        # the roots and colours were computed on the mesh as it was: when it moves or changes,
        # draw them again (show_result checks the result still fits) or take them off
        if what in ("positions", "topology", "mesh"):
            if self.is_shown():
                self.show_result()
            else:
                self.hide_view()

    def show_result(self) -> None:
        vp = self.window_.viewport
        doc = self.window_.document
        r = self.outcome
        if r is None or doc.is_empty or doc.state.V.shape != self._outcome_shape:
            vp.show_field(None)
            vp.show_points(None)
            return
        i = self.show_combo.currentIndex()
        vp.show_points(None)
        if i == 0:
            vp.show_field(None)
        elif i == 1:
            vp.show_field("clusters", recipe_mod.cluster_field(r), "tab20",
                          (0.0, float(r["m"] - 1)), categorical=True)
            vp.show_points(doc.V[r["ours.roots"]])
        else:
            if i == 2:
                f = recipe_mod.fine_eigenfunction(r, self.eig_index.value())
            else:
                if self._coarse_eigs is None:
                    try:
                        self._coarse_eigs = recipe_mod.coarse_eigenpairs(r)
                    except Stylize3DError as e:   # a plain message, never a traceback
                        self.status_label.setText(f"Cannot show the coarse eigenvectors: {e}")
                        vp.show_field(None)
                        return
                f = recipe_mod.prolonged_eigenvector(r, self.eig_index.value(),
                                                     self._coarse_eigs)
            lim = float(np.abs(f).max()) or 1.0
            vp.show_field("eigenfunction", f, "RdBu", (-lim, lim))
