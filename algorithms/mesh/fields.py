"""Per-vertex scalar fields on disk: read (with plain-English errors) and write (atomically).

Formats, picked by the extension:

* ``.npy`` — a NumPy array of shape (n,) or (n, 1);
* ``.txt`` / ``.csv`` / ``.dat`` — one number per line (commas, semicolons, tabs or spaces may
  separate further columns: then ``column`` picks one, the first by default). Blank lines and lines
  starting with ``#`` are skipped; a first line that is not numeric is taken as a header.

A field must have exactly one finite value per vertex; anything else is refused with a message
that says what was found, so a user can fix the file.
"""

from __future__ import annotations

import io as _io
import os
from pathlib import Path

import numpy as np

from ..errors import MeshReadError, MeshWriteError
from .io import atomic_write

__all__ = ["FIELD_EXTENSIONS", "read_field", "write_field", "field_file_filter"]

FIELD_EXTENSIONS = (".npy", ".txt", ".csv", ".dat")


def field_file_filter() -> str:
    """Qt file-dialog filter for per-vertex fields."""
    pats = " ".join(f"*{e}" for e in FIELD_EXTENSIONS)
    return f"Per-vertex fields ({pats});;All files (*)"


def _parse_text(data: bytes, name: str, column: int) -> np.ndarray:
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise MeshReadError(f"'{name}' is not a text file of numbers (it is binary).") from None
    values = []
    first = True
    for lineno, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        tokens = line.replace(",", " ").replace(";", " ").split()
        try:
            row = [float(t) for t in tokens]
        except ValueError:
            if first:  # a header line
                first = False
                continue
            raise MeshReadError(f"'{name}' line {lineno} is not a number: {raw.strip()[:60]!r}.") from None
        first = False
        if column >= len(row):
            raise MeshReadError(f"'{name}' line {lineno} has {len(row)} column(s); "
                                f"column {column + 1} was asked for.")
        values.append(row[column])
    return np.asarray(values, dtype=np.float64)


def read_field(path: str | os.PathLike, n_vertices: int, *, column: int = 0) -> np.ndarray:
    """Read a per-vertex scalar field for a mesh with ``n_vertices`` vertices.

    Raises :class:`MeshReadError` (exit code 2) when the file cannot be read, has the wrong number
    of values, or holds NaN / infinite values.
    """
    p = Path(os.fspath(path))
    ext = p.suffix.lower()
    if ext not in FIELD_EXTENSIONS:
        raise MeshReadError(f"Cannot read '{p.name}' as a field: use one of "
                            f"{', '.join(FIELD_EXTENSIONS)}.")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise MeshReadError(f"Cannot read '{p.name}': {exc.strerror or exc}.") from None
    if ext == ".npy":
        try:
            arr = np.load(_io.BytesIO(data), allow_pickle=False)
        except Exception as exc:  # noqa: BLE001 - any parse failure is a read error
            raise MeshReadError(f"'{p.name}' is not a valid .npy file ({exc}).") from None
        if arr.ndim == 2 and arr.shape[1] == 1:
            arr = arr[:, 0]
        if arr.ndim != 1 or not np.issubdtype(arr.dtype, np.number):
            raise MeshReadError(f"'{p.name}' holds an array of shape {arr.shape} and type "
                                f"{arr.dtype}; a field needs one number per vertex.")
        values = arr.astype(np.float64)
    else:
        values = _parse_text(data, p.name, column)
    if len(values) != n_vertices:
        raise MeshReadError(f"'{p.name}' has {len(values)} values, but the mesh has "
                            f"{n_vertices} vertices: a field needs one value per vertex.")
    bad = ~np.isfinite(values)
    if bad.any():
        raise MeshReadError(f"'{p.name}' has {int(bad.sum())} NaN or infinite value(s) "
                            f"(first at vertex {int(np.flatnonzero(bad)[0])}).")
    return values


def write_field(path: str | os.PathLike, values: np.ndarray) -> None:
    """Write a per-vertex field atomically (``.npy`` or one number per line for text formats)."""
    p = Path(os.fspath(path))
    ext = p.suffix.lower()
    if ext not in FIELD_EXTENSIONS:
        raise MeshWriteError(f"Cannot save '{p.name}' as a field: use one of "
                             f"{', '.join(FIELD_EXTENSIONS)}.")
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    if ext == ".npy":
        atomic_write(p, lambda fh: np.save(fh, values, allow_pickle=False))
    else:
        atomic_write(p, lambda fh: np.savetxt(fh, values, fmt="%.17g"))
