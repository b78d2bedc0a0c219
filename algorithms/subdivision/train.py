"""Training neural subdivision (thesis §4.4, App. 4.8.6) as a Step generator.

Loss per coarse mesh: the ℓ2 loss summed over the subdivision levels 1..L, each level's mean over
vertices of the squared distance between predicted and target positions (the authors' MSE summed
over 2 levels). Adam, learning rate 2e-3, one coarse mesh per step, the meshes shuffled every
epoch; a tenth of the coarse meshes (at least one, when there are two or more) is held out for
validation and the weights with the lowest validation loss are kept -- so stopping early
(cancelling the generator) keeps the best weights seen so far.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Iterator, Sequence

import numpy as np

from ..errors import ParameterError
from ..params import param, validate_params
from ..steps import Step
from .data import CoarseSample
from .model import MeshLevels, SubdivisionNet

__all__ = ["TrainParams", "Trainer", "train_iter"]


@dataclass(frozen=True)
class TrainParams:
    """Training (thesis §4.5, App. 4.8.6 and the authors' code; defaults are theirs)."""

    epochs: int = param(700, label="Epochs", minimum=1, maximum=100000, step=10,
                        tooltip="Passes over all coarse meshes (thesis: 700). The best "
                                "validation weights are kept, so fewer still gives a result.")
    learning_rate: float = param(2e-3, label="Learning rate", minimum=1e-6, maximum=1.0,
                                 step=1e-4, decimals=6, log_scale=True, advanced=True,
                                 tooltip="Adam step size (thesis: 0.002).")
    validation_fraction: float = param(0.1, label="Validation share", minimum=0.0, maximum=0.5,
                                       step=0.05, decimals=2, advanced=True,
                                       tooltip="Share of the coarse meshes held out to pick the "
                                               "best weights.")
    training_seed: int = param(0, label="Training seed", minimum=0, maximum=2**31 - 1, step=1,
                               advanced=True,
                               tooltip="Seed of the initial weights and the shuffling.")


class Trainer:
    """Holds the network, the optimizer and the best weights; :meth:`steps` trains.

    Parameters
    ----------
    samples : CoarseSample list (from :func:`algorithms.subdivision.data.generate_dataset`).
    params : TrainParams.
    net : an existing network to continue from (default: a fresh one).
    """

    def __init__(self, samples: Sequence[CoarseSample], params: TrainParams = TrainParams(),
                 net: SubdivisionNet | None = None):
        import torch

        validate_params(params)
        if not samples:
            raise ParameterError("Training needs at least one coarse mesh.")
        levels = {s.levels for s in samples}
        if len(levels) != 1 or min(levels) < 1:
            raise ParameterError("All coarse meshes must have the same number (>= 1) of levels.")
        self.levels = levels.pop()
        self.params = params
        self.net = net if net is not None else SubdivisionNet(seed=params.training_seed)
        rng = np.random.default_rng(params.training_seed)
        order = rng.permutation(len(samples))
        nval = int(round(params.validation_fraction * len(samples)))
        if params.validation_fraction > 0 and len(samples) >= 2:
            nval = max(1, nval)
        nval = min(nval, len(samples) - 1)
        self._rng = rng
        self.train_set = [self._prepare(samples[t]) for t in order[nval:]]
        self.val_set = [self._prepare(samples[t]) for t in order[:nval]]
        self.opt = torch.optim.Adam(self.net.module.parameters(), lr=params.learning_rate)
        self.best_loss = np.inf
        self.best_state = self.net.state()
        self.best_epoch = 0
        self.history: list[dict] = []
        self.seconds_per_epoch: list[float] = []

    def _prepare(self, s: CoarseSample):
        import torch

        dt = self.net.dtype
        return (torch.from_numpy(np.ascontiguousarray(s.V)).to(dt),
                MeshLevels(s.F, len(s.V), self.levels, dt),
                [torch.from_numpy(np.ascontiguousarray(T)).to(dt) for T in s.targets])

    def _loss(self, item):
        V0, ml, T = item
        outs = self.net.forward(V0, ml)
        loss = 0.0
        for lv in range(1, self.levels + 1):
            loss = loss + ((outs[lv] - T[lv]) ** 2).sum(dim=1).mean()
        return loss

    def validation_loss(self) -> float:
        import torch

        data = self.val_set or self.train_set
        with torch.no_grad():
            return float(np.mean([float(self._loss(it)) for it in data]))

    def steps(self, epochs: int | None = None) -> Iterator[Step]:
        """Train ``epochs`` (default ``params.epochs``) epochs, one Step per epoch.

        Step.metrics: ``loss`` (mean training loss of the epoch), ``validation_loss``,
        ``best_validation_loss``, ``seconds``. Step.V is the first validation mesh's
        prediction at the last level (for a preview). The best weights are in
        :attr:`best_state` after every step (and loaded into :attr:`net` when the generator
        finishes or is closed).
        """
        total = int(self.params.epochs if epochs is None else epochs)
        try:
            for ep in range(1, total + 1):
                t0 = time.perf_counter()
                losses = []
                for t in self._rng.permutation(len(self.train_set)):
                    self.opt.zero_grad()
                    loss = self._loss(self.train_set[t])
                    loss.backward()
                    self.opt.step()
                    losses.append(float(loss.detach()))
                val = self.validation_loss()
                if val < self.best_loss:
                    self.best_loss = val
                    self.best_state = self.net.state()
                    self.best_epoch = ep
                dt = time.perf_counter() - t0
                self.seconds_per_epoch.append(dt)
                m = {"loss": float(np.mean(losses)), "validation_loss": val,
                     "best_validation_loss": float(self.best_loss), "seconds": dt}
                self.history.append(m)
                yield Step(ep, total, self.preview(), m,
                           f"epoch {ep}/{total}: loss {m['loss']:.3g}, validation {val:.3g}")
        finally:
            self.net.load_state(self.best_state)

    def preview(self) -> np.ndarray:
        import torch

        V0, ml, _ = (self.val_set or self.train_set)[0]
        with torch.no_grad():
            return self.net.forward(V0, ml)[-1].double().numpy().copy()


def train_iter(samples: Sequence[CoarseSample], params: TrainParams = TrainParams()
               ) -> Iterator[Step]:
    """Shorthand: ``Trainer(samples, params).steps()``."""
    return Trainer(samples, params).steps()
