"""Viewport tools that edit the document: a brush that paints a per-vertex field, and point
handles. They receive picks from :class:`app.viewport.Viewport` (which alone touches VTK) and end
every stroke or drag as ONE undoable command.

Brush falloff: vertices within ``radius`` (a fraction of the bounding-box diagonal, Euclidean
distance to the picked point) move towards the target value by ``strength · (1 − (d/r)²)²``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np
from PySide6.QtCore import QObject, Signal

from app.commands import StateCommand
from app.viewport import PickResult

if TYPE_CHECKING:  # pragma: no cover
    from app.main_window import MainWindow


@dataclass
class BrushSettings:
    radius: float = 0.08     # fraction of the bounding-box diagonal
    strength: float = 0.5    # 0..1 per drag event
    erase: bool = False      # move towards ``low`` instead of ``high``


class FieldBrush(QObject):
    """Paints ``field`` (per-vertex float) between ``low`` and ``high``; starts from ``default``
    where the field does not exist yet. ``changed`` is emitted with the live values while
    painting (the panel redraws its colour map); the document changes only on release."""

    changed = Signal(object)

    def __init__(self, window: "MainWindow", field: str, *, low: float, high: float,
                 default: float, label: str, settings: BrushSettings | None = None,
                 cmap: str = "coolwarm"):
        super().__init__(window)
        self.window_ = window
        self.field = field
        self.low, self.high, self.default = low, high, default
        self.label = label
        self.settings = settings or BrushSettings()
        self.cmap = cmap
        self._values: np.ndarray | None = None
        self._before = None
        self._dabs: list[list[float]] = []
        #: where the falloff is measured: "surface" (3D distance) or "gauss" (normal angle)
        self.space = "surface"

    def current(self) -> np.ndarray:
        st = self.window_.document.state
        if st is None:
            return np.zeros(0)
        v = st.fields.get(self.field)
        return np.full(len(st.V), self.default) if v is None else np.array(v)

    def show(self) -> None:
        """Colour the mesh by this field."""
        if not self.window_.document.is_empty:
            self.window_.viewport.show_field(self.field, self.current(), self.cmap,
                                             (self.low, self.high))

    # -- InteractionHandler -----------------------------------------------------------------
    def press(self, hit: PickResult) -> bool:
        doc = self.window_.document
        if doc.is_empty or self.window_.runner.busy:
            return False
        self._before = doc.state
        self._values = self.current()
        self._dabs = []
        self._dab(hit)
        return True

    def drag(self, hit: PickResult | None) -> None:
        if hit is not None and self._values is not None:
            self._dab(hit)

    def release(self) -> None:
        if self._values is None:
            return
        before, values = self._before, self._values
        self._values = self._before = None
        old = before.fields.get(self.field)
        if old is not None and np.array_equal(old, values):
            return
        after = before.with_field(self.field, values)
        cmd = StateCommand(self.window_.document, before, after, f"Paint {self.label}")
        # what a study log records with the stroke (app/study/session.py)
        # everything app.edits.brush_stroke needs to re-compute the stroke (study replay)
        cmd.log_details = {"tool": "brush", "space": self.space, "field": self.field,
                           "low": self.low, "high": self.high, "default": self.default,
                           "radius": self.settings.radius, "strength": self.settings.strength,
                           "erase": self.settings.erase, "dabs": self._dabs}
        self._dabs = []
        self.window_.undo_stack.push(cmd)

    def weights(self, hit: PickResult) -> tuple[np.ndarray, np.ndarray]:
        """Vertices touched by a dab at ``hit`` and their falloff weights in (0, 1]."""
        from app.edits import surface_weights

        return surface_weights(self.window_.document.V, hit.position, self.settings.radius)

    def _dab(self, hit: PickResult) -> None:
        from app.edits import apply_dab

        idx, w = self.weights(hit)
        target = self.low if self.settings.erase else self.high
        apply_dab(self._values, idx, w, self.settings.strength, target)
        self._dabs.append([float(x) for x in np.asarray(hit.position, dtype=np.float64)])
        self.window_.viewport.show_field(self.field, self._values, self.cmap, (self.low, self.high))
        self.changed.emit(self._values)


class HandleTool(QObject):
    """Click a mesh point to add a handle at its nearest vertex; drag to move the handle's target
    in the view plane; Ctrl+click removes the nearest handle. Handles live in the document state
    (``MeshState.handles``: vertex -> target), so each add / move / removal is undoable."""

    changed = Signal()

    def __init__(self, window: "MainWindow"):
        super().__init__(window)
        self.window_ = window
        self._before = None
        self._vertex: int | None = None
        self._target: np.ndarray | None = None
        self._anchor: np.ndarray | None = None

    def press(self, hit: PickResult) -> bool:
        from PySide6.QtCore import Qt

        doc = self.window_.document
        if doc.is_empty or self.window_.runner.busy:
            return False
        st = doc.state
        F = st.F
        corners = F[hit.face]
        vi = int(corners[np.argmin(((st.V[corners] - hit.position) ** 2).sum(axis=1))])
        handles = dict(st.handles)
        if hit.modifiers & Qt.KeyboardModifier.ControlModifier:
            if handles:
                keys = np.array(list(handles))
                tgt = np.array([handles[k] for k in keys])
                k = int(keys[np.argmin(((tgt - hit.position) ** 2).sum(axis=1))])
                del handles[k]
                cmd = StateCommand(doc, st, st.with_handles(handles), "Remove handle")
                cmd.log_details = _handles_details(cmd.after)
                self.window_.undo_stack.push(cmd)
                self.changed.emit()
            return True
        self._before = st
        self._vertex = vi
        self._target = np.array(handles.get(vi, st.V[vi]), dtype=np.float64)
        self._anchor = hit.position
        self._press_screen = hit.screen
        self.window_.viewport.show_handles(self._preview(handles))
        return True

    def _preview(self, handles: dict) -> dict:
        h = dict(handles)
        h[self._vertex] = tuple(self._target)
        return h

    def drag(self, hit: PickResult | None) -> None:
        # hit may be None when the mouse leaves the mesh: the move is computed from the screen
        if self._vertex is None:
            return
        vp = self.window_.viewport
        pos = vp.last_mouse
        start = np.array(self.window_.document.V[self._vertex] if self._vertex not in
                         self._before.handles else self._before.handles[self._vertex])
        self._target = vp.screen_to_world(pos[0], pos[1], start)
        vp.show_handles(self._preview(dict(self._before.handles)))

    def release(self) -> None:
        if self._vertex is None:
            return
        st = self._before
        handles = self._preview(dict(st.handles))
        text = "Move handle" if self._vertex in st.handles else "Add handle"
        self._vertex = self._before = None
        cmd = StateCommand(self.window_.document, st, st.with_handles(handles), text)
        cmd.log_details = _handles_details(cmd.after)
        self.window_.undo_stack.push(cmd)
        self.changed.emit()


class StampBrush(QObject):
    """Stamps fixed values into several per-vertex fields at once (no falloff): every vertex
    within the brush radius gets ``values()`` (e.g. the three angles of a local cube frame);
    with ``settings.erase`` it gets NaN ("not set"). One stroke is one undoable command."""

    changed = Signal()

    def __init__(self, window: "MainWindow", fields: tuple[str, ...], values: Callable[[], tuple],
                 label: str, settings: BrushSettings | None = None):
        super().__init__(window)
        self.window_ = window
        self.fields = fields
        self.values = values
        self.label = label
        self.settings = settings or BrushSettings()
        self._before = None
        self._arrays: list[np.ndarray] | None = None
        self._touched: np.ndarray | None = None

    def mask(self) -> np.ndarray:
        """(n,) bool: vertices where the fields are set (not NaN)."""
        st = self.window_.document.state
        if st is None:
            return np.zeros(0, bool)
        a = st.fields.get(self.fields[0])
        return np.zeros(len(st.V), bool) if a is None else np.isfinite(a)

    def press(self, hit: PickResult) -> bool:
        doc = self.window_.document
        if doc.is_empty or self.window_.runner.busy:
            return False
        st = doc.state
        self._before = st
        n = len(st.V)
        self._arrays = [np.array(st.fields[f]) if f in st.fields else np.full(n, np.nan)
                        for f in self.fields]
        self._touched = np.zeros(n, bool)
        self._dabs: list[list[float]] = []
        self._stamp_values = tuple(float(v) for v in self.values())
        self._dab(hit)
        return True

    def drag(self, hit: PickResult | None) -> None:
        if hit is not None and self._arrays is not None:
            self._dab(hit)

    def _dab(self, hit: PickResult) -> None:
        from app.edits import stamp_mask

        near = stamp_mask(self.window_.document.V, hit.position, self.settings.radius)
        vals = (np.nan,) * len(self.fields) if self.settings.erase else self._stamp_values
        for arr, v in zip(self._arrays, vals):
            arr[near] = v
        self._touched |= near
        self._dabs.append([float(x) for x in np.asarray(hit.position, dtype=np.float64)])
        self.window_.viewport.show_field(self.fields[0] + "_mask",
                                         np.isfinite(self._arrays[0]).astype(float), "Purples",
                                         (0.0, 1.0))

    def release(self) -> None:
        if self._arrays is None:
            return
        before, arrays = self._before, self._arrays
        self._arrays = self._before = None
        if not self._touched.any():
            return
        after = before
        for f, arr in zip(self.fields, arrays):
            after = after.with_field(f, None if np.isnan(arr).all() else arr)
        cmd = StateCommand(self.window_.document, before, after, f"Paint {self.label}")
        # everything app.edits.stamp_stroke needs to re-compute the stroke (study replay)
        cmd.log_details = {"tool": "stamp", "names": list(self.fields),
                           "values": list(self._stamp_values), "radius": self.settings.radius,
                           "erase": self.settings.erase, "dabs": self._dabs}
        self.window_.undo_stack.push(cmd)
        self.changed.emit()


def _handles_details(after) -> dict:
    """What app.edits.set_handles needs to re-compute a handle edit (study replay)."""
    return {"tool": "handles",
            "handles": [[int(v), [float(x) for x in p]] for v, p in after.handles]}
