"""Panel "Paparazzi": image filters applied to a shape through its renderings (thesis ch. 2).

* A filter from the registry (:func:`algorithms.paparazzi.filter_names`: the built-in ones and
  any registered later, e.g. by a plug-in) with a form generated from its Params dataclass; the
  form is rebuilt when the filter changes and each filter keeps its own settings. Text fields
  without choices are files (a target image, a target mesh): they get a "Choose…" button, and
  a file that cannot be used is refused with a plain message before anything runs.
* The run's settings (:class:`~algorithms.paparazzi.PaparazziParams`: iterations, learning rate,
  σ, resolution, ...), with a shorter default run than the command line's (see
  :data:`GUI_ITERATIONS`).
* While the loop runs on the worker thread the shape updates in the 3D view (remeshing changes
  its triangles: the panel is a ``changes_faces`` panel, see :mod:`app.panels.base`), a pair of
  small images shows the current iteration's rendering and its filtered version, and the plot
  shows the monitor energy: the mean over 16 fixed views all around the shape (thesis
  353-356 watch one view; see :mod:`algorithms.paparazzi.optimize`).
* Stop puts the mesh back; the finished result (new vertices and triangles) is one undoable
  command.

The run itself is the Qt-free recipe "Paparazzi" (:mod:`app.recipes.paparazzi`): the panel gives
it the form's Params and :meth:`PaparazziPanel.job_options` (the filter, its settings, its files
as blob references, a plug-in's file); the pictures and the plot read the streamed steps through
that module's view functions.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from PySide6.QtCore import Qt
from PySide6.QtGui import QImage, QPixmap
from PySide6.QtWidgets import (QComboBox, QFormLayout, QGridLayout, QGroupBox, QHBoxLayout,
                               QLabel, QLineEdit, QPushButton, QVBoxLayout, QWidget)

from algorithms.errors import Stylize3DError
from algorithms.params import describe, param, params_from_dict
from algorithms.paparazzi import PaparazziParams
from algorithms.steps import Step
from app.document import MeshState
from app.forms import ParamsForm
from app.panels.base import MethodPanel
from app.recipes.paparazzi import (describe_filter_file, ensure_filter, filter_names,
                                   filter_options, manifold_report, monitor_points, rgb8)
from app.recipes.paparazzi import filter_spec as get_filter
from app.widgets import article, number, plural

#: the panel's default number of iterations: a 3,000-vertex mesh takes about 10-20 s at the
#: filter's resolution (the command line and the thesis use 1000 or more)
GUI_ITERATIONS = 300
#: the filter chosen when the panel opens: the one whose effect shows on any shape in the
#: default 300 iterations (issue 24, item 4: the guided filter, the former default, smooths what
#: is rough, and the bundled blob is smooth already, so its default Run changed nothing one
#: could see; quantize cuts facets into every shape, e.g. the blob's monitor energy falls by
#: more than half; docs/results/paparazzi.md, "The panel's default Run")
DEFAULT_PANEL_FILTER = "quantize"
#: the panel's monitor interval: 16 monitor views every 25 iterations (the command line's)
#: made quantize's default run on the blob 40 % monitor (22.9 of 56.8 s on a loaded machine);
#: every 50 the plot still has 7 points
GUI_MONITOR_EVERY = 50
#: side of the two live images, in pixels
THUMB = 112


@dataclass(frozen=True)
class PaparazziPanelParams(PaparazziParams):
    """:class:`PaparazziParams` with the panel's shorter default run and sparser monitor (all
    other fields alike)."""

    iterations: int = param(
        GUI_ITERATIONS, label="Iterations", minimum=1, maximum=100000, step=50,
        tooltip=f"How many views to render and filter. {GUI_ITERATIONS} shows the effect in "
                "seconds to a minute; the thesis uses 1000-3000 views (the command line's "
                "default is 1000) for a strong effect. l0 starts at 1000: on a smooth shape "
                "its energy rises before it falls, and a run that ends above its start fails.")
    monitor_every: int = param(
        GUI_MONITOR_EVERY, label="Monitor every", minimum=0, maximum=10000, advanced=True,
        tooltip="Evaluate the monitor energy (the mean over the fixed monitor views) every this "
                "many iterations (0 = only at the start and the end).")


#: plain words appended to the tooltips of the run's settings
PLAIN = {
    "learning_rate": "NAdam: the optimizer that moves the vertices, a gradient descent with "
                     "momentum (as used to train neural networks). The learning rate is its "
                     "step size; it is divided by 5 for the last 10 % of the views.",
    "sigma": "σ (sigma) = camera offset: the cameras sit on a cage this far outside the shape "
             "and look at it from all around. Small σ shows small details; large σ whole parts.",
    "resolution": "The filter sees images this many pixels wide; details smaller than a pixel "
                  "are not changed. Higher is slower.",
    "view_width": "How wide a piece of the shape one picture shows (orthographic camera).",
    "remesh_every": "Remeshing: triangles that got too thin, too long or too short while the "
                    "shape moved are remade (the rest of the surface stays as the steps shaped "
                    "it). If the steps made the surface cross itself, the crossing triangles are "
                    "put back where they were at the last check.",
    "monitor_every": "Monitor views: 16 fixed cameras all around the shape whose pictures are "
                     "filtered now and then; their mean energy (plotted below) says how far the "
                     "shape still is from what the filter wants. It should go down.",
    "monitor_views": "More views give a steadier plot; each costs one filter call per "
                     "evaluation.",
    "upsample_vertices": "More vertices let the shape take on finer features of the filter.",
}


def _image_to_qimage(img, size: int = THUMB) -> QImage:
    """An (H, W, C) float image in [0, 1] (C = 1 or 3) as a size × size QImage (nearest pixels,
    so a 64-pixel rendering stays readable); the pixels come from :func:`rgb8`."""
    rgb = rgb8(img)
    h, w = rgb.shape[:2]
    qimg = QImage(rgb.data, w, h, 3 * w, QImage.Format.Format_RGB888).copy()
    return qimg.scaled(size, size, Qt.AspectRatioMode.KeepAspectRatio,
                       Qt.TransformationMode.FastTransformation)


def _file_kind(spec) -> str:
    """'image', 'mesh' or 'file': what a text field of a filter's Params holds."""
    words = f"{spec.name} {spec.label}".lower()
    if "image" in words:
        return "image"
    if "mesh" in words or spec.name == "target":
        return "mesh"
    return "file"


class _FilterCombo(QComboBox):
    """The filter drop-down; re-reads the registry each time it opens."""

    def __init__(self, refresh, parent=None):
        super().__init__(parent)
        self._refresh = refresh

    def showPopup(self) -> None:  # noqa: N802 (Qt API)
        self._refresh()
        super().showPopup()


class PaparazziPanel(MethodPanel):
    title = "Paparazzi"
    description = ("Moves the surface until its pictures, taken from many cameras, look "
                   "filtered (thesis ch. 2). A run takes a while: choose a filter, press Run, "
                   "watch it change.")
    params_cls = PaparazziPanelParams
    plot_metrics = ("monitor_energy",)
    plot_title = ("Monitor energy (mean over fixed views all around; lower = closer to the "
                  "filter's look)")
    changes_faces = True
    live_by_default = False
    param_groups = {"Cameras and remeshing": ("view_width", "remesh_every", "seed")}
    builtin_presets = {"quick look": {"iterations": 100, "resolution": 64},
                       "thesis length": {"iterations": 1000}}

    def __init__(self, window):
        super().__init__(window)
        self._filter_values: dict[str, Any] = {}   # filter name -> its last Params
        self._paths: dict[tuple[str, str], str] = {}  # (filter, field) -> chosen file
        self._path_edits: dict[str, QLineEdit] = {}
        self._path_buttons: dict[str, QPushButton] = {}
        self._path_kinds: dict[str, str] = {}
        self.filter_form: ParamsForm | None = None
        self._monitor_every = 0
        self._first_monitor = None
        self._add_plain_words()
        self._build_filter_box()
        self._build_views_box()
        self._rebuild_filter_form()
        self.form.changed.connect(lambda _p: self._show_filter_defaults())
        # after the form's own reset (connected first): the chosen filter's iteration count
        self.defaults_button.clicked.connect(self._defaults_for_filter)

    # -- widgets -------------------------------------------------------------------------------
    def _add_plain_words(self) -> None:
        for name, text in PLAIN.items():
            if name in self.form.editors:
                for w in (self.form.editors[name], self.form.labels[name]):
                    w.setToolTip(w.toolTip() + "\n\nIn plain words:\n• " + text)

    def _build_filter_box(self) -> None:
        lay: QVBoxLayout = self.body_layout
        box = QGroupBox("Image filter")
        v = QVBoxLayout(box)
        row = QHBoxLayout()
        self.filter_combo = _FilterCombo(self.refresh_filters)
        self.filter_combo.setToolTip("What the pictures of the shape should look like. Energy "
                                     "filters (target image / mesh) pull the pictures towards a "
                                     "target; the other filters are applied to each picture.")
        row.addWidget(QLabel("Filter"))
        row.addWidget(self.filter_combo, 1)
        v.addLayout(row)
        self.filter_about = QLabel("")
        self.filter_about.setWordWrap(True)
        self.filter_about.setStyleSheet("color: #555;")
        v.addWidget(self.filter_about)
        self.filter_form_holder = QVBoxLayout()
        self.filter_form_holder.setContentsMargins(0, 0, 0, 0)
        v.addLayout(self.filter_form_holder)
        self.filter_box = box
        lay.insertWidget(lay.indexOf(self.form), box)
        self.refresh_filters()
        i = self.filter_combo.findText(DEFAULT_PANEL_FILTER)
        self.filter_combo.setCurrentIndex(max(i, 0))
        self.filter_combo.currentTextChanged.connect(lambda _t: self._rebuild_filter_form())

    def _build_views_box(self) -> None:
        lay: QVBoxLayout = self.body_layout
        box = QGroupBox("This iteration's view")
        box.setToolTip("Left: the shape as this iteration's camera sees it (its colours are the "
                       "lighting the filter works on). Right: that picture after the filter, "
                       "i.e. what the step moves the shape towards (neural-style's Gram "
                       "energy shows the style whose texture the views should take on).")
        g = QGridLayout(box)
        self.render_label = QLabel("no run yet")
        self.filtered_label = QLabel("")
        for col, (lab, cap) in enumerate(((self.render_label, "Rendered"),
                                          (self.filtered_label, "Filtered"))):
            lab.setFixedSize(THUMB, THUMB)
            lab.setAlignment(Qt.AlignmentFlag.AlignCenter)
            lab.setStyleSheet("background: #ececec; color: #777; border: 1px solid #bbb;")
            g.addWidget(lab, 0, col, Qt.AlignmentFlag.AlignHCenter)
            c = QLabel(cap)
            c.setAlignment(Qt.AlignmentFlag.AlignHCenter)
            g.addWidget(c, 1, col)
        self.filtered_caption = c           # the filter may call its picture otherwise
        self.views_box = box
        lay.insertWidget(lay.indexOf(self.plot), box)

    def refresh_filters(self) -> None:
        """List the registered filters (a filter registered later appears by itself)."""
        names = filter_names()
        current = self.filter_combo.currentText()
        have = [self.filter_combo.itemText(i) for i in range(self.filter_combo.count())]
        if names == have:
            return
        self.filter_combo.blockSignals(True)
        self.filter_combo.clear()
        for i, name in enumerate(names):
            self.filter_combo.addItem(name)
            spec = get_filter(name)
            if spec.description:
                self.filter_combo.setItemData(i, spec.description, Qt.ItemDataRole.ToolTipRole)
        if current in names:
            self.filter_combo.setCurrentText(current)
        self.filter_combo.blockSignals(False)
        if current and current not in names and names:
            self._rebuild_filter_form()

    def filter_name(self) -> str:
        return self.filter_combo.currentText()

    def set_filter(self, name: str) -> None:
        """Choose a filter by name (re-reading the registry first)."""
        self.refresh_filters()
        self.filter_combo.setCurrentText(name)

    def _rebuild_filter_form(self) -> None:
        """A new form for the chosen filter's Params (its last values kept per filter)."""
        if self.filter_form is not None:
            self._filter_values[self.filter_form.filter_name] = self.filter_form.params()
            self.filter_form.setParent(None)
            self.filter_form.deleteLater()
            self.filter_form = None
        while self.filter_form_holder.count():
            w = self.filter_form_holder.takeAt(0).widget()
            if w is not None:
                w.setParent(None)
                w.deleteLater()
        self._path_edits.clear()
        self._path_buttons.clear()
        self._path_kinds.clear()
        name = self.filter_name()
        if not name:
            return
        try:
            spec = get_filter(name)
        except Stylize3DError:
            return
        self.filter_about.setText(spec.description or "")
        self._follow_filter_iterations(spec)
        files = [s for s in describe(spec.params) if s.type is str and not s.choices]
        form = ParamsForm(spec.params, values=self._filter_values.get(name),
                          exclude=tuple(s.name for s in files))
        form.filter_name = name
        form.changed.connect(self._on_params_changed)
        # the filter's own step may follow its settings (neural-style's energy)
        form.changed.connect(lambda _p: self._show_filter_defaults())
        self.filter_form = form
        self._show_filter_defaults()
        if files:
            rows = QWidget()
            fl = QFormLayout(rows)
            fl.setContentsMargins(0, 0, 0, 0)
            for s in files:
                kind = _file_kind(s)
                edit = QLineEdit(self._paths.get((name, s.name), ""))
                optional = s.name in spec.optional_files
                edit.setPlaceholderText(f"{'optional: ' if optional else ''}"
                                        f"choose {article(kind)}…")
                edit.setToolTip(s.tooltip)
                edit.editingFinished.connect(
                    lambda s=s, e=edit: e.isModified() and self.set_filter_file(s.name, e.text()))
                button = QPushButton("Choose…")
                button.setToolTip(f"Open {article(kind)} file for '{s.label}'.")
                button.clicked.connect(lambda _=False, s=s: self._choose_file(s.name))
                row = QHBoxLayout()
                row.addWidget(edit, 1)
                row.addWidget(button)
                label = QLabel(s.label)
                label.setToolTip(s.tooltip)
                fl.addRow(label, row)
                self._path_edits[s.name] = edit
                self._path_buttons[s.name] = button
                self._path_kinds[s.name] = kind
            self.filter_form_holder.addWidget(rows)
        if form.specs:
            self.filter_form_holder.addWidget(form)
        elif not files:
            none = QLabel("This filter has no settings.")
            none.setStyleSheet("color: #777;")
            self.filter_form_holder.addWidget(none)

    def presets(self) -> dict[str, dict]:
        """The presets, for the chosen filter: *Defaults* with its own iteration count (l0
        1000) and *quick look* with its own values (``FilterSpec.quick_look``)."""
        out = super().presets()
        if getattr(self, "filter_combo", None) is None:     # the base class asks while building
            return out
        try:
            spec = get_filter(self.filter_name())
        except Stylize3DError:
            return out
        n = int(getattr(spec, "panel_iterations", 0) or GUI_ITERATIONS)
        if n != GUI_ITERATIONS:
            out["Defaults"] = {"iterations": n}
        if "quick look" in self.builtin_presets and "quick look" not in self.user_presets():
            out["quick look"] = {**self.builtin_presets["quick look"],
                                 **(getattr(spec, "quick_look", None) or {})}
        return out

    def _defaults_for_filter(self) -> None:
        """The Defaults button: every run setting's default, the filter's iteration count."""
        values = self.presets().get("Defaults") or {}
        if values:
            self.form.set_params(dataclasses.replace(self.form.params(), **values))
            self.form.changed.emit(self.form.params())

    def _follow_filter_iterations(self, spec) -> None:
        """Each filter starts at its own iteration count (``FilterSpec.panel_iterations``; l0
        1000, the others 300): a count still at the previous filter's is changed with the
        filter, one the user typed is kept."""
        new = int(getattr(spec, "panel_iterations", 0) or GUI_ITERATIONS)
        old = getattr(self, "_filter_iterations", GUI_ITERATIONS)
        self._filter_iterations = new
        p = self.form.params()
        if new != old and p.iterations == old:
            self.form.set_params(dataclasses.replace(p, iterations=new))

    def _show_filter_defaults(self) -> None:
        """Settings left at 0 mean "the filter's own" (resolution, σ, view width and, where
        the filter has one, learning rate): say which value that is."""
        try:
            spec = get_filter(self.filter_name())
        except Stylize3DError:
            return
        if getattr(self, "filtered_caption", None) is not None:
            self.filtered_caption.setText(spec.shown(self.filter_params()))
        thin = self.form.editors.get("thin_step")
        if thin is not None:
            # PaparazziParams.thin_step acts on a filter with step_follows_edge (l0,
            # neural-style) only
            follows = bool(getattr(spec, "step_follows_edge", False))
            for w in (thin, self.form.labels["thin_step"]):
                w.setEnabled(follows)
        for name, attr in (("resolution", "resolution"), ("sigma", "sigma"),
                           ("view_width", "width"), ("learning_rate", "learning_rate")):
            editor = self.form.editors.get(name)
            value = getattr(spec, attr, None)
            if attr == "learning_rate" and value is not None:
                value = spec.step(self.filter_params())     # may depend on them (neural-style)
            if editor is None or value is None or editor.spin.minimum() != 0:
                continue
            # "auto" as elsewhere in the app (cubic, spectral)
            text = f"auto ({value:g})"
            rough = getattr(spec, "rough_learning_rate", 0.0)
            if name == "learning_rate" and rough and getattr(self.form.params(), "rough_step",
                                                             True):
                # PaparazziParams.rough_step; smaller on a fine mesh (optimize.ROUGH_EDGE)
                text = f"auto ({value:g}; rough up to {rough:g})"
            elif name == "learning_rate" and getattr(spec, "step_follows_edge", False):
                # FilterSpec.step_follows_edge (l0, neural-style): smaller on a mesh finer
                # than ROUGH_EDGE, and at the vertices of thin triangles (Paparazzi.thin_factors,
                # thin_step)
                text = (f"auto ({value:g}; smaller on fine meshes and thin triangles)"
                        if getattr(self.form.params(), "thin_step", True)
                        else f"auto ({value:g}; smaller on fine meshes)")
            editor.spin.setSpecialValueText(text)
            wide = editor.spin.fontMetrics().horizontalAdvance(text + "  ") + 34  # + arrows
            editor.spin.setMinimumWidth(max(editor.spin.minimumWidth(), wide))
            editor.spin.update()

    # -- files (target image, target mesh) -------------------------------------------------------
    def _choose_file(self, field: str) -> None:
        from algorithms.mesh import file_filter

        from app import dialogs

        kind = self._path_kinds.get(field, "file")
        flt = {"image": "Images (*.png *.jpg *.jpeg *.bmp *.tif *.tiff)",
               "mesh": file_filter("read")}.get(
                   kind, "All files (*)")
        path = dialogs.open_file(self, f"Choose the {kind}", flt,
                                 str(self.window_.settings.value("files/last_dir", "") or ""))
        if path:
            self.set_filter_file(field, path)

    def set_filter_file(self, field: str, path: str) -> bool:
        """Use ``path`` for the current filter's file field ``field``, after checking that it
        can be read; a file that cannot be used gives a plain message and changes nothing."""
        from app import dialogs

        name = self.filter_name()
        kind = self._path_kinds.get(field, "file")
        edit = self._path_edits.get(field)
        old = self._paths.get((name, field), "")
        if not str(path).strip() and name and field in get_filter(name).optional_files:
            # an optional file (the neural-style painting) can be cleared again
            self._paths.pop((name, field), None)
            if edit is not None:
                edit.setText("")
                edit.setModified(False)
            label = next((s.label for s in describe(get_filter(name).params)
                          if s.name == field), field)
            self.status_label.setText(f"{label}: none; the '{name}' filter runs without one.")
            self._on_params_changed(None)
            return True
        try:
            note = describe_filter_file(name, field, kind, path)
        except Stylize3DError as e:
            if edit is not None:
                edit.setText(old)
            text = str(e)
            self.status_label.setText(text)
            self.window_.report(f"Cannot use this {kind}: {text}", "error")
            dialogs.error(self.window_, f"Cannot use this {kind}", text)
            return False
        self._paths[(name, field)] = str(path)
        if edit is not None:
            edit.setText(str(path))
            edit.setModified(False)
        self.status_label.setText(f"{Path(path).name}: {note}.")
        self._on_params_changed(None)
        return True

    # -- the run ---------------------------------------------------------------------------------
    def filter_params(self):
        """The current filter's Params (form values and chosen files)."""
        spec = get_filter(self.filter_name())
        p = self.filter_form.params() if self.filter_form is not None else spec.params()
        files = {f: self._paths.get((spec.name, f), "") for f in self._path_edits}
        return dataclasses.replace(p, **files) if files else p

    def job_options(self) -> dict:
        """The recipe's options: ``filter``, ``filter_params`` (its files as blob references)
        and, for a plug-in's filter, ``plugin`` (see :mod:`app.recipes.paparazzi`)."""
        return filter_options(self.filter_name(), self.filter_params())

    def restore_options(self, options: dict) -> None:
        """Choose the saved filter (loading its plug-in from the project when it is not
        registered) and set its form and files from ``options``."""
        from app.recipes import blob_path, is_blob_ref

        name = str(options.get("filter") or "")
        if not name:
            return
        try:
            spec = ensure_filter(name, options.get("plugin"))
        except Stylize3DError as e:
            self.status_label.setText(f"The saved filter {name!r} cannot be used: {e}")
            return
        values = dict(options.get("filter_params") or {})
        files = {f: values.pop(f) for f in list(values)
                 if f in {s.name for s in describe(spec.params)
                          if s.type is str and not s.choices}}
        problems = []
        for f, v in files.items():
            path = ""
            if is_blob_ref(v):
                try:
                    path = str(blob_path(v))
                except Stylize3DError as e:
                    problems.append(str(e))
            elif v:
                path = str(v)
            if path:
                self._paths[(name, f)] = path
            else:
                self._paths.pop((name, f), None)
        try:
            p = params_from_dict(spec.params, values)
        except Stylize3DError as e:
            problems.append(str(e))
            p = spec.params()
        if self.filter_form is not None:  # the shown filter's values, before it is replaced
            self._filter_values[self.filter_form.filter_name] = self.filter_form.params()
        self._filter_values[name] = p
        self.refresh_filters()
        run_params = self.form.params()      # restored already: the filter must not change them
        if self.filter_name() == name:
            self.filter_form = None  # rebuilt from the restored values (not saved over them)
            self._rebuild_filter_form()
        else:
            self.filter_combo.setCurrentText(name)
        if self.form.params() != run_params:
            self.form.set_params(run_params)
        if problems:
            self.status_label.setText(" ".join(problems))

    def job_factory(self, state: MeshState, params: Any):
        self._monitor_every = params.monitor_every
        self._first_monitor = None
        return super().job_factory(state, params)

    def run(self, live: bool = False) -> None:
        doc = self.window_.document
        if doc.state is None:
            self.status_label.setText("Open a mesh first (File > Open).")
            return
        if not self._mesh_is_usable():
            return
        optional = get_filter(self.filter_name()).optional_files
        missing = [s for s in self._path_edits
                   if s not in optional and not self._paths.get((self.filter_name(), s), "")]
        if missing:
            kind = self._path_kinds[missing[0]]
            self.status_label.setText(f"The '{self.filter_name()}' filter needs "
                                      f"{article(kind)}: press Choose… next to it first.")
            return
        super().run(live)
        # what to watch while it runs: the images and the plot
        self.scroll_area.ensureWidgetVisible(self.plot)
        loops = (doc.report.stats.get("boundary_loops") or 0) if doc.report is not None else 0
        if loops:
            self.status_label.setText(
                f"Starting… This mesh has {plural(loops, 'open border')}: "
                f"{'it stays' if loops == 1 else 'they stay'} where {'it is' if loops == 1 else 'they are'}.")

    def _mesh_is_usable(self) -> bool:
        """Paparazzi remeshes as it goes, so it needs a 2-manifold mesh: offer Clean, or say
        plainly why not."""
        from app import dialogs

        doc = self.window_.document
        report = manifold_report(doc.V, doc.F)
        if report is None:
            return True
        need = ("Paparazzi needs a 2-manifold mesh: every edge shared by one or two triangles "
                "and every vertex with a single fan of triangles, because it remeshes the "
                "surface as it goes. This mesh is not.")
        fixable = report.needs_cleaning and all(i.fixable for i in report.errors)
        if fixable:
            choice = dialogs.choose(self.window_, "Paparazzi needs a 2-manifold mesh",
                                    f"{need}\n\n{report.advice}.",
                                    ["Clean, then run", "Cancel"], default="Clean, then run",
                                    details=report.summary())
            if choice == "Clean, then run":
                self.window_.clean_mesh()
                cleaned = self.window_.document
                if manifold_report(cleaned.V, cleaned.F) is None:
                    return True
                need += " Cleaning did not make it one."
            else:
                self.status_label.setText("Not run: " + need)
                return False
        self.status_label.setText("Not run: " + need)
        dialogs.error(self.window_, "Paparazzi needs a 2-manifold mesh",
                      f"{need}\n\n{report.advice or 'Repair the mesh in a mesh editor.'}")
        return False

    # -- streamed results ------------------------------------------------------------------------
    def _on_preview(self, step: Step) -> None:
        super()._on_preview(step)
        if not self._mine():
            return
        image = getattr(step, "image", None)
        filtered = getattr(step, "filtered", None)
        if image is not None:
            self.render_label.setPixmap(QPixmap.fromImage(_image_to_qimage(image)))
        if filtered is not None:
            self.filtered_label.setPixmap(QPixmap.fromImage(_image_to_qimage(filtered)))
        m = step.metrics
        parts = [f"Iteration {step.iteration}/{step.total}" if step.total
                 else f"Iteration {step.iteration}"]
        if "vertices" in m:
            parts.append(f"{int(m['vertices']):,} vertices")
        if m.get("remeshes"):
            parts.append(plural(int(m["remeshes"]), "remesh", "remeshes"))
        if m.get("rollbacks"):
            parts.append(plural(int(m["rollbacks"]), "rollback"))
        if m.get("rough_input"):
            parts.append(f"rough surface: step {m.get('base_learning_rate', 0):g}")
        if m.get("step_halvings"):
            parts.append(plural(int(m["step_halvings"]), "step halving"))
        text = " · ".join(parts)
        if step.message:
            text += f"\n{step.message}"
        self.status_label.setText(text)

    def _on_metrics(self, history) -> None:
        """Plot the monitor energy where it was evaluated (the start, every ``monitor_every``
        iterations, the end), not its repeated value in between."""
        if not self._mine():
            return
        req = getattr(self, "last_request", None)
        values, started = monitor_points(history, self._monitor_every,
                                         None if req is None else req["params"].iterations,
                                         self._first_monitor is not None)
        if started and self._first_monitor is None:
            self._first_monitor = values[0]
        for value in values:
            self.plot.append("monitor_energy", value)

    def _on_finished(self, step: Step) -> None:
        if self.window_.last_job_name != self.title:
            return
        super()._on_finished(step)
        m = step.metrics
        e0, e1 = m.get("initial_monitor_energy"), m.get("monitor_energy")
        extra = []
        if e0 and e1 is not None:
            views = int(m.get("monitor_views") or 1)
            extra.append(f"monitor energy{f' (mean of {views} views)' if views > 1 else ''} "
                         f"{number(e0)} → {number(e1)} ({100 * (e1 - e0) / e0:+.0f} %)")
        F = getattr(step, "F", None)
        if F is not None:
            extra.append(f"{len(step.V):,} vertices, {len(F):,} triangles")
        if m.get("rollbacks"):
            held = int(m.get("held_vertices") or 0)
            back = int(m.get("put_back_vertices") or 0)
            notes = ([f"{plural(back, 'corner')} of crossing triangles put back"] if back
                     else []) + ([f"{plural(held, 'vertex', 'vertices')} near the crossings "
                                  f"held still"] if held else [])
            # (a check puts back only what crosses, not the whole run: "rollbacks" read as if
            # the run had been undone that many times)
            extra.append(plural(int(m["rollbacks"]), "check") + " found the surface crossing "
                         "itself" + (f" ({'; '.join(notes)})" if notes else ""))
        if m.get("rough_input"):
            extra.append(f"rough surface: the filter's larger step "
                         f"({m.get('base_learning_rate', 0):g}) was used")
        if m.get("step_halvings"):
            extra.append(f"the energy climbed again, so the step was halved "
                         f"{plural(int(m['step_halvings']), 'time')}")
        kept = int(m.get("kept_iteration") or step.iteration)
        if kept < step.iteration:       # PaparazziParams.lowest_fallback
            extra.append(f"the result is the shape of iteration {kept}, whose energy was the "
                         f"lowest (the last one's: {number(m.get('last_monitor_energy', 0))})")
        if extra:
            self.status_label.setText(self.status_label.text() + "\n" + "; ".join(extra) + ".")
