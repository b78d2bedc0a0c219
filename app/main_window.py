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
from PySide6.QtWidgets import (QDockWidget, QLabel, QMainWindow, QProgressBar, QPushButton,
                               QWidget)

from algorithms.errors import Stylize3DError
from algorithms.mesh import (SUPPORTED_READ, SUPPORTED_WRITE, clean_mesh, file_filter, read_mesh,
                             validate_mesh, write_mesh)
from algorithms.steps import Step
from app import __version__, dialogs, gc_guard
from app.commands import StateCommand
from app.document import Document
from app.jobs import JobRunner
from app.viewport import Viewport
from app.widgets import MessageLog, dock_view_action, plural

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
    ("1", "Front view", "view_front"),
    ("7", "Top view", "view_top"),
    ("3", "Side view", "view_side"),
    ("5", "Orthographic / perspective view", "orthographic"),
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
    #: (the triangles checked, their MeshReport or the exception) from the background check
    _report_ready = Signal(object, object)
    #: triangles above which a changed mesh is checked (validate_mesh) off the GUI thread: 38 ms
    #: at 29k triangles (armadillo: with the redraw, Paparazzi's result froze the window 110 ms),
    #: 1 s at 467k (a subdivided armadillo)
    ASYNC_VALIDATE_FACES = 20_000

    def __init__(self, settings: QSettings | None = None):
        super().__init__()
        from algorithms import offload

        # compiled calls that keep Python's lock (remeshing, exact intersection tests, CHOLMOD
        # refactorizations every step) would freeze this window while a job runs
        offload.keep_lock_free(True)
        # cyclic garbage (which may hold Qt and VTK objects) is collected on this thread only
        gc_guard.acquire()
        self._gc_acquired = True
        self.settings = settings or QSettings(APP_NAME, APP_NAME)
        self.document = Document()
        self.undo_stack = QUndoStack(self)
        self.runner = JobRunner(self)
        self.last_job_name: str | None = None
        self._job_before = None
        self._ever_saved_here: set[str] = set()
        self.project_path: Path | None = None  # the .s3d file the document came from / went to

        self.viewport = Viewport(self)
        # View > Before / After: the mesh as opened, side by side, through the same camera
        from PySide6.QtWidgets import QSplitter

        self.central_split = QSplitter(Qt.Orientation.Horizontal)
        self.before_view: Viewport | None = None
        self.central_split.addWidget(self.viewport)
        self.setCentralWidget(self.central_split)
        self.setAcceptDrops(True)
        self.setDockOptions(QMainWindow.DockOption.AnimatedDocks | QMainWindow.DockOption.AllowTabbedDocks)

        self._build_actions()
        self._build_menus()
        self._build_status_bar()
        self._build_toolbar()
        self._build_panels()

        self.document.subscribe(self._on_document_changed)
        self.undo_stack.cleanChanged.connect(self._on_clean_changed)
        self.runner.preview.connect(self._on_preview)
        self.runner.finished.connect(self._on_job_finished)
        self.runner.cancelled.connect(self._on_job_cancelled)
        self.runner.failed.connect(self._on_job_failed)
        self.runner.busy_changed.connect(self._on_busy_changed)
        self.runner.progress.connect(self._on_progress)
        # the unsaved work is kept in a recovery slot while it changes (app/autosave.py)
        from app.autosave import Autosaver

        self.autosave = Autosaver(self)

        self.resize(1280, 800)
        geo = self.settings.value("window/geometry")
        if geo is not None:
            self.restoreGeometry(geo)
        state = self.settings.value("window/state")
        self._layout_restored = False
        if state is not None:  # a layout saved with another set of panels is ignored
            self._layout_restored = bool(self.restoreState(state, self._layout_version()))
        self._panel_tabs_fitted = False
        self._report_ready.connect(self._on_report_ready)
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
        A("open_project", "Open &Project…", lambda: self.open_project_dialog(),
          tip="Open a Stylize3D project (.s3d): the mesh with everything painted and placed, "
              "and every panel's settings")
        A("save_project", "Save Pro&ject As…", lambda: self.save_project_dialog(),
          tip="Save the mesh, what you painted and placed (λ, fixed regions, planes, handles, "
              "capture sphere, loaded images and styles) and every panel's settings in one "
              ".s3d file; `stylize3d cubic scene.s3d -o out.obj` re-makes the result")
        A("screenshot", "Export &Screenshot…", lambda: self.export_screenshot_dialog(),
          tip="Save the 3D view as a PNG image")
        A("export_field", "Export Shown &Field…", lambda: self.export_field_dialog(),
          tip="Save the values of the colour view shown now, one per vertex (.txt, .csv, .npy)")
        A("export_colored", "Export &Coloured Mesh…", lambda: self.export_colored_dialog(),
          tip="Save the mesh with the colour view shown now as vertex colours (.ply, .obj), "
              "to show it in another program")
        A("batch", "&Batch…", lambda: self.show_batch(),
          tip="Apply a panel's current settings to a whole folder of meshes, with progress "
              "and Stop (the window stays usable; a stopped batch continues when started again)")
        A("study", "Start &Study Session…", lambda: self.start_study_dialog(),
          tip="Run a user-study protocol (.json / .toml): tasks, locked panels, a log of every "
              "action (docs/study.md)")
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
        A("before_after", "&Before / After", self.show_before_after, checkable=True,
          tip="The mesh as it was opened next to the current one, seen through one camera")
        A("ghost", "Show &Original as Ghost", self._toggle_ghost,
          checkable=True, tip="Overlay the mesh as it was when opened, translucent")
        for key, text in (("front", "&Front View"), ("top", "&Top View"),
                          ("side", "&Side View")):
            A(f"view_{key}", text, lambda _=False, key=key: self.viewport.standard_view(key),
              tip=f"Look at the whole mesh from the {key}")
        A("orthographic", "&Orthographic", self.viewport.set_orthographic, checkable=True,
          tip="Parallel projection: no perspective, so sizes compare across the view")
        A("welcome", "&Welcome…", lambda: self.show_welcome(),
          tip="Open a sample mesh or your own file, with a suggestion of what to try first")
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
        m.addAction(a["open_project"])
        m.addSeparator()
        m.addAction(a["save"])
        m.addAction(a["save_as"])
        m.addAction(a["save_project"])
        m.addAction(a["screenshot"])
        m.addAction(a["export_field"])
        m.addAction(a["export_colored"])
        m.addSeparator()
        m.addAction(a["batch"])
        m.addAction(a["study"])
        m.addSeparator()
        m.addAction(a["quit"])
        m = mb.addMenu("&Edit")
        m.addAction(a["undo"])
        m.addAction(a["redo"])
        m.addSeparator()
        m.addAction(a["clean"])
        m = mb.addMenu("&View")
        for name in ("reset_camera", "view_front", "view_top", "view_side", "orthographic",
                     "wireframe", "flat", "ghost", "before_after"):
            m.addAction(a[name])
        self.panels_menu = m.addMenu("&Panels")
        self.view_menu = m
        m = mb.addMenu("&Help")
        m.addAction(a["welcome"])
        m.addAction(a["shortcuts"])
        m.addAction(a["about"])
        self._fill_recent_menu()

    def _build_toolbar(self) -> None:
        """The common actions as icons (the same actions as the menus)."""
        from PySide6.QtGui import QFontMetrics
        from PySide6.QtWidgets import QStyle, QToolBar

        tb = QToolBar("Toolbar", self)
        tb.setObjectName("toolbar_main")
        tb.setMovable(False)
        tb.setToolButtonStyle(Qt.ToolButtonStyle.ToolButtonTextUnderIcon)
        style = self.style()
        icons = {"open": QStyle.StandardPixmap.SP_DialogOpenButton,
                 "save": QStyle.StandardPixmap.SP_DialogSaveButton,
                 "undo": QStyle.StandardPixmap.SP_ArrowBack,
                 "redo": QStyle.StandardPixmap.SP_ArrowForward,
                 "reset_camera": QStyle.StandardPixmap.SP_BrowserReload,
                 "screenshot": QStyle.StandardPixmap.SP_DesktopIcon,
                 "ghost": QStyle.StandardPixmap.SP_TitleBarShadeButton}
        labels = {"reset_camera": "Reset view", "screenshot": "Screenshot", "ghost": "Ghost",
                  "before_after": "Before/After",
                  "view_front": "Front", "view_top": "Top", "view_side": "Side",
                  "orthographic": "Ortho"}
        groups = (("open", "save"), ("undo", "redo"), ("reset_camera", "view_front", "view_top",
                                                      "view_side", "orthographic", "ghost",
                                                      "before_after"),
                  ("screenshot",))
        self.toolbar_buttons = {}
        for i, group in enumerate(groups):
            if i:
                tb.addSeparator()
            for name in group:
                a = self.actions_by_name[name]
                if name in icons:
                    a.setIcon(style.standardIcon(icons[name]))
                if name in labels:
                    a.setIconText(labels[name])
                keys = a.shortcut().toString()
                if keys and keys not in a.toolTip():
                    a.setToolTip(f"{a.toolTip() or a.text().replace('&', '')} ({keys})")
                tb.addAction(a)
                self.toolbar_buttons[name] = tb.widgetForAction(a)
        # Undo / Redo name the step ("Undo Cubic") in a button of one fixed width, the name
        # shortened with "…" when long: the buttons after them no longer jump as it changes
        for name, prefix, signal in (("undo", "Undo", self.undo_stack.undoTextChanged),
                                     ("redo", "Redo", self.undo_stack.redoTextChanged)):
            b = self.toolbar_buttons[name]
            width = b.fontMetrics().horizontalAdvance(f"{prefix} Spectral coarsening") + 16
            b.setFixedWidth(width)
            a = self.actions_by_name[name]

            def show(text, a=a, fm=QFontMetrics(b.font()), prefix=prefix, width=width):
                import shiboken6

                if not shiboken6.isValid(a):  # the window is being destroyed
                    return
                full = f"{prefix} {text}".strip()
                a.setIconText(fm.elidedText(full, Qt.TextElideMode.ElideRight, width - 12))
                keys = a.shortcut().toString()
                a.setToolTip(f"{full} ({keys})" if keys else full)

            signal.connect(show)
            show("")
        self.addToolBar(Qt.ToolBarArea.TopToolBarArea, tb)
        self.toolbar = tb

    def _build_status_bar(self) -> None:
        sb = self.statusBar()
        self.message_log = MessageLog()
        self.messages_dock = QDockWidget("Messages", self)
        self.messages_dock.setObjectName("dock_messages")
        self.messages_dock.setWidget(self.message_log)
        self.addDockWidget(Qt.DockWidgetArea.BottomDockWidgetArea, self.messages_dock)
        self.messages_dock.hide()
        self.view_menu.addAction(dock_view_action(self.messages_dock))
        self.details_button = QPushButton("Details…")
        self.details_button.setFlat(True)
        self.details_button.setToolTip("Show every message of this session in full (the status "
                                       "bar shows each one for a few seconds).")
        self.details_button.clicked.connect(self.show_messages)
        sb.addPermanentWidget(self.details_button)
        self.stats_label = QLabel()
        self.stats_label.setToolTip("Vertices, triangles, boundary loops and genus of the open mesh")
        sb.addPermanentWidget(self.stats_label)
        self.job_label = QLabel()  # what the running job does now, and for how long
        self.job_label.setVisible(False)
        self.job_label.setToolTip("The running job's current stage and the time it has taken")
        sb.addPermanentWidget(self.job_label)
        self._job_stage = ""
        self._job_clock = QTimer(self)
        self._job_clock.setInterval(1000)
        self._job_clock.timeout.connect(self._show_job_stage)
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

    # ------------------------------------------------------------------------------ messages
    def report(self, text: str, level: str = "info", timeout_ms: int = 8000) -> None:
        """Tell the user something: the whole text goes to the message log (View > Messages,
        "Details…"); its first line, shortened with "…" to the free width, to the status bar."""
        self.message_log.add(text, level)
        sb = self.statusBar()
        # a job's label, progress bar and Cancel are about to go when no job runs (a "finished"
        # or "cancelled" message comes just before they hide): their room is the message's
        job = (self.job_label, self.progress_bar, self.cancel_button)
        used = sum(w.width() for w in (self.details_button, self.stats_label) + job
                   if w.isVisible() and (w not in job or self.runner.busy))
        free = max(sb.width() - used - 40, 120)
        line = text.strip().splitlines()[0] if text.strip() else ""
        shown = sb.fontMetrics().elidedText(line, Qt.TextElideMode.ElideRight, free)
        sb.showMessage(shown, timeout_ms)

    def _error(self, title: str, text: str, details: str | None = None) -> None:
        """An error dialog whose text also stays in the message log."""
        self.message_log.add(f"{title}: {text}", "error")
        dialogs.error(self, title, text, details)

    def show_messages(self) -> None:
        self.messages_dock.show()
        self.messages_dock.raise_()

    def _layout_version(self) -> int:
        import zlib

        return zlib.crc32(",".join(self.panels).encode()) & 0x7FFFFFFF

    def _build_panels(self) -> None:
        from app.panels import panel_classes

        self.panels = {}
        for cls in panel_classes():
            panel = cls(self)
            self.addDockWidget(Qt.DockWidgetArea.RightDockWidgetArea, panel)
            self.panels[cls.title] = panel
            self.panels_menu.addAction(dock_view_action(panel))
        docks = list(self.panels.values())
        for other in docks[1:]:
            self.tabifyDockWidget(docks[0], other)
        docks[0].raise_()

    def showEvent(self, event) -> None:  # noqa: N802 - Qt override
        super().showEvent(event)
        if not self._panel_tabs_fitted:
            self._panel_tabs_fitted = True
            self._fit_panel_tabs()

    def _fit_panel_tabs(self) -> None:
        """The panels' tab bar would be as wide as all eight titles (~820 px) and squeeze the
        3D view: it scrolls instead (full titles, arrows at its end; View > Panels lists them
        all), and the panels take at most ~45 % of the window unless a saved layout says
        otherwise."""
        from PySide6.QtWidgets import QTabBar

        docks = list(self.panels.values())
        for bar in self.findChildren(QTabBar):
            if bar.count() and bar.tabText(0) in self.panels:
                bar.setUsesScrollButtons(True)
                bar.setElideMode(Qt.TextElideMode.ElideNone)
        if not self._layout_restored:
            need = max(d.minimumSizeHint().width() for d in docks)
            width = max(need, min(int(0.45 * self.width()), 820))
            self.resizeDocks([docks[0]], [width], Qt.Orientation.Horizontal)

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

    def _document_name(self) -> str:
        """What the window is about, as its title says: the project it was opened from or saved
        as, else the mesh file, else "The mesh"."""
        if self.project_path is not None:
            return self.project_path.name
        return self.document.path.name if self.document.path else "The mesh"

    def _confirm_discard(self) -> bool:
        if not self.document.modified:
            return True
        return dialogs.confirm(self, "Unsaved changes",
                               f"{self._document_name()} has changes that are not saved. "
                               "Discard them?", yes="Discard changes", no="Cancel")

    def open_dialog(self) -> bool:
        path = dialogs.open_file(self, "Open mesh", file_filter(), self._last_dir())
        return self.open_path(path) if path else False

    def show_batch(self):
        """File > Batch…: one non-modal dialog (kept while it runs)."""
        from app.batch_dialog import BatchDialog

        dlg = getattr(self, "batch_dialog", None)
        if dlg is None:
            dlg = self.batch_dialog = BatchDialog(self)
        dlg.show()
        dlg.raise_()
        return dlg

    # ------------------------------------------------------------------------------ projects
    def panel_settings(self) -> dict:
        """Every panel's Params and options ({title: {"params", "options"}}), as a project
        file keeps them. A panel whose options cannot be read now keeps only its Params."""
        from algorithms.params import params_to_dict

        out = {}
        for title, panel in self.panels.items():
            entry = {"params": params_to_dict(panel.form.params()), "options": {}}
            try:
                entry["options"] = panel.job_options()
            except Stylize3DError:
                pass
            out[title] = entry
        return out

    def current_project(self):
        from app.project import project_of_document

        return project_of_document(self.document, self.panel_settings())

    def save_project_to(self, path: str) -> bool:
        from app.project import save_project

        if self.document.is_empty:
            return False
        try:
            p = save_project(path, self.current_project())
        except Stylize3DError as e:
            self._error("Could not save the project", str(e))
            return False
        self.project_path = p
        self._ever_saved_here.add(str(p.resolve()))
        self._add_recent(str(p))
        self.undo_stack.setClean()
        self.document.modified = False
        self._update_title()
        self.report(f"Saved the project {p}", timeout_ms=5000)
        return True

    def save_project_dialog(self) -> bool:
        if self.document.is_empty:
            return False
        path = dialogs.save_file(self, "Save project as", "Stylize3D project (*.s3d)",
                                 self._last_dir())
        if not path:
            return False
        if not path.lower().endswith(".s3d"):
            path += ".s3d"
        if not self._may_overwrite(path):
            return False
        return self.save_project_to(path)

    def open_project_dialog(self) -> bool:
        path = dialogs.open_file(self, "Open project", "Stylize3D project (*.s3d)",
                                 self._last_dir())
        return self.open_project(path) if path else False

    def open_project(self, path) -> bool:
        """Open a ``.s3d`` project: its mesh, painting and handles become the document (the
        mesh as first opened is the Before / ghost view) and each panel takes its saved
        settings. A damaged or newer file gets a plain message; nothing changes then."""
        from app.project import read_project

        if self.runner.busy:
            self._error("A job is running", "Stop the running job (Esc) before opening a file.")
            return False
        try:
            project = read_project(path)
        except Stylize3DError as e:
            self._error("Cannot open the project", str(e))
            return False
        if not self._confirm_discard():
            return False
        problems = self.load_project(project)
        self.project_path = Path(path)
        self._add_recent(str(path))
        self._update_title()
        st = project.state
        msg = (f"Opened the project {Path(path).name}: {len(st.V):,} vertices, "
               f"{len(st.F):,} triangles, {len(st.fields)} painted field(s), "
               f"{len(st.handles)} handle(s).")
        if problems:
            msg += " Some panel settings were not restored: " + "; ".join(problems)
        self.report(msg)
        return True

    def load_project(self, project) -> list[str]:
        """Make a read :class:`~app.project.Project` the document, with an empty undo history
        (not modified), and give each panel its saved settings (no live re-run starts). Returns
        what could not be restored, one line per panel. Used by :meth:`open_project` and by
        the recovery of autosaved work (app/autosave.py)."""
        from algorithms.params import params_from_dict, params_to_dict

        self.undo_stack.clear()
        self._surface_attrs = (None, None, "")  # a project stores no UVs
        orig = project.original or project.state
        self.document.load(orig.V, orig.F, None, validate_mesh(orig.V, orig.F))
        self.document.original = orig
        self.document.set_state(project.state, modified=False)
        self.undo_stack.setClean()
        problems = []
        for title, entry in project.panels.items():
            panel = self.panels.get(title)
            if panel is None:
                problems.append(f"{title}: this version has no such panel")
                continue
            try:
                cls = panel.form.params_cls
                panel.form.set_params(params_from_dict(
                    cls, {**params_to_dict(cls()), **(entry.get("params") or {})}))
                panel.restore_options(entry.get("options") or {})
            except Stylize3DError as e:
                problems.append(f"{title}: {e}")
        for panel in self.panels.values():  # restoring settings is not a request to re-run
            panel._debounce.stop()
            panel.show_live_state(None)
        return problems

    def open_path(self, path: str | os.PathLike) -> bool:
        """Open a mesh file (or a ``.s3d`` project). On any problem the user gets a plain
        message and the open document stays as it was. Returns True when it was opened."""
        path = str(path)
        if path.lower().endswith(".s3d"):
            return self.open_project(path)
        if self.runner.busy:
            self._error("A job is running", "Stop the running job (Esc) before opening a file.")
            return False
        try:
            data = read_mesh(path)
        except Stylize3DError as e:
            self._error("Cannot open mesh", str(e))
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
                        self._error("Cannot open mesh",
                                      f"Cleaning could not fix everything:\n\n{report.summary()}")
                        return False
                elif choice != "Open as it is":
                    return False
            else:
                # what Clean cannot repair may still be removed (vertices with NaN / infinite
                # coordinates or bad indices, and their triangles), as `stylize3d clean
                # --remove-invalid-faces` does: offer it when the rest is then usable
                try:
                    res = clean_mesh(V, F, remove_invalid_faces=True)
                    after = validate_mesh(res.V, res.F, notes=notes + list(res.actions))
                except Stylize3DError:
                    res, after = None, None
                if res is None or after.errors or not len(res.F):
                    self._error("Cannot open mesh", text + "\n\nThese problems cannot be "
                                "fixed automatically, and removing the broken parts would not "
                                "leave a usable mesh; repair the file in a mesh editor.")
                    return False
                removed = len(F) - len(res.F)
                choice = dialogs.choose(
                    self, "Mesh problems", text + "\n\n'Remove the broken parts and open' "
                    f"deletes what cannot be repaired ({removed:,} triangle(s) with their "
                    "broken vertices) and fixes the rest, then tells you what it changed; your "
                    "file is not modified.", ["Remove the broken parts and open", "Cancel"],
                    default="Remove the broken parts and open")
                if choice != "Remove the broken parts and open":
                    return False
                V, F, report = res.V, res.F, after
                notes += list(res.actions)
        if not self._confirm_discard():
            return False
        self.undo_stack.clear()
        self.project_path = None
        self.document.load(V, F, path, report)
        self._remember_surface_attributes(path, data, F)
        self.undo_stack.setClean()
        self._add_recent(path)
        msg = f"Opened {Path(path).name}: {len(V):,} vertices, {len(F):,} triangles."
        if notes:
            msg += " " + " ".join(notes)
        self.report(msg + (f"\n{report.summary()}" if report.warnings else ""))
        return True

    def _remember_surface_attributes(self, path, data, F) -> None:
        """The opened file's UVs, materials and normals (OBJ), kept for Save while the
        document keeps the file's triangles (the methods that move vertices keep them)."""
        from algorithms.mesh.attributes import read_attributes

        attrs = read_attributes(path, len(data.V), len(data.F))
        self._surface_attrs = (F if F is data.F else None, attrs, Path(path).name)
        self._surface_n = len(data.V)

    def _attributes_for_saving(self, path: str):
        """``(attributes or None, what to say)``: the opened file's UVs etc. while the
        triangles are the file's and the format holds them, else a note that they are not
        saved (never silently, issue 39 item 5)."""
        from algorithms.mesh.io import attributes_kept_by

        F0, attrs, name = getattr(self, "_surface_attrs", (None, None, ""))
        if attrs is None:
            return None, ""
        found = attrs.describe()
        if F0 is None:
            return None, f" {name}'s {found} were not saved: cleaning renumbered its triangles."
        F = self.document.F
        if not np.array_equal(F, F0):
            # a subdivision (each triangle split in four, maybe several times) carries them
            levels = next((k for k in (1, 2, 3, 4) if len(F) == len(F0) * 4 ** k), None)
            attrs = None if levels is None else attrs.transferred(F0, self._surface_n, F,
                                                                  levels)
            if attrs is None:
                return None, (f" {name}'s {found} were not saved: the triangles were remade "
                              "(remeshing or coarsening).")
        if not attributes_kept_by(path, attrs):
            return None, (f" {name}'s {found} were not saved: {Path(path).suffix} files cannot "
                          "hold them (save as .obj to keep them).")
        return attrs, f" With {name}'s {found}."

    def _write(self, path: str) -> bool:
        attrs, said = self._attributes_for_saving(path)
        try:
            write_mesh(path, self.document.V, self.document.F, attributes=attrs)
        except Stylize3DError as e:
            self._error("Could not save", str(e))
            return False
        except OSError as e:  # pragma: no cover - write_mesh wraps these
            self._error("Could not save", f"{path}: {e.strerror or e}")
            return False
        self._ever_saved_here.add(str(Path(path).resolve()))
        if Path(path).suffix.lower() in SUPPORTED_READ:
            self.project_path = None  # the window is about this mesh file now
            self.document.mark_saved(path)
            self.undo_stack.setClean()
            self._add_recent(path)
        self.report(f"Saved {path}.{said}", timeout_ms=5000)
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
            self._error("Could not export screenshot", f"{path}: {e}")
            return False
        self._ever_saved_here.add(str(Path(path).resolve()))
        self.report(f"Screenshot saved to {path}", timeout_ms=5000)
        return True

    def export_field_dialog(self) -> bool:
        """File > Export Shown Field: the per-vertex values behind the colours on screen."""
        from algorithms.mesh.fields import FIELD_EXTENSIONS, field_file_filter

        shown = None if self.document.is_empty else self.viewport.shown_field()
        if shown is None:
            dialogs.info(self, "Export field", "No per-vertex colour view is shown. Choose one "
                         "in a panel first (for example Cubic > Show > λ scale, or Analogies > "
                         "Colour by).")
            return False
        path = dialogs.save_file(self, "Export the shown field", field_file_filter(),
                                 self._last_dir())
        if not path:
            return False
        if Path(path).suffix.lower() not in FIELD_EXTENSIONS:
            path += ".txt"
        if not self._may_overwrite(path):
            return False
        return self.export_field(path)

    def start_study_dialog(self):
        """File > Start Study Session: choose a protocol; the start dialog asks for the
        participant and condition (app/study/session.py)."""
        from app.study.session import start_study

        if getattr(self, "study_session", None) is not None and not self.study_session.finished:
            dialogs.info(self, "Study session", "A study session is already running.")
            return None
        path = dialogs.open_file(self, "Open a study protocol", "Study protocols (*.json *.toml)",
                                 self._last_dir())
        if not path:
            return None
        try:
            return start_study(self, path)
        except Stylize3DError as e:
            self._error("Cannot start the study session", str(e))
            return None

    def export_colored_dialog(self) -> bool:
        """File > Export Coloured Mesh: the mesh with the colour view on screen as vertex
        colours (PLY or OBJ), to show the result in another program."""
        if self.document.is_empty or self.viewport.shown_colors() is None:
            dialogs.info(self, "Export coloured mesh", "No per-vertex colour view is shown. "
                         "Choose one in a panel first (for example Analogies > Colour by).")
            return False
        path = dialogs.save_file(self, "Export the mesh with its colours",
                                 "Coloured meshes (*.ply *.obj)", self._last_dir())
        if not path:
            return False
        if Path(path).suffix.lower() not in (".ply", ".obj"):
            path += ".ply"
        if not self._may_overwrite(path):
            return False
        return self.export_colored(path)

    def export_colored(self, path: str) -> bool:
        from algorithms.mesh import write_mesh

        colors = self.viewport.shown_colors()
        if colors is None or self.document.is_empty:
            return False
        try:
            write_mesh(path, self.document.V, self.document.F, vertex_colors=colors)
        except Stylize3DError as e:
            self._error("Could not export the coloured mesh", str(e))
            return False
        self._ever_saved_here.add(str(Path(path).resolve()))
        self.report(f"Saved the mesh with its colours ({len(colors):,} vertices) to {path}",
                    timeout_ms=5000)
        return True

    def export_field(self, path: str) -> bool:
        from algorithms.mesh.fields import write_field

        shown = self.viewport.shown_field()
        if shown is None:
            return False
        name, values = shown
        try:
            write_field(path, values)
        except Stylize3DError as e:
            self._error("Could not export the field", str(e))
            return False
        self._ever_saved_here.add(str(Path(path).resolve()))
        self.report(f"Saved the field '{name}' ({len(values):,} values, one per vertex) to "
                    f"{path}", timeout_ms=5000)
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
            self._error("Cannot clean the mesh", str(e))
            return False
        changed = res.V.shape != doc.V.shape or res.F.shape != doc.F.shape or not (
            np.array_equal(res.F, doc.F) and np.array_equal(res.V, doc.V))
        if not changed:
            dialogs.info(self, "Clean mesh", "\n".join(res.actions))
            return False
        before = doc.state
        after = doc.remapped(res.V, res.F, res.vertex_map)
        cmd = StateCommand(doc, before, after, "Clean mesh")
        cmd.log_details = {"tool": "clean"}  # app.edits.clean re-computes it (study replay)
        self.undo_stack.push(cmd)
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

    def _show_job_stage(self) -> None:
        import time

        if not self.runner.busy:
            return
        seconds = time.perf_counter() - self.runner.started_at
        stage = self._job_stage or "working"
        self.job_label.setText(f"{stage[:60]} — {seconds:.0f} s")

    def _on_progress(self, it: int, total, message: str) -> None:
        self._job_stage = message or ""
        self._show_job_stage()
        if total:
            self.progress_bar.setRange(0, int(total))
            self.progress_bar.setValue(int(it))
            # steps counted in per cent (spectral coarsening's stages) read as per cent
            self.progress_bar.setFormat(f"{self.runner.name}: %p %" if int(total) == 100
                                        else f"{self.runner.name}: %v/%m")
        else:
            self.progress_bar.setRange(0, 0)
            self.progress_bar.setFormat(f"{self.runner.name}: {it}")

    def _on_busy_changed(self, busy: bool) -> None:
        self.viewport.set_streaming(busy)
        self._job_stage = ""
        self.job_label.setVisible(busy)
        if busy:
            self._show_job_stage()
            self._job_clock.start()
        else:
            self._job_clock.stop()
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
            self.report(f"{self.last_job_name} finished in {self.runner.last_duration:.2f} s.")
            return
        before = self._job_before
        if before is None or self.document.state is not before:
            self._restore_view()
            return
        if step.V.shape != before.V.shape or not np.isfinite(step.V).all():
            self._restore_view()
            self._error(f"{self.last_job_name} failed",
                          "The method returned an invalid result; your mesh was not changed.")
            return
        commit = getattr(self, "_job_commit", None)
        after = before.with_positions(step.V) if commit is None else commit(before, step)
        self.undo_stack.push(StateCommand(self.document, before, after, self.last_job_name,
                                          merge_id=getattr(self, "_job_merge_id", -1)))
        self._job_before = None
        self.job_committed.emit(self.last_job_name, after)
        panel = self.panels.get(self.last_job_name)
        counted = (getattr(panel, "counts_iterations", True) and step.iteration > 0)
        what = f" ({plural(step.iteration, 'iteration')})" if counted else ""
        self.report(f"{self.last_job_name} finished in {self.runner.last_duration:.2f} s"
                    f"{what}. Undo with Ctrl+Z.")

    def _on_job_cancelled(self, message: str) -> None:
        if not self.runner.busy:  # a restarted (live) job keeps streaming instead
            self._restore_view()
        self.report(message + " The mesh is as it was.", timeout_ms=5000)

    def _on_job_failed(self, message: str, details: str) -> None:
        self._restore_view()
        self._error(f"{self.last_job_name or 'Job'} failed",
                      message + "\n\nYour mesh is as it was before the job.", details or None)

    # ------------------------------------------------------------------------------ document
    def _on_document_changed(self, what: str) -> None:
        doc = self.document
        if what == "mesh":
            self.viewport.set_mesh(doc.V, doc.F)
            self._refresh_ghost()
            self._refresh_before()
            self._update_stats()
            self.mesh_shown.emit()
        elif what == "topology":
            self._validate(doc)
            self.viewport.set_mesh(doc.V, doc.F, reset_camera=False)
            self._update_stats()
        elif what == "positions":
            self.viewport.update_points(doc.V)
        self._update_title()

    def _validate(self, doc) -> None:
        """The report (stats line, problems) of a mesh whose triangles changed: at once for a
        small mesh, on a worker thread for a big one (the stats line says "checking…" meanwhile;
        the report lands only if the triangles are still the same)."""
        if len(doc.F) <= self.ASYNC_VALIDATE_FACES:
            doc.report = validate_mesh(doc.V, doc.F)
            return
        import threading

        V, F = doc.V, doc.F  # immutable snapshots (MeshState)
        signal = self._report_ready

        def work() -> None:
            try:
                result = validate_mesh(V, F)
            except Exception as exc:  # noqa: BLE001 - shown as a stats-line problem
                result = exc
            try:
                signal.emit(F, result)
            except RuntimeError:  # the window was closed meanwhile
                pass

        threading.Thread(target=work, name="validate-mesh", daemon=True).start()

    def _on_report_ready(self, F, result) -> None:
        doc = self.document
        if doc.is_empty or doc.F is not F:  # another edit came first: its own check follows
            return
        if isinstance(result, Exception):
            self.report(f"Could not check the mesh: {result}", "error")
            return
        doc.report = result
        self._update_stats()

    def _on_clean_changed(self, clean: bool) -> None:
        self.document.modified = not clean
        self._update_title()

    def _update_title(self) -> None:
        t = self.document.title.removesuffix(" *")
        if self.project_path is not None:  # the work was saved as / opened from a project
            t = self.project_path.name
        self.setWindowTitle(f"{t}[*] — {APP_NAME}" if t else f"{APP_NAME}[*]")
        self.setWindowModified(self.document.modified)

    def _update_stats(self) -> None:
        r = self.document.report
        if self.document.is_empty:
            self.stats_label.setText("No mesh open — File > Open or drop a mesh file here.")
            return
        if r is None:  # being checked (a big mesh whose triangles just changed)
            doc = self.document
            self.stats_label.setText(f"V {len(doc.V):,}   F {len(doc.F):,}   checking the mesh…")
            self.stats_label.setToolTip("Boundary loops, genus, components and problems follow "
                                        "in a moment")
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

    def show_before_after(self, on: bool) -> None:
        """Split the view: left the mesh as it was opened ("before"), right the current one;
        one camera for both."""
        if on and self.before_view is None:
            self.before_view = Viewport(self)
            self.before_view.show_legend = False
            self.central_split.insertWidget(0, self.before_view)
        if self.before_view is None:
            return
        self.before_view.setVisible(on)
        if on:
            self._refresh_before()
            self.before_view.link_camera(self.viewport)
        else:
            self.before_view.unlink_camera()
        self.before_view.set_label("Before — as opened" if on else None)
        self.viewport.set_label("After — now" if on else None)
        # each half (or the whole view again) is a new size: fit the mesh once the layout
        # settled, keeping the direction the user looks from (both halves share the camera)
        QTimer.singleShot(60, self.viewport.fit_view)

    def _refresh_before(self) -> None:
        bv = self.before_view
        if bv is None or not bv.isVisible():
            return
        orig = self.document.original
        if orig is None:
            bv.clear()
        else:
            bv.set_mesh(orig.V, orig.F, reset_camera=False)

    def _refresh_ghost(self) -> None:
        if self.actions_by_name["ghost"].isChecked() and self.document.original is not None:
            self.viewport.set_ghost(self.document.original.V, self.document.original.F)
        else:
            self.viewport.set_ghost(None)

    # ------------------------------------------------------------------------------ help
    def show_about(self) -> None:
        dialogs.info(self, "About Stylize3D",
                     "Stylize3D — stylize and process 3D surface meshes.\n\n"
                     "In this app: cubic stylization, shape analogies, neural subdivision, "
                     "smoothing, surface multigrid, spectral coarsening, Paparazzi image "
                     "filters and adversarial lighting; each also runs from the command line "
                     "(stylize3d --help). After one PhD thesis on data-driven "
                     "geometric stylization and scalable geometry processing.\n\n"
                     f"Version {__version__}.")

    def show_welcome(self):
        """Help > Welcome (and the first start): samples with thumbnails, or open a file."""
        from app.welcome import WelcomeDialog

        dlg = getattr(self, "welcome_dialog", None)
        if dlg is None:
            dlg = self.welcome_dialog = WelcomeDialog(self)
        dlg.show()
        dlg.raise_()
        return dlg

    def show_shortcuts(self) -> None:
        dialogs.info(self, "Keyboard shortcuts", SHORTCUTS_TEXT)

    # ------------------------------------------------------------------------------ Qt events
    def dragEnterEvent(self, event) -> None:  # noqa: N802
        urls = event.mimeData().urls() if event.mimeData().hasUrls() else []
        if any(Path(u.toLocalFile()).suffix.lower() in (*SUPPORTED_READ, ".s3d") for u in urls):
            event.acceptProposedAction()
        else:
            event.ignore()

    def dropEvent(self, event) -> None:  # noqa: N802
        for u in event.mimeData().urls():
            p = u.toLocalFile()
            if Path(p).suffix.lower() in (*SUPPORTED_READ, ".s3d"):
                event.acceptProposedAction()
                QTimer.singleShot(0, lambda p=p: self.open_path(p))
                return
        event.ignore()

    def closeEvent(self, event) -> None:  # noqa: N802
        if not self._confirm_discard():
            event.ignore()
            return
        bd = getattr(self, "batch_dialog", None)
        if bd is not None and bd.running:
            if not dialogs.confirm(self, "A batch is running", "Stop the batch and quit? "
                                   "(Starting it again later continues it.)", yes="Stop and quit",
                                   no="Cancel"):
                event.ignore()
                return
            bd.stop()
            bd.thread_.wait(60000)
        for panel in self.panels.values():
            panel.shutdown()
        self.runner.shutdown()
        self.settings.setValue("window/geometry", self.saveGeometry())
        self.settings.setValue("window/state", self.saveState(self._layout_version()))
        self.settings.sync()
        for vp in self.findChildren(Viewport):  # the main view and panel views (Gauss map)
            vp.close_plotter()
        self.autosave.close()  # a normal close: this window's recovery files go
        event.accept()
        if self._gc_acquired:
            self._gc_acquired = False
            gc_guard.release()
