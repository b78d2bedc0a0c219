"""Parametric adversaries: lighting and geometry perturbations that fool an image classifier
(thesis ch. 3, Eq. 3.1-3.5; norm balls and random baseline 604-680; protocol 1012-1030).

Image formation: the shape, scaled to a unit box (longest side 1, centred), is rendered by the
one renderer with spherical-harmonics lighting (:mod:`algorithms.render.sh`, 49 x 3 coefficients
initialized with a published environment) and per-face albedo, through orthographic cameras
at 30 degrees elevation around the vertical (+y) axis, on a black background (issue 13's
measurements: 30 degrees beats 0, black is best). Each view is rendered at ``supersample`` x the
classifier's resolution and box-filtered down (2 x by default: it helps recognition), then
clipped to [0, 1] (a choice: what the classifier sees is what a screen shows; clipped pixels
pass no gradient).

Cost (Eq. 3.1): ``C = - sum_views CE(f(I), L_d) + sum_views CE(f(I), L_i)``: ``L_d`` the class
to decrease (the one the classifier sees before the attack), ``L_i`` an optional target per view
(two views with two targets = the optical illusion of Fig. 3.6). Multi-view attacks sum the cost
over views (Eq. 3.5).

Step (Eq. 3.3, 3.4): ``x <- x - gamma dC/dx`` with ``x`` the lighting coefficients or the
vertex positions, then projected onto the L-infinity parametric norm ball around the start
(radius 0.1 per lighting coefficient, 0.002 per vertex coordinate of the unit-box shape: thesis
Fig. 3.10). ``gamma`` = 0.05 (thesis App. 3.7.6) for lighting; for geometry the same step is
scaled by the ratio of the balls (0.002 / 0.1), a choice: the thesis gives no geometry step.
``direction="sign"`` (an option) steps along the sign of the gradient instead (steepest descent
for the L-infinity norm, as in PGD). The attack stops as soon as every attacked view is fooled
(top-1 differs from ``L_d``, or equals the view's target) or after ``iterations`` (<= 30 in the
thesis) steps. (App. 3.7.6 says "stepsize 0.05 along the direction of lighting gradients",
which could also be read as a normalized gradient; we keep Eq. 3.3's ``gamma dC/dx``. Where the
lighting attack fails -- confidently recognized views, :mod:`.shapes` -- this step already takes
the light to the ball's boundary within the 30 iterations, and sign steps do no better.)

Options measured against the thesis's set-up (``benchmarks/adversarial.py --table34``,
docs/results/adversarial_lighting.md): ``until_fooled=False`` runs all the iterations (the
thesis stops once fooled, App. 3.7.6; a stronger light transfers to more unseen views), and
``formation="radiance"`` (:class:`RadianceSHShading`) looks the light up along the normal
instead of forming the irradiance of a diffuse surface: every degree then shades, where Eq. 3.24
gives degrees 3 and 5 no effect (``A_3 = A_5 = 0``) and degrees 4 and 6 only ``1/24`` and
``1/64`` of degree 0's weight. Two more options for views the attack does not see:
``aggregate="max"`` lowers, at each step, the cost of the attacked view the classifier is
still surest of (the worst case of the views) instead of Eq. 3.5's sum; ``jitter=J`` takes each
step's gradient on the attacked views turned by random angles of up to ``J`` degrees
(:func:`jittered_cameras`; the light is checked and reported on the views as given), so that the
light also fools views near them (an expectation over nearby views). The defaults stay the
thesis's (irradiance, gradient steps, sum over views, no jitter, stop once fooled).

Random baseline (Fig. 3.10): a perturbation of the same norm, ``radius * sign(N(0, 1))`` per
parameter (a corner of the ball: the largest random perturbation the ball allows), evaluated on
the same views.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Iterator, Sequence

import numpy as np

from ..errors import InvalidMeshError, ParameterError
from ..params import param, validate_params
from ..render import look_at
from ..render.camera import Camera
from ..render.sh import SHShading, environment, face_albedo, n_coefficients, sh_image_vjp, sh_render
from ..steps import Step
from .labels import resolve_label, short_name

__all__ = ["AdversaryParams", "Scene", "prepare_scene", "orbit_cameras", "render_views",
           "classify", "find_recognized_views", "attack_iter", "attack", "AttackStep",
           "AttackResult", "random_perturbation", "evaluate", "DEFAULT_RADIUS", "ViewResult",
           "cost_image_gradients", "RadianceSHShading", "FORMATIONS", "shading_for",
           "jittered_cameras"]

#: the thesis's L-infinity norm balls (Fig. 3.10)
DEFAULT_RADIUS = {"lighting": 0.1, "geometry": 0.002}


@dataclass(frozen=True)
class AdversaryParams:
    mode: str = param("lighting", label="Attack", choices=("lighting", "geometry"),
                      tooltip="What the attack may change: the spherical-harmonics lighting "
                              "(49 x 3 coefficients) or the vertex positions.")
    radius: float = param(0.0, label="Norm-ball radius", minimum=0.0, maximum=1.0, step=0.001,
                          decimals=4,
                          tooltip="Largest change of any one parameter (L-infinity ball). 0 = the "
                                  "thesis's: 0.1 per lighting coefficient, 0.002 per vertex "
                                  "coordinate of the shape scaled to a unit box.")
    step: float = param(0.05, label="Step size", minimum=1e-4, maximum=1.0, step=0.01,
                        decimals=4,
                        tooltip="Gradient step for the lighting (thesis: 0.05); geometry steps "
                                "are scaled by the ratio of the norm balls.")
    iterations: int = param(30, label="Iterations", minimum=1, maximum=1000, step=1,
                            tooltip="At most this many steps (thesis: 30); the attack stops "
                                    "earlier once every view is fooled.")
    views: int = param(1, label="Views", minimum=1, maximum=64, step=1,
                       tooltip="How many views around the shape the attack must fool at once "
                               "(their costs are summed, Eq. 3.5).")
    direction: str = param("gradient", label="Step direction", choices=("gradient", "sign"),
                           advanced=True,
                           tooltip="gradient: the thesis's gradient step (Eq. 3.3/3.4); sign: "
                                   "step along the sign of the gradient (PGD).")
    elevation: float = param(30.0, label="Camera elevation", minimum=-89.0, maximum=89.0,
                             step=5.0, advanced=True,
                             tooltip="Degrees above the horizon of the cameras.")
    resolution: int = param(224, label="Image size", minimum=32, maximum=1024, step=16,
                            advanced=True, tooltip="Pixels per side of the classifier's image.")
    supersample: int = param(2, label="Supersampling", minimum=1, maximum=4, step=1,
                             advanced=True,
                             tooltip="Render this many times larger and average down.")
    view_width: float = param(1.5, label="View width", minimum=0.5, maximum=5.0, step=0.1,
                              advanced=True,
                              tooltip="Width of the orthographic view in units of the shape's "
                                      "longest side.")
    seed: int = param(0, label="Random seed", minimum=0, maximum=2**31 - 1, step=1,
                      advanced=True,
                      tooltip="Seed of the random baseline perturbation and of the view "
                              "jitter.")
    until_fooled: bool = param(True, label="Stop once fooled", advanced=True,
                               tooltip="Stop as soon as every attacked view is fooled (thesis "
                                       "App. 3.7.6). Off: run all the iterations (a stronger "
                                       "perturbation, for views the attack does not see).")
    formation: str = param("irradiance", label="Image formation",
                           choices=("irradiance", "radiance"), advanced=True,
                           tooltip="irradiance: the thesis's diffuse surface (Eq. 3.24, the "
                                   "light convolved with the clamped cosine; degrees 3 and 5 "
                                   "do not shade). radiance: the light looked up along the "
                                   "normal, every degree shades (not the thesis's; an "
                                   "experiment).")
    aggregate: str = param("sum", label="Views' cost", choices=("sum", "max"), advanced=True,
                           tooltip="sum: the views' costs added (thesis Eq. 3.5); max: each "
                                   "step lowers the cost of the view the classifier is still "
                                   "surest of (the worst case of the views).")
    jitter: float = param(0.0, label="View jitter", minimum=0.0, maximum=45.0, step=1.0,
                          decimals=1, advanced=True,
                          tooltip="0: every step looks at the views as given (thesis). J > 0: "
                                  "each step turns every view by a random angle of up to J "
                                  "degrees around the vertical and tilts it by up to J / 2 "
                                  "degrees (Random seed), so the perturbation also fools views "
                                  "near them.")

    def ball(self) -> float:
        return float(self.radius) if self.radius > 0 else DEFAULT_RADIUS[self.mode]


@dataclass
class Scene:
    """A shape ready to be rendered for a classifier.

    Attributes
    ----------
    V : (n, 3) vertices scaled to a unit box (longest side 1) around the origin.
    F : (m, 3) faces.
    albedo : (m, 3) per-face colours.
    lighting : (49, 3) SH lighting.
    center, scale : ``V_original = V * scale + center``.
    background : grey level behind the shape.
    """

    V: np.ndarray
    F: np.ndarray
    albedo: np.ndarray
    lighting: np.ndarray
    center: np.ndarray
    scale: float
    background: float = 0.0

    def to_original(self, V) -> np.ndarray:
        return np.asarray(V) * self.scale + self.center


def prepare_scene(V, F, *, albedo=0.7, lighting="Grace Cathedral", background: float = 0.0,
                  frame=None) -> Scene:
    """Scale ``(V, F)`` to a unit box and attach albedo (number, colour, per-face or per-vertex
    colours) and lighting (an environment name or a (49, 3) array). ``frame``: ``(cx, cy, cz,
    size)`` to use instead of the box of ``V`` (the box of the shape before a geometry attack:
    the attacked shape is then seen exactly as the attack saw it, not re-centred on its own
    slightly different box)."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or len(V) < 3 or F.ndim != 2 or F.shape[1] != 3 or \
            len(F) == 0 or not np.isfinite(V).all():
        raise InvalidMeshError("The shape needs finite 3D vertices and at least one triangle.")
    if frame is None:
        center, size = scene_frame(V)
    else:
        fr = np.asarray(frame, dtype=np.float64).ravel()
        if fr.shape != (4,) or not np.isfinite(fr).all() or fr[3] <= 0:
            raise ParameterError(f"A frame is (cx, cy, cz, size) with size > 0; got {frame!r}.")
        center, size = fr[:3], float(fr[3])
    Vn = (V - center) / size
    if isinstance(lighting, str):
        U = environment(lighting)
    else:
        U = np.asarray(lighting, dtype=np.float64)
        if U.shape != (n_coefficients(6), 3):
            Uf = np.zeros((n_coefficients(6), 3))
            if U.ndim != 2 or U.shape[1] != 3 or U.shape[0] > len(Uf) or \
                    round(math.sqrt(U.shape[0])) ** 2 != U.shape[0]:
                raise ParameterError(f"The lighting must be (l+1)^2 x 3 SH coefficients (up to "
                                     f"49 x 3); got shape {U.shape}.")
            Uf[:len(U)] = U
            U = Uf
    return Scene(Vn, F, face_albedo(F, albedo, channels=3), U.copy(), center, size,
                 float(background))


def scene_frame(V) -> tuple[np.ndarray, float]:
    """``(centre, size)`` of the unit-box scaling :func:`prepare_scene` applies to ``V``: the
    centre of its bounding box and its longest side."""
    V = np.asarray(V, dtype=np.float64)
    lo, hi = V.min(0), V.max(0)
    size = float((hi - lo).max())
    if not size > 0:
        raise InvalidMeshError("The shape has no extent (all its vertices are at one point).")
    return (lo + hi) / 2, size


def orbit_cameras(azimuths_deg: Sequence[float], *, elevation: float = 30.0,
                  width: float = 1.5, resolution: int = 448) -> list[Camera]:
    """Orthographic cameras looking at the origin from ``azimuths_deg`` (around +y, 0 = from +z)
    at ``elevation`` degrees, distance 3."""
    e = math.radians(elevation)
    cams = []
    for a in azimuths_deg:
        a = math.radians(a)
        pos = 3.0 * np.array([math.cos(e) * math.sin(a), math.sin(e), math.cos(e) * math.cos(a)])
        cams.append(look_at(pos, (0, 0, 0), (0, 1, 0), width=width, resolution=resolution))
    return cams


def _downsample(img: np.ndarray, s: int) -> np.ndarray:
    if s == 1:
        return img
    H, W, C = img.shape
    return img.reshape(H // s, s, W // s, s, C).mean(axis=(1, 3))


def _upsample_grad(g: np.ndarray, s: int) -> np.ndarray:
    if s == 1:
        return g
    return np.repeat(np.repeat(g, s, axis=0), s, axis=1) / (s * s)


class RadianceSHShading(SHShading):
    """The SH lighting looked up along the face normal, ``I = rho sum_j U_j Y_j(n)``: the
    radiance arriving from the normal's direction instead of the irradiance of a diffuse
    surface (Eq. 3.24 with every ``A_l`` replaced by 1). Not the thesis's image formation (App.
    3.7.3 derives the Lambertian one, :class:`SHShading`); an option measured in
    ``benchmarks/adversarial.py --table34``: with it, degrees 3 and 5 shade and degrees 4 and 6
    shade at full weight instead of ``|A_4| / A_0 = 1/24`` and ``A_6 / A_0 = 1/64``.

    Everything else (rendering, lighting and normal derivatives, compiled kernels) is the
    renderer's: they all use the weights ``_A``."""

    def __init__(self, coefficients):
        super().__init__(coefficients)
        self._A = np.ones_like(self._A)


FORMATIONS = {"irradiance": SHShading, "radiance": RadianceSHShading}


def shading_for(lighting, formation: str = "irradiance") -> SHShading:
    """The shading of ``lighting (49, 3)`` for an image formation of :data:`FORMATIONS`."""
    try:
        return FORMATIONS[formation](lighting)
    except KeyError:
        raise ParameterError(f"Unknown image formation {formation!r}: use one of "
                             f"{', '.join(FORMATIONS)}.") from None


def render_views(scene: Scene, cameras: Sequence[Camera], *, V=None, lighting=None,
                 supersample: int = 2, check_visible: bool = True,
                 formation: str = "irradiance"):
    """Images ``(B, S, S, 3)`` in [0, 1] as the classifier sees them (``S`` = camera resolution
    / supersample), the renderings (for the derivatives) and the unclipped images."""
    V = scene.V if V is None else V
    U = scene.lighting if lighting is None else lighting
    shading = shading_for(U, formation)
    images, renders, raw = [], [], []
    for k, cam in enumerate(cameras):
        r = sh_render(V, scene.F, cam, shading, albedo=scene.albedo, background=scene.background)
        if check_visible and r.mask.mean() < 0.002:
            raise ParameterError(f"The shape is not visible from view {k + 1} (it covers "
                                 f"{int(r.mask.sum())} pixels): widen or turn the view.")
        img = _downsample(r.image, supersample)
        raw.append(img)
        images.append(np.clip(img, 0.0, 1.0))
        renders.append(r)
    return np.stack(images), renders, np.stack(raw)


def _torch():
    import torch

    return torch


def classify(classifier, images: np.ndarray) -> np.ndarray:
    """Softmax probabilities ``(B, K)`` of images ``(B, S, S, 3)`` in [0, 1]."""
    torch = _torch()
    x = torch.from_numpy(np.ascontiguousarray(images.transpose(0, 3, 1, 2), dtype=np.float32))
    with torch.no_grad():
        return torch.softmax(classifier.logits(x), dim=1).double().numpy()


def cost_image_gradients(classifier, images: np.ndarray, decrease: Sequence[int | None],
                         increase: Sequence[int | None], aggregate: str = "sum"):
    """Eq. 3.1 summed over the views (Eq. 3.5; ``aggregate="max"``: the largest of the views'
    costs, the worst case) and its gradient w.r.t. the images.

    Returns ``(cost, dC/dI (B, S, S, 3), probabilities (B, K))``."""
    if aggregate not in ("sum", "max"):
        raise ParameterError(f"Unknown views' cost {aggregate!r}: use sum or max.")
    torch = _torch()
    dtype = getattr(classifier, "dtype", torch.float32)
    x = torch.from_numpy(np.ascontiguousarray(images.transpose(0, 3, 1, 2),
                                              dtype=np.float64)).to(dtype)
    x.requires_grad_(True)
    logits = classifier.logits(x)
    logp = torch.log_softmax(logits, dim=1)
    per_view = []
    for b in range(len(images)):
        c = logits.new_zeros(())
        if decrease[b] is not None:
            c = c + logp[b, int(decrease[b])]                # -CE(f(I), L_d) = log p_d
        if increase[b] is not None:
            c = c - logp[b, int(increase[b])]                # +CE(f(I), L_i) = -log p_i
        per_view.append(c)
    per_view = torch.stack(per_view)
    cost = per_view.sum() if aggregate == "sum" else per_view.max()
    cost.backward()
    g = x.grad.numpy().transpose(0, 2, 3, 1).astype(np.float64)
    return float(cost.detach()), g, torch.exp(logp.detach()).double().numpy()


def _rotation(axis, angle: float) -> np.ndarray:
    """Rotation matrix of ``angle`` radians about the unit ``axis`` (Rodrigues)."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def jittered_cameras(cameras: Sequence[Camera], degrees: float, rng: np.random.Generator
                     ) -> list[Camera]:
    """Each camera turned about the origin (the unit-box shape's centre) by a random angle in
    ``[-degrees, degrees]`` around the vertical (+y) and tilted by one in ``[-degrees / 2,
    degrees / 2]`` around its own horizontal axis: views near the given ones, for the option
    ``jitter`` (an expectation over nearby views, as in expectation-over-transformation
    attacks)."""
    out = []
    for c in cameras:
        right = np.cross(c.direction, c.up)
        tilt = math.radians(rng.uniform(-degrees / 2, degrees / 2))
        turn = math.radians(rng.uniform(-degrees, degrees))
        R = _rotation((0.0, 1.0, 0.0), turn) @ _rotation(right, tilt)
        out.append(replace(c, position=R @ c.position, direction=R @ c.direction,
                           up=R @ c.up))
    return out


def _parameter_gradient(scene, renders, V, raw, gI, mode, supersample):
    total = None
    for b, r in enumerate(renders):
        g = gI[b] * ((raw[b] >= 0.0) & (raw[b] <= 1.0))        # clip passes no gradient
        g = _upsample_grad(g, supersample)
        gr = sh_image_vjp(V, scene.F, r, g, vertices=(mode == "geometry"),
                          lighting=(mode == "lighting"))
        part = gr.lighting if mode == "lighting" else gr.vertices
        total = part if total is None else total + part
    return total


@dataclass
class ViewResult:
    label_before: str
    confidence_before: float
    label_after: str
    confidence_after: float
    success: bool

    def to_dict(self) -> dict:
        return dict(label_before=self.label_before, confidence_before=self.confidence_before,
                    label_after=self.label_after, confidence_after=self.confidence_after,
                    success=self.success)


@dataclass
class AttackStep(Step):
    """A :class:`Step` with the attack's state: ``lighting (49, 3)``, ``images (B, S, S, 3)``
    float32 as classified, and per view the top-5 ``(name, probability)``."""

    lighting: np.ndarray | None = None
    images: np.ndarray | None = None
    top5: list = field(default_factory=list)
    fooled: list = field(default_factory=list)


@dataclass
class AttackResult:
    V: np.ndarray               # (n, 3) in the input's coordinates
    lighting: np.ndarray        # (49, 3)
    views: list                 # ViewResult per attacked view
    iterations: int
    norm: float                 # L-infinity norm of the perturbation (unit-box units)
    images_before: np.ndarray
    images_after: np.ndarray

    @property
    def success_rate(self) -> float:
        return float(np.mean([v.success for v in self.views])) if self.views else 0.0


def _cost_of(probs, decrease, increase, aggregate="sum") -> float:
    """Eq. 3.1's cost of the views from their probabilities (as :func:`cost_image_gradients`)."""
    lp = np.log(np.maximum(probs, 1e-300))
    c = [(lp[b, decrease[b]] if decrease[b] is not None else 0.0)
         - (lp[b, increase[b]] if increase[b] is not None else 0.0) for b in range(len(probs))]
    return float(np.sum(c) if aggregate == "sum" else np.max(c))


def _top5(p, names):
    idx = np.argsort(-p)[:5]
    return [(short_name(names[i]), float(p[i])) for i in idx]


def _fooled(probs, decrease, increase):
    top = probs.argmax(1)
    out = []
    for b in range(len(probs)):
        if increase[b] is not None:
            out.append(bool(top[b] == increase[b]))
        else:
            out.append(bool(decrease[b] is not None and top[b] != decrease[b]))
    return out


def _per_view(values, n, what):
    if values is None:
        return [None] * n
    if isinstance(values, (str, int, np.integer)):
        values = [values] * n
    values = list(values)
    if len(values) == 1:
        values = values * n
    if len(values) != n:
        raise ParameterError(f"Give one {what} for all views or one per view ({n}); got "
                             f"{len(values)}.")
    return values


def attack_iter(scene: Scene, classifier, cameras: Sequence[Camera],
                params: AdversaryParams = AdversaryParams(), *, decrease=None, increase=None,
                center=None, _out: dict | None = None) -> Iterator[AttackStep]:
    """Run a lighting or geometry attack on the views ``cameras`` (rendered at
    ``params.resolution * params.supersample``), yielding an :class:`AttackStep` per iteration
    (iteration 0 = before). ``decrease`` / ``increase`` are labels (names or indices; one for all
    views or one per view); ``decrease`` defaults to each view's top-1 before the attack.
    ``center``: the centre of the norm ball (lighting (49, 3) or unit-box vertices (n, 3));
    default the start (the scene's), as in the thesis. A start inside a ball around another
    centre is what rendered data augmentation uses (:mod:`.augment`: a random light in the ball
    around a base light, then the attack); the result's ``norm`` is then measured from it.
    The final :class:`AttackResult` is stored in ``_out["result"]`` when a dict is given."""
    validate_params(params)
    names = classifier.class_names
    cameras = [c.with_resolution(params.resolution * params.supersample) for c in cameras]
    B = len(cameras)
    if B == 0:
        raise ParameterError("An attack needs at least one view.")
    inc = [None if t is None else resolve_label(t, names) for t in _per_view(increase, B, "target")]
    mode = params.mode
    r = params.ball()
    x0 = (scene.lighting if mode == "lighting" else scene.V).copy()
    x = x0.copy()
    if center is not None:
        x0 = np.asarray(center, dtype=np.float64)
        if x0.shape != x.shape or not np.isfinite(x0).all():
            raise ParameterError(f"The norm ball's centre must be finite with the shape "
                                 f"{x.shape} of what the attack changes; got {x0.shape}.")
        if np.abs(x - x0).max() > r * (1 + 1e-9):
            raise ParameterError("The attack's start lies outside its norm ball (radius "
                                 f"{r:g}) around the given centre.")
    gamma = params.step * (1.0 if mode == "lighting" else r / DEFAULT_RADIUS["lighting"]
                           if params.radius > 0 else
                           DEFAULT_RADIUS["geometry"] / DEFAULT_RADIUS["lighting"])

    def state(x):
        return (x, scene.V) if mode == "lighting" else (scene.lighting, x)

    U, V = state(x)
    images, renders, raw = render_views(scene, cameras, V=V, lighting=U,
                                        supersample=params.supersample,
                                        formation=params.formation)
    p0 = classify(classifier, images)
    dec = [p0[b].argmax() if d is None else d for b, d in
           enumerate(_per_view(decrease, B, "label"))]
    dec = [None if d is None else resolve_label(d, names) if isinstance(d, str) else int(d)
           for d in dec]
    images_before = images.astype(np.float32)
    rng = np.random.default_rng(params.seed)
    it = 0
    while True:
        if params.jitter > 0:      # the step's gradient comes from jittered views (below)
            probs = classify(classifier, images)
            cost = _cost_of(probs, dec, inc, params.aggregate)
        else:
            cost, gI, probs = cost_image_gradients(classifier, images, dec, inc,
                                                   params.aggregate)
        fooled = _fooled(probs, dec, inc)
        conf_d = float(np.mean([probs[b, dec[b]] for b in range(B) if dec[b] is not None])) \
            if any(d is not None for d in dec) else 0.0
        conf_i = float(np.mean([probs[b, inc[b]] for b in range(B) if inc[b] is not None])) \
            if any(t is not None for t in inc) else 0.0
        U, V = state(x)
        yield AttackStep(it, params.iterations, scene.to_original(V),
                         {"cost": cost, "confidence_decreased": conf_d,
                          "confidence_increased": conf_i, "views_fooled": float(sum(fooled))},
                         f"iteration {it}: {sum(fooled)}/{B} views fooled",
                         lighting=U.copy(), images=images.astype(np.float32),
                         top5=[_top5(probs[b], names) for b in range(B)], fooled=fooled)
        if (params.until_fooled and all(fooled)) or it >= params.iterations:
            break
        if params.jitter > 0:
            jc = jittered_cameras(cameras, params.jitter, rng)
            _, jrenders, jraw = render_views(scene, jc, V=V, lighting=U,
                                             supersample=params.supersample,
                                             check_visible=False, formation=params.formation)
            _, gI, _ = cost_image_gradients(classifier, np.clip(jraw, 0.0, 1.0), dec, inc,
                                            params.aggregate)
            g = _parameter_gradient(scene, jrenders, V, jraw, gI, mode, params.supersample)
        else:
            g = _parameter_gradient(scene, renders, V, raw, gI, mode, params.supersample)
        step = np.sign(g) if params.direction == "sign" else g
        x = np.clip(x - gamma * step, x0 - r, x0 + r)
        it += 1
        U, V = state(x)
        images, renders, raw = render_views(scene, cameras, V=V, lighting=U,
                                            supersample=params.supersample, check_visible=False,
                                            formation=params.formation)
    if _out is not None:
        views = []
        for b in range(B):
            lb = int(p0[b].argmax())
            la = int(probs[b].argmax())
            views.append(ViewResult(short_name(names[lb]), float(p0[b, lb]),
                                    short_name(names[la]), float(probs[b, la]), fooled[b]))
        _out["result"] = AttackResult(scene.to_original(V), U.copy(), views, it,
                                      float(np.abs(x - x0).max()), images_before,
                                      images.astype(np.float32))


def attack(scene, classifier, cameras, params=AdversaryParams(), **kw) -> AttackResult:
    """Run :func:`attack_iter` to the end and return its :class:`AttackResult`."""
    out: dict = {}
    for _ in attack_iter(scene, classifier, cameras, params, _out=out, **kw):
        pass
    return out["result"]


def random_perturbation(scene: Scene, mode: str, radius: float, seed: int = 0) -> np.ndarray:
    """The random baseline: the start (lighting or unit-box vertices) plus ``radius`` times a
    random sign per parameter (L-infinity norm exactly ``radius``)."""
    rng = np.random.default_rng(seed)
    x0 = scene.lighting if mode == "lighting" else scene.V
    return x0 + radius * rng.choice([-1.0, 1.0], size=x0.shape)


def evaluate(scene: Scene, classifier, cameras, *, V=None, lighting=None, supersample: int = 2,
             resolution: int = 224, formation: str = "irradiance", batch: int = 16):
    """Top-1 class indices and probabilities ``(B,), (B, K)`` of the views (V in unit-box units),
    rendered and classified ``batch`` views at a time."""
    cams = [c.with_resolution(resolution * supersample) for c in cameras]
    ps = []
    for i in range(0, len(cams), batch):
        images, _, _ = render_views(scene, cams[i:i + batch], V=V, lighting=lighting,
                                    supersample=supersample, formation=formation)
        ps.append(classify(classifier, images))
    p = np.concatenate(ps) if ps else np.zeros((0, len(classifier.class_names)))
    return p.argmax(1), p


def find_recognized_views(scene: Scene, classifier, label, *, candidates: int = 24,
                          elevation: float = 30.0, width: float = 1.5, resolution: int = 224,
                          supersample: int = 2, top: int = 1, batch: int = 8,
                          formation: str = "irradiance"):
    """Azimuths (degrees) among ``candidates`` evenly spaced ones whose view the classifier gets
    right (``label`` among its top-``top``), best first, with the label's probability:
    ``[(azimuth, probability), ...]``."""
    k = resolve_label(label, classifier.class_names) if isinstance(label, str) else int(label)
    az = np.arange(candidates) * 360.0 / candidates
    found = []
    for i in range(0, candidates, batch):
        cams = orbit_cameras(az[i:i + batch], elevation=elevation, width=width,
                             resolution=resolution * supersample)
        images, _, _ = render_views(scene, cams, supersample=supersample, formation=formation)
        p = classify(classifier, images)
        for a, pb in zip(az[i:i + batch], p):
            if k in np.argsort(-pb)[:top]:
                found.append((float(a), float(pb[k])))
    return sorted(found, key=lambda t: -t[1])
