from __future__ import annotations

from dataclasses import dataclass

import pytest

from algorithms.errors import ParameterError
from algorithms.params import describe, param, params_from_dict, params_to_dict, validate_params


@dataclass(frozen=True)
class P:
    x: float = param(0.5, label="X", minimum=0.0, maximum=1.0, tooltip="x")
    n: int = param(3, label="N", minimum=1, maximum=10, tooltip="n")
    mode: str = param("a", label="Mode", choices=("a", "b"), tooltip="m")
    on: bool = param(False, label="On", tooltip="o")


def test_describe_reads_metadata_in_order():
    specs = describe(P)
    assert [s.name for s in specs] == ["x", "n", "mode", "on"]
    assert specs[0].flag == "--x" and specs[0].maximum == 1.0 and specs[1].type is int
    assert specs[2].choices == ("a", "b")


@pytest.mark.parametrize("values, words", [
    ({"x": 1.5}, "at most 1"), ({"x": -0.1}, "at least 0"), ({"n": 2.5}, "whole number"),
    ({"mode": "c"}, "one of a, b"), ({"on": 1}, "on or off"), ({"x": float("nan")}, "finite"),
    ({"nope": 1}, "Unknown parameter"),
])
def test_out_of_range_values_give_plain_messages(values, words):
    with pytest.raises(ParameterError, match=words):
        params_from_dict(P, values)


def test_round_trip_and_int_to_float():
    p = params_from_dict(P, {"x": 1, "n": 4})
    assert isinstance(p.x, float) and p.x == 1.0
    assert params_from_dict(P, params_to_dict(p)) == p
    assert validate_params(P()) == P()


def test_fields_must_use_param():
    @dataclass(frozen=True)
    class Bad:
        x: float = 1.0

    with pytest.raises(TypeError):
        describe(Bad)


def test_a_field_may_say_which_value_of_another_field_it_needs():
    @dataclass(frozen=True)
    class Two:
        method: str = param("a", label="Method", tooltip="t", choices=("a", "b"))
        weight: float = param(1.0, label="Weight", tooltip="t", enabled_when=("method", "b"))

    specs = {s.name: s for s in describe(Two)}
    assert specs["weight"].enabled_when == ("method", "b")
    assert specs["method"].enabled_when is None

