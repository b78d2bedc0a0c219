"""Spherical-harmonics lighting files (.json): the format ``stylize3d adversary -o x.json`` writes,
read back by the app's "Adversarial lighting" panel.

The file is a JSON object::

    {"format": "stylize3d spherical-harmonics lighting", "degree": 6,
     "order": "index l*l + l + m; columns R, G, B",
     "coefficients": [[R, G, B], ...]}          # 49 rows (degree 6)

:func:`read_lighting` also accepts fewer rows (1, 4, 9, ... = degrees 0, 1, 2, ...; the missing
higher degrees are zero) and a bare list of rows, so a hand-written file with the nine classic
coefficients works.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from ..errors import Stylize3DError
from ..render.sh import SH_DEGREE, n_coefficients

__all__ = ["LIGHTING_FORMAT", "LightingFileError", "lighting_document", "write_lighting",
           "read_lighting"]

LIGHTING_FORMAT = "stylize3d spherical-harmonics lighting"


class LightingFileError(Stylize3DError):
    """A lighting file could not be read (missing, not JSON, wrong shape)."""

    exit_code = 2


def lighting_document(U) -> dict:
    """The JSON object of the lighting ``U ((l+1)^2, 3)`` (padded with zeros to degree 6)."""
    U = np.asarray(U, dtype=np.float64)
    full = np.zeros((n_coefficients(SH_DEGREE), 3))
    full[:len(U)] = U
    return {"format": LIGHTING_FORMAT, "degree": SH_DEGREE,
            "order": "index l*l + l + m; columns R, G, B",
            "coefficients": full.tolist()}


def write_lighting(path, U) -> None:
    """Write the lighting ``U ((l+1)^2, 3)`` to ``path`` atomically (an existing file is replaced
    only once the new one is complete; :class:`~algorithms.errors.MeshWriteError` says why a
    write failed)."""
    from ..mesh.io import atomic_write

    doc = lighting_document(U)
    atomic_write(path, lambda fh: fh.write(json.dumps(doc, indent=1).encode()))


def read_lighting(path) -> np.ndarray:
    """The lighting ``(49, 3)`` stored in ``path`` (see the module docstring)."""
    p = Path(os.fspath(path))
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise LightingFileError(f"The lighting file '{p}' does not exist. Check the name.") \
            from None
    except (OSError, UnicodeDecodeError) as exc:
        raise LightingFileError(f"'{p.name}' cannot be read as a lighting file "
                                f"({getattr(exc, 'strerror', None) or exc}).") from None
    try:
        doc = json.loads(text)
    except ValueError:
        raise LightingFileError(f"'{p.name}' is not a lighting file: it is not JSON. Use a file "
                                "saved by Stylize3D (stylize3d adversary -o lighting.json, or "
                                "Save… in the Adversarial lighting panel).") from None
    rows = doc.get("coefficients") if isinstance(doc, dict) else doc
    try:
        U = np.asarray(rows, dtype=np.float64)
    except (TypeError, ValueError):
        U = None
    full = n_coefficients(SH_DEGREE)
    if U is None or U.ndim != 2 or U.shape[1] != 3 or not 0 < len(U) <= full or \
            round(math.sqrt(len(U))) ** 2 != len(U):
        raise LightingFileError(
            f"'{p.name}' does not hold spherical-harmonics lighting: expected 'coefficients' as "
            f"1, 4, 9, ... or {full} rows of three numbers (R, G, B).")
    if not np.isfinite(U).all():
        raise LightingFileError(f"'{p.name}' has lighting coefficients that are not finite "
                                "numbers.")
    out = np.zeros((full, 3))
    out[:len(U)] = U
    return out
