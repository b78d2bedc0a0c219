"""`stylize3d analogy`, `paparazzi` and `coarsen` are thin wrappers around their recipes
(issue 20): the command's output is ``app.recipes.run(...)``'s bit for bit, on a plain mesh and
on a project (.s3d) whose saved panel options matter (a painted capture sphere, a style mesh,
a target image, an operator and baselines); flags given on the command line win."""

from __future__ import annotations

import json

import numpy as np
import pytest

import app.recipes
from algorithms.deform.targets import CaptureSphere
from algorithms.mesh import icosphere, read_mesh, write_mesh
from app.cli import main
from app.document import MeshState
from app.project import Project, read_project, save_project
from tests.conftest import TEST_DATA

SPOT = TEST_DATA / "spot_lowres.obj"


def _json(out: str) -> dict:
    return json.loads(out[out.index("{"):out.rindex("}") + 1])


def _state(path) -> MeshState:
    d = read_mesh(path)
    return MeshState.make(d.V, d.F)


def _forget_blobs(*refs: str) -> None:
    """Drop blobs from this process's store: a run must find them in the project file."""
    for ref in refs:
        app.recipes._BLOBS.pop(ref, None)
        app.recipes._BLOB_FILES.pop(ref, None)


def _same_mesh(path, state) -> None:
    got = read_mesh(path)
    assert got.V.dtype == state.V.dtype and np.array_equal(got.V, state.V)
    assert np.array_equal(got.F, state.F)


# ----------------------------------------------------------------------------- analogy
@pytest.fixture
def style_mesh(tmp_path):
    """A small bumpy sphere (a style mesh for the spherical parameterization)."""
    V, F = icosphere(2)
    V = V * (1 + 0.15 * np.sin(3 * V[:, :1]) * np.cos(2 * V[:, 1:2]))
    p = tmp_path / "bumpy_style.obj"
    write_mesh(p, V, F)
    return p


def test_analogy_on_a_mesh_is_the_recipe_run(tmp_path, capsys, style_mesh):
    out = tmp_path / "a.obj"
    assert main(["analogy", str(SPOT), "-o", str(out), "--max-iterations", "6", "--lambda",
                 "2", "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["style"] == "cube" and rep["iterations"] == 6
    ref = app.recipes.run("analogy", _state(SPOT), {"max_iterations": 6, "lam": 2.0},
                          {"style": "cube", "style_map": "auto", "progressive": None})
    _same_mesh(out, ref.state)
    assert rep["mean_angle_after"] < rep["mean_angle_before"]
    # a style mesh given as a file is a blob of the recipe's options
    style = style_mesh
    out2 = tmp_path / "b.obj"
    assert main(["analogy", str(SPOT), "-o", str(out2), "--max-iterations", "4", "--style",
                 str(style), "--style-map", "spherical", "--quiet"]) == 0
    ref2 = app.recipes.run("analogy", _state(SPOT), {"max_iterations": 4},
                           {"style": app.recipes.put_blob_file(style),
                            "style_map": "spherical"})
    _same_mesh(out2, ref2.state)
    assert np.abs(ref2.state.V - ref.state.V).max() > 1e-3


def test_analogy_on_a_project_uses_its_saved_capture_sphere_and_style_mesh(tmp_path, capsys,
                                                                          style_mesh):
    cap = CaptureSphere(3)
    cap.paint_cap([0, 1, 0], 40.0, [0, 0, 1])  # normals facing up are sent to +z
    panels = {"Analogies": {"params": {"max_iterations": 5, "lam": 3.0},
                            "options": {"style": "capture sphere", "style_map": "auto",
                                        "capture": cap.to_dict()}}}
    path = save_project(tmp_path / "cap.s3d", Project(state=_state(SPOT), panels=panels))
    out = tmp_path / "cap.obj"
    assert main(["analogy", str(path), "-o", str(out), "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["style"] == "capture sphere" and "capture" in rep["style_map"]
    assert rep["params"]["lam"] == 3.0 and rep["progressive_faces"] is None
    ref = app.recipes.run("analogy", read_project(path))
    _same_mesh(out, ref.state)
    # the saved capture matters: the cube (a flag given here wins) gives another shape
    cube = tmp_path / "cube.obj"
    assert main(["analogy", str(path), "-o", str(cube), "--style", "cube", "--quiet"]) == 0
    ref_cube = app.recipes.run("analogy", read_project(path), None,
                               {**panels["Analogies"]["options"], "style": "cube"})
    _same_mesh(cube, ref_cube.state)
    assert np.abs(ref_cube.state.V - ref.state.V).max() > 1e-3
    # a style mesh saved in the project (a blob) is read from the project file
    ref_style = app.recipes.put_blob_file(style_mesh)
    panels = {"Analogies": {"params": {"max_iterations": 4},
                            "options": {"style": ref_style, "style_map": "spherical"}}}
    path2 = save_project(tmp_path / "mesh.s3d", Project(state=_state(SPOT), panels=panels))
    _forget_blobs(ref_style)
    out2 = tmp_path / "mesh.obj"
    assert main(["analogy", str(path2), "-o", str(out2), "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["style"] == ref_style and rep["style_map"].startswith(
        "spherical map of bumpy_style.obj")
    _same_mesh(out2, app.recipes.run("analogy", read_project(path2)).state)


def test_analogy_capture_sphere_needs_a_saved_one(tmp_path, capsys):
    out = tmp_path / "o.obj"
    assert main(["analogy", str(SPOT), "-o", str(out), "--style", "capture sphere"]) == 5
    err = capsys.readouterr().err
    assert "Unknown style" in err and "Traceback" not in err and not out.exists()


# ----------------------------------------------------------------------------- paparazzi
FAST = {"iterations": 12, "resolution": 32, "remesh_every": 6, "remesh_threshold": 0.0,
        "monitor_every": 0}
FAST_FLAGS = ["--iterations", "12", "--resolution", "32", "--remesh-every", "6",
              "--remesh-threshold", "0", "--monitor-every", "0"]


@pytest.fixture
def sphere(tmp_path):
    V, F = icosphere(2)
    V = V * (1 + 0.05 * np.random.default_rng(0).random((len(V), 1)))
    p = tmp_path / "in.obj"
    write_mesh(p, V, F)
    return p


@pytest.fixture
def target_png(tmp_path):
    from PIL import Image

    yy, xx = np.mgrid[0:32, 0:32]
    img = np.stack([(xx * 8) % 256, (yy * 8) % 256, ((xx + yy) * 4) % 256], axis=2)
    p = tmp_path / "target.png"
    Image.fromarray(img.astype(np.uint8)).save(p)
    return p


def test_paparazzi_on_a_mesh_is_the_recipe_run(sphere, target_png, tmp_path, capsys):
    out = tmp_path / "q.obj"
    assert main(["paparazzi", str(sphere), "-o", str(out), "--filter", "quantize", "--seed",
                 "5", "--json", *FAST_FLAGS]) == 0
    rep = _json(capsys.readouterr().out)
    ref = app.recipes.run("paparazzi", _state(sphere), {**FAST, "seed": 5},
                          {"filter": "quantize", "filter_params": {}})
    _same_mesh(out, ref.state)
    assert rep["final_monitor_energy"] == ref.outcome["monitor_energy"]
    assert rep["remeshes"] == ref.outcome["remeshes"] == 1
    assert rep["input_self_intersecting_pairs"] == 0 and rep["setup_seconds"] > 0
    # a target image given as a file is a blob of the recipe's options
    out2 = tmp_path / "t.obj"
    assert main(["paparazzi", str(sphere), "-o", str(out2), "--filter", "target-image",
                 "--image", str(target_png), "--json", *FAST_FLAGS]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["filter_params"] == {"image": str(target_png)}
    ref2 = app.recipes.run("paparazzi", _state(sphere), FAST,
                           {"filter": "target-image",
                            "filter_params": {"image": app.recipes.put_blob_file(target_png)}})
    _same_mesh(out2, ref2.state)
    assert np.abs(ref2.state.V - ref.state.V).max() > 1e-6


def test_paparazzi_on_a_project_uses_its_saved_filter_and_image(sphere, target_png, tmp_path,
                                                               capsys):
    image = app.recipes.put_blob_file(target_png)
    panels = {"Paparazzi": {"params": {**FAST, "seed": 2},
                            "options": {"filter": "target-image",
                                        "filter_params": {"image": image}}}}
    path = save_project(tmp_path / "p.s3d", Project(state=_state(sphere), panels=panels))
    _forget_blobs(image)
    out = tmp_path / "p.obj"
    assert main(["paparazzi", str(path), "-o", str(out), "--json"]) == 0  # no --filter
    rep = _json(capsys.readouterr().out)
    assert rep["filter"] == "target-image" and rep["filter_params"] == {"image": image}
    assert rep["params"]["seed"] == 2
    ref = app.recipes.run("paparazzi", read_project(path))
    _same_mesh(out, ref.state)
    # flags win: the same filter with another image, or another filter
    other = tmp_path / "other.png"
    from PIL import Image

    Image.fromarray(np.full((32, 32, 3), 200, np.uint8)).save(other)
    out2 = tmp_path / "p2.obj"
    assert main(["paparazzi", str(path), "-o", str(out2), "--filter", "target-image",
                 "--image", str(other), "--quiet"]) == 0
    ref2 = app.recipes.run("paparazzi", read_project(path), None,
                           {"filter": "target-image",
                            "filter_params": {"image": app.recipes.put_blob_file(other)}})
    _same_mesh(out2, ref2.state)
    assert np.abs(ref2.state.V - ref.state.V).max() > 1e-6
    out3 = tmp_path / "p3.obj"
    assert main(["paparazzi", str(path), "-o", str(out3), "--filter", "quantize",
                 "--quiet"]) == 0
    _same_mesh(out3, app.recipes.run("paparazzi", read_project(path), None,
                                     {"filter": "quantize"}).state)


PLUGIN = '''
from dataclasses import dataclass

from algorithms.params import param
from algorithms.paparazzi import register_filter


@dataclass(frozen=True)
class Dim:
    test_dim: float = param(0.5, label="Dim", minimum=0.0, maximum=1.0, tooltip="Darker.")


@register_filter("test-cli-recipes-dim", kind="iterative", params=Dim)
def dim(image, params, ctx):
    return image * params.test_dim
'''


def test_paparazzi_on_a_project_loads_its_saved_plugin(sphere, tmp_path, capsys):
    from algorithms.paparazzi import filter_names, unregister_filter

    plugin = tmp_path / "dim_plugin.py"
    plugin.write_text(PLUGIN)
    ref = app.recipes.put_blob_file(plugin)
    plugin.unlink()  # the project's copy is used
    panels = {"Paparazzi": {"params": FAST, "options": {
        "filter": "test-cli-recipes-dim", "filter_params": {"test_dim": 0.25}, "plugin": ref}}}
    path = save_project(tmp_path / "plug.s3d", Project(state=_state(sphere), panels=panels))
    _forget_blobs(ref)
    out = tmp_path / "plug.obj"
    try:
        assert "test-cli-recipes-dim" not in filter_names()
        assert main(["paparazzi", str(path), "-o", str(out), "--json"]) == 0
        rep = _json(capsys.readouterr().out)
        assert rep["filter"] == "test-cli-recipes-dim"
        assert rep["filter_params"] == {"test_dim": 0.25}
        _same_mesh(out, app.recipes.run("paparazzi", read_project(path)).state)
    finally:
        unregister_filter("test-cli-recipes-dim")


def test_paparazzi_without_a_filter_on_a_mesh_is_a_usage_error(sphere, tmp_path, capsys):
    out = tmp_path / "o.obj"
    assert main(["paparazzi", str(sphere), "-o", str(out), *FAST_FLAGS]) == 2
    err = capsys.readouterr().err
    assert "--filter" in err and "Traceback" not in err and not out.exists()


# ----------------------------------------------------------------------------- coarsen
def _npz_is_the_outcome(path, outcome: dict) -> None:
    z = np.load(path)
    for name in ("L", "M", "P", "G"):
        for part in ("data", "indices", "indptr", "shape"):
            assert np.array_equal(z[f"{name}_{part}"], outcome[f"ours.{name}.{part}"]), name
    assert z["L_data"].dtype == outcome["ours.L.data"].dtype
    # K: the m × n cluster indicator (a one in the row of each fine vertex's cluster)
    m, n = z["K_shape"]
    assert (m, n) == (len(outcome["ours.roots"]), len(outcome["ours.clusters"]))
    assert np.array_equal(z["K_indices"], np.argsort(outcome["ours.clusters"], kind="stable"))
    assert np.array_equal(np.diff(z["K_indptr"]), np.bincount(outcome["ours.clusters"],
                                                               minlength=m))
    assert np.array_equal(z["K_data"], np.ones(n))


def _report_is_the_outcome(rep: dict, outcome: dict) -> None:
    assert (rep["n"], rep["m"], rep["k"]) == (outcome["n"], outcome["m"], outcome["k"])
    assert list(rep["methods"]) == outcome["methods"]
    for name, d in rep["methods"].items():
        assert d["c_diag_score"] == outcome[f"{name}.c_diag_score"]
        assert d["eig_rel_err_mean"] == outcome[f"{name}.eig_rel_error_mean"]
        assert d["eig_rel_err_max"] == outcome[f"{name}.eig_rel_error_max"]
        assert d["seconds"] > 0
    assert rep["methods"]["ours"]["iterations"] == outcome["ours.iterations"]


def test_coarsen_on_a_mesh_is_the_recipe_run(tmp_path, capsys):
    out = tmp_path / "c.npz"
    assert main(["coarsen", str(SPOT), "--m", "60", "--k", "10", "--max-iterations", "15",
                 "--compare", "amg", "-o", str(out), "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    ref = app.recipes.run("coarsen", _state(SPOT), {"m": 60, "k": 10, "max_iterations": 15},
                          {"operator": "cotangent", "compare": ["amg"], "isolated": False})
    _report_is_the_outcome(rep, ref.outcome)
    _npz_is_the_outcome(out, ref.outcome)
    # the table names each method's figures
    assert main(["coarsen", str(SPOT), "--m", "60", "--k", "10", "--max-iterations", "15",
                 "--quiet"]) == 0
    text = capsys.readouterr().out.splitlines()
    assert text[0].split() == ["method", "m", "C", "diag", "eig", "mean", "eig", "max", "s"]
    assert len(text) == 2 and text[1].split()[:3] == [
        "ours", "60", f"{ref.outcome['ours.c_diag_score']:.3f}"]


def test_coarsen_on_a_project_uses_its_saved_operator_and_baselines(tmp_path, capsys):
    panels = {"Spectral coarsening": {
        "params": {"m": 60, "k": 10, "max_iterations": 15},
        "options": {"operator": "anisotropic", "alpha": 70.0, "compare": ["amg"],
                    "isolated": True}}}
    path = save_project(tmp_path / "s.s3d", Project(state=_state(SPOT), panels=panels))
    out = tmp_path / "s.npz"
    assert main(["coarsen", str(path), "-o", str(out), "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    # the panel runs it in a child process; the command in this process
    opts = {**panels["Spectral coarsening"]["options"], "isolated": False}
    ref = app.recipes.run("coarsen", read_project(path), None, opts)
    assert list(rep["methods"]) == ["ours", "amg"]
    _report_is_the_outcome(rep, ref.outcome)
    _npz_is_the_outcome(out, ref.outcome)
    # flags win: --operator and --compare "" (no baselines)
    out2 = tmp_path / "t.npz"
    assert main(["coarsen", str(path), "-o", str(out2), "--json", "--operator", "cotan",
                 "--compare", ""]) == 0
    rep2 = _json(capsys.readouterr().out)
    ref2 = app.recipes.run("coarsen", read_project(path), None,
                           {**opts, "operator": "cotangent", "alpha": 10.0, "compare": []})
    _report_is_the_outcome(rep2, ref2.outcome)
    _npz_is_the_outcome(out2, ref2.outcome)
    assert not np.array_equal(ref.outcome["fine.eigenvalues"], ref2.outcome["fine.eigenvalues"])
