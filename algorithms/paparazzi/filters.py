"""Image filters for Paparazzi and their registry (thesis 2.3.1, 2.3.3, 2.6.1, 2.7.1).

A filter is one Python function plus a frozen ``Params`` dataclass (fields made with
:func:`algorithms.params.param`, so the CLI and the GUI build their flags and forms from it):

* kind ``"energy"`` (Alg. at thesis 204-220): ``fn(image, params, ctx) -> (E, dE/dR)``, or
  ``(E, dE/dR, shown)`` with the picture the panel shows as the view's filtered version (without
  it: ``R - dE/dR``, the target of a ``1/2 |R - T|^2`` energy);
* kind ``"iterative"`` (thesis 235-248): ``fn(image, params, ctx) -> f(R)``; the optimizer uses
  ``dE/dR := -(f(R) - R)``, i.e. it moves the shape so that its image becomes ``f(R)``.

``image`` is the ``(H, W, C)`` rendering; ``ctx`` (:class:`FilterContext`) carries the camera, the
foreground mask, the filter's prepared state (``prepare(params, ctx_info)``, run once: a loaded
image, a target mesh) and a ``render_other(V, F)`` helper. Register your own::

    from dataclasses import dataclass
    from algorithms.params import param
    from algorithms.paparazzi import register_filter

    @dataclass(frozen=True)
    class Posterize:
        levels: int = param(4, label="Levels", minimum=2, maximum=64, tooltip="Colour levels.")

    @register_filter("posterize", kind="iterative", params=Posterize)
    def posterize(image, params, ctx):
        return np.round(image * (params.levels - 1)) / (params.levels - 1)

A filter that raises stops the run with its message (the optimizer wraps it in a
:class:`~algorithms.errors.Stylize3DError` naming the filter). Such a file is a *plugin*:
``stylize3d paparazzi --plugin posterize.py --filter posterize --levels 6 ...`` imports it (with
:func:`load_filter_plugin`) before the command's flags are built, so its Params become flags.

Built-in filters and their defaults (DESIGN.md §5, the authors' settings)
-------------------------------------------------------------------------
* ``guided`` -- guided filter (He et al. 2010; fast variant of He and Sun 2015 with
  ``subsample`` > 1), self-guided with the colour image as guide (3x3 covariance per window),
  radius 4, epsilon 2e-3, subsampling 1, at 128 px, learning rate 1e-5, creases kept by the
  remeshing (45 degrees). Not the authors' script's radius 15, epsilon 1e-8, subsampling 4, nor
  the thesis's Fig. 2.15 epsilon 0.02: see :func:`_guided` for why (issue 23).
* ``quantize`` -- each pixel's normal (rendered in the *world* frame, thesis 447-449) replaced by
  the nearest of the 20 icosahedron face normals.
* ``slic`` -- SLIC superpixels (scikit-image's, label for label, compiled: :mod:`.slic`; 100
  segments, compactness 10, colours compared in CIELAB as scikit-image does by default, as the
  authors' call did) on the foreground, each
  superpixel painted with its mean colour; view width 1.0 (the authors' window was 0.3 on
  meshes of 10^5 vertices and more; see :func:`_slic` for why a wider one here), learning rate
  6e-5 (the authors' SLIC script; see :func:`_slic` for why 2e-4 roughened the shapes).
* ``l0`` -- L0 gradient smoothing (Xu et al. 2011; lambda 0.01, kappa 2, beta_max 1e5, periodic
  boundary as in their MATLAB code) at 256 px; written here.
* ``target-image`` -- energy 1/2 |R - I|^2 to an image, single fixed front view.
* ``target-mesh`` -- energy 1/2 |R(V) - R(T)|^2 to the rendering of another mesh from the same
  camera (detail transfer, Fig. 2.12-2.13), summed over the pixels where *both* renderings see a
  face: with flat shading and fixed visibility nothing can move a silhouette, so pixels that only
  one of them covers would only pull normals towards the background colour. The target is placed
  with the *input's* normalization, so meshes that are aligned stay aligned.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..compiled import KernelModule
from ..errors import ParameterError, Stylize3DError
from ..params import param
from ..render import Camera, LambertianShading, Shading

__all__ = ["FilterSpec", "FilterContext", "register_filter", "unregister_filter", "get_filter",
           "filter_names", "read_image", "ImageReadError", "icosahedron_face_normals",
           "guided_filter", "guided_noise_pixels", "l0_smooth", "front_camera", "NoParams",
           "load_filter_plugin", "PluginError"]


class ImageReadError(Stylize3DError):
    """An image file could not be used."""

    exit_code = 2


class PluginError(Stylize3DError):
    """A filter plugin file could not be loaded."""

    exit_code = 2


@dataclass(frozen=True)
class NoParams:
    """A filter without parameters."""


@dataclass
class FilterContext:
    """What a filter may look at besides the image."""

    camera: Camera
    mask: np.ndarray
    state: Any = None
    render_other: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    rng: np.random.Generator | None = None
    other_mask: np.ndarray | None = None   # foreground of the last render_other() image


@dataclass(frozen=True)
class FilterSpec:
    """A registered filter.

    ``resolution`` / ``width`` / ``sigma`` / ``learning_rate`` are the filter's preferred render
    resolution, view width, camera offset and NAdam step (used when the run's parameter is left at
    0 = "the filter's default"; ``learning_rate`` may be a function of the filter's Params, read
    with :meth:`step`);
    ``single_view`` fixes the camera to :func:`front_camera`; ``shading(params)`` builds the
    shading (default: R, G, B lights along the camera axes); ``prepare(params, info)`` builds the
    state once (``info``: dict with ``normalize`` (a function mapping world points into the
    optimizer's frame), ``resolution``);
    ``file_readers`` maps a file field of ``params`` (a ``str`` path) to the function that reads
    it as ``prepare`` will (``reader(path)``, raising a :class:`~algorithms.errors.Stylize3DError`
    with a plain message for a file it cannot use): the GUI checks a chosen file with it. A file
    field without one is checked like a target image (:func:`read_image`) or a mesh;
    ``optional_files``: the file fields that may stay empty (the GUI runs without them; the
    others it asks for before a run);
    ``crease_angle`` (degrees, 0 = none): remeshing keeps the edges whose faces' normals differ
    by more than this as creases (split and collapsed only along the crease, never flipped) --
    for filters that make a shape piecewise planar (slic, l0: 45), whose creases (and a CAD
    model's) remeshing would otherwise round off, and for the edge-preserving guided filter (45:
    remeshing alone rounded fandisk's creases, crease5 0.95 -> 0.01 in 1000 iterations, and
    raised the guided run's energy); 0 for quantize, whose facets meet at ~40 deg
    everywhere: kept creases there made camelhead's remeshings cross the surface (15 of 33
    rejected, palette share 0.77 instead of 0.89); 0 for neural-style, whose relief folds
    sharply here and there (kept as creases, those folds made remeshings cross the surface; the
    input's creases alone, tried in issue 23's third pass, made the orange sample's energy rise
    with 3 rollbacks, against a fall without creases, now that remeshing moves only bad
    elements). Ignored for an input that already crosses itself (see ``Paparazzi._remesh``).

    ``rough_learning_rate`` (0 = none): the step used instead of ``learning_rate`` when the run's
    step is "auto", ``PaparazziParams.rough_step`` is on, and the input is *rough* for this
    filter: a small step along the filter's own pull, summed over the monitor views, raises the
    filter's energy (``Paparazzi.rough_probe``). An edge-preserving filter's energy has a
    barrier between a noisy scan and its smooth surface (it takes noise stronger than its
    threshold for edges, so smoothing the noise first raises the energy); a small step stays on
    the near side of it. The guided filter: 2e-4 (docs/results/paparazzi.md, "Rough scans").

    ``noise_pixels(image, mask, params)`` (None = no such test): ``(pixels, of)``, how many of
    the shape's pixels of one rendering the filter takes for noise or edges, out of how many.
    A probe that rises says "rough" only where this share, over the monitor views, is at least
    ``Paparazzi.ROUGH_SHARE`` (issue 38): a clean CAD model already at the filter's fixed point
    (flat faces, sharp creases) also rises under any step, but its pixels are flat. The guided
    filter: pixels whose window colour variance exceeds epsilon (:func:`guided_noise_pixels`).

    ``halve_on_climb`` (default True): ``PaparazziParams.plateau_step`` applies to this filter,
    whose energy then reads as the run's progress. False for neural-style: the style network
    repaints a more textured picture more strongly, so its energy is no measure of how far the
    shape is from the style (lower on the noisy fandisk than on the clean one, 299.8 against
    406.5), and halving on its climbs cut the change of the Gram loss (armadillo -8.1 % ->
    -1.0 %, 1000 iterations; docs/results/paparazzi.md).

    ``quick_look``: the panel's *quick look* preset for this filter, over its generic values
    (100 iterations at 64 px): l0 1000 iterations, slic 300 (their energies rise before they
    fall on a smooth shape, so fewer end above the start and the run fails), neural-style its own
    resolution (``{"resolution": 0}``: at 64 px its Gram energy hardly moves); measured on the
    four samples, issue 23's seventh pass (docs/results/paparazzi.md).

    ``shown_caption`` (default "Filtered"; may be a function of the Params): the panel's
    caption of the picture beside the rendered view (neural-style's Gram energy shows the
    style's texture there: "Style").

    ``panel_iterations`` (0 = the panel's own, 300): how many iterations the panel starts a run
    of this filter with. l0: 1000 -- on a smooth shape its energy rises before it falls (the
    blob sample: 29.9 -> 41 at iteration 175, back below its start from iteration 650, 20.1 at
    1000), so 300 iterations end above the start and the run fails (issue 23, sixth pass).

    ``min_change`` (an iterative filter's; default one 8-bit grey level, 1/255; 0 = never):
    when filtering the input's monitor views changes them by less than this (the root mean
    square of ``f(R) - R`` per colour channel over their foreground pixels), the shape already
    looks the way the filter makes pictures look and the run is refused before its first step
    (:class:`~algorithms.paparazzi.optimize.NothingToFilter`): the filter asks for nothing a
    person could see, and the optimizer's steps (about the learning rate each, whatever the
    pull's size) only add noise. On the corpus every guided and l0 run that started below one
    grey level raised its energy (docs/results/paparazzi.md, "Nothing to filter").

    ``step_follows_edge`` (l0, neural-style): the default step (``learning_rate``, when the
    run's is on auto)
    shrinks in proportion to the mesh's mean edge below ``optimize.ROUGH_EDGE``, as the rough
    step does: a step is about the learning rate per coordinate, so a fixed one is a larger
    share of a shorter edge, and l0 folded dense scans (docs/results/paparazzi.md, "l0's step
    on dense scans"); and at each vertex in proportion to its thinnest triangle's altitude
    below that of an equilateral triangle of that edge (:meth:`~algorithms.paparazzi.optimize.
    Paparazzi.thin_factors`): a step turns a sliver's normal by far more than a regular
    triangle's, and l0's energy rose from the first steps on sliver-laden CAD parts
    (docs/results/paparazzi.md, "l0's step on thin triangles").

    ``parallel_views`` (default False): the filter may run on several pictures at once, one per
    Python thread (it keeps no state between calls and its compiled or library code releases
    Python's lock), so :meth:`~algorithms.paparazzi.optimize.Paparazzi.monitor_energy` filters
    the monitor views side by side when the run has more than one thread. True for the
    built-in image filters; False for neural-style, whose Gram energy runs PyTorch with one
    thread set per call (a process-wide setting that two calls at once would race on).
    """

    name: str
    kind: str
    function: Callable
    params: type = NoParams
    prepare: Callable | None = None
    shading: Callable[[Any], Shading] | None = None
    resolution: int = 128
    width: float = 0.5
    sigma: float = 0.1
    single_view: bool | Callable[[Any], bool] = False
    learning_rate: float | Callable[[Any], float] = 2e-4
    description: str = ""
    file_readers: dict[str, Callable[[str], Any]] = field(default_factory=dict, compare=False,
                                                          hash=False)
    optional_files: tuple[str, ...] = ()
    crease_angle: float = 0.0
    rough_learning_rate: float = 0.0
    halve_on_climb: bool = True
    noise_pixels: Callable | None = None
    panel_iterations: int = 0
    shown_caption: str | Callable[[Any], str] = "Filtered"
    quick_look: dict = field(default_factory=dict, compare=False, hash=False)
    min_change: float = 1.0 / 255.0
    step_follows_edge: bool = False
    parallel_views: bool = False

    def make_shading(self, params) -> Shading:
        return self.shading(params) if self.shading is not None else LambertianShading()

    def shown(self, params) -> str:
        """What the panel calls the picture an energy filter shows beside the rendered view
        (``shown_caption``, or its value for these Params)."""
        c = self.shown_caption
        return str(c(params) if callable(c) else c)

    def step(self, params) -> float:
        """The filter's learning rate for ``params`` (``learning_rate``, or its value for these
        Params when it is a function of them)."""
        lr = self.learning_rate
        return float(lr(params) if callable(lr) else lr)

    def is_single_view(self, params) -> bool:
        sv = self.single_view
        return bool(sv(params) if callable(sv) else sv)


_REGISTRY: dict[str, FilterSpec] = {}
_KERNELS = KernelModule("algorithms.paparazzi.kernels")


def register_filter(name: str, *, kind: str, params: type = NoParams, **options):
    """Decorator registering ``fn`` as filter ``name`` (see the module docstring); options are
    the other :class:`FilterSpec` fields. Re-registering a name replaces it."""
    if kind not in ("energy", "iterative"):
        raise ParameterError(f"A filter's kind must be 'energy' or 'iterative' (got {kind!r}).")
    if not dataclasses.is_dataclass(params):
        raise ParameterError(f"Filter {name!r}: params must be a dataclass.")

    def deco(fn):
        _REGISTRY[name] = FilterSpec(name=name, kind=kind, function=fn, params=params, **options)
        return fn

    return deco


def unregister_filter(name: str) -> None:
    _REGISTRY.pop(name, None)


def filter_names() -> list[str]:
    return list(_REGISTRY)


def get_filter(name: str) -> FilterSpec:
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ParameterError(f"There is no image filter called {name!r}; choose one of "
                             f"{', '.join(_REGISTRY)}.") from None


def load_filter_plugin(path) -> list[str]:
    """Import the Python file ``path`` (which registers filters with :func:`register_filter`) and
    return the names it registered or replaced. A file that is missing, fails to import, or
    registers nothing raises :class:`PluginError` with a plain message, and the registry is left
    as it was."""
    import hashlib
    import importlib.util
    import sys
    from pathlib import Path

    p = Path(str(path))
    if not p.is_file():
        raise PluginError(f"The filter plugin {path} does not exist (give a .py file).")
    if p.suffix != ".py":
        raise PluginError(f"The filter plugin {path} is not a Python file (.py).")
    before = dict(_REGISTRY)
    tag = hashlib.sha1(str(p.resolve()).encode()).hexdigest()[:10]
    name = f"stylize3d_filter_plugin_{tag}"
    try:
        spec = importlib.util.spec_from_file_location(name, p)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module          # dataclasses look their module up while importing
        spec.loader.exec_module(module)
    except (Exception, SystemExit) as e:  # noqa: BLE001 - any failure is the same plain message
        sys.modules.pop(name, None)
        _REGISTRY.clear()
        _REGISTRY.update(before)
        where = ""
        tb = e.__traceback__
        while tb is not None:
            if tb.tb_frame.f_code.co_filename == str(p):
                where = f" (line {tb.tb_lineno})"
            tb = tb.tb_next
        if isinstance(e, SyntaxError) and e.lineno:
            where = f" (line {e.lineno})"
        raise PluginError(f"The filter plugin {path} could not be loaded{where}: "
                          f"{type(e).__name__}: {e}") from None
    changed = [n for n, f in _REGISTRY.items() if before.get(n) is not f]
    if not changed:
        raise PluginError(f"The filter plugin {path} registered no image filter; it must "
                          "decorate a function with @register_filter(...) (see the "
                          "algorithms.paparazzi.filters documentation).")
    return changed


def front_camera(resolution: int, shading_width: float = 2.4) -> Camera:
    """The fixed single view: orthographic, from +z looking at the origin, the whole [-1, 1]^3."""
    return Camera((0.0, 0.0, 3.0), (0.0, 0.0, -1.0), (0.0, 1.0, 0.0), width=shading_width,
                  resolution=resolution)


# ----------------------------------------------------------------------------- images
def read_image(path: str, resolution: int | None = None, channels: int = 3) -> np.ndarray:
    """Read an image as ``(H, W, channels)`` float64 in [0, 1]; grey images are repeated to
    colour, colour ones averaged to grey when ``channels == 1``, alpha is dropped. A square image
    of another size is resized to ``resolution``; a non-square one is refused."""
    from pathlib import Path

    p = Path(str(path))
    if not str(path):
        raise ImageReadError("No image was given; choose an image file (PNG or JPEG).")
    if not p.exists():
        raise ImageReadError(f"The image {path} does not exist.")
    if p.is_dir():
        raise ImageReadError(f"{path} is a folder, not an image file.")
    try:
        from PIL import Image

        with Image.open(p) as im:
            im.load()
            arr = np.asarray(im.convert("RGBA" if im.mode in ("RGBA", "LA", "P") else
                                        ("L" if im.mode in ("L", "I", "I;16", "F", "1") else "RGB")))
    except Exception as e:  # noqa: BLE001 - any decoder failure is the same plain message
        raise ImageReadError(f"The image {path} cannot be read ({type(e).__name__}); "
                             "use a PNG or JPEG file.") from None
    img = arr.astype(np.float64)
    img /= 255.0 if arr.dtype == np.uint8 else max(1.0, float(img.max()))
    if img.ndim == 2:
        img = img[..., None]
    if img.shape[2] in (2, 4):
        img = img[..., :-1]
    if img.shape[0] != img.shape[1]:
        raise ImageReadError(f"The image {path} is {img.shape[1]} x {img.shape[0]} pixels; "
                             "Paparazzi renders square images, so crop it to a square first.")
    if channels == 3 and img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    elif channels == 1 and img.shape[2] == 3:
        img = img.mean(axis=2, keepdims=True)
    if resolution is not None and img.shape[0] != resolution:
        from skimage.transform import resize

        img = resize(img, (resolution, resolution, img.shape[2]), order=1, anti_aliasing=True)
    return np.ascontiguousarray(img)


# ----------------------------------------------------------------------------- guided filter
def _box(x: np.ndarray, r: int) -> np.ndarray:
    """Mean over the (2r+1)^2 window clipped to the image (He et al.'s boxfilter / N), of every
    channel of ``x (H, W, ...)`` at once (one summed-area table)."""
    H, W = x.shape[:2]
    S = np.zeros((H + 1, W + 1) + x.shape[2:])
    np.cumsum(x, axis=0, out=S[1:, 1:])
    np.cumsum(S[1:, 1:], axis=1, out=S[1:, 1:])
    y1 = np.minimum(np.arange(H) + r + 1, H)
    y0 = np.maximum(np.arange(H) - r, 0)
    x1 = np.minimum(np.arange(W) + r + 1, W)
    x0 = np.maximum(np.arange(W) - r, 0)
    out = S[y1][:, x1] - S[y0][:, x1] - S[y1][:, x0] + S[y0][:, x0]
    N = np.multiply.outer(y1 - y0, x1 - x0).astype(np.float64)
    return out / N.reshape(N.shape + (1,) * (x.ndim - 2))


def _upsample_matrix(m: int, n: int) -> np.ndarray:
    """``(n, m)`` matrix of bilinear (pixel-centre aligned, edge-clamped) resampling from ``m`` to
    ``n`` samples (applied with BLAS, much cheaper than gathering at 128 px)."""
    x = np.clip((np.arange(n) + 0.5) * (m / n) - 0.5, 0.0, m - 1.0)
    i0 = np.minimum(np.floor(x).astype(np.int64), m - 1)
    i1 = np.minimum(i0 + 1, m - 1)
    w = x - i0
    A = np.zeros((n, m))
    np.add.at(A, (np.arange(n), i0), 1.0 - w)
    np.add.at(A, (np.arange(n), i1), w)
    return A


def _upsample2(a: np.ndarray, H: int, W: int) -> np.ndarray:
    """Bilinear resampling of ``a (h, w, K)`` to ``(H, W, K)``."""
    h, w, K = a.shape
    t = (_upsample_matrix(h, H) @ a.reshape(h, w * K)).reshape(H, w, K)
    return np.matmul(_upsample_matrix(w, W), t)


def guided_filter(I: np.ndarray, p: np.ndarray, radius: int, eps: float, subsample: int = 1
                  ) -> np.ndarray:
    """Fast guided filter (He and Sun 2015) of ``p (H, W, C)`` with colour guide ``I (H, W, 3)``:
    the coefficients are computed on images subsampled by ``subsample`` with radius
    ``radius / subsample`` and bilinearly upsampled. ``subsample=1`` is He et al. 2010.
    All window means of one stage are taken together (one summed-area table of the stacked
    channels), which is what makes it cheap at Paparazzi's 128 px; with Numba the whole filter
    is one compiled pass (:mod:`.kernels`, same arithmetic)."""
    kernels = _KERNELS.get()
    if kernels is not None and I.ndim == 3 and I.shape[2] == 3 and p.ndim == 3 \
            and p.shape[:2] == I.shape[:2]:
        return kernels.guided_filter(np.ascontiguousarray(I, np.float64),
                                     np.ascontiguousarray(p, np.float64), float(radius),
                                     float(eps), max(1, int(subsample)))
    H, W = I.shape[:2]
    k = I.shape[2]
    C = p.shape[2]
    s = max(1, int(subsample))
    Is = I[::s, ::s] if s > 1 else I
    ps = p[::s, ::s] if s > 1 else p
    h, w = Is.shape[:2]
    r = max(1, int(round(radius / s)))
    stack = np.concatenate([Is, ps, (Is[..., :, None] * ps[..., None, :]).reshape(h, w, k * C),
                            (Is[..., :, None] * Is[..., None, :]).reshape(h, w, k * k)], axis=2)
    means = _box(stack, r)
    mI = means[..., :k]                                              # (h, w, 3)
    mp = means[..., k:k + C]                                         # (h, w, C)
    cov_Ip = means[..., k + C:k + C + k * C].reshape(h, w, k, C) - mI[..., :, None] * mp[..., None, :]
    Sigma = (means[..., k + C + k * C:].reshape(h, w, k, k) - mI[..., :, None] * mI[..., None, :]
             + eps * np.eye(k))
    a = np.linalg.solve(Sigma, cov_Ip)                               # (h, w, 3, C)
    b = mp - np.einsum("hwk,hwkc->hwc", mI, a)
    mab = _box(np.concatenate([a.reshape(h, w, k * C), b], axis=2), r)
    if s > 1:
        mab = _upsample2(mab, H, W)
    ma = mab[..., :k * C].reshape(H, W, k, C)
    mb = mab[..., k * C:]
    return np.einsum("hwk,hwkc->hwc", I, ma) + mb


#: the guided filter's defaults (issue 23; the measurements are in :func:`_guided`)
GUIDED_RADIUS = 4
GUIDED_EPSILON = 2e-3
GUIDED_SUBSAMPLE = 1
GUIDED_LEARNING_RATE = 1e-5
#: the guided filter's step on a rough scan (``FilterSpec.rough_learning_rate``; issue 23's
#: fifth pass, docs/results/paparazzi.md "Rough scans: the guided filter's energy barrier")
GUIDED_ROUGH_LEARNING_RATE = 2e-4


@dataclass(frozen=True)
class GuidedParams:
    radius: int = param(GUIDED_RADIUS, label="Radius", minimum=1, maximum=64, step=1,
                        tooltip="Window radius of the guided filter in pixels (at 128 px). "
                                "Larger smooths bigger features away.")
    epsilon: float = param(GUIDED_EPSILON, label="Epsilon", minimum=0.0, maximum=1.0,
                           log_scale=True, decimals=10,
                           tooltip="Edge-preservation threshold: colour variations in a window "
                                   "much smaller than this are smoothed, larger ones (sharp "
                                   "edges) kept. Near 0 the filter returns its input.")
    subsample: int = param(GUIDED_SUBSAMPLE, label="Subsampling", minimum=1, maximum=16, step=1,
                           tooltip="Fast guided filter speed-up: coefficients are computed on an "
                                   "image this many times smaller (1 = the exact guided filter, "
                                   "which keeps sharp edges; larger values blur them).")


def guided_noise_pixels(image: np.ndarray, mask: np.ndarray, params: GuidedParams
                        ) -> tuple[int, int]:
    """``(pixels, of)``: of the shape's pixels whose whole window (``params.radius``) lies on the
    shape (``of``; silhouettes left out), how many have a window colour variance (the mean of
    the three channels') above ``params.epsilon``: the pixels the guided filter keeps as edges
    rather than smooths (:func:`_guided`). A noisy scan is edges nearly everywhere, a clean
    surface only at its creases (``FilterSpec.noise_pixels``; measured in
    docs/results/paparazzi.md, "Rough probe on clean CAD models")."""
    I = np.asarray(image, np.float64)
    r = max(1, int(params.radius))
    inside = _box(np.asarray(mask, np.float64)[..., None], r)[..., 0] > 1.0 - 1e-9
    means = _box(np.concatenate([I, I * I], axis=2), r)
    k = I.shape[2]
    var = (means[..., k:] - means[..., :k] ** 2).mean(axis=2)
    return int((var[inside] > params.epsilon).sum()), int(inside.sum())


@register_filter("guided", kind="iterative", params=GuidedParams, resolution=128,
                 learning_rate=GUIDED_LEARNING_RATE, crease_angle=45.0,
                 rough_learning_rate=GUIDED_ROUGH_LEARNING_RATE,
                 noise_pixels=guided_noise_pixels, parallel_views=True,
                 description="Guided filter: edge-preserving smoothing")
def _guided(image, params: GuidedParams, ctx: FilterContext):
    """Self-guided filter (He et al. 2010; He and Sun 2015 with ``subsample`` > 1) of the
    rendering, colour image as guide (thesis 390-402, Fig. 2.15).

    Defaults (issue 23; docs/results/paparazzi.md, "Why the guided filter did not smooth"):
    radius 4, epsilon 2e-3, subsampling 1, learning rate 1e-5, and the remeshing keeps edges
    sharper than 45 degrees (``crease_angle``). The former defaults, the authors' script's
    radius 15, epsilon 1e-8, subsampling 4 at learning rate 5e-5 with creases free, did not
    lower the filter's own energy (the mean over the 16 monitor views rose on the bundled blob,
    300 iterations: 2.6e-8 -> 5.5e-8) and ended rougher than remeshing alone on spot, bob and
    camelhead. Each suspect measured on its own (benchmarks/paparazzi_effects.py --suspects):

    * epsilon 1e-8: a self-guided filter with a colour guide fits ``q = a I + b`` in each window;
      a window of a flat-shaded picture holds a few flat colours, which an affine map of the
      3 colour channels reproduces exactly (up to 4 of them), so as epsilon -> 0 the filter
      returns its input: the change it asks for is ~1e-4 per pixel, a displacement hundreds of
      times smaller than NAdam's step (about the learning rate whatever the gradient's size),
      so the steps are noise and the energy rises.
    * subsampling 4: the coefficients come from a picture 4 times smaller and are interpolated
      back, which mixes the two sides of a sharp edge: on fandisk the pixels of faces at its
      sharp edges changed 3-5 times more than the others (exact filter: about as much), so the
      filter asked to round every crease.
    * the thesis's epsilon 0.02: smooths strongly (bob, spot below their controls) but a 60-90
      degree crease's colour variance (sin^2(theta/2)/4 = 0.06-0.125 per window across it) is
      not far above it, so fandisk's creases were rounded (crease5 below 0.04) and its energy
      rose. Epsilon trades the two: at 1e-3 fandisk kept its creases (0.91) but spot ended no
      smoother than remeshing alone (343 vs 342); at 5e-3 spot 331 but fandisk's creases went
      (0.19) and its energy rose; 2e-3 does both (below).
    * remeshing without creases rounded fandisk's edges by itself (control crease5 0.01) and
      raised the guided run's energy (0.22 -> 0.55 at epsilon 1e-3); keeping creases fixes both.
    * learning rate: NAdam's step is about the learning rate per coordinate whatever the pull,
      so where the filter asks for little the step is noise. At epsilon 2e-3, 2e-5 still raised
      fandisk's energy (+0.6 %) and left camelhead rougher than its control (1362 vs 1338);
      1e-5 lowers it everywhere.

    Measured (1000 iterations, CLI defaults otherwise, control = the same run with the picture
    returned unchanged; mean energy of the 16 monitor views, bending energy, crease5): fandisk
    0.351 -> 0.339, 1529 vs 1604, crease5 0.91 (control 0.95); spot 1.059 -> 1.045, 337 vs 342;
    bob 1.85 -> 1.76, 161 vs 165; camelhead 1.37 -> 1.21, 1284 vs 1338.
    """
    return guided_filter(image, image, params.radius, params.epsilon, params.subsample)


# ----------------------------------------------------------------------------- quantization
def icosahedron_face_normals() -> np.ndarray:
    """(20, 3) unit outward normals of the faces of a regular icosahedron."""
    from ..mesh.primitives import icosahedron

    V, F = icosahedron()
    c = V[F].mean(1)
    return c / np.linalg.norm(c, axis=1, keepdims=True)


def _world_shading(params) -> Shading:
    return LambertianShading(frame="world")


@register_filter("quantize", kind="iterative", resolution=256, shading=_world_shading,
                 parallel_views=True,
                 description="Quantize normals (world frame) to the 20 icosahedron face normals")
def _quantize(image, params, ctx: FilterContext):
    palette = icosahedron_face_normals()
    n = image.reshape(-1, 3) * 2.0 - 1.0                 # colour -> normal (authors' mapping)
    # three broadcast products, not one (k, 3) @ (3, 20) BLAS call: on this 2-core machine at a
    # load of 9 the threaded BLAS call took 0.17 s for a 256 x 256 picture, these 0.09 s
    # (medians of 15, same process, 2026-11-26)
    dots = n[:, 0:1] * palette[:, 0] + n[:, 1:2] * palette[:, 1] + n[:, 2:3] * palette[:, 2]
    k = np.argmax(dots, axis=1)
    out = ((palette[k] + 1.0) / 2.0).reshape(image.shape)
    return np.where(ctx.mask[..., None], out, image)


# ----------------------------------------------------------------------------- SLIC
@dataclass(frozen=True)
class SlicParams:
    segments: int = param(100, label="Segments", minimum=2, maximum=5000, step=10,
                          tooltip="About how many superpixels a view full of the shape is cut "
                                  "into (fewer where the shape fills less of it).")
    compactness: float = param(10.0, label="Compactness", minimum=0.01, maximum=1000.0,
                               log_scale=True, tooltip="Higher values make squarer superpixels; "
                                                       "lower ones follow colour more.")


_EMPTY_CLUSTER = "One of the clusters is empty"


def _quiet_empty_cluster_warning() -> None:
    """Silence one harmless warning for good: scikit-image places the masked superpixels' first
    centres with SciPy's k-means, which warns when one of its clusters ends up empty (it keeps
    that centre where it was); seen in the wide views of 1000-iteration runs, and not the user's
    business. A filter installed once, matching that message only: ``warnings.catch_warnings``
    around each call (as before) swaps the process's filter list and is not safe when two
    pictures are filtered at once in two threads (``FilterSpec.parallel_views``). Looked up
    each time, since a caller (pytest, for one) may reset the list between runs."""
    import warnings

    for action, message, *_ in warnings.filters:
        if action == "ignore" and message is not None and message.pattern == _EMPTY_CLUSTER:
            return
    warnings.filterwarnings("ignore", message=_EMPTY_CLUSTER, category=UserWarning)


@register_filter("slic", kind="iterative", params=SlicParams, resolution=256, width=1.0,
                 learning_rate=6e-5, crease_angle=45.0, quick_look={"iterations": 300},
                 parallel_views=True,
                 description="SLIC superpixels: each superpixel takes its mean colour")
def _slic(image, params: SlicParams, ctx: FilterContext):
    """SLIC superpixels of the foreground, each painted with its mean colour (thesis 414-418).

    * Background: the pixels outside ``ctx.mask`` get no superpixel and enter no mean (the
      authors ran SLIC on the whole picture, so a superpixel across the silhouette pulled the
      faces beside it towards the background colour), and ``segments`` is scaled by the
      foreground's share of the picture, so a superpixel has the size it has in a full view
      (``segments`` per whole picture, as in the authors' call) whatever the silhouette: given
      the mask, scikit-image would cut the foreground alone into ``segments`` pieces, smaller
      ones the less of the view the shape fills (a fifth of the views of fandisk are less than
      80 % foreground).
    * Learning rate 6e-5, the authors' (their SLIC script; 1e-5 for the last sixth of the run,
      about our fifth for the last tenth). A view's superpixels are drawn anew each time, so
      the pull on a face changes from view to view: on average it flattens the face towards
      its neighbours, the rest is noise, and NAdam makes every pull, however weak, a step of
      about the learning rate along each coordinate. At 2e-4 (the other filters' default) the
      noise won: 1000 iterations with the CLI's defaults lowered the share of near-planar area
      of spot 0.30 -> 0.16 and of fandisk 0.75 -> 0.42, far below remeshing alone (0.30,
      0.63), and a Gaussian blur in place of SLIC roughened spot as much (0.30 -> 0.12 in 300
      iterations). At 6e-5: docs/results/paparazzi.md's effects table
      (benchmarks/paparazzi_effects.py).
    * View width 1.0 (the authors' 0.3). ``segments`` counts superpixels per picture, so the view
      width sets their size on the shape: at 0.3 a superpixel (a hundredth of the picture)
      covered only 1.5-4 triangles of the test meshes Loop-subdivided to >= 5,000 vertices
      (spot at 13,234: 3.4; bob, fandisk: 1.5; camelhead: 3.9), so the "flat patches" were
      hardly larger than a face, and 1000 iterations with the CLI's defaults left the
      near-planar share (measures.planar_area_fraction) below the remeshing-only control on
      spot (0.3005 -> 0.2948, control 0.2982) and barely above it on fandisk (0.751 -> 0.755,
      control 0.754). The thesis's shapes have 10^5-10^6 vertices (its SLIC example 43,000):
      many triangles per superpixel. At 1.0 a superpixel covers 11 times the area (spot 38
      triangles, bob and fandisk 16, camelhead 44), and each face is seen in more of the views.
      Measured 2026-11-25 (benchmarks/paparazzi_effects.py, 1000 iterations, CLI defaults;
      controls 0.2982, 0.018, 0.754, 0.278): spot 0.3005 -> 0.551, bob 0.008 -> 0.328, fandisk
      0.751 -> 0.798, camelhead 0.221 -> 0.589, all clean (camelhead: 2 rollbacks, step halved
      once); width 0.6: spot 0.419, fandisk 0.774; 1.5: spot 0.576, fandisk 0.799; spot in 300
      iterations (control 0.302): 0.263 at 0.3, 0.342 at 0.6, 0.429 at 1.0, 0.436 at 1.5, 0.404
      at 2.0. Painting each superpixel with its normalized mean normal instead of its mean
      colour did not help (spot, 300 iterations, 1.0 wide: 0.418).
    """
    from .slic import slic_labels

    mask = ctx.mask
    share = float(mask.mean())
    if mask.sum() < 4:
        return image
    img = np.clip(image, 0.0, 1.0)
    n = max(1, int(round(params.segments * share)))
    _quiet_empty_cluster_warning()
    # scikit-image's slic, label for label, 3.8 times faster (algorithms/paparazzi/slic.py)
    lab = slic_labels(img, mask, n, params.compactness)
    out = image.copy()
    m = lab > 0
    L = lab[m]
    cnt = np.bincount(L)
    for c in range(image.shape[2]):
        mean = np.bincount(L, weights=image[..., c][m]) / np.maximum(cnt, 1)
        out[..., c][m] = mean[L]
    return out


# ----------------------------------------------------------------------------- L0 smoothing
def l0_smooth(image: np.ndarray, lam: float = 0.01, kappa: float = 2.0,
              beta_max: float = 1e5) -> np.ndarray:
    """Image smoothing via L0 gradient minimization (Xu, Lu, Xu, Jia 2011), the half-quadratic
    splitting of their paper with periodic boundaries (FFT), as in the authors' MATLAB code.

    The iterations run in single precision (float32 planes, complex64 spectra; the result is
    returned as float64): a forward and back FFT pair of three 256 x 256 planes takes 0.6 ms
    instead of 2.1 ms, and with the compiled spatial step the filter takes 72 -> 23 ms a
    picture; the result differs from float64's by at most 0.004 (under one 8-bit grey level) on
    rendered views (docs/results/paparazzi.md). Each threshold ``lam / beta`` is rounded to
    float32 once, so that the NumPy and compiled paths compare the same numbers (the same bits;
    tested)."""
    from scipy import fft

    img = np.asarray(image, dtype=np.float32)
    S = np.ascontiguousarray(np.moveaxis(img, -1, 0))      # (C, H, W): contiguous FFT planes
    H, W = S.shape[1:]
    fx = np.zeros((H, W), np.float32); fx[0, 0], fx[0, -1] = -1.0, 1.0
    fy = np.zeros((H, W), np.float32); fy[0, 0], fy[-1, 0] = -1.0, 1.0
    denorm2 = np.abs(fft.rfft2(fx)) ** 2 + np.abs(fft.rfft2(fy)) ** 2
    normin1 = fft.rfft2(S)
    beta = 2.0 * lam
    kernels = _KERNELS.get()
    normin2 = np.empty_like(S)
    while beta < beta_max:
        thresh = np.float32(lam / beta)
        if kernels is not None:
            kernels.l0_gradient_step(S, thresh, normin2)
        else:
            h = np.roll(S, -1, axis=2) - S
            v = np.roll(S, -1, axis=1) - S
            t = (h * h + v * v).sum(axis=0) < thresh
            h[:, t] = 0.0
            v[:, t] = 0.0
            normin2 = (np.roll(h, 1, axis=2) - h) + (np.roll(v, 1, axis=1) - v)
        # (normin1 + beta F(normin2)) / (1 + beta |F(dx)|^2 + beta |F(dy)|^2), in place
        FS = fft.rfft2(normin2)
        FS *= np.float32(beta)
        FS += normin1
        FS *= np.float32(1.0) / (np.float32(1.0) + np.float32(beta) * denorm2)
        S = fft.irfft2(FS, s=(H, W))
        beta *= kappa
    return np.moveaxis(S, 0, -1).astype(np.float64)


@dataclass(frozen=True)
class L0Params:
    l0_lambda: float = param(0.01, label="λ (L0)", minimum=1e-5, maximum=1.0, log_scale=True,
                             decimals=5, tooltip="Weight of the L0 gradient penalty: larger "
                                                 "values give fewer, larger flat regions.")
    kappa: float = param(2.0, label="κ", minimum=1.05, maximum=10.0, advanced=True,
                         tooltip="Growth factor of the splitting weight per inner iteration.")


@register_filter("l0", kind="iterative", crease_angle=45.0, params=L0Params, resolution=256,
                 panel_iterations=1000, step_follows_edge=True, quick_look={"iterations": 1000},
                 parallel_views=True,
                 description="L0 gradient smoothing: piecewise-constant images, planar shapes")
def _l0(image, params: L0Params, ctx: FilterContext):
    return l0_smooth(image, params.l0_lambda, params.kappa)


# ----------------------------------------------------------------------------- L2 targets
@dataclass(frozen=True)
class TargetImageParams:
    image: str = param("", label="Target image",
                       tooltip="A square PNG/JPEG seen from the front camera (it is resized to "
                               "the render resolution).")


def _prepare_target_image(params: TargetImageParams, info: dict):
    return read_image(params.image, info["resolution"], 3)


@register_filter("target-image", kind="energy", params=TargetImageParams,
                 prepare=_prepare_target_image, single_view=True, resolution=128,
                 parallel_views=True,
                 description="L2 distance to a target image from one fixed view")
def _target_image(image, params, ctx: FilterContext):
    d = image - ctx.state
    return 0.5 * float((d * d).sum()), d


@dataclass(frozen=True)
class TargetMeshParams:
    target: str = param("", label="Target mesh",
                        tooltip="A mesh whose look is transferred (rendered from the same "
                                "cameras). It is placed like the input.")
    single_view: bool = param(False, label="Single view",
                              tooltip="Only the fixed front view instead of cameras all around.")


def _prepare_target_mesh(params: TargetMeshParams, info: dict):
    from ..mesh import read_mesh

    if not params.target:
        raise ParameterError("No target mesh was given; choose a mesh file to transfer.")
    data = read_mesh(params.target)
    if not np.isfinite(data.V).all() or data.F.min() < 0 or data.F.max() >= len(data.V):
        raise ParameterError(f"The target mesh {params.target} has invalid coordinates or faces; "
                             "clean it first (stylize3d clean).")
    return info["normalize"](data.V), data.F


@register_filter("target-mesh", kind="energy", params=TargetMeshParams,
                 prepare=_prepare_target_mesh, single_view=lambda p: p.single_view,
                 resolution=128, parallel_views=True,
                 description="L2 distance to renderings of another mesh (detail transfer)")
def _target_mesh(image, params, ctx: FilterContext):
    VT, FT = ctx.state
    other = ctx.render_other(VT, FT)
    both = ctx.mask & ctx.other_mask if ctx.other_mask is not None else ctx.mask
    d = (image - other) * both[..., None]
    return 0.5 * float((d * d).sum()), d
