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
* ``{"tool": "stamp", "names": [field, ...], "values": [...], "radius", "erase", "dabs": [...]}``
* ``{"tool": "handles", "handles": [[vertex, [x, y, z]], ...]}`` (the handles after the edit)
* ``{"tool": "clear", "names": [field, ...], "clear_handles": bool}`` (fields removed, handles
  cleared)

(The study log adds its own ``fields``, ``moved_vertices`` and ``handles`` keys — what changed —
to every edit; only the handles tool's ``handles`` means the same as the log's.)
* ``{"tool": "clean"}`` (Edit > Clean Mesh)
* ``{"tool": "set_fields", "values": {name: [values] | null}}`` (whole fields set or removed)
* ``{"tool": "new_noise", "field", "noise", "seed"}`` (the Multigrid panel's noisy test field)
* ``{"tool": "load_field", "field", "file": "blob:..."}`` (a per-vertex field read from a file)
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
    fields = list(details["names"])
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
    for f in details.get("names", []):
        after = after.with_field(f, None)
    if details.get("clear_handles"):
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
    for name, values in (details.get("values") or {}).items():
        after = after.with_field(name, None if values is None
                                 else np.asarray(values, dtype=np.float64))
    return after


def new_noise(state, details: dict):
    """The Multigrid panel's "New noise": a seeded noisy test field; the old result goes."""
    from app.recipes.multigrid import RESULT_FIELD, noisy_field

    noisy = noisy_field(state.V, state.F, float(details["noise"]), int(details["seed"]))
    return state.with_field(details["field"], noisy).with_field(RESULT_FIELD, None)


def load_field(state, details: dict):
    """The Multigrid panel's "Load field…": the file's values (kept as a blob)."""
    from algorithms.mesh.fields import read_field
    from app.recipes import blob_path
    from app.recipes.multigrid import RESULT_FIELD

    values = read_field(str(blob_path(details["file"])), len(state.V))
    return state.with_field(details["field"], values).with_field(RESULT_FIELD, None)


EDITS: dict[str, Callable] = {"brush": brush_stroke, "stamp": stamp_stroke,
                              "handles": set_handles, "clear": clear_fields, "clean": clean,
                              "set_fields": set_fields, "new_noise": new_noise,
                              "load_field": load_field}


def replay_edit(state, details: dict):
    """Re-compute a logged edit from its input ``state``; None when the tool is unknown."""
    fn = EDITS.get(str(details.get("tool", "")))
    return None if fn is None else fn(state, details)
