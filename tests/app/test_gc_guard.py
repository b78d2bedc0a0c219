"""The cyclic garbage collector runs on the GUI thread only while a main window is open."""

from __future__ import annotations

import gc
import threading

from PySide6.QtCore import QObject


class _Cycle:
    """A reference cycle holding a QObject, the kind a worker thread must not destroy."""

    def __init__(self, log):
        self.me = self
        self.obj = QObject()
        self.log = log

    def __del__(self):
        self.log.append(threading.current_thread() is threading.main_thread())


def test_cycles_made_on_a_worker_die_on_the_gui_thread(window, qtbot):
    from app import gc_guard

    assert gc_guard.active() and not gc.isenabled()
    log: list[bool] = []
    kept = []

    def worker():
        for _ in range(50):
            _Cycle(log)
        # allocate far past generation 0's threshold (and keep it): the automatic collector
        # would run here, on the worker
        kept.append([[i] for i in range(20 * gc.get_threshold()[0])])

    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert log == []  # nothing collected on the worker
    qtbot.waitUntil(lambda: len(log) == 50, timeout=5000)  # the GUI thread's timer did it
    assert all(log)


def test_the_collector_is_back_after_the_last_window_closes(qtbot, tmp_path, dialogs,
                                                           needs_display):
    from PySide6.QtCore import QSettings

    from app import gc_guard
    from app.main_window import MainWindow

    assert gc.isenabled() and not gc_guard.active()
    wins = [MainWindow(settings=QSettings(str(tmp_path / f"s{i}.ini"),
                                          QSettings.Format.IniFormat)) for i in range(2)]
    assert gc_guard.active() and not gc.isenabled()
    for w in wins:
        w.document.modified = False
    wins[0].close()
    wins[0].close()  # closing one window twice releases it once: the other still holds it
    assert gc_guard.active() and not gc.isenabled()
    wins[1].close()
    assert not gc_guard.active() and gc.isenabled()
    for w in wins:
        w.deleteLater()
