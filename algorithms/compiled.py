"""The one switch for the compiled (Numba) kernels of every method.

Kernel modules (``algorithms/deform/kernels.py``, ``algorithms/multigrid/kernels.py``,
``algorithms/mesh/_selfparam_kernels.py``) import Numba; the methods load them lazily through a
:class:`KernelModule`, so importing a method never imports Numba, and fall back to NumPy / SciPy /
PyAMG code when it returns None: Numba missing, the environment variable ``STYLIZE3D_NUMBA=0``
(also ``false`` / ``no``), or switched off with :meth:`KernelModule.set` (for comparisons).
"""

from __future__ import annotations

import importlib
import os
from types import ModuleType

__all__ = ["numba_wanted", "KernelModule"]


def numba_wanted() -> bool:
    """False when ``STYLIZE3D_NUMBA`` is 0 / false / no (the pure Python paths are used)."""
    return os.environ.get("STYLIZE3D_NUMBA", "1").strip().lower() not in ("0", "false", "no")


class KernelModule:
    """A lazily imported kernel module that may be unavailable or switched off."""

    def __init__(self, name: str):
        self.name = name
        self._enabled: bool | None = None
        self._module: ModuleType | None = None

    def get(self) -> ModuleType | None:
        """The module, or None (see the module docstring)."""
        if self._enabled is None:
            self._enabled = numba_wanted()
        if not self._enabled:
            return None
        if self._module is None:
            try:
                self._module = importlib.import_module(self.name)
            except ImportError:
                self._enabled = False
                return None
        return self._module

    def set(self, enabled: bool) -> bool:
        """Switch the kernels on or off; returns the previous setting. Switching on where Numba
        is missing leaves them off."""
        previous = self.get() is not None
        self._enabled = bool(enabled)
        return previous
