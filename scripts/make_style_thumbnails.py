"""Renders the style gallery's thumbnails (resources/styles/<name>.png, 96 px) with pyvista
off screen. Run once after changing the primitives:
    xvfb-run -a .venv/bin/python scripts/make_style_thumbnails.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pyvista as pv
from scipy.spatial import ConvexHull

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from algorithms.deform.targets import PRIMITIVES  # noqa: E402
from algorithms.mesh import platonic_solid  # noqa: E402


def prism(n: int):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.stack([np.cos(a), np.zeros(n), np.sin(a)], 1)
    return np.vstack([ring + [0, -0.8, 0], ring + [0, 0.8, 0]])


def shape(name: str):
    if name in ("cube", "tetrahedron", "octahedron", "dodecahedron", "icosahedron"):
        V, F = platonic_solid(name)
        return V, F
    pts = {"triangular_prism": prism(3), "hexagonal_prism": prism(6), "prism": prism(12),
           "pyramid": np.array([[1, -0.5, 1], [1, -0.5, -1], [-1, -0.5, -1], [-1, -0.5, 1],
                                [0, 0.91, 0]], float)}[name]
    hull = ConvexHull(pts)
    return pts, hull.simplices


def main() -> None:
    out = ROOT / "resources" / "styles"
    out.mkdir(parents=True, exist_ok=True)
    for name in PRIMITIVES:
        V, F = shape(name)
        poly = pv.PolyData(V, np.hstack([np.full((len(F), 1), 3), F]).ravel())
        pl = pv.Plotter(off_screen=True, window_size=(96, 96))
        pl.set_background("#f4f4f4")
        pl.add_mesh(poly, color="#e8d4b0", smooth_shading=False, show_edges=False)
        pl.view_vector((0.55, 0.45, 1.0), viewup=(0, 1, 0))
        pl.reset_camera()
        pl.screenshot(str(out / f"{name}.png"))
        pl.close()
        print("wrote", out / f"{name}.png")


if __name__ == "__main__":
    main()
