"""The Gauss-map painter (thesis Fig. 5.20): a small sphere view of normal directions.

Painting a direction on the sphere changes the per-vertex field (e.g. the λ scale of cubic
stylization) of every mesh vertex whose unit normal points near that direction: the weight falls
off with the angle, ``(1 − (θ/θ_r)²)²`` for θ < θ_r = ``radius`` × 180°. The mesh shows the
resulting field at once, and the sphere shows it too: each sphere direction is coloured by the
mean field value of the mesh vertices whose normals are closest to it, or, where no normal is
closest, by the mesh vertex whose normal is nearest within 20° (grey: no surface faces that way).
One stroke is one undoable command, exactly like the surface brush (it is one, with a different
notion of "near").
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from PySide6.QtWidgets import QLabel, QVBoxLayout, QWidget
from scipy.spatial import cKDTree

from algorithms.mesh import icosphere
from algorithms.mesh.operators import vertex_normals
from app.tools import BrushSettings, FieldBrush
from app.viewport import PickResult, Viewport

if TYPE_CHECKING:  # pragma: no cover
    from app.main_window import MainWindow


class GaussMapBrush(FieldBrush):
    """A :class:`FieldBrush` whose neighbourhood is in normal space (picks on the sphere)."""

    def __init__(self, window: "MainWindow", painter: "GaussMapPainter", **kw):
        super().__init__(window, **kw)
        self.painter = painter
        self._normals: np.ndarray | None = None
        self.space = "gauss"

    def press(self, hit: PickResult) -> bool:
        doc = self.window_.document
        if doc.is_empty:
            return False
        self._normals = vertex_normals(doc.V, doc.F)
        return super().press(hit)

    def weights(self, hit: PickResult):
        from app.edits import gauss_weights

        return gauss_weights(self._normals, hit.position, self.settings.radius)

    def _dab(self, hit: PickResult) -> None:
        super()._dab(hit)
        self.painter.refresh(self._values)


class GaussMapPainter(QWidget):
    """A sphere view beside the panel; painting on it sets the field by normal direction."""

    def __init__(self, window: "MainWindow", field: str, *, low: float, high: float,
                 default: float, label: str, settings: BrushSettings | None = None,
                 parent: QWidget | None = None):
        super().__init__(parent)
        self.window_ = window
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 0, 0, 0)
        hint = QLabel(f"Gauss map: paint a direction to change {label} of every part of the "
                      "surface facing that way. Right-drag rotates the sphere.")
        hint.setWordWrap(True)
        lay.addWidget(hint)
        self.view = Viewport(self)
        self.view.show_legend = False  # a small view: its colours are the panel's λ
        self.view.setMinimumSize(200, 200)
        lay.addWidget(self.view, 1)
        Vs, Fs = icosphere(4)
        self.sphere_V, self.sphere_F = Vs, Fs
        self._tree = cKDTree(Vs)
        self.view.set_mesh(Vs, Fs)
        self.brush = GaussMapBrush(window, self, field=field, low=low, high=high, default=default,
                                   label=label, settings=settings)
        self.view.set_handler(self.brush)
        window.document.subscribe(self._on_doc)
        self.refresh()

    def _on_doc(self, what: str) -> None:
        if what not in ("mesh", "topology", "fields", "positions"):
            return
        st = self.window_.document.state
        key = None if st is None else (id(st.V), id(st.F), id(st.fields.get(self.brush.field)))
        if key == getattr(self, "_drawn_key", 0):
            return  # another panel's field changed: the sphere shows the same
        self._drawn_key = key
        if self._panel_shown():
            self.refresh()
        else:  # drawn when its panel comes to the front (refresh_if_stale)
            self._stale = True

    def _panel_shown(self) -> bool:
        w = self.parentWidget()
        while w is not None and not hasattr(w, "is_shown"):
            w = w.parentWidget()
        return self.isVisible() if w is None else w.is_shown()

    def refresh_if_stale(self) -> None:
        if getattr(self, "_stale", False):
            self.refresh()

    def sphere_values(self, values: np.ndarray | None = None) -> np.ndarray:
        """Field value per sphere vertex (see the module docstring; NaN: no surface faces
        that way)."""
        doc = self.window_.document
        out = np.full(len(self.sphere_V), np.nan)
        if doc.is_empty:
            return out
        vals = self.brush.current() if values is None else values
        N = vertex_normals(doc.V, doc.F)
        ok = np.linalg.norm(N, axis=1) > 0.5
        _, nearest = self._tree.query(N[ok])
        sums = np.bincount(nearest, weights=vals[ok], minlength=len(self.sphere_V))
        counts = np.bincount(nearest, minlength=len(self.sphere_V))
        has = counts > 0
        out[has] = sums[has] / counts[has]
        gaps = np.flatnonzero(~has)
        if gaps.size:
            Nu = N[ok] / np.linalg.norm(N[ok], axis=1, keepdims=True)
            dist, j = cKDTree(Nu).query(self.sphere_V[gaps])
            close = dist < 2 * np.sin(np.radians(20) / 2)  # chord of 20°
            out[gaps[close]] = vals[ok][j[close]]
        return out

    def refresh(self, values: np.ndarray | None = None) -> None:
        self._stale = False
        b = self.brush
        self.view.show_field(b.field, self.sphere_values(values), b.cmap, (b.low, b.high))
