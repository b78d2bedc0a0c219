"""The 3D viewport: the ONLY module that touches VTK / pyvista objects (GUI thread only).

Wraps a pyvistaqt ``QtInteractor``. The mesh is one ``pyvista.PolyData`` whose points are updated
in place while a job streams (no actor rebuild per frame), with our own area-weighted vertex
normals so smooth shading follows the moving surface. Optional: a translucent "ghost" of the
original mesh, edges (wireframe overlay), flat or smooth shading, a per-vertex scalar colour map.
"""

from __future__ import annotations

import numpy as np
import pyvista as pv
from pyvistaqt import QtInteractor
from PySide6.QtCore import Signal
from PySide6.QtWidgets import QVBoxLayout, QWidget

from algorithms.mesh.operators import vertex_normals

BACKGROUND_TOP = "#d9dee8"
BACKGROUND_BOTTOM = "#7d8799"
MESH_COLOR = "#e8d4b0"
GHOST_COLOR = "#5b8bd9"
HOME_VIEW_DIRECTION = (0.55, 0.35, 1.0)


def _faces_vtk(F: np.ndarray) -> np.ndarray:
    F = np.asarray(F, dtype=np.int64)
    return np.hstack([np.full((len(F), 1), 3, dtype=np.int64), F]).ravel()


class Viewport(QWidget):
    """The central 3D view. ``rendered`` is emitted after every render of new geometry."""

    rendered = Signal()

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.plotter = QtInteractor(self, auto_update=False)
        self.plotter.set_background(BACKGROUND_BOTTOM, top=BACKGROUND_TOP)
        self.plotter.add_axes(interactive=False, line_width=2, labels_off=False)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(0, 0, 0, 0)
        layout.addWidget(self.plotter.interactor)
        self.poly: pv.PolyData | None = None
        self.mesh_actor = None
        self.ghost_actor = None
        self._F: np.ndarray | None = None
        self._flat = False
        self._edges = False
        self._field_name: str | None = None

    # -- geometry ----------------------------------------------------------------------------
    def set_mesh(self, V: np.ndarray, F: np.ndarray, *, reset_camera: bool = True) -> None:
        """Show a new mesh (rebuilds the actor)."""
        self._F = np.asarray(F, dtype=np.int64)
        poly = pv.PolyData(np.asarray(V, dtype=np.float64), _faces_vtk(self._F))
        poly.point_data["Normals"] = vertex_normals(np.asarray(V, dtype=np.float64), self._F)
        poly.point_data.active_normals_name = "Normals"
        self.poly = poly
        self.plotter.remove_actor("mesh", render=False)
        self.mesh_actor = self.plotter.add_mesh(
            poly, name="mesh", color=MESH_COLOR, smooth_shading=False, show_edges=self._edges,
            edge_color="#404040", line_width=0.5, specular=0.25, specular_power=20,
            scalars=None, reset_camera=False)
        self._apply_shading()
        self._field_name = None
        if reset_camera:
            self._home_camera()
        self.render()

    def update_points(self, V: np.ndarray) -> None:
        """Move the vertices of the shown mesh in place (streamed previews)."""
        if self.poly is None:
            return
        V = np.asarray(V, dtype=np.float64)
        if V.shape != (self.poly.n_points, 3):
            raise ValueError(f"expected {(self.poly.n_points, 3)} positions, got {V.shape}")
        self.poly.points = V
        self.poly.point_data["Normals"] = vertex_normals(V, self._F)
        self.poly.point_data.active_normals_name = "Normals"
        self.poly.Modified()
        self.render()

    @property
    def n_points(self) -> int:
        """Number of points in the mesh actor's VTK input (0 when empty)."""
        if self.mesh_actor is None:
            return 0
        return int(self.mesh_actor.GetMapper().GetInput().GetNumberOfPoints())

    @property
    def points(self) -> np.ndarray | None:
        return None if self.poly is None else np.asarray(self.poly.points)

    def clear(self) -> None:
        self.plotter.clear_actors()
        self.poly = self.mesh_actor = self.ghost_actor = None
        self.render()

    # -- display options -----------------------------------------------------------------------
    def set_ghost(self, V: np.ndarray | None, F: np.ndarray | None = None) -> None:
        """Show (or with None hide) a translucent copy of the original mesh."""
        self.plotter.remove_actor("ghost", render=False)
        self.ghost_actor = None
        if V is not None:
            ghost = pv.PolyData(np.asarray(V, dtype=np.float64), _faces_vtk(F))
            self.ghost_actor = self.plotter.add_mesh(ghost, name="ghost", color=GHOST_COLOR,
                                                     opacity=0.25, reset_camera=False,
                                                     scalars=None)
        self.render()

    def set_wireframe(self, on: bool) -> None:
        self._edges = bool(on)
        if self.mesh_actor is not None:
            self.mesh_actor.prop.show_edges = self._edges
        self.render()

    def set_flat_shading(self, on: bool) -> None:
        self._flat = bool(on)
        self._apply_shading()
        self.render()

    def _apply_shading(self) -> None:
        if self.mesh_actor is not None:
            self.mesh_actor.prop.interpolation = "flat" if self._flat else "gouraud"

    def show_field(self, name: str | None, values: np.ndarray | None = None,
                   cmap: str = "viridis", clim: tuple[float, float] | None = None) -> None:
        """Colour the mesh by a per-vertex scalar field (None: plain colour)."""
        if self.poly is None or self.mesh_actor is None:
            return
        mapper = self.mesh_actor.mapper
        if name is None or values is None:
            mapper.scalar_visibility = False
            self._field_name = None
        else:
            self.poly.point_data[name] = np.asarray(values, dtype=np.float64)
            self.poly.point_data.active_scalars_name = name
            mapper.lookup_table = pv.LookupTable(cmap)
            lo, hi = clim if clim else (float(np.min(values)), float(np.max(values)))
            mapper.scalar_range = (lo, hi if hi > lo else lo + 1.0)
            mapper.scalar_visibility = True
            self._field_name = name
        self.render()

    def _home_camera(self) -> None:
        # Most mesh files are Y-up: a three-quarter view from the front, Y pointing up.
        self.plotter.view_vector(HOME_VIEW_DIRECTION, viewup=(0.0, 1.0, 0.0))
        self.plotter.reset_camera()
        self.plotter.camera.zoom(1.15)

    def reset_camera(self) -> None:
        self._home_camera()
        self.render()

    def render(self) -> None:
        self.plotter.render()
        self.rendered.emit()

    def screenshot(self, path: str | None = None) -> np.ndarray:
        """Render and return the (h, w, 3) uint8 image; also write it as PNG when ``path`` is given."""
        self.plotter.render()
        img = self.plotter.screenshot(filename=None, return_img=True)
        if path is not None:
            from PySide6.QtGui import QImage

            h, w = img.shape[:2]
            buf = np.ascontiguousarray(img[..., :3])
            qimg = QImage(buf.data, w, h, 3 * w, QImage.Format.Format_RGB888).copy()
            if not qimg.save(str(path), "PNG"):
                raise OSError(f"could not write {path}")
        return img

    def close_plotter(self) -> None:
        try:
            self.plotter.close()
        except Exception:
            pass
