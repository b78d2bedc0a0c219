import numpy as np
import pytest

from algorithms.subdivision.train import Trainer, TrainParams

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def samples(spot_coarse_samples):
    return spot_coarse_samples(3)


def test_training_lowers_the_loss_and_streams_steps(samples):
    tr = Trainer(samples, TrainParams(epochs=6))
    assert len(tr.val_set) == 1 and len(tr.train_set) == 2
    first = tr.validation_loss()
    steps = list(tr.steps())
    assert [s.iteration for s in steps] == list(range(1, 7))
    assert all({"loss", "validation_loss", "best_validation_loss"} <= set(s.metrics)
               for s in steps)
    assert tr.best_loss < first
    assert min(s.metrics["validation_loss"] for s in steps) == pytest.approx(tr.best_loss)
    assert steps[0].V.shape[1] == 3


def test_cancel_keeps_the_best_weights(samples):
    tr = Trainer(samples, TrainParams(epochs=50))
    gen = tr.steps()
    for _ in range(3):
        next(gen)
    gen.close()  # a cancelled job
    assert len(tr.history) == 3
    for k, v in tr.net.state().items():
        assert torch.equal(v, tr.best_state[k])
    assert tr.validation_loss() == pytest.approx(tr.best_loss, rel=1e-5)


def test_early_stopping_on_a_validation_plateau(samples):
    # a learning rate so small that no epoch improves the validation loss by 1 %
    tr = Trainer(samples, TrainParams(epochs=40, learning_rate=1e-6, patience=3,
                                      min_improvement=0.01))
    steps = list(tr.steps())
    assert len(steps) == 4 and tr.stopped_early  # epoch 1 counts as progress, then 3 without
    assert "stopping early" in steps[-1].message
    assert {"seconds_forward", "seconds_backward", "seconds_validation"} <= set(steps[0].metrics)
    assert steps[0].metrics["seconds_forward"] > 0 and steps[0].metrics["seconds_backward"] > 0
    # patience 0: all epochs run
    tr0 = Trainer(samples, TrainParams(epochs=5, learning_rate=1e-6, patience=0))
    assert len(list(tr0.steps())) == 5 and not tr0.stopped_early


def test_batched_validation_is_the_mean_of_the_meshes_losses(samples):
    tr = Trainer(samples, TrainParams(epochs=1, validation_fraction=0.0))
    with torch.no_grad():
        # the validation loss is inference's: the network averaged with its mirror image
        assert tr.net.mirror_average
        one_by_one = np.mean([float(tr._loss(it, mirror=True)) for it in tr.train_set])
        plain = np.mean([float(tr._loss(it)) for it in tr.train_set])
    assert tr.validation_loss() == pytest.approx(one_by_one, rel=1e-5)
    assert abs(plain - one_by_one) > 1e-3 * one_by_one
