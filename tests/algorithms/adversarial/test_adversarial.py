"""Parametric adversaries: labels, classifier files, the cost's image gradient, the chain rule
through the SH renderer against finite differences, and small attacks on a recognized model."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
torch.set_num_threads(1)

from algorithms.adversarial import (AdversaryParams, ClassifierLoadError,  # noqa: E402
                                    TorchClassifier, attack, attack_iter, cost_image_gradients,
                                    default_classifier, evaluate, load_classifier,
                                    orbit_cameras, prepare_scene, random_perturbation,
                                    render_views, resolve_label)
from algorithms.adversarial.attack import _parameter_gradient  # noqa: E402
from algorithms.adversarial.shapes import SUBJECTS  # noqa: E402
from algorithms.errors import ParameterError  # noqa: E402
from algorithms.render import look_at  # noqa: E402

NAMES = ["tench, Tinca tinca", "coffee mug", "teapot", "cup"]


def test_labels_names_synonyms_numbers_and_suggestions():
    assert resolve_label("Coffee Mug", NAMES) == 1
    assert resolve_label("Tinca tinca", NAMES) == 0
    assert resolve_label("2", NAMES) == 2
    with pytest.raises(ParameterError, match="Did you mean: 'coffee mug'"):
        resolve_label("cofee mug", NAMES)
    with pytest.raises(ParameterError, match="classes 0 to 3"):
        resolve_label("7", NAMES)


class _Toy(torch.nn.Module):
    """A small smooth classifier: average-pooled colours -> 4 logits."""

    def __init__(self):
        super().__init__()
        g = torch.Generator().manual_seed(0)
        self.w = torch.nn.Parameter(torch.randn(4, 3 * 16, generator=g))

    def forward(self, x):
        p = torch.nn.functional.adaptive_avg_pool2d(x, 4).flatten(1)
        return p @ self.w.T


def _toy(dtype=torch.float32):
    return TorchClassifier(_Toy().to(dtype), NAMES, input_size=32)


def test_classifier_files_are_loaded_safely_with_plain_errors(tmp_path):
    text = tmp_path / "notes.pt"
    text.write_text("hello, I am not a model")
    with pytest.raises(ClassifierLoadError, match="not a model file"):
        load_classifier(text)
    # a pickle that would run code when unpickled: refused, and the code never runs
    marker = tmp_path / "ran.txt"

    class Evil:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    evil = tmp_path / "evil.pt"
    torch.save({"x": Evil()}, evil)
    with pytest.raises(ClassifierLoadError, match="refused for safety"):
        load_classifier(evil)
    assert not marker.exists()
    weights = tmp_path / "weights.pt"
    torch.save({"conv.weight": torch.zeros(2, 2)}, weights)
    with pytest.raises(ClassifierLoadError, match="torch.jit.save"):
        load_classifier(weights)
    data = tmp_path / "data.pt"
    torch.save([1, 2, 3], data)
    with pytest.raises(ClassifierLoadError, match="holds data"):
        load_classifier(data)
    # a TorchScript model loads, and its classes are named when it is not ImageNet's
    ts = tmp_path / "toy.pt"
    torch.jit.script(_Toy()).save(str(ts))
    clf = load_classifier(ts, input_size=32)
    assert clf.class_names == ("class 0", "class 1", "class 2", "class 3")
    assert tuple(clf.logits(torch.zeros(2, 3, 32, 32)).shape) == (2, 4)


def test_cost_gradient_is_eq_3_1_and_matches_finite_differences():
    clf = _toy()
    rng = np.random.default_rng(0)
    images = rng.random((2, 32, 32, 3))
    cost, g, p = cost_image_gradients(clf, images, [1, 2], [None, 3])
    x = torch.tensor(images.transpose(0, 3, 1, 2), dtype=torch.float32)
    logp = torch.log_softmax(clf.logits(x), 1).detach().double().numpy()
    assert cost == pytest.approx(logp[0, 1] + logp[1, 2] - logp[1, 3], rel=1e-5)
    D = rng.standard_normal(images.shape)
    eps = 1e-2
    fd = (cost_image_gradients(clf, images + eps * D, [1, 2], [None, 3])[0]
          - cost_image_gradients(clf, images - eps * D, [1, 2], [None, 3])[0]) / (2 * eps)
    assert fd == pytest.approx(float((g * D).sum()), rel=1e-2)


@pytest.mark.parametrize("formation", ["irradiance", "radiance"])
@pytest.mark.parametrize("mode", ["lighting", "geometry"])
def test_chain_rule_through_renderer_and_classifier_matches_finite_differences(mode, formation):
    V, F, A = SUBJECTS["orange"]()
    scene = prepare_scene(V, F, albedo=A)
    # all 49 x 3 coefficients non-zero: degrees 3-6 take part in the image and its derivatives
    scene.lighting = scene.lighting + 0.05 * np.random.default_rng(7).standard_normal((49, 3))
    cams = orbit_cameras([20.0, 200.0], resolution=64)
    clf = _toy(torch.float64)

    def cost_at(x):
        kw = {"lighting": x} if mode == "lighting" else {"V": x}
        images, renders, raw = render_views(scene, cams, supersample=2, formation=formation,
                                            **kw)
        c, gI, _ = cost_image_gradients(clf, images, [1, 1], [2, None])
        return c, gI, renders, raw

    x0 = scene.lighting if mode == "lighting" else scene.V
    c, gI, renders, raw = cost_at(x0)
    g = _parameter_gradient(scene, renders, scene.V, raw, gI, mode, 2)
    assert g.shape == x0.shape
    rng = np.random.default_rng(1)
    D = rng.standard_normal(x0.shape)
    # float64 classifier; displacements of 1e-8 (1e-6 pixel) leave visibility fixed
    eps = 1e-8 if mode == "geometry" else 1e-5
    fd = (cost_at(x0 + eps * D)[0] - cost_at(x0 - eps * D)[0]) / (2 * eps)
    assert fd == pytest.approx(float((g * D).sum()), rel=1e-4)


def test_worst_view_cost_is_the_largest_view_cost_and_matches_finite_differences():
    """aggregate="max": the cost is the largest of the views' Eq. 3.1 costs, its gradient only
    that view's (zero on the others), and it agrees with central differences."""
    clf = _toy(torch.float64)
    rng = np.random.default_rng(2)
    images = rng.random((3, 32, 32, 3))
    dec, inc = [1, 2, 0], [None, 3, None]
    x = torch.tensor(images.transpose(0, 3, 1, 2))
    logp = torch.log_softmax(clf.logits(x), 1).detach().numpy()
    per_view = [logp[0, 1], logp[1, 2] - logp[1, 3], logp[2, 0]]
    cost, g, _ = cost_image_gradients(clf, images, dec, inc, aggregate="max")
    worst = int(np.argmax(per_view))
    assert cost == pytest.approx(max(per_view), rel=1e-10)
    assert all(np.abs(g[b]).max() == 0 for b in range(3) if b != worst)
    assert np.abs(g[worst]).max() > 0
    D = rng.standard_normal(images.shape)
    eps = 1e-6
    fd = (cost_image_gradients(clf, images + eps * D, dec, inc, aggregate="max")[0]
          - cost_image_gradients(clf, images - eps * D, dec, inc, aggregate="max")[0]) / (2 * eps)
    assert fd == pytest.approx(float((g * D).sum()), rel=1e-6)
    with pytest.raises(ParameterError, match="Unknown views' cost"):
        cost_image_gradients(clf, images, dec, inc, aggregate="mean")


@pytest.mark.parametrize("mode", ["lighting", "geometry"])
def test_jittered_views_max_cost_chain_rule_matches_finite_differences(mode):
    """The options jitter and aggregate="max" together: the step's gradient (taken on views
    turned by jittered_cameras) is the derivative of the worst jittered view's cost."""
    from algorithms.adversarial.attack import jittered_cameras

    V, F, A = SUBJECTS["orange"]()
    scene = prepare_scene(V, F, albedo=A)
    scene.lighting = scene.lighting + 0.05 * np.random.default_rng(7).standard_normal((49, 3))
    base = orbit_cameras([20.0, 200.0], resolution=64)
    cams = jittered_cameras(base, 15.0, np.random.default_rng(4))
    for c, b in zip(cams, base):      # turned about the origin, still looking at it
        assert np.linalg.norm(c.position) == pytest.approx(np.linalg.norm(b.position))
        assert np.cross(c.direction, -c.position / np.linalg.norm(c.position)) == \
            pytest.approx(np.zeros(3), abs=1e-12)
        assert 0 < np.degrees(np.arccos(np.clip(c.direction @ b.direction, -1, 1))) <= 15 * 1.2
    clf = _toy(torch.float64)

    def cost_at(x):
        kw = {"lighting": x} if mode == "lighting" else {"V": x}
        images, renders, raw = render_views(scene, cams, supersample=2, formation="radiance",
                                            **kw)
        c, gI, _ = cost_image_gradients(clf, images, [1, 1], [2, None], aggregate="max")
        return c, gI, renders, raw

    x0 = scene.lighting if mode == "lighting" else scene.V
    c, gI, renders, raw = cost_at(x0)
    g = _parameter_gradient(scene, renders, scene.V, raw, gI, mode, 2)
    D = np.random.default_rng(1).standard_normal(x0.shape)
    eps = 1e-8 if mode == "geometry" else 1e-5
    fd = (cost_at(x0 + eps * D)[0] - cost_at(x0 - eps * D)[0]) / (2 * eps)
    assert fd == pytest.approx(float((g * D).sum()), rel=1e-4)


def test_radiance_formation_shades_every_degree_and_irradiance_skips_odd_ones():
    """Eq. 3.24: A_3 = A_5 = 0, so degrees 3 and 5 do not change a diffuse image; looked up as
    radiance they do. With degree-0-2 light, the radiance of A_l U_l is the irradiance of U."""
    from algorithms.adversarial.attack import RadianceSHShading, shading_for
    from algorithms.render.sh import SHShading, convolution_weights, sh_index

    V, F, A = SUBJECTS["orange"]()
    scene = prepare_scene(V, F, albedo=A)
    cams = orbit_cameras([30.0], resolution=96)
    base, _, _ = render_views(scene, cams, supersample=1)
    same, _, _ = render_views(scene, cams, supersample=1, formation="radiance",
                              lighting=convolution_weights()[:, None] * scene.lighting)
    np.testing.assert_allclose(same, base, atol=1e-12)
    for l, moves_diffuse in ((3, False), (4, True), (5, False), (6, True)):
        U = scene.lighting.copy()
        U[sh_index(l, -l):sh_index(l, l) + 1] += 0.3
        irr, _, raw_i = render_views(scene, cams, supersample=1, lighting=U)
        rad, _, raw_r = render_views(scene, cams, supersample=1, lighting=U,
                                     formation="radiance")
        assert (np.abs(raw_i - render_views(scene, cams, supersample=1)[2]).max() > 1e-3) \
            == moves_diffuse, l
        assert np.abs(rad - same).max() > 1e-2, l
    assert isinstance(shading_for(scene.lighting, "radiance"), RadianceSHShading)
    assert type(shading_for(scene.lighting)) is SHShading
    with pytest.raises(ParameterError, match="Unknown image formation"):
        shading_for(scene.lighting, "phong")


@pytest.fixture(scope="module")
def mug():
    V, F, A = SUBJECTS["coffee mug"]()
    return prepare_scene(V, F, albedo=A)


@pytest.fixture(scope="module")
def clf():
    return default_classifier()


def test_lighting_attack_streams_steps_and_stays_in_the_ball(mug, clf):
    cams = orbit_cameras([0.0, 180.0])
    params = AdversaryParams(mode="lighting", iterations=2)
    steps = list(attack_iter(mug, clf, cams, params, decrease="coffee mug"))
    assert [s.iteration for s in steps] == [0, 1, 2]
    assert steps[0].images.shape == (2, 224, 224, 3)
    assert steps[0].top5[0][0][0] == "coffee mug"          # recognized before the attack
    assert np.abs(steps[-1].lighting - mug.lighting).max() <= 0.1 + 1e-12
    assert np.abs(steps[-1].lighting - mug.lighting).max() > 0
    # the cost goes down (confidence in the true class decreases)
    assert steps[-1].metrics["confidence_decreased"] < steps[0].metrics["confidence_decreased"]
    np.testing.assert_allclose(steps[-1].V, mug.to_original(mug.V))   # geometry untouched


def test_the_attack_can_run_all_its_iterations(mug, clf):
    """until_fooled=False keeps stepping after the views are fooled (a stronger light for views
    the attack does not see); the default stops at the first fooled iterate."""
    cams = orbit_cameras([270.0])                  # a view where the mug is easily fooled
    short = attack(mug, clf, cams, AdversaryParams(iterations=6, direction="sign"))
    full = attack(mug, clf, cams, AdversaryParams(iterations=6, direction="sign",
                                                  until_fooled=False))
    assert short.views[0].success and short.iterations < 6
    assert full.iterations == 6 and full.norm <= 0.1 + 1e-12


def test_geometry_attack_and_random_baseline_keep_the_norm(mug, clf):
    cams = orbit_cameras([0.0])
    res = attack(mug, clf, cams, AdversaryParams(mode="geometry", iterations=1))
    assert res.V.shape == (len(mug.V), 3)
    assert 0 < res.norm <= 0.002 + 1e-12
    assert np.abs((res.V - mug.to_original(mug.V)) / mug.scale).max() <= 0.002 + 1e-12
    assert res.views[0].label_before == "coffee mug"
    x = random_perturbation(mug, "geometry", 0.002, seed=3)
    np.testing.assert_allclose(np.abs(x - mug.V), 0.002)
    top, p = evaluate(mug, clf, orbit_cameras([90.0]), V=x)      # an unseen view
    assert p.shape == (1, 1000) and top.shape == (1,)


def test_optical_illusion_takes_one_target_per_view(mug, clf):
    cams = orbit_cameras([0.0, 90.0])
    steps = list(attack_iter(mug, clf, cams, AdversaryParams(iterations=1),
                             increase=["cup", "bucket"]))
    assert steps[0].metrics["confidence_increased"] < steps[-1].metrics["confidence_increased"]
    with pytest.raises(ParameterError, match="one per view"):
        next(attack_iter(mug, clf, cams, AdversaryParams(iterations=1),
                         increase=["cup", "bucket", "pail"]))
    with pytest.raises(ParameterError, match="Did you mean"):
        next(attack_iter(mug, clf, cams, AdversaryParams(iterations=1), increase="coffe mug"))


def test_a_view_that_does_not_see_the_shape_is_refused(mug, clf):
    away = look_at((0, 0, 3), (0, 0, 6), width=1.5, resolution=448)
    with pytest.raises(ParameterError, match="not visible from view 1"):
        next(attack_iter(mug, clf, [away]))


@pytest.mark.parametrize("name", sorted(SUBJECTS))
def test_subjects_are_valid_coloured_meshes(name):
    V, F, A = SUBJECTS[name]()
    assert V.ndim == 2 and V.shape[1] == 3 and np.isfinite(V).all()
    assert F.dtype == np.int64 and F.shape[1] == 3 and F.min() >= 0 and F.max() < len(V)
    assert A.shape == (len(F), 3) and A.min() >= 0 and A.max() <= 1
    area = np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    assert area.min() > 0                                   # no degenerate triangles
    scene = prepare_scene(V, F, albedo=A)
    assert np.isclose(np.ptp(scene.V, axis=0).max(), 1.0)
