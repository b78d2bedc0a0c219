"""Rendered adversarial data augmentation (thesis §3.5, App. 3.7.6): training images of a shape
under random or adversarial spherical-harmonics lighting.

Each image ``j`` of mesh ``k`` gets its own random numbers, drawn from
``numpy.random.default_rng([seed, k, j])`` in a fixed order -- view azimuth (uniform in
[0, 360)), elevation and view width (the orthographic camera's distance; uniform in the
params' ranges), background grey (one of App. 3.7.6's five: 0, 0.25, 0.5, 0.75, 1) and a
lighting perturbation ``delta`` uniform in ``[-radius, radius]`` per coefficient (49 x 3) -- so
an image depends only on ``(seed, k, j)`` and the params, never on which other images are
made (a resumed run reproduces it bit for bit), and the three modes see the same views and
backgrounds:

* ``none``: the base lighting only (the view, distance and background still vary);
* ``random``: ``base + delta`` (App. 3.7.6: "randomly perturbing the lighting coefficients
  ranging from -0.5 to 0.5": the default radius is 0.5);
* ``adversarial``: the untargeted lighting attack (:func:`~.attack.attack_iter`, Eq. 3.1-3.3:
  gradient steps of 0.05 that lower the classifier's probability of the true class, until it
  is fooled or after ``iterations`` steps) from the random start ``base + delta``, projected
  onto the same ball around ``base`` (the random mode's ball), against the classifier given.

Choices the thesis leaves open, written down here:

* the base lighting is ``"neutral"`` by default (:data:`NEUTRAL`: white light, brighter from
  above), not one of the published light probes, so that the probes stay unseen test lighting
  (benchmarks/augmentation.py); any published environment can be the base instead;
* the thesis adds 100 adversarial images per epoch, renewed against the current model at every
  epoch (App. 3.7.6). Here a dataset is made once against the classifier given; renewing it is
  running ``augment`` again with ``--classifier`` set to the fine-tuned weights;
* views: App. 3.7.6 places its cameras at 30 degrees elevation (polar angle pi / 3) with 10
  azimuths; "random views" here are uniform azimuths, elevations in [0, 60] and view widths in
  [1.3, 1.9] x the shape (as the unseen-view protocol of :mod:`.transfer`);
* defaults sized for a CPU: 128 px images (the classifier resizes them to its 224) and at most
  10 attack iterations (the thesis: 30).

An attack that does not fool the classifier within its iterations keeps its last light (the
image is still made) and says so in its record (``fooled`` False and a ``note``); so does an
image whose start the classifier already gets wrong.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Iterator, Sequence

import numpy as np

from ..errors import ParameterError
from ..params import param, validate_params
from ..render.sh import ENVIRONMENTS, environment, n_coefficients
from ..steps import Step
from .attack import AdversaryParams, Scene, attack_iter, classify, render_views
from .labels import short_name
from .transfer import View, view_camera

__all__ = ["AugmentParams", "MODES", "BACKGROUNDS", "NEUTRAL", "base_lighting", "ImageDraw",
           "draw_image", "AugmentStep", "augment_iter", "in_ball", "check_params",
           "summarize"]

MODES = ("none", "random", "adversarial")
#: App. 3.7.6: "five gray-scale background colors with intensities 0.0, 0.25, 0.5, 0.75, 1.0"
BACKGROUNDS = (0.0, 0.25, 0.5, 0.75, 1.0)


def _neutral() -> np.ndarray:
    U = np.zeros((n_coefficients(6), 3))
    U[0] = 0.7      # ambient: irradiance 0.62 on every side
    U[1] = 0.35     # l=1, m=-1 (+y): 0.98 from above, 0.26 from below
    U.setflags(write=False)
    return U


#: the default base lighting: white, brighter from above (none of the published probes)
NEUTRAL = _neutral()


@dataclass(frozen=True)
class AugmentParams:
    lighting: str = param("adversarial", label="Lighting", choices=MODES,
                          tooltip="none: the base lighting only (views, distance and background "
                                  "vary); random: a random light in the norm ball around the "
                                  "base; adversarial: the lighting attack against the classifier "
                                  "from a random light in that ball (thesis §3.5).")
    count: int = param(10, label="Images per mesh", minimum=1, maximum=100000, step=1,
                       tooltip="How many images (lightings and views) to make of each mesh.")
    seed: int = param(0, label="Random seed", minimum=0, maximum=2**31 - 1, step=1,
                      tooltip="The same seed makes the same images (views, backgrounds, "
                              "lights).")
    radius: float = param(0.5, label="Norm-ball radius", minimum=0.0, maximum=1.0, step=0.05,
                          decimals=3,
                          tooltip="Largest change of any lighting coefficient from the base "
                                  "lighting, for random and adversarial lights (thesis App. "
                                  "3.7.6: random lights in -0.5..0.5).")
    step: float = param(0.05, label="Step size", minimum=1e-4, maximum=1.0, step=0.01,
                        decimals=4, tooltip="The attack's gradient step (thesis: 0.05).")
    iterations: int = param(10, label="Attack iterations", minimum=1, maximum=1000, step=1,
                            tooltip="At most this many attack steps per image (thesis: 30; 10 "
                                    "by default to keep it quick); it stops once fooled.")
    direction: str = param("gradient", label="Step direction", choices=("gradient", "sign"),
                           advanced=True,
                           tooltip="gradient: the thesis's step; sign: each coefficient moves "
                                   "by the whole step (PGD).")
    resolution: int = param(128, label="Image size", minimum=16, maximum=1024, step=16,
                            tooltip="Pixels per side of the images written (the classifier "
                                    "resizes them to its own input size).")
    supersample: int = param(2, label="Supersampling", minimum=1, maximum=4, step=1,
                             advanced=True,
                             tooltip="Render this many times larger and average down.")
    elevation_min: float = param(0.0, label="Lowest elevation", minimum=-89.0, maximum=89.0,
                                 step=5.0, advanced=True,
                                 tooltip="Degrees above the horizon of the lowest camera.")
    elevation_max: float = param(60.0, label="Highest elevation", minimum=-89.0, maximum=89.0,
                                 step=5.0, advanced=True,
                                 tooltip="Degrees above the horizon of the highest camera.")
    width_min: float = param(1.3, label="Narrowest view", minimum=0.5, maximum=5.0, step=0.1,
                             advanced=True,
                             tooltip="Smallest view width (camera distance) in units of the "
                                     "shape's longest side.")
    width_max: float = param(1.9, label="Widest view", minimum=0.5, maximum=5.0, step=0.1,
                             advanced=True,
                             tooltip="Largest view width (camera distance) in units of the "
                                     "shape's longest side.")
    base_lighting: str = param("neutral", label="Base lighting",
                               choices=("neutral",) + tuple(ENVIRONMENTS), advanced=True,
                               tooltip="The centre of the lights: neutral (white, from above) "
                                       "or a published light probe.")


def base_lighting(name: str) -> np.ndarray:
    """(49, 3) lighting of ``"neutral"`` (:data:`NEUTRAL`) or a published environment."""
    if str(name).strip().lower() == "neutral":
        return NEUTRAL.copy()
    return environment(name)


def check_params(params: AugmentParams) -> None:
    validate_params(params)
    if params.elevation_min > params.elevation_max or params.width_min > params.width_max:
        raise ParameterError("The lowest elevation and the narrowest view must not exceed the "
                             "highest elevation and the widest view.")


@dataclass(frozen=True)
class ImageDraw:
    """The random choices of one image (module docstring)."""

    view: View
    background: float
    delta: np.ndarray          # (49, 3) in [-radius, radius]


def draw_image(params: AugmentParams, mesh_index: int, index: int) -> ImageDraw:
    """The view, background and lighting perturbation of image ``index`` of mesh
    ``mesh_index`` (depends on nothing else but the params' seed, ranges and radius)."""
    rng = np.random.default_rng([int(params.seed), int(mesh_index), int(index)])
    view = View(float(rng.uniform(0.0, 360.0)),
                float(rng.uniform(params.elevation_min, params.elevation_max)),
                float(rng.uniform(params.width_min, params.width_max)))
    bg = float(BACKGROUNDS[int(rng.integers(len(BACKGROUNDS)))])
    delta = rng.uniform(-params.radius, params.radius, size=(n_coefficients(6), 3))
    return ImageDraw(view, bg, delta)


def in_ball(U, base, radius: float) -> bool:
    """Whether every coefficient of ``U`` is within ``radius`` of ``base`` (L-infinity)."""
    return bool(np.abs(np.asarray(U) - np.asarray(base)).max() <= radius * (1 + 1e-9) + 1e-12)


@dataclass
class AugmentStep(Step):
    """One finished image: ``image`` (S, S, 3) float32 in [0, 1] as classified, and its
    ``record`` (JSON-able: what the manifest stores, see :func:`augment_iter`)."""

    image: np.ndarray | None = None
    record: dict = field(default_factory=dict)


class _Recording:
    """The classifier, keeping the probabilities of its first and last calls (the attack's
    start and its last iterate: no second classification)."""

    def __init__(self, inner):
        self._inner = inner
        self.first = self.last = None

    def __getattr__(self, name):
        return getattr(self._inner, name)

    def logits(self, images):
        out = self._inner.logits(images)
        self.last = out.detach()
        if self.first is None:
            self.first = self.last
        return out

    def probabilities(self):
        import torch

        return tuple(torch.softmax(x, dim=1)[0].double().numpy() for x in (self.first,
                                                                           self.last))


def _top1(p: np.ndarray, names) -> dict:
    k = int(np.argmax(p))
    return {"class": k, "name": short_name(names[k]), "probability": float(p[k])}


def augment_iter(scene: Scene, classifier, label: int, params: AugmentParams,
                 indices: Sequence[int], *, mesh_index: int = 0) -> Iterator[AugmentStep]:
    """The images ``indices`` of one mesh, one :class:`AugmentStep` each (cancel = stop
    asking). ``scene``: the shape prepared by :func:`~.attack.prepare_scene` (its lighting and
    background are replaced per image); ``label``: the true class index in ``classifier``.

    Each record holds ``index``, ``mode``, ``seed``, ``mesh_index``, ``view`` (azimuth,
    elevation, width), ``background``, ``sh`` (the image's 49 x 3 lighting), ``sh_start`` (the
    attack's random start; adversarial only), ``top1_before`` / ``top1_after`` (class, name,
    probability: under the start light / the image's light), ``true_probability_before`` /
    ``true_probability_after``, ``iterations`` and ``fooled`` (the attack's; 0 and whether the
    top-1 is wrong for the other modes), ``norm`` (L-infinity distance of the light from the
    base) and ``note`` (what did not go as planned, else "")."""
    check_params(params)
    if params.lighting not in MODES:
        raise ParameterError(f"Unknown lighting mode {params.lighting!r}: use one of "
                             f"{', '.join(MODES)}.")
    names = classifier.class_names
    label = int(label)
    base = base_lighting(params.base_lighting)
    S = params.resolution * params.supersample
    attack_params = AdversaryParams(mode="lighting", radius=params.radius if params.radius > 0
                                    else 1e-12, step=params.step, iterations=params.iterations,
                                    direction=params.direction, resolution=params.resolution,
                                    supersample=params.supersample, seed=params.seed)
    indices = [int(i) for i in indices]
    for n, j in enumerate(indices):
        d = draw_image(params, mesh_index, j)
        cam = view_camera(d.view, S)
        start = base if params.lighting == "none" else base + d.delta
        sc = dataclasses.replace(scene, lighting=start, background=d.background)
        rec = {"index": j, "mode": params.lighting, "seed": int(params.seed),
               "mesh_index": int(mesh_index), "view": dataclasses.asdict(d.view),
               "background": d.background}
        note = ""
        if params.lighting == "adversarial":
            rec_clf = _Recording(classifier)
            last = None
            for last in attack_iter(sc, rec_clf, [cam], attack_params, decrease=label,
                                    center=base):
                pass
            U = np.asarray(last.lighting)
            image = last.images[0]
            p0, p1 = rec_clf.probabilities()
            fooled = bool(last.fooled[0])
            iterations = int(last.iteration)
            rec["sh_start"] = start.tolist()
            if int(np.argmax(p0)) != label:
                note = (f"the classifier already missed '{short_name(names[label])}' under the "
                        "random start light" + (": no attack step was needed (the image is "
                                                "the random light's)" if iterations == 0 else
                                                "; the attack lowered its probability further"))
            elif not fooled:
                note = (f"not fooled within {params.iterations} iterations: the image keeps the "
                        "attack's last light")
        else:
            U = start
            images, _, _ = render_views(sc, [cam], supersample=params.supersample)
            image = images[0].astype(np.float32)
            p0 = p1 = classify(classifier, images)[0]
            fooled = bool(int(np.argmax(p1)) != label)
            iterations = 0
        rec.update({"sh": np.asarray(U).tolist(), "top1_before": _top1(p0, names),
                    "top1_after": _top1(p1, names),
                    "true_probability_before": float(p0[label]),
                    "true_probability_after": float(p1[label]),
                    "iterations": iterations, "fooled": fooled,
                    "norm": float(np.abs(np.asarray(U) - base).max()), "note": note})
        top = rec["top1_after"]
        yield AugmentStep(n + 1, len(indices), scene.V, {
            "true_probability": rec["true_probability_after"], "fooled": float(fooled)},
            f"image {n + 1}/{len(indices)}: {top['name']} {100 * top['probability']:.0f}%",
            image=np.asarray(image, dtype=np.float32), record=rec)


def summarize(records) -> dict:
    """Summary figures of records: ``images``, ``fooled``, ``mean_true_probability_before`` /
    ``_after``."""
    recs = list(records)
    if not recs:
        return {"images": 0, "fooled": 0}
    return {"images": len(recs), "fooled": int(sum(bool(r["fooled"]) for r in recs)),
            "mean_true_probability_before": float(np.mean([r["true_probability_before"]
                                                           for r in recs])),
            "mean_true_probability_after": float(np.mean([r["true_probability_after"]
                                                          for r in recs]))}

