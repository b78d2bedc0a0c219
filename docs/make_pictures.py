"""Make the pictures of the panel help pages (docs/images/*.png) with the real app window.

    xvfb-run -a -s "-screen 0 1920x1080x24" .venv/bin/python docs/make_pictures.py [NAME ...]

Each picture is the 3D view after the panel's method ran on a bundled sample, as a user would
see it (the same window, colours and legend).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from PySide6.QtCore import QSettings  # noqa: E402
from PySide6.QtWidgets import QApplication  # noqa: E402

OUT = ROOT / "docs" / "images"


def pump(app, seconds: float = 0.3) -> None:
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        app.processEvents()
        time.sleep(0.01)


def run_and_wait(app, win, start) -> None:
    start()
    pump(app, 0.2)
    while win.runner.busy:
        pump(app, 0.1)
    pump(app, 0.5)


def main(names: list[str]) -> None:
    app = QApplication(sys.argv[:1])
    from app.main_window import MainWindow

    settings = QSettings(str(Path(tempfile.mkdtemp()) / "s.ini"), QSettings.Format.IniFormat)
    win = MainWindow(settings=settings)
    win.resize(1280, 800)
    win.show()
    pump(app, 1.0)
    samples = ROOT / "resources" / "samples"
    OUT.mkdir(parents=True, exist_ok=True)

    def shot(name: str) -> None:
        win.viewport.screenshot(str(OUT / f"{name}.png"))
        print("wrote", OUT / f"{name}.png")
        win.undo_stack.setClean()  # the next sample opens without asking to save
        win.document.modified = False

    for p in win.panels.values():
        p.live_box.setChecked(False)
    if not names or "cubic" in names:
        win.open_path(samples / "blob.obj")
        panel = win.panels["Cubic"]
        panel.raise_()
        panel.form.set_value("lam", 0.6)
        run_and_wait(app, win, panel.run)
        win.actions_by_name["ghost"].setChecked(True)
        shot("cubic")
        win.actions_by_name["ghost"].setChecked(False)
    if not names or "analogies" in names:
        win.open_path(samples / "pretzel.obj")
        panel = win.panels["Analogies"]
        panel.raise_()
        pump(app)
        item = next(panel.gallery.item(i) for i in range(panel.gallery.count())
                    if panel.gallery.item(i).data(256) == "octahedron")
        panel.gallery.setCurrentItem(item)
        panel.form.set_value("lam", 4.0)
        panel.form.set_value("max_iterations", 40)
        run_and_wait(app, win, panel.run)
        panel.view_combo.setCurrentText("Angle to targets")
        pump(app)
        shot("analogies")
        panel.view_combo.setCurrentText("Shape only")
    if not names or "smooth" in names:
        win.open_path(samples / "bumpy.obj")
        panel = win.panels["Smooth"]
        panel.raise_()
        panel.form.set_value("iterations", 3)
        panel.form.set_value("step_size", 0.002)
        run_and_wait(app, win, panel.run)
        shot("smooth")
    if not names or "multigrid_smoothing" in names:
        win.open_path(samples / "blob.obj")
        panel = win.panels["Multigrid smoothing"]
        panel.raise_()
        pump(app)
        panel.form.set_value("alpha", 0.001)
        run_and_wait(app, win, panel.run)
        panel.view_combo.setCurrentIndex(0)
        pump(app)
        shot("multigrid_smoothing")
    if not names or "spectral_coarsening" in names:
        win.open_path(samples / "blob.obj")
        panel = win.panels["Spectral coarsening"]
        panel.raise_()
        pump(app)
        panel.form.set_value("m", 120)
        panel.form.set_value("k", 0)
        panel.form.set_value("max_iterations", 40)
        run_and_wait(app, win, panel.run)
        panel.show_combo.setCurrentText("Clusters and roots")
        pump(app)
        shot("spectral_coarsening")
    if not names or "paparazzi" in names:
        # the whole window: the panel's live image pair and monitor plot belong to the picture
        win.open_path(samples / "blob.obj")
        panel = win.panels["Paparazzi"]
        panel.raise_()
        pump(app)
        panel.set_filter("quantize")
        panel.form.set_value("iterations", 300)
        panel.form.set_value("learning_rate", 5e-4)
        run_and_wait(app, win, panel.run)
        win.grab().save(str(OUT / "paparazzi.png"))
        print("wrote", OUT / "paparazzi.png")
        win.undo_stack.setClean()
        win.document.modified = False
    if not names or "adversarial_lighting" in names:
        # the whole window: the classifier's image, its top-5 and before / after are the picture
        import numpy as np

        from algorithms.adversarial.shapes import orange
        from algorithms.mesh import write_mesh

        V, F, A = orange()
        C, n = np.zeros((len(V), 3)), np.zeros(len(V))
        for k in range(3):  # the orange's face colours as vertex colours of an OBJ file
            np.add.at(C, F[:, k], A)
            np.add.at(n, F[:, k], 1)
        path = Path(tempfile.mkdtemp()) / "orange.obj"
        write_mesh(path, V, F, vertex_colors=C / n[:, None])
        panel = win.panels["Adversarial lighting"]
        panel.raise_()
        pump(app)
        win.open_path(path)
        while panel.preview_count == 0:
            pump(app, 0.1)
        run_and_wait(app, win, lambda: panel.attack("lighting"))  # the thesis's settings
        while panel.preview_runner.busy:
            pump(app, 0.1)
        pump(app, 0.5)
        win.save_window_image(str(OUT / "adversarial_lighting.png"))
        print("wrote", OUT / "adversarial_lighting.png")
        win.undo_stack.setClean()
        win.document.modified = False
    win.document.modified = False
    win.close()


if __name__ == "__main__":
    main(sys.argv[1:])
