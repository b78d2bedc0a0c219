"""The open document, Qt-free: the mesh, the original it came from, per-vertex fields, selection.

Every change goes through :meth:`Document.set_state` with a :class:`MeshState` snapshot, so an undo
command is just "state before" / "state after" (app/commands.py wraps that in a QUndoCommand).
Listeners registered with :meth:`subscribe` are told what changed ("mesh" for a newly opened
mesh, "topology" when an edit changed the triangles, "positions", "fields", "selection", "handles", "path"); the GUI redraws from that. Arrays stored here are never modified in place:
each state owns read-only copies.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np


def _frozen(a: np.ndarray | None, dtype) -> np.ndarray | None:
    if a is None:
        return None
    b = np.array(a, dtype=dtype, copy=True)
    b.setflags(write=False)
    return b


@dataclass(frozen=True)
class MeshState:
    """An immutable snapshot of everything an edit can change.

    V : (n, 3) float64 positions; F : (m, 3) int64 triangles;
    fields : name -> (n,) float64 per-vertex scalar field (λ, masks, ...);
    selection : (n,) bool or None;
    handles : tuple of (vertex, (x, y, z)) point handles with their target positions.
    """

    V: np.ndarray
    F: np.ndarray
    fields: dict = field(default_factory=dict)
    selection: np.ndarray | None = None
    handles: tuple = ()

    @property
    def handle_dict(self) -> dict[int, tuple[float, float, float]]:
        return dict(self.handles)

    @staticmethod
    def make(V, F, fields=None, selection=None) -> "MeshState":
        V = _frozen(V, np.float64)
        F = _frozen(F, np.int64)
        n = len(V)
        fl = {}
        for k, v in (fields or {}).items():
            arr = _frozen(v, np.float64)
            if arr.shape[0] != n:
                raise ValueError(f"field {k!r} has {arr.shape[0]} values for {n} vertices")
            fl[k] = arr
        sel = _frozen(selection, bool)
        if sel is not None and sel.shape != (n,):
            raise ValueError("selection must have one flag per vertex")
        return MeshState(V, F, fl, sel)

    def with_positions(self, V) -> "MeshState":
        if not (isinstance(V, np.ndarray) and V.dtype == np.float64 and not V.flags.writeable
                and V.base is None):  # positions of another state are shared, not copied
            V = _frozen(V, np.float64)
        if V.shape != self.V.shape:
            raise ValueError(f"positions have shape {V.shape}, expected {self.V.shape}")
        return replace(self, V=V)

    def with_field(self, name: str, values) -> "MeshState":
        fl = dict(self.fields)
        if values is None:
            fl.pop(name, None)
        else:
            arr = _frozen(values, np.float64)
            if arr.shape[0] != len(self.V):
                raise ValueError(f"field {name!r} needs one value per vertex")
            fl[name] = arr
        return replace(self, fields=fl)

    def with_selection(self, selection) -> "MeshState":
        return replace(self, selection=_frozen(selection, bool))

    def with_handles(self, handles: dict) -> "MeshState":
        n = len(self.V)
        items = []
        for v, t in sorted(dict(handles).items()):
            if not 0 <= int(v) < n:
                raise ValueError(f"handle vertex {v} out of range")
            items.append((int(v), tuple(float(x) for x in t)))
        return replace(self, handles=tuple(items))


class Document:
    """The open mesh and where it came from. Qt-free; see the module docstring."""

    def __init__(self) -> None:
        self.state: MeshState | None = None
        self.original: MeshState | None = None
        self.path: Path | None = None
        self.report = None  # algorithms.mesh.MeshReport of the loaded mesh
        self.modified = False
        self._listeners: list[Callable[[str], None]] = []

    # -- observers -------------------------------------------------------------------------
    def subscribe(self, listener: Callable[[str], None]) -> None:
        self._listeners.append(listener)

    def _notify(self, what: str) -> None:
        for fn in list(self._listeners):
            fn(what)

    # -- queries ---------------------------------------------------------------------------
    @property
    def is_empty(self) -> bool:
        return self.state is None

    @property
    def V(self) -> np.ndarray:
        return self.state.V

    @property
    def F(self) -> np.ndarray:
        return self.state.F

    @property
    def title(self) -> str:
        name = self.path.name if self.path else ("untitled" if self.state is not None else "")
        return name + (" *" if self.modified else "")

    # -- changes ---------------------------------------------------------------------------
    def load(self, V, F, path: str | Path | None, report=None) -> None:
        """Replace the whole document by a freshly opened mesh (not an undoable edit)."""
        self.state = MeshState.make(V, F)
        self.original = self.state
        self.path = Path(path) if path else None
        self.report = report
        self.modified = False
        self._notify("mesh")

    def set_state(self, state: MeshState, *, modified: bool = True) -> None:
        """Switch to ``state`` (used by undo commands)."""
        old = self.state
        self.state = state
        self.modified = modified
        if old is None:
            self._notify("mesh")
        elif len(old.V) != len(state.V) or (old.F is not state.F and (
                old.F.shape != state.F.shape or not np.array_equal(old.F, state.F))):
            self.report = None  # stale: the window re-validates
            self._notify("topology")
        else:
            if old.V is not state.V:
                self._notify("positions")
            if old.fields is not state.fields:
                self._notify("fields")
            if old.selection is not state.selection:
                self._notify("selection")
            if old.handles != state.handles:
                self._notify("handles")

    def remapped(self, V, F, vertex_map: np.ndarray) -> MeshState:
        """A new state on (V, F) from the current one, see :func:`remap_state`."""
        return remap_state(self.state, V, F, vertex_map)

    def mark_saved(self, path: str | Path) -> None:
        self.path = Path(path)
        self.modified = False
        self._notify("path")


def remap_state(old: MeshState, V, F, vertex_map: np.ndarray) -> MeshState:
    """A new state on (V, F) whose per-vertex fields and selection follow ``vertex_map``
    (old vertex -> new vertex, -1 deleted). New vertices without a preimage (copies made by
    splitting a vertex) take the field's mean value and are not selected. Handles follow
    their vertex (dropped with it)."""
    vmap = np.asarray(vertex_map, dtype=np.int64)
    keep = vmap >= 0
    n = len(V)

    def move(values, fill):
        out = np.full(n, fill, dtype=np.asarray(values).dtype)
        out[vmap[keep]] = np.asarray(values)[keep]
        return out

    fields = {k: move(v, float(np.mean(v)) if len(v) else 0.0) for k, v in old.fields.items()}
    sel = None if old.selection is None else move(old.selection, False)
    new = MeshState.make(V, F, fields, sel)
    return new.with_handles({int(vmap[v]): t for v, t in old.handles if vmap[v] >= 0})
