"""``subdivide``, ``subdivide-train`` and ``smooth --signal`` run their recipes: the CLI's output
file is what ``app.recipes.run`` makes, bit for bit, on a plain mesh and on a project whose
saved panel options matter (issue 20)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import app.recipes
from algorithms.mesh import read_mesh, write_mesh
from app.cli import main
from app.document import MeshState
from app.project import Project, read_project, save_project
from app.recipes import multigrid as rm
from tests.conftest import SAMPLES, TEST_DATA

SPOT = TEST_DATA / "spot_lowres.obj"
HAND = TEST_DATA / "hand_lowres.obj"
BLOB = SAMPLES / "blob.obj"
#: a tiny training (3 coarse meshes of 60-80 vertices), made in this process, no cache
TINY = {"coarse_meshes": 3, "min_vertices": 60, "max_vertices": 80, "epochs": 2}
TINY_FLAGS = ["--min-vertices", "60", "--max-vertices", "80", "--workers", "1", "--no-cache"]
LOCAL = {"workers": 1, "cache": False}


def _state(path) -> MeshState:
    d = read_mesh(path)
    return MeshState.make(d.V, d.F)


def _json(out: str) -> dict:
    return json.loads(out[out.index("{"):out.rindex("}") + 1])


def _same_mesh_file(path, state, tmp_path):
    """The CLI's mesh file holds ``state``'s mesh: the same bytes as writing it, and the same
    float64 bits read back."""
    ref = tmp_path / ("ref" + path.suffix)
    write_mesh(ref, state.V, state.F)
    assert path.read_bytes() == ref.read_bytes()
    m = read_mesh(path)
    assert m.V.tobytes() == np.asarray(state.V, dtype=np.float64).tobytes()
    assert np.array_equal(m.F, state.F)


# ----------------------------------------------------------------------------- subdivision
@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """subdivide-train on spot (tiny), and the recipe's run of the same input."""
    torch = pytest.importorskip("torch")
    d = tmp_path_factory.mktemp("train")
    w = d / "w.pt"
    flags = ["--coarse-meshes", "3", "--epochs", "2", *TINY_FLAGS]
    assert main(["subdivide-train", str(SPOT), "-o", str(w), "--json", *flags]) == 0
    ref = app.recipes.run("subdivide-train", _state(SPOT), TINY, LOCAL)
    return torch, w, ref


def test_subdivide_train_is_the_recipe_run(trained, tmp_path, capsys):
    from algorithms.subdivision.model import load_weights
    from app.recipes import subdivision as rs

    torch, w, ref = trained
    # the file: the recipe's best weights, with the trained_on the command line always wrote
    assert w.read_bytes() == rs.trained_weights_bytes(ref.last, {"trained_on": SPOT.name})
    net, info = load_weights(w)
    best = rs.load_network(ref.outcome["weights"]).state()
    assert all(torch.equal(v, best[k]) for k, v in net.state().items())
    assert info["trained_on"] == SPOT.name and info["epochs_run"] == 2
    # --json: the outcome's figures, and the keys it always had
    out = tmp_path / "again.pt"
    assert main(["subdivide-train", str(SPOT), "-o", str(out), "--json", "--coarse-meshes", "3",
                 "--epochs", "2", *TINY_FLAGS]) == 0
    rep = _json(capsys.readouterr().out)
    assert out.read_bytes() == w.read_bytes()  # repeatable
    assert set(rep) == {"weights", "meshes", "coarse_meshes", "epochs", "best_epoch",
                        "best_validation_loss", "final_loss", "stopped_early", "seconds_data",
                        "seconds_training", "seconds_per_epoch"}
    assert (rep["epochs"], rep["best_epoch"]) == (2, ref.outcome["best_epoch"])
    assert rep["best_validation_loss"] == ref.outcome["best_validation_loss"]
    assert rep["final_loss"] == ref.outcome["losses"][-1] and rep["coarse_meshes"] == 3
    # several meshes: the coarse meshes spread over both (other weights than spot's alone)
    both = tmp_path / "both.pt"
    assert main(["subdivide-train", str(SPOT), str(HAND), "-o", str(both), "--quiet",
                 "--coarse-meshes", "3", "--epochs", "2", *TINY_FLAGS]) == 0
    capsys.readouterr()
    net2, info2 = load_weights(both)
    assert info2["trained_on"] == f"{SPOT.name}, {HAND.name}"
    assert not all(torch.equal(v, best[k]) for k, v in net2.state().items())
    assert main(["subdivide-train", str(SPOT), "-o", str(both), *TINY_FLAGS]) == 3  # exists


def test_subdivide_train_on_a_project_uses_its_training_settings(trained, tmp_path, capsys):
    from app.recipes import subdivision as rs

    torch, _w, _ref = trained
    panels = {"Subdivision": {"params": {"method": "loop", "levels": 1},
                              "options": {"weights": "shipped",
                                          "training": {"coarse_meshes": 4, "epochs": 3}}}}
    path = save_project(tmp_path / "t.s3d", Project(state=_state(SPOT), panels=panels))
    out = tmp_path / "p.pt"
    assert main(["subdivide-train", str(path), "-o", str(out), "--json", *TINY_FLAGS]) == 0
    rep = _json(capsys.readouterr().out)
    assert (rep["coarse_meshes"], rep["epochs"]) == (4, 3)
    ref = app.recipes.run("subdivide-train", read_project(path).state,
                          {**TINY, "coarse_meshes": 4, "epochs": 3}, LOCAL)
    assert out.read_bytes() == rs.trained_weights_bytes(ref.last, {"trained_on": path.name})
    # flags win over the project's settings
    assert main(["subdivide-train", str(path), "-o", str(tmp_path / "q.pt"), "--json",
                 "--epochs", "1", *TINY_FLAGS]) == 0
    assert _json(capsys.readouterr().out)["epochs"] == 1


def test_subdivide_is_the_recipe_run_on_a_mesh(trained, tmp_path, capsys):
    from app.recipes.subdivision import weights_blob_from_file

    _torch, w, _ref = trained
    hand = _state(HAND)
    cases = [(["--method", "loop", "--levels", "1"], {"method": "loop", "levels": 1}, {}),
             # the hand is denser than the networks were trained for: "scale" makes both run
             # the network (the default falls back to Loop), so the weights file shows
             (["--levels", "1", "--dense-input", "scale"], {"levels": 1, "dense_input": "scale"},
              {}),
             (["--levels", "1", "--weights", str(w), "--dense-input", "scale"],
              {"levels": 1, "dense_input": "scale"},
              {"weights": "file", "weights_file": weights_blob_from_file(w)}),
             (["--levels", "1", "--coarsen-first", "400", "--method", "butterfly"],
              {"levels": 1, "coarsen_first": 400, "method": "butterfly"}, {})]
    results = []
    for k, (flags, params, options) in enumerate(cases):
        out = tmp_path / f"s{k}.obj"
        assert main(["subdivide", str(HAND), "-o", str(out), "--json", *flags]) == 0
        rep = _json(capsys.readouterr().out)
        ref = app.recipes.run("subdivide", hand, params, options)
        _same_mesh_file(out, ref.state, tmp_path)
        assert rep["faces"] == ref.outcome["faces"] and rep["vertices"] == ref.outcome["vertices"]
        results.append(ref.state.V)
    assert not np.array_equal(results[1], results[2])  # the weights file is used


def test_subdivide_on_a_project_uses_its_saved_weights(trained, tmp_path, capsys):
    from app.recipes.subdivision import weights_blob_from_file

    _torch, w, _ref = trained
    panels = {"Subdivision": {"params": {"method": "neural", "levels": 1, "coarsen_first": 0,
                                         "dense_input": "scale"},
                              "options": {"weights": "file",
                                          "weights_file": weights_blob_from_file(w),
                                          "training": {"coarse_meshes": 3, "epochs": 2}}}}
    path = save_project(tmp_path / "s.s3d", Project(state=_state(HAND), panels=panels))
    w.rename(tmp_path / "moved.pt")  # the project holds the weights itself
    try:
        out = tmp_path / "p.obj"
        assert main(["subdivide", str(path), "-o", str(out), "--json"]) == 0
        capsys.readouterr()
        project = read_project(path)
        ref = app.recipes.run("subdivide", project)  # its saved params and options
        _same_mesh_file(out, ref.state, tmp_path)
        shipped = app.recipes.run("subdivide", project.state,
                                  {"levels": 1, "dense_input": "scale"}, {}).state
        assert not np.array_equal(ref.state.V, shipped.V)
        # --weights shipped wins over the saved choice
        out2 = tmp_path / "shipped.obj"
        assert main(["subdivide", str(path), "-o", str(out2), "--weights", "shipped"]) == 0
        _same_mesh_file(out2, shipped, tmp_path)
    finally:
        (tmp_path / "moved.pt").rename(w)


# ----------------------------------------------------------------------------- data smoothing
def test_smooth_data_is_the_recipe_run_on_a_mesh(tmp_path, capsys):
    blob = _state(BLOB)
    # a noisy field (its seed and level), multigrid with a looser tolerance
    out = tmp_path / "n.npy"
    assert main(["smooth", str(BLOB), "-o", str(out), "--signal", "noise", "--seed", "3",
                 "--noise", "0.2", "--solver", "multigrid", "--rtol", "1e-3", "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    opts = {"signal": "noise", "noise": 0.2, "noise_seed": 3, "rtol": 1e-3}
    ref = app.recipes.run("Multigrid smoothing", blob, {"solver": "multigrid"}, opts)
    got = np.load(out)
    assert got.tobytes() == ref.state.fields["smoothed"].tobytes()
    assert rep["cycles"] == ref.outcome["cycles"] and rep["solver"] == "multigrid"
    assert rep["rms_error_after"] < rep["rms_error_before"]
    tight = app.recipes.run("Multigrid smoothing", blob, {"solver": "multigrid"},
                            {**opts, "rtol": 1e-8}).state.fields["smoothed"]
    assert not np.array_equal(got, tight)  # --rtol reaches the recipe
    # positions (a mesh), direct solver
    out = tmp_path / "p.obj"
    assert main(["smooth", str(BLOB), "-o", str(out), "--energy", "bilaplacian", "--alpha",
                 "1e-5", "--solver", "direct"]) == 0
    ref = app.recipes.run("Multigrid smoothing", blob,
                          {"energy": "bilaplacian", "alpha": 1e-5, "solver": "direct"},
                          {"signal": "positions"})
    _same_mesh_file(out, ref.state, tmp_path)
    # a field file: stored as a blob, the file is not needed by the run
    f = tmp_path / "values.txt"
    np.savetxt(f, np.sin(blob.V[:, 0] * 7.0))
    out = tmp_path / "f.txt"
    assert main(["smooth", str(BLOB), "-o", str(out), "--signal", str(f), "--json"]) == 0
    assert _json(capsys.readouterr().out)["signal"] == str(f)
    opts = {"signal": "loaded", "field": app.recipes.put_blob_file(f)}
    f.unlink()
    ref = app.recipes.run("Multigrid smoothing", blob, {}, opts)
    want = tmp_path / "want.txt"
    from algorithms.mesh.fields import write_field

    write_field(want, ref.state.fields["smoothed"])
    assert out.read_bytes() == want.read_bytes()


def test_smooth_data_on_a_project_uses_its_saved_options(tmp_path, capsys):
    blob = _state(BLOB)
    panels = {rm.SMOOTH: {"params": {"energy": "dirichlet", "alpha": 2e-3, "solver": "direct"},
                          "options": {"signal": "noise", "noise": 0.3, "noise_seed": 7,
                                      "flow_step_size": 1e-3, "flow_steps": 5}}}
    path = save_project(tmp_path / "m.s3d", Project(state=blob, panels=panels))
    # no --signal, a field file: the project's signal, noise level, seed and settings
    out = tmp_path / "n.npy"
    assert main(["smooth", str(path), "-o", str(out), "--solver", "direct", "--json"]) == 0
    rep = _json(capsys.readouterr().out)
    assert rep["signal"] == "noise" and rep["params"]["alpha"] == 2e-3
    ref = app.recipes.run("Multigrid smoothing", read_project(path))
    assert np.load(out).tobytes() == ref.state.fields["smoothed"].tobytes()
    seed0 = app.recipes.run("Multigrid smoothing", blob, panels[rm.SMOOTH]["params"],
                            {"signal": "noise", "noise": 0.3, "noise_seed": 0})
    assert not np.array_equal(np.load(out), seed0.state.fields["smoothed"])
    # a mesh output without --signal: positions, as before
    out = tmp_path / "p.obj"
    assert main(["smooth", str(path), "-o", str(out), "--solver", "direct"]) == 0
    ref = app.recipes.run("Multigrid smoothing", blob, panels[rm.SMOOTH]["params"],
                          {"signal": "positions"})
    _same_mesh_file(out, ref.state, tmp_path)
    # the project's own noisy field is smoothed; --seed makes new noise instead
    noisy = rm.noisy_field(blob.V, blob.F, 0.5, 11)
    path2 = save_project(tmp_path / "f.s3d", Project(state=blob.with_field(rm.NOISY_FIELD, noisy),
                                                     panels=panels))
    out = tmp_path / "own.npy"
    assert main(["smooth", str(path2), "-o", str(out), "--signal", "noise"]) == 0
    ref = app.recipes.run("Multigrid smoothing", read_project(path2))
    assert np.load(out).tobytes() == ref.state.fields["smoothed"].tobytes()
    assert np.array_equal(ref.state.fields[rm.NOISY_FIELD], noisy)
    out = tmp_path / "seed.npy"
    assert main(["smooth", str(path2), "-o", str(out), "--signal", "noise", "--seed", "4"]) == 0
    ref = app.recipes.run("Multigrid smoothing", blob, panels[rm.SMOOTH]["params"],
                          {"signal": "noise", "noise": 0.3, "noise_seed": 4})
    assert np.load(out).tobytes() == ref.state.fields["smoothed"].tobytes()
    # a loaded field kept in the project
    loaded = np.cos(blob.V[:, 1] * 5.0)
    panels_l = {rm.SMOOTH: {**panels[rm.SMOOTH], "options": {"signal": "loaded"}}}
    path3 = save_project(tmp_path / "l.s3d", Project(
        state=blob.with_field(rm.LOADED_FIELD, loaded), panels=panels_l))
    out = tmp_path / "l.txt"
    assert main(["smooth", str(path3), "-o", str(out), "--alpha", "1e-2", "--json"]) == 0
    assert _json(capsys.readouterr().out)["signal"] == "loaded"
    ref = app.recipes.run("Multigrid smoothing", read_project(path3),
                          {**panels[rm.SMOOTH]["params"], "alpha": 1e-2}, {"signal": "loaded"})
    want = tmp_path / "want.txt"
    from algorithms.mesh.fields import write_field

    write_field(want, ref.state.fields["smoothed"])
    assert out.read_bytes() == want.read_bytes()


def test_smooth_data_errors_name_the_users_file(tmp_path, capsys):
    f = tmp_path / "short.txt"
    f.write_text("1\n2\n")
    out = tmp_path / "o.txt"
    assert main(["smooth", str(BLOB), "-o", str(out), "--signal", str(f)]) == 2
    err = capsys.readouterr().err
    assert "has 2 values" in err and str(f.name) in err and "stylize3d-blobs" not in err
    assert not out.exists()
    # the kind of output is checked before anything is read or computed
    exists = tmp_path / "exists.obj"
    exists.write_text("")
    assert main(["smooth", str(BLOB), "-o", str(exists), "--signal", "noise"]) == 5
    assert "one value per vertex" in capsys.readouterr().err


def test_subdivide_train_interrupted_keeps_the_best_weights_so_far(trained, tmp_path, capsys,
                                                                   monkeypatch):
    from app.recipes import subdivision as rs

    real = rs.training_steps
    seen = []

    def interrupted_after(epochs):
        def steps(*a, **kw):
            for s in real(*a, **kw):
                yield s
                if isinstance(s, rs.TrainingStep):
                    seen.append(s)
                    if s.iteration == epochs:
                        raise KeyboardInterrupt
        return steps

    monkeypatch.setattr(rs, "training_steps", interrupted_after(1))
    out = tmp_path / "stop.pt"
    assert main(["subdivide-train", str(SPOT), "-o", str(out), "--json", "--coarse-meshes", "3",
                 "--epochs", "5", *TINY_FLAGS]) == 0
    cap = capsys.readouterr()
    assert "interrupted; saving the best weights so far" in cap.err
    assert _json(cap.out)["epochs"] == 1
    assert out.read_bytes() == rs.trained_weights_bytes(seen[-1], {"trained_on": SPOT.name})

    # interrupted while making the data: nothing is written
    def no_epoch(*a, **kw):
        yield next(real(*a, **kw))
        raise KeyboardInterrupt

    monkeypatch.setattr(rs, "training_steps", no_epoch)
    out2 = tmp_path / "none.pt"
    assert main(["subdivide-train", str(SPOT), "-o", str(out2), "--quiet", "--coarse-meshes", "3",
                 *TINY_FLAGS]) == 130
    assert "nothing was written" in capsys.readouterr().err and not out2.exists()
