"""``stylize3d smooth`` data smoothing (issue 10): solver auto, never a silent wrong answer."""

from __future__ import annotations

import json

import numpy as np

from algorithms.mesh import read_mesh, write_mesh
from algorithms.mesh.primitives import icosphere
from app.cli import main
from tests.algorithms.multigrid.scan_meshes import scan_like


def _mesh(tmp_path, subdivisions=4):
    V, F = icosphere(subdivisions)
    p = tmp_path / "sphere.obj"
    write_mesh(p, V, F)
    return p


def _json(out: str) -> dict:
    return json.loads(out[out.index("{"):out.rindex("}") + 1])


def test_unconverged_multigrid_writes_nothing_and_exits_6(tmp_path, capsys):
    src = _mesh(tmp_path)
    out = tmp_path / "out.obj"
    rc = main(["smooth", str(src), "-o", str(out), "--signal", "positions", "--energy",
               "bilaplacian", "--solver", "multigrid", "--max-cycles", "2", "--no-fallback"])
    err = capsys.readouterr().err
    assert rc == 6
    assert not out.exists()
    assert "Multigrid stopped after 2 iterations" in err and "--solver direct" in err
    assert "Traceback" not in err


def test_unconverged_multigrid_falls_back_to_direct_and_says_so(tmp_path, capsys):
    src = _mesh(tmp_path)
    out = tmp_path / "out.obj"
    ref = tmp_path / "ref.obj"
    rc = main(["smooth", str(src), "-o", str(out), "--signal", "positions", "--energy",
               "bilaplacian", "--solver", "multigrid", "--max-cycles", "2", "--json"])
    res = _json(capsys.readouterr().out)
    assert rc == 0 and out.exists()
    assert res["solver"] == "direct" and "direct solver instead" in res["fallback"]
    assert res["cycles"] == 2
    assert main(["smooth", str(src), "-o", str(ref), "--signal", "positions", "--energy",
                 "bilaplacian", "--solver", "direct"]) == 0
    np.testing.assert_allclose(read_mesh(out).V, read_mesh(ref).V, atol=1e-9)


def test_auto_is_the_default_and_says_which(tmp_path, capsys):
    src = _mesh(tmp_path, 3)
    out = tmp_path / "out.obj"
    rc = main(["smooth", str(src), "-o", str(out), "--energy", "dirichlet"])
    err = capsys.readouterr().err
    assert rc == 0 and "auto: direct solver" in err
    rc = main(["smooth", str(src), "-o", str(out), "--overwrite", "--energy", "dirichlet",
               "--json"])
    res = _json(capsys.readouterr().out)
    assert rc == 0 and res["params"]["solver"] == "auto" and res["solver"] == "direct"
    assert res["solver_choice"].startswith("auto: direct solver")


def test_multigrid_converges_on_a_scan_with_holes_and_thin_triangles(tmp_path, capsys):
    """The failure of issue 10 (residual growing for 200 cycles, mesh written anyway)."""
    V, F = icosphere(5)
    V, F = scan_like(V, F, holes=2, needles=150, caps=60, seed=3)
    src = tmp_path / "scan.obj"
    write_mesh(src, V, F)
    for energy in ("bilaplacian", "dirichlet"):
        out = tmp_path / f"{energy}.obj"
        rc = main(["smooth", str(src), "-o", str(out), "--signal", "positions", "--energy",
                   energy, "--solver", "multigrid", "--no-fallback", "--json"])
        res = _json(capsys.readouterr().out)
        assert rc == 0 and res["converged"] and res["fallback"] is None, res
        assert res["cycles"] <= 30 and res["relative_residual"] <= 1e-5


def test_the_flow_says_where_it_held_the_surface_from_crossing_itself(tmp_path, capsys):
    """fertility at a strong step: the arms would pull through each other (issue 38). The line
    and --json say what was held; --no-hold-crossings runs the flow as it is, and says nothing."""
    from algorithms.mesh.intersections import intersecting_pairs_here, new_crossings_away_from
    from tests.conftest import shared_mesh

    src = shared_mesh("fertility.off")
    m = read_mesh(src)
    known = intersecting_pairs_here(m.V, m.F)

    def made(path) -> int:
        return len(new_crossings_away_from(intersecting_pairs_here(read_mesh(path).V, m.F), m.F,
                                           known))

    out = tmp_path / "held.obj"
    assert main(["smooth", str(src), "-o", str(out), "--step-size", "1e-4"]) == 0
    line = capsys.readouterr().out
    assert "Its steps would have pushed the surface through itself in " in line
    assert "none is left" in line and made(out) == 0
    assert main(["smooth", str(src), "-o", str(out), "--overwrite", "--step-size", "1e-4",
                 "--json"]) == 0
    c = _json(capsys.readouterr().out)["crossings"]
    assert c["checked"] and c["made"] >= 1 and c["left"] == 0 and c["held_vertices"] > 0
    free = tmp_path / "free.obj"
    assert main(["smooth", str(src), "-o", str(free), "--step-size", "1e-4",
                 "--no-hold-crossings", "--json"]) == 0
    res = _json(capsys.readouterr().out)
    assert res["crossings"] is None and res["params"]["hold_crossings"] is False
    assert made(free) >= 20


def test_a_flat_sheet_with_a_fixed_border_says_nothing_moved_and_why(tmp_path, capsys):
    """A 2-D drawing (the corpus's woody): no step size moves it, so the line must not advise
    a larger one."""
    from tests.conftest import unit_square_grid

    V, F = unit_square_grid(8)
    V[:, 0] += 0.05 * np.sin(7 * V[:, 1])  # an uneven but flat layout
    src = tmp_path / "flat.obj"
    write_mesh(src, V, F)
    out = tmp_path / "out.obj"
    assert main(["smooth", str(src), "-o", str(out), "--step-size", "1e-3"]) == 0
    line = capsys.readouterr().out
    assert "Nothing moved: the surface is flat with a fixed border" in line
    assert "Raise Step size" not in line and "--step-size" not in line
    np.testing.assert_allclose(read_mesh(out).V, V, atol=1e-9)


def test_a_barely_changed_shape_says_which_flag_to_raise_in_the_line_and_the_json(
        tmp_path, capsys):
    """A ball with broad bumps at the default step size moves less than 0.5 % of its size
    (measured 0.11 %): the line and ``--json`` (``note``, with ``moved``) name the flag and a
    value, and that value smooths visibly (0.62 %, no note)."""
    V, F = icosphere(3)
    V = V * (1.0 + 0.03 * np.sin(12 * V[:, :1]))
    src = tmp_path / "ball.obj"
    write_mesh(src, V, F)
    out = tmp_path / "out.obj"
    assert main(["smooth", str(src), "-o", str(out), "--json"]) == 0
    d = _json(capsys.readouterr().out)
    assert 0 < d["moved"] < 0.005
    assert "changed little" in d["note"] and "--step-size 1e-04" in d["note"]
    assert main(["smooth", str(src), "-o", str(out), "--overwrite"]) == 0
    assert "Raise --step-size (e.g. --step-size 1e-04)" in capsys.readouterr().out
    assert main(["smooth", str(src), "-o", str(out), "--overwrite", "--json", "--step-size",
                 "1e-04"]) == 0
    d = _json(capsys.readouterr().out)
    assert d["moved"] >= 0.005 and "note" not in d
