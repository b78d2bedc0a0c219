"""Stylize3D's public Python API (``import stylize3d``).

The names scripts need, from one namespace; ``app`` and ``algorithms`` stay the implementation
(docs/scripting.md):

* :func:`load` -- a ``.s3d`` project or a mesh file as a Project;
* :func:`run` -- a panel's Run, headless (the recipe the app, the command line and the study
  replay call);
* :func:`recipes` -- every recipe by name;
* :mod:`batch` -- many meshes in worker processes (docs/batch.md);
* ``__version__``.

Each name is imported on first use, so ``import stylize3d`` costs nothing.
"""

from __future__ import annotations

__all__ = ["load", "run", "recipes", "batch", "__version__"]

_FROM = {"load": ("app.recipes", "load"), "run": ("app.recipes", "run"),
         "recipes": ("app.recipes", "recipes"), "batch": ("app.batch", None),
         "__version__": ("app", "__version__")}


def __getattr__(name: str):
    if name not in _FROM:
        raise AttributeError(f"module 'stylize3d' has no attribute {name!r}")
    import importlib

    module, attr = _FROM[name]
    value = importlib.import_module(module)
    if attr is not None:
        value = getattr(value, attr)
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)
