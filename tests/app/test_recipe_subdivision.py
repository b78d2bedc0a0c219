"""Recipes "Subdivision" and "Subdivision training" run headless (no Qt)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from algorithms.errors import ParameterError, Stylize3DError
from algorithms.mesh import read_mesh
from algorithms.params import describe, params_to_dict
from app.document import MeshState
from app.recipes import (blob_bytes, blob_path, get_recipe, is_blob_ref, outcome_hash, put_blob, recipes,
                         run)
from app.recipes import subdivision as rs

torch = pytest.importorskip("torch")

SPOT = "tests/data/spot_lowres.obj"
# a tiny training: 3 coarse meshes of 60-80 vertices, a few epochs, made in this process
TINY = {"coarse_meshes": 3, "min_vertices": 60, "max_vertices": 80}
LOCAL = {"workers": 1, "cache": False}


@pytest.fixture(scope="module")
def spot():
    m = read_mesh(SPOT)
    return MeshState.make(m.V, m.F)


@pytest.fixture(scope="module")
def trained(spot):
    """One tiny training run (3 epochs) headless."""
    return run("subdivide-train", spot, {**TINY, "epochs": 3}, LOCAL)


def _same_state(a, b):
    assert a.V.dtype == b.V.dtype and a.F.dtype == b.F.dtype
    assert a.V.tobytes() == b.V.tobytes() and a.F.tobytes() == b.F.tobytes()


def test_registered_with_cli_names():
    every = recipes()
    sub, train = every["Subdivision"], every["Subdivision training"]
    assert get_recipe("subdivide") is sub and get_recipe("subdivide-train") is train
    assert sub.changes_faces and not train.changes_faces
    assert sub.deterministic and train.deterministic
    # the training form: DataParams then TrainParams, their defaults and labels
    from algorithms.subdivision.data import DataParams
    from algorithms.subdivision.train import TrainParams

    P = train.params_cls()
    assert P is rs.SubdivisionTrainingParams and P.__name__.endswith("Params")
    assert params_to_dict(P()) == {**params_to_dict(DataParams()), **params_to_dict(TrainParams())}
    assert [s.label for s in describe(P)] == ([s.label for s in describe(DataParams)]
                                              + [s.label for s in describe(TrainParams)])
    with pytest.raises(ParameterError):
        train.make_params({"epoch": 3})
    d, t = rs.split_training_params(train.make_params({"seed": 4, "epochs": 9}))
    assert (d.seed, t.epochs, d.coarse_meshes) == (4, 9, 200)


@pytest.mark.parametrize("method", ["loop", "butterfly", "midpoint"])
def test_baselines_are_the_algorithms(spot, method):
    from algorithms.subdivision.baselines import subdivide_baseline

    r = run("Subdivision", spot, {"method": method, "levels": 1}, {})
    V, F = subdivide_baseline(spot.V, spot.F, 1, method)
    assert np.array_equal(r.state.V, V) and np.array_equal(r.state.F, F)
    assert r.outcome == {"vertices": len(V), "faces": 4 * len(spot.F), "method_used": method,
                         "fallback": False, "levels_used": [method]}
    assert not r.state.fields and r.last.F.dtype == np.int64


def test_neural_shipped_with_coarsen_first_streams_progress(spot):
    from algorithms.subdivision.metrics import coarsen_to_vertices
    from algorithms.subdivision.model import neural_subdivide

    seen = []
    r = run("subdivide", spot, {"method": "neural", "levels": 1, "coarsen_first": 300},
            {"weights": "shipped"}, callback=seen.append)
    V0, F0 = coarsen_to_vertices(spot.V, spot.F, 300)
    V, F = neural_subdivide(V0, F0, 1, None)
    assert r.state.V.tobytes() == V.tobytes() and np.array_equal(r.state.F, F)
    assert all(s.total == 1000 and s.V is spot.V for s in seen[:-1])
    assert isinstance(seen[-1], rs.MeshStep) and seen[-1].message.startswith(f"{len(F):,} "
                                                                             f"triangles")
    # same inputs, same bits
    again = run("subdivide", spot, {"method": "neural", "levels": 1, "coarsen_first": 300},
                {"weights": "shipped"})
    _same_state(r.state, again.state)
    # coarsen_first at or above the vertex count does nothing
    a = run("subdivide", spot, {"method": "loop", "levels": 1, "coarsen_first": len(spot.V)}, {})
    b = run("subdivide", spot, {"method": "loop", "levels": 1}, {})
    _same_state(a.state, b.state)


def test_weights_options(spot, trained, tmp_path):
    from algorithms.subdivision.model import load_weights, neural_subdivide, save_weights

    p = {"method": "neural", "levels": 1, "dense_input": "off"}  # the network, whatever
    shipped = run("subdivide", spot, p, {}).state
    # a weights file as a blob (the trained weights here, written to a file)
    net = rs.load_network(trained.outcome["weights"])
    path = tmp_path / "mine.pt"
    save_weights(path, net, {"trained_on": "test"})
    ref = rs.weights_blob_from_file(path)
    assert is_blob_ref(ref) and ref.endswith("/mine.pt")
    path.unlink()  # the run does not need the file any more
    by_file = run("subdivide", spot, p, {"weights": "file", "weights_file": ref}).state
    V, F = neural_subdivide(spot.V, spot.F, 1, blob_path(ref), dense="off")
    assert by_file.V.tobytes() == V.tobytes() and np.array_equal(by_file.F, F)
    assert not np.array_equal(by_file.V, shipped.V)
    # the other choice's weights are not used; a choice without weights is the shipped one;
    # the panel's older combo texts are read
    for opts in ({"weights": "shipped", "weights_file": ref},
                 {"weights": "trained", "trained_weights": None, "weights_file": ref},
                 {"weights": "File…", "weights_file": None}, {"weights": "Shipped"}):
        _same_state(run("subdivide", spot, p, opts).state, shipped)
    trained_opts = {"weights": "Trained here", "trained_weights": trained.outcome["weights"]}
    _same_state(run("subdivide", spot, p, trained_opts).state, by_file)
    # plain errors: an unknown choice, a path instead of a blob, a blob that is not loaded, a
    # file that is not weights
    with pytest.raises(ParameterError, match="Unknown weights"):
        run("subdivide", spot, p, {"weights": "mine"})
    with pytest.raises(ParameterError, match="not a reference"):
        run("subdivide", spot, p, {"weights": "file", "weights_file": str(path)})
    with pytest.raises(ParameterError, match="missing"):
        run("subdivide", spot, p, {"weights": "file", "weights_file": "blob:" + "0" * 64 + "/x.pt"})
    junk = put_blob(b"not weights", "junk.pt")
    with pytest.raises(Stylize3DError, match="not a Stylize3D neural-subdivision"):
        run("subdivide", spot, p, {"weights": "file", "weights_file": junk})
    (tmp_path / "junk.pt").write_bytes(b"not weights")
    with pytest.raises(Stylize3DError, match="not a Stylize3D neural-subdivision"):
        rs.weights_blob_from_file(tmp_path / "junk.pt")
    # the baselines ignore the weights
    _same_state(run("subdivide", spot, {"method": "loop", "levels": 1},
                    {"weights": "file", "weights_file": junk}).state,
                run("subdivide", spot, {"method": "loop", "levels": 1}, {}).state)


def test_training_outcome_and_document_unchanged(spot, trained):
    out = trained.outcome
    assert trained.state is spot  # the document does not change
    assert out["epochs"] == 3 and 1 <= out["best_epoch"] <= 3
    assert out["losses"].shape == (3,) and out["validation_losses"].shape == (3,)
    assert out["best_validation_loss"] == out["validation_losses"].min()
    assert out["best_validation_loss"] == out["validation_losses"][out["best_epoch"] - 1]
    assert not out["stopped_early"]
    ref = out["weights"]
    import hashlib

    assert hashlib.sha256(blob_bytes(ref)).hexdigest() == out["weights_sha256"]
    assert ref == f"blob:{out['weights_sha256']}/{rs.TRAINED_WEIGHTS_NAME}"
    # the weights are the best epoch's, in a file of the project's format with the settings
    from algorithms.subdivision.model import load_weights

    net, info = load_weights(blob_path(ref))
    best = trained.last.best_state
    assert all(torch.equal(v, best[k]) for k, v in net.state().items())
    assert info["trained_by"] == "Subdivision training" and info["epochs"] == 3
    assert info["coarse_meshes"] == 3 and info["best_epoch"] == out["best_epoch"]
    json.dumps({k: v.tolist() if isinstance(v, np.ndarray) else v for k, v in out.items()})


def test_training_is_deterministic_and_seeded(spot, trained, tmp_path, monkeypatch):
    monkeypatch.setenv("STYLIZE3D_CACHE", str(tmp_path / "cache"))
    steps = []
    again = run("subdivide-train", spot, {**TINY, "epochs": 3}, LOCAL, callback=steps.append)
    assert outcome_hash(again.outcome) == outcome_hash(trained.outcome)
    assert again.outcome["weights"] == trained.outcome["weights"]
    assert again.outcome["losses"].tobytes() == trained.outcome["losses"].tobytes()
    # progress steps while making the data, then one step per epoch with its losses
    epochs = [s for s in steps if isinstance(s, rs.TrainingStep)]
    assert [s.iteration for s in epochs] == [1, 2, 3] and all(s.total == 3 for s in epochs)
    assert all(s.total == 1000 and s.V is spot.V for s in steps[:-3])
    assert [s.metrics["loss"] for s in epochs] == list(again.outcome["losses"])
    # through the data cache (written, then read) and in worker processes: the same bits
    cached = {"workers": 1, "cache": True}
    for opts in (cached, cached, {"workers": 2, "cache": False}):
        r = run("subdivide-train", spot, {**TINY, "epochs": 3}, opts)
        assert r.outcome["weights"] == trained.outcome["weights"]
    assert any((tmp_path / "cache").rglob("*.npz"))
    # another seed of the initial weights and shuffling, or of the collapses: other weights
    for change in ({"training_seed": 1}, {"seed": 1}):
        other = run("subdivide-train", spot, {**TINY, "epochs": 3, **change}, LOCAL)
        assert other.outcome["weights_sha256"] != trained.outcome["weights_sha256"]


def test_stopping_keeps_the_best_weights_so_far(spot):
    recipe = get_recipe("Subdivision training")
    params = recipe.make_params({**TINY, "epochs": 50})
    gen = recipe.steps(spot, params, LOCAL, {})
    last = None
    for last in gen:
        if isinstance(last, rs.TrainingStep) and last.iteration == 2:
            break
    gen.close()  # a cancelled job
    out = recipe.outcome(last)
    assert out["epochs"] == 2 and len(out["losses"]) == 2
    # the same as a whole 2-epoch run (the first epochs do not depend on the total)
    whole = run("subdivide-train", spot, {**TINY, "epochs": 2}, LOCAL)
    a = rs.load_network(out["weights"]).state()
    b = rs.load_network(whole.outcome["weights"]).state()
    assert all(torch.equal(v, b[k]) for k, v in a.items())
    assert out["losses"].tobytes() == whole.outcome["losses"].tobytes()
    # stopped while making the data: no outcome
    gen = recipe.steps(spot, params, LOCAL, {})
    first = next(gen)
    gen.close()
    assert recipe.outcome(first) == {}


def test_training_input_errors(spot):
    with pytest.raises(Stylize3DError, match="denser than the coarse meshes"):
        run("subdivide-train", spot, {"coarse_meshes": 3, "max_vertices": 900}, LOCAL)
    with pytest.raises(ParameterError):
        run("subdivide-train", spot, {**TINY, "min_vertices": 90}, LOCAL)


def test_subdividing_imports_no_torch():
    """Subdividing with a trained network (here the shipped one, and a weights file as the
    panel / CLI store it) runs without PyTorch."""
    import subprocess
    import sys

    code = (
        "import sys, numpy as np\n"
        "from algorithms.mesh import read_mesh\n"
        "from app.document import MeshState\n"
        "from app.recipes import run\n"
        "from app.recipes import subdivision as rs\n"
        "m = read_mesh('tests/data/spot_lowres.obj')\n"
        "s = MeshState.make(m.V, m.F)\n"
        "r = run('subdivide', s, {'method': 'neural', 'levels': 1}, {})\n"
        "ref = rs.weights_blob_from_file('resources/subdivision/neural_subdivision.pt')\n"
        "f = run('subdivide', s, {'method': 'neural', 'levels': 1},\n"
        "        {'weights': 'file', 'weights_file': ref})\n"
        "assert np.array_equal(r.state.V, f.state.V) and len(f.state.F) == 4 * len(m.F)\n"
        "print('torch' in sys.modules)\n")
    from tests.conftest import ROOT

    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False"]


def test_stop_after_the_first_step_does_little_work(monkeypatch):
    """The recipe's steps are the work's own pieces (no helper thread): a consumer that stops
    after the first step has made at most one chunk of half-flaps, and a whole run yields a
    step at least every CHUNK_FLAPS half-flaps, with "Level i of L" words."""
    import threading

    from algorithms.subdivision import inference

    m = read_mesh("tests/data/hand_lowres.obj")
    state = MeshState.make(m.V, m.F)
    flaps = []
    real = inference._Module.hidden

    def counting(self, geo, Zw, ijkl):
        flaps.append(len(geo))
        return real(self, geo, Zw, ijkl)

    monkeypatch.setattr(inference._Module, "hidden", counting)
    monkeypatch.setattr(inference, "CHUNK_FLAPS", 3000)
    recipe = get_recipe("Subdivision")
    params = recipe.make_params({"method": "neural", "levels": 2, "dense_input": "scale"})
    threads = threading.active_count()
    gen = recipe.steps(state, params, {}, {})
    first = next(gen)
    gen.close()
    assert first.total == 1000 and first.message.startswith("Level 1 of 2")
    assert sum(flaps) <= 3000 and threading.active_count() == threads
    # a whole run: one step per chunk (and per piece of reading each level)
    flaps.clear()
    steps = list(recipe.steps(state, params, {}, {}))
    assert isinstance(steps[-1], rs.MeshStep) and len(steps[-1].F) == 16 * len(m.F)
    progress = steps[:-1]
    assert max(flaps) <= 3000 + 40 and len(progress) >= sum(flaps) / 3040  # + one vertex's flaps
    assert all(s.total == 1000 and s.message.startswith(("Level 1 of 2", "Level 2 of 2"))
               for s in progress)
    # the classic schemes say their level too
    loop = list(recipe.steps(state, recipe.make_params({"method": "loop", "levels": 2}), {}, {}))
    assert [s.message for s in loop[:-1]] == ["Level 1 of 2: Loop subdivision",
                                             "Level 2 of 2: Loop subdivision"]


def test_the_epoch_is_chosen_on_the_bundled_pretzel_by_default(spot, monkeypatch):
    """Issue 22: chosen on the training shape's own coarse meshes, an armadillo network beat
    Loop and butterfly on 8 of 11 test meshes; chosen on coarse meshes of another shape, on
    10-11. The default training takes the validation share from the bundled pretzel and
    trains on every coarse mesh of the user's."""
    from algorithms.subdivision import data, train

    seen = {}
    real = train.Trainer

    class Spy(real):
        def __init__(self, samples, params, net=None, validation_samples=None):
            super().__init__(samples, params, net, validation_samples)
            seen[params.validation_shape] = (samples, validation_samples, self)

    monkeypatch.setattr(train, "Trainer", Spy)
    ten = {**TINY, "coarse_meshes": 10, "epochs": 1}
    run("subdivide-train", spot, ten, LOCAL)
    samples, validation, trainer = seen["pretzel"]
    assert len(samples) == 10 and len(trainer.train_set) == 10       # all of spot's train
    assert len(validation) == 1 and len(trainer.val_set) == 1          # 10 % of 10: pretzels
    dparams, _ = rs.split_training_params(get_recipe("Subdivision training").make_params(ten))
    own = data.generate_dataset([data.selection_shape()],
                                data.DataParams(**{**params_to_dict(dparams), "coarse_meshes": 1}),
                                workers=1, use_cache=False)
    np.testing.assert_array_equal(validation[0].V, own[0].V)
    assert not any(np.array_equal(validation[0].V, s.V) for s in samples)
    # the thesis's choice: a tenth of the user's own coarse meshes
    run("subdivide-train", spot, {**ten, "validation_shape": "this mesh"}, LOCAL)
    samples, validation, trainer = seen["this mesh"]
    assert validation is None and len(trainer.train_set) == 9 and len(trainer.val_set) == 1
