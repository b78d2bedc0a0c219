"""The main window: viewport in the centre, method docks on the right, menus, status bar.

Owns the Qt-free :class:`~app.document.Document`, the QUndoStack (every edit is a
:class:`~app.commands.StateCommand`), the :class:`~app.jobs.JobRunner` and the settings.
Dialogs go through :mod:`app.dialogs` (patched in tests).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from PySide6.QtCore import QSettings, Qt, QTimer, Signal
from PySide6.QtGui import QAction, QKeySequence, QShortcut, QUndoStack
from PySide6.QtWidgets import (QLabel, QMainWindow, QProgressBar, QPushButton, QWidget)

from algorithms.errors import Stylize3DError
from algorithms.mesh import (SUPPORTED_READ, SUPPORTED_WRITE, clean_mesh, file_filter, read_mesh,
                             validate_mesh, write_mesh)
from algorithms.steps import Step
from app import dialogs
from app.commands import StateCommand
from app.document import Document
from app.jobs import JobRunner
from app.viewport import Viewport

APP_NAME = "Stylize3D"
MAX_RECENT = 8

#: Every key the app binds: (keys as the user reads them, " or " between alternatives; what
#: they do; the action's name in ``MainWindow.actions_by_name`` or None). The actions take their
#: shortcuts from here and the shortcut sheet (Help > Keyboard Shortcuts) is made from it, so the
#: two cannot disagree; tests/app/test_novice.py presses every key listed.
SHORTCUTS: list[tuple[str, str, str | None]] = [
    ("Ctrl+O", "Open a mesh (or drop a file on the window)", "open"),
    ("Ctrl+S", "Save", "save"),
    ("Ctrl+Shift+S", "Save as (another name or format)", "save_as"),
    ("Ctrl+Shift+E", "Export a screenshot of the 3D view", "screenshot"),
    ("Ctrl+Z", "Undo", "undo"),
    ("Ctrl+Shift+Z or Ctrl+Y", "Redo", "redo"),
    ("Ctrl+Shift+C", "Clean the mesh (duplicates, degenerate triangles, ...)", "clean"),
    ("Esc", "Stop the running job (the mesh goes back to how it was)", None),
    ("R", "Reset the camera", "reset_camera"),
    ("W", "Show / hide edges", "wireframe"),
    ("F", "Flat / smooth shading", "flat"),
    ("G", "Show the original mesh as a ghost", "ghost"),
    ("F1", "This list of shortcuts", "shortcuts"),
    ("Ctrl+Q", "Quit", "quit"),
]


def shortcut_keys(action: str) -> list[QKeySequence]:
    """The key sequences of ``action`` in :data:`SHORTCUTS` (empty when it has none)."""
    for keys, _what, name in SHORTCUTS:
        if name == action:
            return [QKeySequence(k.strip()) for k in keys.split(" or ")]
    return []


SHORTCUTS_TEXT = ("<table>" + "".join(
    f"<tr><td><b>{keys.replace(' or ', ' / ')}</b></td><td>{what}</td></tr>"
    for keys, what, _name in SHORTCUTS)
    + "<tr><td><b>Mouse</b></td><td>Left drag: rotate · Right drag / wheel: zoom · Middle drag "
      "or Shift+left: pan</td></tr></table>")


class MainWindow(QMainWindow):
    """See the module docstring. ``mesh_shown`` is emitted after a mesh is opened and drawn."""

    mesh_shown = Signal()
    #: (job name, the document state the job's result created) after a job's command is pushed
    job_committed = Signal(str, object)

    def __init__(self, settings: QSettings | None = None):
        super().__init__()
        self.settings = settings or QSettings(APP_NAME, APP_NAME)
        self.document = Document()
        self.undo_stack = QUndoStack(self)
        self.runner = JobRunner(self)
        self.last_job_name: str | None = None
        self._job_before = None
        self._ever_saved_here: set[str] = set()

        self.viewport = Viewport(self)
        self.setCentralWidget(self.viewport)
        self.setAcceptDrops(True)
        self.setDockOptions(QMainWindow.DockOption.AnimatedDocks | QMainWindow.DockOption.AllowTabbedDocks)

        self._build_actions()
        self._build_menus()
        self._build_status_bar()
        self._build_panels()

        self.document.subscribe(self._on_document_changed)
        self.undo_stack.cleanChanged.connect(self._on_clean_changed)
        self.runner.preview.connect(self._on_preview)
        self.runner.finished.connect(self._on_job_finished)
        self.runner.cancelled.connect(self._on_job_cancelled)
        self.runner.failed.connect(self._on_job_failed)
        self.runner.busy_changed.connect(self._on_busy_changed)
        self.runner.progress.connect(self._on_progress)

        self.resize(1280, 800)
        geo = self.settings.value("window/geometry")
        if geo is not None:
            self.restoreGeometry(geo)
        state = self.settings.value("window/state")
        if state is not None:  # a layout saved with another set of panels is ignored
            self.restoreState(state, self._layout_version())
        self._update_title()
        self._update_stats()

    # ------------------------------------------------------------------------------ building
    def _action(self, name: str, text: str, slot, checkable=False, tip="") -> QAction:
        """An action named ``name``; its keys come from :data:`SHORTCUTS`."""
        a = QAction(text, self)
        keys = shortcut_keys(name)
        if keys:
            a.setShortcuts(keys)
        a.setCheckable(checkable)
        if tip:
            a.setStatusTip(tip)
            a.setToolTip(tip)
        (a.toggled if checkable else a.triggered).connect(slot)
        self.actions_by_name[name] = a
        return a

    def _build_actions(self) -> None:
        self.actions_by_name: dict[str, QAction] = {}
        A = self._action
        A("open", "&Open…", lambda: self.open_dialog(), tip="Open a mesh file (OBJ, PLY, STL, OFF)")
        A("save", "&Save", lambda: self.save(), tip="Save the mesh")
        A("save_as", "Save &As…", lambda: self.save_as(),
          tip="Save the mesh under a new name or format (OBJ, PLY, STL, OFF, glTF .glb)")
        A("screenshot", "Export &Screenshot…", lambda: self.export_screenshot_dialog(),
          tip="Save the 3D view as a PNG image")
        A("quit", "&Quit", self.close)
        undo = self.undo_stack.createUndoAction(self, "&Undo")
        undo.setShortcuts(shortcut_keys("undo"))
        # one binding per key: StandardKey.Redo already is Ctrl+Shift+Z on Linux, and a key
        # bound twice is "ambiguous" to Qt and does nothing
        redo = self.undo_stack.createRedoAction(self, "&Redo")
        redo.setShortcuts(shortcut_keys("redo"))
        self.actions_by_name["undo"], self.actions_by_name["redo"] = undo, redo
        A("clean", "&Clean Mesh", lambda: self.clean_mesh(),
          tip="Fix duplicate or loose vertices, degenerate or extra triangles, flipped triangles "
              "(undoable; says what it changed)")
        A("reset_camera", "&Reset Camera", lambda: self.viewport.reset_camera(),
          tip="Look at the whole mesh from the front, three-quarter view (R)")
        A("wireframe", "Show &Edges", self.viewport.set_wireframe, checkable=True,
          tip="Draw the triangle edges on the surface")
        A("flat", "&Flat Shading", self.viewport.set_flat_shading,
          checkable=True, tip="Shade each triangle with one colour (shows facets)")
        A("ghost", "Show &Original as Ghost", self._toggle_ghost,
          checkable=True, tip="Overlay the mesh as it was when opened, translucent")
        A("about", "&About Stylize3D", self.show_about)
        A("shortcuts", "&Keyboard Shortcuts", self.show_shortcuts)

    def _build_menus(self) -> None:
        a = self.actions_by_name
        mb = self.menuBar()
        m = mb.addMenu("&File")
        m.addAction(a["open"])
        self.recent_menu = m.addMenu("Open &Recent")
        self.recent_menu.aboutToShow.connect(self._fill_recent_menu)
        m.addSeparator()
        m.addAction(a["save"])
        m.addAction(a["save_as"])
        m.addAction(a["screenshot"])
        m.addSeparator()
        m.addAction(a["quit"])
        m = mb.addMenu("&Edit")
        m.addAction(a["undo"])
        m.addAction(a["redo"])
        m.addSeparator()
        m.addAction(a["clean"])
        m = mb.addMenu("&View")
        for name in ("reset_camera", "wireframe", "flat", "ghost"):
            m.addAction(a[name])
        self.panels_menu = m.addMenu("&Panels")
        m = mb.addMenu("&Help")
        m.addAction(a["shortcuts"])
        m.addAction(a["about"])
        self._fill_recent_menu()

    def _build_status_bar(self) -> None:
        sb = self.statusBar()
        self.stats_label = QLabel()
        self.stats_label.setToolTip("Vertices, triangles, boundary loops and genus of the open mesh")
        sb.addPermanentWidget(self.stats_label)
        self.progress_bar = QProgressBar()
        self.progress_bar.setMaximumWidth(220)
        self.progress_bar.setTextVisible(True)
        self.progress_bar.setVisible(False)
        sb.addPermanentWidget(self.progress_bar)
        self.cancel_button = QPushButton("Cancel (Esc)")
        self.cancel_button.setToolTip("Stop the running job; the mesh goes back to how it was")
        self.cancel_button.setVisible(False)
        self.cancel_button.clicked.connect(self.cancel_job)
        sb.addPermanentWidget(self.cancel_button)
        self._esc = QShortcut(QKeySequence(Qt.Key.Key_Escape), self)
        self._esc.setContext(Qt.ShortcutContext.ApplicationShortcut)
        self._esc.activated.connect(self.cancel_job)

    def _layout_version(self) -> int:
        import zlib

        return zlib.crc32(",".join(self.panels).encode()) & 0x7FFFFFFF

    def _build_panels(self) -> None:
        from app.panels.analogies import AnalogiesPanel
        from app.panels.cubic import CubicPanel
        from app.panels.multigrid import MultigridPanel
        from app.panels.smooth import SmoothPanel
        from app.panels.spectral import SpectralPanel
        from app.panels.subdivision import SubdivisionPanel

        self.panels = {}
        for cls in (CubicPanel, AnalogiesPanel, SmoothPanel, MultigridPanel, SpectralPanel,
                    SubdivisionPanel):
            panel = cls(self)
            self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, panel)
            self.panels[cls.title] = panel
            self.panels_menu.addAction(panel.toggleViewAction())
        docks = list(self.panels.values())
        for other in docks[1:]:
            self.tabifyDockWidget(docks[0], other)
        docks[0].raise_()

    # ------------------------------------------------------------------------------ files
    def _last_dir(self) -> str:
        return str(self.settings.value("files/last_dir", "") or "")

    def recent_files(self) -> list[str]:
        v = self.settings.value("files/recent", [])
        if isinstance(v, str):
            v = [v]
        return [str(p) for p in (v or [])]

    def _add_recent(self, path: str) -> None:
        path = str(Path(path).resolve())
        rec = [p for p in self.recent_files() if p != path]
        self.settings.setValue("files/recent", [path] + rec[: MAX_RECENT - 1])
        self.settings.setValue("files/last_dir", str(Path(path).parent))

    def _fill_recent_menu(self) -> None:
        self.recent_menu.clear()
        rec = self.recent_files()
        if not rec:
            a = self.recent_menu.addAction("(no recent files)")
            a.setEnabled(False)
            return
        for p in rec:
            a = self.recent_menu.addAction(p)
            a.triggered.connect(lambda _=False, p=p: self.open_path(p))

    def _confirm_discard(self) -> bool:
        if not self.document.modified:
            return True
        return dialogs.confirm(self, "Unsaved changes",
                               f"{self.document.path.name if self.document.path else 'The mesh'} "
                               "has changes that are not saved. Discard them?",
                               yes="Discard changes", no="Cancel")

    def open_dialog(self) -> bool:
        path = dialogs.open_file(self, "Open mesh", file_filter(), self._last_dir())
        return self.open_path(path) if path else False

    def open_path(self, path: str | os.PathLike) -> bool:
        """Open a mesh file. On any problem the user gets a plain message and the open document
        stays as it was. Returns True when the mesh was opened."""
        path = str(path)
        if self.runner.busy:
            dialogs.error(self, "A job is running", "Stop the running job (Esc) before opening a file.")
            return False
        try:
            data = read_mesh(path)
        except Stylize3DError as e:
            dialogs.error(self, "Cannot open mesh", str(e))
            return False
        V, F, notes = data.V, data.F, list(data.notes)
        report = validate_mesh(V, F, notes=notes)
        if report.errors or report.needs_cleaning:
            fixable = all(i.fixable for i in report.errors)
            text = (f"{Path(path).name} has problems:\n\n{report.summary()}")
            if fixable:
                choices = ["Clean and open"] + ([] if report.errors else ["Open as it is"]) + ["Cancel"]
                choice = dialogs.choose(self, "Mesh problems", text + "\n\n'Clean and open' fixes "
                                        "them and tells you what it changed; your file is not "
                                        "modified.", choices, default="Clean and open")
                if choice == "Clean and open":
                    res = clean_mesh(V, F)
                    V, F = res.V, res.F
                    notes += list(res.actions)
                    report = validate_mesh(V, F, notes=notes)
                    if report.errors:
                        dialogs.error(self, "Cannot open mesh",
                                      f"Cleaning could not fix everything:\n\n{report.summary()}")
                        return False
                elif choice != "Open as it is":
                    return False
            else:
                dialogs.error(self, "Cannot open mesh", text + "\n\nThese problems cannot be "
                              "fixed automatically; repair the file in a mesh editor.")
                return False
        if not self._confirm_discard():
            return False
        self.undo_stack.clear()
        self.document.load(V, F, path, report)
        self.undo_stack.setClean()
        self._add_recent(path)
        msg = f"Opened {Path(path).name}: {len(V):,} vertices, {len(F):,} triangles."
        if notes:
            msg += " " + " ".join(notes)
        self.statusBar().showMessage(msg, 8000)
        return True

    def _write(self, path: str) -> bool:
        try:
            write_mesh(path, self.document.V, self.document.F)
        except Stylize3DError as e:
            dialogs.error(self, "Could not save", str(e))
            return False
        except OSError as e:  # pragma: no cover - write_mesh wraps these
            dialogs.error(self, "Could not save", f"{path}: {e.strerror or e}")
            return False
        self._ever_saved_here.add(str(Path(path).resolve()))
        if Path(path).suffix.lower() in SUPPORTED_READ:
            self.document.mark_saved(path)
            self.undo_stack.setClean()
            self._add_recent(path)
        self.statusBar().showMessage(f"Saved {path}", 5000)
        self._update_title()
        return True

    def _may_overwrite(self, path: str) -> bool:
        p = Path(path)
        if not p.exists() or str(p.resolve()) in self._ever_saved_here:
            return True
        return dialogs.confirm(self, "Replace file?", f"{p.name} already exists in {p.parent}.\n"
                               "Do you want to replace it?", yes="Replace", no="Cancel")

    def save(self) -> bool:
        if self.document.is_empty:
            return False
        if self.document.path is None:
            return self.save_as()
        path = str(self.document.path)
        if not self._may_overwrite(path):
            return False
        return self._write(path)

    def save_as(self) -> bool:
        if self.document.is_empty:
            return False
        exts = " ".join(f"*{e}" for e in SUPPORTED_WRITE)
        path = dialogs.save_file(self, "Save mesh as", f"Meshes ({exts})", self._last_dir())
        if not path:
            return False
        if Path(path).suffix.lower() not in SUPPORTED_WRITE:
            path += ".obj"
        if not self._may_overwrite(path):
            return False
        return self._write(path)

    def export_screenshot_dialog(self) -> bool:
        path = dialogs.save_file(self, "Export screenshot", "PNG image (*.png)", self._last_dir())
        if not path:
            return False
        if not path.lower().endswith(".png"):
            path += ".png"
        if not self._may_overwrite(path):
            return False
        return self.export_screenshot(path)

    def export_screenshot(self, path: str) -> bool:
        tmp = f"{path}.part.png"
        try:
            self.viewport.screenshot(tmp)
            os.replace(tmp, path)
        except Exception as e:
            if os.path.exists(tmp):
                os.remove(tmp)
            dialogs.error(self, "Could not export screenshot", f"{path}: {e}")
            return False
        self._ever_saved_here.add(str(Path(path).resolve()))
        self.statusBar().showMessage(f"Screenshot saved to {path}", 5000)
        return True

    def save_window_image(self, path: str) -> bool:
        """A PNG of the whole window (menus, panels, status bar) with the 3D view composited in
        (the OpenGL view is rendered off the widget tree, so it is painted from its own frame)."""
        from PySide6.QtGui import QImage, QPainter

        pix = self.grab()
        img = self.viewport.screenshot()
        h, w = img.shape[:2]
        buf = np.ascontiguousarray(img[..., :3])
        view = QImage(buf.data, w, h, 3 * w, QImage.Format.Format_RGB888).copy()
        painter = QPainter(pix)
        top_left = self.viewport.mapTo(self, self.viewport.rect().topLeft())
        target = self.viewport.rect().translated(top_left)
        painter.drawImage(target, view)
        painter.end()
        tmp = f"{path}.part.png"
        if not pix.save(tmp, "PNG"):
            return False
        os.replace(tmp, path)
        return True

    # ------------------------------------------------------------------------------ edits
    def clean_mesh(self) -> bool:
        """Edit > Clean Mesh: one undoable command; tells the user what it changed."""
        doc = self.document
        if doc.is_empty or self.runner.busy:
            return False
        try:
            res = clean_mesh(doc.V, doc.F)
        except Stylize3DError as e:
            dialogs.error(self, "Cannot clean the mesh", str(e))
            return False
        changed = res.V.shape != doc.V.shape or res.F.shape != doc.F.shape or not (
            np.array_equal(res.F, doc.F) and np.array_equal(res.V, doc.V))
        if not changed:
            dialogs.info(self, "Clean mesh", "\n".join(res.actions))
            return False
        before = doc.state
        after = doc.remapped(res.V, res.F, res.vertex_map)
        self.undo_stack.push(StateCommand(doc, before, after, "Clean mesh"))
        dialogs.info(self, "Clean mesh", "\n".join(res.actions) + "\n\nUndo with Ctrl+Z.")
        return True

    # ------------------------------------------------------------------------------ jobs
    def start_positions_job(self, name: str, factory, merge_id: int = -1, commit=None) -> None:
        """Run a Step generator whose vertices replace the document's positions when it ends.
        With ``merge_id`` > 0, the result merges with a directly preceding command of the same id
        into one undo step (live re-runs). ``commit(before, last_step) -> MeshState`` makes the
        new document state instead (e.g. a job whose result is a per-vertex field); by default
        it is ``before`` with the last step's positions."""
        if self.document.is_empty:
            return
        self.last_job_name = name
        self._job_before = self.document.state
        self._job_merge_id = merge_id
        self._job_kind = "positions"
        self._job_commit = commit
        self.runner.start(name, factory)

    def start_analysis_job(self, name: str, factory) -> None:
        """Run a Step generator that only computes (spectral analysis, ...): progress, plots and
        cancel as usual, but the document and the viewport's shape are never changed."""
        if self.document.is_empty:
            return
        self.last_job_name = name
        self._job_before = None
        self._job_kind = "analysis"
        self.runner.start(name, factory)

    def cancel_job(self) -> None:
        if self.runner.busy:
            self.runner.cancel()

    def _on_preview(self, step: Step) -> None:
        if getattr(self, "_job_kind", "positions") == "analysis":
            return
        if self.document.state is not None and step.V.shape == self.document.V.shape:
            self.viewport.update_points(step.V)

    def _on_progress(self, it: int, total, message: str) -> None:
        if total:
            self.progress_bar.setRange(0, int(total))
            self.progress_bar.setValue(int(it))
            self.progress_bar.setFormat(f"{self.runner.name}: %v/%m")
        else:
            self.progress_bar.setRange(0, 0)
            self.progress_bar.setFormat(f"{self.runner.name}: {it}")

    def _on_busy_changed(self, busy: bool) -> None:
        self.progress_bar.setVisible(busy)
        self.cancel_button.setVisible(busy)
        if busy:
            self.progress_bar.setRange(0, 0)
        for name in ("open", "save", "save_as", "undo", "redo", "clean"):
            self.actions_by_name[name].setEnabled(not busy)
        if not busy:
            self.actions_by_name["undo"].setEnabled(self.undo_stack.canUndo())
            self.actions_by_name["redo"].setEnabled(self.undo_stack.canRedo())
        self.recent_menu.setEnabled(not busy)

    def _restore_view(self) -> None:
        if self.document.state is not None:
            self.viewport.update_points(self.document.V)

    def _on_job_finished(self, step: Step) -> None:
        if getattr(self, "_job_kind", "positions") == "analysis":
            self.statusBar().showMessage(f"{self.last_job_name} finished in "
                                         f"{self.runner.last_duration:.2f} s.", 8000)
            return
        before = self._job_before
        if before is None or self.document.state is not before:
            self._restore_view()
            return
        if step.V.shape != before.V.shape or not np.isfinite(step.V).all():
            self._restore_view()
            dialogs.error(self, f"{self.last_job_name} failed",
                          "The method returned an invalid result; your mesh was not changed.")
            return
        commit = getattr(self, "_job_commit", None)
        after = before.with_positions(step.V) if commit is None else commit(before, step)
        self.undo_stack.push(StateCommand(self.document, before, after, self.last_job_name,
                                          merge_id=getattr(self, "_job_merge_id", -1)))
        self._job_before = None
        self.job_committed.emit(self.last_job_name, after)
        self.statusBar().showMessage(
            f"{self.last_job_name} finished in {self.runner.last_duration:.2f} s "
            f"({step.iteration} iterations). Undo with Ctrl+Z.", 8000)

    def _on_job_cancelled(self, message: str) -> None:
        if not self.runner.busy:  # a restarted (live) job keeps streaming instead
            self._restore_view()
        self.statusBar().showMessage(message + " The mesh is as it was.", 5000)

    def _on_job_failed(self, message: str, details: str) -> None:
        self._restore_view()
        dialogs.error(self, f"{self.last_job_name or 'Job'} failed",
                      message + "\n\nYour mesh is as it was before the job.", details or None)

    # ------------------------------------------------------------------------------ document
    def _on_document_changed(self, what: str) -> None:
        doc = self.document
        if what == "mesh":
            self.viewport.set_mesh(doc.V, doc.F)
            self._refresh_ghost()
            self._update_stats()
            self.mesh_shown.emit()
        elif what == "topology":
            doc.report = validate_mesh(doc.V, doc.F)
            self.viewport.set_mesh(doc.V, doc.F, reset_camera=False)
            self._update_stats()
        elif what == "positions":
            self.viewport.update_points(doc.V)
        self._update_title()

    def _on_clean_changed(self, clean: bool) -> None:
        self.document.modified = not clean
        self._update_title()

    def _update_title(self) -> None:
        t = self.document.title.removesuffix(" *")
        self.setWindowTitle(f"{t}[*] — {APP_NAME}" if t else f"{APP_NAME}[*]")
        self.setWindowModified(self.document.modified)

    def _update_stats(self) -> None:
        r = self.document.report
        if self.document.is_empty or r is None:
            self.stats_label.setText("No mesh open — File > Open or drop a mesh file here.")
            return
        s = r.stats
        genus = "—" if s.get("genus") is None else s["genus"]
        text = (f"V {s['vertices']:,}   F {s['faces']:,}   boundary loops {s['boundary_loops']}   "
                f"genus {genus}   components {s['components']}")
        problems = len(r.errors) + len(r.warnings)
        if problems:
            hint = "Edit > Clean Mesh" if r.needs_cleaning else "Clean cannot fix it: see tooltip"
            text += f"   ⚠ {problems} problem{'s' if problems > 1 else ''} ({hint})"
            self.stats_label.setToolTip(r.summary())
        else:
            self.stats_label.setToolTip("Vertices, triangles, boundary loops and genus of the open mesh")
        self.stats_label.setText(text)

    def _toggle_ghost(self, on: bool) -> None:
        self._refresh_ghost()

    def _refresh_ghost(self) -> None:
        if self.actions_by_name["ghost"].isChecked() and self.document.original is not None:
            self.viewport.set_ghost(self.document.original.V, self.document.original.F)
        else:
            self.viewport.set_ghost(None)

    # ------------------------------------------------------------------------------ help
    def show_about(self) -> None:
        dialogs.info(self, "About Stylize3D",
                     "Stylize3D — stylize and process 3D surface meshes.\n\n"
                     "Cubic stylization, shape analogies, Paparazzi, neural subdivision, spectral "
                     "coarsening and surface multigrid, after one PhD thesis on data-driven "
                     "geometric stylization and scalable geometry processing.")

    def show_shortcuts(self) -> None:
        dialogs.info(self, "Keyboard shortcuts", SHORTCUTS_TEXT)

    # ------------------------------------------------------------------------------ Qt events
    def dragEnterEvent(self, event) -> None:  # noqa: N802
        urls = event.mimeData().urls() if event.mimeData().hasUrls() else []
        if any(Path(u.toLocalFile()).suffix.lower() in SUPPORTED_READ for u in urls):
            event.acceptProposedAction()
        else:
            event.ignore()

    def dropEvent(self, event) -> None:  # noqa: N802
        for u in event.mimeData().urls():
            p = u.toLocalFile()
            if Path(p).suffix.lower() in SUPPORTED_READ:
                event.acceptProposedAction()
                QTimer.singleShot(0, lambda p=p: self.open_path(p))
                return
        event.ignore()

    def closeEvent(self, event) -> None:  # noqa: N802
        if not self._confirm_discard():
            event.ignore()
            return
        for panel in self.panels.values():
            panel.shutdown()
        self.runner.shutdown()
        self.settings.setValue("window/geometry", self.saveGeometry())
        self.settings.setValue("window/state", self.saveState(self._layout_version()))
        self.settings.sync()
        for vp in self.findChildren(Viewport):  # the main view and panel views (Gauss map)
            vp.close_plotter()
        event.accept()
