"""Parametric adversaries on views the attack never saw (thesis Table 3.4, ch. 3 lines 604-612).

Protocol (Table 3.4: "we randomly sample 500 correctly classified views for a given shape and
perform adversarial lighting and geometry algorithms only on a subset of views, then evaluate
the resulting adversarial lights/shapes on all the views"):

1. :func:`sample_views` draws random views -- azimuth uniform in [0, 360), elevation and the
   orthographic view width (the camera's distance, for an orthographic camera) uniform in given
   ranges -- and keeps those the classifier gets right (top-1 = the shape's class), until it has
   ``wanted`` of them or has tried ``max_candidates``.
2. :func:`transfer_trial` attacks a random subset of ``n_attacked`` of them (one adversary for
   the subset: Eq. 3.5 sums the cost over the views) and classifies the *other* views under the
   adversarial light / shape.
3. The baseline is a random perturbation of the same norm (a random corner of the L-infinity
   ball, :func:`~.attack.random_perturbation`), classified on the same unseen views
   (:func:`fooled`).

The fooled fraction of unseen views is the table's figure. ``benchmarks/adversarial.py
--table34`` runs it on every procedural subject with several draws; the CI test runs a small
case.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import ParameterError
from ..render import look_at
from ..render.camera import Camera
from .attack import AdversaryParams, Scene, attack, evaluate

__all__ = ["View", "view_camera", "sample_views", "fooled", "TransferTrial", "transfer_trial"]


@dataclass(frozen=True)
class View:
    """A camera direction: ``azimuth`` (degrees around +y, 0 = from +z), ``elevation`` (degrees
    above the horizon) and ``width`` (of the orthographic view, in units of the shape's longest
    side)."""

    azimuth: float
    elevation: float
    width: float


def view_camera(view: View, resolution: int = 448) -> Camera:
    """The orthographic camera of ``view`` looking at the origin from distance 3."""
    a, e = math.radians(view.azimuth), math.radians(view.elevation)
    pos = 3.0 * np.array([math.cos(e) * math.sin(a), math.sin(e), math.cos(e) * math.cos(a)])
    return look_at(pos, (0, 0, 0), (0, 1, 0), width=view.width, resolution=resolution)


def _cameras(views: Sequence[View]) -> list[Camera]:
    return [view_camera(v) for v in views]


def sample_views(scene: Scene, classifier, label: int, *, wanted: int = 100,
                 max_candidates: int = 300, elevation=(0.0, 60.0), width=(1.3, 1.9),
                 seed: int = 0, batch: int = 16, formation: str = "irradiance",
                 supersample: int = 2, resolution: int = 224):
    """Random views the classifier gets right (top-1 = ``label``).

    Returns ``(views, tried)``: at most ``wanted`` :class:`View` s, and how many candidates were
    classified to find them (at most ``max_candidates``)."""
    if wanted < 1 or max_candidates < 1:
        raise ParameterError("Ask for at least one view among at least one candidate.")
    rng = np.random.default_rng(seed)
    found: list[View] = []
    tried = 0
    while len(found) < wanted and tried < max_candidates:
        n = min(batch, max_candidates - tried)
        cand = [View(float(rng.uniform(0.0, 360.0)), float(rng.uniform(*elevation)),
                     float(rng.uniform(*width))) for _ in range(n)]
        top, _ = evaluate(scene, classifier, _cameras(cand), supersample=supersample,
                          resolution=resolution, formation=formation, batch=batch)
        tried += n
        found += [v for v, t in zip(cand, top) if int(t) == int(label)]
    return found[:wanted], tried


def fooled(scene: Scene, classifier, label: int, views: Sequence[View], *, lighting=None,
           V=None, formation: str = "irradiance", supersample: int = 2,
           resolution: int = 224) -> np.ndarray:
    """Per view, whether the classifier's top-1 is no longer ``label`` under the lighting /
    unit-box vertices given (the scene's own where None): a boolean array."""
    if not len(views):
        return np.zeros(0, dtype=bool)
    top, _ = evaluate(scene, classifier, _cameras(views), V=V, lighting=lighting,
                      supersample=supersample, resolution=resolution, formation=formation)
    return top != int(label)


@dataclass
class TransferTrial:
    attacked: np.ndarray         # indices (into the views) of the attacked views
    attacked_fooled: int         # how many of them the adversary fools
    iterations: int
    norm: float                  # L-infinity norm of the adversarial perturbation
    unseen_fooled: np.ndarray    # per unseen view (all views but the attacked, in order)
    perturbation: np.ndarray     # the adversarial lighting (49, 3) or unit-box vertices (n, 3)

    @property
    def unseen_rate(self) -> float:
        return float(self.unseen_fooled.mean()) if len(self.unseen_fooled) else 0.0


def transfer_trial(scene: Scene, classifier, label: int, views: Sequence[View], n_attacked: int,
                   params: AdversaryParams, rng: np.random.Generator) -> TransferTrial:
    """Attack ``n_attacked`` views drawn at random among ``views`` (one adversary for all of
    them) and evaluate the adversary on the other views."""
    if not 1 <= n_attacked < len(views):
        raise ParameterError(f"Attack between 1 and {len(views) - 1} of the {len(views)} views "
                             f"(got {n_attacked}).")
    pick = np.sort(rng.choice(len(views), n_attacked, replace=False))
    seen = [views[i] for i in pick]
    unseen = [v for i, v in enumerate(views) if i not in set(pick.tolist())]
    cams = [view_camera(v, params.resolution * params.supersample) for v in seen]
    res = attack(scene, classifier, cams, params, decrease=int(label))
    if params.mode == "lighting":
        x, kw = res.lighting, {"lighting": res.lighting}
    else:
        x = (res.V - scene.center) / scene.scale
        kw = {"V": x}
    f = fooled(scene, classifier, label, unseen, formation=params.formation,
               supersample=params.supersample, resolution=params.resolution, **kw)
    return TransferTrial(pick, sum(v.success for v in res.views), res.iterations, res.norm, f,
                         x)
