"""`stylize3d coarsen` on the inputs of issue 10, run as a user would (a separate process):
plain messages, exit codes, nothing written on failure, baselines that cannot run left out."""

from __future__ import annotations

import json

import numpy as np

from algorithms.mesh.io import write_mesh
from tests.algorithms.spectral.test_spectral_robustness import parts_mesh
from tests.app.test_cli import stylize3d


def test_many_parts_with_non_orientable_pieces_leave_qslim_out(tmp_path):
    """A CAD-like model in 10 parts, two of them Möbius strips: igl.qslim used to allocate
    until killed; now QSlim is left out with a note and ours and AMG are reported."""
    V, F = parts_mesh(10, mobius_every=5)
    path = tmp_path / "parts.obj"
    write_mesh(path, V, F)
    r = stylize3d("coarsen", path, "--m", "100", "--k", "30", "--compare", "qslim,amg", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert set(d) == {"n", "m", "k", "methods"}            # the JSON interface is fixed
    assert set(d["methods"]) == {"ours", "amg"}
    assert "Note: QSlim" in r.stderr and "left out" in r.stderr
    assert "Traceback" not in r.stderr


def test_many_parts_text_output_names_the_left_out_baseline(tmp_path):
    V, F = parts_mesh(10, mobius_every=5)
    path = tmp_path / "parts.obj"
    write_mesh(path, V, F)
    r = stylize3d("coarsen", path, "--m", "100", "--k", "30", "--compare", "qslim")
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert "Note: QSlim" in r.stdout and "ours" in r.stdout and "qslim" not in r.stdout


def test_too_few_coarse_nodes_for_the_parts_fails_plainly_and_writes_nothing(tmp_path):
    V, F = parts_mesh(12)
    path = tmp_path / "parts.obj"
    write_mesh(path, V, F)
    out = tmp_path / "out.npz"
    r = stylize3d("coarsen", path, "--m", "10", "--k", "3", "-o", out)
    assert r.returncode == 5, r.stderr
    assert "12 separate parts" in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()
    # issue 38: the message names the flag and the value that works, and they do
    assert "--m 15 or more" in r.stderr, r.stderr       # 12 parts + 3 eigenvectors
    # one coarse vertex per part leaves no non-zero eigenvalue: refused (it crashed the scoring)
    r = stylize3d("coarsen", path, "--m", "12", "--k", "3", "-o", out)
    assert r.returncode == 5 and "--m 15 or more" in r.stderr, r.stderr
    r = stylize3d("coarsen", path, "--m", "15", "--k", "3", "-o", out)
    assert r.returncode == 0, r.stderr
    assert out.exists()
    # without --k the advice names a small one too (k = m / 3 would make it large and slow)
    r = stylize3d("coarsen", path, "--m", "10", "-o", tmp_path / "b.npz")
    assert r.returncode == 5 and "--m 22 --k 10 or more" in r.stderr, r.stderr
    r = stylize3d("coarsen", path, "--m", "22", "--k", "10", "-o", tmp_path / "b.npz")
    assert r.returncode == 0, r.stderr


def test_many_parts_ours_beats_amg_and_writes_npz(tmp_path):
    V, F = parts_mesh(12)
    path = tmp_path / "parts.obj"
    write_mesh(path, V, F)
    out = tmp_path / "out.npz"
    r = stylize3d("coarsen", path, "--m", "150", "--k", "40", "--compare", "amg", "--json",
                  "-o", out)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    ours, amg = d["methods"]["ours"], d["methods"]["amg"]
    assert ours["c_diag_score"] > amg["c_diag_score"]
    assert ours["eig_rel_err_mean"] < amg["eig_rel_err_mean"]
    z = np.load(out)
    assert tuple(z["L_shape"]) == (150, 150)


def test_a_mesh_smaller_than_the_coarse_size_gets_advice_that_works(tmp_path, capsys):
    """Issue 38 (the corpus): the default m = 500 on a 280-vertex mesh was refused with
    "Need 2k < m < n"; the message now names the --m that works, and it does."""
    from algorithms.mesh import icosphere, write_mesh
    from app.cli import main

    V, F = icosphere(2)  # 162 vertices
    path = tmp_path / "small.obj"
    write_mesh(path, V, F)
    assert main(["coarsen", str(path)]) != 0
    err = capsys.readouterr().err
    assert "This mesh has 162 vertices" in err and "--m 81" in err
    assert main(["coarsen", str(path), "--m", "81", "--json"]) == 0
    assert main(["coarsen", str(path), "--m", "100", "--k", "60"]) != 0
    assert "ask for --k 49 or fewer" in capsys.readouterr().err
