"""Python's cyclic garbage collector, run on the GUI thread only, while a main window is open.

CPython's cyclic collector runs in whichever thread happens to allocate past its threshold. In
the app that is often a job's worker thread (:mod:`app.jobs`), the batch thread, or a library's
own thread. Qt and VTK objects that die in a reference cycle (a widget connected to a lambda
that refers to it, a panel's actors) are then destroyed on that thread: Qt objects belong to
the GUI thread and VTK's graphics objects release OpenGL resources of the GUI thread's context,
so such a destruction can corrupt the window's state and crash it later, far from the cause.

While a :class:`~app.main_window.MainWindow` is open the automatic collector is therefore off
and a GUI-thread timer runs the same generational collections (:meth:`MainThreadGC.check`,
every ``INTERVAL_MS``; a generation is collected when its count passes the threshold CPython
itself would use). Reference counting, which frees almost everything, is unchanged; only
cyclic garbage waits for the timer. When the last window closes, one full collection runs on
the GUI thread and the automatic collector is switched back on (so the command line, the
batch workers and the tests after a window closed run as before).
"""

from __future__ import annotations

import gc

from PySide6.QtCore import QCoreApplication, QObject, QThread, QTimer

__all__ = ["MainThreadGC", "acquire", "release", "active"]

INTERVAL_MS = 250
"""How often the GUI thread looks at the collector's counts (ms)."""


class MainThreadGC(QObject):
    """Generational collections from a timer of the GUI thread (automatic collector off)."""

    def __init__(self, parent: QObject | None = None):
        super().__init__(parent)
        self.threshold = gc.get_threshold()
        self.was_enabled = gc.isenabled()
        self.collections = [0, 0, 0]
        gc.disable()
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.check)
        self.timer.start(INTERVAL_MS)

    def check(self) -> None:
        """Collect each generation whose count passed its threshold (on this, the GUI thread)."""
        c0, c1, c2 = gc.get_count()
        t0, t1, t2 = self.threshold
        if t0 and c0 > t0:
            gen = 2 if (c1 > t1 and c2 > t2) else 1 if c1 > t1 else 0
            gc.collect(gen)
            self.collections[gen] += 1

    def stop(self) -> None:
        self.timer.stop()
        gc.collect()
        if self.was_enabled:
            gc.enable()


_guard: MainThreadGC | None = None
_users = 0


def acquire() -> None:
    """A main window opened (GUI thread): start collecting there, if not already."""
    global _guard, _users
    app = QCoreApplication.instance()
    if app is None or QThread.currentThread() is not app.thread():
        return  # not the GUI thread of a running application: leave the collector alone
    _users += 1
    if _guard is None:
        _guard = MainThreadGC(app)


def release() -> None:
    """A main window closed: after the last one, collect once and restore the collector."""
    global _guard, _users
    if _users == 0:
        return
    _users -= 1
    if _users == 0 and _guard is not None:
        guard, _guard = _guard, None
        guard.stop()
        guard.deleteLater()


def active() -> bool:
    """Whether the GUI thread owns the cyclic collector now."""
    return _guard is not None
