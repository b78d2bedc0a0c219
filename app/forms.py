"""A parameter form generated from a Params dataclass (label, range, step, tooltip from metadata).

Numbers get a spin box plus a slider (logarithmic where the field says so) for immediate feedback;
booleans a check box; strings with choices a drop-down. Fields marked ``advanced`` go into a
collapsed "Advanced" group. ``changed`` fires on every edit with the new Params instance;
``params()`` returns the current one; ``set_params`` loads one.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QValidator
from PySide6.QtWidgets import (QAbstractSpinBox, QCheckBox, QComboBox, QDoubleSpinBox, QFormLayout,
                               QGroupBox, QHBoxLayout, QLabel, QSlider, QSpinBox, QVBoxLayout,
                               QWidget)

from algorithms.params import ParamSpec, describe

SLIDER_STEPS = 1000


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
    def _log_range(self) -> tuple[float, float] | None:
        """(low, high) of a logarithmic slider; a range starting at 0 starts the log scale at one
        step (or 1e-3) and keeps position 0 for the value 0."""
        lo, hi = self.spec.minimum, self.spec.maximum
        if not self.spec.log_scale or hi <= 0:
            return None
        if lo > 0:
            return lo, hi
        return min(self.spec.step or 1e-3, hi / 10.0), hi

    def _to_pos(self, v: float) -> int:
        lo, hi = self.spec.minimum, self.spec.maximum
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
        lo, hi = self.spec.minimum, self.spec.maximum
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
                 exclude: tuple[str, ...] = ()):
        super().__init__(parent)
        self.params_cls = params_cls
        self.specs = [s for s in describe(params_cls) if s.name not in exclude]
        self._excluded = {s.name: s.default for s in describe(params_cls) if s.name in exclude}
        self.editors: dict[str, QWidget] = {}
        outer = QVBoxLayout(self)
        outer.setContentsMargins(0, 0, 0, 0)
        main = QFormLayout()
        outer.addLayout(main)
        self.advanced_box = QGroupBox("Advanced")
        self.advanced_box.setCheckable(True)
        self.advanced_box.setChecked(False)
        self.advanced_box.setToolTip("Settings most users never need to change.")
        adv_body = QWidget()
        adv = QFormLayout(adv_body)
        adv.setContentsMargins(0, 0, 0, 0)
        box_lay = QVBoxLayout(self.advanced_box)
        box_lay.addWidget(adv_body)
        adv_body.setVisible(False)
        self.advanced_box.toggled.connect(adv_body.setVisible)
        if any(s.advanced for s in self.specs):
            outer.addWidget(self.advanced_box)
        else:
            self.advanced_box.setVisible(False)
        for spec in self.specs:
            form = adv if spec.advanced else main
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
            w.setToolTip(tip)
            label = QLabel(spec.label)
            label.setToolTip(tip)
            form.addRow(label, w)
            self.editors[spec.name] = w
        self._loading = False
        self.set_params(values if values is not None else params_cls())

    def _emit(self, *_):
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
