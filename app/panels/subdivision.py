"""Panel "Subdivision": neural subdivision (thesis ch. 4) and the classic schemes.

* Subdivide the current mesh 1-3 levels with neural / Loop / butterfly / mid-point; each result
  is one undoable command (the mesh's connectivity changes). "Coarsen first" QSlims the mesh to
  a vertex count before, so a user can watch a method rebuild the detail.
* Weights: the shipped ones, the ones trained here, or a weights file.
* "Train on this mesh": data generation (with progress) then training, the training and
  validation losses streamed to the plot; Stop keeps the best weights so far; "Save weights…"
  writes them.

The subdivided mesh has other vertices and faces than the input: the last step is a
:class:`~app.jobs.MeshStep` carrying them, committed as the new mesh by the shared mechanism of
:class:`~app.panels.base.MethodPanel` (``changes_faces``).
"""

from __future__ import annotations

from typing import Any, Iterator

import numpy as np
from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QPushButton, QSpinBox

from algorithms.steps import Step, with_progress
from algorithms.subdivision.model import SubdivideParams
from app.document import MeshState
from app.jobs import MeshStep
from app.panels.base import MethodPanel


class SubdivisionPanel(MethodPanel):
    title = "Subdivision"
    description = ("Subdivides the mesh: neural subdivision (learned from example meshes, "
                   "thesis ch. 4) or Loop, modified butterfly, mid-point. Try 'Coarsen first' "
                   "= 400 to see a method rebuild the detail.")
    params_cls = SubdivideParams
    plot_metrics = ("loss", "validation_loss")
    plot_title = "Training loss (ℓ2), validation loss"
    plot_log_y = True
    changes_faces = True

    def __init__(self, window):
        super().__init__(window)
        self.trained_net = None
        self.weights_file: str | None = None
        self.workers = 2
        self._trainer = None
        lay = self.body_layout
        row = QHBoxLayout()
        row.addWidget(QLabel("Weights"))
        self.weights_combo = QComboBox()
        self.weights_combo.addItems(["Shipped", "Trained here", "File…"])
        self.weights_combo.setToolTip("Which network neural subdivision uses.")
        self.weights_combo.activated.connect(self._on_weights_choice)
        row.addWidget(self.weights_combo, 1)
        lay.insertLayout(2, row)
        row = QHBoxLayout()
        self.coarse_spin = QSpinBox()
        self.coarse_spin.setRange(2, 10000)
        self.coarse_spin.setValue(200)
        self.coarse_spin.setToolTip("Random coarse meshes made from this mesh (thesis: 200).")
        self.epochs_spin = QSpinBox()
        self.epochs_spin.setRange(1, 100000)
        self.epochs_spin.setValue(700)
        self.epochs_spin.setToolTip("Training epochs (thesis: 700). Stop keeps the best so far.")
        row.addWidget(QLabel("Coarse meshes"))
        row.addWidget(self.coarse_spin)
        row.addWidget(QLabel("Epochs"))
        row.addWidget(self.epochs_spin)
        lay.insertLayout(3, row)
        row = QHBoxLayout()
        self.train_button = QPushButton("Train on this mesh")
        self.train_button.setToolTip("Make training data from the current mesh and train a "
                                     "network on it (can take long; Stop keeps the best).")
        self.train_button.clicked.connect(self.train)
        self.save_button = QPushButton("Save weights…")
        self.save_button.setEnabled(False)
        self.save_button.clicked.connect(self._save_dialog)
        row.addWidget(self.train_button, 2)
        row.addWidget(self.save_button, 1)
        lay.insertLayout(4, row)
        window.runner.finished.connect(self._training_ended)
        window.runner.cancelled.connect(self._training_ended)

    # -- subdividing ----------------------------------------------------------------------------
    def job_options(self) -> dict:
        return {"weights": self.weights_combo.currentText(), "weights_file": self.weights_file}

    def _network(self):
        from algorithms.subdivision.model import load_weights

        choice = self.weights_combo.currentIndex()
        if choice == 1 and self.trained_net is not None:
            return self.trained_net
        if choice == 2 and self.weights_file:
            return load_weights(self.weights_file)[0]
        return load_weights(None)[0]

    def build_steps(self, state: MeshState, params: Any) -> Iterator[Step]:
        net = self._network() if params.method == "neural" else None

        def work(progress):
            from algorithms.subdivision.baselines import subdivide_baseline
            from algorithms.subdivision.metrics import coarsen_to_vertices
            from algorithms.subdivision.model import neural_subdivide

            V, F = np.asarray(state.V), np.asarray(state.F)
            if params.coarsen_first and params.coarsen_first < len(V):
                progress(0.1, f"QSlim to {params.coarsen_first} vertices")
                V, F = coarsen_to_vertices(V, F, params.coarsen_first)
            progress(0.5, f"{params.method} subdivision")
            if params.method == "neural":
                return neural_subdivide(V, F, params.levels, net)
            return subdivide_baseline(V, F, params.levels, params.method)

        box: dict = {}
        yield from with_progress(work, state.V, box)
        if "value" in box:
            V, F = box["value"]
            yield MeshStep(1, 1, np.asarray(V, dtype=np.float64), {}, f"{len(F):,} triangles",
                           F=np.asarray(F, dtype=np.int64))

    # -- training -------------------------------------------------------------------------------
    def train(self) -> None:
        state = self.window_.document.state
        if state is None:
            self.status_label.setText("Open a mesh first (File > Open).")
            return
        from algorithms.subdivision.data import DataParams
        from algorithms.subdivision.train import TrainParams

        dparams = DataParams(coarse_meshes=self.coarse_spin.value())
        tparams = TrainParams(epochs=self.epochs_spin.value())
        workers = self.workers
        self.plot.clear()
        self.status_label.setText("Making training data…")

        def factory():
            return self._training_steps(state, dparams, tparams, workers)

        self.window_.start_analysis_job(self.title, factory)

    def _training_steps(self, state, dparams, tparams, workers) -> Iterator[Step]:
        from algorithms.subdivision.data import generate_dataset
        from algorithms.subdivision.train import Trainer

        box: dict = {}
        yield from with_progress(
            lambda progress: generate_dataset([(np.asarray(state.V), np.asarray(state.F))],
                                              dparams, workers=workers, progress=progress),
            state.V, box)
        if "value" not in box:
            return
        self._trainer = Trainer(box["value"], tparams)
        yield from self._trainer.steps()

    def _training_ended(self, *_):
        if self.window_.last_job_name != self.title or self._trainer is None:
            return
        if self._trainer.history:
            from algorithms.subdivision.model import SubdivisionNet

            net = SubdivisionNet(seed=None)
            net.load_state(self._trainer.best_state)
            self.trained_net = net
            self.weights_combo.setCurrentIndex(1)
            self.save_button.setEnabled(True)
            self.status_label.setText(
                f"Trained {len(self._trainer.history)} epochs; best validation loss "
                f"{self._trainer.best_loss:.3g} (epoch {self._trainer.best_epoch}). "
                f"'Trained here' is selected.")
        self._trainer = None

    def save_weights(self, path: str) -> None:
        from algorithms.subdivision.model import save_weights

        if self.trained_net is None:
            return
        save_weights(path, self.trained_net, {"trained_on": "the Subdivision panel"})
        self.status_label.setText(f"Saved {path}.")

    def _save_dialog(self) -> None:
        from app import dialogs

        path = dialogs.save_file(self, "Save weights", "Weights (*.pt)", "weights.pt")
        if path:
            try:
                self.save_weights(path)
            except Exception as exc:  # noqa: BLE001 - shown as a plain message
                self.status_label.setText(str(exc))

    def _on_weights_choice(self, index: int) -> None:
        if index == 2:
            from app import dialogs

            path = dialogs.open_file(self, "Open weights", "Weights (*.pt)")
            if path:
                self.set_weights_file(path)
            else:
                self.weights_combo.setCurrentIndex(0)
        elif index == 1 and self.trained_net is None:
            self.status_label.setText("No network trained here yet: press 'Train on this mesh'.")
            self.weights_combo.setCurrentIndex(0)

    def set_weights_file(self, path: str) -> None:
        """Use a weights file (checked now: a file that is not ours gives a plain message)."""
        from algorithms.errors import Stylize3DError
        from algorithms.subdivision.model import load_weights

        try:
            load_weights(path)
        except Stylize3DError as exc:
            self.status_label.setText(str(exc))
            self.weights_combo.setCurrentIndex(0)
            return
        self.weights_file = path
        self.weights_combo.setCurrentIndex(2)
        self.status_label.setText(f"Using weights {path}.")
