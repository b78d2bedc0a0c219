"""Panel "Subdivision": neural subdivision (thesis ch. 4) and the classic schemes.

* Subdivide the current mesh 1-3 levels with neural / Loop / butterfly / mid-point; each result
  is one undoable command (the mesh's connectivity changes). "Coarsen first" QSlims the mesh to
  a vertex count before, so a user can watch a method rebuild the detail.
* Weights: the shipped ones, the ones trained here, or a weights file.
* "Train on this mesh": data generation (with progress) then training, the training and
  validation losses streamed to the plot; Stop keeps the best weights so far; "Save weights…"
  writes them.

Both are computed by the Qt-free recipes of :mod:`app.recipes.subdivision` ("Subdivision" for
Run, "Subdivision training" for training): a weights file and the weights trained here are
blobs referenced in :meth:`SubdivisionPanel.job_options`. The subdivided mesh has other vertices
and faces than the input: the last step carries them and is committed as the new mesh by the
shared mechanism of :class:`~app.panels.base.MethodPanel` (``changes_faces``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

from PySide6.QtWidgets import QComboBox, QHBoxLayout, QLabel, QPushButton, QSpinBox

from algorithms.steps import Step
from algorithms.subdivision.model import SubdivideParams
from app.panels.base import MethodPanel
from app.recipes import subdivision as recipe_mod

_CHOICE_INDEX = {"shipped": 0, "trained": 1, "file": 2}


class SubdivisionPanel(MethodPanel):
    counts_iterations = False  # its steps are stages and solver cycles
    title = "Subdivision"
    description = ("Subdivides the mesh: neural subdivision (learned from example meshes, "
                   "thesis ch. 4) or Loop, modified butterfly, mid-point. Try 'Coarsen first' "
                   "= 400 to see a method rebuild the detail.")
    params_cls = SubdivideParams
    plot_metrics = ("loss", "validation_loss")
    plot_title = "Training loss (ℓ2), validation loss"
    plot_log_y = True
    plot_empty_text = ("The training and validation losses appear here while "
                       "'Train on this mesh' runs.")
    changes_faces = True

    def __init__(self, window):
        super().__init__(window)
        self.trained_net = None  # the network trained here (for "Save weights…")
        self.trained_weights: str | None = None  # its weights file, as a blob reference
        self.weights_file: str | None = None  # the chosen weights file, as a blob reference
        self.weights_file_name = ""  # where it came from (for messages)
        self.workers = 2
        self._training: dict | None = None  # the running training job's last step
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
        window.runner.failed.connect(self._training_failed)

    # -- subdividing (recipe "Subdivision") ------------------------------------------------------
    def job_options(self) -> dict:
        """The chosen weights (``weights``: shipped / trained / file) with the blob references
        of the weights trained here and of the weights file (see
        :mod:`app.recipes.subdivision`), and the training settings (``training``: coarse
        meshes, epochs; kept in project files, not read by the subdivide recipe)."""
        return {"weights": recipe_mod.WEIGHTS_CHOICES[self.weights_combo.currentIndex()],
                "trained_weights": self.trained_weights, "weights_file": self.weights_file,
                "training": {"coarse_meshes": self.coarse_spin.value(),
                             "epochs": self.epochs_spin.value()}}

    def restore_options(self, options: dict) -> None:
        """Set the weights choice, the trained network, the weights file and the training
        settings from saved :meth:`job_options` (their blobs loaded with the project)."""
        from algorithms.errors import Stylize3DError

        problems = []
        try:
            choice = recipe_mod.weights_choice(options)
        except Stylize3DError as exc:
            problems.append(str(exc))
            choice = "shipped"
        self.trained_net, self.trained_weights = None, None
        ref = options.get("trained_weights")
        if ref:
            try:
                self.trained_net = recipe_mod.load_network(ref)
                self.trained_weights = ref
            except Stylize3DError as exc:
                problems.append(str(exc))
        self.save_button.setEnabled(self.trained_net is not None)
        self.weights_file, self.weights_file_name = None, ""
        ref = options.get("weights_file")
        if ref:
            try:
                recipe_mod.load_network(ref, self._recipe_cache)
                self.weights_file = ref
                self.weights_file_name = ref.split("/", 1)[1]
            except Stylize3DError as exc:
                problems.append(str(exc))
        training = options.get("training") or {}
        if "coarse_meshes" in training:
            self.coarse_spin.setValue(int(training["coarse_meshes"]))
        if "epochs" in training:
            self.epochs_spin.setValue(int(training["epochs"]))
        index = _CHOICE_INDEX[choice]
        if (index == 1 and self.trained_weights is None) or (index == 2
                                                             and self.weights_file is None):
            index = 0
        self.weights_combo.setCurrentIndex(index)
        if problems:
            self.status_label.setText(" ".join(problems))

    # -- training (recipe "Subdivision training") ------------------------------------------------
    def training_params(self):
        """The training run's Params: the panel's coarse meshes and epochs, the rest at the
        thesis' defaults (seeds 0)."""
        return recipe_mod.training_params_cls()(coarse_meshes=self.coarse_spin.value(),
                                                epochs=self.epochs_spin.value())

    def training_options(self) -> dict:
        return {"workers": int(self.workers), "cache": True}

    def train(self) -> None:
        state = self.window_.document.state
        if state is None:
            self.status_label.setText("Open a mesh first (File > Open).")
            return
        name = recipe_mod.TRAIN_RECIPE
        recipe = self.recipe(name)
        params = self.training_params()
        options = self.training_options()
        # what this run asks for, read by the study log when it starts
        self.last_request = {"params": params, "options": options, "input": state,
                             "recipe": name}
        self.plot.clear()
        self.plot_shows_run = False  # Stop keeps the best weights: the loss curve stays
        self.status_label.setText("Making training data…")
        holder: dict = {}

        def factory():  # worker thread, when the job starts: its steps go to ``holder``
            self._training = holder
            return self._training_steps(recipe, state, params, options, holder)

        self.window_.start_analysis_job(self.title, factory)

    @staticmethod
    def _training_steps(recipe, state, params, options, holder) -> Iterator[Step]:
        steps = recipe.steps(state, params, options, {})
        try:
            for step in steps:
                holder["last"] = step
                yield step
        finally:
            steps.close()  # a cancelled run: the recipe keeps the best weights

    def _training_ended(self, *_):
        """A training job finished or was stopped: its best weights become "Trained here"."""
        holder, self._training = self._training, None
        if holder is None or holder.get("last") is None:
            return
        from algorithms.errors import Stylize3DError

        out = self.recipe(recipe_mod.TRAIN_RECIPE).outcome(holder["last"])
        if not out:  # stopped while making the data: say that nothing was trained
            kept = {0: "the shipped weights", 1: "the weights trained here before",
                    2: "the weights file"}.get(self.weights_combo.currentIndex(), "")
            self.status_label.setText(
                "Training stopped while making its data: no network was trained"
                + (f"; subdividing keeps using {kept}." if kept else "."))
            return
        try:
            net = recipe_mod.load_network(out["weights"])
        except Stylize3DError as exc:
            self.status_label.setText(str(exc))
            return
        self.trained_net, self.trained_weights = net, out["weights"]
        self.weights_combo.setCurrentIndex(1)
        self.save_button.setEnabled(True)
        info = holder["last"].info
        on = ("coarse pretzels" if info.get("validation_shape") == "pretzel"
              and info.get("validation_fraction", 0) > 0 else "this mesh's coarse meshes")
        self.status_label.setText(
            f"Trained {out['epochs']} epochs; best validation loss "
            f"{out['best_validation_loss']:.3g} (epoch {out['best_epoch']}, measured on {on}). "
            f"'Trained here' is selected.")

    def _training_failed(self, *_):
        self._training = None

    def _on_finished(self, step) -> None:
        super()._on_finished(step)
        note = getattr(step, "note", "")
        if note and self.window_.last_job_name == self.title:
            # what the network did with this input (scaled to its training edge length, or
            # Loop with the advice to coarsen first): said where the user looks
            self.status_label.setText(f"{self.status_label.text()} {note}")
            self.window_.report(f"Subdivision: {note}")

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
        """Use a weights file (checked now: a file that is not ours gives a plain message); it
        is stored as a blob, so a run does not depend on the file staying where it is."""
        from algorithms.errors import Stylize3DError

        try:
            ref = recipe_mod.weights_blob_from_file(path)
        except Stylize3DError as exc:
            self.status_label.setText(str(exc))
            self.weights_combo.setCurrentIndex(0)
            return
        except OSError as exc:
            self.status_label.setText(f"Cannot read '{Path(path).name}' "
                                      f"({exc.strerror or exc}).")
            self.weights_combo.setCurrentIndex(0)
            return
        self.weights_file, self.weights_file_name = ref, str(path)
        self.weights_combo.setCurrentIndex(2)
        self.status_label.setText(f"Using weights {path}.")
