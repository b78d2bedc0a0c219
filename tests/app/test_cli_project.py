"""The command line on project files (.s3d), --params, the precedence of settings, mistyped
commands, and cubic / smooth as wrappers around their recipes (issue 20)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import app.recipes
from algorithms.mesh import read_mesh
from app import cli
from app.__main__ import main as app_main
from app.cli import main
from app.document import MeshState
from app.project import Project, read_project, save_project
from app.recipes import FIXED_FIELD, LAMBDA_FIELD, PLANE_FIELD
from tests.conftest import ROOT, SAMPLES, TEST_DATA

SPOT = TEST_DATA / "spot_lowres.obj"


def _spot_state() -> MeshState:
    d = read_mesh(SPOT)
    return MeshState.make(d.V, d.F)


def _painted_project(panels: dict | None = None) -> Project:
    """spot with a painted λ scale (x-dependent), a fixed region, a plane region, a handle."""
    st = _spot_state()
    V = st.V
    x = (V[:, 0] - V[:, 0].min()) / np.ptp(V[:, 0])
    st = st.with_field(LAMBDA_FIELD, 0.2 + 1.8 * x)
    st = st.with_field(FIXED_FIELD, (V[:, 1] < np.quantile(V[:, 1], 0.04)).astype(float))
    st = st.with_field(PLANE_FIELD, (V[:, 2] > np.quantile(V[:, 2], 0.97)).astype(float))
    top = int(np.argmax(V[:, 1]))
    st = st.with_handles({top: tuple(V[top] + np.array([0.0, 0.05, 0.0]) * np.ptp(V[:, 1]))})
    if panels is None:
        panels = {"Cubic": {"params": {"lam": 0.3, "max_iterations": 12},
                            "options": {"plane_axis": 2, "progressive": None,
                                        "multigrid": False}}}
    return Project(state=st, panels=panels, source="spot_lowres.obj")


def _json(out: str) -> dict:
    return json.loads(out[out.index("{"):out.rindex("}") + 1])


@pytest.fixture
def scene(tmp_path):
    return save_project(tmp_path / "scene.s3d", _painted_project())


# ----------------------------------------------------------------------------- cubic = recipe
def test_cubic_on_a_project_is_the_recipe_run_bit_for_bit(scene, tmp_path, capsys):
    out = tmp_path / "out.obj"
    assert main(["cubic", str(scene), "-o", str(out), "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["params"]["lam"] == 0.3 and rep["params"]["max_iterations"] == 12
    assert rep["progressive_faces"] is None and rep["progressive_auto"] is False
    got = read_mesh(out).V
    ref = app.recipes.run("cubic", read_project(scene)).state.V
    assert got.dtype == ref.dtype and np.array_equal(got, ref)
    # the same as the in-memory project the file was saved from
    assert np.array_equal(got, app.recipes.run("cubic", _painted_project()).state.V)
    # what was painted and placed is used: fixed vertices stay, the handle is reached, the
    # plane region is flat along z, and the result differs from the bare mesh's
    st = read_project(scene).state
    fixed = st.fields[FIXED_FIELD] > 0.5
    assert np.array_equal(got[fixed], st.V[fixed])
    (h, target), = st.handles
    assert np.allclose(got[h], target, atol=1e-9)
    plane = st.fields[PLANE_FIELD] > 0.5
    assert np.ptp(got[plane, 2]) < 1e-9 < np.ptp(st.V[plane, 2])
    bare = app.recipes.run("cubic", MeshState.make(st.V, st.F), {"lam": 0.3,
                                                                 "max_iterations": 12}, {})
    assert np.abs(bare.state.V - got).max() > 1e-3


def test_two_cli_runs_on_a_project_give_identical_bits(scene, tmp_path):
    outs = []
    for name in ("a.obj", "b.obj"):
        out = tmp_path / name
        assert main(["cubic", str(scene), "-o", str(out), "--quiet", "--max-iterations", "5"]) == 0
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]


def test_cubic_saved_progressive_option_and_flags_that_override_it(tmp_path, capsys):
    prog = {"target_faces": 800, "strategy": "qslim", "tikhonov": 1e-6, "preview_every": 3}
    panels = {"Cubic": {"params": {"max_iterations": 8},
                        "options": {"plane_axis": 0, "progressive": prog, "multigrid": False}}}
    project = _painted_project(panels)
    project.state = project.state.with_field(PLANE_FIELD, None)
    path = save_project(tmp_path / "p.s3d", project)
    out = tmp_path / "p.obj"
    assert main(["cubic", str(path), "-o", str(out), "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["progressive_faces"] == 800 and rep["progressive_auto"] is False
    # previews (GUI only) do not change the result: the saved preview_every is used here
    ref = app.recipes.run("cubic", read_project(path)).state.V
    assert np.array_equal(read_mesh(out).V, ref)
    assert main(["cubic", str(path), "-o", str(tmp_path / "q.obj"), "--json",
                 "--no-progressive"]) == 0
    assert _json(capsys.readouterr().out)["progressive_faces"] is None
    assert main(["cubic", str(path), "-o", str(tmp_path / "r.obj"), "--json",
                 "--progressive-faces", "600"]) == 0
    assert _json(capsys.readouterr().out)["progressive_faces"] == 600


def test_cubic_on_a_plain_mesh_is_the_recipe_run(tmp_path):
    out = tmp_path / "c.obj"
    assert main(["cubic", str(SPOT), "-o", str(out), "--quiet", "--lambda", "0.4",
                 "--max-iterations", "6"]) == 0
    ref = app.recipes.run("cubic", _spot_state(), {"lam": 0.4, "max_iterations": 6}, {})
    assert np.array_equal(read_mesh(out).V, ref.state.V)


# ----------------------------------------------------------------------------- precedence
def test_precedence_defaults_project_params_file_flags(scene, tmp_path, capsys):
    pfile = tmp_path / "settings.json"
    pfile.write_text(json.dumps({"lam": 0.5, "rho0": 0.001}))
    run = ["cubic", str(scene), "--max-iterations", "1", "--json", "--overwrite",
           "-o", str(tmp_path / "o.obj")]
    assert main(run) == 0                          # project (0.3) over the default (0.2)
    p = _json(capsys.readouterr().out)["params"]
    assert p["lam"] == 0.3 and p["max_iterations"] == 1 and p["rho0"] == 1e-4
    assert main(run + ["--params", str(pfile)]) == 0   # the file over the project
    p = _json(capsys.readouterr().out)["params"]
    assert p["lam"] == 0.5 and p["rho0"] == 0.001 and p["max_iterations"] == 1
    assert main(run + ["--params", str(pfile), "--lambda", "0.7"]) == 0   # flags over all
    p = _json(capsys.readouterr().out)["params"]
    assert p["lam"] == 0.7 and p["rho0"] == 0.001
    # on a plain mesh: defaults < file < flags
    assert main(["cubic", str(SPOT), "-o", str(tmp_path / "m.obj"), "--max-iterations", "1",
                 "--json", "--params", str(pfile)]) == 0
    assert _json(capsys.readouterr().out)["params"]["lam"] == 0.5


def test_bad_params_files_are_plain_errors(tmp_path, capsys):
    out = tmp_path / "o.obj"
    cases = [({"lam": 0.4, "lamda": 1}, "'lamda' (did you mean 'lam'?)"),
             ([0.4], "JSON object"), ("{not json", "not valid JSON"),
             ({"lam": -1}, "at least 0")]
    for content, words in cases:
        f = tmp_path / "p.json"
        f.write_text(content if isinstance(content, str) else json.dumps(content))
        assert main(["cubic", str(SPOT), "-o", str(out), "--params", str(f)]) == 5
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err
        assert not out.exists()
    assert main(["smooth", str(SPOT), "-o", str(out), "--params",
                 str(tmp_path / "missing.json")]) == 5
    assert "no file" in capsys.readouterr().err and not out.exists()


def test_every_method_command_takes_params_and_a_project(capsys):
    for command in ("smooth", "multigrid-info", "cubic", "analogy", "coarsen", "subdivide",
                    "subdivide-train", "subdivide-eval", "paparazzi", "adversary"):
        with pytest.raises(SystemExit) as e:
            cli.build_parser().parse_args([command, "--help"])
        assert e.value.code == 0
        text = capsys.readouterr().out
        assert "--params FILE.json" in text and ".s3d" in text, command


# ----------------------------------------------------------------------------- smooth = recipe
def test_smooth_on_a_project_uses_its_saved_settings(tmp_path, capsys):
    panels = {"Smooth": {"params": {"iterations": 3, "flow": "cmcf", "step_size": 0.002},
                         "options": {}}}
    path = save_project(tmp_path / "s.s3d", _painted_project(panels))
    out = tmp_path / "s.obj"
    assert main(["smooth", str(path), "-o", str(out), "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["iterations"] == 3 and rep["params"]["flow"] == "cmcf"
    ref = app.recipes.run("smooth", read_project(path)).state.V
    assert np.array_equal(read_mesh(out).V, ref)
    # a --params file of data-smoothing names switches to data smoothing, as its flags do
    f = tmp_path / "d.json"
    f.write_text(json.dumps({"energy": "dirichlet", "alpha": 0.001}))
    assert main(["smooth", str(path), "-o", str(tmp_path / "d.obj"), "--params", str(f),
                 "--json", "--solver", "direct"]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["signal"] == "positions" and rep["params"] == {
        "energy": "dirichlet", "alpha": 0.001, "solver": "direct"}


# ----------------------------------------------------------------------------- other methods
def test_other_commands_use_the_projects_mesh_and_saved_params(tmp_path, capsys):
    panels = {"Subdivision": {"params": {"method": "loop", "levels": 1, "coarsen_first": 0},
                              "options": {}},
              "Analogies": {"params": {"max_iterations": 3}, "options": {}}}
    path = save_project(tmp_path / "x.s3d", _painted_project(panels))
    n_faces = len(_spot_state().F)
    out = tmp_path / "sub.obj"
    assert main(["subdivide", str(path), "-o", str(out), "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["method"] == "loop" and rep["levels"] == 1
    assert len(read_mesh(out).F) == 4 * n_faces
    assert main(["subdivide", str(path), "-o", str(tmp_path / "sub2.obj"), "--json",
                 "--method", "midpoint"]) == 0
    assert _json(capsys.readouterr().out)["method"] == "midpoint"
    assert main(["analogy", str(path), "-o", str(tmp_path / "a.obj"), "--json",
                 "--no-progressive"]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["params"]["max_iterations"] == 3 and rep["iterations"] <= 3
    assert main(["info", str(path), "--json"]) == 0
    assert _json(capsys.readouterr().out)["stats"]["faces"] == n_faces


def test_a_damaged_project_is_a_plain_error(tmp_path, capsys):
    bad = tmp_path / "bad.s3d"
    bad.write_bytes(b"not a zip")
    out = tmp_path / "o.obj"
    assert main(["cubic", str(bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "not a Stylize3D project" in err and "Traceback" not in err and not out.exists()


# ----------------------------------------------------------------------------- mistyped commands
def test_a_mistyped_command_is_named_with_a_suggestion():
    r = subprocess.run([sys.executable, "-m", "app", "cubc", "x"], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert r.stderr.strip() == "stylize3d: unknown command 'cubc'. Did you mean 'cubic'?"
    assert r.stdout == ""


def test_what_opens_the_app_and_what_is_a_typo(monkeypatch, tmp_path, capsys):
    opened = []
    monkeypatch.setattr(cli, "gui_main", lambda argv: opened.append(list(argv)) or 0)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "meshfile").write_text("")        # an existing file without an extension
    for argv in (["missing.obj"], ["scene.s3d"], ["meshfile"], [str(SAMPLES / "blob.obj")],
                 ["--study", "p.json"], ["sub/dir"], []):
        assert app_main(argv) == 0
        assert opened[-1] == argv
    n = len(opened)
    assert app_main(["smoth", "a.obj"]) == 2
    assert "unknown command 'smoth'. Did you mean 'smooth'?" in capsys.readouterr().err
    assert app_main(["frobnicate"]) == 2
    err = capsys.readouterr().err
    assert "unknown command 'frobnicate'" in err and "cubic" in err
    assert main(["subdivde", "x.obj"]) == 2
    assert "Did you mean 'subdivide'?" in capsys.readouterr().err
    assert len(opened) == n                        # none of them opened the app


def test_the_readme_project_examples_run(tmp_path):
    """The README's project examples use the bundled resources/samples/blob-painted.s3d (made by
    scripts/make_samples.py): the painting and the saved settings are used."""
    import json as _json

    from app.project import read_project
    from app.recipes import run
    from tests.conftest import ROOT

    sample = ROOT / "resources" / "samples" / "blob-painted.s3d"
    settings = ROOT / "resources" / "samples" / "cubic-params.json"
    project = read_project(sample)
    assert {"lambda_scale", "fixed"} <= set(project.state.fields) and project.state.handles
    out = tmp_path / "out.obj"
    assert main(["cubic", str(sample), "-o", str(out), "--quiet"]) == 0
    from algorithms.mesh import read_mesh

    np.testing.assert_allclose(read_mesh(out).V, run("cubic", project).state.V, atol=1e-6)
    out2 = tmp_path / "out2.obj"
    assert main(["cubic", str(sample), "-o", str(out2), "--params", str(settings),
                 "--lambda", "0.5", "--quiet"]) == 0
    assert _json.loads(settings.read_text())["max_iterations"] == 60
    fine = tmp_path / "fine.obj"
    assert main(["subdivide", str(sample), "-o", str(fine)]) == 0
    assert len(read_mesh(fine).F) == 4 * len(project.state.F)


def test_a_partial_params_dict_keeps_the_projects_other_settings(tmp_path, capsys):
    """``run("cubic", load(project), {"max_iterations": N})`` keeps the project's λ (issue 39,
    item 3), and gives the bits of the command line with the same flag."""
    proj = app.recipes.load(SAMPLES / "blob-painted.s3d")
    saved = proj.panels["Cubic"]["params"]
    assert saved["lam"] != 0.2                      # not the default: the test can tell
    r = app.recipes.run("cubic", proj, {"max_iterations": 3})
    assert r.params.lam == saved["lam"] and r.params.max_iterations == 3
    out = tmp_path / "cli.obj"
    assert main(["cubic", str(SAMPLES / "blob-painted.s3d"), "-o", str(out),
                 "--max-iters", "3"]) == 0
    assert np.array_equal(read_mesh(out).V, r.state.V)
