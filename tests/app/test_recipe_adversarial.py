"""The Adversarial lighting panel's recipes run headless (app/recipes/adversarial.py): the same
input gives the same bits, the options are the whole input (JSON, blobs for the classifier and
the face colours), the outcomes agree with the attack's own figures, bad input is refused in
plain words. Most runs use a tiny TorchScript classifier (cheap); one uses the installed one."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from algorithms.adversarial.shapes import SUBJECTS  # noqa: E402
from algorithms.errors import ParameterError  # noqa: E402
from app.document import MeshState  # noqa: E402
from app.recipes import adversarial as rcp  # noqa: E402
from app.recipes import get_recipe, outcome_hash, put_blob_file, run  # noqa: E402

# the tiny classifier is a TorchScript file (torch warns that TorchScript is deprecated)
pytestmark = pytest.mark.filterwarnings("ignore:`torch.jit:DeprecationWarning")

SMALL = {"iterations": 3, "resolution": 64, "supersample": 1}


class _Tiny(torch.nn.Module):
    def __init__(self):
        super().__init__()
        self.conv = torch.nn.Conv2d(3, 6, 7, stride=8)
        self.fc = torch.nn.Linear(6, 10)

    def forward(self, x):
        return self.fc(torch.tanh(self.conv(x)).mean((2, 3)))


@pytest.fixture(scope="module")
def tiny_ref(tmp_path_factory):
    """A blob reference of a small TorchScript classifier of 10 classes ("class 0".."class 9")."""
    torch.manual_seed(3)
    path = tmp_path_factory.mktemp("adv_recipe") / "tiny.pt"
    torch.jit.script(_Tiny()).save(str(path))
    return put_blob_file(path)


@pytest.fixture(scope="module")
def candle():
    V, F, _ = SUBJECTS["candle"]()
    return MeshState.make(V, F)


def opts(ref, **kw):
    return {"classifier": ref, "azimuth": 30, "true_label": "", "target": "", **kw}


def test_registered_under_titles_and_commands():
    assert get_recipe("adversary").name == rcp.LIGHTING == "Adversarial lighting"
    assert get_recipe("adversary-geometry").name == rcp.GEOMETRY
    assert get_recipe(rcp.CLASSIFY).command == "adversary-classify"
    for r in rcp.RECIPES_BY_NAME.values():
        assert get_recipe(r.name) is r and r.deterministic
        assert r.params_cls().__name__ == "AdversaryParams"


def test_lighting_attack_twice_same_bits_and_json_options(candle, tiny_ref):
    o = opts(tiny_ref, target="class 7", environment="St. Peter's Basilica")
    a = run("adversary", candle, SMALL, o)
    b = run("adversary", candle, SMALL, json.loads(json.dumps(o)))   # options through JSON
    assert outcome_hash(a.outcome) == outcome_hash(b.outcome)
    for k, v in a.outcome.items():
        np.testing.assert_array_equal(v, b.outcome[k])
    out = a.outcome
    # the document does not change; the steps' V are the input's own
    assert a.state is candle and a.last.V is candle.V
    # the attack's lighting within the ball around the environment's, its norm as reported
    from algorithms.render.sh import environment

    U0 = environment("St. Peter's Basilica")
    d = np.abs(out["lighting"] - U0).max()
    assert 0 < d <= 0.1 + 1e-12 and d == out["norm"]
    np.testing.assert_array_equal(out["lighting"], a.last.lighting)
    # probabilities are the attack's own: its reported confidences, bit for bit
    res = a.last.result
    pb, pa = out["probabilities_before"], out["probabilities_after"]
    assert pb.shape == pa.shape == (1, 10)
    lb, la = out["label_before"][0], out["label_after"][0]
    assert res.views[0].confidence_before == pb[0, lb] == out["confidence_before"][0]
    assert res.views[0].confidence_after == pa[0, la] == out["confidence_after"][0]
    assert res.views[0].label_before == f"class {lb}"
    assert bool(out["fooled"][0]) == (la == 7) and out["success_rate"] == float(la == 7)
    assert 1 <= out["iterations"] <= 3
    # a lighting given as coefficients is the same input as its environment's name
    c = run("adversary", candle, SMALL, {**o, "lighting": U0[:4].tolist()})
    assert outcome_hash(c.outcome) != outcome_hash(a.outcome)     # degrees 0-1 only: another
    d2 = run("adversary", candle, SMALL, {**o, "lighting": U0.tolist()})
    assert outcome_hash(d2.outcome) == outcome_hash(a.outcome)


def test_geometry_attack_twice_same_bits_unmoved_vertices_exact(candle, tiny_ref):
    o = opts(tiny_ref)
    params = {**SMALL, "iterations": 2, "views": 2}
    a = run("adversary-geometry", candle, params, o)
    b = run("adversary-geometry", candle, params, o)
    np.testing.assert_array_equal(a.state.V, b.state.V)
    assert outcome_hash(a.outcome) == outcome_hash(b.outcome)
    assert a.state.F is candle.F
    size = np.ptp(candle.V, axis=0).max()
    dV = np.abs(a.state.V - candle.V)
    assert 0 < dV.max() <= 0.002 * size * (1 + 1e-9)
    assert np.all(dV == 0, axis=1).any()          # hidden vertices keep their exact coordinates
    assert a.outcome["probabilities_before"].shape == (2, 10)
    assert a.outcome["norm"] <= 0.002 + 1e-15
    # the params' mode is the recipe's, whatever the caller passed
    c = run("adversary-geometry", candle, {**params, "mode": "lighting"}, o)
    np.testing.assert_array_equal(c.state.V, a.state.V)


def test_classify_outcome_is_the_top5_and_colours_are_inputs(candle, tiny_ref):
    params = {"resolution": 64, "supersample": 1}
    a = run("adversary-classify", candle, params, opts(tiny_ref))
    b = run("adversary-classify", candle, params, opts(tiny_ref))
    np.testing.assert_array_equal(a.last.image, b.last.image)
    np.testing.assert_array_equal(a.last.probs, b.last.probs)
    top = rcp.top_k(a.last.probs, a.last.names)
    assert list(a.outcome["top5"]) == [i for _n, _p, i in top]
    assert list(a.outcome["top5_probabilities"]) == [p for _n, p, _i in top]
    assert np.all(np.diff(a.outcome["top5_probabilities"]) <= 0)
    assert 0.002 < a.outcome["covered"] < 1
    assert a.state is candle
    # face colours equal to the one colour: the same picture; red faces: another one
    m = len(candle.F)
    grey = rcp.face_colors_ref(np.full((m, 3), 0.7))
    c = run("adversary-classify", candle, params, opts(tiny_ref, face_colors=grey))
    np.testing.assert_array_equal(c.last.image, a.last.image)
    red = np.tile([0.9, 0.1, 0.1], (m, 1))
    d = run("adversary-classify", candle, params, opts(tiny_ref, face_colors=rcp.face_colors_ref(red)))
    e = run("adversary-classify", candle, params, opts(tiny_ref, color=[0.9, 0.1, 0.1]))
    assert np.abs(d.last.image - a.last.image).max() > 0.05
    np.testing.assert_array_equal(d.last.image, e.last.image)
    # another view is another picture; "azimuths" names the views outright
    f = run("adversary-classify", candle, params, opts(tiny_ref, azimuths=[120.0]))
    g = run("adversary-classify", candle, params, opts(tiny_ref, azimuth=120))
    np.testing.assert_array_equal(f.last.image, g.last.image)
    assert np.abs(f.last.image - a.last.image).max() > 0


def test_classifier_loaded_once_and_again_from_its_blob(candle, tiny_ref, tmp_path):
    first = rcp.classifier_of(tiny_ref)
    assert rcp.classifier_of(tiny_ref) is first           # kept, not loaded per run
    assert rcp.classifier_of(None) is rcp.classifier_of(None)
    params = {"resolution": 64, "supersample": 1}
    a = run("adversary-classify", candle, params, opts(tiny_ref))
    # a replay in a fresh process: the classifier comes back from the blob's bytes
    rcp._CLASSIFIERS.clear()
    b = run("adversary-classify", candle, params, opts(tiny_ref))
    assert rcp.classifier_of(tiny_ref) is not first
    np.testing.assert_array_equal(a.last.probs, b.last.probs)
    # a model file loaded by the panel is the one the runs use
    path = tmp_path / "again.pt"
    torch.manual_seed(11)
    torch.jit.script(_Tiny()).save(str(path))
    clf, ref = rcp.load_classifier_file(path)
    assert ref.startswith("blob:") and ref.endswith("/again.pt")
    assert rcp.classifier_of(ref) is clf and clf.class_names[9] == "class 9"


def test_bad_inputs_are_refused_in_plain_words(candle, tiny_ref):
    with pytest.raises(ParameterError, match="Did you mean"):
        run("adversary", candle, SMALL, opts(tiny_ref, target="clas 7"))
    with pytest.raises(ParameterError, match="target is the true label"):
        run("adversary", candle, SMALL, opts(tiny_ref, target="class 2", true_label="2"))
    with pytest.raises(ParameterError, match="for 5 triangles but the mesh has"):
        run("adversary-classify", candle, SMALL,
            opts(tiny_ref, face_colors=rcp.face_colors_ref(np.zeros((5, 3)))))
    with pytest.raises(ParameterError, match="missing"):
        run("adversary-classify", candle, SMALL, opts("blob:" + "0" * 64 + "/gone.pt"))
    with pytest.raises(ParameterError, match="Unknown lighting environment"):
        run("adversary-classify", candle, SMALL, opts(tiny_ref, environment="Mars"))
    with pytest.raises(ParameterError, match="spherical-harmonics"):
        run("adversary-classify", candle, SMALL, opts(tiny_ref, lighting=[[1, 2, 3]] * 5))


def test_installed_classifier_mug_attack_and_random_baseline():
    """(Same bits twice with this classifier: tests/app/test_adversarial_panel.py.)"""
    V, F, _ = SUBJECTS["coffee mug"]()
    mug = MeshState.make(V, F)
    params = {"iterations": 2, "views": 2}
    o = {"azimuth": 0, "random_baseline": True}
    a = run("adversary", mug, params, o)
    names = rcp.class_names_of(None)
    assert names[a.outcome["label_before"][0]].split(",")[0] == "coffee mug"
    assert a.outcome["random_fooled"].shape == (2,) and a.outcome["random_fooled"].dtype == bool
    assert a.outcome["random_success_rate"] == np.mean(a.outcome["random_fooled"])
    assert a.outcome["probabilities_after"].shape == (2, 1000)


def test_random_baseline_is_judged_in_the_attacks_image_formation(candle, tiny_ref, monkeypatch):
    # the control light of the same norm is rendered the way the attack's images are (with
    # radiance selected it was rendered as irradiance: the baseline of another picture)
    import importlib

    attack = importlib.import_module("algorithms.adversarial.attack")  # the module, not the function
    seen = []
    real = attack.evaluate

    def spy(*a, **k):
        seen.append(k.get("formation", "irradiance"))
        return real(*a, **k)

    monkeypatch.setattr(attack, "evaluate", spy)
    for formation in ("radiance", "irradiance"):
        seen.clear()
        out = run("adversary", candle, {**SMALL, "formation": formation},
                  opts(tiny_ref, random_baseline=True)).last
        assert seen and set(seen) == {formation}
        assert out.random_fooled is not None and len(out.random_fooled) == 1
