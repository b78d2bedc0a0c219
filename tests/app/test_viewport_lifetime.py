"""No Python wrapper outlives the C++ object behind it in the viewport (issue 35).

CI saw ``QMenu.addAction`` return a ``PySide6.QtGui.QSurface``: a wrapper whose C++ object Qt
had deleted, handed back for a new object at the same address. The only ``QSurface`` wrapper
the app ever held was pyvistaqt's ``_surface`` (the GL context's offscreen surface, which Qt
deletes with the context and Shiboken does not track; see ``app.viewport._TimedInteractor``).
"""

from __future__ import annotations

import gc


def _surface_wrappers() -> list:
    from PySide6.QtGui import QSurface

    gc.collect()
    return [o for o in gc.get_objects() if issubclass(type(o), QSurface)]


def test_no_surface_wrapper_is_kept_while_the_view_draws(window, qtbot):
    from PySide6.QtGui import QOpenGLContext

    pl = window.viewport.plotter
    window.viewport.render()
    qtbot.wait(200)
    assert pl._ctx is not None                      # the view has its GL context
    assert _surface_wrappers() == []                # ... and holds no wrapper of its surface
    surface = pl._surface                           # read: the context's current surface
    assert surface is not None
    assert pl._ctx.makeCurrent(surface)             # it works (what VTK's renders ask for)
    assert QOpenGLContext.currentContext() is pl._ctx
    del surface
    assert _surface_wrappers() == []


def test_a_view_moved_to_another_window_and_deleted_leaves_no_stale_wrapper(qtbot,
                                                                            needs_display):
    """Moving the view to another top-level window re-creates its context (Qt deletes the old
    surface); deleting the window deletes the new one, while the interactor object is still
    referenced from Python (as a reference cycle keeps it until the next collection)."""
    import shiboken6
    from PySide6.QtCore import QCoreApplication, QEvent
    from PySide6.QtWidgets import QMainWindow, QVBoxLayout, QWidget

    from app.viewport import Viewport

    win = QMainWindow()
    vp = Viewport()
    win.setCentralWidget(vp)
    win.resize(320, 240)
    win.show()
    qtbot.waitExposed(win)
    vp.render()
    qtbot.wait(100)
    pl = vp.plotter
    first_ctx = pl._ctx
    assert first_ctx is not None
    other = QWidget()
    QVBoxLayout(other).addWidget(vp)
    other.resize(320, 240)
    other.show()
    qtbot.waitExposed(other)
    vp.render()
    qtbot.wait(200)
    assert not shiboken6.isValid(first_ctx)         # Qt made a new context for the new window
    assert pl._surface is not None and pl._ctx is not first_ctx
    assert _surface_wrappers() == []
    vp.close_plotter()
    other.deleteLater()
    win.deleteLater()
    QCoreApplication.sendPostedEvents(None, QEvent.Type.DeferredDelete.value)
    qtbot.wait(50)
    assert not shiboken6.isValid(pl)
    assert pl._surface is None                      # nothing left to make current
    assert _surface_wrappers() == []


def test_new_actions_are_actions_after_windows_come_and_go(qtbot, tmp_path, dialogs,
                                                           needs_display):
    """The CI symptom, end to end: windows opened, drawn and closed one after the other (as the
    GUI tests do); every QAction a menu hands back afterwards is a QAction."""
    from PySide6.QtCore import QCoreApplication, QEvent, QSettings
    from PySide6.QtGui import QAction
    from PySide6.QtWidgets import QMenu

    from app.main_window import MainWindow

    for i in range(3):
        settings = QSettings(str(tmp_path / f"s{i}.ini"), QSettings.Format.IniFormat)
        win = MainWindow(settings=settings)
        win.show()
        qtbot.waitExposed(win)
        win.viewport.render()
        qtbot.wait(100)
        win.document.modified = False
        win.close()
        win.deleteLater()
        QCoreApplication.sendPostedEvents(None, QEvent.Type.DeferredDelete.value)
        assert _surface_wrappers() == []
    menu = QMenu()
    for _ in range(2000):
        assert isinstance(menu.addAction("x"), QAction)
