"""Starts the Qt application (imported only when the GUI is opened)."""

from __future__ import annotations

import sys

from PySide6.QtCore import QTimer
from PySide6.QtWidgets import QApplication

from app.main_window import APP_NAME, MainWindow


def run_app(mesh: str | None = None, screenshot: str | None = None) -> int:
    app = QApplication.instance() or QApplication(sys.argv[:1])
    app.setApplicationName(APP_NAME)
    app.setOrganizationName(APP_NAME)
    win = MainWindow()
    win.show()
    status = {"code": 0}
    if mesh:
        QTimer.singleShot(0, lambda: win.open_path(mesh))
    if screenshot:
        def shoot():
            if mesh and win.document.is_empty:
                print(f"stylize3d: could not open {mesh}", file=sys.stderr)
                status["code"] = 2
            elif not win.save_window_image(screenshot):
                status["code"] = 3
            else:
                print(f"Saved screenshot to {screenshot}")
            win.document.modified = False
            win.close()
        QTimer.singleShot(1500, shoot)
    rc = app.exec()
    return status["code"] or rc
