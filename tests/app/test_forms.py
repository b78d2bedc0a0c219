"""The parameter form generated from a Params dataclass (no viewport needed)."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from algorithms.params import param
from algorithms.smoothing import SmoothParams


@dataclass(frozen=True)
class DemoParams:
    weight: float = param(0.2, label="Weight", minimum=0.0, maximum=1.0, step=0.05,
                          tooltip="How strong.")
    scale: float = param(1e-3, label="Scale", minimum=1e-6, maximum=1.0, log_scale=True,
                         decimals=6, tooltip="Log-scaled.")
    count: int = param(5, label="Count", minimum=1, maximum=100, step=1, tooltip="How many.")
    mode: str = param("b", label="Mode", choices=("a", "b", "c"), tooltip="Which.")
    flag: bool = param(True, label="Flag", tooltip="On or off.")


def test_form_reflects_metadata_and_defaults(qtbot):
    from app.forms import ParamsForm

    form = ParamsForm(DemoParams)
    qtbot.addWidget(form)
    assert form.params() == DemoParams()
    w = form.editors["weight"]
    assert w.spin.minimum() == 0.0 and w.spin.maximum() == 1.0
    assert w.spin.singleStep() == pytest.approx(0.05)
    assert "How strong." in w.toolTip() and "Range 0 to 1" in w.toolTip()
    assert form.editors["mode"].count() == 3


def test_form_edits_emit_new_params(qtbot):
    from app.forms import ParamsForm

    form = ParamsForm(DemoParams)
    qtbot.addWidget(form)
    got = []
    form.changed.connect(got.append)
    form.editors["count"].setValue(7)  # programmatic set does not emit...
    assert got == []
    form.editors["count"].spin.setValue(9)  # ...a user edit does
    assert got[-1].count == 9
    form.editors["weight"].slider.setValue(500)  # slider half-way
    assert got[-1].weight == pytest.approx(0.5)
    assert form.editors["weight"].spin.value() == pytest.approx(0.5)
    form.editors["scale"].slider.setValue(500)  # log slider half-way between 1e-6 and 1
    assert got[-1].scale == pytest.approx(1e-3, rel=0.05)
    form.editors["flag"].setChecked(False)
    assert got[-1].flag is False
    form.editors["mode"].setCurrentText("c")
    assert got[-1].mode == "c"
    form.reset_defaults()
    assert form.params() == DemoParams()


def test_smooth_form_round_trip(qtbot):
    from app.forms import ParamsForm

    form = ParamsForm(SmoothParams)
    qtbot.addWidget(form)
    p = SmoothParams(flow="cmcf", step_size=0.01, iterations=3, keep_size=False, fix_boundary=True)
    form.set_params(p)
    assert form.params() == p


@dataclass(frozen=True)
class AdvParams:
    a: float = param(1.0, label="A", minimum=0.0, maximum=2.0, tooltip="a")
    b: int = param(3, label="B", minimum=1, maximum=9, advanced=True, tooltip="b")
    c: bool = param(False, label="C", tooltip="c")


def test_advanced_fields_are_collapsed_and_excluded_fields_keep_defaults(qtbot):
    from app.forms import ParamsForm

    form = ParamsForm(AdvParams, exclude=("c",))
    qtbot.addWidget(form)
    form.show()
    assert "c" not in form.editors and form.params().c is False
    assert not form.editors["b"].isVisible() and form.editors["a"].isVisible()
    form.advanced_box.setChecked(True)
    assert form.editors["b"].isVisible()
    got = []
    form.changed.connect(got.append)
    form.set_value("b", 7)
    assert got[-1] == AdvParams(b=7)


@dataclass(frozen=True)
class ZeroLogParams:
    lam: float = param(1.0, label="λ", minimum=0.0, maximum=1e5, step=0.1, log_scale=True,
                       tooltip="spans decades from 0")


def test_log_slider_starting_at_zero(qtbot):
    from app.forms import ParamsForm

    form = ParamsForm(ZeroLogParams)
    qtbot.addWidget(form)
    ed = form.editors["lam"]
    assert 0 < ed.slider.value() < 1000  # λ = 1 is somewhere inside, not at an end
    got = []
    form.changed.connect(got.append)
    ed.slider.setValue(0)
    assert got[-1].lam == 0.0
    ed.slider.setValue(1000)
    assert got[-1].lam == pytest.approx(1e5)
    ed.slider.setValue(500)
    assert 0.1 < got[-1].lam < 1e5


def test_parameters_spanning_many_decades_read_in_scientific_notation(qtbot):
    from app.forms import ParamsForm

    form = ParamsForm(DemoParams)  # scale: 1e-6 .. 1, log-scaled
    qtbot.addWidget(form)
    spin = form.editors["scale"].spin
    spin.setValue(2.5e-6)
    assert spin.text() == "2.5e-06" and form.params().scale == pytest.approx(2.5e-6)
    got = []
    form.changed.connect(got.append)
    spin.lineEdit().setText("3e-5")
    spin.interpretText()
    assert got[-1].scale == pytest.approx(3e-5)
    assert spin.validate("3e-5", 4)[0].name == "Acceptable"
    assert spin.validate("abc", 3)[0].name == "Invalid"
    assert spin.validate("5", 1)[0].name == "Intermediate"  # above the maximum
    # a plain range keeps the ordinary spin box
    from app.forms import _ScientificSpinBox

    assert not isinstance(form.editors["weight"].spin, _ScientificSpinBox)
    assert isinstance(spin, _ScientificSpinBox)


def test_slider_spans_the_useful_range_and_the_field_takes_the_rest(qtbot):
    from app.forms import ParamsForm

    """Issue 24 item 10: analogies' λ (allowed 0 to 1e5, log slider) jumped from 1 to 102 when
    the slider was dragged to its middle. Its slider now spans 0 to 100; typing 1000 still
    works and puts the slider at its end."""
    from algorithms.deform.analogies import AnalogyParams
    from app.forms import SLIDER_STEPS

    form = ParamsForm(AnalogyParams)
    qtbot.addWidget(form)
    ed = form.editors["lam"]
    assert ed.slider.value() == ed._to_pos(1.0)
    assert 0.2 * SLIDER_STEPS < ed.slider.value() < 0.5 * SLIDER_STEPS
    ed.slider.setValue(SLIDER_STEPS // 2)  # the middle of the slider
    assert 1.0 < form.params().lam < 5.0
    ed.slider.setValue(SLIDER_STEPS)
    assert form.params().lam == pytest.approx(100.0)
    ed.spin.setValue(1000.0)
    assert form.params().lam == 1000.0 and ed.slider.value() == SLIDER_STEPS
    ed.slider.setValue(0)
    assert form.params().lam == 0.0


def test_a_form_greys_out_a_field_while_its_other_field_has_another_value(qtbot):
    from app.forms import ParamsForm

    @dataclass(frozen=True)
    class Two:
        method: str = param("a", label="Method", tooltip="t", choices=("a", "b"))
        weight: float = param(1.0, label="Weight", tooltip="t", enabled_when=("method", "b"))

    form = ParamsForm(Two)
    qtbot.addWidget(form)
    assert not form.editors["weight"].isEnabled()
    form.editors["method"].setCurrentText("b")
    assert form.editors["weight"].isEnabled() and form.labels["weight"].isEnabled()
    form.set_params(Two(method="a", weight=2.0))
    assert not form.editors["weight"].isEnabled()
    assert form.params() == Two(method="a", weight=2.0)    # greyed out, still kept
