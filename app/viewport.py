"""The 3D viewport: the ONLY module that touches VTK / pyvista objects (GUI thread only).

Wraps a pyvistaqt ``QtInteractor``. The mesh is one ``pyvista.PolyData`` whose points are updated
in place while a job streams (no actor rebuild per frame), with our own area-weighted vertex
normals so smooth shading follows the moving surface. Optional: a translucent "ghost" of the
original mesh, edges (wireframe overlay), flat or smooth shading, a per-vertex scalar colour map.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import pyvista as pv
from pyvistaqt import QtInteractor
from PySide6.QtCore import QEvent, QObject, Qt, QTimer, Signal
from PySide6.QtWidgets import QVBoxLayout, QWidget
from vtkmodules.vtkRenderingCore import vtkCellPicker

from algorithms.mesh.operators import vertex_normals

BACKGROUND_TOP = "#d9dee8"
BACKGROUND_BOTTOM = "#7d8799"
MESH_COLOR = "#e8d4b0"
GHOST_COLOR = "#5b8bd9"
HOME_VIEW_DIRECTION = (0.55, 0.35, 1.0)
#: at most this share of the GUI thread's time goes to redrawing the 3D view (the rest answers
#: the user): after a redraw that took t seconds the next one waits t · (1 − s) / s
REDRAW_SHARE = 0.5
#: what the colour legend says of each field the app shows (title with units); a field not
#: listed is titled by its name. Categorical fields (region labels) get no bar.
FIELD_TITLES = {
    "lambda_scale": "λ scale (× the slider's λ)",
    "fixed": "fixed region (1 = pinned)",
    "plane": "plane region (1 = flattened)",
    "frame_mask": "own cube frame (1 = painted)",
    "angle_to_targets": "angle to target normals (°)",
    "gaussian_curvature": "Gaussian curvature (1/length²)",
    "signal": "signal value",
    "eigenfunction": "eigenfunction value",
}
#: fields whose colours are not a scale (hues of directions): no bar
NO_LEGEND = {"target_direction", "capture"}
#: anti-aliasing samples when idle; none while a job streams or the camera moves (3× cheaper
#: with software OpenGL)
MULTI_SAMPLES = 4
#: meshes with more triangles than this are drawn without anti-aliasing even when still: their
#: triangles are about a pixel, and 4x anti-aliasing made a still frame of a 467k-triangle mesh
#: 3-4x slower with software OpenGL (a window frozen ~0.7 s each time it is shown)
MSAA_MAX_FACES = 200_000
#: while the camera moves (a drag, the wheel), a mesh with more triangles than this is drawn as a
#: stand-in of about LOD_TARGET_FACES triangles (app/lod.py), the full mesh again on release
LOD_FACES = 50_000
LOD_TARGET_FACES = 25_000
#: the wheel has no "release": the camera counts as still after this many ms without a turn
WHEEL_IDLE_MS = 250


def _faces_vtk(F: np.ndarray) -> np.ndarray:
    F = np.asarray(F, dtype=np.int64)
    return np.hstack([np.full((len(F), 1), 3, dtype=np.int64), F]).ravel()


def legend_font_file():
    """A TrueType font with Greek letters for the colour bar (DejaVu Sans, installed with the
    app's system packages), or None to keep VTK's built-in font."""
    from pathlib import Path

    for p in ("/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
              "/usr/share/fonts/TTF/DejaVuSans.ttf", "/usr/share/fonts/dejavu/DejaVuSans.ttf"):
        if Path(p).is_file():
            return Path(p)
    return None


@dataclass(frozen=True)
class PickResult:
    """A point of the mesh under the mouse: world ``position`` (3,), triangle index ``face``,
    the widget pixel ``screen`` (x, y) and the modifiers held."""

    position: np.ndarray
    face: int
    screen: tuple[int, int]
    modifiers: Qt.KeyboardModifier = Qt.KeyboardModifier.NoModifier


class InteractionHandler(Protocol):
    """A viewport tool (brush, handle placement, ...). While one is active, left-button drags on
    the mesh go to it instead of rotating the camera (right/middle buttons and the wheel still
    move the camera); a drag that starts just off the mesh neither rotates the camera nor paints
    until it reaches the mesh. ``press`` returns False to let the camera have the drag after
    all."""

    def press(self, hit: PickResult) -> bool: ...
    def drag(self, hit: PickResult | None) -> None: ...
    def release(self) -> None: ...


class _MouseFilter(QObject):
    def __init__(self, viewport: "Viewport"):
        super().__init__(viewport)
        self.vp = viewport
        self.dragging = False
        #: a stroke that started off the model: it begins where the mouse first reaches it
        self.pending = False

    def eventFilter(self, obj, event) -> bool:  # noqa: N802 (Qt API)
        consumed = self._tool_event(event)
        if not consumed:  # what reaches VTK moves the camera: draw a light stand-in meanwhile
            t = event.type()
            if t == QEvent.Type.MouseButtonPress:
                self.vp.begin_interaction()
            elif t == QEvent.Type.MouseButtonRelease and event.buttons() == Qt.MouseButton.NoButton:
                self.vp.end_interaction()
            elif t == QEvent.Type.Wheel:
                self.vp.begin_interaction()
                self.vp._wheel_timer.start(WHEEL_IDLE_MS)
        return consumed

    def _tool_event(self, event) -> bool:
        """The active tool's share of the mouse (True: the event is the tool's, not VTK's)."""
        h = self.vp.handler
        t = event.type()
        if h is None:
            self.dragging = self.pending = False
            return False
        if t == QEvent.Type.MouseButtonPress and event.button() == Qt.MouseButton.LeftButton:
            hit = self.vp.pick(event.position().x(), event.position().y(), event.modifiers())
            if hit is not None and h.press(hit):
                self.dragging = True
                return True
            if hit is None:  # just off the model: a tool is active, the camera stays put
                self.pending = True
                return True
            return False
        if t in (QEvent.Type.MouseMove, QEvent.Type.MouseButtonPress):
            self.vp.last_mouse = (event.position().x(), event.position().y())
        if t == QEvent.Type.MouseMove and self.pending:
            hit = self.vp.pick(event.position().x(), event.position().y(), event.modifiers())
            if hit is not None and h.press(hit):
                self.pending, self.dragging = False, True
            return True
        if t == QEvent.Type.MouseButtonRelease and self.pending and \
                event.button() == Qt.MouseButton.LeftButton:
            self.pending = False
            return True
        if t == QEvent.Type.MouseMove and self.dragging:
            h.drag(self.vp.pick(event.position().x(), event.position().y(), event.modifiers()))
            return True
        if t == QEvent.Type.MouseButtonRelease and self.dragging and \
                event.button() == Qt.MouseButton.LeftButton:
            self.dragging = False
            h.release()
            return True
        return False


class _TimedInteractor(QtInteractor):
    """pyvistaqt's widget, its paints timed and prepared by the :class:`Viewport`.

    **No wrapper of the GL surface is kept** (issue 35). pyvistaqt keeps ``self._surface =
    context.surface()`` from ``initializeGL`` to make its context current later. That surface is
    the ``QOffscreenSurface`` Qt creates and deletes with the widget's context, and the wrapper
    PySide makes for it is a plain ``QSurface``: not a ``QObject``, so Shiboken is never told
    when Qt deletes it. Whenever the context went away without pyvistaqt's clean-up slot running
    (a window deleted while its interactor lived on in a reference cycle, which the GUI-thread
    collector of :mod:`app.gc_guard` frees only later), the wrapper stayed in Shiboken's
    address map; the next C++ object allocated at that address and handed to Python got it
    back: ``QMenu.addAction`` returned a ``QSurface`` (seen in CI), and making the context
    current through it would touch freed memory. Here ``_surface`` is a property: pyvistaqt's
    assignments only record whether there is a surface, and each read asks the (tracked,
    ``QObject``) context for its current surface, a wrapper that lives for that call only.
    ``tests/app/test_viewport_lifetime.py`` checks that no ``QSurface`` wrapper outlives a
    call."""

    viewport: "Viewport | None" = None

    @property
    def _surface(self):  # noqa: D401 - pyvistaqt's attribute
        ctx = getattr(self, "_ctx", None)
        if not getattr(self, "_has_surface", False) or ctx is None:
            return None
        import shiboken6

        if not shiboken6.isValid(ctx):  # the context is gone (QObject: tracked)
            return None
        return ctx.surface()

    @_surface.setter
    def _surface(self, value) -> None:
        self._has_surface = value is not None

    def paintGL(self) -> None:  # noqa: N802 (Qt API)
        vp = self.viewport
        if vp is not None:
            vp._before_paint()
        # A paint that only follows a render VTK already did (the camera interactor renders on
        # every mouse move, then asks Qt for this paint) shows that frame: pyvistaqt renders
        # every paint again, which halved the frame rate while turning the view. Paints we
        # asked for (Viewport.render), and Qt's own (expose, resize), render as before.
        skip = (vp is not None and vp._vtk_frame_ready and not vp._paint_asked
                and not getattr(self, "_in_paint", False))
        if vp is not None:
            vp._vtk_frame_ready = False
            vp._in_our_paint = True
        t0 = time.perf_counter()
        if skip:
            self._in_paint = True  # pyvistaqt's own guard: blit the finished frame only
        try:
            super().paintGL()
        finally:
            if skip:
                self._in_paint = False
            if vp is not None:
                vp._in_our_paint = False
        if vp is not None:
            vp._after_paint(t0, time.perf_counter())


class Viewport(QWidget):
    """The central 3D view. ``rendered`` is emitted after every redraw.

    Redraws are asked for with :meth:`render` and happen in the widget's next paint: several
    changes before it are drawn once, and while redraws are expensive (software OpenGL, big
    meshes) they are spaced so that at most :data:`REDRAW_SHARE` of the GUI thread's time goes
    to them (``render_seconds`` is the measured cost of one). Streamed positions are stored at
    once (``points`` is always current); their normals are computed just before the paint."""

    rendered = Signal()

    def __init__(self, parent: QWidget | None = None):
        super().__init__(parent)
        self.plotter = _TimedInteractor(self, auto_update=False, multi_samples=MULTI_SAMPLES)
        self.plotter.viewport = self
        self.render_seconds = 0.0       # measured cost of one redraw (moving average)
        self.redraws = 0
        self.redraw_seconds_total = 0.0
        self._last_paint_end = 0.0
        self._paint_asked = False
        self._normals_dirty = False
        self._paint_timer = QTimer(self)
        self._paint_timer.setSingleShot(True)
        self._paint_timer.timeout.connect(self._ask_paint)
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
        self.show_legend = True   # small views (Gauss map, capture sphere) switch it off
        self.legend = None        # the colour bar (vtkScalarBarActor) of the shown field
        self.legend_title = ""
        self.legend_range: tuple[float, float] | None = None
        self.handler: InteractionHandler | None = None
        self.last_mouse: tuple[float, float] = (0.0, 0.0)
        self.handles_actor = None
        self._picker = vtkCellPicker()
        self._picker.SetTolerance(0.0005)
        self._picker.PickFromListOn()
        self._mouse_filter = _MouseFilter(self)
        self.plotter.interactor.installEventFilter(self._mouse_filter)
        # a render VTK did by itself (the interactor, on a camera move), not in one of our
        # paints: the next paint only shows it (see _TimedInteractor.paintGL)
        self._vtk_frame_ready = False
        self._in_our_paint = False
        rw = self.plotter.ren_win
        if rw is not None:
            rw.AddObserver("EndEvent", self._on_vtk_render_end)
        # the camera moving (see begin_interaction)
        self.interacting = False
        self._proxy = None             # app.lod.Proxy of the shown mesh
        self._proxy_poly: pv.PolyData | None = None
        self._proxy_key = None
        self._streaming = False
        self._wheel_timer = QTimer(self)
        self._wheel_timer.setSingleShot(True)
        self._wheel_timer.timeout.connect(self.end_interaction)

    # -- tools and picking -------------------------------------------------------------------
    def set_handler(self, handler: InteractionHandler | None) -> None:
        """Route left-button drags on the mesh to ``handler`` (None: back to camera control)."""
        self.handler = handler
        self.plotter.interactor.setCursor(Qt.CursorShape.CrossCursor if handler
                                          else Qt.CursorShape.ArrowCursor)

    def pick(self, x: float, y: float,
             modifiers: Qt.KeyboardModifier = Qt.KeyboardModifier.NoModifier) -> PickResult | None:
        """The visible mesh point under widget pixel (x, y) of the 3D view, or None.

        A ray cast (vtkCellPicker) gives the triangle; it can slip through exactly at a shared
        vertex and report a triangle behind. The depth buffer tells what is really visible there,
        so a ray hit behind the visible surface is replaced by the visible point and a triangle
        of its nearest vertex."""
        if self.mesh_actor is None or self.poly is None:
            return None
        if self._paint_timer.isActive() or self._paint_asked:
            self.render_now()  # the depth buffer must show the current geometry
        w = self.plotter.interactor
        dpr = w.devicePixelRatioF()
        xd, yd = x * dpr, (w.height() - 1 - y) * dpr
        ren = self.plotter.renderer
        self._picker.InitializePickList()
        self._picker.AddPickList(self.mesh_actor)
        ray_hit = self._picker.Pick(xd, yd, 0.0, ren) and self._picker.GetCellId() >= 0
        pos = np.array(self._picker.GetPickPosition(), dtype=np.float64) if ray_hit else None
        face = int(self._picker.GetCellId()) if ray_hit else -1
        z = ren.GetZ(int(round(xd)), int(round(yd)))
        if z < 1.0:
            ren.SetDisplayPoint(xd, yd, z)
            ren.DisplayToWorld()
            hw = np.array(ren.GetWorldPoint(), dtype=np.float64)
            visible = hw[:3] / (hw[3] if hw[3] != 0 else 1.0)
            P = np.asarray(self.poly.points)
            diag = float(np.linalg.norm(np.ptp(P, axis=0))) or 1.0
            cam = np.array(self.plotter.camera.position)
            d2 = ((P - visible) ** 2).sum(axis=1)
            v = int(np.argmin(d2))
            on_mesh = d2[v] < (0.05 * diag) ** 2
            behind = pos is None or (np.linalg.norm(pos - cam) - np.linalg.norm(visible - cam)
                                     > 1e-3 * diag)
            if on_mesh and behind:
                faces = np.flatnonzero((self._F == v).any(axis=1))
                cent = P[self._F[faces]].mean(axis=1)
                face = int(faces[np.argmin(((cent - visible) ** 2).sum(axis=1))])
                pos = visible
        if pos is None or face < 0:
            return None
        return PickResult(pos, face, (int(x), int(y)), modifiers)

    def project(self, points: np.ndarray) -> np.ndarray:
        """Widget pixel coordinates (k, 2) of world points (k, 3) (for tests and overlays)."""
        ren = self.plotter.renderer
        w = self.plotter.interactor
        dpr = w.devicePixelRatioF()
        out = np.empty((len(points), 2))
        for i, p in enumerate(np.asarray(points, dtype=np.float64)):
            ren.SetWorldPoint(p[0], p[1], p[2], 1.0)
            ren.WorldToDisplay()
            dx, dy, _ = ren.GetDisplayPoint()
            out[i] = dx / dpr, w.height() - 1 - dy / dpr
        return out

    def screen_to_world(self, x: float, y: float, reference: np.ndarray) -> np.ndarray:
        """The world point under widget pixel (x, y) on the plane through ``reference`` facing
        the camera (dragging a handle moves it in the view plane)."""
        ren = self.plotter.renderer
        w = self.plotter.interactor
        dpr = w.devicePixelRatioF()
        ref = np.asarray(reference, dtype=np.float64)
        ren.SetWorldPoint(ref[0], ref[1], ref[2], 1.0)
        ren.WorldToDisplay()
        depth = ren.GetDisplayPoint()[2]
        ren.SetDisplayPoint(x * dpr, (w.height() - 1 - y) * dpr, depth)
        ren.DisplayToWorld()
        p = np.array(ren.GetWorldPoint(), dtype=np.float64)
        return p[:3] / (p[3] if p[3] != 0 else 1.0)

    def show_points(self, points: np.ndarray | None, color: str = "#111111") -> None:
        """Draw marker dots at world points (k, 3) (e.g. root nodes); None removes them."""
        self.plotter.remove_actor("markers", render=False)
        if points is not None and len(points):
            self.plotter.add_mesh(pv.PolyData(np.asarray(points, dtype=np.float64)),
                                  name="markers", color=color, point_size=9,
                                  render_points_as_spheres=True, reset_camera=False,
                                  pickable=False, render=False)
        self.render()

    def show_overlay(self, V: np.ndarray | None, F: np.ndarray | None = None,
                     color: str = "#e8d2b0") -> None:
        """Show another triangle mesh with its edges *instead of* the document's mesh (e.g. a
        coarse level of a multigrid hierarchy, which lies partly inside the fine surface); None
        removes it and shows the document's mesh again."""
        self.plotter.remove_actor("overlay", render=False)
        if V is not None and F is not None and len(F):
            poly = pv.PolyData(np.asarray(V, dtype=np.float64), _faces_vtk(np.asarray(F)))
            self.plotter.add_mesh(poly, name="overlay", color=color, show_edges=True,
                                  edge_color="#8b1a1a", line_width=1.0, smooth_shading=False,
                                  reset_camera=False, pickable=False, render=False)
            if self.mesh_actor is not None:
                self.mesh_actor.SetVisibility(False)
        elif self.mesh_actor is not None:
            self.mesh_actor.SetVisibility(True)
        self.render()

    def show_handles(self, handles: dict | None) -> None:
        """Draw point handles: a sphere at each target, a line from its vertex to the target."""
        self.plotter.remove_actor(["handles", "handle_lines"], render=False)
        self.handles_actor = None
        if handles and self.poly is not None:
            verts = np.array(list(handles), dtype=np.int64)
            targets = np.array([handles[v] for v in verts], dtype=np.float64)
            self.handles_actor = self.plotter.add_mesh(
                pv.PolyData(targets), name="handles", color="#d62728", point_size=14,
                render_points_as_spheres=True, reset_camera=False, pickable=False, render=False)
            src = np.asarray(self.poly.points)[verts]
            lines = pv.line_segments_from_points(np.stack([src, targets], 1).reshape(-1, 3))
            self.plotter.add_mesh(lines, name="handle_lines", color="#d62728", line_width=2,
                                  reset_camera=False, pickable=False, render=False)
        self.render()

    # -- geometry ----------------------------------------------------------------------------
    def set_mesh(self, V: np.ndarray, F: np.ndarray, *, reset_camera: bool = True) -> None:
        """Show a new mesh (rebuilds the actor)."""
        self._F = np.asarray(F, dtype=np.int64)
        poly = pv.PolyData(np.asarray(V, dtype=np.float64), _faces_vtk(self._F))
        poly.point_data["Normals"] = vertex_normals(np.asarray(V, dtype=np.float64), self._F)
        poly.point_data.active_normals_name = "Normals"
        self.poly = poly
        # marker dots belong to the mesh they were put on (e.g. spectral coarsening's roots)
        self.plotter.remove_actor(["mesh", "overlay", "markers"], render=False)
        self.mesh_actor = self.plotter.add_mesh(
            poly, name="mesh", color=MESH_COLOR, smooth_shading=False, show_edges=self._edges,
            edge_color="#404040", line_width=0.5, specular=0.25, specular_power=20,
            scalars=None, reset_camera=False, render=False)
        self._apply_shading()
        self._field_name = None
        self._set_legend(None)
        if reset_camera:
            self._home_camera()
        self._set_samples()
        self.render()

    def update_points(self, V: np.ndarray) -> None:
        """Move the vertices of the shown mesh in place (streamed previews)."""
        if self.poly is None:
            return
        V = np.asarray(V, dtype=np.float64)
        if V.shape != (self.poly.n_points, 3):
            raise ValueError(f"expected {(self.poly.n_points, 3)} positions, got {V.shape}")
        self.poly.points = V
        self._normals_dirty = True  # computed once, just before the next redraw
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
                                                     scalars=None, render=False)
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
                   cmap: str = "viridis", clim: tuple[float, float] | None = None,
                   categorical: bool = False) -> None:
        """Colour the mesh by a scalar field (None: plain colour): one value per vertex, or one
        per triangle (then each triangle is drawn in one colour); or by colours: ``values`` of
        shape (n or m, 3), 0-255 RGB, drawn as they are. ``categorical`` per-vertex
        labels blend colours across a triangle instead of running through the colour map."""
        if self.poly is None or self.mesh_actor is None:
            return
        mapper = self.mesh_actor.mapper
        if name is None or values is None:
            mapper.scalar_visibility = False
            self._field_name = None
            self._set_legend(None)
        elif np.ndim(values) == 2 and np.shape(values)[1] == 3:
            # colours (0-255 RGB per vertex or per triangle), drawn as they are: no colour map
            rgb = np.clip(np.rint(np.asarray(values, dtype=np.float64)), 0, 255).astype(np.uint8)
            if len(rgb) == self.poly.n_points:
                self.poly.point_data[name] = rgb
                self.poly.point_data.active_scalars_name = name
                mapper.SetScalarModeToUsePointData()
            elif len(rgb) == self.poly.n_cells:
                self.poly.cell_data[name] = rgb
                self.poly.cell_data.active_scalars_name = name
                mapper.SetScalarModeToUseCellData()
            else:
                raise ValueError(f"colours need {self.poly.n_points} vertex or "
                                 f"{self.poly.n_cells} triangle rows, got {len(rgb)}")
            mapper.SetColorModeToDirectScalars()
            mapper.scalar_visibility = True
            self._field_name = name
            self._set_legend(None)
        else:
            mapper.SetColorModeToDefault()
            values = np.asarray(values, dtype=np.float64)
            if categorical and len(values) == self.poly.n_points and self._F is not None \
                    and len(self._F):
                # region labels: each triangle takes its first corner's label, so regions are
                # drawn in flat colours with sharp borders (no blended label colours); the
                # per-vertex labels stay readable in point_data
                self.poly.point_data.set_array(values, name)
                values = values[self._F[:, 0]]
            if len(values) == self.poly.n_points:
                self.poly.point_data[name] = values
                self.poly.point_data.active_scalars_name = name
                mapper.SetScalarModeToUsePointData()
            elif len(values) == self.poly.n_cells:
                self.poly.cell_data[name] = values
                self.poly.cell_data.active_scalars_name = name
                mapper.SetScalarModeToUseCellData()
            else:
                raise ValueError(f"a field needs {self.poly.n_points} vertex values or "
                                 f"{self.poly.n_cells} triangle values, got {len(values)}")
            lut = pv.LookupTable(cmap, nan_color="#9a9a9a")
            if clim:
                lo, hi = clim
            else:
                finite = values[np.isfinite(values)]
                lo, hi = ((float(finite.min()), float(finite.max())) if finite.size
                          else (0.0, 1.0))
            hi = hi if hi > lo else lo + 1.0
            lut.scalar_range = (lo, hi)
            mapper.lookup_table = lut
            mapper.scalar_range = (lo, hi)
            mapper.SetInterpolateScalarsBeforeMapping(not categorical)
            mapper.scalar_visibility = True
            self._field_name = name
            self._set_legend(None if categorical or name in NO_LEGEND else lut,
                             FIELD_TITLES.get(name, name.replace("_", " ")), (lo, hi))
        self.render()

    def shown_colors(self) -> np.ndarray | None:
        """(n, 3) uint8 RGB of each vertex as the colour view on screen paints it (the same
        lookup table, range and NaN colour), or None when no per-vertex colour view is shown."""
        shown = self.shown_field()
        if shown is None:
            return None
        from vtkmodules.util.numpy_support import numpy_to_vtk, vtk_to_numpy

        lut = self.mesh_actor.mapper.lookup_table
        rgba = lut.MapScalars(numpy_to_vtk(np.ascontiguousarray(shown[1])), 0, -1)
        return np.array(vtk_to_numpy(rgba)[:, :3], dtype=np.uint8)

    def shown_field(self) -> tuple[str, np.ndarray] | None:
        """(name, one value per vertex) of the colour view shown now; None when the mesh is
        plain or coloured per triangle."""
        name = self._field_name
        if self.poly is None or name is None or name not in self.poly.point_data:
            return None
        if not self.mesh_actor.mapper.scalar_visibility:
            return None
        return name, np.array(self.poly.point_data[name], dtype=np.float64)

    def _set_legend(self, lut, title: str = "", rng: tuple[float, float] | None = None) -> None:
        """The colour bar of the shown field: its title (with units) and its range; one bar,
        made once, shown for every colour view of this viewport (None hides it)."""
        if lut is None or not self.show_legend:
            if self.legend is not None:
                self.legend.SetVisibility(False)
            self.legend_title, self.legend_range = "", None
            return
        if self.legend is None:
            from vtkmodules.vtkRenderingAnnotation import vtkScalarBarActor

            bar = vtkScalarBarActor()
            bar.SetOrientationToHorizontal()
            bar.SetNumberOfLabels(5)
            bar.SetLabelFormat("%.3g")  # "-346", "0.5", "1e+03" (no dangling "346.")
            bar.GetPositionCoordinate().SetCoordinateSystemToNormalizedViewport()
            bar.GetPositionCoordinate().SetValue(0.30, 0.02)
            bar.SetWidth(0.45)
            bar.SetHeight(0.12)
            bar.SetBarRatio(0.28)
            bar.SetTextPositionToPrecedeScalarBar()  # labels under the bar, title above it
            bar.SetVerticalTitleSeparation(4)
            bar.UnconstrainedFontSizeOn()
            for prop in (bar.GetTitleTextProperty(), bar.GetLabelTextProperty()):
                prop.SetColor(0.08, 0.08, 0.1)
                prop.SetShadow(False)
                prop.SetBold(False)
                prop.SetItalic(False)
                prop.SetFontSize(13)
                font = legend_font_file()
                if font is not None:  # VTK's own Arial has no Greek: "λ scale" lost its λ
                    prop.SetFontFamilyAsString("File")
                    prop.SetFontFile(str(font))
            bar.SetPickable(False)
            self.plotter.renderer.AddViewProp(bar)
            self.legend = bar
        self.legend.SetLookupTable(lut)
        self.legend.SetTitle(title)
        self.legend.SetVisibility(True)
        self.legend_title, self.legend_range = title, (float(rng[0]), float(rng[1]))

    def _home_camera(self) -> None:
        # Most mesh files are Y-up: a three-quarter view from the front, Y pointing up.
        self.plotter.view_vector(HOME_VIEW_DIRECTION, viewup=(0.0, 1.0, 0.0))
        self.plotter.reset_camera()
        self.plotter.camera.zoom(1.15)

    def camera_pose(self) -> dict | None:
        """The camera as plain numbers (position, focal point, up; rounded), or None."""
        try:
            cam = self.plotter.camera
            r = lambda v: [round(float(x), 6) for x in v]  # noqa: E731
            return {"position": r(cam.position), "focal_point": r(cam.focal_point),
                    "up": r(cam.up)}
        except Exception:  # no render window yet / closed
            return None

    def reset_camera(self) -> None:
        self._home_camera()
        self.render()

    def fit_view(self) -> None:
        """Fit the whole mesh in the view, keeping the direction the user looks from (after the
        view changed size: Before / After split on or off)."""
        if self.poly is None:
            return
        self.plotter.reset_camera()
        self.plotter.camera.zoom(1.15)
        self.render()

    def set_label(self, text: str | None) -> None:
        """A caption at the top of the view ("Before", "After"); None removes it."""
        self.plotter.remove_actor("view_label", render=False)
        if text:
            actor = self.plotter.add_text(text, position="upper_edge", font_size=9,
                                          color="#222222", name="view_label")
            font = legend_font_file()
            if font is not None:
                prop = actor.GetTextProperty()
                prop.SetFontFamilyAsString("File")
                prop.SetFontFile(str(font))
        self.label_text = text or ""
        self.render()

    #: standard views of a Y-up mesh: (direction from the centre to the camera, up)
    STANDARD_VIEWS = {"front": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
                      "top": ((0.0, 1.0, 0.0), (0.0, 0.0, -1.0)),
                      "side": ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))}

    def standard_view(self, name: str) -> None:
        """Look at the whole mesh from the front (+Z), the top (+Y) or the right side (+X)."""
        direction, up = self.STANDARD_VIEWS[name]
        self.plotter.view_vector(direction, viewup=up)
        self.plotter.reset_camera()
        self.render()

    def set_orthographic(self, on: bool) -> None:
        """Parallel projection (no perspective: sizes compare across the view) or perspective."""
        if on:
            self.plotter.enable_parallel_projection()
        else:
            self.plotter.disable_parallel_projection()
        self.render()

    def link_camera(self, other: "Viewport") -> None:
        """Look through ``other``'s camera: both views show the same angle, zoom and pan, and
        moving one moves the other (before/after comparison)."""
        self.plotter.renderer.SetActiveCamera(other.plotter.renderer.GetActiveCamera())
        self.plotter.renderer.ResetCameraClippingRange()
        cam = other.plotter.renderer.GetActiveCamera()
        if getattr(self, "_link_observer", None) is None:
            def moved(*_):
                for vp in (self, other):
                    if vp.isVisible():
                        vp.render()
            self._link_observer = (cam, cam.AddObserver("ModifiedEvent", moved))
        self.render()

    def unlink_camera(self) -> None:
        link = getattr(self, "_link_observer", None)
        if link is not None:
            link[0].RemoveObserver(link[1])
            self._link_observer = None
            from vtkmodules.vtkRenderingCore import vtkCamera

            cam = vtkCamera()
            cam.DeepCopy(link[0])
            self.plotter.renderer.SetActiveCamera(cam)

    @property
    def orthographic(self) -> bool:
        return bool(self.plotter.camera.GetParallelProjection())

    def render(self) -> None:
        """Ask for a redraw (see the class docstring): soon, once, at most REDRAW_SHARE busy."""
        if self._paint_timer.isActive() or self._paint_asked:
            return
        idle_needed = self.render_seconds * (1.0 - REDRAW_SHARE) / REDRAW_SHARE
        wait = self._last_paint_end + idle_needed - time.perf_counter()
        self._paint_timer.start(max(0, int(wait * 1000)))

    def render_now(self) -> None:
        """Redraw at once (screenshots, picking)."""
        self._paint_timer.stop()
        self._before_paint()
        self.plotter.render()

    def set_streaming(self, on: bool) -> None:
        """While a job streams previews: no anti-aliasing (a redraw costs a third)."""
        self._streaming = bool(on)
        self._set_samples()

    def _set_samples(self) -> None:
        big = self.poly is not None and self.poly.n_cells > MSAA_MAX_FACES
        samples = 0 if (self._streaming or self.interacting or big) else MULTI_SAMPLES
        rw = self.plotter.ren_win
        if rw is not None and rw.GetMultiSamples() != samples:
            rw.SetMultiSamples(samples)
            self.render()

    def _on_vtk_render_end(self, *_args) -> None:
        if not self._in_our_paint:
            self._vtk_frame_ready = True

    # -- the camera moving: a light stand-in --------------------------------------------------
    def begin_interaction(self) -> None:
        """The user started turning / panning / zooming: until :meth:`end_interaction` redraws
        skip anti-aliasing, and a mesh of more than LOD_FACES triangles is drawn as a stand-in
        of about LOD_TARGET_FACES (its colours averaged), so the view follows the mouse."""
        if self.interacting:
            return
        self.interacting = True
        self._set_samples()
        if self.mesh_actor is None or self.poly is None or self.poly.n_cells <= LOD_FACES:
            return
        proxy = self._proxy_mesh()
        self.mesh_actor.mapper.SetInputData(proxy)

    def end_interaction(self) -> None:
        """The camera is still again: the full mesh, anti-aliased."""
        self._wheel_timer.stop()
        if not self.interacting:
            return
        self.interacting = False
        if self.mesh_actor is not None and self.poly is not None:
            self.mesh_actor.mapper.SetInputData(self.poly)
        self._set_samples()
        self.render()

    @property
    def drawn_triangles(self) -> int:
        """Triangles of what the mesh actor draws now (the stand-in while the camera moves)."""
        if self.mesh_actor is None:
            return 0
        return int(self.mesh_actor.GetMapper().GetInput().GetNumberOfCells())

    def _proxy_mesh(self) -> pv.PolyData:
        from app.lod import cluster_proxy

        key = (id(self.poly), id(self._F), len(self._F))
        if self._proxy is None or self._proxy_key != key:
            self._proxy = cluster_proxy(np.asarray(self.poly.points), self._F, LOD_TARGET_FACES)
            self._proxy_key = key
            self._proxy_poly = pv.PolyData(self._proxy.V, _faces_vtk(self._proxy.F))
        self._sync_proxy()
        return self._proxy_poly

    def _sync_proxy(self) -> None:
        """The stand-in's positions, normals and colour arrays from the shown mesh now."""
        proxy, poly, out = self._proxy, self.poly, self._proxy_poly
        if proxy is None or poly is None or out is None:
            return
        Vp = proxy.vertex_values(np.asarray(poly.points, dtype=np.float64))
        out.points = Vp
        for name in poly.point_data.keys():
            if name != "Normals":
                out.point_data[name] = proxy.vertex_values(np.asarray(poly.point_data[name]))
        for name in poly.cell_data.keys():
            out.cell_data[name] = proxy.face_values(np.asarray(poly.cell_data[name]))
        out.point_data["Normals"] = vertex_normals(Vp, proxy.F)
        out.point_data.active_normals_name = "Normals"
        active = poly.point_data.active_scalars_name
        if active is not None and active in out.point_data:
            out.point_data.active_scalars_name = active
        active = poly.cell_data.active_scalars_name
        if active is not None and active in out.cell_data:
            out.cell_data.active_scalars_name = active
        out.Modified()

    def _ask_paint(self) -> None:
        self._paint_asked = True
        self.plotter.update()

    def _before_paint(self) -> None:
        if self._normals_dirty and self.poly is not None:
            self._normals_dirty = False
            if self.interacting and self.drawn_triangles != self.poly.n_cells:
                self._sync_proxy()  # a job streams while the camera moves
            V = np.asarray(self.poly.points)
            self.poly.point_data["Normals"] = vertex_normals(V, self._F)
            self.poly.point_data.active_normals_name = "Normals"

    def _after_paint(self, t0: float, t1: float) -> None:
        self._paint_asked = False
        cost = t1 - t0
        self.redraws += 1
        self.redraw_seconds_total += cost
        self.render_seconds = cost if self.render_seconds == 0.0 else (
            0.7 * self.render_seconds + 0.3 * cost)
        self._last_paint_end = t1
        self.rendered.emit()

    def screenshot(self, path: str | None = None) -> np.ndarray:
        """Render and return the (h, w, 3) uint8 image; also write it as PNG when ``path`` is given."""
        self.render_now()
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
