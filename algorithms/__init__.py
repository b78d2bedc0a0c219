"""Stylize3D's Qt-free algorithms. Importing any of them first sets the thread counts the
compiled kernels and PyTorch share (:mod:`algorithms.compiled`), before either loads OpenMP."""

from . import compiled as _compiled  # noqa: F401
