"""A parameter form generated from a Params dataclass (label, range, step, tooltip from metadata).

Numbers get a spin box plus a slider (logarithmic where the field says so) for immediate feedback;
booleans a check box; strings with choices a drop-down. Fields marked ``advanced`` go into a
folded "Advanced" section (one line of text while folded), panels may fold other rarely used
fields into sections of their own (``groups``) and grey out fields that need a switch
(``enable_when``); a field declared with ``param(..., enabled_when=(other, value))`` is greyed
out while the other field has another value. ``changed`` fires on every edit with the new Params instance;
``params()`` returns the current one; ``set_params`` loads one.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from PySide6.QtCore import QEvent, QObject, Qt, Signal
from PySide6.QtGui import QKeySequence, QValidator
from PySide6.QtWidgets import (QAbstractSpinBox, QCheckBox, QComboBox, QDoubleSpinBox, QFormLayout,
                               QHBoxLayout, QLabel, QSlider, QSpinBox, QVBoxLayout,
                               QWidget)

from algorithms.params import ParamSpec, describe
from app.widgets import CollapsibleSection

SLIDER_STEPS = 1000

#: thesis terms that appear in the GUI, in plain words: every form field whose label, tooltip or
#: choices use one gets the explanation appended to its tooltip (drop-down items get their own)
GLOSSARY: dict[str, str] = {
    "ADMM": "ADMM: the small per-vertex solver inside each cubic step (it alternates between "
            "two easier problems until they agree).",
    "ρ₀": "ρ₀ (rho): how hard ADMM pushes its two halves to agree at the start; it adapts itself.",
    "μ": "μ (mu): ADMM changes ρ when one of its two errors is μ times the other.",
    "τ": "τ (tau): the factor ADMM multiplies or divides ρ by.",
    "ε_abs": "ε_abs / ε_rel: how small ADMM's errors must get before it stops (absolute / "
             "relative).",
    "V-cycle": "V-cycle: one multigrid pass, from the fine mesh down through coarser copies and "
               "back up, fixing errors of every size.",
    "multigrid": "Multigrid: solves on a stack of ever coarser copies of the mesh; fast for big "
                 "meshes, and reusable when a parameter changes.",
    "dirichlet": "Dirichlet: penalizes how steep the signal is (its gradient); the plainest "
                 "smoothing.",
    "bilaplacian": "Bilaplacian: penalizes how curved the signal is; smoother, rounder results.",
    "hessian": "Hessian: like bilaplacian, but does not pull values at open borders towards "
               "flat.",
    "arap": "ARAP (as-rigid-as-possible): each small piece may rotate but not stretch; keeps "
            "details.",
    "farap": "FARAP (face ARAP): ARAP per triangle; allows sharp creases between triangles.",
    "acap": "ACAP (as-conformal-as-possible): pieces may also grow or shrink, angles are kept.",
    "cmcf": "cMCF (conformalized mean curvature flow): rounds the shape without pinching thin "
            "parts.",
    "mcf": "MCF (mean curvature flow): moves the surface along its curvature; can pinch thin "
           "parts.",
    "laplacian": "Laplacian smoothing: each vertex moves towards the average of its neighbours.",
    "NADAM": "NADAM: a gradient-descent optimizer with momentum (as used to train neural "
             "networks).",
    "Lloyd": "Lloyd iterations: alternately assign every vertex to its nearest centre and move "
             "each centre to the middle of its group.",
    "k-medoids": "k-medoids: grouping vertices into clusters around chosen centre vertices.",
    "Tikhonov": "Tikhonov weight: a small pull towards the simplest answer where the data alone "
                "do not decide.",
    "qslim": "QSlim: simplification that removes the edges whose removal changes the shape least.",
    "midpoint": "Midpoint: simplification that collapses the shortest edges to their middles.",
    "PolyCube": "PolyCube: a shape made only of axis-aligned flat faces.",
    "developable": "Developable: can be bent from a flat sheet of paper without stretching.",
    "gram": "Gram (style) energy: compares which of a network's feature detectors fire together "
            "across a picture (its texture, wherever it is) with the style's.",
}


def glossary_for(*texts: str) -> list[str]:
    """The plain-words explanations of the glossary terms found in ``texts`` (each once)."""
    import re

    blob = " ".join(t for t in texts if t)
    out = []
    for term, plain in GLOSSARY.items():
        pattern = (re.escape(term) if not term.isascii() or not term.isalnum()
                   else r"(?<![A-Za-z])" + re.escape(term) + r"(?![A-Za-z])")
        if re.search(pattern, blob, flags=0 if not term.islower() else re.IGNORECASE):
            out.append(plain)
    return out


class _DocumentUndoKeys(QObject):
    """Ctrl+Z / Ctrl+Y / Ctrl+Shift+Z while the cursor is in a form's number field: the field's
    own text editor would take the keys (and do nothing visible once the value was entered);
    they undo / redo the document (the window's Undo / Redo actions) instead, unless the field
    holds text being typed. Installed on each form's spin boxes only (an application-wide
    Python event filter would see every event of the app)."""

    def eventFilter(self, obj, event) -> bool:  # noqa: N802 - Qt override
        if event.type() != QEvent.Type.ShortcutOverride:
            return False
        spin = obj if isinstance(obj, QAbstractSpinBox) else obj.parent()
        if not isinstance(spin, QAbstractSpinBox):
            return False
        actions = getattr(spin.window(), "actions_by_name", None)
        if not actions or "undo" not in actions or "redo" not in actions:
            return False
        keys = QKeySequence(event.keyCombination())
        wanted = [*actions["undo"].shortcuts(), *actions["redo"].shortcuts()]
        if not any(keys.matches(k) == QKeySequence.SequenceMatch.ExactMatch for k in wanted):
            return False
        value = getattr(spin, "value", None)
        if callable(value) and hasattr(spin, "textFromValue") and \
                spin.cleanText() != spin.textFromValue(value()):
            return False  # an edit in progress: the field undoes its own typing
        event.ignore()  # not for the field: the window's shortcut gets the keys
        return True


_undo_keys: _DocumentUndoKeys | None = None


def document_undo_keys() -> _DocumentUndoKeys:
    """The one filter object (see :class:`_DocumentUndoKeys`)."""
    global _undo_keys
    if _undo_keys is None:
        _undo_keys = _DocumentUndoKeys()
    return _undo_keys


class _ScientificSpinBox(QDoubleSpinBox):
    """A float spin box that shows and accepts numbers like 1e-06 or 0.0025 (4 significant
    digits), for log-scale parameters spanning many decades."""

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.setDecimals(323)  # no rounding of small values by the spin box itself

    def textFromValue(self, value: float) -> str:  # noqa: N802 (Qt API)
        return f"{value:.4g}"

    def valueFromText(self, text: str) -> float:  # noqa: N802 (Qt API)
        try:
            return float(text.strip())
        except ValueError:
            return self.value()

    def validate(self, text: str, pos: int):  # noqa: A003 (Qt API)
        t = text.strip()
        try:
            v = float(t)
        except ValueError:
            ok = t == "" or all(c in "0123456789.eE+-" for c in t)
            return (QValidator.State.Intermediate if ok else QValidator.State.Invalid), text, pos
        if self.minimum() <= v <= self.maximum():
            return QValidator.State.Acceptable, text, pos
        return QValidator.State.Intermediate, text, pos


class _NumberEditor(QWidget):
    """Spin box + slider kept in sync."""

    valueChanged = Signal()

    def __init__(self, spec: ParamSpec, parent: QWidget | None = None):
        super().__init__(parent)
        self.spec = spec
        lay = QHBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        if spec.type is int:
            self.spin = QSpinBox()
            self.spin.setRange(int(spec.minimum if spec.minimum is not None else -10**9),
                               int(spec.maximum if spec.maximum is not None else 10**9))
            self.spin.setSingleStep(int(spec.step or 1))
        elif (spec.log_scale and spec.maximum is not None and spec.minimum is not None
              and spec.maximum >= 1e4 * (spec.minimum if spec.minimum > 0
                                         else (spec.step or 1e-3))):
            self.spin = _ScientificSpinBox()  # many decades: 1e-06 reads better than 0.000001
            self.spin.setRange(spec.minimum, spec.maximum)
            self.spin.setStepType(QAbstractSpinBox.StepType.AdaptiveDecimalStepType)
        else:
            self.spin = QDoubleSpinBox()
            self.spin.setDecimals(spec.decimals if spec.decimals is not None else 4)
            self.spin.setRange(spec.minimum if spec.minimum is not None else -1e12,
                               spec.maximum if spec.maximum is not None else 1e12)
            if spec.log_scale:
                self.spin.setStepType(QAbstractSpinBox.StepType.AdaptiveDecimalStepType)
            else:
                self.spin.setSingleStep(spec.step or 0.1)
        self.spin.setKeyboardTracking(False)
        self.spin.setMinimumWidth(90)
        self.spin.installEventFilter(document_undo_keys())  # Ctrl+Z undoes the document
        self.slider = None
        if spec.minimum is not None and spec.maximum is not None:
            self.slider = QSlider(Qt.Orientation.Horizontal)
            self.slider.setRange(0, SLIDER_STEPS)
            self.slider.setMinimumWidth(80)
            lay.addWidget(self.slider, 1)
            self.slider.valueChanged.connect(self._from_slider)
        lay.addWidget(self.spin)
        self.spin.valueChanged.connect(self._from_spin)
        self._sync = False

    # slider position <-> value (log-scale when asked and the range is positive)
    def _slider_bounds(self) -> tuple[float, float]:
        """What the slider spans: the parameter's slider_range (its useful values), else its
        whole allowed range."""
        if self.spec.slider_range:
            return self.spec.slider_range
        return self.spec.minimum, self.spec.maximum

    def _log_range(self) -> tuple[float, float] | None:
        """(low, high) of a logarithmic slider; a range starting at 0 starts the log scale at one
        step (or 1e-3) and keeps position 0 for the value 0."""
        lo, hi = self._slider_bounds()
        if not self.spec.log_scale or hi <= 0:
            return None
        if lo > 0:
            return lo, hi
        return min(self.spec.step or 1e-3, hi / 10.0), hi

    def _to_pos(self, v: float) -> int:
        lo, hi = self._slider_bounds()
        lr = self._log_range()
        if lr is not None:
            a, b = lr
            if v <= lo or v <= 0:
                return 0
            t = (math.log(max(v, a)) - math.log(a)) / (math.log(b) - math.log(a))
            if lo < a:  # position 0 is the value 0: the log scale starts at position 1
                t = (1 + t * (SLIDER_STEPS - 1)) / SLIDER_STEPS
        else:
            t = (v - lo) / (hi - lo) if hi > lo else 0.0
        return int(round(min(max(t, 0.0), 1.0) * SLIDER_STEPS))

    def _from_pos(self, pos: int) -> float:
        lo, hi = self._slider_bounds()
        t = pos / SLIDER_STEPS
        lr = self._log_range()
        if lr is not None:
            a, b = lr
            if lo < a:
                if pos == 0:
                    return float(lo)
                t = (pos - 1) / (SLIDER_STEPS - 1)
            v = math.exp(math.log(a) + t * (math.log(b) - math.log(a)))
            digits = max(0, -int(math.floor(math.log10(v))) + 1)  # two significant digits
            return round(v, digits)
        v = lo + t * (hi - lo)
        if self.spec.step:
            v = lo + round((v - lo) / self.spec.step) * self.spec.step
        return v

    def _from_slider(self, pos: int) -> None:
        if self._sync:
            return
        v = self._from_pos(pos)
        self._sync = True
        self.spin.setValue(int(round(v)) if self.spec.type is int else v)
        self._sync = False
        self.valueChanged.emit()

    def _from_spin(self, _v) -> None:
        if self.slider is not None and not self._sync:
            self._sync = True
            self.slider.setValue(self._to_pos(self.spin.value()))
            self._sync = False
        if not self._sync:
            self.valueChanged.emit()

    def value(self):
        return int(self.spin.value()) if self.spec.type is int else float(self.spin.value())

    def setValue(self, v) -> None:  # noqa: N802
        self._sync = True
        self.spin.setValue(v)
        if self.slider is not None:
            self.slider.setValue(self._to_pos(float(v)))
        self._sync = False


class ParamsForm(QWidget):
    """See the module docstring. ``editors[name]`` is the widget of each field (tests use it)."""

    changed = Signal(object)

    def __init__(self, params_cls: type, parent: QWidget | None = None, values: Any = None,
                 exclude: tuple[str, ...] = (),
                 groups: dict[str, tuple[str, ...]] | None = None,
                 enable_when: dict[str, str] | None = None,
                 auto_text: dict[str, Any] | None = None):
        """``groups``: title -> field names shown in a folded section of their own (rarely used
        fields); fields marked ``advanced`` fold into "Advanced". ``enable_when``: field ->
        the bool field that must be on for it to be editable (e.g. x/y/z factors need
        "Per-axis λ"). ``auto_text``: field -> ``f(params) -> str``, what the field's minimum
        means, shown instead of the number (e.g. "auto (167)" for "0 = round(m/3)")."""
        super().__init__(parent)
        self.params_cls = params_cls
        self.specs = [s for s in describe(params_cls) if s.name not in exclude]
        self._excluded = {s.name: s.default for s in describe(params_cls) if s.name in exclude}
        self.editors: dict[str, QWidget] = {}
        self.labels: dict[str, QLabel] = {}
        outer = QVBoxLayout(self)
        outer.setContentsMargins(0, 0, 0, 0)
        main = QFormLayout()
        outer.addLayout(main)
        in_group = {n: title for title, names in (groups or {}).items() for n in names}
        self.sections: dict[str, CollapsibleSection] = {}
        forms: dict[str, QFormLayout] = {}
        for title in list(groups or {}) + ["Advanced"]:
            names = [sp.name for sp in self.specs
                     if (in_group.get(sp.name) == title if title != "Advanced"
                         else sp.advanced and sp.name not in in_group)]
            if not names:
                continue
            sec = CollapsibleSection(f"{title} ({len(names)})")
            forms[title] = QFormLayout(sec.body)
            forms[title].setContentsMargins(12, 0, 0, 0)
            outer.addWidget(sec)
            self.sections[title] = sec
        self.advanced_box = self.sections.get("Advanced") or CollapsibleSection("Advanced")
        self.advanced_box.setToolTip("Settings most users never need to change.")
        for spec in self.specs:
            title = in_group.get(spec.name) or ("Advanced" if spec.advanced else None)
            form = forms.get(title, main)
            if spec.type is bool:
                w = QCheckBox()
                w.toggled.connect(self._emit)
            elif spec.type is str:
                w = QComboBox()
                w.addItems(list(spec.choices or [spec.default]))
                w.currentTextChanged.connect(self._emit)
            else:
                w = _NumberEditor(spec)
                w.valueChanged.connect(self._emit)
            tip = spec.tooltip
            if spec.minimum is not None and spec.maximum is not None:
                tip += f"\nRange {spec.minimum:g} to {spec.maximum:g}; default {spec.default}."
            plain = glossary_for(spec.label, spec.tooltip, *(spec.choices or ()))
            if plain:
                tip += "\n\nIn plain words:\n" + "\n".join(f"• {t}" for t in plain)
            if spec.type is str:
                for i, choice in enumerate(spec.choices or ()):
                    item_tip = glossary_for(choice)
                    if item_tip:
                        w.setItemData(i, item_tip[0], Qt.ItemDataRole.ToolTipRole)
            w.setToolTip(tip)
            label = QLabel(spec.label)
            label.setToolTip(tip)
            form.addRow(label, w)
            self.editors[spec.name] = w
            self.labels[spec.name] = label
        self._enable_when = {k: v for k, v in (enable_when or {}).items() if k in self.editors}
        for controller in set(self._enable_when.values()):
            self.editors[controller].toggled.connect(lambda _on: self._update_enabled())
        # a field's own ``enabled_when`` (algorithms.params.param): (other field, value)
        self._enable_if = {s.name: s.enabled_when for s in self.specs
                           if s.enabled_when and s.enabled_when[0] in self.editors}
        for controller in {c for c, _ in self._enable_if.values()}:
            w = self.editors[controller]
            signal = w.toggled if isinstance(w, QCheckBox) else (
                w.currentTextChanged if isinstance(w, QComboBox) else w.valueChanged)
            signal.connect(lambda *_: self._update_enabled())
        self._auto_text = {k: f for k, f in (auto_text or {}).items() if k in self.editors}
        self._loading = False
        self.set_params(values if values is not None else params_cls())
        self._update_enabled()
        self._update_auto_text()

    def _update_auto_text(self) -> None:
        if not self._auto_text:
            return
        p = self.params()
        for name, f in self._auto_text.items():
            spin = self.editors[name].spin
            spin.setSpecialValueText(str(f(p)))
            spin.update()

    def _update_enabled(self) -> None:
        for name, controller in self._enable_when.items():
            on = self.editors[controller].isChecked()
            self.editors[name].setEnabled(on)
            self.labels[name].setEnabled(on)
        if self._enable_if:
            p = self.params()
            for name, (controller, value) in self._enable_if.items():
                on = getattr(p, controller) == value
                self.editors[name].setEnabled(on)
                self.labels[name].setEnabled(on)

    def _emit(self, *_):
        self._update_auto_text()
        if not self._loading:
            self.changed.emit(self.params())

    def params(self) -> Any:
        values = dict(self._excluded)
        for spec in self.specs:
            w = self.editors[spec.name]
            if spec.type is bool:
                values[spec.name] = w.isChecked()
            elif spec.type is str:
                values[spec.name] = w.currentText()
            else:
                values[spec.name] = w.value()
        return self.params_cls(**values)

    def set_params(self, params: Any) -> None:
        self._loading = True
        try:
            for spec in self.specs:
                v = getattr(params, spec.name)
                w = self.editors[spec.name]
                if spec.type is bool:
                    w.setChecked(bool(v))
                elif spec.type is str:
                    w.setCurrentText(str(v))
                else:
                    w.setValue(v)
        finally:
            self._loading = False

    def set_value(self, name: str, value) -> None:
        """Set one field as if the user had edited it (emits ``changed``)."""
        spec = next(s for s in self.specs if s.name == name)
        w = self.editors[name]
        if spec.type is bool:
            w.setChecked(bool(value))
        elif spec.type is str:
            w.setCurrentText(str(value))
        else:
            w.spin.setValue(value)

    def reset_defaults(self) -> None:
        self.set_params(self.params_cls())
        self.changed.emit(self.params())
