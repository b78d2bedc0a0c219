"""Makes docs/screenshot.png with the app itself: opens the blob sample, runs cubic stylization,
waits for it, and saves the whole window (File > Export Screenshot saves the 3D view alone).

Run under a display, e.g.: xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/python scripts/readme_screenshot.py
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> int:
    from PySide6.QtCore import QSettings, QTimer
    from PySide6.QtWidgets import QApplication

    from app.main_window import MainWindow

    app = QApplication(sys.argv[:1])
    settings = QSettings(str(ROOT / "out" / "screenshot-settings.ini"), QSettings.Format.IniFormat)
    win = MainWindow(settings=settings)
    win.resize(1400, 860)
    win.show()
    out = ROOT / "docs" / "screenshot.png"

    def start():
        assert win.open_path(ROOT / "resources" / "samples" / "blob.obj")
        panel = win.panels["Cubic"]
        panel.raise_()
        panel.live_box.setChecked(False)
        panel.form.editors["lam"].setValue(0.6)
        win.runner.finished.connect(lambda _s: QTimer.singleShot(500, shoot))
        panel.run()

    def shoot():
        out.parent.mkdir(exist_ok=True)
        win.save_window_image(str(out))
        print(f"wrote {out}")
        win.undo_stack.setClean()
        win.close()

    QTimer.singleShot(500, start)
    return app.exec()


if __name__ == "__main__":
    sys.exit(main())
