"""Panel "Cubic": cubic (and polyhedral) stylization with every artistic control (thesis ch. 5).

* the Params form (λ slider; style; per-axis λ; cube orientation; tolerances; Advanced);
* Live (on by default): every parameter change restarts the solve from the document after a
  short pause; the precomputation (normalization, ARAP factorizations) is cached and reused
  while only λ, the style or the orientation change;
* viewport tools, one undoable step per stroke: a λ brush (paints a per-vertex λ *scale* in
  [0, 2], 1 = the slider's λ), a Gauss-map painter (the same field, painted by normal
  direction), a fix brush (painted region stays put), point handles (click, drag; Ctrl+click
  removes), and a plane brush (the painted region keeps its mean coordinate along an axis);
* a frame brush: the painted region gets the current cube orientation as its own local cube
  frame (thesis §5.4: per-region n_i^local); elsewhere the global orientation applies;
* "Progressive meshes" (thesis Alg. 4) for big meshes: stylize a decimated copy with m triangles,
  put the details back with fitted affine maps, then (*Finish on every triangle*, on by
  default) go on stylizing every triangle from there; switched on by itself for meshes above
  ``AUTO_PROGRESSIVE_FACES`` triangles. Without the finish it is the quick λ preview. The
  decimation and both factorizations are cached like the rest;
* the finished run is one undoable command (the pattern of :mod:`app.panels.base`).
"""

from __future__ import annotations

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import (QButtonGroup, QCheckBox, QComboBox, QDoubleSpinBox, QFormLayout,
                               QGroupBox, QHBoxLayout, QLabel, QPushButton, QRadioButton,
                               QVBoxLayout)

from algorithms.deform.cubic import CubicParams
from algorithms.deform.progressive import AUTO_PROGRESSIVE_FACES, ProgressiveParams
from app.forms import ParamsForm
from app.commands import StateCommand
from app.gaussmap import GaussMapPainter
from app.panels.base import MethodPanel
from app.widgets import CollapsibleSection
from app.tools import BrushSettings, FieldBrush, HandleTool, StampBrush

# the painted fields and the run itself are the Qt-free recipe's (app/recipes/cubic.py)
from app.recipes import FIXED_FIELD, FRAME_FIELDS, LAMBDA_FIELD, PLANE_FIELD  # noqa: E402,F401


class CubicPanel(MethodPanel):
    title = "Cubic"
    description = ("Makes the shape look cubic while keeping its details (cubic stylization). "
                   "Move the λ slider: the result updates live. Paint where it should be more or "
                   "less cubic, pin regions, or drag handles with the tools below.")
    params_cls = CubicParams
    plot_metrics = ("energy",)
    plot_title = "Energy (ARAP + λ·L1) per iteration"
    live_by_default = True
    run_from_base = True  # Run and the λ slider start from one base shape
    builtin_presets = {"subtle": {"lam": 0.1}, "strong": {"lam": 0.6}}
    param_groups = {"Per-axis λ": ("per_axis", "axis_factor_x", "axis_factor_y", "axis_factor_z"),
                    "Cube orientation": ("rot_x", "rot_y", "rot_z")}
    param_enable_when = {f"axis_factor_{a}": "per_axis" for a in "xyz"}

    def __init__(self, window):
        super().__init__(window)
        self.brush_settings = BrushSettings(radius=0.06, strength=0.5)
        self.lambda_brush = FieldBrush(window, LAMBDA_FIELD, low=0.0, high=2.0, default=1.0,
                                       label="λ", settings=self.brush_settings, cmap="coolwarm")
        self.fix_brush = FieldBrush(window, FIXED_FIELD, low=0.0, high=1.0, default=0.0,
                                    label="fixed region", settings=self.brush_settings,
                                    cmap="Reds")
        self.plane_brush = FieldBrush(window, PLANE_FIELD, low=0.0, high=1.0, default=0.0,
                                      label="plane region", settings=self.brush_settings,
                                      cmap="Greens")
        self.handle_tool = HandleTool(window)
        self.frame_brush = StampBrush(
            window, FRAME_FIELDS, lambda: self._frame_angles, label="cube frame",
            settings=self.brush_settings)
        self._build_tools()
        window.document.subscribe(self._on_doc)

    # -- widgets -------------------------------------------------------------------------------
    def _build_tools(self) -> None:
        lay: QVBoxLayout = self.body_layout
        box = QGroupBox("Tools")
        v = QVBoxLayout(box)
        self.tool_group = QButtonGroup(self)
        row1, row2 = QHBoxLayout(), QHBoxLayout()
        specs = [("camera", "Camera", "Left drag rotates the view (no painting)."),
                 ("lambda", "λ brush", "Paint where the shape should be more cubic (drag) or "
                  "less cubic (tick 'Erase'). Red = more, blue = less."),
                 ("fix", "Fix", "Paint a region that must not move."),
                 ("handle", "Handles", "Click the surface to add a handle, drag to move it; "
                  "Ctrl+click removes the nearest handle."),
                 ("plane", "Plane", "Paint a region that keeps its average coordinate along the "
                  "chosen axis (it becomes flat in that direction)."),
                 ("frame", "Frame", "Paint a region that gets its own cube orientation: the "
                  "three 'Cube orientation' angles set now. 'Erase' gives it back the global "
                  "orientation.")]
        self.tool_buttons = {}
        for i, (key, text, tip) in enumerate(specs):
            b = QRadioButton(text)
            b.setToolTip(tip)
            self.tool_group.addButton(b, i)
            self.tool_buttons[key] = b
            (row1 if i < 3 else row2).addWidget(b)  # 3 + 3 buttons
            b.toggled.connect(lambda on, key=key: on and self.set_tool(key))
        v.addLayout(row1)
        v.addLayout(row2)
        form = QFormLayout()
        self.radius_spin = QDoubleSpinBox()
        self.radius_spin.setRange(0.005, 0.5)
        self.radius_spin.setSingleStep(0.01)
        self.radius_spin.setDecimals(3)
        self.radius_spin.setValue(self.brush_settings.radius)
        self.radius_spin.setToolTip("Brush radius as a fraction of the model size (on the Gauss "
                                    "map: of 180°).")
        self.radius_spin.valueChanged.connect(lambda x: setattr(self.brush_settings, "radius", x))
        self.strength_spin = QDoubleSpinBox()
        self.strength_spin.setRange(0.01, 1.0)
        self.strength_spin.setSingleStep(0.05)
        self.strength_spin.setValue(self.brush_settings.strength)
        self.strength_spin.setToolTip("How much one dab changes the painted value (1 = fully).")
        self.strength_spin.valueChanged.connect(
            lambda x: setattr(self.brush_settings, "strength", x))
        self.erase_box = QCheckBox("Erase")
        self.erase_box.setToolTip("Paint towards 'less' (λ brush: less cubic; Fix/Plane: remove).")
        self.erase_box.toggled.connect(lambda on: setattr(self.brush_settings, "erase", on))
        self.plane_axis = QComboBox()
        self.plane_axis.addItems(["x", "y", "z"])
        self.plane_axis.setToolTip("The coordinate the plane region keeps (its current mean).")
        form.addRow("Radius", self.radius_spin)
        form.addRow("Strength", self.strength_spin)
        form.addRow(self.erase_box)
        form.addRow("Plane axis", self.plane_axis)
        v.addLayout(form)
        row = QHBoxLayout()
        self.show_combo = QComboBox()
        self.show_combo.addItems(["Shape only", "λ scale", "Fixed region", "Plane region",
                                  "Local frames"])
        self.show_combo.setToolTip("Colour the mesh by a painted field.")
        self.show_combo.currentIndexChanged.connect(self._show_field)
        self.clear_button = QPushButton("Clear painting")
        self.clear_button.setToolTip("Remove painted λ, fixed and plane regions and all handles "
                                     "(undoable).")
        self.clear_button.clicked.connect(self.clear_constraints)
        row.addWidget(QLabel("Show"))
        row.addWidget(self.show_combo, 1)
        row.addWidget(self.clear_button)
        v.addLayout(row)
        self.gauss = GaussMapPainter(self.window_, LAMBDA_FIELD, low=0.0, high=2.0, default=1.0,
                                     label="λ", settings=self.brush_settings)
        self.gauss.setMinimumHeight(220)
        v.addWidget(self.gauss)
        # right under the parameters: the painting tools are what the description points to,
        # and must be in sight at 1024×700 without scrolling past big-mesh options
        self.tools_box = box
        lay.insertWidget(lay.indexOf(self.form) + 1, box)
        self.big_section = CollapsibleSection("Big meshes (progressive, multigrid)")
        self.big_section.setToolTip("Two ways to stylize meshes of hundreds of thousands of "
                                    "triangles quickly; progressive meshes turn on by themselves "
                                    "for very big meshes.")
        big_lay = QVBoxLayout(self.big_section.body)
        big_lay.setContentsMargins(12, 0, 0, 0)
        self.progressive_box = QGroupBox("Progressive meshes (for big meshes)")
        self.progressive_box.setCheckable(True)
        self.progressive_box.setChecked(False)
        self.progressive_box.setToolTip(
            "Stylize a simplified copy, put the details back (thesis Alg. 4), then finish on "
            "every triangle from there: on big meshes this gets closer to the cubic shape you "
            "asked for than working on every triangle from the start, in a fraction of the "
            "iterations. Untick 'Finish on every triangle' to try λ values quickly (about a "
            "second each after a one-time preparation); the copy alone comes out less cubic "
            "on scans.")
        pl = QVBoxLayout(self.progressive_box)
        self.progressive_form = ParamsForm(ProgressiveParams)
        pl.addWidget(self.progressive_form)
        self.progressive_box.toggled.connect(lambda _on: self._on_params_changed(None))
        self.progressive_form.changed.connect(self._on_params_changed)
        big_lay.addWidget(self.progressive_box)
        self.multigrid_box = QCheckBox("Multigrid global step (full resolution, big meshes)")
        self.multigrid_box.setToolTip(
            "Solve each global step with surface multigrid V-cycles instead of a sparse "
            "factorization (thesis ch. 8): the full-resolution mesh is stylized, with less memory "
            "and no factorization. Builds a hierarchy once per mesh. Not combined with "
            "progressive meshes.")
        self.multigrid_box.toggled.connect(self._on_multigrid_toggled)
        self.progressive_box.toggled.connect(
            lambda on: on and self.multigrid_box.setChecked(False))
        big_lay.addWidget(self.multigrid_box)
        # folded below the tools (rarely needed); it opens itself when either is on (a big mesh
        # opened, a project restored)
        for w in (self.progressive_box, self.multigrid_box):
            w.toggled.connect(lambda on: on and self.big_section.setChecked(True))
        lay.insertWidget(lay.indexOf(self.tools_box) + 1, self.big_section)
        self.tool_buttons["camera"].setChecked(True)
        self.plane_axis.currentIndexChanged.connect(lambda _i: self._on_params_changed(None))
        self._frame_angles = (0.0, 0.0, 0.0)
        self.form.changed.connect(lambda p: setattr(self, "_frame_angles",
                                                    (p.rot_x, p.rot_y, p.rot_z)))
        self.gauss.brush.changed.connect(lambda _v: self.show_combo.setCurrentIndex(1))

    def set_tool(self, key: str) -> None:
        p = self.form.params()
        self._frame_angles = (p.rot_x, p.rot_y, p.rot_z)
        tool = {"camera": None, "lambda": self.lambda_brush, "fix": self.fix_brush,
                "handle": self.handle_tool, "plane": self.plane_brush,
                "frame": self.frame_brush}[key]
        self.window_.viewport.set_handler(tool)
        show = {"lambda": 1, "fix": 2, "plane": 3, "frame": 4}.get(key)
        if show is not None:
            self.show_combo.setCurrentIndex(show)
        if not self.tool_buttons[key].isChecked():
            self.tool_buttons[key].setChecked(True)

    def _show_field(self, index: int) -> None:
        brush = {1: self.lambda_brush, 2: self.fix_brush, 3: self.plane_brush}.get(index)
        if index == 4:
            if not self.window_.document.is_empty:
                self.window_.viewport.show_field("frame_mask",
                                                 self.frame_brush.mask().astype(float),
                                                 "Purples", (0.0, 1.0))
        elif brush is None:
            self.window_.viewport.show_field(None)
        else:
            brush.show()

    def parts_warning(self) -> str:
        """A warning when the mesh is made of separate parts that touch (issue 41: a 62-part
        CAD truck fell apart: doors, hood and windows each moved on their own), else ""."""
        st = self.window_.document.state
        if st is None:
            return ""
        if getattr(self, "_parts_of", (None,))[0] is not st.F:
            from app.recipes.cubic import touching_parts_of

            self._parts_of = (st.F, touching_parts_of(st))
        parts, touching = self._parts_of[1]
        if not touching:
            return ""
        return (f"This model is made of {parts:,} separate parts, {touching:,} of them touching "
                "another: Cubic moves each part on its own, so touching parts can come apart "
                "(gaps, floating pieces). Parts that share vertices stay together: weld them "
                "first if your modeller can, or stylize one part at a time.")

    def _on_doc(self, what: str) -> None:
        if what in ("mesh", "topology"):
            warning = self.parts_warning()
            if warning:
                self.status_label.setText(warning)
        if what == "mesh":
            st = self.window_.document.state
            big = st is not None and len(st.F) > AUTO_PROGRESSIVE_FACES
            self.progressive_box.setChecked(big)
            if big:
                from app.recipes.cubic import big_mesh_note

                self.status_label.setText(big_mesh_note(len(st.F)) + " "
                                          + self.parts_warning())
        if what == "fields" and self.is_shown():
            self._show_field(self.show_combo.currentIndex())
        elif what in ("mesh", "topology"):
            # the window puts the new mesh on the 3D view after this listener: colour it then
            QTimer.singleShot(0, self._refresh_if_shown)
        if what in ("handles", "mesh", "topology"):
            st = self.window_.document.state
            self.window_.viewport.show_handles(st.handle_dict if st is not None else None)
        # painting re-runs a live result (only this panel's fields, only once it has a result)
        st = self.window_.document.state
        key = None if st is None else (tuple(id(st.fields.get(f)) for f in
                                             (LAMBDA_FIELD, FIXED_FIELD, PLANE_FIELD)
                                             + FRAME_FIELDS), st.handles)
        changed, self._constraint_key = key != getattr(self, "_constraint_key", None), key
        if (what in ("fields", "handles") and changed and self.live_box.isChecked()
                and self._last is not None and st is not None and st.V is self._last[1].V):
            self._debounce.start()

    def _on_finished(self, step) -> None:
        super()._on_finished(step)
        if self.window_.last_job_name == self.title:
            from app.recipes.cubic import change_note

            request = self.last_request or {}
            start = request.get("input")
            if start is not None and step.V is not None:   # the last step: what was committed
                note = change_note(start.V, step.V, start.F, request["params"].lam)
                if note:
                    self.status_label.setText(f"{self.status_label.text()} {note}")
        warning = self.parts_warning() if self.window_.last_job_name == self.title else ""
        if warning:
            parts = self._parts_of[1][0]
            self.status_label.setText(f"{self.status_label.text()} The {parts:,} separate parts "
                                      "were stylized each on its own; look for gaps where "
                                      "they touched.")

    def refresh_view(self) -> None:
        self._show_field(self.show_combo.currentIndex())
        self.gauss.refresh_if_stale()

    def clear_constraints(self) -> None:
        doc = self.window_.document
        if doc.is_empty:
            return
        st = doc.state
        after = st
        for f in (LAMBDA_FIELD, FIXED_FIELD, PLANE_FIELD) + FRAME_FIELDS:
            after = after.with_field(f, None)
        after = after.with_handles({})
        if after.fields != st.fields or after.handles != st.handles:
            cmd = StateCommand(doc, st, after, "Clear painting")
            cmd.log_details = {"tool": "clear", "clear_handles": True,
                               "names": [LAMBDA_FIELD, FIXED_FIELD, PLANE_FIELD, *FRAME_FIELDS]}
            self.window_.undo_stack.push(cmd)

    def _on_multigrid_toggled(self, on: bool) -> None:
        if on and self.progressive_box.isChecked():
            self.progressive_box.setChecked(False)
        self._on_params_changed(None)

    # -- the method ------------------------------------------------------------------------------
    def job_options(self) -> dict:
        """Plane axis, progressive meshes and the multigrid switch (read on the GUI thread)."""
        prog = (self.progressive_form.params() if self.progressive_box.isChecked() else None)
        from algorithms.params import params_to_dict

        return {"plane_axis": self.plane_axis.currentIndex(),
                "progressive": None if prog is None else params_to_dict(prog),
                "multigrid": self.multigrid_box.isChecked() and prog is None}

    def restore_options(self, options: dict) -> None:
        from algorithms.params import params_from_dict

        self.plane_axis.setCurrentIndex(int(options.get("plane_axis", 0)))
        prog = options.get("progressive")
        self.progressive_box.setChecked(prog is not None)
        if prog is not None:
            # options saved before "finish" existed ran the copy alone
            self.progressive_form.set_params(params_from_dict(ProgressiveParams,
                                                              {"finish": False, **prog}))
        self.multigrid_box.setChecked(bool(options.get("multigrid", False)) and prog is None)
