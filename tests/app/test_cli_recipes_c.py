"""`stylize3d adversary` is a thin wrapper around the Adversarial lighting recipes: its output
file (the attacked lighting, or the attacked mesh) and its report equal app.recipes.run on the
same input bit for bit, on a mesh file (its own colours used) and on a project (the panel's
saved lighting, colours, labels, view and classifier used; flags win). A tiny TorchScript
classifier keeps every run cheap."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from algorithms.adversarial import find_recognized_views, prepare_scene  # noqa: E402
from algorithms.adversarial.lighting_io import read_lighting  # noqa: E402
from algorithms.adversarial.shapes import SUBJECTS  # noqa: E402
from algorithms.mesh import read_mesh, write_mesh  # noqa: E402
from algorithms.render.sh import environment  # noqa: E402
from app.cli import main  # noqa: E402
from app.document import MeshState  # noqa: E402
from app.project import Project, read_project, save_project  # noqa: E402
from app.recipes import adversarial as rcp  # noqa: E402
from app.recipes import put_blob_file, run  # noqa: E402

pytestmark = pytest.mark.filterwarnings("ignore:`torch.jit:DeprecationWarning")

SMALL = {"iterations": 3, "resolution": 64, "supersample": 1}
SMALL_FLAGS = ["--iterations", "3", "--resolution", "64", "--supersample", "1"]
PANEL = "Adversarial lighting"


class _Tiny(torch.nn.Module):
    def __init__(self):
        super().__init__()
        self.conv = torch.nn.Conv2d(3, 6, 7, stride=8)
        self.fc = torch.nn.Linear(6, 10)

    def forward(self, x):
        return self.fc(torch.tanh(self.conv(x)).mean((2, 3)))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A small TorchScript classifier file of 10 classes ("class 0".."class 9")."""
    torch.manual_seed(5)
    path = tmp_path_factory.mktemp("cli_adv") / "tiny.pt"
    torch.jit.script(_Tiny()).save(str(path))
    return path


@pytest.fixture(scope="module")
def candle(tmp_path_factory):
    """The candle as an OBJ file with vertex colours, and its state as the CLI reads it."""
    V, F, _ = SUBJECTS["candle"]()
    t = (V[:, 1] - V[:, 1].min()) / np.ptp(V[:, 1])
    colours = np.stack([0.2 + 0.7 * t, 0.8 - 0.5 * t, 0.4 + 0 * t], axis=1)
    path = tmp_path_factory.mktemp("cli_adv") / "candle.obj"
    write_mesh(path, V, F, vertex_colors=colours)
    d = read_mesh(path)
    return path, MeshState.make(d.V, d.F)


def _report(out: str) -> dict:
    return json.loads(out)


def _check_report(rep: dict, outcome: dict):
    assert rep["success_rate"] == outcome["success_rate"]
    assert rep["random_success_rate"] == outcome["random_success_rate"]
    assert rep["norm"] == outcome["norm"]
    assert [v["confidence_before"] for v in rep["views"]] == list(outcome["confidence_before"])
    assert [v["confidence_after"] for v in rep["views"]] == list(outcome["confidence_after"])
    assert [v["label_after"] for v in rep["views"]] == [
        f"class {k}" for k in outcome["label_after"]]
    assert [v["success"] for v in rep["views"]] == [bool(x) for x in outcome["fooled"]]


# ----------------------------------------------------------------------------- mesh files
def test_lighting_attack_on_a_mesh_file_is_the_recipe_run(candle, tiny, tmp_path, capsys):
    path, state = candle
    out = tmp_path / "light.json"
    code = main(["adversary", str(path), "--mode", "lighting", *SMALL_FLAGS, "--views", "2",
                 "--classifier", str(tiny), "--target", "class 7",
                 "--lighting", "St. Peter's Basilica", "-o", str(out), "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    face = rcp.read_face_colors((str(path), len(state.V), len(state.F)), state.F)
    assert face is not None and np.ptp(face) > 0.3          # the file's colours, per face
    options = {"classifier": put_blob_file(tiny), "environment": "St. Peter's Basilica",
               "target": "class 7", "face_colors": rcp.face_colors_ref(face),
               "random_baseline": True}
    params = {**SMALL, "views": 2}
    ref = run("adversary", state, params, options)
    assert np.array_equal(read_lighting(out), ref.outcome["lighting"])
    rep = _report(captured.out)
    _check_report(rep, ref.outcome)
    # the file's colours are an input that matters: grey gives other figures
    grey = run("adversary", state, params, {**options, "face_colors": None})
    assert not np.array_equal(grey.outcome["probabilities_before"],
                              ref.outcome["probabilities_before"])
    # a headless run again: the same bits
    again = run("adversary", state, params, json.loads(json.dumps(options)))
    assert np.array_equal(again.outcome["lighting"], ref.outcome["lighting"])


def test_geometry_attack_on_a_mesh_file_is_the_recipe_run(candle, tiny, tmp_path, capsys):
    path, state = candle
    out = tmp_path / "adv.obj"
    start = tmp_path / "start.json"
    start.write_text(json.dumps({"coefficients": environment("Eucalyptus Grove")[:9].tolist()}))
    code = main(["adversary", str(path), "--mode", "geometry", *SMALL_FLAGS, "--iterations",
                 "2", "--classifier", str(tiny), "--lighting", str(start), "--seed", "4",
                 "-o", str(out), "--quiet"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "success rate" in captured.out and "view 1 (azimuth 0°)" in captured.out
    face = rcp.read_face_colors((str(path), len(state.V), len(state.F)), state.F)
    options = {"classifier": put_blob_file(tiny), "lighting": read_lighting(start).tolist(),
               "face_colors": rcp.face_colors_ref(face)}
    ref = run("adversary-geometry", state, {**SMALL, "iterations": 2, "seed": 4}, options)
    got = read_mesh(out)
    assert np.array_equal(got.F, state.F)
    assert got.V.dtype == ref.state.V.dtype and np.array_equal(got.V, ref.state.V)
    assert not np.array_equal(got.V, state.V)


def test_label_chooses_the_recognized_views(candle, tiny, tmp_path, capsys):
    path, state = candle
    V, F = state.V, state.F
    face = rcp.read_face_colors((str(path), len(V), len(F)), F)
    scene = prepare_scene(V, F, albedo=face, lighting="Grace Cathedral")
    clf = rcp.classifier_of(put_blob_file(tiny))
    seen = {k: find_recognized_views(scene, clf, k, resolution=64, supersample=1)
            for k in range(10)}
    label = max(seen, key=lambda k: len(seen[k]))
    assert seen[label]
    out = tmp_path / "l.json"
    code = main(["adversary", str(path), *SMALL_FLAGS, "--views", "2", "--classifier",
                 str(tiny), "--label", f"class {label}", "-o", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    azimuths = [a for a, _ in seen[label][:2]]
    assert f"view 1 (azimuth {azimuths[0]:.0f}°): class {label}" in captured.out
    options = {"classifier": put_blob_file(tiny), "face_colors": rcp.face_colors_ref(face),
               "true_label": f"class {label}", "azimuths": azimuths}
    ref = run("adversary", state, {**SMALL, "views": 2}, options)
    assert np.array_equal(read_lighting(out), ref.outcome["lighting"])
    unseen = [k for k in range(10) if not seen[k]]
    if unseen:
        assert main(["adversary", str(path), *SMALL_FLAGS, "--classifier", str(tiny),
                     "--label", f"class {unseen[0]}"]) == 5
        err = capsys.readouterr().err
        assert "does not see" in err and "Traceback" not in err


# ----------------------------------------------------------------------------- projects
def _project(tmp_path, tiny, mode: str):
    V, F, _ = SUBJECTS["candle"]()
    options = {"lighting": environment("Eucalyptus Grove")[:9].tolist(),
               "environment": "Custom", "true_label": "", "target": "class 3",
               "azimuth": 40, "classifier": put_blob_file(tiny), "classifier_name": "tiny.pt",
               "color": [0.9, 0.5, 0.2], "face_colors": None}
    params = {**SMALL, "iterations": 2, "views": 2, "mode": mode, "seed": 2}
    project = Project(MeshState.make(V, F), panels={PANEL: {"params": params,
                                                            "options": options}})
    return save_project(tmp_path / f"{mode}.s3d", project)


def test_lighting_attack_on_a_project_uses_its_saved_options(tiny, tmp_path, capsys):
    path = _project(tmp_path, tiny, "lighting")
    out = tmp_path / "p.json"
    assert main(["adversary", str(path), "-o", str(out), "--json"]) == 0   # no flags at all
    rep = _report(capsys.readouterr().out)
    project = read_project(path)
    ref = run("adversary", project)                       # the panel's saved params + options
    assert np.array_equal(read_lighting(out), ref.outcome["lighting"])
    assert len(rep["views"]) == 2
    assert rep["success_rate"] == ref.outcome["success_rate"] and rep["norm"] == \
        ref.outcome["norm"]
    assert [v["confidence_after"] for v in rep["views"]] == list(
        ref.outcome["confidence_after"])
    # the saved options matter: the defaults (same classifier) give another lighting
    plain = run("adversary", project.state, project.params_of(PANEL),
                {"classifier": put_blob_file(tiny)})
    assert not np.array_equal(plain.outcome["lighting"], ref.outcome["lighting"])
    # flags win over the saved options
    out2 = tmp_path / "p2.json"
    assert main(["adversary", str(path), "-o", str(out2), "--json", "--lighting",
                 "Grace Cathedral", "--color", "0.3", "0.6", "0.9", "--target", "class 1",
                 "--views", "1"]) == 0
    rep2 = _report(capsys.readouterr().out)
    opts = {**project.options_of(PANEL), "lighting": None, "environment": "Grace Cathedral",
            "color": [0.3, 0.6, 0.9], "target": "class 1", "random_baseline": True}
    ref2 = run("adversary", project, {**project.params_of(PANEL), "views": 1}, opts)
    assert np.array_equal(read_lighting(out2), ref2.outcome["lighting"])
    _check_report(rep2, ref2.outcome)


def test_geometry_attack_on_a_project_uses_its_saved_options(tiny, tmp_path, capsys):
    path = _project(tmp_path, tiny, "geometry")
    out = tmp_path / "g.obj"
    assert main(["adversary", str(path), "-o", str(out), "--json"]) == 0
    rep = _report(capsys.readouterr().out)
    project = read_project(path)
    ref = run("adversary-geometry", project, project.params_of(PANEL),
              {**project.options_of(PANEL), "random_baseline": True})
    got = read_mesh(out).V
    assert got.dtype == ref.state.V.dtype and np.array_equal(got, ref.state.V)
    _check_report(rep, ref.outcome)
    # the saved options matter: the default view and colour move other vertices
    plain = run("adversary-geometry", project.state, project.params_of(PANEL),
                {"classifier": put_blob_file(tiny)})
    assert not np.array_equal(plain.state.V, got)
