"""One definition of each parameter set (DESIGN.md §2).

Each method declares a frozen ``@dataclass Params`` whose fields are made with :func:`param`. The
field metadata (label, range, step, tooltip, choices, CLI flag) is read by the CLI to build its
flags, by the GUI to build its form, and by the session log to record a run. Defaults are the
paper's.

Example
-------
>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class Params:
...     iterations: int = param(10, label="Iterations", minimum=1, maximum=1000, step=1,
...                             tooltip="How many smoothing steps to take.")
>>> describe(Params)[0].label
'Iterations'
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from typing import Any, Sequence

from .errors import ParameterError

__all__ = ["param", "ParamSpec", "describe", "validate_params", "params_to_dict", "params_from_dict"]


def param(
    default: Any,
    *,
    label: str,
    tooltip: str,
    minimum: float | None = None,
    maximum: float | None = None,
    step: float | None = None,
    decimals: int | None = None,
    choices: Sequence[str] | None = None,
    log_scale: bool = False,
    advanced: bool = False,
    cli_aliases: Sequence[str] = (),
    slider_range: tuple[float, float] | None = None,
    enabled_when: tuple[str, Any] | None = None,
) -> Any:
    """A dataclass field carrying the metadata the CLI and the GUI need.

    Parameters
    ----------
    default : the paper's default value.
    label : short human label ("Step size").
    tooltip : one or two sentences for a novice: what it does and what larger values do.
    minimum, maximum : inclusive range for numbers (checked by :func:`validate_params`).
    step : increment for spin boxes and sliders.
    decimals : digits shown by the GUI (floats).
    choices : allowed values for a string parameter (a drop-down in the GUI).
    log_scale : the GUI slider moves logarithmically (for values spanning decades).
    advanced : hidden behind "Advanced" in the GUI.
    cli_aliases : extra CLI flags for the same field (e.g. ``("--lambda",)`` for ``lam``).
    slider_range : the part of [minimum, maximum] the GUI slider spans (the useful values), when
        the allowed range is much wider; the number field still takes any allowed value.
    enabled_when : ``(other field, value)``: this field is used only while the other field has
        that value (the GUI greys it out otherwise, e.g. a setting of one of two methods).
    """
    meta = dict(label=label, tooltip=tooltip, minimum=minimum, maximum=maximum, step=step,
                decimals=decimals, choices=tuple(choices) if choices else None,
                log_scale=log_scale, advanced=advanced, cli_aliases=tuple(cli_aliases),
                slider_range=tuple(slider_range) if slider_range else None,
                enabled_when=tuple(enabled_when) if enabled_when else None)
    return field(default=default, metadata={"stylize3d": meta})


@dataclass(frozen=True)
class ParamSpec:
    """Everything known about one parameter: its name, type, default and metadata."""

    name: str
    type: type
    default: Any
    label: str
    tooltip: str
    minimum: float | None
    maximum: float | None
    step: float | None
    decimals: int | None
    choices: tuple[str, ...] | None
    log_scale: bool
    advanced: bool
    cli_aliases: tuple[str, ...] = ()
    slider_range: tuple[float, float] | None = None
    enabled_when: tuple[str, Any] | None = None

    @property
    def flag(self) -> str:
        """The CLI flag: ``step_size`` -> ``--step-size``."""
        return "--" + self.name.replace("_", "-")


def describe(params_cls: type) -> list[ParamSpec]:
    """The :class:`ParamSpec` of every field of a Params dataclass, in declaration order."""
    if not dataclasses.is_dataclass(params_cls):
        raise TypeError(f"{params_cls!r} is not a dataclass")
    hints = typing.get_type_hints(params_cls)
    specs = []
    for f in dataclasses.fields(params_cls):
        meta = f.metadata.get("stylize3d")
        if meta is None:
            raise TypeError(f"field {params_cls.__name__}.{f.name} was not declared with param()")
        typ = hints[f.name]
        if typ not in (int, float, bool, str):
            raise TypeError(f"field {params_cls.__name__}.{f.name}: unsupported type {typ!r}")
        specs.append(ParamSpec(name=f.name, type=typ, default=f.default, **meta))
    return specs


def validate_params(params: Any) -> Any:
    """Check every field against its range and choices; return ``params`` or raise ParameterError."""
    for spec in describe(type(params)):
        value = getattr(params, spec.name)
        if spec.type is bool:
            if not isinstance(value, bool):
                raise ParameterError(f"{spec.label} must be on or off (got {value!r}).")
            continue
        if spec.type is str:
            if spec.choices and value not in spec.choices:
                raise ParameterError(
                    f"{spec.label} must be one of {', '.join(spec.choices)} (got {value!r}).")
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParameterError(f"{spec.label} must be a number (got {value!r}).")
        if spec.type is int and int(value) != value:
            raise ParameterError(f"{spec.label} must be a whole number (got {value!r}).")
        if not math.isfinite(float(value)):
            raise ParameterError(f"{spec.label} must be a finite number (got {value!r}).")
        if spec.minimum is not None and value < spec.minimum:
            raise ParameterError(f"{spec.label} must be at least {spec.minimum:g} (got {value:g}).")
        if spec.maximum is not None and value > spec.maximum:
            raise ParameterError(f"{spec.label} must be at most {spec.maximum:g} (got {value:g}).")
    return params


def params_to_dict(params: Any) -> dict[str, Any]:
    """JSON-safe dict of a Params instance (for logs and --json output)."""
    return {f.name: getattr(params, f.name) for f in dataclasses.fields(params)}


def params_from_dict(params_cls: type, values: dict[str, Any]) -> Any:
    """Build and validate a Params instance; unknown keys raise ParameterError."""
    names = {s.name: s for s in describe(params_cls)}
    unknown = set(values) - set(names)
    if unknown:
        raise ParameterError(f"Unknown parameter(s): {', '.join(sorted(unknown))}.")
    coerced = {}
    for k, v in values.items():
        t = names[k].type
        coerced[k] = float(v) if (t is float and isinstance(v, int) and not isinstance(v, bool)) else v
    return validate_params(params_cls(**coerced))
