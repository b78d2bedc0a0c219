"""Colour views export as vertex colours; .glb files the app writes open again (issue 11)."""

from __future__ import annotations

import numpy as np

from algorithms.mesh import read_mesh, write_mesh
from tests.conftest import shared_mesh


def test_coloured_mesh_export_matches_the_colour_view(window, dialogs, tmp_path):
    assert window.open_path(shared_mesh("spot_lowres.obj"))
    V = window.document.V
    values = V[:, 1].copy()  # a field: height
    window.viewport.show_field("height", values, cmap="viridis")
    path = tmp_path / "coloured.ply"
    assert window.export_colored(str(path))
    head, body = path.read_bytes().split(b"end_header\n", 1)
    assert b"property uchar red" in head
    rec = np.frombuffer(body[:len(V) * 27], dtype=np.dtype([("p", "<f8", (3,)),
                                                            ("c", "u1", (3,))]))
    assert np.allclose(rec["p"], V)
    lo, hi = np.argmin(values), np.argmax(values)
    # viridis runs from dark purple to yellow: the lowest vertex is dark, the highest bright
    # (VTK's table rounds the last bit differently from matplotlib's: within 1 of 255)
    assert np.abs(rec["c"][lo].astype(int) - (68, 1, 84)).max() <= 1
    assert np.abs(rec["c"][hi].astype(int) - (253, 231, 37)).max() <= 1
    assert len({tuple(c) for c in rec["c"]}) > 50  # a real gradient, not one colour
    back = read_mesh(path)
    assert np.array_equal(back.F, window.document.F)
    # with no colour view shown, the user is told and nothing is written
    window.viewport.show_field(None)
    assert not window.export_colored_dialog()
    assert "No per-vertex colour view" in dialogs.infos[-1][1]


def test_glb_written_by_the_app_opens_again(window, dialogs, tmp_path):
    data = read_mesh(shared_mesh("bob.obj"))
    path = tmp_path / "bob.glb"
    write_mesh(path, data.V, data.F)
    assert window.open_path(path)
    assert not dialogs.errors
    assert window.document.F.shape == data.F.shape
    assert np.allclose(window.document.V, data.V, atol=1e-5)
