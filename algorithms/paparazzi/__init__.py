"""Paparazzi (thesis ch. 2): image filters applied to shapes through the one differentiable
renderer (:mod:`algorithms.render`). See :mod:`.optimize` for the loop and its choices,
:mod:`.filters` for the filter registry, :mod:`.offset` for the camera cage."""

from .filters import (FilterContext, FilterSpec, ImageReadError, NoParams, filter_names,
                      get_filter, read_image, register_filter, unregister_filter)
from .measures import bending_energy, palette_fraction, planar_area_fraction
from .offset import OffsetSurface, monitor_cameras, offset_surface, sample_camera
from .optimize import (EnergyNotLowered, FilterFailed, NothingToFilter, Paparazzi,
                       PaparazziParams, PaparazziStep, count_self_intersections, paparazzi,
                       paparazzi_iter, require_lowered)
from . import neural_style  # noqa: F401  (registers the neural-style filter; no heavy imports)

__all__ = ["FilterContext", "FilterSpec", "ImageReadError", "NoParams", "filter_names",
           "get_filter", "read_image", "register_filter", "unregister_filter", "bending_energy",
           "palette_fraction", "planar_area_fraction", "OffsetSurface", "offset_surface",
           "sample_camera", "monitor_cameras", "FilterFailed", "Paparazzi", "PaparazziParams",
           "PaparazziStep", "EnergyNotLowered", "NothingToFilter", "require_lowered",
           "count_self_intersections", "paparazzi", "paparazzi_iter"]
