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

# normal-driven spherical shape analogies (thesis ch. 6) and their target normals
from . import analogies, targets  # noqa: E402
from .analogies import (  # noqa: E402
    REGULARIZERS,
    AnalogyParams,
    ShapeAnalogy,
    developable_face_targets,
    shape_analogy,
    shape_analogy_iter,
)
from .targets import (  # noqa: E402
    PRIMITIVES,
    CaptureSphere,
    ClosestNormals,
    SphericalStyleMap,
    TargetMap,
    closest_normal_targets,
    mesh_style_normals,
    primitive_normals,
)

__all__ += [
    "analogies", "targets",
    "AnalogyParams", "ShapeAnalogy", "shape_analogy_iter", "shape_analogy", "REGULARIZERS",
    "developable_face_targets",
    "TargetMap", "ClosestNormals", "SphericalStyleMap", "CaptureSphere", "PRIMITIVES",
    "primitive_normals", "mesh_style_normals", "closest_normal_targets",
]  # fmt: skip
