"""Stylize3D's application layer: the GUI (Qt, VTK in viewport.py only) and the batch CLI."""

from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("stylize3d")
except _metadata.PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.1.0"
