"""Edits as Qt-free functions: what a brush stroke, a stamp, a handle move or a Clean does to a
document state, given everything the tool recorded.

The viewport tools (app/tools.py, app/gaussmap.py) call the same functions while the user paints,
and put the stroke's inputs on their undo command (``log_details``); the study log writes them
and the study replay (:mod:`app.study.replay`) re-computes every edit with :func:`replay_edit`
from its logged input state, so an edit is checked exactly as a run is.

Brush falloff: vertices within ``radius`` (a fraction of the bounding-box diagonal, Euclidean
distance to the picked point) move towards the target value by ``strength · (1 − (d/r)²)²``; on
the Gauss map the distance is the angle between the vertex normal and the picked direction,
``radius · π`` the angular radius.

``details`` of each tool (JSON-able; ``dabs`` are the picked points, one per mouse event):

* ``{"tool": "brush", "space": "surface" | "gauss", "field", "low", "high", "default",
  "radius", "strength", "erase", "dabs": [[x, y, z], ...]}``
* ``{"tool": "stamp", "fields": [...], "values": [...], "radius", "erase", "dabs": [...]}``
* ``{"tool": "handles", "handles": [[vertex, [x, y, z]], ...]}`` (the handles after the edit)
* ``{"tool": "clear", "fields": [...], "handles": bool}`` (fields removed, handles cleared)
* ``{"tool": "clean"}`` (Edit > Clean Mesh)
* ``{"tool": "set_fields", "fields": {name: [values] | null}}`` (whole fields set or removed)
"""

from __future__ import annotations

from typing import Callable

import numpy as np


# ------------------------------------------------------------------------------ brushes
def _diagonal(V: np.ndarray) -> float:
    return float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))


def surface_weights(V: np.ndarray, center, radius: float,
                    diagonal: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices within ``radius`` × diagonal of ``center`` and their falloff weights in (0, 1]."""
    diag = _diagonal(V) if diagonal is None else diagonal
    r = max(float(radius) * diag, 1e-12)
    d2 = ((V - np.asarray(center, dtype=np.float64)) ** 2).sum(axis=1)
    near = np.flatnonzero(d2 < r * r)
    return near, (1.0 - d2[near] / (r * r)) ** 2


def gauss_weights(normals: np.ndarray, center, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices whose normal is within ``radius`` × π of the direction of ``center`` (a point
    on the Gauss-map sphere) and their falloff weights."""
    c = np.asarray(center, dtype=np.float64)
    d = c / max(np.linalg.norm(c), 1e-12)
    theta_r = max(float(radius), 1e-6) * np.pi
    theta = np.arccos(np.clip(normals @ d, -1.0, 1.0))
    near = np.flatnonzero(theta < theta_r)
    return near, (1.0 - (theta[near] / theta_r) ** 2) ** 2


def apply_dab(values: np.ndarray, idx: np.ndarray, w: np.ndarray, strength: float,
              target: float) -> None:
    """One dab, in place: ``values[idx]`` move towards ``target`` by ``strength · w``."""
    values[idx] += float(strength) * w * (float(target) - values[idx])


def brush_stroke(state, details: dict):
    """The state after a whole FieldBrush stroke (see the module docstring)."""
    V = state.V
    field = details["field"]
    old = state.fields.get(field)
    values = np.full(len(V), float(details["default"])) if old is None else np.array(old)
    target = float(details["low"] if details.get("erase") else details["high"])
    space = details.get("space", "surface")
    if space == "gauss":
        from algorithms.mesh.operators import vertex_normals

        normals = vertex_normals(V, state.F)
    diag = _diagonal(V)
    for c in details.get("dabs", []):
        if space == "gauss":
            idx, w = gauss_weights(normals, c, details["radius"])
        else:
            idx, w = surface_weights(V, c, details["radius"], diag)
        apply_dab(values, idx, w, details["strength"], target)
    return state.with_field(field, values)


def stamp_mask(V: np.ndarray, center, radius: float) -> np.ndarray:
    """(n,) bool: vertices within ``radius`` × diagonal of ``center`` (no falloff)."""
    r = max(float(radius) * _diagonal(V), 1e-12)
    return ((V - np.asarray(center, dtype=np.float64)) ** 2).sum(axis=1) < r * r


def stamp_stroke(state, details: dict):
    """The state after a StampBrush stroke: every vertex within the radius of a dab gets the
    values (NaN when erasing); a field left all-NaN is removed."""
    V = state.V
    n = len(V)
    fields = list(details["fields"])
    arrays = [np.array(state.fields[f]) if f in state.fields else np.full(n, np.nan)
              for f in fields]
    vals = ((np.nan,) * len(fields) if details.get("erase")
            else tuple(float(v) for v in details["values"]))
    for c in details.get("dabs", []):
        near = stamp_mask(V, c, details["radius"])
        for arr, v in zip(arrays, vals):
            arr[near] = v
    after = state
    for f, arr in zip(fields, arrays):
        after = after.with_field(f, None if np.isnan(arr).all() else arr)
    return after


# ------------------------------------------------------------------------------ others
def set_handles(state, details: dict):
    return state.with_handles({int(v): tuple(float(x) for x in p)
                               for v, p in details.get("handles", [])})


def clear_fields(state, details: dict):
    after = state
    for f in details.get("fields", []):
        after = after.with_field(f, None)
    if details.get("handles"):
        after = after.with_handles({})
    return after


def clean(state, details: dict):
    """Edit > Clean Mesh (algorithms.mesh.clean_mesh); fields and handles follow the vertices."""
    from algorithms.mesh import clean_mesh
    from app.document import remap_state

    res = clean_mesh(state.V, state.F)
    return remap_state(state, res.V, res.F, res.vertex_map)


def set_fields(state, details: dict):
    after = state
    for name, values in (details.get("fields") or {}).items():
        after = after.with_field(name, None if values is None
                                 else np.asarray(values, dtype=np.float64))
    return after


EDITS: dict[str, Callable] = {"brush": brush_stroke, "stamp": stamp_stroke,
                              "handles": set_handles, "clear": clear_fields, "clean": clean,
                              "set_fields": set_fields}


def replay_edit(state, details: dict):
    """Re-compute a logged edit from its input ``state``; None when the tool is unknown."""
    fn = EDITS.get(str(details.get("tool", "")))
    return None if fn is None else fn(state, details)
