"""Training options of the ablation (issue 22): the author's formulation, learning-rate
schedules, scale augmentation, model selection on held-out shapes."""

import numpy as np
import pytest

from algorithms.errors import ParameterError
from algorithms.mesh import read_mesh
from algorithms.subdivision.inference import network_from_state, neural_subdivide_np
from algorithms.subdivision.model import MeshLevels, SubdivisionNet
from algorithms.subdivision.train import Trainer, TrainParams

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def samples(spot_coarse_samples):
    return spot_coarse_samples(4)


@pytest.mark.parametrize("name", ["spot_lowres.obj", "hand_lowres.obj"])
@pytest.mark.parametrize("fused", [True, False])
def test_author_formulation_matches_the_numpy_author_inference(name, fused):
    m = read_mesh("tests/data/" + name)
    V = m.V - m.V.min(0)
    V = V / V.max()  # the unit cube: the author's normalization is then the identity
    net = SubdivisionNet(seed=2, formulation="author")
    net.fused = fused
    assert net.module["V"][0].in_features == 125 and net.module["I"][0].in_features == 21
    ml = MeshLevels(m.F, len(V), 2, net.dtype)
    with torch.no_grad():
        ours = net.forward(torch.from_numpy(V).float(), ml)[-1].double().numpy()
    numpy_net = network_from_state(net.author_state(), "author")
    ref, F, _ = neural_subdivide_np(V, m.F, 2, numpy_net, adapt_scale=False)
    np.testing.assert_array_equal(F, ml.faces[-1])
    assert np.abs(ours - ref).max() < 1e-5
    # and it is not our formulation with other numbers: the differential coordinates are unused
    assert np.abs(ours - V.mean()).max() > 0.1


def test_author_formulation_is_not_saved_as_our_weights(tmp_path):
    from algorithms.subdivision.model import WeightsError, save_weights

    with pytest.raises(WeightsError, match="author"):
        save_weights(tmp_path / "w.pt", SubdivisionNet(seed=0, formulation="author"))
    assert not (tmp_path / "w.pt").exists()


def test_author_state_needs_the_author_formulation():
    with pytest.raises(ParameterError):
        SubdivisionNet(seed=0).author_state()
    with pytest.raises(ParameterError, match="formulation"):
        SubdivisionNet(seed=0, formulation="other")


def test_author_formulation_trains(samples):
    tr = Trainer(samples, TrainParams(epochs=4),
                 net=SubdivisionNet(seed=0, formulation="author"))
    first = tr.validation_loss()
    list(tr.steps())
    assert tr.best_loss < first


@pytest.mark.parametrize("schedule", ["constant", "cosine", "step"])
def test_learning_rate_schedules(samples, schedule):
    tr = Trainer(samples, TrainParams(epochs=10, learning_rate=1e-3, lr_schedule=schedule))
    lrs = [tr.learning_rate(e, 10) for e in range(1, 11)]
    assert lrs[0] == pytest.approx(1e-3)
    if schedule == "constant":
        assert lrs == [pytest.approx(1e-3)] * 10
    elif schedule == "cosine":
        assert all(a > b for a, b in zip(lrs, lrs[1:]))
        assert lrs[-1] == pytest.approx(1e-5)
    else:
        assert lrs[:7] == [pytest.approx(1e-3)] * 7 and lrs[7:] == [pytest.approx(1e-4)] * 3
    steps = list(tr.steps(3))  # the optimizer gets the epoch's step size
    assert [s.metrics["learning_rate"] for s in steps] == pytest.approx(
        [tr.learning_rate(e, 3) for e in (1, 2, 3)])
    assert tr.opt.param_groups[0]["lr"] == pytest.approx(tr.learning_rate(3, 3))


def test_scale_augmentation_changes_training_but_not_the_loss_frame(samples):
    plain = Trainer(samples, TrainParams(epochs=2, validation_fraction=0.0))
    # fresh, the network is positively homogeneous (zero biases, ReLU): a scaled mesh gives the
    # scaled result, the same loss; trained biases end that
    item = plain.train_set[0]
    with torch.no_grad():
        assert float(plain._loss(item, 2.0)) == pytest.approx(float(plain._loss(item)),
                                                              rel=1e-4)
    list(plain.steps())
    with torch.no_grad():
        l1 = float(plain._loss(item))
        l2 = float(plain._loss(item, 2.0))
    assert np.isfinite(l2) and l2 != pytest.approx(l1)  # the network is not scale invariant
    a = Trainer(samples, TrainParams(epochs=2, scale_augmentation=1.5))
    b = Trainer(samples, TrainParams(epochs=2))
    list(a.steps())
    list(b.steps())
    assert a.history[0]["loss"] != pytest.approx(b.history[0]["loss"], rel=1e-6)
    with pytest.raises(ParameterError):
        Trainer(samples, TrainParams(scale_augmentation=0.5))


def test_held_out_shapes_select_the_model(samples):
    held = samples[:1]
    tr = Trainer(samples[1:], TrainParams(epochs=3), validation_samples=held)
    assert len(tr.train_set) == 3 and len(tr.val_set) == 1
    assert torch.equal(tr.val_set[0][0], torch.from_numpy(held[0].V).float())
    steps = list(tr.steps())
    assert min(s.metrics["validation_loss"] for s in steps) == pytest.approx(tr.best_loss)
