"""GUI harness: a real MainWindow with a real VTK viewport, settings in a temp file, dialogs
patched to record what the user would have seen and answer as the test says."""

from __future__ import annotations

import os

import pytest


class DialogRecorder:
    def __init__(self):
        self.errors: list[tuple[str, str]] = []
        self.infos: list[tuple[str, str]] = []
        self.questions: list[tuple[str, str, list[str]]] = []
        self.answers: list[str | None] = []   # answers for choose/confirm, in order
        self.open_paths: list[str | None] = []
        self.save_paths: list[str | None] = []

    def error(self, parent, title, text, details=None):
        self.errors.append((title, text))

    def info(self, parent, title, text):
        self.infos.append((title, text))

    def choose(self, parent, title, text, choices, default=None, details=None):
        self.questions.append((title, text, list(choices)))
        if not self.answers:
            raise AssertionError(f"unexpected question: {title}: {text}")
        ans = self.answers.pop(0)
        assert ans is None or ans in choices, (ans, choices)
        return ans

    def confirm(self, parent, title, text, yes="Yes", no="Cancel"):
        return self.choose(parent, title, text, [yes, no]) == yes

    def open_file(self, parent, title, filter, directory=""):
        return self.open_paths.pop(0)

    def save_file(self, parent, title, filter, directory=""):
        return self.save_paths.pop(0)

    def open_folder(self, parent, title, directory=""):
        return self.open_paths.pop(0)


@pytest.fixture
def dialogs(monkeypatch):
    from app import dialogs as mod

    rec = DialogRecorder()
    for name in ("error", "info", "choose", "confirm", "open_file", "save_file", "open_folder"):
        monkeypatch.setattr(mod, name, getattr(rec, name))
    return rec


@pytest.fixture
def needs_display():
    if not os.environ.get("DISPLAY"):
        pytest.skip("the VTK viewport needs an X display: install Debian's 'xvfb' package "
                    "(scripts/setup.sh does this when run as root) so pytest-xvfb can start one")


@pytest.fixture
def window(qtbot, tmp_path, dialogs, needs_display):
    from PySide6.QtCore import QSettings

    from app.main_window import MainWindow

    settings = QSettings(str(tmp_path / "settings.ini"), QSettings.Format.IniFormat)
    win = MainWindow(settings=settings)
    # closed by this fixture (qtbot.addWidget would close it before our teardown runs)
    win.show()
    qtbot.waitExposed(win)
    yield win
    win.runner.cancel()
    win.runner.wait(10000)
    win.undo_stack.setClean()
    win.document.modified = False
    win.close()
    win.deleteLater()
    from algorithms import offload

    offload.keep_lock_free(False)   # the window turned it on; later algorithm tests run here


def front_vertex(window) -> int:
    """A vertex facing the camera, near the middle of the view."""
    import numpy as np

    cam = np.array(window.viewport.plotter.camera.position)
    V = window.document.V
    return int(np.argmin(((V - cam) ** 2).sum(axis=1)))


def drag(qtbot, window, points, modifier=None):
    """A left-button drag on the 3D view through the pixel ``points`` (press, moves, release)."""
    from PySide6.QtCore import QPoint, Qt

    modifier = Qt.KeyboardModifier.NoModifier if modifier is None else modifier
    w = window.viewport.plotter.interactor
    pts = [QPoint(int(round(x)), int(round(y))) for x, y in points]
    qtbot.mousePress(w, Qt.MouseButton.LeftButton, modifier, pts[0])
    for p in pts[1:]:
        qtbot.mouseMove(w, p)
    qtbot.mouseRelease(w, Qt.MouseButton.LeftButton, modifier, pts[-1])


def open_and_run(window, qtbot, tmp_path, V, F, panel_name: str, prepare=None):
    """Write ``(V, F)``, open it, run panel ``panel_name`` once (Live off; ``prepare(panel)``
    first, if given) with a real click, and return the panel."""
    from PySide6.QtCore import Qt

    from algorithms.mesh import write_mesh

    src = tmp_path / "shape.obj"
    write_mesh(src, V, F)
    assert window.open_path(src)
    panel = window.panels[panel_name]
    panel.raise_()
    panel.live_box.setChecked(False)
    if prepare is not None:
        prepare(panel)
    with qtbot.waitSignal(window.runner.finished, timeout=120000):
        qtbot.mouseClick(panel.run_button, Qt.MouseButton.LeftButton)
    return panel

