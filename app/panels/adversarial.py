"""Panel "Adversarial lighting": fool an image classifier with the lighting or with tiny changes
of the shape (thesis ch. 3, parametric adversaries; algorithms/adversarial).

* What the classifier sees: the shape rendered as the attack renders it (224 x 224, black
  background, spherical-harmonics lighting, orthographic view at an azimuth / elevation), with
  the classifier's top-5 classes and confidences. It is recomputed after a short pause whenever
  the lighting, the view, the colour, the classifier or the shape changes, on a job runner of the
  panel's own (app/jobs.py: render + classify take ~0.1 s and the classifier's first load
  seconds, so the window never waits).
* The lighting: a preset environment (the embedded light probes) and sliders for the nine
  coefficients of degrees 0-2 per colour channel; Save / Load (.json, the format of
  ``stylize3d adversary -o x.json``: algorithms/adversarial/lighting_io.py) and Revert.
* The true label (defaults to the classifier's top-1) and an optional target, each a searchable
  field of the classifier's class names; unknown names are refused with close names.
* "Attack lighting" / "Attack geometry" run :func:`algorithms.adversarial.attack_iter` on the
  window's job runner: the perturbed image and its top-5 stream in, Stop restores, and the
  before / after images are shown side by side at the end. A lighting attack changes the panel's
  lighting (Revert takes it back); a geometry attack is one undoable command (Ctrl+Z restores
  the vertices exactly).
* "Make training images…" (thesis §3.5) renders the shape under random or adversarial lighting
  into a dataset folder on the window's job runner (the recipe of ``stylize3d augment``,
  app/recipes/augment.py; its settings in the folded "Training images" section): progress and
  the last image stream in, Stop keeps what was made, the document never changes.

Every job is a recipe of app/recipes/adversarial.py ("Adversarial lighting", "Adversarial
lighting: geometry", "Adversarial lighting: classify") or app/recipes/augment.py ("Adversarial
lighting: training images"), run with :meth:`job_options` read on the
GUI thread when it starts; the command line, the study replay and scripts run the same ones.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from PySide6.QtCore import QStringListModel, Qt, QTimer, Signal
from PySide6.QtGui import QColor, QImage, QPixmap
from PySide6.QtWidgets import (QCheckBox, QColorDialog, QComboBox, QCompleter, QFormLayout,
                               QGridLayout, QGroupBox, QHBoxLayout, QLabel, QLineEdit,
                               QProgressBar, QPushButton, QSlider, QVBoxLayout, QWidget)

from algorithms.adversarial.attack import DEFAULT_RADIUS, AdversaryParams
from algorithms.adversarial.augment import AugmentParams
from algorithms.errors import Stylize3DError
from algorithms.render.sh import ENVIRONMENTS
from app import dialogs
from app.forms import ParamsForm
from app.jobs import JobRunner
from app.panels.base import MethodPanel
from app.recipes import adversarial as rcp
from app.recipes import augment as aug
from app.recipes.adversarial import AttackStep, PreviewStep, top_k  # noqa: F401 (re-exported)
from app.widgets import CollapsibleSection

#: the coefficients with a slider: degrees 0-2 (index l*l + l + m), what each pattern looks like
SH_ROWS = (("l=0", "ambient", "the same light from every direction"),
           ("l=1, m=−1", "up / down", "brighter from above than from below (or the reverse)"),
           ("l=1, m=0", "front / back", "brighter from the front (+z) than from the back"),
           ("l=1, m=1", "right / left", "brighter from the right (+x) than from the left"),
           ("l=2, m=−2", "xy", "two opposite diagonal quadrants (seen from the front) brighter"),
           ("l=2, m=−1", "yz", "up-front and down-back brighter than the other two quadrants"),
           ("l=2, m=0", "poles / band", "top and bottom brighter than the band around the middle"),
           ("l=2, m=1", "xz", "right-front and left-back brighter than the other two quadrants"),
           ("l=2, m=2", "x² − y²", "left and right brighter than top and bottom"))
SLIDER_SCALE = 100          # slider units per coefficient unit (0.01 resolution)
SLIDER_LIMIT = 2.0          # coefficients from -2 to 2
IMAGE_SIZE = 224            # pixels of the shown image (the classifier's input)
FILE_COLORS_FIELD = "file_colors"  # the opened file's colours on the 3D view
CUSTOM = "Custom"
DEFAULT_CLASSIFIER_NAME = "EfficientNet-lite0 (ImageNet, default)"

SH_TIP = ("A spherical-harmonics coefficient: the lighting around the shape is a sum of smooth "
          "brightness patterns over all directions, and each coefficient says how strong one "
          "pattern is for one colour. Degree l = 0 is light from everywhere, l = 1 makes one "
          "side brighter than the other, l = 2 finer patterns.")
RADIUS_PLAIN = ("\n\nIn plain words: the L∞ (L-infinity) radius is the most any single number "
                "may change: each lighting coefficient by at most this much, or each vertex "
                "coordinate by at most this fraction of the shape's size. 0 uses the thesis's "
                f"sizes: {DEFAULT_RADIUS['lighting']:g} for lighting, "
                f"{DEFAULT_RADIUS['geometry']:g} for geometry.")
TOP5_TIP = ("Top-5: the five classes the classifier finds most likely for this image, with its "
            "confidence in each (a probability: the confidences of all its classes add up to "
            "100 %).")

def image_to_pixmap(img: np.ndarray, size: int | None = None) -> QPixmap:
    """A QPixmap of an ``(H, W, 3)`` image with values in [0, 1] (scaled to ``size`` pixels)."""
    a = np.ascontiguousarray((np.clip(np.asarray(img, np.float64), 0, 1) * 255 + 0.5)
                             .astype(np.uint8))
    h, w = a.shape[:2]
    q = QImage(a.data, w, h, 3 * w, QImage.Format.Format_RGB888).copy()
    pm = QPixmap.fromImage(q)
    if size is not None and size != w:
        pm = pm.scaled(size, size, Qt.AspectRatioMode.KeepAspectRatio,
                       Qt.TransformationMode.SmoothTransformation)
    return pm


class Top5View(QWidget):
    """Five rows "name  [bar  xx.x %]"."""

    def __init__(self, parent=None):
        super().__init__(parent)
        grid = QGridLayout(self)
        grid.setContentsMargins(0, 0, 0, 0)
        grid.setVerticalSpacing(2)
        self.names: list[QLabel] = []
        self.bars: list[QProgressBar] = []
        for i in range(5):
            name = QLabel("—")
            name.setMinimumWidth(110)
            bar = QProgressBar()
            bar.setRange(0, 1000)
            bar.setValue(0)
            bar.setTextVisible(True)
            bar.setFormat("")
            bar.setFixedHeight(16)
            grid.addWidget(name, i, 0)
            grid.addWidget(bar, i, 1)
            self.names.append(name)
            self.bars.append(bar)
        grid.setColumnStretch(1, 1)
        self.setToolTip(TOP5_TIP)
        self.entries: list[tuple[str, float]] = []

    def set_entries(self, entries) -> None:
        self.entries = [(str(n), float(p)) for n, p, *_ in entries][:5]
        for i in range(5):
            if i < len(self.entries):
                n, p = self.entries[i]
                self.names[i].setText(n if i else f"<b>{n}</b>")
                self.names[i].setToolTip(n)
                self.bars[i].setValue(int(round(1000 * p)))
                self.bars[i].setFormat(f"{100 * p:.1f} %")
            else:
                self.names[i].setText("—")
                self.bars[i].setValue(0)
                self.bars[i].setFormat("")


class AdversarialPanel(MethodPanel):
    title = "Adversarial lighting"
    description = ("Shows the shape as an image classifier sees it and what it recognizes, then "
                   "finds a small change of the lighting or of the shape that makes it see "
                   "something else (thesis ch. 3).")
    params_cls = AdversaryParams
    plot_metrics = ("confidence_decreased", "confidence_increased")
    plot_title = "Confidence in the true class (blue) and the target (orange) per iteration"
    help_page = "adversarial_lighting"
    param_auto_text = {"radius": lambda p: "thesis (0.1 light / 0.002 shape)"}
    preview_debounce_ms = 120

    #: a classification of the current view was shown (tests, scripts)
    classified = Signal()

    def __init__(self, window):
        super().__init__(window)
        self.lighting = rcp.environment_lighting(rcp.DEFAULT_ENVIRONMENT)   # (49, 3)
        self.classifier = None            # None: the default EfficientNet-lite0 (ImageNet)
        self._classifier_ref: str | None = None   # the loaded one's blob (options["classifier"])
        self.classifier_name = DEFAULT_CLASSIFIER_NAME
        self.color = rcp.DEFAULT_COLOR
        self._file_colors = None          # (m, 3) face colours of the opened file, if any
        self._file_colors_ref = None      # ... as a blob (options["face_colors"])
        self._file_colors_key = None      # (path, n, m) they were read for
        self._preview_cache: dict = {}    # the classify recipe's (the attacks use _recipe_cache)
        self.preview_request: dict | None = None   # the newest classification's request
        self.probs: np.ndarray | None = None
        self.shown_image: np.ndarray | None = None
        self.preview_error: str | None = None
        self.streamed_images = 0
        self.preview_count = 0
        self.last_result = None
        self._attack_mode = "lighting"
        self._attack_lighting_before: np.ndarray | None = None
        self._revert_to: tuple | None = None   # (lighting, environment) before the last attack
        # (positions of a geometry attack's result, the unit-box frame of the shape before the
        # attacks): that result is classified in the frame the attack saw it in
        self._attack_frame: tuple | None = None
        self._preview_stale = True
        self._augmenting = False          # the running job makes training images
        self.augment_summary: dict | None = None   # the last finished one's summary
        self.preview_runner = JobRunner(self)
        self.preview_runner.finished.connect(self._on_preview_done)
        self.preview_runner.failed.connect(self._on_preview_failed)
        self.preview_runner.cancelled.connect(lambda _m: self._restart_if_stale())
        self._preview_timer = QTimer(self)
        self._preview_timer.setSingleShot(True)
        self._preview_timer.setInterval(self.preview_debounce_ms)
        self._preview_timer.timeout.connect(self.update_preview)
        self._build()
        window.document.subscribe(self._on_doc)
        self.form.changed.connect(lambda _p: self.schedule_preview())

    # -- widgets -------------------------------------------------------------------------------
    def _build(self) -> None:
        lay: QVBoxLayout = self.body_layout
        self.live_box.setChecked(False)
        self.live_box.setVisible(False)
        self.form.editors["mode"].setVisible(False)        # the two Attack buttons choose it
        self.form.labels["mode"].setVisible(False)
        radius = self.form.editors["radius"]
        radius.setToolTip(radius.toolTip() + RADIUS_PLAIN)
        self.form.labels["radius"].setToolTip(radius.toolTip())
        views_tip = ("1: attack the current view only (the image above). n: the current view and "
                     "n − 1 more evenly spaced around the shape; the attack must fool them all.")
        for w in (self.form.editors["views"], self.form.labels["views"]):
            w.setToolTip(views_tip)
        at = lay.indexOf(self.form)

        # classifier
        row = QHBoxLayout()
        self.classifier_label = QLabel(self.classifier_name)
        self.classifier_label.setWordWrap(True)
        self.classifier_label.setToolTip("The image classifier being fooled. The default is "
                                         "EfficientNet-lite0 trained on ImageNet (1000 classes of "
                                         "everyday objects and animals), installed with the app.")
        self.classifier_button = QPushButton("Load…")
        self.classifier_button.setToolTip("Use your own classifier: a TorchScript model "
                                          "(torch.jit.save) or EfficientNet-lite0 weights (a state "
                                          "dict). Files that would run code when opened are "
                                          "refused.")
        self.classifier_button.clicked.connect(self._load_classifier_dialog)
        self.default_classifier_button = QPushButton("Default")
        self.default_classifier_button.setToolTip("Back to the installed EfficientNet-lite0.")
        self.default_classifier_button.clicked.connect(self.use_default_classifier)
        row.addWidget(QLabel("Classifier"))
        row.addWidget(self.classifier_label, 1)
        row.addWidget(self.classifier_button)
        row.addWidget(self.default_classifier_button)
        lay.insertLayout(at, row)
        at += 1

        # the image and its top-5
        box = QGroupBox("What the classifier sees")
        box.setToolTip("The shape rendered exactly as the attack renders it: 224 × 224 pixels, "
                       "black background, the lighting below, seen from the view below.")
        h = QHBoxLayout(box)
        self.image_label = QLabel("Open a mesh.")
        self.image_label.setFixedSize(IMAGE_SIZE, IMAGE_SIZE)
        self.image_label.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.image_label.setWordWrap(True)
        self.image_label.setStyleSheet("background: black; color: #ddd;")
        self.image_label.setToolTip(box.toolTip())
        h.addWidget(self.image_label, 0, Qt.AlignmentFlag.AlignTop)
        v = QVBoxLayout()
        head = QLabel("Top-5")
        head.setStyleSheet("font-weight: bold;")
        head.setToolTip(TOP5_TIP)
        v.addWidget(head)
        self.top5_view = Top5View()
        v.addWidget(self.top5_view)
        self.image_note = QLabel("")
        self.image_note.setWordWrap(True)
        self.image_note.setStyleSheet("color: #555;")
        v.addWidget(self.image_note)
        v.addStretch(1)
        h.addLayout(v, 1)
        lay.insertWidget(at, box)
        self.image_box = box
        at += 1

        # the view
        row = QHBoxLayout()
        self.azimuth_slider = QSlider(Qt.Orientation.Horizontal)
        self.azimuth_slider.setRange(0, 359)
        self.azimuth_slider.setValue(0)
        az_tip = ("The current view: the camera's direction around the shape in degrees (0 = "
                  "from the front, +z), at the elevation set under Advanced.")
        self.azimuth_slider.setToolTip(az_tip)
        self.azimuth_value = QLabel("0°")
        self.azimuth_value.setMinimumWidth(34)
        self.azimuth_slider.valueChanged.connect(self._on_azimuth)
        self.from_view_button = QPushButton("From 3D view")
        self.from_view_button.setToolTip("Look from where the 3D view looks (azimuth and "
                                         "elevation).")
        self.from_view_button.clicked.connect(self.view_from_viewport)
        lab = QLabel("View")
        lab.setToolTip(az_tip)
        row.addWidget(lab)
        row.addWidget(self.azimuth_slider, 1)
        row.addWidget(self.azimuth_value)
        row.addWidget(self.from_view_button)
        lay.insertLayout(at, row)
        at += 1

        # labels
        form = QFormLayout()
        self.names_model = QStringListModel(list(rcp.class_names_of(None)))
        self.true_edit = QLineEdit()
        self.true_edit.setPlaceholderText("the classifier's top-1")
        self.true_edit.setToolTip("What the object really is: the class the attack makes less "
                                  "likely. Starts as the classifier's top-1 on the current view; "
                                  "type to search the classes (empty: the top-1 again).")
        self.target_edit = QLineEdit()
        self.target_edit.setPlaceholderText("none: any other class")
        self.target_edit.setToolTip("The class the classifier should see after the attack. Empty: "
                                    "any class but the true one (an untargeted attack). Type to "
                                    "search the classes.")
        for edit in (self.true_edit, self.target_edit):
            comp = QCompleter(self.names_model, edit)
            comp.setCaseSensitivity(Qt.CaseSensitivity.CaseInsensitive)
            comp.setFilterMode(Qt.MatchFlag.MatchContains)
            comp.setMaxVisibleItems(12)
            edit.setCompleter(comp)
            edit.setClearButtonEnabled(True)
            edit.editingFinished.connect(lambda e=edit: self.check_label(e))
        form.addRow("True label", self.true_edit)
        form.addRow("Target", self.target_edit)
        lay.insertLayout(at, form)
        at += 1

        # the lighting
        box = QGroupBox("Lighting (spherical harmonics)")
        box.setToolTip(SH_TIP)
        v = QVBoxLayout(box)
        row = QHBoxLayout()
        self.env_combo = QComboBox()
        self.env_combo.addItems(list(ENVIRONMENTS) + [CUSTOM])
        self.env_combo.setToolTip("Start from the lighting of a real place (light probes of "
                                  "Debevec, as spherical harmonics by Ramamoorthi & Hanrahan "
                                  "2001). 'Custom' is what you changed.")
        self.env_combo.activated.connect(
            lambda i: self.set_environment(self.env_combo.itemText(i)))
        self.link_box = QCheckBox("Link R, G, B")
        self.link_box.setToolTip("Move the three colours of a coefficient together (white light "
                                 "changes).")
        row.addWidget(QLabel("Environment"))
        row.addWidget(self.env_combo, 1)
        row.addWidget(self.link_box)
        v.addLayout(row)
        grid = QGridLayout()
        grid.setHorizontalSpacing(6)
        grid.setVerticalSpacing(3)
        for c, name in enumerate(("R", "G", "B")):
            h = QLabel(name)
            h.setAlignment(Qt.AlignmentFlag.AlignCenter)
            h.setStyleSheet(f"color: {('#b91c1c', '#15803d', '#1d4ed8')[c]}; font-weight: bold;")
            grid.addWidget(h, 0, c + 1)
        self.sh_sliders: list[list[QSlider]] = []
        for j, (lm, short, what) in enumerate(SH_ROWS):
            lab = QLabel(f"{short}")
            lab.setToolTip(f"{lm}: {what}.\n\n{SH_TIP}")
            grid.addWidget(lab, j + 1, 0)
            row_sliders = []
            for c in range(3):
                s = QSlider(Qt.Orientation.Horizontal)
                s.setRange(-int(SLIDER_LIMIT * SLIDER_SCALE), int(SLIDER_LIMIT * SLIDER_SCALE))
                s.setMinimumWidth(70)
                s.valueChanged.connect(lambda val, j=j, c=c: self._on_sh_slider(j, c, val))
                grid.addWidget(s, j + 1, c + 1)
                row_sliders.append(s)
            self.sh_sliders.append(row_sliders)
        grid.setColumnStretch(1, 1)
        grid.setColumnStretch(2, 1)
        grid.setColumnStretch(3, 1)
        v.addLayout(grid)
        row = QHBoxLayout()
        self.save_lighting_button = QPushButton("Save…")
        self.save_lighting_button.setToolTip("Write this lighting (all 49 × 3 coefficients) to a "
                                             ".json file, the format of 'stylize3d adversary -o'.")
        self.save_lighting_button.clicked.connect(self._save_lighting_dialog)
        self.load_lighting_button = QPushButton("Load…")
        self.load_lighting_button.setToolTip("Read a lighting .json file (saved here or by "
                                             "'stylize3d adversary -o').")
        self.load_lighting_button.clicked.connect(self._load_lighting_dialog)
        self.revert_button = QPushButton("Revert attack")
        self.revert_button.setToolTip("Back to the lighting before the last lighting attack.")
        self.revert_button.setEnabled(False)
        self.revert_button.clicked.connect(self.revert_lighting)
        row.addWidget(self.save_lighting_button)
        row.addWidget(self.load_lighting_button)
        row.addWidget(self.revert_button)
        v.addLayout(row)
        row = QHBoxLayout()
        self.color_button = QPushButton()
        self.color_button.setToolTip("The surface colour of the shape in the image (one colour "
                                     "for the whole shape).")
        self.color_button.clicked.connect(self._color_dialog)
        self.file_colors_box = QCheckBox("Colours from the file")
        self.file_colors_box.setToolTip("Use the colours stored in the mesh file instead.")
        self.file_colors_box.setVisible(False)
        self.file_colors_box.toggled.connect(lambda _on: self.schedule_preview())
        self.file_colors_box.toggled.connect(lambda _on: self._show_file_colors())
        self.file_colors_box.toggled.connect(lambda on: self.color_button.setEnabled(not on))
        row.addWidget(QLabel("Surface colour"))
        row.addWidget(self.color_button, 1)
        row.addWidget(self.file_colors_box)
        v.addLayout(row)
        lay.insertWidget(at, box)
        self.lighting_box = box
        at += 1
        self._show_color()
        self._sync_sliders()

        # before / after
        box = QGroupBox("Before / after the last attack")
        box.setToolTip("View 1 before the attack and after it, with the classifier's top-1.")
        h = QHBoxLayout(box)
        self.before_image, self.after_image = QLabel(), QLabel()
        self.before_caption, self.after_caption = QLabel(), QLabel()
        for img, cap in ((self.before_image, self.before_caption),
                         (self.after_image, self.after_caption)):
            col = QVBoxLayout()
            img.setFixedSize(150, 150)
            img.setStyleSheet("background: black;")
            cap.setWordWrap(True)
            cap.setAlignment(Qt.AlignmentFlag.AlignHCenter | Qt.AlignmentFlag.AlignTop)
            col.addWidget(img, 0, Qt.AlignmentFlag.AlignHCenter)
            col.addWidget(cap)
            h.addLayout(col)
        box.setVisible(False)
        lay.insertWidget(lay.indexOf(self.image_box) + 1, box)
        self.before_after_box = box

        # training images (thesis §3.5): the same recipe as `stylize3d augment`
        sec = CollapsibleSection("Training images (thesis §3.5)")
        sec.setToolTip("Settings of Make training images…: how many images, which lighting, "
                       "image size, attack iterations.")
        tl = QVBoxLayout(sec.body)
        tl.setContentsMargins(12, 0, 0, 0)
        self.augment_form = ParamsForm(AugmentParams)
        tl.addWidget(self.augment_form)
        end = lay.count() - 1 if lay.itemAt(lay.count() - 1).spacerItem() else lay.count()
        lay.insertWidget(end, sec)                       # last: after the attack's settings
        self.augment_section = sec
        self.augment_button = QPushButton("Make training images…")
        self.augment_button.setToolTip(
            "Render this shape many times (random views, distances and grey backgrounds) under "
            "random or adversarial lighting, the lighting attack against the classifier above, "
            "into a folder you choose: FOLDER/LABEL/0000.png, ... and manifest.jsonl (LABEL = "
            "the true label). Runs in the background with progress; Stop keeps the images made "
            "so far, and running it again on the same folder adds only the missing ones. Train "
            "a classifier on them with: stylize3d augment-train FOLDER -o weights.pt "
            "(thesis §3.5, rendered adversarial data augmentation).")
        self.augment_button.clicked.connect(lambda: self.make_training_images())
        lay.insertWidget(lay.indexOf(sec) + 1, self.augment_button)

        # footer: the two attacks instead of Run
        self.attack_light_button = self.run_button     # Run = the lighting attack (see run)
        self.run_button.setText("Attack lighting")
        self.attack_light_button.setToolTip("Change the lighting a little (within the radius) "
                                            "until the classifier no longer sees the true label "
                                            "(or sees the target). The shape is not changed.")
        self.attack_geom_button = QPushButton("Attack geometry")
        self.attack_geom_button.setToolTip("Move the vertices a little (within the radius) until "
                                           "the classifier is fooled. The result is one undo "
                                           "step (Ctrl+Z).")
        self.attack_geom_button.clicked.connect(lambda: self.attack("geometry"))
        row = self.footer.layout().itemAt(0).layout()
        row.insertWidget(1, self.attack_geom_button, 2)
        self.defaults_button.setToolTip("Reset the attack settings (radius, iterations, views, "
                                        "advanced) to their defaults.")
        self.scroll_area.setMinimumWidth(
            max(self.scroll_area.minimumWidth(), self.scroll_area.widget().sizeHint().width() + 24))

    # -- the lighting --------------------------------------------------------------------------
    def _sync_sliders(self) -> None:
        for j, row in enumerate(self.sh_sliders):
            for c, s in enumerate(row):
                x = float(self.lighting[j, c])
                s.blockSignals(True)
                s.setValue(int(round(np.clip(x, -SLIDER_LIMIT, SLIDER_LIMIT) * SLIDER_SCALE)))
                s.blockSignals(False)
                self._slider_tip(j, c)

    def _slider_tip(self, j: int, c: int) -> None:
        lm, short, what = SH_ROWS[j]
        self.sh_sliders[j][c].setToolTip(
            f"{'RGB'[c]} coefficient {lm} ({short}): {self.lighting[j, c]:+.3f}.\n{what}.\n\n"
            f"{SH_TIP}")

    def _on_sh_slider(self, j: int, c: int, value: int) -> None:
        x = value / SLIDER_SCALE
        delta = x - float(self.lighting[j, c])
        U = self.lighting.copy()
        U[j, c] = x
        if self.link_box.isChecked():
            for o in range(3):
                if o != c:
                    U[j, o] = float(np.clip(U[j, o] + delta, -SLIDER_LIMIT, SLIDER_LIMIT))
        self.lighting = U
        if self.link_box.isChecked():
            self._sync_sliders()
        else:
            self._slider_tip(j, c)
        self.env_combo.setCurrentText(CUSTOM)
        self.schedule_preview()

    def set_sh_coefficient(self, j: int, c: int, value: float) -> None:
        """Move the slider of coefficient ``j`` (0-8), channel ``c`` (0-2) as a user would."""
        self.sh_sliders[j][c].setValue(int(round(value * SLIDER_SCALE)))

    def set_lighting(self, U, name: str = CUSTOM) -> None:
        """Use the lighting ``U`` ((l+1)^2 x 3, padded to 49 x 3) and re-classify."""
        full = np.zeros((49, 3))
        U = np.asarray(U, dtype=np.float64)
        full[:len(U)] = U
        self.lighting = full
        self.env_combo.setCurrentText(name if name in ENVIRONMENTS else CUSTOM)
        self._sync_sliders()
        self.schedule_preview()

    def set_environment(self, name: str) -> None:
        if name == CUSTOM:
            return
        self.set_lighting(rcp.environment_lighting(name), name)

    def save_lighting(self, path: str) -> bool:
        from algorithms.adversarial.lighting_io import write_lighting

        try:
            write_lighting(path, self.lighting)
        except Stylize3DError as exc:
            self.status_label.setText(str(exc))
            return False
        self.status_label.setText(f"Saved the lighting to {path}.")
        return True

    def load_lighting(self, path: str) -> bool:
        from algorithms.adversarial.lighting_io import read_lighting

        try:
            U = read_lighting(path)
        except Stylize3DError as exc:
            self.status_label.setText(str(exc))
            return False
        self.set_lighting(U)
        self.status_label.setText(f"Loaded the lighting of {path}.")
        return True

    def _save_lighting_dialog(self) -> None:
        from app import dialogs

        path = dialogs.save_file(self, "Save lighting", "Lighting (*.json)", "lighting.json")
        if path:
            self.save_lighting(path)

    def _load_lighting_dialog(self) -> None:
        from app import dialogs

        path = dialogs.open_file(self, "Load lighting", "Lighting (*.json)")
        if path:
            self.load_lighting(path)

    def revert_lighting(self) -> None:
        if self._revert_to is not None:
            self.set_lighting(*self._revert_to)
            self._revert_to = None
            self.revert_button.setEnabled(False)
            self.status_label.setText("The lighting is back to how it was before the attack.")

    # -- colour ---------------------------------------------------------------------------------
    def _show_color(self) -> None:
        r, g, b = (int(round(255 * x)) for x in self.color)
        self.color_button.setText(f"{r}, {g}, {b}")
        fg = "black" if 0.3 * r + 0.59 * g + 0.11 * b > 128 else "white"
        self.color_button.setStyleSheet(f"background: rgb({r},{g},{b}); color: {fg};")

    def set_surface_color(self, rgb) -> None:
        self.color = tuple(float(np.clip(x, 0, 1)) for x in rgb)
        self._show_color()
        self.file_colors_box.setChecked(False)
        self.schedule_preview()

    def _color_dialog(self) -> None:
        c = QColorDialog.getColor(QColor.fromRgbF(*self.color), self, "Surface colour")
        if c.isValid():
            self.set_surface_color((c.redF(), c.greenF(), c.blueF()))

    def _face_colors_ref(self, state):
        """The blob of the file's face colours when they colour the shape (else None)."""
        if state is not None and self.file_colors_box.isChecked() \
                and self._file_colors is not None and len(self._file_colors) == len(state.F):
            return self._file_colors_ref
        return None

    def _colors_key(self, state):
        doc = self.window_.document
        return None if doc.path is None else (str(doc.path), len(state.V), len(state.F))

    def _take_file_colors(self, key, colors, ref=None) -> None:
        """The opened file's face colours (or None) and their blob, read by a preview job on
        the worker."""
        if key != self._colors_key_of_doc():
            return
        self._file_colors_key = key
        self._file_colors = colors
        self._file_colors_ref = None if colors is None else (ref or rcp.face_colors_ref(colors))
        has = colors is not None
        self.file_colors_box.blockSignals(True)
        self.file_colors_box.setVisible(has)
        self.file_colors_box.setChecked(has)
        self.file_colors_box.blockSignals(False)
        self.color_button.setEnabled(not has)
        self._show_file_colors()

    def _show_file_colors(self) -> None:
        """The file's colours on the 3D view while they colour the shape and this panel is in
        front (what the classifier sees is what the user sees); off otherwise."""
        vp = self.window_.viewport
        state = self.window_.document.state
        if self.is_shown() and self._face_colors_ref(state) is not None:
            vp.show_field(FILE_COLORS_FIELD, 255.0 * np.asarray(self._file_colors))
        elif getattr(vp, "_field_name", None) == FILE_COLORS_FIELD:
            vp.show_field(None)

    def _colors_key_of_doc(self):
        st = self.window_.document.state
        return None if st is None else self._colors_key(st)

    # -- classifier -----------------------------------------------------------------------------
    def class_names(self):
        return rcp.class_names_of(self.classifier)

    def load_classifier(self, path: str) -> bool:
        """Use the classifier in ``path``; a file that is not a model leaves the current one."""
        from PySide6.QtWidgets import QApplication

        QApplication.setOverrideCursor(Qt.CursorShape.WaitCursor)
        try:
            clf, ref = rcp.load_classifier_file(path)
        except Stylize3DError as exc:
            self.status_label.setText(f"{exc} The classifier was not changed.")
            return False
        finally:
            QApplication.restoreOverrideCursor()
        self._use_classifier(clf, ref)
        return True

    def _use_classifier(self, clf, ref: str) -> None:
        self.classifier = clf
        self._classifier_ref = ref
        self.classifier_name = f"{clf.name} ({len(clf.class_names)} classes)"
        self._classifier_changed()

    def use_default_classifier(self) -> None:
        if self.classifier is None:
            return
        self.classifier = None
        self._classifier_ref = None
        self.classifier_name = DEFAULT_CLASSIFIER_NAME
        self._classifier_changed()

    def _classifier_changed(self) -> None:
        self.classifier_label.setText(self.classifier_name)
        self.names_model.setStringList(list(self.class_names()))
        self.true_edit.clear()
        self.target_edit.clear()
        self.status_label.setText(f"Classifier: {self.classifier_name}.")
        self.schedule_preview()

    def _load_classifier_dialog(self) -> None:
        from app import dialogs

        path = dialogs.open_file(self, "Load a classifier",
                                 "Models (*.pt *.pth *.pts *.zip);;All files (*)")
        if path:
            self.load_classifier(path)

    # -- labels ---------------------------------------------------------------------------------
    def check_label(self, edit: QLineEdit) -> int | None:
        """The class index typed in ``edit`` (None when empty); an unknown name is shown with
        close names in the status line and the field is marked."""
        text = edit.text().strip()
        if not text:
            edit.setStyleSheet("")
            return None
        try:
            k = rcp.resolve_label(text, self.class_names())
        except Stylize3DError as exc:
            edit.setStyleSheet("border: 1px solid #dc2626;")
            self.status_label.setText(str(exc))
            raise
        edit.setStyleSheet("")
        return k

    # -- the view -------------------------------------------------------------------------------
    def _on_azimuth(self, value: int) -> None:
        self.azimuth_value.setText(f"{value}°")
        self.schedule_preview()

    def view_from_viewport(self) -> None:
        pose = self.window_.viewport.camera_pose()
        if pose is None:
            return
        d = np.array(pose["position"], float) - np.array(pose["focal_point"], float)
        n = np.linalg.norm(d)
        if n == 0:
            return
        d /= n
        az = math.degrees(math.atan2(d[0], d[2])) % 360.0
        el = math.degrees(math.asin(float(np.clip(d[1], -1, 1))))
        self.form.set_value("elevation", float(np.clip(round(el), -89, 89)))
        self.azimuth_slider.setValue(int(round(az)) % 360)

    # -- the live classification ----------------------------------------------------------------
    def schedule_preview(self) -> None:
        """Re-classify soon: at most one start per ``preview_debounce_ms`` while a slider moves
        (a throttle, so a drag shows images as it goes), never cancelling one in progress."""
        self._preview_stale = True
        if self.window_.document.is_empty:
            return
        if not self._preview_timer.isActive():
            self._preview_timer.start()

    def _attacking(self) -> bool:
        return self.window_.runner.busy and self._mine()

    def update_preview(self) -> None:
        """Render and classify the current view on the panel's runner (latest request wins):
        the recipe "Adversarial lighting: classify" (app/recipes/adversarial.py)."""
        state = self.window_.document.state
        if state is None or not self.is_shown() or self._attacking():
            return  # done when the panel comes to the front / the attack ends
        if self.preview_runner.busy:
            return  # the running one restarts this when it ends (still stale)
        self._preview_stale = False
        params = self.form.params()
        options = self.job_options()
        key = self._colors_key(state)
        read_colors = key is not None and key != self._file_colors_key
        # the request of this classification (same keys as last_request). It is not
        # last_request: the study log takes the newest last_request of any panel for the next
        # job of the window's runner, and this job runs on the panel's own runner, unlogged
        request = self.preview_request = {"params": params, "options": options, "input": state,
                                          "recipe": rcp.CLASSIFY}
        recipe = rcp.RECIPES_BY_NAME[rcp.CLASSIFY]
        cache = self._preview_cache

        def steps():
            opts, colors, ref = options, None, None
            if read_colors:     # the opened file's colours, read here on the worker once
                colors = rcp.read_face_colors(key, state.F)
                if colors is not None:
                    ref = rcp.face_colors_ref(colors)
                    opts = {**options, "face_colors": ref}
            for step in recipe.steps(state, params, opts, cache):
                step.colors = (key, colors, ref) if read_colors else None
                step.options = opts
                step.request = request
                yield step

        if self.probs is None:
            waiting = ("Loading the classifier…" if self.classifier is None
                       else "Classifying…")
            self.image_note.setText(waiting)
            if self.shown_image is None:  # never "Open a mesh." with a mesh open
                self.image_label.setText(waiting)
        self._update_attack_buttons()
        self.preview_runner.start("classify", steps)

    def _start_request(self, recipe: str, params, options: dict, state) -> dict:
        """What the attack about to start computes (as MethodPanel.run): its options and recipe
        for the worker and the commit, and ``last_request`` for the study log."""
        self._run_options = options
        self._run_recipe = recipe
        self.last_request = {"params": params, "options": options, "input": state,
                             "recipe": recipe}
        return self.last_request

    def _on_preview_done(self, step) -> None:
        if not isinstance(step, PreviewStep) or self._attacking():
            return
        self.preview_error = None
        if step.colors is not None:
            self._take_file_colors(*step.colors)
        req = getattr(step, "request", None)
        if req is not None and req is self.preview_request:   # the colours it read count too
            req["options"] = step.options
        self.show_classification(step.image, top_k(step.probs, step.names))
        self.probs = np.asarray(step.probs)
        if not self.true_edit.text().strip():  # the object's class: set once, not after attacks
            self.true_edit.setText(top_k(step.probs, step.names, 1)[0][0])
            self.true_edit.setStyleSheet("")
        self.image_note.setText(f"{step.covered * 100:.0f} % of the image is the shape.")
        self.preview_count += 1
        self._update_attack_buttons()
        if self._preview_stale:     # something changed meanwhile: shown, and computed again
            self._restart_if_stale()
        else:
            self.classified.emit()

    def _restart_if_stale(self) -> None:
        if self._preview_stale and not self._attacking():
            QTimer.singleShot(0, self.schedule_preview)

    def _on_preview_failed(self, message: str, _details: str) -> None:
        self.preview_error = message
        self.probs = None
        self.shown_image = None
        self.image_label.setPixmap(QPixmap())
        self.image_label.setText(message)
        self.top5_view.set_entries([])
        self.image_note.setText("")
        self.status_label.setText(message)
        self._update_attack_buttons()
        if self._preview_stale:
            self._restart_if_stale()
        else:
            self.classified.emit()

    def show_classification(self, image, entries) -> None:
        self.shown_image = np.asarray(image)
        self.image_label.setText("")
        self.image_label.setPixmap(image_to_pixmap(image, IMAGE_SIZE))
        self.top5_view.set_entries(entries)

    def refresh_view(self) -> None:
        self._show_file_colors()
        if self._preview_stale or self.probs is None:
            self.schedule_preview()

    def hide_view(self) -> None:
        vp = self.window_.viewport
        if getattr(vp, "_field_name", None) == FILE_COLORS_FIELD:
            vp.show_field(None)

    def _on_doc(self, what: str) -> None:
        if what == "mesh":  # another object: the last one's attack results do not apply
            self.before_after_box.setVisible(False)
            self.last_result = None
            if self._revert_to is not None:  # its attacked lighting goes with it
                self.set_lighting(*self._revert_to)
                self._revert_to = None
                self.revert_button.setEnabled(False)
            self.shown_image = None
            self.image_label.setPixmap(QPixmap())
            self.image_label.setText("Loading the classifier…" if self.classifier is None
                                     else "Classifying…")
            self.top5_view.set_entries([])
        if what in ("mesh", "topology"):
            self.true_edit.clear()
            self.probs = None
            self._update_attack_buttons()
            self._take_file_colors(self._colors_key_of_doc(), None)
            self._file_colors_key = None  # read by the next preview job, on the worker
        if what in ("mesh", "topology", "positions"):
            if self.is_shown():
                self.schedule_preview()
            else:
                self._preview_stale = True

    def shutdown(self) -> None:
        super().shutdown()
        self._preview_timer.stop()
        self.preview_runner.shutdown()

    # -- the attacks ----------------------------------------------------------------------------
    def job_options(self) -> dict:
        """Everything an attack or a classification reads besides the mesh and the Params (the
        keys are documented in app/recipes/adversarial.py): the whole lighting, the labels, the
        view, the classifier (a blob of its file, None = the installed one) and the colours."""
        return {"lighting": self.lighting.tolist(),
                "environment": self.env_combo.currentText(),
                "true_label": self.true_edit.text().strip(),
                "target": self.target_edit.text().strip(),
                "azimuth": self.azimuth_slider.value(),
                "classifier": self._classifier_ref,
                "classifier_name": self.classifier_name,
                "color": [float(x) for x in self.color],
                "face_colors": self._face_colors_ref(self.window_.document.state),
                "frame": self._frame_for(self.window_.document.state)}

    def _frame_for(self, state):
        """The unit-box frame to classify ``state`` in: the frame of the shape before this
        panel's geometry attacks when ``state`` is their result (else None: its own box)."""
        keep = self._attack_frame
        if state is not None and keep is not None and state.V is keep[0]:
            return list(keep[1])
        return None

    def _on_committed(self, name: str, after) -> None:
        super()._on_committed(name, after)
        before = self._pending_input
        if name == self.title and self._attack_mode == "geometry" and before is not None:
            frame = self._frame_for(before) or rcp.frame_of(before)
            self._attack_frame = (after.V, frame)

    def restore_options(self, options: dict) -> None:
        """Set the classifier, labels, view, lighting (sliders and environment) and colours
        back from saved :meth:`job_options` (keys that are absent leave their widgets as they
        are); re-classifies. A classifier whose file is missing leaves the current one and says
        so in the status line."""
        note = ""
        if "classifier" in options:
            ref = options.get("classifier")
            if not ref:
                self.use_default_classifier()
            elif ref != self._classifier_ref:
                try:
                    self._use_classifier(rcp.classifier_of(ref), ref)
                except Stylize3DError as exc:
                    note = f"{exc} The classifier was not changed."
        for key, edit in (("true_label", self.true_edit), ("target", self.target_edit)):
            if key in options:
                edit.setText(str(options.get(key) or ""))
                edit.setStyleSheet("")
        if "azimuth" in options:
            self.azimuth_slider.setValue(int(round(float(options["azimuth"]))) % 360)
        env = options.get("environment") or CUSTOM
        try:
            if options.get("lighting") is not None:
                self.set_lighting(rcp.full_lighting(options["lighting"]), env)
            elif env in ENVIRONMENTS:
                self.set_environment(env)
        except Stylize3DError as exc:
            note = note or str(exc)
        if "color" in options:
            self.color = tuple(float(np.clip(x, 0, 1)) for x in options["color"])
            self._show_color()
        if "face_colors" in options:
            face = options.get("face_colors")
            state = self.window_.document.state
            use_file = False
            if face:
                try:
                    C = rcp.face_colors_of(face)
                except Stylize3DError as exc:
                    note = note or str(exc)
                else:
                    if state is not None and len(C) == len(state.F):
                        self._file_colors, self._file_colors_ref = C, face
                        self._file_colors_key = self._colors_key(state)
                        use_file = True
            self.file_colors_box.blockSignals(True)
            self.file_colors_box.setVisible(self._file_colors is not None)
            self.file_colors_box.setChecked(use_file)
            self.file_colors_box.blockSignals(False)
            self.color_button.setEnabled(not use_file)
        if note:
            self.status_label.setText(note)
        self.schedule_preview()

    def run(self, live: bool = False) -> None:
        """The Run button is "Attack lighting"."""
        self.attack("lighting")

    def attack(self, mode: str) -> bool:
        """Start a lighting or geometry attack with the panel's settings (False: refused, the
        reason is in the status line)."""
        state = self.window_.document.state
        if state is None:
            self.status_label.setText("Open a mesh first (File > Open).")
            return False
        if self.preview_error:
            self.status_label.setText(self.preview_error)
            return False
        try:
            true = self.check_label(self.true_edit)
            target = self.check_label(self.target_edit)
        except Stylize3DError:
            return False
        if true is not None and target is not None and true == target:
            self.status_label.setText("The target is the true label: choose another target, or "
                                      "leave it empty.")
            return False
        if true is None and self.probs is not None:
            # the class the attack moves away from is the one shown now: write it down, so the
            # re-classification of the attacked result does not take the fooled class for it
            self.true_edit.setText(top_k(self.probs, self.class_names(), 1)[0][0])
            self.true_edit.setStyleSheet("")
        params = dataclasses.replace(self.form.params(), mode=mode)
        name = rcp.LIGHTING if mode == "lighting" else rcp.GEOMETRY
        recipe = rcp.RECIPES_BY_NAME[name]
        options = self.job_options()
        self._attack_mode = mode
        self._attack_lighting_before = self.lighting.copy()
        self._attack_env_before = self.env_combo.currentText()
        self.streamed_images = 0
        self._pending_input = state
        self._start_request(name, params, options, state)
        self.preview_runner.cancel()
        self._preview_timer.stop()
        cache = self._recipe_cache

        def factory():
            return recipe.steps(state, params, options, cache)

        self.plot.title = self.plot_title
        self.plot.clear()
        what = "lighting" if mode == "lighting" else "shape"
        self.status_label.setText(f"Attacking the {what}…")
        if mode == "geometry":
            self.window_.start_positions_job(
                self.title, factory, commit=lambda before, step: recipe.result(before, step,
                                                                               options))
        else:
            self.window_.start_analysis_job(self.title, factory)
        return True

    def _on_busy(self, *_):
        super()._on_busy()
        self._update_attack_buttons()

    def _update_attack_buttons(self) -> None:
        """Attacks need a mesh and its first classification (the classifier loaded): until
        then, and while an attack runs, the buttons say why they wait."""
        ready = (not self.window_.document.is_empty and self.probs is not None
                 and not self._attacking())
        for b in (self.attack_light_button, self.attack_geom_button, self.augment_button):
            b.setEnabled(ready)
        why = ("" if ready else "Open a mesh first." if self.window_.document.is_empty
               else "An attack is running." if self._attacking()
               else "Waiting for the classifier's first answer…")
        self.attack_light_button.setStatusTip(why)
        self.attack_geom_button.setStatusTip(why)

    # -- training images --------------------------------------------------------------------
    def make_training_images(self, folder: str | None = None) -> bool:
        """Start *Make training images…* on the document's mesh (the recipe of ``stylize3d
        augment``, :mod:`app.recipes.augment`) into ``folder`` (None: ask for one); False when
        refused or cancelled (the reason is in the status line)."""
        state = self.window_.document.state
        if state is None:
            self.status_label.setText("Open a mesh first (File > Open).")
            return False
        if self.window_.runner.busy:
            self.status_label.setText("Wait for the running job to finish (or Stop it).")
            return False
        try:
            self.check_label(self.true_edit)
        except Stylize3DError:
            return False
        label = self.true_edit.text().strip()
        if not label and self.probs is not None:
            label = top_k(self.probs, self.class_names(), 1)[0][0]
        if not label:
            self.status_label.setText("Type the true label first: it names the images' folder.")
            return False
        if folder is None:
            folder = dialogs.open_folder(self, "Folder for the training images")
            if not folder:
                return False
        params = self.augment_form.params()
        src = self.window_.document.path
        options = {"dataset": str(folder), "label": label, "classifier": self._classifier_ref,
                   "color": [float(x) for x in self.color],
                   "face_colors": self._face_colors_ref(state),
                   "mesh": src.name if src else "mesh", "mesh_index": 0, "overwrite": False}
        try:
            todo, done = aug.plan_request(state, params, options, self.class_names())
        except Stylize3DError as exc:
            if "--overwrite" not in str(exc):
                self.status_label.setText(str(exc))
                return False
            if not dialogs.confirm(self, "Replace training images?",
                                   str(exc).replace("pass --overwrite", "replace them")
                                   + "\n\nReplace them?", yes="Replace"):
                return False
            options["overwrite"] = True
            todo, done = aug.plan_request(state, params, options, self.class_names())
        if not todo:
            self.status_label.setText(f"All {len(done)} images are already in {folder}.")
            return False
        options.update(indices=todo, skipped=len(done))
        self._augmenting = True
        self.augment_summary = None
        self.plot.title = "The classifier's confidence in the true class per training image"
        self.plot.clear()
        self.status_label.setText(f"Making {len(todo)} training image(s) ({len(done)} already "
                                  "there)…")
        recipe = aug.AUGMENT_RECIPE
        self.window_.start_analysis_job(
            self.title, lambda: recipe.steps(state, params, options, {}))
        return True

    def _augment_done(self, step) -> None:
        self._augmenting = False
        self.stop_button.setEnabled(False)
        self.augment_summary = dict(getattr(step, "summary", {}) or {})
        text = f"Training images: {step.message}."
        self.status_label.setText(text)
        self.window_.report(text)
        self._preview_stale = True
        QTimer.singleShot(0, self.schedule_preview)

    def _augment_stopped(self, message: str) -> None:
        self._augmenting = False
        self.status_label.setText(f"{message} The training images made so far are kept (the "
                                  "manifest lists them); Make training images… on the same "
                                  "folder makes the missing ones.")
        self.stop_button.setEnabled(False)
        QTimer.singleShot(0, self.schedule_preview)

    def _on_metrics(self, history) -> None:
        if not self._mine():
            return
        if self._augmenting:
            for _it, m in history:
                if "true_probability" in m:
                    self.plot.append("true class", m["true_probability"])
            return
        target = bool(self.target_edit.text().strip())
        for _it, m in history:
            if "confidence_decreased" in m:
                self.plot.append("true class", m["confidence_decreased"])
            if target and "confidence_increased" in m:
                self.plot.append("target", m["confidence_increased"])

    def _on_preview(self, step) -> None:
        if self._mine() and self._augmenting and isinstance(step, aug.DatasetStep):
            if step.image is not None:
                self.image_label.setPixmap(image_to_pixmap(step.image, IMAGE_SIZE))
                self.image_note.setText("Making training images: the last image written.")
            self.status_label.setText(f"Image {step.iteration}/{step.total}: {step.message}")
            return
        if not self._mine() or not isinstance(step, AttackStep):
            return
        if step.images is not None and len(step.images) and step.top5:
            self.show_classification(step.images[0], step.top5[0])
            self.streamed_images += 1
        total = f"/{step.total}" if step.total else ""
        fooled = sum(step.fooled)
        self.status_label.setText(f"Iteration {step.iteration}{total}: {fooled} of "
                                  f"{len(step.fooled)} view(s) fooled.")
        self.image_note.setText("During the attack: the perturbed image as classified.")

    def _on_finished(self, step) -> None:
        if self.window_.last_job_name != self.title:
            return
        if self._augmenting:
            self._augment_done(step)
            return
        self.stop_button.setEnabled(False)
        res = getattr(step, "result", None)
        if res is None:
            return
        self.last_result = res
        if self._attack_mode == "lighting":
            self._revert_to = (self._attack_lighting_before, self._attack_env_before)
            self.lighting = np.array(res.lighting, dtype=np.float64)
            self.env_combo.setCurrentText(CUSTOM)
            self._sync_sliders()
            self.revert_button.setEnabled(True)
        v = res.views[0]
        self.before_image.setPixmap(image_to_pixmap(res.images_before[0], 150))
        self.after_image.setPixmap(image_to_pixmap(res.images_after[0], 150))
        self.before_caption.setText(f"Before: {v.label_before} {100 * v.confidence_before:.0f} %")
        self.after_caption.setText(f"After: {v.label_after} {100 * v.confidence_after:.0f} %"
                                   + (" (fooled)" if v.success else ""))
        self.before_after_box.setVisible(True)
        QTimer.singleShot(0, lambda: self.scroll_area.ensureWidgetVisible(self.before_after_box))
        fooled = sum(x.success for x in res.views)
        what = "lighting coefficient" if self._attack_mode == "lighting" else \
            "vertex coordinate (of the shape scaled to a unit box)"
        undo = ("Revert attack restores the lighting." if self._attack_mode == "lighting"
                else "Undo with Ctrl+Z.")
        self.status_label.setText(
            f"Done after {res.iterations} iteration(s): {fooled} of {len(res.views)} view(s) "
            f"fooled; the largest change of a {what} is {res.norm:.3g}. {undo}")
        self._preview_stale = True
        QTimer.singleShot(0, self.schedule_preview)

    def _on_stopped(self, message: str) -> None:
        if self.window_.last_job_name != self.title:
            return
        if self._augmenting:
            self._augment_stopped(message)
            return
        super()._on_stopped(message)
        if self._attack_lighting_before is not None and self._attack_mode == "lighting":
            self.lighting = self._attack_lighting_before.copy()
            self._sync_sliders()
        self.image_note.setText("Stopped: the lighting and the shape are as they were.")
        QTimer.singleShot(0, self.schedule_preview)
