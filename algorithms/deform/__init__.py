"""Deformation methods on one local-global ARAP core (thesis ch. 5 and 6).

``arap``: the shared ARAP machinery (:class:`~algorithms.deform.arap.ArapSystem`) and plain ARAP
deformation with handles; ``cubic``: cubic (and polyhedral) stylization.
"""

from __future__ import annotations

from . import arap, cubic, progressive
from .arap import ArapParams, ArapSystem, arap_iter, procrustes_rotations
from .cubic import (
    STYLE_PRESETS,
    CubicParams,
    CubicStylizer,
    L1Prox,
    cubic_stylization,
    cubic_stylization_iter,
    rotation_from_degrees,
    shrinkage,
)
from .progressive import ProgressiveCubic, ProgressiveParams, progressive_cubic_iter

__all__ = [
    "arap", "cubic",
    "ArapSystem", "ArapParams", "arap_iter", "procrustes_rotations",
    "CubicParams", "CubicStylizer", "cubic_stylization_iter", "cubic_stylization",
    "STYLE_PRESETS", "L1Prox", "shrinkage",
    "progressive", "ProgressiveCubic", "ProgressiveParams", "progressive_cubic_iter", "rotation_from_degrees",
]  # fmt: skip
