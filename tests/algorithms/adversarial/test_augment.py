"""Rendered data augmentation (issue 40, thesis §3.5): the random draws, the ball, the attack
from a random start, SH rotation, fine-tuning and its weights file."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from algorithms.adversarial import default_classifier, prepare_scene, resolve_label  # noqa: E402
from algorithms.adversarial.augment import (AugmentParams, NEUTRAL, augment_iter,  # noqa: E402
                                            draw_image, in_ball)
from algorithms.adversarial.shapes import subject  # noqa: E402
from algorithms.errors import ParameterError  # noqa: E402

TINY = dict(resolution=48, supersample=1, iterations=3)


@pytest.fixture(scope="module")
def clf():
    return default_classifier()


@pytest.fixture(scope="module")
def golf():
    V, F, A = subject("golf ball")
    return prepare_scene(V, F, albedo=A)


def run(scene, clf, label, idx, **kw):
    p = AugmentParams(**{**TINY, **kw})
    return [s for s in augment_iter(scene, clf, resolve_label(label, clf.class_names), p, idx)]


def test_draws_depend_only_on_seed_mesh_and_index():
    p = AugmentParams(seed=3, radius=0.3)
    a, b = draw_image(p, 1, 5), draw_image(p, 1, 5)
    assert a.view == b.view and a.background == b.background
    np.testing.assert_array_equal(a.delta, b.delta)
    assert draw_image(p, 1, 6).view != a.view and draw_image(p, 2, 5).view != a.view
    assert draw_image(AugmentParams(seed=4, radius=0.3), 1, 5).view != a.view
    assert a.delta.shape == (49, 3) and np.abs(a.delta).max() <= 0.3
    assert 0 <= a.view.elevation <= 60 and 1.3 <= a.view.width <= 1.9
    with pytest.raises(ParameterError):
        list(augment_iter(None, None, 0, AugmentParams(elevation_min=50, elevation_max=10),
                          [0]))


def test_random_lights_stay_in_the_ball_and_none_is_the_base(golf, clf):
    rnd = run(golf, clf, "golf ball", range(6), lighting="random", radius=0.2)
    non = run(golf, clf, "golf ball", range(6), lighting="none", radius=0.2)
    for r, n in zip(rnd, non):
        U = np.array(r.record["sh"])
        assert in_ball(U, NEUTRAL, 0.2) and r.record["norm"] <= 0.2
        assert r.record["norm"] > 0.15             # uniform in the ball: far from the centre
        np.testing.assert_array_equal(np.array(n.record["sh"]), NEUTRAL)
        assert r.record["view"] == n.record["view"]   # the modes share views and backgrounds
        assert r.record["background"] == n.record["background"]
        assert r.image.shape == (48, 48, 3) and 0 <= r.image.min() <= r.image.max() <= 1
        assert not np.array_equal(r.image, n.image)
    assert not in_ball(np.array(rnd[0].record["sh"]), NEUTRAL, 0.1)


def test_the_attack_lowers_the_true_class_from_its_random_start(golf, clf):
    idx = range(8)
    rnd = run(golf, clf, "golf ball", idx, lighting="random", radius=0.2)
    adv = run(golf, clf, "golf ball", idx, lighting="adversarial", radius=0.2)
    lower = 0
    for r, a in zip(rnd, adv):
        np.testing.assert_array_equal(np.array(a.record["sh_start"]), np.array(r.record["sh"]))
        assert a.record["true_probability_before"] == pytest.approx(
            r.record["true_probability_after"], abs=1e-6)      # the start is the random light
        assert in_ball(np.array(a.record["sh"]), NEUTRAL, 0.2)
        if a.record["iterations"] > 0:
            lower += a.record["true_probability_after"] < a.record["true_probability_before"]
        else:  # stopped at once: the start was already fooled, and says so
            assert a.record["fooled"] and "no attack step" in a.record["note"]
    attacked = sum(a.record["iterations"] > 0 for a in adv)
    assert attacked >= 3 and lower >= attacked - 1, [a.record for a in adv]
    mean_r = np.mean([r.record["true_probability_after"] for r in rnd])
    mean_a = np.mean([a.record["true_probability_after"] for a in adv])
    assert mean_a < 0.8 * mean_r, (mean_a, mean_r)
    for a in adv:
        if a.record["iterations"] == TINY["iterations"] and not a.record["fooled"]:
            assert "not fooled within" in a.record["note"]


def test_rotate_lighting_is_exact_and_invertible():
    from scipy.spatial.transform import Rotation

    from algorithms.render.sh import environment, rotate_lighting, sh_basis

    U = environment("Eucalyptus Grove")
    R = Rotation.from_euler("xyz", [20, 70, -35], degrees=True).as_matrix()
    U2 = rotate_lighting(U, R)
    w = np.random.default_rng(0).normal(size=(50, 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    # the light from w now comes from R w
    np.testing.assert_allclose(sh_basis(w @ R.T) @ U2, sh_basis(w) @ U, atol=1e-12)
    np.testing.assert_allclose(rotate_lighting(U2, R.T), U, atol=1e-12)
    assert np.abs(U2[9:]).max() < 1e-12 and np.abs(U2 - U).max() > 0.05
    with pytest.raises(ParameterError):
        rotate_lighting(U, 2 * np.eye(3))


def test_finetuning_learns_the_training_images_and_round_trips(clf, tmp_path):
    from algorithms.adversarial import classify, load_classifier
    from algorithms.adversarial.finetune import FinetuneParams, finetune_iter, save_finetuned

    images, labels = [], []
    names = ["golf ball", "orange"]
    for c, name in enumerate(names):
        V, F, A = subject(name)
        sc = prepare_scene(V, F, albedo=A)
        for s in run(sc, clf, name, range(8), lighting="random"):
            images.append(s.image)
            labels.append(c)
    images, labels = np.stack(images), np.array(labels)
    idx = [resolve_label(n, clf.class_names) for n in names]
    steps = list(finetune_iter(clf, images, labels, idx, FinetuneParams(epochs=8)))
    first, last = steps[0], steps[-1]
    # epoch 0 is the ImageNet classifier restricted to the two classes
    p = classify(clf, images)[:, idx]
    assert first.metrics["accuracy"] == pytest.approx(float((p.argmax(1) == labels).mean()))
    assert last.metrics["loss"] < 0.7 * first.metrics["loss"]
    assert last.metrics["accuracy"] > first.metrics["accuracy"]
    assert last.metrics["accuracy"] >= 0.9
    out = tmp_path / "w.pt"
    save_finetuned(out, last, idx)
    loaded = load_classifier(out)
    assert [n.split(",")[0] for n in loaded.class_names] == names
    np.testing.assert_allclose(classify(loaded, images), classify(last.classifier, images),
                               atol=1e-5)
    assert (classify(loaded, images).argmax(1) == labels).mean() == last.metrics["accuracy"]
