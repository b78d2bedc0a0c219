"""Panel "Spectral coarsening" (thesis ch. 7): coarsen the mesh's operator with ours, QSlim and
AMG; see the energy per iteration, the clusters and root nodes on the mesh, the |C| heat maps of
the three methods side by side (Fig. 7.1), the eigenvalues (Fig. 7.2), and browse eigenfunctions:
Φ_i on the fine mesh next to the prolonged coarse eigenvector. The mesh itself never changes.
"""

from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtGui import QColor, QImage, QPixmap
from PySide6.QtWidgets import (QComboBox, QGridLayout, QGroupBox, QHBoxLayout, QLabel,
                               QSpinBox, QVBoxLayout, QWidget)

from algorithms.errors import Stylize3DError
from algorithms.spectral.coarsen import CoarsenParams, generalized_eigs, suggested_coarse_size
from algorithms.spectral.compare import compare_coarsenings_iter
from algorithms.steps import Step, isolated_iter
from app.panels.base import MethodPanel
from app.widgets import LinePlot

OPERATORS = {"cotangent": "cotangent", "intrinsic Delaunay": "intrinsic_delaunay",
             "anisotropic (α 70)": "anisotropic", "graph": "graph",
             "point cloud (vertices only)": "point_cloud"}
METHODS = ("ours", "qslim", "amg")


def heatmap_image(C: np.ndarray, size: int = 140) -> QImage:
    """|C| as a white-to-dark-blue image (size × size)."""
    A = np.abs(np.asarray(C, dtype=np.float64))
    A = A / max(A.max(), 1e-12)
    k = A.shape[0]
    idx = (np.arange(size) * k // size).clip(0, k - 1)
    A = A[np.ix_(idx, idx)]
    rgb = np.empty(A.shape + (3,), dtype=np.uint8)
    rgb[..., 0] = (255 * (1 - 0.85 * A)).astype(np.uint8)
    rgb[..., 1] = (255 * (1 - 0.7 * A)).astype(np.uint8)
    rgb[..., 2] = (255 * (1 - 0.35 * A)).astype(np.uint8)
    buf = np.ascontiguousarray(rgb)
    return QImage(buf.data, size, size, 3 * size, QImage.Format.Format_RGB888).copy()


class SpectralPanel(MethodPanel):
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
        self.result = None
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

    def _fit_size_to_mesh(self) -> None:
        """A newly opened mesh gets a coarse size that suits it: the thesis's 500, but at most
        n / 8 (see suggested_coarse_size); the panel says so."""
        doc = self.window_.document
        if doc.is_empty:
            return
        n = len(doc.V)
        m = suggested_coarse_size(n, CoarsenParams().m)
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

    # -- the job ---------------------------------------------------------------------------------
    def run(self, live: bool = False) -> None:
        state = self.window_.document.state
        if state is None:
            self.status_label.setText("Open a mesh first (File > Open).")
            return
        params = self.form.params()
        op = OPERATORS[self.operator_combo.currentText()]
        alpha = 70.0 if op == "anisotropic" else 10.0
        self.plot.clear()
        self.status_label.setText("Eigenvectors of the fine operator…")
        holder = self._holder = {}

        def steps():
            # in a child process: ARPACK, SciPy's sparse products and PyAMG hold the GIL for
            # seconds, which would freeze the window even from the worker thread
            gen = isolated_iter(compare_coarsenings_iter, state.V, state.F, op, params.m,
                                params.k or None, params, alpha=alpha, eig_progress=True)
            while True:
                try:
                    cs = next(gen)
                except StopIteration as stop:
                    holder["result"] = stop.value
                    holder["state"] = state
                    yield Step(holder.get("it", 0) + 1, None, state.V, {}, "done")
                    return
                if np.isnan(cs.energy):      # the eigenvector stage: its own progress
                    yield Step(cs.iteration, cs.total, state.V, {}, cs.message)
                    continue
                holder["it"] = cs.iteration
                yield Step(cs.iteration, cs.total, state.V, {"energy": cs.energy},
                           f"iteration {cs.iteration}")

        self.window_.start_analysis_job(self.title, steps)

    def _on_finished(self, step) -> None:
        super()._on_finished(step)
        holder = getattr(self, "_holder", {})
        if self.window_.last_job_name == self.title and "result" in holder:
            self.result = holder["result"]
            self._result_state = holder["state"]
            self._coarse_eigs = None
            self.show_comparison()

    # -- display -----------------------------------------------------------------------------------
    def show_comparison(self) -> None:
        r = self.result
        for name in METHODS:
            mr = r.methods.get(name)
            if mr is None:
                self.heatmaps[name].clear()
                self.scores[name].setText("left out" if name != "ours" else "")
                continue
            self.heatmaps[name].setPixmap(QPixmap.fromImage(heatmap_image(mr.spectral.C, 110)))
            self.scores[name].setText(f"C diag {mr.metrics['c_diag_score']:.3f}\n"
                                      f"eig err {mr.metrics['eig_rel_error_mean']:.3f}")
        self.eig_plot.clear()
        ours = r.methods["ours"].spectral
        k = r.k
        for v in ours.lam_fine[:k]:
            self.eig_plot.append("fine", float(v))
        for name in METHODS:
            if name in r.methods:
                for v in r.methods[name].spectral.lam_coarse[:k]:
                    self.eig_plot.append(name, float(v))
        self.eig_index.setRange(1, max(1, k - 1))
        self.status_label.setText(
            f"n = {r.n} → m = {r.m}, k = {r.k}. Ours: C diag "
            f"{r.methods['ours'].metrics['c_diag_score']:.3f}, mean eigenvalue error "
            f"{r.methods['ours'].metrics['eig_rel_error_mean']:.3f}."
            + "".join(f"\n{note}" for note in getattr(r, "notes", [])))
        if self.show_combo.currentIndex() == 0:
            self.show_combo.setCurrentIndex(1)
        else:
            self.show_result()

    def show_result(self) -> None:
        vp = self.window_.viewport
        doc = self.window_.document
        r = self.result
        if r is None or doc.is_empty or doc.state.V.shape != self._result_state.V.shape:
            vp.show_field(None)
            vp.show_points(None)
            return
        i = self.show_combo.currentIndex()
        ours = r.methods["ours"]
        vp.show_points(None)
        if i == 0:
            vp.show_field(None)
        elif i == 1:
            K = ours.extra["K"].tocsc()
            labels = np.asarray(K.argmax(axis=0)).ravel().astype(float)
            rng = np.random.default_rng(0).permutation(r.m).astype(float)
            vp.show_field("clusters", rng[labels.astype(int)], "tab20", (0.0, float(r.m - 1)),
                          categorical=True)
            roots = np.asarray(ours.P.tocsr().argmax(axis=1)).ravel()
            vp.show_points(doc.V[roots])
        else:
            lam_f, phi_f = r.fine_eigs
            j = min(self.eig_index.value(), phi_f.shape[1] - 1)
            if i == 2:
                f = phi_f[:, j]
            else:
                if self._coarse_eigs is None:
                    try:
                        self._coarse_eigs = generalized_eigs(ours.L, ours.M,
                                                             min(r.k + 1, r.m - 1))
                    except Stylize3DError as e:   # a plain message, never a traceback
                        self.status_label.setText(f"Cannot show the coarse eigenvectors: {e}")
                        vp.show_field(None)
                        return
                phi_c = self._coarse_eigs[1]
                f = ours.extra["G"] @ phi_c[:, min(j, phi_c.shape[1] - 1)]
                if f @ phi_f[:, j] < 0:  # eigenvectors have arbitrary signs
                    f = -f
            lim = float(np.abs(f).max()) or 1.0
            vp.show_field("eigenfunction", f, "RdBu", (-lim, lim))
