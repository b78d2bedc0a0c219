"""The batch CLI, run as a user would: a separate process, plain messages, exit codes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from algorithms.mesh import read_mesh
from tests.conftest import ROOT, SAMPLES, shared_mesh


def stylize3d(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "app", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def test_info_json_on_real_mesh():
    r = stylize3d("info", shared_mesh("bob.obj"), "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["ok"] and d["stats"]["vertices"] == 5344 and d["stats"]["faces"] == 10688
    assert d["stats"]["genus"] == 1


def test_info_text_on_mesh_with_boundary():
    r = stylize3d("info", shared_mesh("camelhead.off"))
    assert r.returncode == 0, r.stderr
    assert "11381" in r.stdout.replace(",", "") and "bound" in r.stdout.lower()


@pytest.mark.parametrize("kind, code", [("empty", 2), ("garbage", 2), ("nan", 4),
                                        ("out_of_range", 4), ("nonmanifold", 4),
                                        ("duplicates", 4)])
def test_bad_input_plain_message_nonzero_exit(bad_files, kind, code):
    r = stylize3d("info", bad_files[kind])
    assert r.returncode == code, (r.stdout, r.stderr)
    msg = r.stdout + r.stderr
    assert "Traceback" not in msg and len(msg.strip()) > 20


@pytest.mark.parametrize("kind", ["empty", "garbage", "nan", "out_of_range", "nonmanifold",
                                  "duplicates"])
def test_smooth_refuses_bad_input_and_writes_nothing(bad_files, tmp_path, kind):
    out = tmp_path / "out.obj"
    r = stylize3d("smooth", bad_files[kind], "-o", out)
    assert r.returncode != 0 and "Traceback" not in r.stderr and r.stderr.strip()
    assert not out.exists()


def test_clean_fixes_duplicates_and_reports(bad_files, tmp_path):
    out = tmp_path / "clean.obj"
    r = stylize3d("clean", bad_files["duplicates"], "-o", out)
    assert r.returncode == 0, r.stderr
    assert "duplicate" in r.stdout.lower()
    data = read_mesh(out)
    assert data.V.shape == (4, 3) and data.F.shape == (4, 3)


def test_smooth_with_clean_flag_says_what_it_fixed(bad_files, tmp_path):
    out = tmp_path / "out.obj"
    r = stylize3d("smooth", bad_files["duplicates"], "-o", out, "--iterations", "1")
    assert r.returncode == 4 and "--clean" in r.stderr and "duplicate" in r.stderr.lower()
    r = stylize3d("smooth", bad_files["duplicates"], "-o", out, "--iterations", "1", "--clean")
    assert r.returncode == 0, r.stderr
    assert "clean:" in r.stderr and "merged" in r.stderr.lower()
    assert read_mesh(out).V.shape == (4, 3)


def test_smooth_json_and_no_overwrite(tmp_path):
    out = tmp_path / "s.obj"
    r = stylize3d("smooth", SAMPLES / "blob.obj", "-o", out, "--iterations", "4", "--flow", "cmcf",
                  "--step-size", "0.002", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["iterations"] == 4 and d["params"]["flow"] == "cmcf" and d["seconds"] > 0
    b = d["bending_energy"]
    assert len(b) == 4 and b[-1] < b[0]
    before = out.read_bytes()
    r = stylize3d("smooth", SAMPLES / "blob.obj", "-o", out)
    assert r.returncode == 3 and "already exists" in r.stderr
    assert out.read_bytes() == before
    r = stylize3d("smooth", SAMPLES / "blob.obj", "-o", out, "--overwrite", "--iterations", "1")
    assert r.returncode == 0 and out.read_bytes() != before


def test_smooth_flags_come_from_params_and_are_checked(tmp_path):
    r = stylize3d("smooth", "--help")
    assert r.returncode == 0
    for flag in ("--flow", "--step-size", "--iterations", "--keep-size", "--no-keep-size",
                 "--fix-boundary"):
        assert flag in r.stdout
    r = stylize3d("smooth", SAMPLES / "blob.obj", "-o", tmp_path / "x.obj", "--iterations", "0")
    assert r.returncode == 5 and "at least 1" in r.stderr
    assert not (tmp_path / "x.obj").exists()


def test_gui_opens_bundled_sample_and_screenshots(tmp_path):
    """What the README's first command does: open the app on the sample mesh (here it also
    saves a screenshot and quits)."""
    import os

    if not os.environ.get("DISPLAY"):
        pytest.skip("needs an X display (pytest-xvfb with Debian's xvfb)")
    shot = tmp_path / "app.png"
    r = subprocess.run([sys.executable, "-m", "app", str(SAMPLES / "blob.obj"), "--screenshot",
                        str(shot)], cwd=ROOT, capture_output=True, text=True, timeout=120,
                       env={**os.environ, "HOME": str(tmp_path)})
    assert r.returncode == 0, r.stderr
    from PySide6.QtGui import QImage

    img = QImage(str(shot))
    assert not img.isNull() and img.width() >= 400


@pytest.mark.parametrize("kind, code", [("nan", 4), ("out_of_range", 4), ("garbage", 2)])
def test_clean_refuses_what_it_cannot_fix_and_writes_nothing(bad_files, tmp_path, kind, code):
    out = tmp_path / "c.obj"
    r = stylize3d("clean", bad_files[kind], "-o", out)
    assert r.returncode == code and "Traceback" not in r.stderr and r.stderr.strip()
    assert not out.exists()


def test_clean_nonmanifold_removes_the_extra_triangle(bad_files, tmp_path):
    out = tmp_path / "c.obj"
    r = stylize3d("clean", bad_files["nonmanifold"], "-o", out)
    assert r.returncode == 0, r.stderr
    assert read_mesh(out).F.shape == (2, 3)
    assert stylize3d("info", out).returncode == 0


def test_cubic_json_reports_cubier_normals(tmp_path):
    out = tmp_path / "c.obj"
    r = stylize3d("cubic", shared_mesh("spot_lowres.obj"), "-o", out, "--lambda", "0.4",
                  "--max-iters", "40", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert 1 <= d["iterations"] <= 40 and d["seconds"] > 0
    assert d["l1_normals_after"] < d["l1_normals_before"] - 0.02
    assert 0 <= d["final_relative_displacement"]
    data = read_mesh(out)
    assert data.F.shape == (1654, 3)


def test_cubic_on_a_box_says_its_faces_already_face_the_axes(tmp_path):
    """A box (the corpus's CAD tray is one): the style has nothing to square off; the line and
    --json say why nothing visible changed, instead of a silent copy. A shape that changes
    says nothing of the kind."""
    from algorithms.mesh import write_mesh
    from algorithms.mesh.primitives import cube

    src = tmp_path / "box.obj"
    write_mesh(src, *cube(3))
    out = tmp_path / "c.obj"
    r = stylize3d("cubic", src, "-o", out)
    assert r.returncode == 0, r.stderr
    assert "its faces already face the axes (100 % of its area within 10 degrees" in r.stdout
    r = stylize3d("cubic", src, "-o", out, "--overwrite", "--json")
    assert "already face the axes" in json.loads(r.stdout)["note"]
    r = stylize3d("cubic", shared_mesh("spot_lowres.obj"), "-o", out, "--overwrite", "--json",
                  "--max-iters", "20")
    assert "note" not in json.loads(r.stdout)


def test_analogy_on_a_flat_drawing_says_its_normals_already_match_the_style(tmp_path):
    """A flat drawing (the corpus's woody): every normal is a cube normal already."""
    from algorithms.mesh import write_mesh
    from tests.conftest import unit_square_grid

    src = tmp_path / "box.obj"
    write_mesh(src, *unit_square_grid(8))
    out = tmp_path / "a.obj"
    r = stylize3d("analogy", src, "-o", out, "--style", "cube")
    assert r.returncode == 0, r.stderr
    assert "its normals are already within 0.0 degrees of the style's" in r.stdout
    r = stylize3d("analogy", src, "-o", out, "--style", "cube", "--overwrite", "--json")
    assert "already within" in json.loads(r.stdout)["note"]


def test_cubic_lambda_xyz_and_bad_values(tmp_path):
    out = tmp_path / "c.obj"
    r = stylize3d("cubic", SAMPLES / "blob.obj", "-o", out, "--lambda-xyz", "1", "0", "0",
                  "--max-iters", "5", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["params"]["per_axis"] and d["params"]["axis_factor_y"] == 0.0
    r = stylize3d("cubic", SAMPLES / "blob.obj", "-o", tmp_path / "x.obj", "--lambda", "-1")
    assert r.returncode == 5 and "at least 0" in r.stderr


def test_cubic_progressive_faces(tmp_path):
    out = tmp_path / "p.obj"
    r = stylize3d("cubic", shared_mesh("bob.obj"), "-o", out, "--progressive-faces", "2000",
                  "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["progressive_faces"] == 2000
    assert d["l1_normals_after"] < d["l1_normals_before"] - 0.03
    assert read_mesh(out).F.shape == (10688, 3)
    r = stylize3d("cubic", shared_mesh("bob.obj"), "-o", tmp_path / "q.obj",
                  "--progressive-faces", "50000")
    assert r.returncode == 5 and "larger than the mesh" in r.stderr


def test_analogy_json_and_style_errors(tmp_path):
    out = tmp_path / "a.obj"
    r = stylize3d("analogy", shared_mesh("spot_lowres.obj"), "-o", out, "--style", "cube",
                  "--lambda", "1", "--max-iterations", "30", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["iterations"] <= 30 and d["mean_angle_after"] < d["mean_angle_before"] - 2
    assert "cube" in d["style_map"]
    assert read_mesh(out).F.shape == (1654, 3)
    # a genus-1 style shape cannot be mapped to the sphere: plain message, nothing written
    r = stylize3d("analogy", SAMPLES / "blob.obj", "-o", tmp_path / "b.obj", "--style",
                  shared_mesh("bob.obj"), "--style-map", "spherical")
    assert r.returncode == 4 and "genus" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "b.obj").exists()
    r = stylize3d("analogy", SAMPLES / "blob.obj", "-o", tmp_path / "c.obj", "--style", "nope")
    assert r.returncode == 5 and "Unknown style" in r.stderr


def test_analogy_with_capture_json_and_flags(tmp_path):
    from algorithms.deform.targets import CaptureSphere

    cap = CaptureSphere(3)
    cap.paint_cap([0, 1, 0], 40.0, [0, 0, 1])  # normals facing up are sent to +z
    cap.save(tmp_path / "capture.json")
    r = stylize3d("analogy", SAMPLES / "blob.obj", "-o", tmp_path / "d.obj", "--style",
                  tmp_path / "capture.json", "--regularizer", "farap", "--dynamic",
                  "--developable", "0.03", "--max-iterations", "5", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["params"]["regularizer"] == "farap" and d["params"]["dynamic_targets"]
    assert d["params"]["developable_threshold"] == 0.03
    assert "capture" in d["style_map"]


def test_coarsen_json_keys_are_the_interface(tmp_path):
    out = tmp_path / "c.npz"
    r = stylize3d("coarsen", shared_mesh("spot_lowres.obj"), "--m", "60", "--k", "20",
                  "--compare", "qslim,amg", "-o", out, "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert set(d) == {"n", "m", "k", "methods"} and (d["n"], d["m"], d["k"]) == (829, 60, 20)
    assert set(d["methods"]) == {"ours", "qslim", "amg"}
    for name, mt in d["methods"].items():
        keys = {"c_diag_score", "eig_rel_err_mean", "eig_rel_err_max", "seconds"}
        assert set(mt) == keys | ({"iterations"} if name == "ours" else set())
        assert 0 < mt["c_diag_score"] <= 1
    assert d["methods"]["ours"]["c_diag_score"] > max(d["methods"]["qslim"]["c_diag_score"],
                                                      d["methods"]["amg"]["c_diag_score"])
    import numpy as np

    z = np.load(out)
    assert tuple(z["L_shape"]) == (60, 60) and tuple(z["P_shape"]) == (60, 829)


def test_coarsen_bad_arguments(tmp_path):
    r = stylize3d("coarsen", SAMPLES / "blob.obj", "--operator", "nope")
    assert r.returncode == 5 and "Unknown operator" in r.stderr
    r = stylize3d("coarsen", SAMPLES / "blob.obj", "--m", "30", "--k", "20")
    assert r.returncode == 5 and "ask for --k 14 or fewer" in r.stderr
    r = stylize3d("coarsen", SAMPLES / "blob.obj", "--m", "60", "--k", "10", "--operator",
                  "aniso:70", "--max-iterations", "20", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["methods"]["ours"]["iterations"] <= 20


# ----------------------------------------------------------------------------- multigrid (ch. 8)
def test_smooth_noise_signal_multigrid_matches_direct_and_reduces_error(tmp_path):
    outs = {}
    for solver in ("multigrid", "direct"):
        out = tmp_path / f"{solver}.txt"
        r = stylize3d("smooth", SAMPLES / "blob.obj", "-o", out, "--signal", "noise",
                      "--energy", "dirichlet", "--alpha", "5e-4", "--solver", solver, "--json")
        assert r.returncode == 0, r.stderr
        d = json.loads(r.stdout)
        assert d["signal"] == "noise" and d["params"]["solver"] == solver
        # the noisy test field gets much closer to the clean pattern
        assert d["rms_error_after"] < 0.5 * d["rms_error_before"]
        outs[solver] = np.loadtxt(out)
        if solver == "multigrid":
            assert d["levels"][0] == 3232 and len(d["levels"]) >= 2
            assert d["cycles"] >= 1 and d["converged"] and d["relative_residual"] <= 1e-5
    scale = np.abs(outs["direct"]).max()
    assert np.abs(outs["multigrid"] - outs["direct"]).max() < 1e-3 * scale


def test_smooth_positions_bilaplacian_writes_a_smoothed_mesh(tmp_path):
    out = tmp_path / "smooth.obj"
    r = stylize3d("smooth", SAMPLES / "bumpy.obj", "-o", out, "--signal", "positions",
                  "--energy", "bilaplacian", "--alpha", "1e-5", "--solver", "multigrid")
    assert r.returncode == 0, r.stderr
    assert "with multigrid (" in r.stdout and "CG steps" in r.stdout
    before, after = read_mesh(SAMPLES / "bumpy.obj"), read_mesh(out)
    np.testing.assert_array_equal(before.F, after.F)
    from algorithms.mesh.operators import cotangent_laplacian, mass_matrix

    def willmore(V, F):  # ∫H² dA: scale-invariant bending, falls as the bumps go
        m = mass_matrix(V, F).diagonal()
        HN = (cotangent_laplacian(V, F) @ V) / m[:, None]
        return float((m * (HN ** 2).sum(axis=1)).sum() / 4)
    assert willmore(after.V, after.F) < 0.7 * willmore(before.V, before.F)


def test_smooth_data_mode_errors(tmp_path, bad_files):
    # a field file with the wrong number of values: exit 2, nothing written
    f = tmp_path / "values.txt"
    f.write_text("1\n2\n")
    out = tmp_path / "o.txt"
    r = stylize3d("smooth", SAMPLES / "blob.obj", "-o", out, "--signal", f)
    assert r.returncode == 2 and "has 2 values" in r.stderr and not out.exists()
    r = stylize3d("smooth", SAMPLES / "blob.obj", "-o", tmp_path / "o.obj", "--signal", "noise")
    assert r.returncode == 5 and "one value per vertex" in r.stderr
    r = stylize3d("smooth", SAMPLES / "blob.obj", "-o", tmp_path / "o.txt", "--alpha", "1.5")
    assert r.returncode == 5 and "Traceback" not in r.stderr
    r = stylize3d("smooth", bad_files["nonmanifold"], "-o", tmp_path / "o2.obj", "--alpha", "0.01")
    assert r.returncode == 4 and not (tmp_path / "o2.obj").exists()


def test_multigrid_info_json_reports_a_bijective_hierarchy():
    r = stylize3d("multigrid-info", shared_mesh("camelhead.off"), "--json", "--min-vertices",
                  "300")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["bijective"] and d["prolongation"] == "intrinsic" and d["n_levels"] >= 3
    sizes = [lv["vertices"] for lv in d["levels"]]
    assert sizes[0] == d["vertices"] and sizes == sorted(sizes, reverse=True)
    assert sizes[-1] >= 300 and d["hierarchy_seconds"] > 0
    for lv in d["levels"][1:]:
        assert lv["bijective"] and lv["min_barycentric"] >= -1e-8
        assert lv["prolongation_nnz_per_row"] == 3 and lv["max_row_sum_error"] <= 1e-8
    r = stylize3d("multigrid-info", SAMPLES / "blob.obj")
    assert r.returncode == 0 and "level 1" in r.stdout and "bijective" in r.stdout


def test_cubic_with_multigrid_global_step_matches_direct(tmp_path):
    outs = {}
    for solver in ("direct", "multigrid"):
        out = tmp_path / f"{solver}.obj"
        r = stylize3d("cubic", SAMPLES / "blob.obj", "-o", out, "--global-solver", solver,
                      "--max-iterations", "15", "--json")
        assert r.returncode == 0, r.stderr
        outs[solver] = read_mesh(out).V
    diag = np.linalg.norm(np.ptp(outs["direct"], axis=0))
    assert np.abs(outs["direct"] - outs["multigrid"]).max() < 1e-3 * diag
    r = stylize3d("cubic", SAMPLES / "blob.obj", "-o", tmp_path / "x.obj", "--global-solver",
                  "multigrid", "--progressive-faces", "500")
    assert r.returncode == 5 and "choose one" in r.stderr


def test_smooth_hessian_energy(tmp_path):
    out = tmp_path / "h.npy"
    r = stylize3d("smooth", SAMPLES / "blob.obj", "-o", out, "--signal", "noise", "--energy",
                  "hessian", "--alpha", "1e-6", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["converged"] and d["rms_error_after"] < 0.5 * d["rms_error_before"]
    assert np.load(out).shape == (3232,)
