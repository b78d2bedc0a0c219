"""One dock widget per method. Every panel derives from :class:`app.panels.base.MethodPanel`.

:data:`PANELS` is the one list of the window's panels, in tab order ("module:Class"): adding a
method means adding its panel module here (and its recipe in :mod:`app.recipes`); the window
itself does not change.
"""

from __future__ import annotations

import importlib

PANELS: tuple[str, ...] = (
    "cubic:CubicPanel",
    "analogies:AnalogiesPanel",
    "smooth:SmoothPanel",
    "multigrid:MultigridPanel",
    "spectral:SpectralPanel",
    "subdivision:SubdivisionPanel",
    "paparazzi:PaparazziPanel",
    "adversarial:AdversarialPanel",
)


def panel_classes() -> list[type]:
    """The panel classes of :data:`PANELS`, imported (Qt is loaded)."""
    out = []
    for entry in PANELS:
        module, name = entry.split(":")
        out.append(getattr(importlib.import_module(f"{__name__}.{module}"), name))
    return out
