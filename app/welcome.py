"""The welcome window: shown on first start (and from Help > Welcome). Open a file, or start from
one of eight suggestions, one per panel: a bundled sample (its thumbnail), the panel brought to
the front, and what to try first.

Thumbnails are rendered by the app itself (an off-screen pyvista plot of the sample, the same
colours as the viewport) on first use and cached in the user's cache folder.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from PySide6.QtCore import QSize, QStandardPaths, Qt
from PySide6.QtGui import QIcon
from PySide6.QtWidgets import (QCheckBox, QDialog, QGridLayout, QHBoxLayout, QLabel, QPushButton,
                               QSizePolicy, QToolButton, QVBoxLayout)

if TYPE_CHECKING:  # pragma: no cover
    from app.main_window import MainWindow

SAMPLES_DIR = Path(__file__).resolve().parents[1] / "resources" / "samples"
#: One suggestion per panel, in the panels' tab order: (sample file, panel title, short name of
#: the panel, what to try first). The orange is coloured (its vertex colours are what the
#: classifier sees), so the Adversarial panel starts from an object it recognizes.
SAMPLES = (
    ("blob.obj", "Cubic", "Cubic", "drag λ: it turns into cubes"),
    ("pretzel.obj", "Analogies", "Analogies", "pick a style, drag λ"),
    ("bumpy.obj", "Smooth", "Smooth", "Run smooths the bumps away"),
    ("bumpy.obj", "Multigrid smoothing", "Multigrid", "Run, then compare solvers"),
    ("pretzel.obj", "Spectral coarsening", "Spectral", "Run: a small operator alike"),
    ("blob.obj", "Subdivision", "Subdivision", "Run: a network adds detail"),
    ("blob.obj", "Paparazzi", "Paparazzi", "Run: an image filter shapes it"),
    ("orange.obj", "Adversarial lighting", "Adversarial", "Attack: fool it with light"),
)
#: settings a suggestion puts in its panel, so that its first Run shows the method: the blob
#: (3,232 vertices) is denser than the subdivision network was trained for, and at the
#: defaults it would get Loop; coarsened first to the count the panel's own advice names for
#: it, the network runs (tests/app/test_welcome_defaults.py)
CARD_SETTINGS = {("blob.obj", "Subdivision"): {"coarsen_first": 450}}
COLUMNS = 4
THUMB_SIZE = (176, 132)


def thumbnail(mesh: Path) -> QIcon:
    """A picture of ``mesh`` (cached PNG, made once with an off-screen render)."""
    cache = Path(QStandardPaths.writableLocation(
        QStandardPaths.StandardLocation.CacheLocation) or Path.home() / ".cache") / "thumbnails"
    png = cache / f"{mesh.stem}-{int(mesh.stat().st_mtime)}-c.png"  # -c: in its colours
    if not png.exists():
        try:
            _render_thumbnail(mesh, png)
        except Exception:  # no off-screen OpenGL: a button without a picture still works
            return QIcon()
    return QIcon(str(png))


def _file_colors(mesh: Path, n: int, m: int):
    """(n, 3) uint8 vertex colours stored in the file (face colours spread to vertices), or
    None."""
    import numpy as np

    from algorithms.errors import Stylize3DError
    from algorithms.render.sh import read_mesh_colors

    try:
        got = read_mesh_colors(mesh, n, m)
    except Stylize3DError:
        return None
    if got is None or got[0] != "vertex":
        return None
    return np.clip(np.rint(255.0 * got[1]), 0, 255).astype(np.uint8)


def _render_thumbnail(mesh: Path, png: Path) -> None:
    import numpy as np
    import pyvista as pv

    from algorithms.mesh import read_mesh
    from app.viewport import BACKGROUND_BOTTOM, BACKGROUND_TOP, HOME_VIEW_DIRECTION, MESH_COLOR

    data = read_mesh(mesh)
    faces = np.hstack([np.full((len(data.F), 1), 3), data.F]).ravel()
    p = pv.Plotter(off_screen=True, window_size=THUMB_SIZE)
    try:
        p.set_background(BACKGROUND_BOTTOM, top=BACKGROUND_TOP)
        poly = pv.PolyData(data.V, faces)
        colors = _file_colors(mesh, len(data.V), len(data.F))
        if colors is None:
            p.add_mesh(poly, color=MESH_COLOR, smooth_shading=True, specular=0.25)
        else:  # a coloured sample (the orange) is shown in its colours
            poly.point_data["rgb"] = colors
            p.add_mesh(poly, scalars="rgb", rgb=True, smooth_shading=True, specular=0.25)
        p.view_vector(HOME_VIEW_DIRECTION, viewup=(0.0, 1.0, 0.0))
        p.reset_camera()
        p.camera.zoom(1.2)
        png.parent.mkdir(parents=True, exist_ok=True)
        tmp = png.with_suffix(".part.png")
        p.screenshot(str(tmp))
        tmp.replace(png)
    finally:
        p.close()


class WelcomeDialog(QDialog):
    """See the module docstring. ``sample_buttons[panel title]`` are the suggestions' thumbnails
    (tests click them)."""

    def __init__(self, window: "MainWindow"):
        super().__init__(window)
        self.window_ = window
        self.setWindowTitle("Welcome to Stylize3D")
        lay = QVBoxLayout(self)
        intro = QLabel("<h2>Welcome to Stylize3D</h2>"
                       "Stylize a 3D surface mesh: make it cubic, give it the look of another "
                       "shape, smooth it, subdivide it, shape it with image filters. Open your "
                       "own mesh (OBJ, PLY, STL, OFF; or drop it on the window), or start with "
                       "one of these samples, one for each panel:")
        intro.setWordWrap(True)
        lay.addWidget(intro)
        grid = QGridLayout()
        self.sample_buttons: dict[str, QToolButton] = {}
        icons: dict[str, QIcon] = {}
        for i, (name, panel, short, hint) in enumerate(SAMPLES):
            path = SAMPLES_DIR / name
            if not path.exists():
                continue
            if name not in icons:
                icons[name] = thumbnail(path)
            b = QToolButton()
            b.setIcon(icons[name])
            b.setIconSize(QSize(*THUMB_SIZE))
            text = f"{short} · {Path(name).stem}\n{hint}"
            b.setText(text)
            b.setToolTip(f"Open the sample {name} and bring the {panel} panel to the front: "
                         f"{hint}.")
            b.setToolButtonStyle(Qt.ToolButtonStyle.ToolButtonTextUnderIcon)
            fm = b.fontMetrics()
            # room for the picture and both text lines (the default hint cut the second off)
            b.setMinimumWidth(max(THUMB_SIZE[0] + 16,
                                  *(fm.horizontalAdvance(t) + 24 for t in text.split("\n"))))
            b.setMinimumHeight(THUMB_SIZE[1] + 2 * fm.lineSpacing() + 24)
            b.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
            b.clicked.connect(lambda _=False, n=name, p=panel: self.open_sample(n, p))
            grid.addWidget(b, i // COLUMNS, i % COLUMNS)
            self.sample_buttons[panel] = b
        # every card the same size, in equal columns, with a gap: a card with a longer hint
        # made its column wider and the grid uneven (cards touching at 1024 x 700)
        if self.sample_buttons:
            w = max(b.minimumWidth() for b in self.sample_buttons.values())
            h = max(b.minimumHeight() for b in self.sample_buttons.values())
            for b in self.sample_buttons.values():
                b.setMinimumSize(w, h)
        for c in range(COLUMNS):
            grid.setColumnStretch(c, 1)
        grid.setHorizontalSpacing(8)
        grid.setVerticalSpacing(8)
        lay.addLayout(grid)
        row = QHBoxLayout()
        self.open_button = QPushButton("Open a mesh file…")
        self.open_button.setDefault(True)
        self.open_button.clicked.connect(self._open_file)
        self.show_box = QCheckBox("Show this window at start")
        self.show_box.setChecked(self.show_at_start(window))
        self.show_box.toggled.connect(
            lambda on: window.settings.setValue("welcome/show_at_start", bool(on)))
        close = QPushButton("Close")
        close.clicked.connect(self.close)
        row.addWidget(self.show_box, 1)
        row.addWidget(self.open_button)
        row.addWidget(close)
        lay.addLayout(row)
        hint = QLabel("Later: File > Open, Help > Welcome, Help > Keyboard Shortcuts (F1). Each "
                      "panel's \"What does this do?\" explains its method in plain words.")
        hint.setWordWrap(True)
        hint.setStyleSheet("color: #555;")
        lay.addWidget(hint)

    @staticmethod
    def show_at_start(window: "MainWindow") -> bool:
        v = window.settings.value("welcome/show_at_start", True)
        return v not in (False, "false", "0", 0)

    def open_sample(self, name: str, panel: str) -> bool:
        if not self.window_.open_path(SAMPLES_DIR / name):
            return False
        dock = self.window_.panels.get(panel)
        if dock is not None:
            dock.show()
            dock.raise_()
            short, hint = next((sh, h) for n, p, sh, h in SAMPLES if (n, p) == (name, panel))
            preset = CARD_SETTINGS.get((name, panel), {})
            for key, value in preset.items():
                dock.form.set_value(key, value)
            said = "".join(f" (set: {dock.form.labels[k].text().rstrip(':')} = {v})"
                           for k, v in preset.items())
            dock.status_label.setText(f"{short}: {hint}.{said}")
        self.close()
        return True

    def _open_file(self) -> None:
        if self.window_.open_dialog():
            self.close()
