"""Panel "Analogies": normal-driven spherical shape analogies (thesis ch. 6).

* a gallery of style primitives (thumbnails from resources/styles, made by
  scripts/make_style_thumbnails.py), "Load style…" for a user mesh (closest normals when it is
  convex, a cMCF spherical map otherwise) or a capture .json, and "Capture sphere" mode;
* the Params form (λ, regularizer, dynamic targets, developable threshold, PolyCube), live by
  default; a Run computes the recipe "Analogies" (:mod:`app.recipes.analogies`) from the
  state, the Params and :meth:`AnalogiesPanel.job_options` (the style, the painted capture
  sphere); its cache keeps the ShapeAnalogy precomputation while only the parameters change;
* a normal-capture sphere: pick a target direction, paint regions of the sphere of directions;
  vertices whose normals fall in a region are sent to that direction (one undo step per stroke,
  computed by :func:`app.recipes.analogies.apply_capture_stroke`; the command's
  ``log_details`` let the study replay check it);
* views: the mesh coloured by the angle between its normals and their targets (thesis Fig. 6.15),
  by Gaussian curvature (angle defect per Voronoi area, Fig. 6.21), or by its transferred target
  directions in the same colours as the capture sphere (computed by the recipe module).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PySide6.QtCore import QSize
from PySide6.QtGui import QIcon, QUndoCommand
from PySide6.QtWidgets import (QComboBox, QGroupBox, QHBoxLayout, QLabel, QListWidget,
                               QListWidgetItem, QPushButton, QVBoxLayout, QWidget)

from algorithms.deform.analogies import AnalogyParams
from algorithms.deform.targets import PRIMITIVES
from algorithms.errors import Stylize3DError
from app import dialogs
from app.panels.base import MethodPanel
from app.recipes import put_blob_file
from app.recipes.analogies import (CAPTURE, HUE_RANGE, angle_to_targets_view,
                                   apply_capture_stroke, capture_from_dict, capture_hash,
                                   capture_view_values, direction_hue, gaussian_curvature_view,
                                   new_capture, style_target_map, target_direction_view)
from app.tools import BrushSettings
from app.viewport import PickResult, Viewport
from app.widgets import article

STYLE_DIR = Path(__file__).resolve().parents[2] / "resources" / "styles"
AXES = {"+X": (1, 0, 0), "−X": (-1, 0, 0), "+Y": (0, 1, 0), "−Y": (0, -1, 0),
        "+Z": (0, 0, 1), "−Z": (0, 0, -1)}

__all__ = ["AnalogiesPanel", "CaptureBrush", "direction_hue", "HUE_RANGE", "CAPTURE", "AXES"]


def _capture_icon(size: int = 56) -> QIcon:
    """A sphere with painted patches: the gallery's picture of "paint your own"."""
    from PySide6.QtCore import QRectF
    from PySide6.QtGui import QBrush, QColor, QPainter, QPixmap, QRadialGradient

    pix = QPixmap(size, size)
    pix.fill(QColor(0, 0, 0, 0))
    p = QPainter(pix)
    p.setRenderHint(QPainter.RenderHint.Antialiasing)
    g = QRadialGradient(size * 0.38, size * 0.35, size * 0.6)
    g.setColorAt(0.0, QColor("#d8d8d8"))
    g.setColorAt(1.0, QColor("#6e6e6e"))
    r = QRectF(3, 3, size - 6, size - 6)
    p.setBrush(QBrush(g))
    p.setPen(QColor("#555"))
    p.drawEllipse(r)
    p.setPen(QColor(0, 0, 0, 0))
    for color, start in (("#d64545", 20 * 16), ("#3f9b4f", 140 * 16), ("#3b6fd6", 260 * 16)):
        p.setBrush(QColor(color))
        p.drawPie(r.adjusted(8, 8, -8, -8), start, 50 * 16)
    p.end()
    return QIcon(pix)


class _CaptureCommand(QUndoCommand):
    """One capture-sphere stroke. ``log_details`` (written by the study log) holds the sphere
    before, the stroke and the hash of the sphere after, for
    :func:`app.recipes.analogies.replay_capture_edit`. (The spheres are ``capture_before`` /
    ``capture_after``, not ``before`` / ``after``: those names mean document states to the
    study log.)"""

    def __init__(self, panel: "AnalogiesPanel", before: dict, after: dict, stroke: dict):
        super().__init__("Paint capture sphere")
        self.panel, self.capture_before, self.capture_after = panel, before, after
        self.stroke = stroke
        self.log_details = {"tool": "capture", "capture_before": before, "stroke": stroke,
                            "capture_after_hash": capture_hash(after)}

    def redo(self) -> None:
        self.panel.set_capture(capture_from_dict(self.capture_after))

    def undo(self) -> None:
        self.panel.set_capture(capture_from_dict(self.capture_before))


class CaptureBrush:
    """Paints the capture sphere's regions (picks on the sphere view). A stroke is recorded as
    its inputs (the picked points, radius, erase, target); after each dab the sphere shown is
    :func:`~app.recipes.analogies.apply_capture_stroke` of the sphere before the stroke and the
    stroke so far, and the release commits that as one undo step."""

    def __init__(self, panel: "AnalogiesPanel", settings: BrushSettings):
        self.panel = panel
        self.settings = settings
        self._before: dict | None = None
        self._stroke: dict | None = None
        self._after: dict | None = None

    def press(self, hit: PickResult) -> bool:
        from PySide6.QtCore import Qt

        if hit.modifiers & Qt.KeyboardModifier.ShiftModifier:  # pick a custom target direction
            self.panel.set_custom_target(hit.position)
            return True
        self._before = self.panel.capture.to_dict()
        self._stroke = {"dabs": [], "radius": float(self.settings.radius),
                        "erase": bool(self.settings.erase),
                        "target": [float(x) for x in self.panel.capture_target()]}
        self._dab(hit)
        return True

    def drag(self, hit: PickResult | None) -> None:
        if hit is not None and self._before is not None:
            self._dab(hit)

    def _dab(self, hit: PickResult) -> None:
        self._stroke["dabs"].append([float(x) for x in np.asarray(hit.position).reshape(3)])
        after = apply_capture_stroke(self._before, self._stroke)
        self.panel.capture = capture_from_dict(after)
        self._after = after
        self.panel.refresh_capture_view()

    def release(self) -> None:
        if self._before is None:
            return
        before, self._before = self._before, None
        stroke, self._stroke = self._stroke, None
        after, self._after = self._after, None
        if after != before:
            self.panel.window_.undo_stack.push(_CaptureCommand(self.panel, before, after,
                                                               stroke))


class AnalogiesPanel(MethodPanel):
    title = "Analogies"
    description = ("Gives the shape the look of a style: its surface normals are pulled towards "
                   "the normals of a style shape (or of a sphere you paint). Pick a style, move λ.")
    params_cls = AnalogyParams
    plot_metrics = ("mean_angle_to_targets",)
    plot_title = "Mean angle to the target normals (°)"
    live_by_default = True
    run_from_base = True  # Run and the λ slider start from one base shape
    builtin_presets = {"subtle": {"lam": 0.3}, "strong": {"lam": 4.0}}

    def __init__(self, window):
        super().__init__(window)
        self.style_name = "cube"
        self.custom_style = None  # (blob reference, description) of a loaded style file
        self.capture = new_capture()
        self.brush_settings = BrushSettings(radius=0.1, strength=1.0)
        self._build()
        window.document.subscribe(self._on_doc)

    # -- widgets -------------------------------------------------------------------------------
    def _build(self) -> None:
        lay = self.body_layout
        box = QGroupBox("Style")
        v = QVBoxLayout(box)
        self.gallery = QListWidget()
        self.gallery.setViewMode(QListWidget.ViewMode.IconMode)
        self.gallery.setIconSize(QSize(56, 56))
        self.gallery.setGridSize(QSize(104, 92))  # one cell per style: labels never run together
        self.gallery.setWordWrap(True)
        self.gallery.setFixedHeight(196)  # two rows of cells
        self.gallery.setResizeMode(QListWidget.ResizeMode.Adjust)
        self.gallery.setToolTip("Click a style: the surface is pulled towards its face "
                                "directions.")
        for name in PRIMITIVES + (CAPTURE,):
            png = STYLE_DIR / f"{name}.png"
            icon = (QIcon(str(png)) if png.exists()
                    else _capture_icon() if name == CAPTURE else QIcon())
            item = QListWidgetItem(icon,
                                   name.replace("_", " "))
            item.setData(256, name)
            item.setToolTip("Paint your own targets on the sphere below" if name == CAPTURE
                            else f"Closest normals of {article(name.replace('_', ' '))}")
            self.gallery.addItem(item)
        self.gallery.setCurrentRow(0)
        self.gallery.currentItemChanged.connect(self._on_gallery)
        v.addWidget(self.gallery)
        row = QHBoxLayout()
        self.load_button = QPushButton("Load style…")
        self.load_button.setToolTip("Use a mesh file as the style (convex: its faces; any closed "
                                    "genus-0 shape: a spherical map) or a capture .json file.")
        self.load_button.clicked.connect(self.load_style_dialog)
        self.style_label = QLabel("closest normals of a cube")
        self.style_label.setWordWrap(True)
        row.addWidget(self.load_button)
        row.addWidget(self.style_label, 1)
        v.addLayout(row)
        lay.insertWidget(lay.indexOf(self.form), box)

        cap = QGroupBox("Capture sphere: paint regions of directions (Shift+click: pick target)")
        cv = QVBoxLayout(cap)
        row = QHBoxLayout()
        self.target_combo = QComboBox()
        self.target_combo.addItems(list(AXES) + ["custom"])
        self.target_combo.setToolTip("The direction painted regions send their normals to. "
                                     "Shift+click the sphere to pick any direction (custom).")
        self._custom_target = np.array([0.0, 0.0, 1.0])
        self.erase_button = QPushButton("Erase mode")
        self.erase_button.setCheckable(True)
        self.erase_button.toggled.connect(lambda on: setattr(self.brush_settings, "erase", on))
        self.save_capture_button = QPushButton("Save…")
        self.save_capture_button.setToolTip("Save the painted sphere as a capture .json file.")
        self.save_capture_button.clicked.connect(self.save_capture_dialog)
        row.addWidget(QLabel("Target"))
        row.addWidget(self.target_combo)
        row.addWidget(self.erase_button)
        row.addWidget(self.save_capture_button)
        cv.addLayout(row)
        self.capture_view = Viewport(cap)
        self.capture_view.show_legend = False  # hues are directions, shown on the sphere itself
        self.capture_view.setMinimumSize(200, 200)
        self.capture_view.set_mesh(self.capture.vertices, self.capture.faces)
        self.capture_brush = CaptureBrush(self, self.brush_settings)
        self.capture_view.set_handler(self.capture_brush)
        cv.addWidget(self.capture_view)
        self.capture_box = cap
        lay.insertWidget(lay.indexOf(self.form) + 1, cap)

        row = QHBoxLayout()
        self.view_combo = QComboBox()
        self.view_combo.addItems(["Shape only", "Angle to targets", "Gaussian curvature",
                                  "Target directions"])
        self.view_combo.setToolTip("Colour the mesh by the angle between its normals and their "
                                   "targets, or by its Gaussian curvature.")
        self.view_combo.currentIndexChanged.connect(lambda _i: self.show_view())
        row.addWidget(QLabel("Colour by"))
        row.addWidget(self.view_combo, 1)
        lay.insertLayout(lay.indexOf(self.plot) + 1, row)
        self.refresh_capture_view()

    # -- style -----------------------------------------------------------------------------------
    def capture_target(self) -> np.ndarray:
        key = self.target_combo.currentText()
        if key == "custom":
            return self._custom_target.copy()
        return np.array(AXES[key], dtype=np.float64)

    def set_custom_target(self, direction) -> None:
        d = np.asarray(direction, dtype=np.float64)
        self._custom_target = d / max(np.linalg.norm(d), 1e-12)
        self.target_combo.setCurrentText("custom")
        self.status_label.setText("Custom target direction ({:.2f}, {:.2f}, {:.2f}): paint "
                                  "regions to send their normals there."
                                  .format(*self._custom_target))

    def set_capture(self, cap: CaptureSphere) -> None:
        self.capture = cap
        self.refresh_capture_view()
        if self.style_name == CAPTURE:
            self._on_params_changed(None)

    def refresh_capture_view(self) -> None:
        # regions coloured by their target direction
        self.capture_view.show_field("capture", capture_view_values(self.capture), "hsv",
                                     HUE_RANGE)
        if self.view_combo.currentIndex() == 3:
            self.show_view()

    def _on_gallery(self, item, _prev=None) -> None:
        if item is None:
            return
        self.style_name = item.data(256)
        self.custom_style = None
        self.style_label.setText("your painted capture sphere" if self.style_name == CAPTURE
                                 else f"closest normals of {article(item.text())}")
        self._on_params_changed(None)
        self.show_view()

    def load_style_dialog(self) -> bool:
        path = dialogs.open_file(self, "Load style", "Style meshes or captures "
                                 "(*.obj *.ply *.stl *.off *.json)")
        if not path:
            return False
        try:
            ref = put_blob_file(path)
            # read (and kept in the recipe's cache) now: errors show here, runs reuse the map
            _tmap, what = style_target_map({"style": ref}, self._recipe_cache)
        except OSError as e:
            dialogs.error(self, "Cannot use this style", f"{path} could not be read ({e}).")
            return False
        except Stylize3DError as e:
            dialogs.error(self, "Cannot use this style", str(e))
            return False
        self.custom_style = (ref, what)
        self.style_name = path
        self.gallery.clearSelection()
        self.style_label.setText(what)
        self._on_params_changed(None)
        return True

    def save_capture_dialog(self) -> bool:
        path = dialogs.save_file(self, "Save capture sphere", "Capture (*.json)")
        if not path:
            return False
        if not path.endswith(".json"):
            path += ".json"
        if Path(path).exists() and not dialogs.confirm(self, "Replace file?",
                                                       f"{path} exists. Replace it?",
                                                       yes="Replace"):
            return False
        try:
            self.capture.save(path)
        except (OSError, Stylize3DError) as e:
            dialogs.error(self, "Could not save", str(e))
            return False
        return True

    def job_options(self) -> dict:
        """The recipe's options (:mod:`app.recipes.analogies`): ``style`` (a primitive name,
        "capture sphere", or the blob reference of a loaded style file), ``style_map``
        ("auto") and ``capture`` (the painted sphere's dict, always: a saved project keeps
        the painting)."""
        style = self.custom_style[0] if self.custom_style is not None else self.style_name
        return {"style": style, "style_map": "auto", "capture": self.capture.to_dict()}

    def restore_options(self, options: dict) -> None:
        """Set the gallery / loaded style and the capture sphere from saved options (no live
        re-run). A style file whose data is missing leaves the style as it was and says so."""
        cap = options.get("capture")
        if cap is not None:
            try:
                self.capture = capture_from_dict(cap)
            except Stylize3DError as e:
                self.status_label.setText(f"The saved capture sphere was not restored: {e}")
            self.refresh_capture_view()
        style = options.get("style", "cube")
        if style in PRIMITIVES or style == CAPTURE:
            rows = [i for i in range(self.gallery.count())
                    if self.gallery.item(i).data(256) == style]
            self.gallery.blockSignals(True)
            self.gallery.setCurrentRow(rows[0])
            self.gallery.blockSignals(False)
            self.style_name, self.custom_style = style, None
            self.style_label.setText("your painted capture sphere" if style == CAPTURE
                                     else f"closest normals of "
                                          f"{article(style.replace('_', ' '))}")
            return
        mode = options.get("style_map", "auto")
        try:
            _tmap, what = style_target_map({"style": style, "style_map": mode},
                                           self._recipe_cache)
        except Stylize3DError as e:
            self.status_label.setText(f"The saved style was not restored: {e}")
            return
        self.custom_style = (style, what)
        self.style_name = str(style).split("/", 1)[-1]
        self.gallery.blockSignals(True)
        self.gallery.clearSelection()
        self.gallery.blockSignals(False)
        self.style_label.setText(what)

    def target_map(self):
        """The chosen style's target map (a capture sphere: a snapshot of the painting)."""
        return style_target_map(self.job_options(), self._recipe_cache)[0]

    # -- views -----------------------------------------------------------------------------------
    def show_view(self) -> None:
        doc = self.window_.document
        if doc.is_empty:
            return
        i = self.view_combo.currentIndex()
        if i == 0:
            self.window_.viewport.show_field(None)
        elif i == 1:
            ang = angle_to_targets_view(doc.V, doc.F, self.target_map())
            self.window_.viewport.show_field("angle_to_targets", ang, "magma", (0.0, 45.0))
        elif i == 3:  # the transferred targets, in the capture sphere's colours
            hue = target_direction_view(doc.V, doc.F, self.target_map())
            self.window_.viewport.show_field("target_direction", hue, "hsv", HUE_RANGE)
        else:
            K, lim = gaussian_curvature_view(doc.V, doc.F)
            self.window_.viewport.show_field("gaussian_curvature", K, "coolwarm", lim)

    def _on_doc(self, what: str) -> None:
        if (what in ("mesh", "positions", "topology") and self.view_combo.currentIndex()
                and self.is_shown()):
            self.show_view()

    def _on_finished(self, step) -> None:
        super()._on_finished(step)
        if self.window_.last_job_name != self.title:
            return
        from app.recipes.analogies import change_note

        request = self.last_request or {}
        start = request.get("input")
        angle = step.metrics.get("mean_angle_to_targets")
        if start is None or step.V is None or angle is None:
            return
        # the last step's positions: what was committed
        note = change_note(start.V, step.V, float(angle), request["params"].lam)
        if note:
            self.status_label.setText(f"{self.status_label.text()} {note}")

    def refresh_view(self) -> None:
        self.show_view()

    # -- the method --------------------------------------------------------------------------------
    def run(self, live: bool = False) -> None:
        # the style is read here, on the GUI thread, as before: a style that cannot be used is
        # said in the status line and nothing starts (the run itself is the recipe's)
        try:
            style_target_map(self.job_options(), self._recipe_cache)
        except Stylize3DError as e:
            self.status_label.setText(str(e))
            return
        super().run(live)
