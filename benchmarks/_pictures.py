"""A grid of flat- or smooth-shaded meshes with captions, written as one PNG (the pictures of
benchmarks/progressive_picture.py and benchmarks/subdivision_picture.py; needs a display or
xvfb-run)."""

from __future__ import annotations

import numpy as np


def render_grid(rows, out: str, px: int, *, smooth: bool, view: str = "iso",
                zoom: float = 1.0) -> None:
    """``rows``: a list of rows, each a list of ``(caption, V (n, 3), F (m, 3))``; every view
    is ``px`` pixels square, white, with the same camera ``view``."""
    import pyvista as pv

    cols = max(len(r) for r in rows)
    pl = pv.Plotter(off_screen=True, shape=(len(rows), cols),
                    window_size=(px * cols, px * len(rows)), border=False)
    for i, row in enumerate(rows):
        for j, (caption, V, F) in enumerate(row):
            pl.subplot(i, j)
            F = np.asarray(F)
            faces = np.hstack([np.full((len(F), 1), 3), F]).ravel()
            pl.add_mesh(pv.PolyData(np.asarray(V, dtype=np.float64), faces), color="#d9d4c7",
                        smooth_shading=smooth, specular=0.2 if smooth else 0.1)
            pl.add_text(caption, font_size=10 if smooth else 8, color="black")
            pl.set_background("white")
            pl.camera_position = view
            pl.reset_camera()
            pl.camera.zoom(zoom)
    pl.screenshot(out)
