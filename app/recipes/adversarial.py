"""Recipes of the Adversarial lighting panel (thesis ch. 3; :mod:`algorithms.adversarial`).

Three recipes, one per job the panel starts:

* ``"Adversarial lighting"`` (command ``adversary``): the lighting attack. The document does
  not change (:func:`~app.recipes.unchanged_result`); the outcome holds the attacked lighting
  and what the classifier saw before and after (see :func:`attack_outcome`).
* ``"Adversarial lighting: geometry"`` (command ``adversary-geometry``): the geometry attack;
  the result is the moved vertices (a vertex the attack did not move keeps its coordinates bit
  for bit, see :func:`exact_moves`).
* ``"Adversarial lighting: classify"`` (command ``adversary-classify``): the panel's live
  classification of the current view (one step); outcome = the top-5.

(``run("adversary", ...)`` and the other names work with :func:`app.recipes.run`; the panel's
jobs, whose window job is always named "Adversarial lighting", say which recipe they ran in
``last_request["recipe"]``.)

``options`` (JSON-able; every key optional):

``lighting`` : list of (l+1)^2 rows of 3 floats (up to 49 x 3)
    The starting spherical-harmonics lighting, all its coefficients (the panel's sliders show
    degrees 0-2; a loaded or attacked lighting has all 49 rows). Default: ``environment``'s.
``environment`` : str
    The name of the panel's environment choice ("Grace Cathedral", ..., or "Custom"): the
    lighting when ``lighting`` is not given (default "Grace Cathedral"); shown again by
    ``restore_options``.
``true_label`` : str
    The class the attack makes less likely (a name, a synonym or a class number); "" = each
    view's top-1 before the attack.
``target`` : str
    The class the attack makes the classifier see; "" = any class but the true one.
``azimuth`` : number
    Degrees around +y of view 1 (0 = from +z); ``params.views`` views are spaced evenly from it
    (the classify recipe renders view 1 only).
``azimuths`` : list of numbers or None
    Explicit views (scripts, the CLI's recognized views); overrides ``azimuth`` and
    ``params.views``.
``classifier`` : str or None
    A blob reference (:func:`app.recipes.put_blob_file`) of a TorchScript model or
    EfficientNet-lite0 weights; None = the installed EfficientNet-lite0 (ImageNet).
``classifier_name`` : str
    What the panel shows for the classifier (not used by the run).
``color`` : [r, g, b] in [0, 1]
    The surface colour (default 0.7 grey) when ``face_colors`` is None.
``frame`` : [cx, cy, cz, size] or None
    The unit-box scaling of the shape (default: its own bounding box). The panel passes the
    box of the shape before its geometry attacks, so an attacked shape is classified exactly as
    the attack saw it (re-centred on its own box the picture moves by a fraction of a pixel,
    enough to change an adversarial prediction by several points).
``face_colors`` : str or None
    A blob reference of an ``.npy`` array (m, 3) of per-face colours in [0, 1] (the mesh file's
    colours, see :func:`face_colors_ref`), used instead of ``color``.
``random_baseline`` : bool
    Attacks only: also classify the views under a random perturbation of the same norm
    (``params.seed``, thesis Fig. 3.10); the outcome gets ``random_fooled`` and
    ``random_success_rate``. The panel does not ask for it.

The radius, step, iterations, number of views, camera elevation, image size and the seed are
the Params' (:class:`algorithms.adversarial.AdversaryParams`); the recipes set ``params.mode``
themselves. No recipe is random: the same input gives the same bits.

The classifiers are loaded once per process and kept in this module (:func:`classifier_of`):
the installed one on first use, a file's when the panel loads it or when a run names its blob.
"""

from __future__ import annotations

import dataclasses
import io
import threading
from collections import OrderedDict
from dataclasses import dataclass
from typing import Iterator

import numpy as np

from algorithms.adversarial.attack import AttackStep
from algorithms.steps import Step
from app.recipes import Recipe, blob_bytes, blob_path, put_blob, register, unchanged_result

__all__ = ["LIGHTING", "GEOMETRY", "CLASSIFY", "PreviewStep", "AttackStep", "classifier_of",
           "load_classifier_file", "remember_classifier", "class_names_of", "resolve_label",
           "top_k", "environment_lighting", "full_lighting", "face_colors_ref", "albedo_of",
           "face_colors_of", "read_face_colors", "azimuths_of", "exact_moves", "frame_of",
           "lighting_steps", "geometry_steps", "classify_steps", "attack_outcome",
           "classify_outcome"]

LIGHTING = "Adversarial lighting"
GEOMETRY = "Adversarial lighting: geometry"
CLASSIFY = "Adversarial lighting: classify"
DEFAULT_ENVIRONMENT = "Grace Cathedral"
DEFAULT_COLOR = (0.7, 0.7, 0.7)


# ------------------------------------------------------------------------------ classifiers
_CLF_LOCK = threading.Lock()
#: blob reference -> loaded classifier (the installed one is cached by its own module)
_CLASSIFIERS: "OrderedDict[str, object]" = OrderedDict()
_MAX_FILE_CLASSIFIERS = 4


def classifier_of(ref: str | None = None):
    """The classifier of ``options["classifier"]``: None = the installed EfficientNet-lite0,
    else a blob reference of a model file (loaded once, then kept in this module)."""
    if not ref:
        from algorithms.adversarial.classifiers import default_classifier

        with _CLF_LOCK:
            return default_classifier()
    with _CLF_LOCK:
        clf = _CLASSIFIERS.get(ref)
        if clf is not None:
            _CLASSIFIERS.move_to_end(ref)
            return clf
        from algorithms.adversarial.classifiers import load_classifier

        clf = load_classifier(blob_path(ref))
        _remember(ref, clf)
        return clf


def _remember(ref: str, clf) -> None:
    _CLASSIFIERS[ref] = clf
    _CLASSIFIERS.move_to_end(ref)
    while len(_CLASSIFIERS) > _MAX_FILE_CLASSIFIERS:
        _CLASSIFIERS.popitem(last=False)


def remember_classifier(ref: str, clf) -> None:
    """Keep an already loaded classifier under its blob reference (see :func:`classifier_of`)."""
    with _CLF_LOCK:
        _remember(ref, clf)


def load_classifier_file(path):
    """``(classifier, blob reference)`` of a user's model file: loaded (refused with a plain
    message when it is not a model, see :func:`algorithms.adversarial.load_classifier`), its
    bytes stored as a blob for the runs' options, and the classifier kept for them."""
    from algorithms.adversarial.classifiers import load_classifier

    from app.recipes import put_blob_file

    clf = load_classifier(path)
    ref = put_blob_file(path)
    remember_classifier(ref, clf)
    return clf, ref


def class_names_of(classifier=None) -> tuple:
    """The class names of a loaded classifier, or the installed one's (ImageNet) for None
    (without loading the network)."""
    if classifier is not None:
        return tuple(classifier.class_names)
    from algorithms.adversarial.classifiers import imagenet_class_names

    return imagenet_class_names()


def resolve_label(text, class_names) -> int:
    """The class index a person typed (a name, a synonym or a number); an unknown one raises
    ParameterError naming close names."""
    from algorithms.adversarial.labels import resolve_label as _resolve

    return _resolve(text, class_names)


def top_k(probs: np.ndarray, names, k: int = 5) -> list[tuple[str, float, int]]:
    """``[(short name, probability, class index), ...]`` of the ``k`` most likely classes."""
    from algorithms.adversarial.labels import short_name

    idx = np.argsort(-np.asarray(probs))[:k]
    return [(short_name(names[i]), float(probs[i]), int(i)) for i in idx]


class _Recording:
    """A classifier that keeps the logits of its first and last calls (the attack's
    probabilities before and after, without classifying again); everything else is the
    wrapped classifier's."""

    def __init__(self, inner):
        self._inner = inner
        self.first = None
        self.last = None

    def __getattr__(self, name):
        return getattr(self._inner, name)

    def logits(self, images):
        out = self._inner.logits(images)
        rec = out.detach()
        if self.first is None:
            self.first = rec
        self.last = rec
        return out


# ------------------------------------------------------------------------------ inputs
def environment_lighting(name: str) -> np.ndarray:
    """The (49, 3) lighting of a published environment (``ENVIRONMENTS``)."""
    from algorithms.render.sh import environment

    return environment(name)


def full_lighting(U) -> np.ndarray:
    """``(l+1)^2 x 3`` coefficients padded with zeros to (49, 3) float64."""
    from algorithms.errors import ParameterError

    U = np.asarray(U, dtype=np.float64)
    if U.ndim != 2 or U.shape[1] != 3 or not 1 <= U.shape[0] <= 49 \
            or round(np.sqrt(U.shape[0])) ** 2 != U.shape[0] or not np.isfinite(U).all():
        raise ParameterError(f"The lighting must be (l+1)^2 x 3 finite spherical-harmonics "
                             f"coefficients (up to 49 x 3); got shape {U.shape}.")
    full = np.zeros((49, 3))
    full[:len(U)] = U
    return full


def _lighting_of(options: dict) -> np.ndarray:
    U = options.get("lighting")
    if U is not None:
        return full_lighting(U)
    name = options.get("environment") or DEFAULT_ENVIRONMENT
    from algorithms.render.sh import ENVIRONMENTS

    if name not in ENVIRONMENTS:
        from algorithms.errors import ParameterError

        raise ParameterError(f"Unknown lighting environment {name!r}: use one of "
                             f"{', '.join(ENVIRONMENTS)}, or give the coefficients.")
    return environment_lighting(name)


def face_colors_ref(colors: np.ndarray) -> str:
    """A blob reference of per-face colours (m, 3) for ``options["face_colors"]``."""
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(colors, dtype=np.float64), allow_pickle=False)
    return put_blob(buf.getvalue(), "face_colors.npy")


def face_colors_of(ref: str) -> np.ndarray:
    """The per-face colours (m, 3) behind a :func:`face_colors_ref` reference."""
    from algorithms.errors import ParameterError

    try:
        C = np.load(io.BytesIO(blob_bytes(ref)), allow_pickle=False)
    except ValueError:
        raise ParameterError("The stored face colours of this run are not a colour table.") \
            from None
    if C.ndim != 2 or C.shape[1] != 3:
        raise ParameterError(f"The stored face colours must be (faces, 3); got {C.shape}.")
    return np.asarray(C, dtype=np.float64)


def read_face_colors(key, F):
    """Face colours ``(m, 3)`` stored in the mesh file ``key[0]`` (``key`` = (path, vertices,
    faces); vertex colours averaged over each face's corners), or None (no colours, another
    size, unreadable)."""
    from algorithms.errors import Stylize3DError
    from algorithms.render.sh import read_mesh_colors

    path, n, m = key
    try:
        got = read_mesh_colors(path, n, m)
    except Stylize3DError:
        return None
    if got is None:
        return None
    kind, C = got
    return C[np.asarray(F)].mean(axis=1) if kind == "vertex" else C


def _albedo_of(state, options: dict):
    ref = options.get("face_colors")
    if ref:
        C = face_colors_of(ref)
        if len(C) != len(state.F):
            from algorithms.errors import ParameterError

            raise ParameterError(f"The face colours of this run are for {len(C)} triangles but "
                                 f"the mesh has {len(state.F)}: open the mesh they belong to, "
                                 "or use one surface colour.")
        return C
    return np.array([float(x) for x in options.get("color", DEFAULT_COLOR)])


def albedo_of(state, options: dict):
    """The surface colours of a run's options: the per-face colours of ``face_colors`` (checked
    against the mesh) or the one ``color``."""
    return _albedo_of(state, options)


def frame_of(state) -> list[float]:
    """``[cx, cy, cz, size]``: the unit-box frame the renders of ``state`` use by default."""
    from algorithms.adversarial.attack import scene_frame

    c, size = scene_frame(state.V)
    return [float(x) for x in c] + [float(size)]


def azimuths_of(options: dict, views: int) -> list[float]:
    """The views' azimuths (degrees): ``options["azimuths"]``, else ``views`` evenly spaced
    from ``options["azimuth"]``."""
    az = options.get("azimuths")
    if az:
        return [float(a) for a in az]
    az0 = float(options.get("azimuth", 0.0))
    return [az0 + k * 360.0 / views for k in range(views)]


def scene_and_cameras(state, params, options: dict, views: int):
    from algorithms.adversarial.attack import orbit_cameras, prepare_scene

    scene = prepare_scene(np.asarray(state.V), np.asarray(state.F),
                          albedo=_albedo_of(state, options), lighting=_lighting_of(options),
                          frame=options.get("frame"))
    cams = orbit_cameras(azimuths_of(options, views), elevation=params.elevation,
                         width=params.view_width,
                         resolution=params.resolution * params.supersample)
    return scene, cams


def _label(options: dict, key: str, names):
    text = str(options.get(key) or "").strip()
    return None if not text else resolve_label(text, names)


# ------------------------------------------------------------------------------ attacks
def exact_moves(steps, V, scene):
    """The geometry attack's steps with ``V + (moved - unmoved)`` as positions: a vertex the
    attack did not move keeps its coordinates bit for bit (the unit-box round trip
    ``(V - c) / s * s + c`` alone changes the last bits of about 40 % of them)."""
    base = scene.to_original(scene.V)
    for step in steps:
        step.V = V + (step.V - base)
        yield step


def _attack_steps(state, params, options: dict, mode: str) -> Iterator[AttackStep]:
    from algorithms.adversarial.attack import attack_iter
    from algorithms.errors import ParameterError

    options = options or {}
    if params.mode != mode:
        params = dataclasses.replace(params, mode=mode)
    clf = classifier_of(options.get("classifier"))
    names = clf.class_names
    true = _label(options, "true_label", names)
    target = _label(options, "target", names)
    if true is not None and target is not None and true == target:
        raise ParameterError("The target is the true label: choose another target, or leave "
                             "it empty.")
    azimuths = azimuths_of(options, params.views)
    scene, cams = scene_and_cameras(state, params, options, len(azimuths))
    rec = _Recording(clf)
    out: dict = {}
    steps = attack_iter(scene, rec, cams, params, decrease=true, increase=target, _out=out)
    V = np.asarray(state.V)
    if mode == "geometry":
        steps = exact_moves(steps, V, scene)
    last = None
    for last in steps:
        if mode == "lighting":
            last.V = V           # the document does not change
        yield last
    if last is None or "result" not in out:
        return
    # the figures of the finished run, on the step the caller holds as the last one
    import torch

    res = out["result"]
    last.result = res
    last.probs_before = torch.softmax(rec.first, dim=1).double().numpy()
    last.probs_after = torch.exp(torch.log_softmax(rec.last, dim=1)).double().numpy()
    last.decrease = true
    last.increase = target
    if options.get("random_baseline"):
        _random_baseline(last, scene, clf, cams, params, true, target)


def _random_baseline(last, scene, clf, cams, params, true, target) -> None:
    """Thesis Fig. 3.10's control: a random corner of the same ball, the same views."""
    from algorithms.adversarial.attack import evaluate, random_perturbation

    x = random_perturbation(scene, params.mode, params.ball(), seed=params.seed)
    kw = {"lighting": x} if params.mode == "lighting" else {"V": x}
    top, _ = evaluate(scene, clf, cams, supersample=params.supersample,
                      resolution=params.resolution,
                      formation=getattr(params, "formation", "irradiance"), **kw)
    before = last.probs_before.argmax(1)
    last.random_fooled = np.array(
        [bool(top[b] == target) if target is not None else
         bool(top[b] != (true if true is not None else before[b])) for b in range(len(cams))])


def lighting_steps(state, params, options: dict | None = None, cache: dict | None = None
                   ) -> Iterator[AttackStep]:
    """The lighting attack (the panel's "Attack lighting"): steps carry the perturbed lighting,
    the images as classified and their top-5; ``V`` is the input's (module docstring)."""
    return _attack_steps(state, params, options or {}, "lighting")


def geometry_steps(state, params, options: dict | None = None, cache: dict | None = None
                   ) -> Iterator[AttackStep]:
    """The geometry attack (the panel's "Attack geometry"): steps carry the moved vertices."""
    return _attack_steps(state, params, options or {}, "geometry")


def attack_outcome(last) -> dict:
    """The figures of a finished attack: ``iterations``, ``norm`` (L-infinity, unit-box units
    for geometry), ``success_rate``; per view ``fooled`` (bool), ``label_before`` /
    ``label_after`` (class indices), ``confidence_before`` / ``confidence_after`` and
    ``probabilities_before`` / ``probabilities_after`` (views x classes); ``lighting`` (49, 3)
    the lighting after the attack; with ``random_baseline``, ``random_fooled`` and
    ``random_success_rate``. Empty for a run that did not finish."""
    res = getattr(last, "result", None)
    if res is None:
        return {}
    pb, pa = last.probs_before, last.probs_after
    out = {"iterations": int(res.iterations), "norm": float(res.norm),
           "success_rate": float(res.success_rate),
           "fooled": np.array([bool(v.success) for v in res.views]),
           "label_before": pb.argmax(1).astype(np.int64),
           "label_after": pa.argmax(1).astype(np.int64),
           "confidence_before": np.array([v.confidence_before for v in res.views]),
           "confidence_after": np.array([v.confidence_after for v in res.views]),
           "probabilities_before": pb, "probabilities_after": pa,
           "lighting": np.asarray(res.lighting, dtype=np.float64)}
    rf = getattr(last, "random_fooled", None)
    if rf is not None:
        out["random_fooled"] = rf
        out["random_success_rate"] = float(np.mean(rf))
    return out


# ------------------------------------------------------------------------------ classify
@dataclass
class PreviewStep(Step):
    """One classification of the current view: the image as classified and all probabilities.
    ``colors``: set by the panel when its job also read the mesh file's colours."""

    image: np.ndarray | None = None
    probs: np.ndarray | None = None
    names: tuple = ()
    covered: float = 0.0
    colors: tuple | None = None


def classify_steps(state, params, options: dict | None = None, cache: dict | None = None
                   ) -> Iterator[PreviewStep]:
    """Render view 1 (``options["azimuth"]``, or the first of ``azimuths``) as the attack does
    and classify it: one :class:`PreviewStep`."""
    from algorithms.adversarial.attack import classify, render_views

    options = options or {}
    clf = classifier_of(options.get("classifier"))
    scene, cams = scene_and_cameras(state, params, options, 1)
    images, renders, _ = render_views(scene, cams[:1], supersample=params.supersample,
                                      formation=params.formation)
    p = classify(clf, images)[0]
    yield PreviewStep(0, None, np.asarray(state.V), {}, "", image=images[0].astype(np.float32),
                      probs=p, names=tuple(clf.class_names),
                      covered=float(renders[0].mask.mean()))


def classify_outcome(last) -> dict:
    """``top5`` (class indices, most likely first), ``top5_probabilities``, ``covered`` (the
    share of the image that is the shape)."""
    p = np.asarray(last.probs)
    idx = np.argsort(-p)[:5].astype(np.int64)
    return {"top5": idx, "top5_probabilities": p[idx].astype(np.float64),
            "covered": float(last.covered)}


# ------------------------------------------------------------------------------ registry
def _params():
    from algorithms.adversarial.attack import AdversaryParams

    return AdversaryParams


LIGHTING_RECIPE = register(Recipe(LIGHTING, "adversary", _params, lighting_steps, result=unchanged_result,
                outcome=attack_outcome,
                note="the lighting attack; the document does not change"))
GEOMETRY_RECIPE = register(Recipe(GEOMETRY, "adversary-geometry", _params, geometry_steps,
                outcome=attack_outcome, note="the geometry attack; the vertices move"))
CLASSIFY_RECIPE = register(Recipe(CLASSIFY, "adversary-classify", _params, classify_steps,
                result=unchanged_result, outcome=classify_outcome,
                note="classify view 1 as the attack renders it"))

#: the three recipes by name (the panel runs these objects)
RECIPES_BY_NAME = {r.name: r for r in (LIGHTING_RECIPE, GEOMETRY_RECIPE, CLASSIFY_RECIPE)}
