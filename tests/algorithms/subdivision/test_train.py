import numpy as np
import pytest

from algorithms.mesh import read_mesh
from algorithms.subdivision.data import DataParams, generate_dataset
from algorithms.subdivision.train import Trainer, TrainParams

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def samples(tmp_path_factory):
    m = read_mesh("tests/data/spot_lowres.obj")
    return generate_dataset([(m.V, m.F)], DataParams(coarse_meshes=3, min_vertices=60,
                                                     max_vertices=80),
                            workers=1, cache_dir=tmp_path_factory.mktemp("cache"))


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
